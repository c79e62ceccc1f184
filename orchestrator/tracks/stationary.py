"""A stationary tag (``motion`` ``stationary``): one position for all its pings, pooled from its arrivals
(:mod:`sblsim.models.tracking.stationary`), and the consider covariance of the errors pooling does not average (the
receivers' survey, the sound speed, the receivers' clock offsets).
"""

from __future__ import annotations

import numpy as np

from sblsim.models.tracking.timing import SIGMA_TOA


def stationary_track(toa: np.ndarray, positions: np.ndarray, c: float, fixes: np.ndarray,
                     sigma_toa: float | np.ndarray = SIGMA_TOA):
    """A stationary tag's pooled fix (:func:`~sblsim.models.tracking.stationary.stationary_fix`) from the median of
    its single-ping fixes ``fixes`` (m, dim) [m], else the receivers' centroid; ``sigma_toa`` the timing noise [s]
    (one, or each receiver's).

    Raises
    ------
    ModelError
        Too few receivers heard it (one line).
    """
    from sblsim.models.tracking.stationary import stationary_fix

    finite = np.isfinite(fixes).all(axis=1)
    start = np.median(fixes[finite], axis=0) if finite.any() else positions.mean(axis=0)
    return stationary_fix(toa, positions, c, sigma_toa, start)


def stationary_consider(toa: np.ndarray, positions: np.ndarray, c: float, pooled, survey: np.ndarray | None,
                        speed_sigma: float | None, sigma_toa: float | np.ndarray = SIGMA_TOA,
                        clock_sigma: np.ndarray | None = None) -> np.ndarray | None:
    """A stationary tag's pooled position's consider covariance (dim, dim) [m²] of the errors pooling does not
    average: the receivers' survey ``survey`` (n,) [m per axis], the sound speed's ``speed_sigma`` [m/s] and the
    receivers' clock offsets' ``clock_sigma`` (n,) [s] (a synchronisation's own uncertainty of each receiver's offset,
    NaN where not known: taken as 0), each a constant bias of one receiver's arrivals
    (:func:`~sblsim.models.tracking.stationary.bias_sensitivity`); None where none is known."""
    from sblsim.models.tracking.stationary import bias_sensitivity

    clock = None if clock_sigma is None else np.nan_to_num(np.asarray(clock_sigma, float), nan=0.0)
    if survey is None and not speed_sigma and (clock is None or not clock.any()):
        return None
    S = bias_sensitivity(toa, positions, c, sigma_toa, pooled)
    B = np.zeros((len(positions), len(positions)))
    if survey is not None:  # a still tag's range to receiver i is off by u_i · δr_i, of variance σ_i² (|u_i| = 1)
        B += np.diag(np.asarray(survey, float) ** 2 / c**2)
    if clock is not None:  # receiver i's arrivals all off by its offset's error, independent between receivers
        B += np.diag(clock**2)
    if speed_sigma:  # the travel time ρ_i / c off by −ρ_i δc / c² at every receiver at once
        rho = np.linalg.norm(pooled.position[None, :] - positions, axis=1)
        B += float(speed_sigma) ** 2 * np.outer(rho, rho) / c**4
    return S @ B @ S.T



__all__ = ["stationary_consider", "stationary_track"]
