"""The variable tables of the FMUs, generated from the declarations (docs/variables.md)."""

from __future__ import annotations

from tabulate import tabulate

from sblsim.models import MODELS
from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import lane_of

BEGIN, END = "<!-- fmu-variables:begin -->", "<!-- fmu-variables:end -->"


def markdown_tables(n_beacons: int = 4) -> str:
    """One Markdown table per FMU: every variable with causality, variability, type, unit, start and description.

    The columns of a table parameter are one row each (``waypoint_time[1..512]``); the fields of the later lanes
    of a delivery one row each for all lanes (``lane<m>_packet_seq (m = 2…8)``); an input's description ends with
    its allowed range.

    Returns
    -------
    str
        The tables, between the :data:`BEGIN` and :data:`END` markers.
    """
    parts = [BEGIN, f"{len(MODELS)} FMUs: " + ", ".join(f"`sblsim_{name}.fmu`" for name in MODELS) + ".", ""]
    for name, model in MODELS.items():
        doc = (model.__doc__ or "").strip().splitlines()[0]
        rows = []
        for v in model.fmu_variables(n_beacons):
            if v.in_table:
                continue
            lane = lane_of(v.name)
            if lane and lane[0] > 2:
                continue  # the lanes of a delivery: one row for all, lane 2's
            description = v.fmi_description()
            if v.causality == "input" and v.fmi_type != "Boolean":  # the FMU refuses a value outside the range
                description += f", allowed {v.allowed()}"
            shown = f"`lane<m>_{lane[1]}` (m = 2…{LANES})" if lane else f"`{v.name}`"
            if lane:
                description = description.replace("Lane 2 ", "Lane m ", 1)
            rows.append((shown, v.causality, v.variability, v.fmi_type, v.unit, _start(v), description))
            if v.table is not None:
                rows += [(f"`{c.name}[1..{v.table.max_rows}]`", "parameter", "fixed", "Real", c.unit, _number(c.start),
                          f"{c.description} (rows 1..{v.name} are used), allowed {c.allowed()}")
                         for c in v.table.columns]
        parts += [f"**`sblsim_{name}.fmu`** — {doc}", "",
                  tabulate(rows, headers=("Variable", "Causality", "Variability", "Type", "Unit", "Start",
                                          "Description"), tablefmt="github"), ""]
    parts.append(END)
    return "\n".join(parts)


def _number(value) -> str:
    return f"{value:g}"


def _start(v) -> str:
    if v.fmi_type == "Boolean":
        return "true" if v.start else "false"
    return _number(v.fmi_start)


__all__ = ["BEGIN", "END", "markdown_tables"]
