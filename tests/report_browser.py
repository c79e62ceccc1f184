"""A study's report opened in a real browser, offline: Debian's Chromium (``/usr/bin/chromium``; never a browser
Playwright downloads) driven by Playwright's Python API, headless, in a new empty profile, every request that is
not a ``file:`` URL aborted and counted (:func:`open_report`); what the page shows, measured in it
(:func:`inspect_page`). The slow tests' browser checks use it, and so does the telemetry page's block that makes
its screenshot of the boats' report::

    python -m tests.report_browser REPORT.html SCREENSHOT.png
"""

from __future__ import annotations

import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

#: The browser, and its switches: headless, no sandbox (root in a container), no GPU, nothing fetched in the
#: background, no first-run screens.
CHROMIUM = Path("/usr/bin/chromium")
SWITCHES = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", "--no-first-run"]
#: The window the page is opened in [px].
VIEWPORT = {"width": 1280, "height": 900}

#: What the page shows, measured in it: every image's natural width, every in-page link's target, the tag table's
#: rows, the section ids.
MEASURE = """() => ({
  images: Array.from(document.images).map(i => ({alt: i.alt, width: i.naturalWidth, complete: i.complete,
                                                 src: i.getAttribute('src').slice(0, 30)})),
  links: Array.from(document.querySelectorAll('a[href]')).map(a => a.getAttribute('href')),
  missing: Array.from(document.querySelectorAll('a[href^="#"]')).map(a => a.getAttribute('href').slice(1))
           .filter(id => !document.getElementById(id)),
  sources: Array.from(document.querySelectorAll('[src]')).map(e => e.getAttribute('src').slice(0, 30)),
  tag_rows: document.querySelectorAll('#tag-table tbody tr').length,
  tag_links: Array.from(document.querySelectorAll('#tag-table tbody tr td:first-child a'))
             .map(a => a.textContent),
  scripts: document.scripts.length,
  text: document.body.innerText.length,
})"""


@dataclass
class Opened:
    """A report as the browser opened it: its page, the requests aborted (not ``file:``), the requests that failed,
    the console's errors, and the seconds from the navigation to the page's ``load`` event."""

    page: Any
    blocked: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    load_s: float = float("nan")


@contextmanager
def open_report(report: Path) -> Iterator[Opened]:
    """``report`` opened from its file URL in headless Chromium with the network blocked (the module docstring).

    Raises
    ------
    RuntimeError
        No Chromium at :data:`CHROMIUM` (install Debian's: ``apt-get install -y chromium``).
    """
    from playwright.sync_api import sync_playwright

    if not CHROMIUM.exists():
        raise RuntimeError(f"no Chromium at {CHROMIUM}: install Debian's package (apt-get install -y chromium)")
    with sync_playwright() as p, tempfile.TemporaryDirectory(prefix="report-profile-") as profile:
        context = p.chromium.launch_persistent_context(profile, executable_path=str(CHROMIUM), headless=True,
                                                       args=SWITCHES, viewport=VIEWPORT)
        try:
            opened = Opened(context.new_page())

            def route(r) -> None:
                if r.request.url.startswith("file:"):
                    r.continue_()
                else:
                    opened.blocked.append(r.request.url)
                    r.abort()

            context.route("**/*", route)
            opened.page.on("console", lambda m: opened.errors.append(m.text) if m.type == "error" else None)
            opened.page.on("pageerror", lambda e: opened.errors.append(str(e)))
            opened.page.on("requestfailed", lambda r: opened.failed.append(r.url))
            start = time.perf_counter()
            opened.page.goto(Path(report).absolute().as_uri(), wait_until="load")
            opened.load_s = time.perf_counter() - start
            yield opened
        finally:
            context.close()


def inspect_page(opened: Opened) -> dict[str, Any]:
    """What the page shows (:data:`MEASURE`), measured in the browser."""
    return opened.page.evaluate(MEASURE)


def screenshot(report: Path, out: Path, full_page: bool = False) -> bytes:
    """A PNG of the report's first screen (or its whole page), written to ``out``; its bytes."""
    with open_report(report) as opened:
        data = opened.page.screenshot(path=str(out), full_page=full_page)
    return data


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python -m tests.report_browser REPORT.html SCREENSHOT.png")
    screenshot(Path(sys.argv[1]), Path(sys.argv[2]))
    print(f"wrote {sys.argv[2]}")
