"""The picture of the house on docs/architecture.md: sblsim's floors, their rooms and the imports between them.

Read from the installed package's source with :mod:`ast` (every import, those inside functions too), so the picture
is the code's as it stands: each module is put on its floor (:data:`FLOORS`, top to bottom), each folder of a floor is
a room (a box: its modules and lines), and every import from one floor to another is counted. An import that goes
up a floor would be drawn in red and printed; ``tests/test_import_graph.py`` fails on one.

Usage: ``python docs/floors.py [FIGURE.png]`` prints the floors' table and, with a file name, draws the picture.
"""

from __future__ import annotations

import ast
import sys
from collections import Counter
from pathlib import Path

import sblsim
import sblsim.fmus
import sblsim.models
import sblsim.orchestrator

#: The floors, top to bottom: a floor's name and the module-name prefixes on it (the first prefix that matches wins).
FLOORS = (
    ("the API and the command line", ("sblsim", "sblsim.orchestrator.api", "sblsim.orchestrator.cli")),
    ("commands", ("sblsim.orchestrator.commands",)),
    ("the commands' work", ("sblsim.orchestrator.",)),
    ("the co-simulation kernel", ("sblsim.orchestrator.cosim",)),
    ("input and output", ("sblsim.orchestrator.io",)),
    ("the FMU build", ("sblsim.fmus",)),
    ("the model", ("sblsim.models",)),
)


def modules() -> dict[str, Path]:
    """Every module of the installed package: dotted name -> source file (the API's is ``sblsim``)."""
    root = Path(sblsim.__file__).parent
    folders = {"sblsim": root, **{package.__name__: Path(package.__file__).parent
                                  for package in (sblsim.models, sblsim.orchestrator, sblsim.fmus)}}
    found = {}
    for name, folder in folders.items():
        for path in sorted(folder.rglob("*.py")):
            if name == "sblsim" and path.parent != root:
                continue
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            dotted = ".".join([name, *parts])
            if dotted != "sblsim.orchestrator.toplevel":  # the API's own source, installed as sblsim
                found[dotted] = path
    return found


def floor_of(name: str) -> int:
    """The floor of a module, 0 the top (:data:`FLOORS`); the most specific prefix wins."""
    best, length = len(FLOORS), -1
    for index, (_, prefixes) in enumerate(FLOORS):
        for prefix in prefixes:
            if (name == prefix or name.startswith(prefix if prefix.endswith(".") else prefix + ".")) \
                    and len(prefix) > length:
                best, length = index, len(prefix)
    if best == len(FLOORS):
        raise ValueError(f"module {name}: on no floor of FLOORS")
    return best


def room_of(name: str, path: Path) -> str:
    """A module's room: the folder below its top package it lives in (``tracks``, ``sync``, ...), or ``PACKAGE/*.py``
    for a module at the root of ``models``, ``orchestrator`` or ``fmus``."""
    for package in ("sblsim.orchestrator", "sblsim.models", "sblsim.fmus"):
        if name == package:  # the package's own __init__
            return package.rpartition(".")[2] + "/*.py"
        if name.startswith(package + "."):
            rest = name[len(package) + 1:].split(".")
            return rest[0] if len(rest) > 1 or path.name == "__init__.py" else package.rpartition(".")[2] + "/*.py"
    return name.rpartition(".")[2]


def imports(name: str, path: Path, known: dict[str, Path]) -> list[str]:
    """The package's modules that ``name`` imports (relative imports resolved; ``from package import module`` is an
    import of the module)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            found.extend(f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names)
    return [target for target in found if target in known and target != name]


def house() -> tuple[dict[int, dict[str, tuple[int, int]]], Counter]:
    """The floors' rooms and the imports between floors: ({floor: {room: (modules, lines)}},
    Counter{(from floor, to floor): imports})."""
    known = modules()
    rooms: dict[int, dict[str, list[int]]] = {index: {} for index in range(len(FLOORS))}
    arrows: Counter = Counter()
    for name, path in known.items():
        floor = floor_of(name)
        counts = rooms[floor].setdefault(room_of(name, path), [0, 0])
        counts[0] += 1
        counts[1] += len(path.read_text(encoding="utf-8").splitlines())
        for target in imports(name, path, known):
            if floor_of(target) != floor:
                arrows[(floor, floor_of(target))] += 1
    return {floor: {room: tuple(n) for room, n in sorted(found.items())} for floor, found in rooms.items()}, arrows


def table(rooms: dict[int, dict[str, tuple[int, int]]], arrows: Counter) -> str:
    """The floors as text: their rooms, modules and imports up (none in a sound house); the lines and the imports
    down, which every change moves, are the picture's."""
    lines = []
    for floor, (title, _) in enumerate(FLOORS):
        found = rooms[floor]
        up = sum(n for (a, b), n in arrows.items() if a == floor and b < floor)
        plural = "" if len(found) == 1 else "s"
        lines.append(f"{title}: {len(found)} room{plural} ({', '.join(found)}), "
                     f"{sum(m for m, _ in found.values())} modules; {up} imports up")
    return "\n".join(lines)


def draw(rooms: dict[int, dict[str, tuple[int, int]]], arrows: Counter, figure: Path) -> None:
    """The floors as bands of rooms, the imports between floors as arrows on the right (red if one goes up)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    count = len(FLOORS)
    fig, ax = plt.subplots(figsize=(13, 1.15 * count + 0.6))
    width = 10.0
    for floor, (title, _) in enumerate(FLOORS):
        y = count - 1 - floor
        found = rooms[floor]
        ax.text(-0.1, y + 0.45, title, ha="right", va="center", fontsize=9, weight="bold")
        step = width / max(len(found), 1)
        for k, (room, (n_modules, n_lines)) in enumerate(found.items()):
            ax.add_patch(plt.Rectangle((k * step + 0.03, y + 0.1), step - 0.06, 0.7, facecolor="#dde8f3",
                                       edgecolor="#3b6e9c"))
            size = 7 if len(found) < 12 else 5.5
            ax.text(k * step + step / 2, y + 0.45, f"{room}\n{n_modules} m, {n_lines} l", ha="center", va="center",
                    fontsize=size)
    for i, ((a, b), n) in enumerate(sorted(arrows.items())):
        x = width + 0.4 + 0.32 * i
        ya, yb = count - 1 - a + 0.45, count - 1 - b + 0.45
        colour = "#c0392b" if b < a else "#555555"
        ax.annotate("", xy=(x, yb), xytext=(x, ya), arrowprops=dict(arrowstyle="->", color=colour, lw=0.8))
        ax.text(x, (ya + yb) / 2, str(n), rotation=90, ha="center", va="center", fontsize=5.5,
                backgroundcolor="white")
    ax.set_xlim(-3.2, width + 0.6 + 0.32 * len(arrows))
    ax.set_ylim(-0.1, count)
    ax.axis("off")
    ax.set_title("sblsim's floors (top: what a user calls; bottom: the model); rooms: modules (m), lines (l); "
                 "arrows: imports between floors, none up", fontsize=9)
    fig.tight_layout()
    fig.savefig(figure, dpi=130)
    plt.close(fig)


def main(argv: list[str]) -> int:
    rooms, arrows = house()
    print(table(rooms, arrows))
    if argv:
        draw(rooms, arrows, Path(argv[0]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
