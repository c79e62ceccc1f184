"""The README's command and Python blocks run top to bottom, as written, in a fresh copy of the repository;
then the Python blocks of every page of docs/.

A new user copies the ``bash`` blocks in order; this test does the same, each block in one shell
(``set -e``: the first failing command fails the test, and the shell's trace names it), in a folder
holding the repository's files and nothing else. What is changed, and why:

* the set-up command's ``python3 -m venv .venv && .venv/bin/pip install -e .`` part: the copy's ``.venv``
  is this test's own environment (installing takes minutes and the network), the rest of the line runs;
* the test command (it would run this test again) and the Dask-cluster line (its address is a placeholder
  for the user's own scheduler) are not run;
* the shell is one session: after the block that activates ``.venv``, the later blocks run activated;
* the built-in studies ``paper`` and ``million`` run as the paper's factors with 2 replicates of 10 s
  (the same commands, the same code paths, a minute instead of an hour).

A ``python`` block runs with the environment's Python in the copy's folder, after the blocks above it (it
reads what they wrote). A page may keep a block from running only by saying why in the page itself: its first
line is a comment ``# not run: <reason>`` (an excerpt, say); every other block runs.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SETUP_INSTALL = "python3 -m venv .venv && .venv/bin/pip install -e . && "
NOT_RUN = {
    'python3 -m venv .venv && .venv/bin/pip install -e ".[test]" && .venv/bin/python -m pytest -q':
        "the test command itself",
}
PLACEHOLDER = "SCHEDULER-HOST"


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
    """The reason a Python block gives for not running (its first line ``# not run: <reason>``), else None."""
    first = body.split("\n", 1)[0].strip()
    return first[len(NOT_RUN_MARK):].strip() if first.startswith(NOT_RUN_MARK) else None


PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]


def as_run(body: str, study: str) -> str:
    """A block as this test runs it (module docstring)."""
    lines = []
    for line in body.splitlines():
        if line.strip() in NOT_RUN or PLACEHOLDER in line:
            continue
        line = line.replace(SETUP_INSTALL, "")
        line = re.sub(r"\bsblsim campaign (paper|million)\b", f"sblsim campaign {study}", line)
        lines.append(line)
    return "\n".join(lines)


def test_the_readme_has_the_blocks_this_test_knows():
    blocks = bash_blocks((ROOT / "README.md").read_text())
    assert len(blocks) >= 5
    first = blocks[0][1].splitlines()
    assert len(first) == 2 and first[0].startswith(SETUP_INSTALL) and first[1] in NOT_RUN


@pytest.mark.parametrize("page", PAGES)
def test_every_python_block_runs_or_says_why_not(page):
    """A block kept from running names its reason in the page; every other one is Python that compiles (the
    run itself is :func:`test_readme_blocks_run_in_order`)."""
    for line, _, body in fenced_blocks((ROOT / page).read_text(), ("python",)):
        reason = not_run(body)
        if reason is not None:
            assert len(reason) >= 10, f"{page} block at line {line}: '# not run:' without a reason"
            continue
        compile(body, f"{page}:{line}", "exec")


def test_the_pages_have_python_blocks_that_run():
    runnable = [(page, line) for page in PAGES for line, _, body in fenced_blocks((ROOT / page).read_text(),
                                                                                    ("python",))
                if not_run(body) is None]
    assert len(runnable) >= 2, runnable


@pytest.fixture(scope="module")
def fresh_copy(tmp_path_factory):
    """The repository's files (as git lists them) in a new folder, with this environment as its ``.venv``."""
    copy = tmp_path_factory.mktemp("readme") / "sblsim"
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        source = ROOT / name
        if source.is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, copy / name)
    (copy / ".venv").symlink_to(sys.prefix, target_is_directory=True)
    paper = (ROOT / "orchestrator" / "studies" / "paper.toml").read_text()
    short = re.sub(r"(?m)^replicates = \d+$", 'replicates = 2\nset = ["simulation.duration=10"]', paper)
    assert short != paper
    (copy / "short-paper.toml").write_text(short.replace('name = "paper"', 'name = "short-paper"'))
    return copy


def test_readme_blocks_run_in_order(fresh_copy):
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")}
    env["SBLSIM_FMU_DIR"] = str(fresh_copy / "fmus" / "build")  # where a checkout's own install builds them
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if Path(sys.prefix) not in
                                  Path(p).parents and p != str(Path(sys.prefix) / "bin"))
    session = ""  # what the user's shell keeps from one block to the next: the activated environment
    python = str(fresh_copy / ".venv" / "bin" / "python")
    for page in PAGES:  # the README first: the docs' blocks may read what its commands wrote
        languages = ("bash", "python") if page == "README.md" else ("python",)
        for line, language, body in fenced_blocks((fresh_copy / page).read_text(), languages):
            if language == "python":
                if not_run(body) is not None:
                    continue
                done = subprocess.run([python, "-c", body], cwd=fresh_copy, env=env, capture_output=True, text=True,
                                      timeout=1200)
                assert done.returncode == 0, f"{page}: Python block at line {line} failed:\n{done.stderr[-4000:]}"
                continue
            script = as_run(body, "short-paper.toml")
            done = subprocess.run(["bash", "-e", "-x", "-c", session + script], cwd=fresh_copy, env=env,
                                  capture_output=True, text=True, timeout=1200)
            assert done.returncode == 0, f"{page}: block at line {line} failed:\n{done.stderr[-4000:]}"
            if "source .venv/bin/activate" in script:
                session = "source .venv/bin/activate\n"
