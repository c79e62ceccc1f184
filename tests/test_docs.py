"""The documentation site builds, as a user builds it, from the ``docs`` extra alone in a fresh virtual
environment, offline, with warnings as errors, and its links hold.

The repository's files (as git lists them) are copied into a new folder, and ``pip install "<copy>[docs]"``
installs sblsim with its dependencies and the docs extra, and nothing else, into a new virtual environment
(from the package index, through pip's cache; the ``network`` mark: ``-m "not network"`` leaves it out where
no index is reachable). ``sphinx-build -W`` then runs there with the network shut (a connection or a name
look-up from the build process raises), so a build that fetches anything, or that imports a package the
extra does not install (autodoc imports sblsim and what its modules import), fails. ``-W`` turns every
warning into an error: a Markdown link to a page or heading that does not exist, a docstring numpydoc cannot
parse, a toctree entry without its page. The built HTML is then checked for what Sphinx does not check:
every internal link reaches a file of the site (and its anchor an ``id`` of that page), and no page loads a
script, style sheet or font from the network.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import venv
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ("index", "getting-started", "usage", "model", "systems-compare", "receivers", "campaigns", "budget", "replay",
         "log-format", "calibration", "interop", "variables", "extending", "measurement-models", "systems",
         "hardware-grades", "benchmarks", "architecture", "cli", "api")


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


#: sphinx-build with the network shut: any connection or name look-up of the build process raises
OFFLINE_BUILD = """
import socket, sys
def offline(*args, **kwargs):
    raise OSError("the documentation's build must not use the network")
socket.socket.connect = socket.socket.connect_ex = offline
socket.create_connection = socket.getaddrinfo = offline
from sphinx.cmd.build import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built offline with ``-W`` in a fresh environment holding sblsim and its ``docs`` extra only."""
    work = tmp_path_factory.mktemp("docs-build")
    copy = work / "sblsim"
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        if (ROOT / name).is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, copy / name)
    env = work / "env"
    venv.EnvBuilder(with_pip=True).create(env)
    python = str(env / "bin" / "python")
    done = subprocess.run([python, "-m", "pip", "install", "-q", "--no-compile", f"{copy}[docs]"],
                          capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, f"pip install '<copy>[docs]' failed:\n{done.stderr[-4000:]}"
    installed = subprocess.run([python, "-m", "pip", "list", "--format=freeze"], capture_output=True, text=True,
                               check=True).stdout.lower()
    for name in ("sphinx", "myst-parser", "numpydoc", "sphinx-argparse", "sblsim"):
        assert f"\n{name}==" in f"\n{installed}", f"{name} is not installed by the docs extra"
    for name in ("pytest", "libcosimpy", "filterpy"):  # the test extra's: the build must not need them
        assert f"\n{name}==" not in f"\n{installed}", f"{name} is installed, but only the docs extra was asked for"
    out = work / "site"
    done = subprocess.run([python, "-c", OFFLINE_BUILD, "-W", "--keep-going", "-q", "-E", "-b", "html",
                           "-d", str(out / ".doctrees"), str(copy / "docs"), str(out / "html")],
                          cwd=work, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"the docs build failed:\n{done.stderr[-6000:]}"
    return out / "html"


@pytest.mark.slow
@pytest.mark.network
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


@pytest.mark.slow
@pytest.mark.network
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


def test_the_offline_build_refuses_the_network():
    """The build's network shut-off works: a connection attempted under it raises (else the build's
    offline check above would hold vacuously)."""
    probe = OFFLINE_BUILD.split("from sphinx")[0] + (
        "import urllib.request\n"
        "try:\n    urllib.request.urlopen('http://127.0.0.1:9/', timeout=5)\n"
        "except OSError as e:\n    print('refused' if 'must not use the network' in str(e) else repr(e))\n")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "refused", done.stdout + done.stderr


def _help_texts(parser: argparse.ArgumentParser):
    yield parser.description or ""
    yield parser.epilog or ""
    for action in parser._actions:
        yield action.help or ""
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                yield choice.help or ""
            for sub in action.choices.values():
                yield from _help_texts(sub)


def test_the_command_lines_help_points_at_pages_that_exist():
    """No help text sends the reader to the README for what moved into docs/; each page a help text names
    (``docs/NAME.md``) exists."""
    from sblsim.orchestrator.cli import _parser

    texts = list(_help_texts(_parser()))
    text = "\n".join(texts)
    assert "README" not in text, [t for t in texts if "README" in t]
    named = set(re.findall(r"docs/([\w-]+)\.md", text))
    assert "extending" in named  # fmus build --model
    for name in named:
        assert (ROOT / "docs" / f"{name}.md").is_file(), f"a help text names docs/{name}.md, which does not exist"
