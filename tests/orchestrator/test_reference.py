"""Reference results: every built-in scenario at seed 1 against tests/data/reference, and the Results tables
of the README and of docs/usage.md against the same files (as the Modelica Reference-FMUs keep a reference
output per model).

After a change meant to alter the numbers: ``python tests/data/reference/regenerate.py``, then update the
README's and docs/usage.md's tables and say why in the commit.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from sblsim.orchestrator.cosim.config import BUILTIN_SCENARIOS
from tests.data.reference.regenerate import reference, table_cells

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "tests" / "data" / "reference"


def stored(name: str) -> dict:
    return json.loads((REFERENCE / f"{name}.json").read_text())


@pytest.mark.slow
@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_a_fresh_run_equals_the_reference(name):
    want, got = stored(name), reference(name)
    assert set(got) == set(want)
    for key, value in want.items():
        if isinstance(value, float):
            assert math.isclose(got[key], value, rel_tol=0, abs_tol=1e-9), (key, got[key], value)
        else:
            assert got[key] == value, key


def readme_results(page: str = "README.md") -> dict[str, list[str]]:
    text = (ROOT / page).read_text()
    section = text.split("## Results", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if re.match(r"^\| [a-z-]+ \| \d", line)]
    return {cells[0]: cells[1:] for cells in ([c.strip() for c in row.strip("|").split("|")] for row in rows)}


@pytest.mark.parametrize("page", ["README.md", "docs/usage.md"])
def test_the_readme_results_table_equals_the_references(page):
    table = readme_results(page)
    assert sorted(table) == sorted(BUILTIN_SCENARIOS)
    for name, cells in table.items():
        ref = stored(name)
        expected = table_cells(ref)
        assert cells == expected, f"{name}: {page} {cells} against the reference {expected}"
