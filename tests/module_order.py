"""The rules the structure tests of a split room share: a room's modules read bottom up, each importing only the
ones before it in a stated order (tests/models/test_channel_package.py, test_receiver_modules.py,
tests/orchestrator/test_config_modules.py, test_design_problem_modules.py, test_design_run_modules.py,
test_engine_modules.py, test_maps_modules.py), what each defines, and no module longer than a limit
(tests/test_module_sizes.py, tests/orchestrator/test_thin_commands.py)."""

from __future__ import annotations

import ast
from pathlib import Path


def sources(root: Path, order: tuple[str, ...]) -> dict[str, str]:
    """Each module's source text, by its name in ``order``, from the folder ``root``."""
    return {name: (root / f"{name}.py").read_text(encoding="utf-8") for name in order}


def imported(source: str) -> list[str]:
    """The modules a source imports (``import`` and ``from ... import``, at any depth)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module:
            found.append(node.module)
        elif isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
    return found


def out_of_order(texts: dict[str, str], order: tuple[str, ...], package: str, face: bool = False,
                 forbidden: tuple[str, ...] = ()) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: a module of ``order`` not before the importer, the package
    itself where ``face`` (its ``__init__`` re-exports them), or a module whose name starts with one of
    ``forbidden``."""
    wrong = []
    for k, name in enumerate(order):
        later = {f"{package}.{m}" for m in order[k:]} | ({package} if face else set())
        for module in imported(texts[name]):
            if module in later or (forbidden and module.startswith(forbidden)):
                wrong.append((name, module))
    return sorted(set(wrong))


def top_level_definitions(source: str) -> set[str]:
    """The functions and classes a module's own top-level statements define."""
    return {node.name for node in ast.parse(source).body if isinstance(node, (ast.FunctionDef, ast.ClassDef))}


def longer_than(folder: Path, limit: int, allowed: dict[str, int] | None = None) -> dict[str, int]:
    """Every ``.py`` file under ``folder`` with more lines than ``limit`` (or than its own cap in ``allowed``): its
    path relative to ``folder`` -> lines."""
    allowed = {} if allowed is None else allowed
    lines = {str(path.relative_to(folder)): len(path.read_text(encoding="utf-8").splitlines())
             for path in sorted(folder.rglob("*.py"))}
    return {name: n for name, n in lines.items() if n > allowed.get(name, limit)}


def top_level_names(source: str) -> set[str]:
    """The names a module's own top-level statements bind (functions, classes, assignments, unpacked ones
    included; not those it imports), ``__all__`` among them where it has one."""
    names = set()
    for node in ast.parse(source).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names |= {n.id for t in node.targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names
