"""What ``sblsim design`` writes for a telemetry array (:mod:`~sblsim.orchestrator.design.telemetry`):
``design.json``, ``designs.csv``, ``receivers.csv`` (:func:`receivers_table`) and ``layout.png``, all at once (an
interrupted run leaves ``--out`` as it was).

``design.json`` holds, as for the other systems, ``problem``, ``summary``, ``meets``, ``search`` and ``designs``,
and ``tag`` (the tag simulated: ``ping_type``, ``burst_interval_s``, a ``pbi`` tag's ``burst_sequence_intervals``,
``source_level_db`` where given, the ``detection_curve`` in one line, and the confirmation's multipath,
``multipath_pct`` and ``multipath_excess_m``: ``detection``'s, not in the prediction);
each design its ``name``, ``system`` (``ilbl``), ``label``, ``cost``, ``meets``, ``fails`` (``part`` one of
``receivers``, ``coverage``, ``drms``, ``positioning_yield``, ``sync_coverage``), ``scenario`` (None: a telemetry
design has no scenario file), ``receivers_m`` (North, East [m], in 3-D and depth; ``existing`` marks those in place,
``spread_m`` the largest distance between two where a footprint is given), ``sync_links`` (the pairs of receivers
that hear each other's sync tags with probability ≥ ``detection.sync_p``), ``predicted`` and ``monte_carlo`` (rows of
``point``, ``north_m``, ``east_m`` (in 3-D ``depth_m``), ``predicted_drms_m``, ``simulated_drms_m``, ``ratio``,
``pings``, ``fixes``, ``predicted_yield``, ``simulated_yield``, ``predicted_fixed``, ``simulated_fixed``,
``confirmed``), ``confirmed`` (the static points'), and ``path`` (the same along an animal's correlated random
walk, with ``monte_carlo.path``, and the walk tracked: ``tracked_*`` with the true clocks, and with
``monte_carlo.sync_clocks`` ``synced_*`` through clocks synchronised from the sync tags,
``sync_residual_m``, ``sync_within_3_sigma`` and the clocks' grade:
:func:`~sblsim.orchestrator.design.telemetry_tracking.track_synchronised`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.design.area import spread
from sblsim.orchestrator.design.area import area_origin
from sblsim.orchestrator.design.keys import TELEMETRY
from sblsim.orchestrator.design.telemetry_judgement import TelemetryDesign, ranked, sync_hearing
from sblsim.orchestrator.design.telemetry_search import TelemetryRun
from sblsim.orchestrator.io.frames import Frame, utm_zone
from sblsim.orchestrator.io.output import staged_directory

#: The columns of ``designs.csv``.
CSV_COLUMNS = ("rank", "name", "system", "count", "cost", "criterion", "drms_p50_m", "drms_p95_m", "drms_max_m",
               "coverage", "positioning_yield", "sync_coverage", "meets", "fails")


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(np.where(np.isfinite(values), values, np.inf), q, method="higher"))


def predicted(design: TelemetryDesign, run: TelemetryRun) -> dict[str, Any]:
    """A design's predicted numbers over the work area: the DRMS of the fixed pings' quantiles (``drms_p50_m``,
    ``drms_p95_m``, ``drms_max_m``, and ``drms_at_coverage_m`` at the prescription's coverage percentile; None where
    a point has no fixed ping), the averaged information's at the coverage percentile (``drms_expected_m``, the
    search's optimistic figure), ``coverage``, ``positioning_yield`` (the mean over the points),
    ``positioning_yield_at_coverage`` (reached at the coverage's share of the points), ``fixable``, and
    ``sync_coverage`` (the share of receivers hearing two other sync tags), ``sync_components``, ``sync_met``."""
    share = run.resolved.prescription["coverage_pct"]
    out = {"drms_p50_m": _percentile(design.drms_fixed, 50.0), "drms_p95_m": _percentile(design.drms_fixed, 95.0),
           "drms_max_m": _percentile(design.drms_fixed, 100.0),
           "drms_at_coverage_m": _percentile(design.drms_fixed, share),
           "drms_expected_m": _percentile(design.drms_expected, share)}
    out = {k: _finite(v) for k, v in out.items()}
    out.update({"coverage": design.coverage / 100.0,
                "positioning_yield": float(np.mean(design.positioning_yield)),
                "positioning_yield_at_coverage": float(np.percentile(design.positioning_yield, 100.0 - share,
                                                                     method="lower")),
                "fixable": float(np.mean(design.fixable)),
                "sync_coverage": float(design.sync.share), "sync_components": int(design.sync.components),
                "sync_met": bool(design.sync.met)})
    return out


def sync_links(design: TelemetryDesign, run: TelemetryRun) -> list[list[int]]:
    """The pairs (i < j) of receivers whose sync link holds (either hears the other's sync tag with probability
    ≥ ``detection.sync_p``)."""
    p = sync_hearing(design.receivers, run.resolved.curve)
    linked = p >= run.resolved.sections["detection"]["sync_p"]
    linked = linked | linked.T
    return [[int(i), int(j)] for i, j in zip(*np.nonzero(np.triu(linked, 1)))]


def design_record(design: TelemetryDesign, run: TelemetryRun) -> dict[str, Any]:
    """One proposed design as ``design.json`` holds it (module docstring)."""
    rows = [{k: _finite(v) for k, v in m.items()} for m in design.monte_carlo]
    kept = {}
    if design.kept:  # those in place (candidates.existing_m) first, kept where they are
        kept["existing"] = [k < design.kept for k in range(len(design.receivers))]
    if run.resolved.footprint > 0.0:
        kept["spread_m"] = float(spread(design.receivers))
    return {"name": design.name, "system": TELEMETRY, "label": design.label, "cost": design.cost, "meets": design.meets,
            "fails": [{k: _finite(v) for k, v in s.items()} for s in design.shortfalls], "scenario": None,
            "receivers_m": [[float(x) for x in r] for r in design.receivers], **kept,
            "sync_links": sync_links(design, run),
            "criterion": {"name": "expected-information", "value": _finite(design.value)},
            "predicted": predicted(design, run), "evaluated_by": "telemetry", "monte_carlo": rows,
            "confirmed": bool(rows) and all(m["confirmed"] for m in rows),
            "path": [{k: _finite(v) for k, v in m.items()} for m in design.path]}


def summary(run: TelemetryRun) -> str:
    """The outcome in one line."""
    p = run.resolved.prescription
    best = run.best
    what = (f"{p['drms_m']:g} m DRMS of a tag's fixes at {p['coverage_pct']:g} % of the water with a positioning "
            f"yield of {p['positioning_yield_pct']:g} % and a synchronisable array")
    pred = predicted(best, run)
    at = pred["drms_at_coverage_m"]
    found = (f"{best.label} (cost {best.cost:g}), covering {best.coverage:.1f} % (DRMS p{p['coverage_pct']:g} "
             f"{'no fix' if at is None else f'{at:.3g} m'}, yield {100 * pred['positioning_yield']:.1f} %, sync "
             f"{100 * pred['sync_coverage']:.0f} %)")
    detection = run.resolved.sections["detection"]
    if best.monte_carlo and detection["multipath_pct"] > 0.0:
        found += (f"; with {detection['multipath_pct']:g} % of the arrivals late by multipath (mean excess "
                  f"{detection['multipath_excess_m']:g} m; not in the prediction)")
    if best.monte_carlo:
        found += "; simulated / predicted DRMS " + ", ".join(
            f"{m['ratio']:.2f} at the {m['point']} point (yield {100 * m['simulated_yield']:.1f} % against "
            f"{100 * m['predicted_yield']:.1f} %)" for m in best.monte_carlo)
    for m in best.path:
        if m.get("tracked_pings"):
            found += (f"; tracked along the walk: RMS {m['tracked_rms_m']:.3g} m over {m['tracked_pings']} pings "
                      f"(smoothing bound {m['tracked_bound_m']:.3g} m, NEES {m['tracked_nees']:.2f})")
        if m.get("synced_pings"):
            found += (f"; through clocks synchronised from the sync tags: RMS {m['synced_rms_m']:.3g} m "
                      f"({m['synced_ratio']:.2f} times the true clocks', their error {m['sync_residual_m']:.2g} m "
                      f"RMS)")
    name = run.resolved.sections["design"]["name"]
    if best.meets:
        return f"{name}: {what}: {found}"
    return (f"{name}: no count of receivers meets {what}; the best found: {found}; what fails: "
            f"{'; '.join(s['text'] for s in best.shortfalls)}")


def table(run: TelemetryRun) -> pd.DataFrame:
    """``designs.csv``: every count searched, ranked."""
    names = {id(d): d.name for d in run.proposed}
    rows = []
    for k, d in enumerate(ranked(run.searched), start=1):
        pred = predicted(d, run)
        rows.append({"rank": k, "name": names.get(id(d), ""), "system": TELEMETRY, "count": d.count, "cost": d.cost,
                     "criterion": d.value, **{q: pred[q] if pred[q] is not None else math.inf
                                              for q in ("drms_p50_m", "drms_p95_m", "drms_max_m")},
                     "coverage": pred["coverage"], "positioning_yield": pred["positioning_yield"],
                     "sync_coverage": pred["sync_coverage"], "meets": d.meets,
                     "fails": "; ".join(s["part"] for s in d.shortfalls)})
    return pd.DataFrame(rows, columns=list(CSV_COLUMNS))


def receivers_table(run: TelemetryRun) -> pd.DataFrame:
    """``receivers.csv``: each proposed design's receivers (best first), as a study's receivers are given: ``x_m``
    (east), ``y_m`` (north) [m] in the design's frame (``depth_m`` in 3-D), ``in_place`` (one of
    ``candidates.existing_m``), and where ``site.area.origin`` places the frame, ``lat``, ``lon`` [° WGS 84] (the
    origin and the receivers projected by pyproj in the UTM zone of the origin; NaN without one)."""
    origin = run.resolved.sections["site.area"]["origin"]
    frame = None
    if origin:
        lat0, lon0 = area_origin(origin)
        frame = Frame(utm_zone(lat0, lon0))
        x0, y0 = frame.from_latlon(np.array([lat0]), np.array([lon0]))
    parts = []
    for design in run.proposed:
        r = np.asarray(design.receivers, float)
        rows = pd.DataFrame({"design": design.name, "receiver": np.arange(1, len(r) + 1), "x_m": r[:, 1],
                             "y_m": r[:, 0]})
        if r.shape[1] > 2:
            rows["depth_m"] = r[:, 2]
        rows["in_place"] = np.arange(len(r)) < design.kept
        if frame is not None:
            rows["lat"], rows["lon"] = frame.to_latlon(x0[0] + r[:, 1], y0[0] + r[:, 0])
        else:
            rows["lat"] = rows["lon"] = np.nan
        parts.append(rows)
    return pd.concat(parts, ignore_index=True)


def document(run: TelemetryRun, seconds: float | None = None, effort: Any = None) -> dict[str, Any]:
    """``design.json`` as a mapping (module docstring)."""
    problem = json.loads(json.dumps(run.resolved.sections, default=str))
    detection = run.resolved.sections["detection"]
    tag = run.resolved.tag.record() | {"detection_curve": run.resolved.curve.describe(),
                                       "multipath_pct": detection["multipath_pct"],
                                       "multipath_excess_m": detection["multipath_excess_m"]}
    out = {"problem": problem, "tag": tag, "summary": summary(run), "meets": run.best.meets,
           "designs": [design_record(d, run) for d in run.proposed],
           "search": {"candidates": len(run.searched), "layouts": sum(d.evaluations for d in run.searched),
                      "work_area_points": int(len(run.resolved.points)), "criterion": "expected-information",
                      "criterion_meaning": "the DRMS of the information averaged over the detections over the "
                                           "prescription's, plus the yield's and the sync graph's shortfalls"}}
    if seconds is not None:
        out["search"]["seconds"] = round(seconds, 1)
    if effort is not None:
        out["search"]["estimate"] = {"candidates": effort.candidates, "layouts": effort.layouts,
                                     "runs": effort.runs, "seconds": round(effort.seconds, 1)}
    return out


def layout_figure(run: TelemetryRun):
    """Each proposed design on the water: the positioning yield and the DRMS of the fixed pings at the work area's
    points (in 3-D, at each horizontal point its worst over the depths), the receivers, the sync links and the Monte
    Carlo's points."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    r = run.resolved
    fig, axes = plt.subplots(len(run.proposed), 2, figsize=(11, 4.6 * len(run.proposed)), squeeze=False,
                             layout="constrained")
    outline = [np.asarray(g.exterior.coords) for g in getattr(r.water, "geoms", [r.water])]
    flat, at = np.unique(r.points[:, :2], axis=0, return_inverse=True)  # in 3-D each point's worst depth
    if r.points.shape[1] == 2:
        flat, at = r.points, np.arange(len(r.points))
    for row, design in zip(axes, run.proposed):
        drms = np.full(len(flat), -np.inf)
        np.maximum.at(drms, at.ravel(), np.where(np.isfinite(design.drms_fixed), design.drms_fixed, np.inf))
        drms = np.where(np.isfinite(drms), drms, np.nan)
        worst_yield = np.full(len(flat), np.inf)
        np.minimum.at(worst_yield, at.ravel(), design.positioning_yield)
        panels = ((worst_yield, "positioning yield", dict(vmin=0.0, vmax=1.0, cmap="viridis")),
                  (drms, "DRMS of the fixed pings [m]", dict(norm=LogNorm(vmin=max(np.nanmin(drms), 1e-3),
                                                                           vmax=max(np.nanmax(drms), 1e-2)),
                                                            cmap="magma_r")))
        for ax, (values, label, style) in zip(row, panels):
            for ring in outline:
                ax.plot(ring[:, 1], ring[:, 0], color="0.3", lw=1)
            shown = ax.scatter(flat[:, 1], flat[:, 0], c=values, s=14, marker="s", **style)
            fig.colorbar(shown, ax=ax, label=label)
            for i, j in sync_links(design, run):
                a, b = design.receivers[i], design.receivers[j]
                ax.plot([a[1], b[1]], [a[0], b[0]], color="tab:blue", lw=0.4, alpha=0.5)
            ax.plot(design.receivers[:, 1], design.receivers[:, 0], "^", color="tab:red", ms=6,
                    label="receiver (with its sync tag)")
            if design.kept:
                ax.plot(design.receivers[:design.kept, 1], design.receivers[:design.kept, 0], "s", mfc="none",
                        mec="k", ms=10, label="in place")
            for m in design.monte_carlo:
                ax.plot(m["east_m"], m["north_m"], "o", mfc="none", color="k", ms=9)
                ax.annotate(f"{m['point']}: {m['ratio']:.2f}", (m["east_m"], m["north_m"]), fontsize=7,
                            xytext=(5, 5), textcoords="offset points")
            ax.set_aspect("equal")
            ax.set_xlabel("East [m]")
            ax.set_ylabel("North [m]")
            ax.set_title(f"{design.name}: {design.label}, coverage {design.coverage:.1f} %", fontsize=9)
        row[0].legend(loc="lower left", fontsize=7)
    return fig


def figures(run: TelemetryRun) -> dict[str, Any]:
    """The figures by name: ``layout``."""
    return {"layout": layout_figure(run)}


def write(run: TelemetryRun, out: Path | str, seconds: float | None = None, effort: Any = None) -> Path:
    """Write ``design.json``, ``designs.csv``, ``receivers.csv`` and ``layout.png`` into ``out`` at once; return
    ``out``."""
    import matplotlib.pyplot as plt

    with staged_directory(out) as tmp:
        (tmp / "design.json").write_text(json.dumps(document(run, seconds, effort), indent=2, allow_nan=False) + "\n")
        table(run).to_csv(tmp / "designs.csv", index=False)
        receivers_table(run).to_csv(tmp / "receivers.csv", index=False)
        for name, figure in figures(run).items():
            figure.savefig(tmp / f"{name}.png", dpi=110, bbox_inches="tight")
            plt.close(figure)
    return Path(out)


__all__ = ["CSV_COLUMNS", "design_record", "document", "figures", "layout_figure", "predicted", "summary",
           "receivers_table", "sync_links", "table", "write"]
