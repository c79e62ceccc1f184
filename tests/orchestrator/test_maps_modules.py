"""The accuracy maps (orchestrator/maps/): the grid and the diver's depth, what the site lets through, the offsets of
reflected arrivals, the accuracy at points and on a grid, a command's maps and their table, figure and files, each a
module of one job, read bottom up, none a chapter; the package re-exports their names."""

from __future__ import annotations

import ast
import importlib
import tomllib
from pathlib import Path

import numpy as np
import pytest

import sblsim.orchestrator.maps as maps
from tests.module_order import imported, out_of_order
from tests.module_order import sources as module_sources

PACKAGE = "sblsim.orchestrator.maps"
#: Bottom up: each module imports only the ones before it here (of these).
ORDER = ("map_grid", "detection", "echoes", "accuracy", "panels", "output")
ROOT = Path(maps.__file__).parent
SOURCES = module_sources(ROOT, ORDER)


def _wrong(sources: dict[str, str]) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: one of ``ORDER`` not before the importer, or the package."""
    return out_of_order(sources, ORDER, PACKAGE, face=True)


def test_the_package_holds_exactly_the_listed_modules():
    assert sorted(p.stem for p in ROOT.glob("*.py")) == sorted((*ORDER, "__init__"))


def test_each_module_imports_only_the_modules_before_it():
    assert _wrong(SOURCES) == []


def test_the_order_rule_can_fail():
    bad = dict(SOURCES)
    bad["map_grid"] += f"\nfrom {PACKAGE}.output import write\n"
    bad["echoes"] += f"\nfrom {PACKAGE} import grid\n"
    assert _wrong(bad) == [("echoes", PACKAGE), ("map_grid", f"{PACKAGE}.output")]


@pytest.mark.parametrize("name", ORDER)
def test_no_module_is_a_chapter(name):
    assert len(SOURCES[name].splitlines()) <= 400


def test_the_package_re_exports_the_modules_objects_and_defines_nothing():
    for name in maps.__all__:
        obj = getattr(maps, name)
        homes = [m for m in ORDER if name in vars(importlib.import_module(f"{PACKAGE}.{m}"))
                 and vars(importlib.import_module(f"{PACKAGE}.{m}"))[name] is obj]
        assert homes, name
    tree = ast.parse((ROOT / "__init__.py").read_text(encoding="utf-8"))
    assert [n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))] == []


def test_only_the_output_draws_and_only_the_computing_modules_read_the_site():
    drawing = [m for m in ORDER if any(i.startswith("matplotlib") for i in imported(SOURCES[m]))]
    assert drawing == ["output"]
    assert "staged_directory" in SOURCES["output"] and all("staged_directory" not in SOURCES[m] for m in ORDER[:-1])


def test_the_package_is_in_the_wheel_list():
    """A package missing from pyproject.toml's explicit ``packages`` is left out of the wheel."""
    pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"
    packages = tomllib.loads(pyproject.read_text(encoding="utf-8"))["tool"]["setuptools"]["packages"]
    assert PACKAGE in packages


def test_the_grid_points_are_north_major_at_the_given_depth():
    """The one name the split made public (``grid_points``): points (M, 3) NED, North varying slowest."""
    east, north = maps.grid(2.0, 1.0)
    points = maps.grid_points(None, east, north, 7.5)
    assert points.shape == (25, 3)
    assert np.array_equal(points[:5, 0], np.full(5, -2.0)) and np.array_equal(points[:5, 1], east)
    assert np.all(points[:, 2] == 7.5)
