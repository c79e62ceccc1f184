"""The variable tables of the FMUs, generated from the core declarations (for the README)."""

from __future__ import annotations

from tabulate import tabulate

from models import CORES

BEGIN, END = "<!-- fmu-variables:begin -->", "<!-- fmu-variables:end -->"


def markdown_tables(n_beacons: int = 4) -> str:
    """One Markdown table per FMU: every variable with causality, type, unit, start and description.

    Returns
    -------
    str
        The tables, between the :data:`BEGIN` and :data:`END` markers.
    """
    parts = [BEGIN]
    for name, core in CORES.items():
        doc = (core.__doc__ or "").strip().splitlines()[0]
        rows = [(f"`{v.name}`", v.causality, v.type, v.unit, _start(v), v.description)
                for v in core.variables(n_beacons)]
        parts += [f"**`sblsim_{name}.fmu`** — {doc}", "",
                  tabulate(rows, headers=("Variable", "Causality", "Type", "Unit", "Start", "Description"),
                           tablefmt="github"), ""]
    parts.append(END)
    return "\n".join(parts)


def _start(v) -> str:
    if v.type == "String":
        return f'"{v.start}"'
    if v.type == "Boolean":
        return "true" if v.start else "false"
    return f"{v.start:g}"


__all__ = ["BEGIN", "END", "markdown_tables"]
