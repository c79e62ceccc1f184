"""The receivers' horizontal positions refined with the clocks (``sblsim sync --refine-positions``): only where
the sync tags determine them (:func:`_identify`, :func:`sblsim.models.sync.identifiability.identify`, with each sync
tag left out too), as ``positions.csv`` (:func:`_positions`); a network adjustment with a priori information at the
table's positions (Tapley, Schutz & Born 2004, ch. 4).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clocks import Geometry
from sblsim.models.sync.identifiability import MAX_SIGMA_RATIO, Identifiability, identify, shape_sigma_ratio
from sblsim.orchestrator.sync import segments
from sblsim.orchestrator.sync.sync_tags import _fit_without
from sblsim.orchestrator.sync.taken_survey import position_errors


def _identify(fit: ClockFit, args: tuple, geometry: Geometry, positions: np.ndarray, names: list[str],
              tag_names: list[str], linked: np.ndarray, survey_sigma: float
              ) -> tuple[Identifiability, dict[int, tuple[ClockFit, np.ndarray] | None]]:
    """The identifiability test of the refined positions (:func:`sblsim.models.sync.identifiability.identify`)
    on ``fit`` and on its fits with each sync tag heard left out (returned too, by tag, for the leave-one-out).

    Raises
    ------
    ModelError
        No receiver's position determined (a sparse sync array): the refinement refused in one line.
    """
    receiver, tag, emission, time, distance, slowness, used, start, width = args
    rows, site = segments.clock_rows(fit, receiver)
    ok = used & (rows >= 0)
    steady = None if len(site) == len(names) else site == start
    heard = [int(i) for i in np.unique(tag[ok])]
    fits = {i: _fit_without(i, fit, rows, tag, emission, time, distance, slowness, ok, start, width, len(site),
                            geometry, site, steady) for i in heard}
    identified = identify(positions[:, :2], fit.shift_covariance_all, survey_sigma, linked,
                          [None if f is None else f[0].shift_covariance_all for f in fits.values()])
    identified = Identifiability(identified.ratio, identified.ratio_without, identified.worst, identified.determined,
                                 identified.threshold, np.array(heard, np.int64))
    if not identified.determined.any():
        worst = np.fmax(identified.ratio, np.nan_to_num(identified.ratio_without, nan=1.0))
        best = int(np.argmin(np.where(linked, worst, np.inf)))
        raise ModelError(
            f"refine positions: the {len(heard)} sync tags heard among {len(names)} receivers determine no "
            f"receiver's position (the best, {names[best]}, has a posterior sigma {worst[best]:.2f} of the "
            f"survey's with a sync tag left out; needed: < {MAX_SIGMA_RATIO:g}, i.e. 3 sync tags not on one line "
            "heard by a receiver with any one left out: 4 or more around the array); allowed: the table's positions "
            "(without refining them)")
    return identified, fits


def _positions(fit: ClockFit, positions: np.ndarray, names: list[str], linked: np.ndarray,
               identified: Identifiability, tag_names: list[str], survey_sigma: float) -> pd.DataFrame:
    """``positions.csv``: each receiver's refined horizontal position, the table's, the shift and its sigmas; a
    receiver the sync tags do not determine (``identified``; in the fit at the survey's prior like the others) or
    not synchronised keeps the table's (``refined`` false, its ``reason``; its sigmas NaN); ``sigma_ratio`` and
    ``sigma_ratio_without`` its posterior sigma in the array's shape over the survey's, with every sync tag and the
    worst with one left out (``worst_tag``); ``position_sigma_m`` [m per axis] its position's error for a tracker
    (:func:`~sblsim.orchestrator.sync.taken_survey.position_errors`: its posterior σ in the array's shape where
    refined, the shape without the array's scale where the sound speed was fitted with the positions, which no
    time of arrival tells apart and a track calibrating its own speed takes up too; the survey's ``survey_sigma``
    where not refined)."""
    refined = linked & identified.determined
    shape = identified.ratio if fit.slowness is None else shape_sigma_ratio(
        positions[:, :2], fit.shift_covariance_all, survey_sigma, linked, scale=True)
    shift = np.where(refined[:, None], fit.shift, 0.0)
    cov = fit.shift_covariance
    ratio, without = identified.ratio, identified.ratio_without
    heard = [tag_names[i] for i in identified.tags] if identified.tags is not None else []
    worst = np.array([heard[k] if 0 <= k < len(heard) else "" for k in identified.worst], dtype=object)
    reason = np.where(~linked, "not synchronised", np.where(
        ~(ratio < identified.threshold),
        [f"its posterior sigma {r:.2f} of the survey's (needs < {identified.threshold:g})" for r in ratio],
        np.where(~(without < identified.threshold),
                 [f"determined only with sync tag {t} (without it {r:.2f} of the survey's, needs < "
                  f"{identified.threshold:g})"
                  for t, r in zip(worst, without, strict=True)], "")))
    return pd.DataFrame({
        "serial": names, "x_m": positions[:, 0] + shift[:, 0], "y_m": positions[:, 1] + shift[:, 1],
        "table_x_m": positions[:, 0], "table_y_m": positions[:, 1], "shift_x_m": shift[:, 0],
        "shift_y_m": shift[:, 1], "shift_m": np.hypot(shift[:, 0], shift[:, 1]),
        "sigma_x_m": np.where(refined, np.sqrt(cov[:, 0, 0]), np.nan),
        "sigma_y_m": np.where(refined, np.sqrt(cov[:, 1, 1]), np.nan),
        "correlation_xy": np.where(refined, cov[:, 0, 1] / np.sqrt(cov[:, 0, 0] * cov[:, 1, 1]), np.nan),
        "refined": refined, "reason": np.where(refined, "", reason), "sigma_ratio": ratio,
        "sigma_ratio_without": without, "worst_tag": worst,
        "position_sigma_m": list(position_errors(names, shape, refined, survey_sigma).values())})


def _loo(summary: dict[str, Any]) -> dict[str, Any] | None:
    """The sync tags' leave-one-out in a summary: their median error [m] and NEES inside the array, or None."""
    t = summary.get("sync_tags") or {}
    if not t:
        return None
    return {"median_error_m": t["median_error_m"], "nees_mean_inside": t["nees_mean_inside"],
            "nees_median_inside": t["nees_median_inside"], "tags": t["tags"]}


def _kept(refined, table, survey_sigma: float):
    """The refined synchronisation where its sync tags' leave-one-out median error is not larger than the table's
    (both recorded in ``summary["positions"]["leave_one_out"]``), else the table's, said in one warning."""
    before, after = _loo(table.summary), _loo(refined.summary)
    worse = after is None or (before is not None and after["median_error_m"] > before["median_error_m"])
    record = {"table": before, "refined": after, "kept": "table" if worse else "refined",
              "rule": "the refined positions kept where their sync tags' median leave-one-out error is not larger "
                      "than the table's (the table's NEES with the survey sigma as its error)"}
    record["table_nees_survey_sigma_m"] = survey_sigma
    if not worse:
        refined.summary["positions"]["leave_one_out"] = record
        return refined
    positions = refined.positions.copy()
    was = "none positioned" if after is None else f"{after['median_error_m']:.3g} m"
    why = f"the refinement worsened the sync tags' leave-one-out (median error {before['median_error_m']:.3g} m " \
          f"with the table's, {was} refined)" if before is not None else "the refinement could not be checked"
    positions["reason"] = np.where(positions["refined"], why, positions["reason"])
    positions["refined"] = False
    positions[["x_m", "y_m"]] = positions[["table_x_m", "table_y_m"]].to_numpy()
    positions[["shift_x_m", "shift_y_m", "shift_m"]] = 0.0
    positions[["sigma_x_m", "sigma_y_m", "correlation_xy"]] = np.nan
    positions["position_sigma_m"] = float(survey_sigma)
    table.positions = positions
    table.summary["positions"] = {**refined.summary["positions"], "refined": False, "leave_one_out": record,
                                  "position_sigma_m": [float(survey_sigma)] * 2}
    table.summary.setdefault("warnings", []).append(f"refine positions: {why}: the table's positions kept")
    return table
