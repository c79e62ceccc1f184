"""The acoustic channel's package (models/acoustics/channel/): one job per module, read bottom up, and the old
module ``sblsim.models.acoustics.core`` a re-export of the same objects only."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import sblsim.models.acoustics.channel as channel
import sblsim.models.acoustics.core as core
from tests.module_order import out_of_order
from tests.module_order import sources as module_sources

PACKAGE = "sblsim.models.acoustics.channel"
#: Bottom up: each module imports only the package's modules before it here (the package's docstring lists them in
#: this order).
ORDER = ("interface", "ocean", "site", "lanes", "pinger", "legs", "exchange", "toa", "component", "site_levels")
ROOT = Path(channel.__file__).parent


def _wrong(sources: dict[str, str]) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: a package module not before the importer, the package's face,
    the old ``core`` or anything of the orchestrator or fmus/."""
    return out_of_order(sources, ORDER, PACKAGE, face=True, forbidden=(
        "sblsim.orchestrator", "sblsim.fmus", "sblsim.models.acoustics.core"))


SOURCES = module_sources(ROOT, ORDER)


def test_the_package_holds_exactly_the_listed_modules():
    assert {p.stem for p in ROOT.glob("*.py")} == {"__init__", *ORDER}
    for name in ORDER:  # the package's face names every module
        assert f"{PACKAGE}.{name}`" in channel.__doc__


def test_each_module_imports_only_the_modules_before_it():
    assert _wrong(SOURCES) == []


def test_the_order_rule_can_fail():
    # the pinger importing the exchange (after it), the site the old core, a leg the package's face
    bad = dict(SOURCES)
    bad["pinger"] += f"\nfrom {PACKAGE}.exchange import _slot\n"
    bad["site"] += "\nfrom sblsim.models.acoustics.core import LANES\n"
    bad["legs"] += f"\nfrom {PACKAGE} import interface\n"
    assert _wrong(bad) == [("legs", PACKAGE), ("pinger", f"{PACKAGE}.exchange"),
                           ("site", "sblsim.models.acoustics.core")]


@pytest.mark.parametrize("name", ORDER)
def test_no_module_is_a_chapter(name):
    assert len(SOURCES[name].splitlines()) <= 400


def test_core_re_exports_the_channel_objects_and_defines_nothing():
    """Every public name of the old module is the very object of the channel module that defines it."""
    owners = [importlib.import_module(f"{PACKAGE}.{m}") for m in ORDER]
    for name in core.__all__:
        defining = [m for m in owners if name in vars(m) and _defines(m, name)]
        assert len(defining) == 1, name
        assert getattr(core, name) is getattr(defining[0], name)
    tree = ast.parse(Path(core.__file__).read_text(encoding="utf-8"))
    defined = [n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef, ast.AnnAssign))
               or (isinstance(n, ast.Assign) and n.targets[0].id != "__all__")]
    assert defined == []


def _defines(module, name: str) -> bool:
    """Whether ``module``'s source binds ``name`` at its top level (not by an import)."""
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and node.name == name:
            return True
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, ast.AnnAssign) else []
        if any(isinstance(n, ast.Name) and n.id == name for t in targets for n in ast.walk(t)):
            return True
    return False
