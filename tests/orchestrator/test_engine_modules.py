"""The engines (orchestrator/cosim/): the handles' interface, one module per engine, the FMU files and the choice of
the engine per component, each a module of one job, read bottom up, none a chapter."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import sblsim.orchestrator.cosim as cosim
from tests.module_order import out_of_order
from tests.module_order import sources as module_sources

PACKAGE = "sblsim.orchestrator.cosim"
#: Bottom up: each module imports only the ones before it here (of these).
ORDER = ("handles", "local_engine", "fmu_files", "fmu_engine", "fmu3_engine", "engines")
ROOT = Path(cosim.__file__).parent
SOURCES = module_sources(ROOT, ORDER)


def _wrong(sources: dict[str, str]) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: one of ``ORDER`` not before the importer."""
    return out_of_order(sources, ORDER, PACKAGE)


def _classes(source: str) -> set[str]:
    return {node.name for node in ast.parse(source).body if isinstance(node, ast.ClassDef)}


def test_each_module_imports_only_the_modules_before_it():
    assert _wrong(SOURCES) == []


def test_the_order_rule_can_fail():
    bad = dict(SOURCES)
    bad["handles"] += f"\nfrom {PACKAGE}.engines import ENGINES\n"
    bad["local_engine"] += f"\nfrom {PACKAGE}.fmu_engine import FmuHandle\n"
    assert _wrong(bad) == [("handles", f"{PACKAGE}.engines"), ("local_engine", f"{PACKAGE}.fmu_engine")]


@pytest.mark.parametrize("name", ORDER)
def test_no_module_is_a_chapter(name):
    assert len(SOURCES[name].splitlines()) <= 400


def test_one_engine_a_module():
    assert {name: _classes(SOURCES[name]) for name in ("local_engine", "fmu_engine", "fmu3_engine")} == {
        "local_engine": {"LocalHandle"}, "fmu_engine": {"FmuHandle"}, "fmu3_engine": {"Fmu3Handle"}}
    assert _classes(SOURCES["engines"]) == set()  # the choice of the engine defines no handle
