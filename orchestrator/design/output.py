"""What ``sblsim design`` writes: ``design.json``, ``designs.csv``, a scenario file per proposed design and figures.

* ``design.json``: the problem as resolved (``problem``), a one-line ``summary``, and ``designs``, the proposed
  designs best first (:func:`design_record`): each its ``name``, ``system``, ``cost``, ``meets``, ``scenario`` (its
  file), ``transponders_m`` (East, North, depth [m]; ``existing`` marks those in place, ``spread_m`` the largest
  distance between two where a footprint is given), ``grades``, ``predicted`` (the map's DRMS quantiles over the
  work area, ``coverage`` and ``availability``) and ``monte_carlo`` (the static vehicles' checks), ``path``;
* ``designs.csv``: every candidate searched, one row each (:data:`CSV_COLUMNS`), in the order of the ranking;
* ``NAME.toml`` per proposed design: its scenario, the base scenario's keys and the design's (``sblsim run``,
  ``map``, ``compare`` and ``fmus build --scenario`` take it as it is);
* ``layout.png`` (each proposed design on its accuracy map, with its transponders, the seafloor region, the areas
  to avoid and the Monte Carlo points), ``pareto.png`` (cost against the criterion of every candidate, the front)
  and ``convergence.png`` (the search's best criterion per generation).

All of it is written at once (:func:`~sblsim.orchestrator.io.output.staged_directory`): an interrupted or failed run
leaves ``--out`` as it was.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
import tomli_w

from sblsim.models.design.area import spread
from sblsim.models.design.criteria import CRITERIA, ECHO_LIMIT
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.config import apply_overrides, read_source
from sblsim.orchestrator.cosim.plan import thaw
from sblsim.orchestrator.design.judgement import Design, pareto_front, quantiles, ranked
from sblsim.orchestrator.design.keys import GRADES
from sblsim.orchestrator.design.resolution import plan_of
from sblsim.orchestrator.design.run import DesignRun
from sblsim.orchestrator.io.output import staged_directory

#: The columns of ``designs.csv``.
CSV_COLUMNS = ("rank", "name", "system", "count", *GRADES, "baseline_m", "cost", "criterion", "drms_p50_m",
               "drms_p95_m", "drms_max_m", "coverage", "availability", "echo", "meets", "fails", "cycle_s",
               "evaluated_by")
#: The files of a design's output folder (besides one ``NAME.toml`` per proposed design).
OUTPUT_FILES = ("design.json", "designs.csv", "layout.png", "pareto.png", "convergence.png")


def _finite(value: float) -> float | None:
    """A number for JSON: None where it is not finite (JSON has no inf or NaN)."""
    return float(value) if math.isfinite(value) else None


def predicted(design: Design, run: DesignRun) -> dict[str, Any]:
    """The map's numbers of a design over the work area: ``drms_p50_m``, ``drms_p95_m``, ``drms_max_m`` [m] (None
    where a point has no fix: an infinite DRMS), ``coverage`` (the share of points that meet the prescription),
    ``availability`` (the mean probability of a fix in one cycle) and ``echo`` (the share of points whose fix takes
    ranges of reflections in more than 1 % of the cycles, where the prediction does not hold), each [0–1]."""
    dimensions = run.resolved.sections["prescription"]["dimensions"]
    out = {k: _finite(v) for k, v in quantiles(design, dimensions).items()}
    out["coverage"] = design.coverage / 100.0
    out["availability"] = float(np.mean(design.values["availability"]))
    out["echo"] = float(np.mean(design.values["echo"] > ECHO_LIMIT))
    return out


def design_record(design: Design, run: DesignRun) -> dict[str, Any]:
    """One proposed design as ``design.json`` holds it (module docstring)."""
    c = design.candidate
    record = {"name": design.name, "system": c.system, "cost": c.cost, "meets": design.meets,
              "fails": [{k: (_finite(v) if isinstance(v, float) else v) for k, v in s.items()}
                        for s in design.shortfalls],
              "scenario": f"{design.name}.toml", "label": c.label}
    if design.transponders is not None:
        record["transponders_m"] = [[float(t[1]), float(t[0]), float(t[2])] for t in design.transponders]
        if c.kept:  # those in place (candidates.existing_m) first, kept where they are
            record["existing"] = [k < c.kept for k in range(len(design.transponders))]
        if run.resolved.footprint > 0.0:
            record["spread_m"] = float(spread(design.transponders[:, :2]))
    if design.baseline is not None:
        record["baseline_m"] = design.baseline
    record["grades"] = dict(c.grades)
    record["cycle_s"] = design.cycle
    record["criterion"] = {"name": run.resolved.sections["search"]["criterion"], "value": _finite(design.value)}
    record["predicted"] = predicted(design, run)
    record["evaluated_by"] = design.evaluated_by
    record["monte_carlo"] = [{k: (_finite(v) if isinstance(v, float) else v) for k, v in m.items()}
                             for m in design.monte_carlo]
    record["confirmed"] = bool(design.monte_carlo) and all(m["confirmed"] for m in design.monte_carlo)
    record["path"] = [{k: (_finite(v) if isinstance(v, float) else v) for k, v in p.items()} for p in design.path]
    return record


def summary(run: DesignRun) -> str:
    """The design's outcome in one line: the best design and whether it meets the prescription, or that none
    does and the best found."""
    p = run.resolved.sections["prescription"]
    best = run.best
    what = (f"{p['drms_m']:g} m {p['dimensions']} DRMS at {p['coverage_pct']:g} % of the work area with a fix in "
            f"{p['availability_pct']:g} % of the cycles"
            + (f" at least every {p['update_interval_s']:g} s" if p["update_interval_s"] else ""))
    found = (f"{best.candidate.label} (cost {best.candidate.cost:g}), covering {best.coverage:.1f} % "
             f"(DRMS p95 {quantiles(best, p['dimensions'])['drms_p95_m']:.3g} m)")
    checked = [m for m in best.monte_carlo]
    if checked:
        ratios = ", ".join(f"{m['ratio']:.2f} at the {m['point']} point" for m in checked)
        confirmed = all(m["confirmed"] for m in checked)
        found += f"; Monte Carlo / map {ratios}" + ("" if confirmed else " (NOT CONFIRMED within "
                                                   f"{run.resolved.sections['monte_carlo']['tolerance_pct']:g} %)")
    if best.meets:
        return f"{run.resolved.sections['design']['name']}: {what}: {found}"
    failed = "; ".join(s["text"] for s in best.shortfalls)
    return (f"{run.resolved.sections['design']['name']}: no candidate meets {what}; the best found: {found}; "
            f"what fails: {failed}")


def table(run: DesignRun) -> pd.DataFrame:
    """``designs.csv``: every candidate searched, ranked (:func:`~sblsim.orchestrator.design.judgement.ranked`: those
    that meet, cheapest first; then by coverage and by how much they miss, the cheapest of the near ones first), with
    the parts each fails (``fails``)."""
    dimensions = run.resolved.sections["prescription"]["dimensions"]
    proposed = {id(d): d.name for d in run.proposed}
    rows = []
    for k, d in enumerate(ranked(run.searched), start=1):
        c = d.candidate
        q = quantiles(d, dimensions)
        rows.append({"rank": k, "name": proposed.get(id(d), ""), "system": c.system, "count": c.count,
                     **{g: c.grades.get(g, "") for g in GRADES},
                     "baseline_m": d.baseline if d.baseline is not None else math.nan, "cost": c.cost,
                     "criterion": d.value, **q, "coverage": d.coverage / 100.0,
                     "availability": float(np.mean(d.values["availability"])),
                     "echo": float(np.mean(d.values["echo"] > ECHO_LIMIT)), "meets": d.meets,
                     "fails": "; ".join(s["part"] for s in d.shortfalls),
                     "cycle_s": d.cycle, "evaluated_by": d.evaluated_by})
    return pd.DataFrame(rows, columns=list(CSV_COLUMNS))


def scenario_text(design: Design, run: DesignRun) -> str:
    """A design's scenario as TOML: the base scenario's own keys with the problem's and the design's overrides
    applied, ``run.scenario`` the design's name (not the resolved configuration: what the scenario derives from its
    keys, such as the receiver's initial state from the trajectory, is derived again when the file is used, with
    the user's overrides)."""
    r = run.resolved
    raw = thaw(r.source) if isinstance(r.source, Mapping) else read_source(r.source)
    raw = apply_overrides(raw, [*r.items, *design.items])
    raw.setdefault("run", {})["scenario"] = design.name
    c = design.candidate
    header = (f"# {design.name}: {c.label}, cost {c.cost:g}, written by sblsim design from the problem "
              f"{r.sections['design']['name']!r} over the scenario {str(r.sections['design']['scenario'])!r}\n")
    return header + tomli_w.dumps({section: dict(table) for section, table in raw.items()})


def document(run: DesignRun, seconds: float | None = None, effort: Any = None) -> dict[str, Any]:
    """``design.json`` as a mapping (module docstring); ``effort`` the problem's
    :class:`~sblsim.orchestrator.design.effort.Estimate` (``search.estimate``)."""
    problem = json.loads(json.dumps(run.resolved.sections, default=str))
    problem["design"]["scenario"] = str(run.resolved.sections["design"]["scenario"])
    out = {"problem": problem, "summary": summary(run), "meets": run.best.meets,
           "designs": [design_record(d, run) for d in run.proposed],
           "search": {"candidates": len(run.searched), "layouts": sum(d.evaluations for d in run.searched),
                      "work_area_points": int(len(run.resolved.points)),
                      "criterion": run.resolved.sections["search"]["criterion"],
                      "criterion_meaning": CRITERIA[run.resolved.sections["search"]["criterion"]]}}
    if seconds is not None:
        out["search"]["seconds"] = round(seconds, 1)
    if effort is not None:
        out["search"]["estimate"] = {"candidates": effort.candidates, "layouts": effort.layouts,
                                     "runs": effort.runs, "seconds": round(effort.seconds, 1)}
    return out


def write(run: DesignRun, out: Path | str, seconds: float | None = None, effort: Any = None) -> Path:
    """Write the design's files into ``out`` at once (module docstring); return ``out``."""
    import matplotlib.pyplot as plt

    with staged_directory(out) as tmp:
        (tmp / "design.json").write_text(json.dumps(document(run, seconds, effort), indent=2, allow_nan=False) + "\n")
        table(run).to_csv(tmp / "designs.csv", index=False)
        for design in run.proposed:
            (tmp / f"{design.name}.toml").write_text(scenario_text(design, run))
        for name, figure in figures(run).items():
            figure.savefig(tmp / f"{name}.png", dpi=110, bbox_inches="tight")
            plt.close(figure)
    return Path(out)


def figures(run: DesignRun) -> dict[str, Any]:
    """The figures by name: ``layout``, ``pareto``, ``convergence`` (matplotlib figures)."""
    return {"layout": layout_figure(run), "pareto": pareto_figure(run), "convergence": convergence_figure(run)}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def layout_figure(run: DesignRun):
    """Each proposed design on its accuracy map over the work area (module docstring): a row of panels per
    work-area depth, the Monte Carlo points of that depth labelled inside the panel."""
    plt = _plt()
    r = run.resolved
    p = r.sections["prescription"]
    key = "drms" if p["dimensions"] == "horizontal" else "drms_3d"
    designs = run.proposed
    depths = list(r.depths)
    fig, axes = plt.subplots(len(depths), len(designs), figsize=(6.4 * len(designs), 6.4 * len(depths)),
                             squeeze=False, layout="constrained")
    for row_axes, depth in zip(axes, depths):
        rows = np.isclose(r.points[:, 2], depth)
        north, east = np.unique(r.points[rows, 0]), np.unique(r.points[rows, 1])
        for ax, design in zip(row_axes, designs):
            _layout_panel(ax, design, r, p, key, depth, rows, north, east, fig)
    return fig


def _layout_panel(ax, design, r, p, key, depth, rows, north, east, fig) -> None:
    """One design's accuracy map at one depth (:func:`layout_figure`)."""
    from matplotlib.colors import LogNorm

    v = design.values[key][rows]
    finite = v[np.isfinite(v)] if np.isfinite(v).any() else np.array([p["drms_m"]])
    low = max(float(finite.min()), 1e-4)
    norm = LogNorm(vmin=low, vmax=max(float(finite.max()), 1.01 * low))
    grid = np.full((len(north), len(east)), np.nan)
    grid[np.searchsorted(north, r.points[rows, 0]), np.searchsorted(east, r.points[rows, 1])] = v
    mesh = ax.pcolormesh(east, north, grid, norm=norm, cmap="viridis", shading="nearest")
    if np.isfinite(grid).sum() > 3 and np.nanmin(grid) < p["drms_m"] < np.nanmax(grid):
        lines = ax.contour(east, north, grid, levels=[p["drms_m"]], colors="w", linewidths=1.2)
        ax.clabel(lines, fmt=lambda x: f"{x:g} m", fontsize=8)
    for area, style in [(r.area, dict(color="k", lw=1.0, ls="-", label="work area"))] + (
            [(r.seafloor, dict(color="0.4", lw=1.0, ls="--", label="seafloor region"))]
            if design.candidate.layout == "seafloor" else []):
        outline = area.outline()
        ax.plot(outline[:, 1], outline[:, 0], **style)
    if design.candidate.layout == "seafloor":
        for k, a in enumerate(r.avoid):
            outline = a.outline()
            ax.fill(outline[:, 1], outline[:, 0], facecolor="none", edgecolor="r", hatch="//", lw=0.8,
                    label="avoid" if k == 0 else None)
    else:
        arms = np.asarray(plan_of(r, design.items).lever_arms)
        ax.plot(arms[:, 1], arms[:, 0], "r^", ms=6, label="transducers", zorder=4)
    middle = 0.5 * (float(east.min()) + float(east.max())) if len(east) else 0.0
    for m in design.monte_carlo:
        if not np.isclose(m["depth_m"], depth):
            continue
        right = m["east_m"] > middle  # a label towards the panel's middle, never past its edge
        ax.plot(m["east_m"], m["north_m"], "wo", mfc="none", ms=9, zorder=3)
        ax.annotate(f"{m['point']}: MC/map {m['ratio']:.2f}", (m["east_m"], m["north_m"]), color="w", fontsize=7,
                    xytext=(-6 if right else 6, 5), textcoords="offset points", ha="right" if right else "left")
    if design.candidate.layout == "seafloor":
        ax.plot(design.transponders[:, 1], design.transponders[:, 0], "r^", ms=9, mec="w", label="transponders",
                zorder=4)
        kept = design.transponders[:design.candidate.kept]
        if len(kept):
            ax.plot(kept[:, 1], kept[:, 0], "s", ms=13, mfc="none", mec="k", label="in place", zorder=5)
    ax.set_aspect("equal")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    verdict = "meets" if design.meets else "does not meet"
    ax.set_title(f"{design.name}\n{design.candidate.label}\ncost {design.candidate.cost:g}, {verdict} "
                 f"({design.coverage:.1f} % of the area), vehicle at {depth:g} m", fontsize=8)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=4, fontsize=7, frameon=False)
    fig.colorbar(mesh, ax=ax, shrink=0.8, label=f"{p['dimensions']} DRMS of one cycle [m]")


def pareto_figure(run: DesignRun):
    """Cost against the criterion of every candidate searched, by system; those that meet filled."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    criterion = run.resolved.sections["search"]["criterion"]
    markers = {"seafloor": "^", "platform": "s", "": "o"}
    for k, system in enumerate(SYSTEMS.values()):
        marker, colour = markers.get(system.design_layout, "D"), f"C{k}"
        mine = [d for d in run.searched if d.candidate.system == system.name]
        for meets in (True, False):
            part = [d for d in mine if d.meets == meets]
            if part:
                ax.plot([d.candidate.cost for d in part], [d.value for d in part], marker, color=colour, ms=7,
                        mfc=colour if meets else "none",
                        label=f"{system.name.upper()}, " + ("meets" if meets else "does not meet"))
    front = pareto_front(run.searched)
    if len(front) > 1:
        ax.step([d.candidate.cost for d in front], [d.value for d in front], where="post", color="0.5", lw=1,
                label="front")
    if criterion == "percentile":
        ax.axhline(run.resolved.sections["prescription"]["drms_m"], color="r", lw=1, ls="--", label="prescription")
    if criterion in ("percentile", "worst", "a-optimal") and all(d.value > 0 for d in run.searched):
        ax.set_yscale("log")
    ax.set_xlabel("cost")
    ax.set_ylabel(f"criterion: {criterion}{' [m]' if criterion in ('percentile', 'worst') else ''}"
                  f"{' [m²]' if criterion == 'a-optimal' else ''}")
    ax.set_title(f"{run.resolved.sections['design']['name']}: the candidates searched", fontsize=9)
    ax.legend(fontsize=7)
    return fig


def convergence_figure(run: DesignRun):
    """The search's best criterion after each generation, for each candidate with a searched layout."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for d in run.searched:
        if d.history:
            ax.plot(np.arange(1, len(d.history) + 1), d.history, lw=1,
                    label=d.candidate.label if d in run.proposed else None)
    ax.set_xlabel("generation (a ring's search, then the free placement's)")
    ax.set_ylabel(run.resolved.sections["search"]["criterion"])
    if any(d.history for d in run.searched) and all(v > 0 for d in run.searched for v in d.history):
        ax.set_yscale("log")
    ax.set_title("the search's best criterion", fontsize=9)
    if any(d.history and d in run.proposed for d in run.searched):
        ax.legend(fontsize=7)
    return fig


__all__ = ["CSV_COLUMNS", "OUTPUT_FILES", "design_record", "document", "figures", "predicted", "scenario_text",
           "summary", "table", "write"]
