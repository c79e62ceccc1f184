"""The documentation site builds from the checkout, offline, with warnings as errors, and its links hold.

``sphinx-build -W`` turns every warning into an error: a Markdown link to a page or heading that does not
exist, a docstring numpydoc cannot parse, a toctree entry without its page. The built HTML is then checked
for what Sphinx does not check: every internal link reaches a file of the site (and its anchor an ``id`` of
that page), and no page loads a script, style sheet or font from the network.
"""

from __future__ import annotations

import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ("index", "getting-started", "usage", "model", "systems-compare", "receivers", "campaigns", "budget", "replay",
         "log-format", "interop", "variables", "extending", "measurement-models", "systems", "hardware-grades",
         "benchmarks", "architecture", "cli", "api")


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []
        self.loads: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if "id" in attrs:
            self.ids.add(attrs["id"])
        if tag == "a" and attrs.get("href"):
            self.links.append(attrs["href"])
        if tag in ("script", "img", "iframe") and attrs.get("src"):
            self.loads.append(attrs["src"])
        if tag == "link" and attrs.get("href") and attrs.get("rel") in ("stylesheet", "preload", "icon"):
            self.loads.append(attrs["href"])


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("sphinx", reason="the docs extra is not installed (pip install -e '.[docs]')")
    pytest.importorskip("myst_parser", reason="the docs extra is not installed (pip install -e '.[docs]')")
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-E", "-b", "html",
                           "-d", str(out / ".doctrees"), str(ROOT / "docs"), str(out / "html")],
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"the docs build failed:\n{done.stderr[-6000:]}"
    return out / "html"


def test_every_page_is_built(site):
    for page in PAGES:
        assert (site / f"{page}.html").is_file(), page
    api = (site / "api.html").read_text()
    for name in ("sblsim.load", "sblsim.run", "sblsim.compare", "sblsim.accuracy_map", "sblsim.budget",
                 "sblsim.replay", "sblsim.campaign", "sblsim.analyze"):
        assert f'id="{name}"' in api, f"{name} is missing from the API reference"
    cli = (site / "cli.html").read_text()
    for command in ("run", "replay", "compare", "budget", "map", "campaign", "analyze", "--extent"):
        assert command in cli


def test_internal_links_reach_a_page_and_anchor_and_nothing_loads_from_the_network(site):
    parsed = {}
    for page in site.rglob("*.html"):
        p = _Links()
        p.feed(page.read_text(encoding="utf-8"))
        parsed[page.resolve()] = p
    broken, remote = [], []
    for page, p in parsed.items():
        remote += [f"{page.name}: {u}" for u in p.loads if re.match(r"^(https?:)?//", u)]
        for href in p.links:
            parts = urlsplit(href)
            if parts.scheme or parts.netloc or href.startswith("mailto:"):
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if not target.exists():
                broken.append(f"{page.name}: {href}")
            elif parts.fragment and target.suffix == ".html" and target in parsed \
                    and unquote(parts.fragment) not in parsed[target].ids:
                broken.append(f"{page.name}: {href} (no such anchor)")
    assert not broken, broken
    assert not remote, remote
