"""A design problem (orchestrator/design/): its declared keys, its places as geometry, its detection curves, the keys'
checks together and the reading and checking of a file, each a module of one job, read bottom up, none a chapter."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import sblsim.orchestrator.design as design
from tests.module_order import out_of_order, top_level_definitions
from tests.module_order import sources as module_sources

PACKAGE = "sblsim.orchestrator.design"
#: Bottom up: each module imports only the ones before it here (of these).
ORDER = ("keys", "area", "curves", "checks", "problem")
ROOT = Path(design.__file__).parent
SOURCES = module_sources(ROOT, ORDER)


def _wrong(sources: dict[str, str]) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: one of ``ORDER`` not before the importer."""
    return out_of_order(sources, ORDER, PACKAGE)


def test_each_module_imports_only_the_modules_before_it():
    assert _wrong(SOURCES) == []


def test_the_order_rule_can_fail():
    bad = dict(SOURCES)
    bad["keys"] += f"\nfrom {PACKAGE}.problem import read_problem\n"
    bad["area"] += f"\nfrom {PACKAGE}.checks import is_telemetry\n"
    assert _wrong(bad) == [("area", f"{PACKAGE}.checks"), ("keys", f"{PACKAGE}.problem")]


@pytest.mark.parametrize("name", ORDER)
def test_no_module_is_a_chapter(name):
    assert len(SOURCES[name].splitlines()) <= 400


def test_the_reading_module_reads_and_checks_each_key_only():
    assert top_level_definitions(SOURCES["problem"]) == {"read_problem", "check_problem", "_value", "_checked",
                                              "_nested_sections"}
    declared = {node.target.id for node in ast.parse(SOURCES["keys"]).body if isinstance(node, ast.AnnAssign)}
    assert "DESIGN_KEYS" in declared  # the declarations live in keys
