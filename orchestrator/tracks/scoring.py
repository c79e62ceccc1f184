"""A track scored against a truth: the errors, their statistics, the NEES, the lag and the lever arm.

The truth (t, x, y[, z]) is interpolated linearly at each estimate's emission time; per ping the 2-D error [m] (and
the 3-D one where both the estimates and the truth have z); over the pings an estimator positions inside the
truth's span, the count, mean, median, RMS, 90th and 95th percentiles, and the mean 2-D NEES (the estimator's
covariance against the truth, whose own error is not in it). Reported beside, never applied to those errors:
``lag_s``, the constant shift of the truth's time (the truth taken at ``t + lag_s``) that minimises the RMS 2-D
error, searched in ±:data:`LAG_RANGE_S` (a 0.25 s grid, then scipy's bounded scalar minimiser around its best
point) over the pings whose shifted times stay inside the truth's span; and the mean error along and across the
truth's heading (a lever arm; at a steady speed a lag and an along-track offset look alike). A reference solution
(x, y, t rows) is scored the same way on the rows it reports.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: A truth whose horizontal positions span at most this is still: no lag is searched against it [m].
STILL_M = 0.01
#: The time lags between the truth and the track searched [s]: ±this.
LAG_RANGE_S = 30.0


def _truth_at(truth: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The truth's (x, y[, z]) interpolated linearly at the times ``t``."""
    return np.column_stack([np.interp(t, truth[:, 0], truth[:, k]) for k in range(1, truth.shape[1])])


def _stats(e: np.ndarray, suffix: str = "") -> dict[str, float]:
    return {f"mean{suffix}_m": float(e.mean()), f"median{suffix}_m": float(np.median(e)),
            f"rms{suffix}_m": float(np.sqrt(np.mean(e**2))), f"p90{suffix}_m": float(np.percentile(e, 90)),
            f"p95{suffix}_m": float(np.percentile(e, 95))}


def estimate_lag(t: np.ndarray, xy: np.ndarray, truth: np.ndarray, bound: float = LAG_RANGE_S
                 ) -> tuple[float | None, float | None]:
    """The constant shift ``lag`` [s] of the truth's time (the truth taken at ``t + lag``) in [−bound, bound] that
    minimises the RMS 2-D error of the estimates at times ``t`` (m,) and positions ``xy`` (m, 2), over the
    estimates whose times shifted by any lag in the range stay inside the truth's span; and that RMS [m]. None
    where fewer than 3 estimates qualify, or where the truth does not move (its horizontal positions within
    :data:`STILL_M` of each other over the span: a surveyed position), which no lag changes."""
    ok = (t - bound >= truth[0, 0]) & (t + bound <= truth[-1, 0]) & np.isfinite(xy).all(axis=1)
    if ok.sum() < 3 or np.ptp(truth[:, 1:3], axis=0).max() <= STILL_M:
        return None, None
    t, xy = t[ok], xy[ok]

    def rms(lag: float) -> float:
        g = _truth_at(truth[:, :3], t + lag)
        return float(np.sqrt(np.mean(((xy - g) ** 2).sum(axis=1))))

    from scipy.optimize import minimize_scalar  # scipy.optimize: a third of a second of every command's start-up

    step = 0.25
    grid = np.arange(-bound, bound + step / 2, step)
    best = float(grid[int(np.argmin([rms(g) for g in grid]))])
    found = minimize_scalar(rms, bounds=(max(-bound, best - step), min(bound, best + step)), method="bounded",
                            options={"xatol": 1e-3})
    return (float(found.x), float(found.fun)) if found.fun <= rms(best) else (best, rms(best))


def score(t: np.ndarray, p: np.ndarray, truth: np.ndarray, cov: np.ndarray | None = None,
          lag_bound: float = LAG_RANGE_S, truth_sigma: float = 0.0
          ) -> tuple[dict[str, Any], np.ndarray, np.ndarray | None]:
    """The errors of estimates at times ``t`` (m,) [s], positions ``p`` (m, 2 or 3) [m] against the truth (rows
    t, x, y[, z]) interpolated at those times, and their statistics (module docstring; the estimates outside the
    truth's span not scored); ``cov`` (m, 2, 2) [m²] adds the 2-D NEES, its mean (``nees``: 2 when consistent)
    and median (``nees_median``: 2 ln 2 = 1.386 when consistent, the χ² of 2 degrees of freedom), with the truth's
    own error ``truth_sigma`` [m] per horizontal axis in the budget (``cov`` + σ² I; 0: the truth taken as exact).
    Returns the statistics, the 2-D errors (m,) (NaN where not scored) and the 3-D ones (None unless both have
    z)."""
    inside = (t >= truth[0, 0]) & (t <= truth[-1, 0])
    g = _truth_at(truth, t)
    e = p[:, :2] - g[:, :2]
    err = np.where(inside, np.hypot(e[:, 0], e[:, 1]), np.nan)
    err3 = None
    if p.shape[1] == 3 and truth.shape[1] == 4:
        err3 = np.where(inside, np.sqrt((e**2).sum(axis=1) + (p[:, 2] - g[:, 2]) ** 2), np.nan)
    ok = np.isfinite(err)
    stats: dict[str, Any] = {"n_scored": int(ok.sum())}
    if not ok.any():
        return stats, err, err3
    stats |= _stats(err[ok])
    stats["nees"] = stats["nees_median"] = None
    if cov is not None:
        c = cov[ok] + truth_sigma**2 * np.eye(2)
        det = c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] * c[:, 1, 0]
        good = np.isfinite(det) & (det > 1e-9 * c[:, 0, 0] * c[:, 1, 1])  # a 3-receiver fix may have none
        x, y, c, det = e[ok][good, 0], e[ok][good, 1], c[good], det[good]
        nees = (c[:, 1, 1] * x**2 - (c[:, 0, 1] + c[:, 1, 0]) * x * y + c[:, 0, 0] * y**2) / det
        if good.any():
            stats["nees"], stats["nees_median"] = float(nees.mean()), float(np.median(nees))
    stats["lag_s"], stats["rms_at_lag_m"] = estimate_lag(t, p[:, :2], truth, lag_bound)
    stats["lag_range_s"] = lag_bound
    # the truth's heading at each ping (its motion over ±0.5 s), where it moves at 0.1 m/s or more
    d = _truth_at(truth[:, :3], t + 0.5) - _truth_at(truth[:, :3], t - 0.5)
    speed = np.hypot(d[:, 0], d[:, 1])
    moving = ok & (speed >= 0.1)
    if moving.any():
        u = d[moving] / speed[moving, None]
        stats["along_track_m"] = float(np.mean((e[moving] * u).sum(axis=1)))
        stats["across_track_m"] = float(np.mean(e[moving, 1] * u[:, 0] - e[moving, 0] * u[:, 1]))
    if err3 is not None:
        stats |= _stats(err3[ok], "_3d")
    return stats, err, err3


__all__ = ["LAG_RANGE_S", "STILL_M", "estimate_lag", "score"]
