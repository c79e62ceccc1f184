"""A design's work (orchestrator/design/): the problem resolved, its candidates, a design's slot period, its
judgement, the search of a candidate, the search of all and the whole problem worked to its outputs; a telemetry
array's tag, problem, judgement and search beside them: each a module of one job, read bottom up, none a chapter."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import sblsim.orchestrator.design as design
from tests.module_order import out_of_order, top_level_definitions
from tests.module_order import sources as module_sources

PACKAGE = "sblsim.orchestrator.design"
#: Bottom up: each module imports only the ones before it here (of these).
ORDER = ("resolution", "candidates", "slot_period", "judgement", "searcher", "run", "telemetry_tag", "telemetry",
         "telemetry_judgement", "telemetry_search", "telemetry_confirm", "telemetry_output", "solve")
ROOT = Path(design.__file__).parent
SOURCES = module_sources(ROOT, ORDER)


def _spelled_out(source: str) -> str:
    """The source with ``from PACKAGE import a, b`` added as ``from PACKAGE.a import *`` lines, so that the order
    rule sees a module imported by its package's name."""
    extra = [f"from {PACKAGE}.{alias.name} import *" for node in ast.walk(ast.parse(source))
             if isinstance(node, ast.ImportFrom) and node.module == PACKAGE for alias in node.names]
    return "\n".join([source, *extra])


def _wrong(sources: dict[str, str]) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: one of ``ORDER`` not before the importer."""
    return out_of_order({name: _spelled_out(text) for name, text in sources.items()}, ORDER, PACKAGE)


def test_each_module_imports_only_the_modules_before_it():
    assert _wrong(SOURCES) == []


def test_the_order_rule_can_fail():
    bad = dict(SOURCES)
    bad["resolution"] += f"\nfrom {PACKAGE}.run import search_all\n"
    bad["telemetry"] += f"\nfrom {PACKAGE} import telemetry_search\n"
    assert _wrong(bad) == [("resolution", f"{PACKAGE}.run"), ("telemetry", f"{PACKAGE}.telemetry_search")]


@pytest.mark.parametrize("name", ORDER)
def test_no_module_is_a_chapter(name):
    assert len(SOURCES[name].splitlines()) <= 450


def test_each_job_is_in_its_module():
    assert {"resolve", "room", "plan_of"} <= top_level_definitions(SOURCES["resolution"])
    assert {"Candidate", "candidates"} <= top_level_definitions(SOURCES["candidates"])
    assert {"Design", "shortfalls", "ranked", "pareto_front"} <= top_level_definitions(SOURCES["judgement"])
    assert "search_all" in top_level_definitions(SOURCES["run"])
    assert "Searcher" in top_level_definitions(SOURCES["searcher"])
    assert {"Tag", "tag_of"} == top_level_definitions(SOURCES["telemetry_tag"])
    assert {"judge", "fixed_pings"} <= top_level_definitions(SOURCES["telemetry_judgement"])
    assert {"search_all", "search_count", "estimate"} <= top_level_definitions(SOURCES["telemetry_search"])
    assert top_level_definitions(SOURCES["solve"]) == {"solve", "solve_telemetry"}
