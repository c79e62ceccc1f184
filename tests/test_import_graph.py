"""The package's import graph, read from the source with ``ast`` (imports at any depth, function-level ones
included): no cycle, no arrow from ``models/`` up or from ``fmus/`` to ``orchestrator/``, and a function-level
import only where it defers a heavy library."""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

import pytest

import sblsim.fmus
import sblsim.models
import sblsim.orchestrator

PACKAGES = {"sblsim.models": sblsim.models, "sblsim.fmus": sblsim.fmus, "sblsim.orchestrator": sblsim.orchestrator}
#: Which layers a layer may import (besides itself): models at the bottom, then fmus, then the orchestrator.
MAY_IMPORT = {"sblsim.models": set(), "sblsim.fmus": {"sblsim.models"},
              "sblsim.orchestrator": {"sblsim.models", "sblsim.fmus"}}
#: Libraries heavy enough to import only when used (seconds, or a process's worth of threads; scipy.integrate: half a
#: second of every command's start-up, scipy.optimize a third; casadi: what
#: ``import sblsim`` must not load): a function-level import is allowed where it defers one of these, directly or
#: through the sblsim module it imports.
HEAVY = ("matplotlib", "statsmodels", "dask", "distributed", "fmpy", "pyarrow", "pandas", "scipy.stats", "pyDOE3",
         "casadi", "scipy.integrate", "scipy.optimize", "pyproj", "mpl_toolkits", "openpyxl", "xlrd",
         # pyarrow's dataset and Parquet: a gigabyte of address space reserved at import (pyarrow and pandas: a third
         # of one), which a reader under a memory limit runs out of (tests/orchestrator/test_reader_memory.py)
         "pyarrow.dataset", "pyarrow.parquet")
#: Function-level imports that defer nothing heavy but ask whether an optional package is installed.
PROBES = {"ziglang"}


def _modules() -> dict[str, Path]:
    """Every module of the three packages: dotted name -> source file."""
    found = {}
    for name, package in PACKAGES.items():
        root = Path(package.__file__).parent
        for path in sorted(root.rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join([name, *parts])] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, int, bool]]:
    """Every import of a module: (imported module, line, at function level). ``from package import submodule``
    is an import of the submodule; relative imports are resolved."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []

    def visit(node: ast.AST, nested: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if _type_checking(child):  # never runs: the body's imports are for the type checker only
                visit(ast.Module(body=child.orelse, type_ignores=[]), nested)
                continue
            inner = nested or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                found.extend((alias.name, child.lineno, nested) for alias in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    parts = package.split(".")[:len(package.split(".")) - child.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                for alias in child.names:
                    sub = f"{base}.{alias.name}"
                    found.append((sub if sub in MODULES else base, child.lineno, nested))
            visit(child, inner)

    visit(ast.parse(path.read_text(encoding="utf-8")), False)
    return found


def _type_checking(node: ast.AST) -> bool:
    """``if TYPE_CHECKING:`` (or ``typing.TYPE_CHECKING``)."""
    if not isinstance(node, ast.If):
        return False
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


class _Imports(Mapping):
    """Every module's imports (:func:`_imports`), read when first asked for: every worker of the suite collects this
    file, one runs its tests."""

    @functools.cached_property
    def _read(self) -> dict[str, list[tuple[str, int, bool]]]:
        return {name: _imports(name, path) for name, path in MODULES.items()}

    def __getitem__(self, name: str) -> list[tuple[str, int, bool]]:
        return self._read[name]

    def __iter__(self):
        return iter(self._read)

    def __len__(self) -> int:
        return len(self._read)


IMPORTS = _Imports()


def _own(module: str) -> str | None:
    """The package module an imported name belongs to (its longest known prefix), or None (not sblsim's)."""
    while module and module not in MODULES:
        module = module.rpartition(".")[0]
    return module or None


def _graph(read: dict[str, list[tuple[str, int, bool]]] | None = None) -> dict[str, set[str]]:
    """The arrows between the package's modules, of :data:`IMPORTS` or of the imports ``read``."""
    graph = {name: set() for name in MODULES}
    for name, imports in (IMPORTS if read is None else read).items():
        for module, _, _ in imports:
            target = _own(module)
            if target and target != name:
                graph[name].add(target)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle through each strongly connected component of more than one module (Tarjan), as a path."""
    index, low, stack, on_stack, components = {}, {}, [], set(), []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(component)

    for v in sorted(graph):
        if v not in index:
            connect(v)
    cycles = []
    for component in components:  # a shortest way back to the start, inside the component
        start = min(component)
        paths, seen = [[start]], {start}
        while paths:
            path = paths.pop(0)
            nxt = sorted(graph[path[-1]] & component)
            if start in nxt:
                cycles.append(path + [start])
                break
            for w in nxt:
                if w not in seen:
                    seen.add(w)
                    paths.append(path + [w])
    return cycles


def _layer(module: str) -> str:
    return ".".join(module.split(".")[:2])


@pytest.mark.slow
def test_the_graph_is_read():
    """The reader finds the package's modules and known arrows, function-level ones included."""
    assert len(MODULES) > 60
    graph = _graph()
    assert "sblsim.orchestrator.cosim.config" in graph["sblsim.orchestrator.cosim.run"]
    assert "sblsim.models.receiver.kalman" in graph["sblsim.models.bound"]  # from package import submodule
    lazy = [(m, line) for m, line, nested in IMPORTS["sblsim.orchestrator.commands.run"] if nested and _own(m)]
    assert ("sblsim.orchestrator.cosim.run" in {m for m, _ in lazy}) and all(line > 0 for _, line in lazy)


def test_imports_for_the_type_checker_are_not_read(tmp_path):
    """``if TYPE_CHECKING:`` imports never run (no arrow, nothing loaded); its ``else`` does."""
    source = tmp_path / "m.py"
    source.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pandas\nelse:\n    import json\n"
                      "def f():\n    import csv\n")
    assert [(m, nested) for m, _, nested in _imports("x.m", source)] == [
        ("typing", False), ("json", False), ("csv", True)]


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}}
    assert _cycles(graph) == [["a", "b", "c", "a"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle():
    cycles = _cycles(_graph())
    for cycle in cycles:
        print("import cycle:", " -> ".join(cycle))
    assert cycles == [], "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_no_arrow_from_a_lower_layer_up():
    """models/ imports nothing of fmus/ or orchestrator/; fmus/ nothing of orchestrator/ (at any depth)."""
    wrong = sorted((name, module, line) for name, imports in IMPORTS.items() for module, line, _ in imports
                   if _own(module) and _layer(_own(module)) != _layer(name)
                   and _layer(_own(module)) not in MAY_IMPORT[_layer(name)])
    for name, module, line in wrong:
        print(f"{MODULES[name]}:{line}: {name} imports {module}")
    assert wrong == []


#: The orchestrator's own layers, bottom up, and what each may import besides itself: io (what every command reads
#: and writes) knows no run, no system and no FMU; cosim (the co-simulation kernel) knows no command.
ORCHESTRATOR_LAYERS = {"sblsim.orchestrator.io": {"sblsim.models"},
                       "sblsim.orchestrator.cosim": {"sblsim.models", "sblsim.fmus", "sblsim.orchestrator.io"}}


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


@pytest.mark.parametrize("layer", list(ORCHESTRATOR_LAYERS))
def test_an_orchestrator_layer_imports_only_the_layers_below_it(layer):
    inside = [name for name in MODULES if _in(name, layer)]
    assert len(inside) >= 7
    allowed = {layer, *ORCHESTRATOR_LAYERS[layer]}
    wrong = sorted((name, module, line) for name in inside for module, line, _ in IMPORTS[name]
                   if _own(module) and not any(_in(_own(module), package) for package in allowed))
    for name, module, line in wrong:
        print(f"{MODULES[name]}:{line}: {name} imports {module}")
    assert wrong == []


#: A study's pipeline, upstream first: the readers (every file a user brings) -> the clocks (sync) -> the tracks ->
#: the study (telemetry). A room imports only the rooms before it here (and anything outside the pipeline it may).
PIPELINE = tuple(f"sblsim.orchestrator.{room}" for room in ("readers", "sync", "tracks", "telemetry"))


def _pipeline_wrong(read: dict[str, list[tuple[str, int, bool]]]) -> list[tuple[str, str, int]]:
    """The arrows (at any depth) from a room of :data:`PIPELINE` to a room after it."""
    wrong = []
    for k, room in enumerate(PIPELINE):
        later = PIPELINE[k + 1:]
        for name in (n for n in read if _in(n, room)):
            for module, line, _ in read[name]:
                own = _own(module)
                if own and any(_in(own, other) for other in later):
                    wrong.append((name, own, line))
    return sorted(wrong)


def test_the_study_pipeline_runs_one_way():
    """readers -> sync -> tracks -> telemetry: no arrow back (the readers know no clock, the clocks no tracker)."""
    wrong = _pipeline_wrong(IMPORTS)
    for name, module, line in wrong:
        print(f"{MODULES[name]}:{line}: {name} imports {module}")
    assert wrong == []
    assert len([n for n in MODULES if _in(n, PIPELINE[0])]) >= 20  # the readers are one room


def test_the_pipeline_rule_can_fail():
    """An arrow from the readers to the clocks, or from the clocks to the tracker, is seen."""
    read = {"sblsim.orchestrator.readers.vue": [("sblsim.orchestrator.sync.run", 3, False)],
            "sblsim.orchestrator.sync.run": [("sblsim.orchestrator.tracks.tracker", 5, True),
                                             ("sblsim.orchestrator.readers.cells", 6, False)]}
    assert _pipeline_wrong(read) == [("sblsim.orchestrator.readers.vue", "sblsim.orchestrator.sync.run", 3),
                                     ("sblsim.orchestrator.sync.run", "sblsim.orchestrator.tracks.tracker", 5)]


#: The commands (orchestrator/commands/: one module per command, its function, result, arguments and main), the
#: modules they share, and the one command that runs another (campaign's --analyze and CampaignResult.analyze).
COMMANDS = "sblsim.orchestrator.commands"
SHARED = {COMMANDS, f"{COMMANDS}.common", f"{COMMANDS}.console"}
RUNS_ANOTHER = {(f"{COMMANDS}.campaign", f"{COMMANDS}.analyze")}


def _commands() -> list[str]:
    return [name for name in MODULES if _in(name, COMMANDS) and name not in SHARED]


def test_a_command_imports_no_other_command():
    """A command's module imports no other command's (the stated exception aside), and what the commands share
    imports none (the package's table registers them all)."""
    commands = _commands()
    assert len(commands) >= 11
    importers = commands + sorted(SHARED - {COMMANDS})
    wrong = sorted((name, own, line) for name in importers for module, line, _ in IMPORTS[name]
                   if (own := _own(module)) in commands and own != name and (name, own) not in RUNS_ANOTHER)
    for name, module, line in wrong:
        print(f"{MODULES[name]}:{line}: {name} imports {module}")
    assert wrong == []


def test_only_the_api_and_the_cli_import_the_commands():
    """The commands are the top of the orchestrator: the kernel, io and the modules that do a command's work
    import none of them (the package's public face reaches them through the API)."""
    above = {"sblsim.orchestrator.api", "sblsim.orchestrator.cli"}
    wrong = sorted((name, module, line) for name in MODULES if not _in(name, COMMANDS) and name not in above
                   for module, line, _ in IMPORTS[name] if _own(module) and _in(_own(module), COMMANDS))
    for name, module, line in wrong:
        print(f"{MODULES[name]}:{line}: {name} imports {module}")
    assert wrong == []


def test_the_command_rules_can_fail():
    """The checks above see the arrows they forbid: campaign's import of analyze is one."""
    campaign = {_own(module) for module, _, _ in IMPORTS[f"{COMMANDS}.campaign"]}
    assert f"{COMMANDS}.analyze" in campaign and f"{COMMANDS}.common" in campaign
    assert {f"{COMMANDS}.run", f"{COMMANDS}.map"} <= {_own(m) for m, _, _ in IMPORTS["sblsim.orchestrator.api"]}


#: The calibration package (models/calibration/), bottom up: each module imports only the modules before it here
#: (its ``__init__`` re-exports them and none imports it), nothing of the orchestrator or of fmus/, so that no import
#: circle can form inside it.
CALIBRATION = "sblsim.models.calibration"
CALIBRATION_ORDER = tuple(f"{CALIBRATION}.{name}" for name in (
    "determination", "perturbation", "legs", "replies", "measurement", "ocean", "leastsquares", "selection", "bound",
    "kalman", "combination", "boxin"))


def _calibration_wrong(read: dict[str, list[tuple[str, int, bool]]]) -> list[tuple[str, str, int]]:
    """The calibration modules' arrows (at any depth) to the orchestrator or fmus/, to the package's ``__init__``,
    or to a module of the package not before the importer in :data:`CALIBRATION_ORDER`."""
    wrong = []
    for k, name in enumerate(CALIBRATION_ORDER):
        for module, line, _ in read[name]:
            own = _own(module)
            if own is None or own == name:
                continue
            up = _in(own, "sblsim.orchestrator") or _in(own, "sblsim.fmus")
            if up or (_in(own, CALIBRATION) and own not in CALIBRATION_ORDER[:k]):
                wrong.append((name, own, line))
    return wrong


def test_the_calibration_package_lists_every_module_in_its_order():
    inside = {name for name in MODULES if _in(name, CALIBRATION)}
    assert inside == {CALIBRATION, *CALIBRATION_ORDER}


def test_the_calibration_package_imports_no_orchestrator_or_fmus_and_reads_bottom_up():
    wrong = _calibration_wrong(IMPORTS)
    for name, module, line in wrong:
        print(f"{MODULES[name]}:{line}: {name} imports {module}")
    assert wrong == []
    inside = {name for name in MODULES if _in(name, CALIBRATION)}
    graph = _graph()
    assert _cycles({name: graph[name] & inside for name in inside}) == []
    assert f"{CALIBRATION}.ocean" in graph[f"{CALIBRATION}.leastsquares"]  # the arrows are read


def test_the_calibration_rules_can_fail(tmp_path):
    """A calibration module importing the orchestrator, fmus/, the package's face or a module above it is caught,
    and an arrow back up the order is a circle the cycle finder prints."""
    source = tmp_path / "legs.py"
    source.write_text("from sblsim.orchestrator.surveys import calibrate\n"
                      "from sblsim.models.calibration import solve\n"
                      "def f():\n"
                      "    import sblsim.fmus.native\n"
                      "    from sblsim.models.calibration.ocean import _Design\n")
    legs = f"{CALIBRATION}.legs"
    read = {**IMPORTS, legs: IMPORTS[legs] + _imports(legs, source)}
    assert sorted((own, line) for name, own, line in _calibration_wrong(read) if name == legs) == [
        ("sblsim.fmus.native", 4), (CALIBRATION, 2), (f"{CALIBRATION}.ocean", 5),
        ("sblsim.orchestrator.surveys.calibrate", 1)]
    inside = {name for name in MODULES if _in(name, CALIBRATION)}
    graph = _graph(read)
    cycles = _cycles({name: graph[name] & inside for name in inside})
    assert cycles and all(legs in cycle for cycle in cycles)


def _heavy_at_load(name: str, seen: set[str] | None = None) -> set[str]:
    """The heavy libraries importing ``name`` loads: its module-level imports and theirs (sblsim's)."""
    seen = set() if seen is None else seen
    if name in seen:
        return set()
    seen.add(name)
    heavy = set()
    for module, _, nested in IMPORTS[name]:
        if nested:
            continue
        own = _own(module)
        if own:
            heavy |= _heavy_at_load(own, seen)
        else:
            heavy |= {h for h in HEAVY if module == h or module.startswith(h + ".")}
    return heavy


@pytest.mark.parametrize("name", sorted(MODULES))
def test_a_function_level_import_defers_a_heavy_library(name):
    """Inside a function, a module imports only what would load a heavy library it does not load already
    (:data:`HEAVY`) or probes an optional package: no function-level import hides a cycle."""
    loaded = _heavy_at_load(name)
    wrong = []
    for module, line, nested in IMPORTS[name]:
        if not nested or module.split(".")[0] in PROBES:
            continue
        own = _own(module)
        deferred = _heavy_at_load(own) if own else {h for h in HEAVY if module == h or module.startswith(h + ".")}
        if not deferred - loaded:
            wrong.append(f"{MODULES[name].name}:{line}: import {module} (defers nothing heavy)")
    assert wrong == []


def test_the_function_level_check_can_fail():
    """A module-level library is not heavy where its importer loads it already; a light one never is."""
    assert "pyarrow" in _heavy_at_load("sblsim.orchestrator.campaign.merge")
    assert _heavy_at_load("sblsim.models.declarations") == set()
    assert "matplotlib" in _heavy_at_load("sblsim.orchestrator.io.plots")
    assert not _heavy_at_load("sblsim.orchestrator.cli") & {"pandas", "scipy.stats", "matplotlib", "scipy.integrate",
                                                                  "scipy.optimize"}


def test_a_campaign_worker_loads_no_statistics_or_plotting():
    """A campaign's worker process starts by importing its worker module: nothing of scipy.stats, pyDOE3 (which
    imports it) or matplotlib, seconds of start-up that the chunks never use (the study's design is made by the
    campaign's process)."""
    assert not _heavy_at_load("sblsim.orchestrator.campaign.worker") & {"scipy.stats", "pyDOE3", "matplotlib"}
    assert "pyDOE3" in {m for m, _, nested in IMPORTS["sblsim.orchestrator.campaign.factorial"] if nested}


def test_the_command_line_loads_no_heavy_library_at_start():
    """What ``sblsim --help`` loads, in a fresh interpreter (the static check above reads each module's own imports,
    not the packages above an imported module, whose ``__init__`` runs first: a command importing
    ``campaign.study`` at load once pulled in pandas through ``campaign/__init__.py``)."""
    loaded = subprocess.run(
        [sys.executable, "-c", "import sys; import sblsim.orchestrator.cli; "
                               "print(sorted({m.split('.')[0] for m in sys.modules}))"],
        capture_output=True, text=True, check=True).stdout
    assert not {"pandas", "matplotlib", "statsmodels", "dask", "pyarrow", "scipy"} & set(ast.literal_eval(loaded))
