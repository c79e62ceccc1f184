"""A still tag's sound speed from its own pings taken as one place: where the pings cannot calibrate it one by one.

A moving tag's pings each have their own place, so a ping tells the sound speed only beyond its place and emission
time (:func:`~sblsim.models.tracking.calibration.calibrate_sound_speed` takes pings heard by dim + 3 receivers or
more: an array of four in 2-D has none, and its tags fall back on a default speed 51 m/s uncertain). A still tag's
pings share one place: every arrival ``toa_ij = t_j + ‖p − r_i‖ s`` (ping j's emission time ``t_j``, the place ``p``,
the slowness ``s = 1/c``), and the record's time differences between receivers tell the place and the slowness
together wherever dim + 2 receivers hear it (in 2-D: in 3-D the tag's depth trades with the speed, as the per-ping
calibration's depth term says). The place, the slowness and every emission time are fitted by scipy's
``least_squares``: least squares from the receivers' centroid, then the soft-L1 loss at
:data:`~sblsim.models.tracking.calibration.ROBUST_SCALE` σ from there (a late arrival of a reflection counts as in an
L1 fit; far from the solution every residual would be an outlier), each arrival's Jacobian row touching its ping's
time, the place and the slowness alone. As the per-ping calibration does, the record is cut into stretches, each
fitted alone, and their median kept, its standard error ``1.2533 s / √K`` (s their spread; the median's efficiency
2/π): the water's sound speed changes over a record, and the stretches' spread is what that change leaves in one speed
for it all.

References
----------
Triggs, McLauchlan, Hartley, Fitzgibbon, "Bundle adjustment — a modern synthesis", Vision Algorithms 1999, LNCS 1883
(the points' and cameras' joint fit); Huber & Ronchetti, *Robust Statistics*, Wiley 2009,
§ 3.2 (the median of independent estimates).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.calibration import BATCH_PINGS, BATCHES, ROBUST_SCALE, Calibration
from sblsim.models.tracking.toa import SOUND_SPEED_RANGE, checked_sigma

#: The fewest pings heard by two receivers or more a stretch is fitted with.
MIN_STRETCH_PINGS = 10


def _stretch(toa: np.ndarray, receivers: np.ndarray, sigma: np.ndarray, start: np.ndarray,
             bounds: tuple[float, float], max_pings: int) -> float:
    """One stretch's sound speed [m/s] from at most ``max_pings`` of its pings heard by two receivers or more
    (evenly spread); NaN where it cannot be fitted or falls outside ``bounds``."""
    rows = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= 2)
    if len(rows) < MIN_STRETCH_PINGS:
        return np.nan
    rows = rows[np.unique(np.linspace(0, len(rows) - 1, min(max_pings, len(rows))).round().astype(int))]
    ping, receiver = np.nonzero(np.isfinite(toa[rows]))
    times = toa[rows][ping, receiver]
    dim, m = receivers.shape[1], len(rows)
    weight = 1.0 / sigma[receiver]
    s0 = 2.0 / (bounds[0] + bounds[1])
    rho0 = np.linalg.norm(start[None] - receivers[receiver], axis=1)
    t0 = np.bincount(ping, times - rho0 * s0, m) / np.bincount(ping, minlength=m)
    origin = float(np.median(t0))  # the emission times about their median: well scaled unknowns

    def unpack(x):
        return x[:dim], x[dim], x[dim + 1:]

    def residuals(x):
        p, s, t = unpack(x)
        rho = np.linalg.norm(p[None] - receivers[receiver], axis=1)
        return (times - origin - t[ping] - rho * s) * weight

    arrivals = np.arange(len(times))

    def jacobian(x):  # (arrivals, dim + 1 + pings): the place and the slowness, then its own ping's time
        p, s, _ = unpack(x)
        d = p[None] - receivers[receiver]
        rho = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        out = np.zeros((len(times), dim + 1 + m))
        out[:, :dim + 1] = np.column_stack([-s * d / rho[:, None], -rho]) * weight[:, None]
        out[arrivals, dim + 1 + ping] = -weight
        return out

    x0 = np.r_[start, s0, t0 - origin]
    try:
        first = least_squares(residuals, x0, jac=jacobian, method="lm", x_scale="jac", max_nfev=200)
        fit = least_squares(residuals, first.x, jac=jacobian, loss="soft_l1", f_scale=ROBUST_SCALE, x_scale="jac",
                            method="trf", tr_solver="exact", max_nfev=100)
    except (ValueError, np.linalg.LinAlgError):
        return np.nan
    c = 1.0 / fit.x[dim] if fit.x[dim] > 0 else np.nan
    return float(c) if fit.success and bounds[0] <= c <= bounds[1] else np.nan


def calibrate_still_sound_speed(toa: np.ndarray, receivers: np.ndarray, sigma_toa: float | np.ndarray,
                                start: np.ndarray | None = None, batches: int = BATCHES,
                                max_pings: int = BATCH_PINGS, bounds: tuple[float, float] = SOUND_SPEED_RANGE
                                ) -> Calibration:
    """The sound speed of a still tag's record, its pings one place (the module docstring).

    Parameters
    ----------
    toa : numpy.ndarray
        (m, n) [s] times of arrival, NaN where not heard.
    receivers : numpy.ndarray
        (n, 2) [m] the receivers' positions.
    sigma_toa : float or numpy.ndarray
        [s] a time of arrival's σ, one or (n,) per receiver.
    start : numpy.ndarray, optional
        (2,) [m] where the place's fit starts (a fix's median); None: the centroid of the receivers heard.
    batches : int
        K, the stretches (at least 3 fitted, or the calibration is refused).
    max_pings : int
        The most pings of a stretch's fit (evenly spread over it).
    bounds : (float, float)
        [m/s] the speeds allowed; a stretch outside them is not counted.

    Returns
    -------
    Calibration
        ``c`` [m/s] the stretches' median, ``sigma`` [m/s] its standard error, the arrivals' pings used and each
        stretch's speed (NaN where not fitted).

    Raises
    ------
    ModelError
        Receivers not in 2-D, fewer than 4 receivers hear the tag (its place and speed are not told apart), or fewer
        than 3 stretches can be fitted (one line each).
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    dim = receivers.shape[1]
    if dim != 2:
        raise ModelError(f"still sound speed: receivers in {dim}-D; allowed: 2-D (in 3-D the tag's depth trades with "
                         "the speed: give the sound speed)")
    heard = np.isfinite(toa).any(axis=0)
    if heard.sum() < dim + 2:
        raise ModelError(f"still sound speed: {int(heard.sum())} receivers hear the tag; at least {dim + 2} are "
                         "needed to tell its place from the sound speed (give the sound speed)")
    sigma = np.broadcast_to(np.asarray(checked_sigma(sigma_toa, len(receivers)), float), (len(receivers),))
    start = receivers[heard].mean(axis=0) if start is None else np.asarray(start, float)
    values = [_stretch(toa[rows], receivers, sigma, start, bounds, max_pings)
              for rows in np.array_split(np.arange(len(toa)), max(int(batches), 3))]
    fitted = np.array([v for v in values if np.isfinite(v)])
    if len(fitted) < 3:
        raise ModelError(f"still sound speed: {len(fitted)} of {len(values)} stretches of the record fitted; at least "
                         f"3 are needed ({MIN_STRETCH_PINGS} pings heard by two receivers each; give the sound speed)")
    used = int((np.isfinite(toa).sum(axis=1) >= 2).sum())
    return Calibration(float(np.median(fitted)), float(1.2533 * np.std(fitted, ddof=1) / np.sqrt(len(fitted))), used,
                       tuple(float(v) for v in values))


__all__ = ["MIN_STRETCH_PINGS", "calibrate_still_sound_speed"]
