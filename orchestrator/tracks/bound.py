"""The accuracy limit along a recorded track: at each ping's true position (the truth at the tracker's emission
time of that ping) with the receivers that heard it, the predicted DRMS of a single-ping fix and the tracker's PCRB,
filtered and smoothed (:mod:`sblsim.models.receiver.toa_bound`); ``bound.csv`` per ping, and in ``score.json`` under
``bound`` the track split into thirds by ping index, each with the predicted DRMS (the RMS and the median over the
pings an estimator positioned) against the observed 2-D errors (RMS, median and the robust RMS
``median / sqrt(ln 2)``: the RMS of a circular Gaussian error with that median, blind to up to half the pings being
gross outliers).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sblsim.models.receiver import toa_bound as tb
from sblsim.orchestrator.tracks.scoring import _truth_at

#: The predicted DRMS of each estimator in ``bound.csv``: the single-ping fix's, the PCRB of the causal filter, the
#: smoothing bound.
BOUND_COLUMNS = {"fix": "fix_drms_m", "ekf": "pcrb_m", "ekf-seq": "pcrb_m", "ukf": "pcrb_m",
                 "rts": "pcrb_smoothed_m", "robust": "pcrb_smoothed_m"}


#: The RMS of a circular Gaussian 2-D error over its median: ``1 / sqrt(ln 2)``.
ROBUST_FROM_MEDIAN = 1.0 / np.sqrt(np.log(2.0))


def bound_along_track(toa: np.ndarray, receivers: np.ndarray, times: np.ndarray, truth: np.ndarray,
                      settings, schedule=None, estimates: np.ndarray | None = None) -> Any:
    """The accuracy limit per ping along a true track (``bound.csv``, a pandas.DataFrame).

    ``toa`` (m, n) [s] (NaN: not heard), ``receivers`` (n, dim) [m], ``times`` (m,) [s] each ping's emission time
    (the tracker's estimate; NaN before the tracker starts: no bound there), ``truth`` rows (t, x, y[, z]),
    ``settings`` the tracker's (:class:`~sblsim.models.tracking.ekf.TrackerSettings`). The true position
    is the truth interpolated at ``times``, the true velocity its difference over ±0.5 s. Columns: ``ping``,
    ``time``, ``heard``, ``fix_drms_m`` (:func:`~sblsim.models.receiver.toa_bound.fix_drms`), ``pcrb_m`` and
    ``pcrb_smoothed_m`` (:func:`~sblsim.models.receiver.toa_bound.pcrb` from the first ping with a time, over the
    steps of ``schedule``, the ping type's, :class:`~sblsim.models.tracking.schedule.PingSchedule`). With 3-D
    receivers and a 2-D truth, the depth of each true position is the tracker's own (``estimates`` (m, 3) [m]; 0
    without them).
    """
    import pandas as pd

    m, dim = len(toa), receivers.shape[1]
    heard = np.isfinite(toa)
    rows = np.flatnonzero(np.isfinite(times))
    frame = pd.DataFrame({"ping": np.arange(m), "time": times, "heard": heard.sum(axis=1),
                          **{v: np.nan for v in BOUND_COLUMNS.values()}})
    if len(rows) < 2:
        return frame
    k0 = rows[0]
    t = times[k0:]
    p = _truth_at(truth, t)[:, :dim]
    v = _truth_at(truth, t + 0.5)[:, :dim] - _truth_at(truth, t - 0.5)[:, :dim]
    if p.shape[1] < dim:  # a 2-D truth of a 3-D array: the tracker's depth, not moving vertically
        depth = np.zeros(len(t)) if estimates is None else np.nan_to_num(np.asarray(estimates)[k0:, 2])
        p, v = np.column_stack([p, depth]), np.column_stack([v, np.zeros(len(t))])
    frame.loc[k0:, "fix_drms_m"] = tb.fix_drms(p, heard[k0:], receivers, settings.sound_speed, settings.sigma_toa)
    b = tb.pcrb(p, v, t, heard[k0:], receivers, settings.sound_speed, settings.sigma_toa, tb.MotionModel.of(settings),
                None if schedule is None else schedule.sliced(k0))
    frame.loc[k0:, "pcrb_m"], frame.loc[k0:, "pcrb_smoothed_m"] = b.filtered, b.smoothed
    return frame


def bound_thirds(bound, errors) -> list[dict[str, Any]]:
    """The thirds of the track by ping index: per estimator of ``errors`` (``errors.csv``) with a column in
    ``bound`` (``bound.csv``), over the pings it positioned inside the truth's span, ``n``, the predicted DRMS
    (``predicted_rms_m``, ``predicted_median_m``) and the observed 2-D errors (``observed_rms_m``,
    ``observed_median_m``, ``observed_robust_rms_m`` = median / sqrt(ln 2)) [m]."""
    thirds = []
    for part in np.array_split(np.arange(len(bound)), 3):
        if not len(part):  # fewer than 3 pings
            continue
        entry: dict[str, Any] = {"first_ping": int(part[0]), "last_ping": int(part[-1])}
        for estimator, column in BOUND_COLUMNS.items():
            e = errors[(errors["estimator"] == estimator) & errors["error_2d_m"].notna()]
            e = e[(e["ping"] >= part[0]) & (e["ping"] <= part[-1])]
            if not len(e):
                continue
            predicted = bound[column].to_numpy()[e["ping"].to_numpy()]
            observed = e["error_2d_m"].to_numpy()
            # a ping before the tracker's start has no bound (NaN); an unbounded one (a degenerate geometry, inf)
            # counts in the median, not in the RMS
            finite, known = np.isfinite(predicted), ~np.isnan(predicted)
            entry[estimator] = {
                "n": int(len(e)), "n_bounded": int(finite.sum()),
                "predicted_rms_m": float(np.sqrt(np.mean(predicted[finite] ** 2))) if finite.any() else None,
                "predicted_median_m": float(np.median(predicted[known])) if finite.any() else None,
                "observed_rms_m": float(np.sqrt(np.mean(observed**2))),
                "observed_median_m": float(np.median(observed)),
                "observed_robust_rms_m": float(np.median(observed) * ROBUST_FROM_MEDIAN)}
        thirds.append(entry)
    return thirds


__all__ = ["BOUND_COLUMNS", "ROBUST_FROM_MEDIAN", "bound_along_track", "bound_thirds"]
