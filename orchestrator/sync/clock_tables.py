"""The fitted clocks as ``sblsim sync``'s tables: ``offsets.csv`` (one row per synchronised receiver, or clock
segment, and time bin: :func:`_offsets`), ``sync.json``'s summary (the model, per receiver its offsets, drifts and
their sigmas, and the diagnostics: :func:`_summary`) and the residuals' ``reason`` column (:func:`_reasons`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.windows import windows_slowness
from sblsim.orchestrator.sync import segments

#: A sync arrival's ``reason`` in the residuals (``residuals.csv``), by its code: kept (empty), or why not.
REASONS = ("", "multipath", "single receiver", "clock break", "not synchronised", "rejected")


def _reasons(code: np.ndarray) -> np.ndarray:
    """The ``reason`` of each arrival (its :data:`REASONS` code (k,)): an object array whose rows share the six
    strings, no fixed-width text array made first (the column of 10⁶ arrivals made at a peak of 50 MB, where nested
    ``numpy.where`` of the texts took 128 MB; the table's column is the same)."""
    return np.array(REASONS, dtype=object)[code]


def _offsets(fit: ClockFit, names: list[str], linked: np.ndarray, bridged: np.ndarray, origin: float
             ) -> pd.DataFrame:
    """``offsets.csv``: one row per synchronised receiver (per clock row: ``linked`` (rows,)) and bin; where a
    receiver's clock broke, its segments' rows each, with ``segment``, ``clock_from`` and ``clock_to``
    (:func:`~sblsim.orchestrator.sync.segments.segment_columns`)."""
    rows = []
    edges = fit.edges + origin
    site, number = segments.clock_rows(fit, np.zeros(0, np.int64))[1], segments.segment_numbers(fit)
    order = sorted(np.flatnonzero(linked), key=lambda j: (site[j], number[j]))  # a receiver's segments together
    for j in order:
        for k in range(len(edges) - 1):
            rows.append((names[site[j]], k, edges[k], edges[k + 1], fit.knots[j, k], fit.knot_sigma[j, k],
                         fit.knots[j, k + 1], fit.knot_sigma[j, k + 1], fit.drift[j, k], fit.drift_sigma[j, k],
                         int(fit.counts[j, k]), bool(bridged[j, k])))
    table = pd.DataFrame(rows, columns=["receiver", "bin", "start", "end", "offset_start_s", "offset_start_sigma_s",
                                        "offset_end_s", "offset_end_sigma_s", "drift", "drift_sigma", "arrivals",
                                        "bridged"])
    for key, values in (segments.segment_columns(fit, origin) or {}).items():
        table[key] = np.repeat(values[order], len(edges) - 1)
    return table


def _summary(fit, names, tag_names, receiver, tag, used, duplicate, single, linked, start, bridged, residuals,
             sync_tags, speed_source, sound_speed, bin_hours, origin, notes, detections, rows, dim, wall
             ) -> dict[str, Any]:
    """``sync.json``: the model, per receiver and bin the offset, drift and their sigmas, and the diagnostics;
    ``rows`` the detections' rows read (counted before they were let go)."""
    per_receiver = {}
    edges = (fit.edges + origin).tolist()
    for j, name in enumerate(names):
        mine = receiver == j
        fitted = mine & used
        kept = fit.kept & mine
        entry: dict[str, Any] = {
            "synchronised": bool(linked[j]), "reference": j == start, "arrivals": int(mine.sum()),
            "used": int(fitted.sum()), "kept": int(kept.sum()),
            "rejected_share": float(1 - kept.sum() / fitted.sum()) if fitted.sum() else None,
            "multipath": int((duplicate & mine).sum()),
            "sync_tags_heard": sorted({tag_names[i] for i in np.unique(tag[fitted])}),
        }
        if linked[j]:
            r = residuals.loc[residuals["kept"].to_numpy() & mine, ["residual_m", "residual_s"]]
            entry.update({
                "noise_scale_s": float(fit.scale[j]),
                "median_abs_residual_m": float(np.median(np.abs(r["residual_m"]))) if len(r) else None,
                "median_abs_residual_s": float(np.median(np.abs(r["residual_s"]))) if len(r) else None,
                "bins_bridged": int(bridged[j].sum()),
                "offset_s": fit.knots[j].tolist(), "offset_sigma_s": _finite(fit.knot_sigma[j]),
                "drift": fit.drift[j].tolist(), "drift_sigma": _finite(fit.drift_sigma[j])})
        per_receiver[name] = entry
    speed = {"source": speed_source}
    if speed_source == "given":
        speed["sound_speed_m_s"] = sound_speed
    elif speed_source == "estimated":
        speed["sound_speed_m_s"] = 1.0 / fit.slowness
        speed["sound_speed_sigma_m_s"] = fit.slowness_sigma / fit.slowness ** 2 if fit.slowness_sigma else None
        tau = None if fit.window_slowness is None else windows_slowness(fit.window_slowness)[2]  # a season's
        if tau is not None:
            speed["windows_spread_m_s"] = tau / fit.slowness ** 2
    loo = {}
    if len(sync_tags):
        inside = sync_tags[sync_tags["inside_array"]]
        loo = {"median_error_m": float(sync_tags["median_error_m"].median()),
               "tags": int(len(sync_tags)), "nees_mean_inside": float(inside["nees_mean"].mean())
               if len(inside) else None,
               "nees_median_inside": float(inside["nees_median"].median()) if len(inside) else None,
               "median_sigma_m": float(sync_tags["median_sigma_m"].median()),
               "fixes": int(sync_tags["fixes"].sum()), "fixes_unchecked": int(sync_tags["fixes_unchecked"].sum()),
               "fixes_failed": int(sync_tags["fixes_failed"].sum()),
               "fixes_ambiguous": int(sync_tags["fixes_ambiguous"].sum()),
               "fix_model": "robust (Student-t IRLS from several starts, then Baarda's data snooping and the overall "
                            "test at a test size of 0.001: Baarda 1968); a fix without redundancy is unchecked, not "
                            "counted"}
        placed = sync_tags[np.isfinite(sync_tags["place_error_m"].to_numpy(float))] \
            if "place_error_m" in sync_tags else sync_tags.iloc[:0]
        if len(placed):  # each as one place, as a reference tag (sync_tags.csv's place_* columns)
            loo |= {"places": int(len(placed)), "place_median_error_m": float(placed["place_error_m"].median()),
                    "place_nees_mean": float(placed["place_nees"].mean()),
                    "place_flagged": int(placed["place_flagged"].sum()), "place_rows": int(placed["place_rows"].sum())}
    kept = residuals["kept"].to_numpy()
    return {
        "model": "piecewise-linear clock offset per receiver, continuous across time bins (drift constant in a bin), "
                 "the reference receiver fixed, sync-tag emission times unknown; robust IRLS (Student-t, nu=3) then "
                 "arrivals beyond 4 sigma rejected (Baktoft et al. 2017, Sci. Rep. 7:14294; YAPS's sync model)",
        "detections": {"file": detections.source, "format": detections.format, "rows": int(rows),
                       "sync_arrivals": int(len(receiver)), "used": int(used.sum()), "kept": int(kept.sum()),
                       "multipath": int(duplicate.sum()), "single_receiver": int(single.sum()),
                       "ignored_columns": detections.ignored_columns},
        "reference_receiver": names[start], "bin_hours": bin_hours, "bin_edges": edges, "dimensions": dim,
        "sound_speed": speed, "receivers": per_receiver,
        "synchronised": [n for j, n in enumerate(names) if linked[j]],
        "not_synchronised": [n for j, n in enumerate(names) if not linked[j]],
        "median_abs_residual_m": float(np.median(np.abs(residuals.loc[kept, "residual_m"]))) if kept.any() else None,
        "sync_tags": loo, "iterations": fit.iterations, "notes": notes, "wall_time_s": wall,
    }


def _finite(values: np.ndarray) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in values]
