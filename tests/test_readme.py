"""The command and Python blocks of the README and of every page of docs/ run, as written, in a fresh copy of the
repository, page by page in the order a new user reads them.

A new user runs the README's set-up, then works through the site in its reading order, the toctree of
docs/index.md: Getting started first (the later pages assume its set-up: sblsim installed into ``.venv`` and
activated, in the repository's folder), then each page's blocks top to bottom; a page may read what the
commands of the pages before it wrote (docs/index.md says so). This test does the same: one test per page, in
that order, in a copy holding the repository's files and nothing else. The pages run as two chains side by
side (:data:`CHAINS`, each a unit of work of pytest-xdist in a copy of its own: :func:`unit_of_test`): the
first is the README and every page
but those of the second, which read nothing another page wrote and start from Getting started's set-up. Each
``bash`` block runs in one shell (``set -e``: the first failing command fails the test, and the shell's trace
names it), each ``python`` block with the environment's Python in the copy's folder; a failure names the page,
the block's number and its line. (A page selected alone with ``-k`` runs without what the pages before it
wrote.) What is changed, and why:

* the set-up's ``python3 -m venv .venv && .venv/bin/pip install -e .`` part: the copy's ``.venv`` is this
  test's own environment (installing takes minutes and the network), the rest of the line runs;
* the test command (it would run this test again) is not run;
* the shell is one session: after a block that activates ``.venv``, the later blocks (of that page and of the
  pages after it) run activated;
* the built-in studies ``paper`` and ``million`` run as the paper's factors with 2 replicates of 10 s
  (the same commands, the same code paths, a minute instead of an hour).

A page may keep a block from running only by saying why in the page itself: its first line is a comment
``# not run: <reason>`` (an excerpt, a placeholder for the user's own Dask scheduler); every other block runs.
Each page's time is printed (``-s``) and reported by ``--durations``; the tutorial pages state it.

The figures the pages show (``![...](figures/NAME.png)``, the README's ``docs/figures/NAME.png``) are made by
the pages' own blocks: each copy starts without any file of ``docs/figures/``, and after a page's blocks have
run, every figure it shows must have been written by them (there, and since the page started: not left by an
earlier page), a PNG of about the size of the committed one (the same figure; matplotlib's bytes are not
stable, so the bytes are not compared). The figures a page quotes from its runs (marked: tests/page_figures.py) are
checked against what its blocks printed and wrote. Once both chains have run, the site is built from the first chain's
copy with the second's figures added (``sphinx-build -W``), and its images are the bytes the runs wrote.
"""

from __future__ import annotations

import os
import re
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.page_figures import check_page, marked

ROOT = Path(__file__).resolve().parents[1]
SETUP_INSTALL = "python3 -m venv .venv && .venv/bin/pip install -e . && "
#: the set-up's install, as this test leaves it out: the README's (followed by its commands) or a page's (alone)
INSTALL = re.compile(r"^python3 -m venv \.venv && \.venv/bin/pip install -e \.(?: && |$)")
NOT_RUN = {
    'python3 -m venv .venv && .venv/bin/pip install -e ".[test]" && .venv/bin/python -m pytest -q -m "not slow"':
        "the test command itself",
}
NOT_RUN_MARK = "# not run:"


def fenced_blocks(text: str, languages: tuple[str, ...] = ("bash",)) -> list[tuple[int, str, str]]:
    """The fenced blocks of a Markdown text in those languages, in order: (line number, language, body)."""
    names = "|".join(map(re.escape, languages))
    return [(text[:m.start()].count("\n") + 1, m.group(1), m.group(2))
            for m in re.finditer(rf"^```({names})\n(.*?)^```$", text, flags=re.S | re.M)]


def bash_blocks(text: str) -> list[tuple[int, str]]:
    """The ``bash`` fenced blocks of a Markdown text: (line number, body)."""
    return [(line, body) for line, _, body in fenced_blocks(text)]


def not_run(body: str) -> str | None:
    """The reason a block gives for not running (its first line ``# not run: <reason>``), else None."""
    first = body.split("\n", 1)[0].strip()
    return first[len(NOT_RUN_MARK):].strip() if first.startswith(NOT_RUN_MARK) else None


def reading_order() -> list[str]:
    """The pages of docs/ in the order of docs/index.md's toctree (index itself first)."""
    index = (ROOT / "docs" / "index.md").read_text()
    tree = re.search(r"^```\{toctree\}\n(.*?)^```$", index, flags=re.S | re.M)
    assert tree, "docs/index.md has no toctree"
    names = [line.strip() for line in tree.group(1).splitlines() if line.strip() and not line.startswith(":")]
    return ["docs/index.md", *(f"docs/{name}.md" for name in names)]


PAGES = ["README.md", *reading_order()]
FIGURES = "docs/figures"
#: The pages of the second chain (the first: every other page), each of which reads nothing another page wrote.
SECOND_CHAIN = ("docs/systems-compare.md", "docs/design.md", "docs/receivers.md", "docs/campaigns.md",
                "docs/budget.md", "docs/replay.md", "docs/tracking.md", "docs/sync.md", "docs/telemetry.md",
                "docs/log-format.md",
                "docs/calibration.md")
#: Chain -> its pages in reading order.
CHAINS = {"pages-1": [p for p in PAGES if p not in SECOND_CHAIN], "pages-2": [p for p in PAGES if p in SECOND_CHAIN]}
CHAIN_OF = {page: chain for chain, pages in CHAINS.items() for page in pages}
PAGE_RUN = "test_the_page_blocks_run_in_order"
SITE_BUILD = "test_the_site_builds_from_the_copy_with_the_figures_the_run_made"


def unit_of_test(name: str) -> str | None:
    """The unit of work (tests/conftest.py's scheduler) of a test of this file, by its name with parameters: a
    page run its chain's, the site's build its own (``pages-site``, run last: it waits for the chains); None for
    the others (the file's unit)."""
    if name.startswith(f"{PAGE_RUN}["):
        return CHAIN_OF.get(name[len(PAGE_RUN) + 1:-1])
    return "pages-site" if name == SITE_BUILD else None
#: What a chain's shell holds when it starts: the first runs the README's set-up, the second starts from Getting
#: started's (sblsim installed into .venv and activated).
START = {"pages-1": "", "pages-2": "source .venv/bin/activate\n"}


def figures_shown(page: str, text: str) -> list[str]:
    """The figures of ``docs/figures/`` a page shows (Markdown images), as paths from the repository's root."""
    shown = []
    for target in re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", text):
        path = os.path.normpath(os.path.join(os.path.dirname(page), target))
        if path.startswith(FIGURES + "/") and path not in shown:
            shown.append(path)
    return shown


def png_size(path: Path) -> tuple[int, int]:
    """The width and height [px] of a PNG file (its IHDR chunk); ValueError if it is not a PNG."""
    head = path.read_bytes()[:24]
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise ValueError(f"{path} is not a PNG file")
    return struct.unpack(">II", head[16:24])


def as_run(body: str, study: str) -> str:
    """A bash block as this test runs it (module docstring)."""
    lines = []
    for line in body.splitlines():
        if line.strip() in NOT_RUN:
            continue
        line = INSTALL.sub("", line)
        line = re.sub(r"\bsblsim campaign (paper|million)\b", f"sblsim campaign {study}", line)
        lines.append(line)
    return "\n".join(lines)


def test_the_readme_has_the_blocks_this_test_knows():
    blocks = bash_blocks((ROOT / "README.md").read_text())
    assert len(blocks) >= 1
    first = blocks[0][1].splitlines()
    assert len(first) == 2 and first[0].startswith(SETUP_INSTALL) and first[1] in NOT_RUN
    assert INSTALL.sub("", first[0]) == first[0][len(SETUP_INSTALL):]


def test_every_page_is_in_the_reading_order():
    """Every page of docs/ is run, once: the toctree lists each exactly once."""
    listed = reading_order()
    assert len(listed) == len(set(listed))
    assert sorted(listed) == sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))


@pytest.mark.parametrize("page", PAGES)
def test_every_block_runs_or_says_why_not(page):
    """A block kept from running names its reason in the page; every other one is Python that compiles or bash
    that parses (the run itself is :func:`test_the_page_blocks_run_in_order`)."""
    for line, language, body in fenced_blocks((ROOT / page).read_text(), ("bash", "python")):
        reason = not_run(body)
        if reason is not None:
            assert len(reason) >= 10, f"{page} block at line {line}: '# not run:' without a reason"
            continue
        if language == "python":
            compile(body, f"{page}:{line}", "exec")
        else:
            done = subprocess.run(["bash", "-n", "-c", body], capture_output=True, text=True)
            assert done.returncode == 0, f"{page}: bash block at line {line} does not parse:\n{done.stderr}"


def test_the_pages_have_blocks_that_run():
    runnable = {language: [(page, line) for page in PAGES
                           for line, lang, body in fenced_blocks((ROOT / page).read_text(), ("bash", "python"))
                           if lang == language and not_run(body) is None]
                for language in ("bash", "python")}
    assert len(runnable["python"]) >= 2, runnable
    assert len(runnable["bash"]) >= 8, runnable
    # the tutorials' commands are on their pages, not only in the README
    assert len({page for page, _ in runnable["bash"]} - {"README.md"}) >= 6, runnable


def test_every_committed_figure_is_shown_and_made_by_a_block_of_its_page():
    """Each file of docs/figures/ is shown by a page, and every page that shows it has a block that names it
    (the run itself, :func:`test_the_page_blocks_run_in_order`, checks that the block writes it)."""
    listed = subprocess.run(["git", "ls-files", FIGURES], cwd=ROOT, capture_output=True, text=True,
                            check=True).stdout.split()
    assert listed, "docs/figures/ holds no figure"
    shown = {page: figures_shown(page, (ROOT / page).read_text()) for page in PAGES}
    for figure in listed:
        pages = [page for page, figures in shown.items() if figure in figures]
        assert pages, f"{figure} is committed but no page shows it"
        for page in pages:
            blocks = [body for _, _, body in fenced_blocks((ROOT / page).read_text(), ("bash", "python"))
                      if not_run(body) is None]
            assert any(figure in body for body in blocks), f"{page} shows {figure} but no block of it writes it"
    for page, figures in shown.items():
        for figure in figures:
            assert figure in listed, f"{page} shows {figure}, which is not committed"
    assert "docs/figures/semicircle_trajectory_xy.png" in shown["README.md"]


def make_copy(tmp_path_factory) -> Path:
    """The repository's files (as git lists them) in a new folder, with this environment as its ``.venv``."""
    copy = tmp_path_factory.mktemp("readme") / "sblsim"
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        source = ROOT / name
        if source.is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, copy / name)
    (copy / ".venv").symlink_to(sys.prefix, target_is_directory=True)
    for figure in (copy / FIGURES).iterdir():  # the pages' blocks make them again
        figure.unlink()
    paper = (ROOT / "orchestrator" / "studies" / "paper.toml").read_text()
    short = re.sub(r"(?m)^replicates = \d+$", 'replicates = 2\nset = ["simulation.duration=10"]', paper)
    assert short != paper
    (copy / "short-paper.toml").write_text(short.replace('name = "paper"', 'name = "short-paper"'))
    return copy


@pytest.fixture(scope="module")
def chains(tmp_path_factory):
    """Per chain (made when its first page runs): its fresh copy, and what the user's shell keeps from one block
    to the next, across pages: the activated environment; and the pages whose blocks all ran."""
    made = {}

    def chain(name: str) -> dict:
        if name not in made:
            made[name] = {"copy": make_copy(tmp_path_factory), "session": START[name], "done": set()}
        return made[name]

    return chain


def shared_folder(tmp_path_factory, config) -> Path:
    """A folder every pytest-xdist worker of this run sees (their temporary folders have one parent per run)."""
    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if hasattr(config, "workerinput") else base) / "page-chains"
    folder.mkdir(exist_ok=True)
    return folder


def _say_chain(tmp_path_factory, config, chain: str, outcome: str, copy: Path | None = None) -> None:
    """Tell the site's build that a chain has ended: ``done`` (with its copy) or ``failed``."""
    folder = shared_folder(tmp_path_factory, config)
    (folder / f"{chain}.{outcome}").write_text(str(copy or ""))


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_the_page_blocks_run_in_order(chains, tmp_path_factory, request, page):
    name = CHAIN_OF[page]
    shell = chains(name)
    try:
        _run_page(shell["copy"], shell, page)
    except BaseException:
        _say_chain(tmp_path_factory, request.config, name, "failed")
        raise
    if page == CHAINS[name][-1] and set(CHAINS[name]) <= shell["done"]:
        _say_chain(tmp_path_factory, request.config, name, "done", shell["copy"])


def _run_page(fresh_copy: Path, shell: dict, page: str) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")}
    env["SBLSIM_FMU_DIR"] = str(fresh_copy / "fmus" / "build")  # where a checkout's own install builds them
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if Path(sys.prefix) not in
                                  Path(p).parents and p != str(Path(sys.prefix) / "bin"))
    python = str(fresh_copy / ".venv" / "bin" / "python")
    start = time.perf_counter()
    text = (fresh_copy / page).read_text()
    figures = figures_shown(page, text)
    before = {figure: (fresh_copy / figure).stat() if (fresh_copy / figure).exists() else None
              for figure in figures}
    started = time.time_ns()
    blocks = fenced_blocks(text, ("bash", "python"))
    printed = {}  # each block's first line -> what it printed (the page's marked figures are checked against it)
    for number, (line, language, body) in enumerate(blocks, 1):
        if not_run(body) is not None:
            continue
        where = f"{page}: {language} block {number} of {len(blocks)} (line {line}) failed"
        if language == "python":
            done = subprocess.run([python, "-c", body], cwd=fresh_copy, env=env, capture_output=True, text=True,
                                  timeout=1200)
            assert done.returncode == 0, f"{where}:\n{done.stderr[-4000:]}"
            printed[line] = done.stdout + "\n" + done.stderr
            continue
        script = as_run(body, "short-paper.toml")
        done = subprocess.run(["bash", "-e", "-x", "-c", shell["session"] + script], cwd=fresh_copy, env=env,
                              capture_output=True, text=True, timeout=1200)
        assert done.returncode == 0, f"{where}:\n{done.stderr[-4000:]}"
        printed[line] = done.stdout + "\n" + done.stderr
        if "source .venv/bin/activate" in script:
            shell["session"] = "source .venv/bin/activate\n"
    for figure in figures:
        made = fresh_copy / figure
        assert made.is_file(), f"{page}: the figure {figure} it shows was not made by its blocks"
        now, earlier = made.stat(), before[figure]
        assert earlier is None or (now.st_mtime_ns, now.st_ino, now.st_size) != \
            (earlier.st_mtime_ns, earlier.st_ino, earlier.st_size), \
            f"{page}: the figure {figure} it shows was not written again by its blocks (an earlier page's)"
        assert now.st_mtime_ns >= started - 2_000_000_000, f"{page}: the figure {figure} is older than the page's run"
        width, height = png_size(made)
        committed = png_size(ROOT / figure)
        assert abs(width / committed[0] - 1) < 0.2 and abs(height / committed[1] - 1) < 0.2, \
            f"{page}: the figure {figure} made is {width}x{height} px, the committed one {committed[0]}x{committed[1]}"
    if marked(text):  # the figures the page quotes, against what its blocks printed and wrote (tests/page_figures.py)
        problems = check_page(text, printed, fresh_copy)
        assert not problems, f"{page}: figures the run does not give:\n" + "\n".join(problems)
    shell["done"].add(page)
    print(f"\n{page}: {len(blocks)} blocks in {time.perf_counter() - start:.0f} s")


#: How long the site's build waits for the page chains run by other workers [s].
CHAIN_WAIT = 3600.0


@pytest.mark.slow
def test_the_site_builds_from_the_copy_with_the_figures_the_run_made(tmp_path_factory, request, tmp_path):
    """After every page has run: ``sphinx-build -W`` of the first chain's copy of docs/, with the figures the
    second chain's pages made added, whose images are the bytes the pages' blocks wrote (the committed figures
    were removed from the copies before the runs)."""
    selected = {item.callspec.params["page"] for item in request.session.items
                if getattr(item, "originalname", None) == PAGE_RUN}
    if set(PAGES) - selected:
        pytest.skip("not every page's blocks run in this selection")
    pytest.importorskip("sphinx", reason="the docs extra is not installed (pip install -e '.[docs]')")
    folder = shared_folder(tmp_path_factory, request.config)
    copies, deadline = {}, time.monotonic() + CHAIN_WAIT
    while len(copies) < len(CHAINS):  # the chains run in other workers, or before this test in this one
        for chain in CHAINS:
            if (folder / f"{chain}.failed").exists():
                pytest.skip(f"a page of {chain} failed")
            if (folder / f"{chain}.done").exists():
                copies[chain] = Path((folder / f"{chain}.done").read_text())
        assert time.monotonic() < deadline, f"the page chains did not end within {CHAIN_WAIT:.0f} s: {sorted(copies)}"
        time.sleep(1.0)
    first, *others = [copies[chain] for chain in CHAINS]
    source = tmp_path / "docs"
    shutil.copytree(first / "docs", source)
    made = {}  # figure -> the copy whose pages made it
    for chain, copy in copies.items():
        for page in CHAINS[chain]:
            for figure in figures_shown(page, (copy / page).read_text()):
                made[figure] = copy
                shutil.copyfile(copy / figure, tmp_path / figure)
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-E", "-b", "html",
                           "-d", str(tmp_path / ".doctrees"), str(source), str(tmp_path / "html")],
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"the docs build of the copy failed:\n{done.stderr[-6000:]}"
    shown = {figure for page in PAGES if page != "README.md"
             for figure in figures_shown(page, (first / page).read_text())}
    assert len(shown) >= 10, shown
    for figure in sorted(shown):
        in_site = tmp_path / "html" / "_images" / Path(figure).name
        assert in_site.is_file(), f"the site has no {figure}"
        assert in_site.read_bytes() == (made[figure] / figure).read_bytes(), f"the site's {figure} is not the run's"
