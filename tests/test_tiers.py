"""The two tiers of the tests: the README's test command runs the fast one (``-m "not slow"``), CI runs it and then
the slow one (``-m slow``), and no check is lost between them.

* the fast tier holds no test of the slow kind (``slow``, ``network``, ``audit``), and the two tiers together are
  every test collected, at least as many as before the tiers (2,496);
* the README's test command and ``.ci/run`` are the commands docs/architecture.md describes;
* (slow, ``audit``: run by hand, ``pytest -m audit``; CI's slow tier leaves it out, ``-m "slow and not audit"``,
  for its ten minutes on two workers) every module of ``models/``, ``orchestrator/`` and ``fmus/`` runs in the fast
  tier: the fast tier run under coverage (pytest-cov, subprocesses measured too), and every module has lines run
  beyond its import.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The markers of the slow kind: a test carrying one is in the slow tier.
SLOW_KIND = {"slow", "network", "audit"}
#: The tests collected over both tiers when they were made (no test removed by the split).
TESTS_BEFORE_THE_TIERS = 2496
#: The package's folders and their installed names.
PACKAGES = {"models": "sblsim.models", "orchestrator": "sblsim.orchestrator", "fmus": "sblsim.fmus"}


def readme_test_command() -> str:
    """The README's second set-up command (the test command)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"^```bash\n(.*?)^```$", text, flags=re.S | re.M).group(1).strip().splitlines()
    return block[1]


def marker_expression(command: str) -> str:
    """The ``-m`` expression of a pytest command line (after ``pytest``)."""
    found = re.search(r"""-m\s+(?:"([^"]*)"|'([^']*)'|(\S+))""", command.split("pytest", 1)[-1])
    assert found, f"no -m in {command!r}"
    return next(g for g in found.groups() if g is not None)


def collected_markers(tmp_path: Path) -> dict[str, list[str]]:
    """Every test's id and markers, as one collection of the whole suite writes them (tests/conftest.py)."""
    target = tmp_path / "markers.json"
    env = {**os.environ, "SBLSIM_COLLECTED_MARKERS": str(target)}
    done = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-n", "0", "-p",
                           "no:cacheprovider", "-m", ""], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return json.loads(target.read_text())


@pytest.mark.slow
def test_the_fast_tier_holds_no_slow_test_and_the_tiers_hold_every_test(tmp_path):
    markers = collected_markers(tmp_path)
    expression = marker_expression(readme_test_command())
    assert expression == "not slow"
    fast = [test for test, names in markers.items() if not SLOW_KIND & set(names)]
    slow = [test for test, names in markers.items() if "slow" in names]
    # a network or audit test that is not also marked slow would be in the fast tier
    assert [test for test, names in markers.items()
            if (SLOW_KIND - {"slow"}) & set(names) and "slow" not in names] == []
    assert any("audit" in names for names in markers.values())
    assert len(fast) + len(slow) == len(markers) >= TESTS_BEFORE_THE_TIERS
    assert fast and slow
    # each test file of the suite keeps a test in the fast tier, but for those that are all builds, hosts or pages,
    # and one that is a whole study tried as a user would (a name's folder has fast tests of its own)
    files = {test.split("::")[0] for test in markers}
    fast_files = {test.split("::")[0] for test in fast}
    assert files - fast_files == {"tests/orchestrator/test_ssp_hosts.py", "tests/test_packaging.py",
                                  "tests/test_bench_detection.py", "tests/orchestrator/test_study_report_browser.py",
                                  "tests/orchestrator/test_study_folders.py"}


def test_ci_runs_the_readme_s_test_command_then_the_slow_tier():
    ci = (ROOT / ".ci" / "run").read_text()
    command = readme_test_command()
    assert command.startswith('python3 -m venv .venv && .venv/bin/pip install -e ".[test]" && ')
    assert command in ci
    slow = re.search(r"""^.*pytest.*-m "slow and not audit".*$""", ci, flags=re.M)
    assert slow and ci.index(command) < slow.start()
    # what CI leaves out of the slow tier is the audit alone, marked slow too (so `pytest -m slow` runs it)
    markers = {name for name, _, _ in (line.partition(":") for line in _markers())}
    assert SLOW_KIND <= markers
    # pytest's exit 5 (no test selected) is handled, every other failure fails CI
    assert "-ne 5" in ci
    architecture = (ROOT / "docs" / "architecture.md").read_text()
    assert '-m "not slow"' in architecture and "-m slow" in architecture and "--durations" in architecture


def _markers() -> list[str]:
    """pyproject.toml's pytest markers (``name: what it marks``)."""
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]["markers"]


def _modules() -> dict[str, Path]:
    """Every module of the package's folders by its path."""
    found = {}
    for folder in PACKAGES:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if "__pycache__" not in path.parts:
                found[str(path.relative_to(ROOT))] = path
    return found


def _body_lines(path: Path) -> set[int]:
    """The lines of a module inside its functions' bodies (run only when a function is called)."""
    import ast

    lines: set[int] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for inner in node.body:
                if isinstance(inner, ast.Expr) and isinstance(getattr(inner, "value", None), ast.Constant):
                    continue  # a docstring
                lines.update(range(inner.lineno, (inner.end_lineno or inner.lineno) + 1))
    return lines


@pytest.mark.slow
@pytest.mark.audit
def test_every_module_is_run_by_the_fast_tier(tmp_path):
    """The fast tier under coverage: every module with functions has one of them run (a test of it left in the
    fast tier), the package's ``__init__`` files and modules of declarations only excepted by having no function."""
    config = tmp_path / "coverage.toml"
    config.write_text('[tool.coverage.run]\nparallel = true\npatch = ["subprocess"]\n'
                      f'data_file = "{tmp_path / ".coverage"}"\n'
                      f'source = [{", ".join(repr(str(ROOT / f)) for f in PACKAGES)}]\n')
    report = tmp_path / "coverage.json"
    # each option's value joined to it by "=": pytest's first look at the arguments, before the plugins' options
    # are known, took a separate value for a path, found no configuration there and ran without pyproject.toml's
    # (one process, no markers)
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-m", "not slow", "-p", "no:cacheprovider",
                           "--cov", f"--cov-config={config}", f"--cov-report=json:{report}",
                           f"--ignore={Path(__file__).relative_to(ROOT)}"],
                          cwd=ROOT, capture_output=True, text=True, timeout=3600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    files = {str(Path(name).resolve().relative_to(ROOT)) if Path(name).is_absolute() else name: data
             for name, data in json.loads(report.read_text())["files"].items()}
    unrun = []
    for name, path in _modules().items():
        body = _body_lines(path)
        if not body:
            continue
        executed = set(files.get(name, {}).get("executed_lines", []))
        if not executed & body:
            unrun.append(name)
    assert unrun == []
