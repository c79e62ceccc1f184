"""The measurement model of a reply, which every solver of the package linearises: the range residual of its two
legs, the Jacobian of the predicted path and the variance of Xie et al.'s weights.

At the unknowns (the offsets of each transponder, or of one rigid shift, from the a-priori positions; then the
speed scale), ``_model`` gives each reply's range residual :math:`v_i = s\\,c_0\\,T_i - \\ell_{tx} - \\ell_{rx}`
[m], its Jacobian, the variance :math:`\\sigma_i^2` of the transducer's GNSS sigmas projected on the legs
(``_line_of_sight_variance``) and the geometry; ``_directions`` each reply's elevation and azimuth and each
transponder's scatter (the weights of :func:`~sblsim.models.calibration.combine`); ``_check`` refuses the inputs
that no solver takes. The least-squares solution (:mod:`sblsim.models.calibration.leastsquares`), the moving
ocean's (:mod:`sblsim.models.calibration.ocean`), the search (:mod:`sblsim.models.calibration.selection`), the
bound (:mod:`sblsim.models.calibration.bound`) and the running solution (:mod:`sblsim.models.calibration.kalman`)
share it, and Gauss-Newton's tolerances with it.
"""

from __future__ import annotations

import numpy as np

from sblsim.models.calibration.legs import SOUND_SPEED_RANGE, LegModel
from sblsim.models.calibration.replies import Replies
from sblsim.models.declarations import ModelError

#: The outlier factors accepted (times the weighted RMS).
OUTLIER_FACTOR_RANGE = (1.0, 100.0)
#: Gauss-Newton stops when no position moves more than this [m] (and the speed scale less than
#: :data:`SCALE_TOLERANCE`), or after :data:`MAX_ITERATIONS`.
POSITION_TOLERANCE = 1e-7
SCALE_TOLERANCE = 1e-10
MAX_ITERATIONS = 50


def _check(replies: Replies, apriori: np.ndarray, sound_speed: float, outlier_factor: float | None,
           twtt_sigma: float) -> None:
    lo, hi = SOUND_SPEED_RANGE
    if not (np.isfinite(sound_speed) and lo <= sound_speed <= hi):
        raise ModelError(f"sound_speed_mps: {sound_speed!r} is outside the allowed range [{lo:g}, {hi:g}] m/s")
    if outlier_factor is not None:
        lo, hi = OUTLIER_FACTOR_RANGE
        if not (np.isfinite(outlier_factor) and lo <= outlier_factor <= hi):
            raise ModelError(f"outlier_factor: {outlier_factor!r} is outside the allowed range [{lo:g}, {hi:g}]")
    if not (np.isfinite(twtt_sigma) and 0.0 <= twtt_sigma <= 1.0):
        raise ModelError(f"twtt_sigma_s: {twtt_sigma!r} is outside the allowed range [0, 1] s")
    if apriori.ndim != 2 or apriori.shape[1] != 3 or not np.all(np.isfinite(apriori)):
        raise ModelError("apriori: the a-priori positions must be finite, shape (k, 3) [m]")
    if len(replies) and (replies.transponder.min() < 0 or replies.transponder.max() >= len(apriori)):
        raise ModelError(f"transponder: an index is outside [0, {len(apriori) - 1}]")


def _line_of_sight_variance(replies: Replies, x: np.ndarray, u_tx: np.ndarray, u_rx: np.ndarray, c: float,
                            twtt_sigma: float) -> np.ndarray:
    """:math:`\\sigma_i^2` [m²]: the transducer's sigmas projected on the legs' unit vectors."""
    return (np.sum((u_tx * replies.tx_sigma) ** 2, axis=1) + np.sum((u_rx * replies.rx_sigma) ** 2, axis=1)
            + (c * twtt_sigma) ** 2)


def _directions(replies: Replies, x: np.ndarray, residual: np.ndarray, w: np.ndarray, used: np.ndarray,
                k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each reply's elevation and azimuth of the receive point seen from the transponder [rad], and per transponder
    the weighted RMS of the used half residuals projected on East, North, Up [m] (:attr:`Solution.scatter`)."""
    horizontal = np.hypot(replies.rx[:, 0] - x[:, 0], replies.rx[:, 1] - x[:, 1])
    elevation = np.arctan2(replies.rx[:, 2] - x[:, 2], horizontal)
    azimuth = np.arctan2(replies.rx[:, 0] - x[:, 0], replies.rx[:, 1] - x[:, 1])
    half = 0.5 * residual
    projected = np.column_stack((half * np.sin(azimuth), half * np.cos(azimuth), half * np.sin(elevation)))
    scatter = np.full((k, 3), np.nan)
    for j in range(k):
        mine = used & (replies.transponder == j)
        if mine.any():
            scatter[j] = np.sqrt(np.sum(w[mine, None] * projected[mine] ** 2, axis=0) / np.sum(w[mine]))
    return elevation, azimuth, scatter


def _unknowns(k: int, rigid: bool, solve_speed: bool) -> int:
    return (3 if rigid else 3 * k) + int(solve_speed)


def _model(replies: Replies, apriori: np.ndarray, theta: np.ndarray, c0: float, rigid: bool, solve_speed: bool,
           legs: LegModel, twtt_sigma: float):
    """Residuals [m], Jacobian of the predicted path, variances [m²] and geometry at the unknowns ``theta``."""
    k = len(apriori)
    shift = theta[:3 * (1 if rigid else k)].reshape(-1, 3)
    position = apriori + shift if not rigid else apriori + shift[0]
    scale = theta[-1] if solve_speed else 1.0
    x = position[replies.transponder]
    l_tx, u_tx = legs.legs(replies.tx, x, replies.transponder)
    l_rx, u_rx = legs.legs(replies.rx, x, replies.transponder)
    c = scale * c0
    residual = c * replies.twtt - l_tx - l_rx
    g = u_tx + u_rx  # d(l_tx + l_rx)/dx
    n, p = len(replies), len(theta)
    jacobian = np.zeros((n, p))
    if rigid:
        jacobian[:, :3] = g
    else:
        for axis in range(3):
            jacobian[np.arange(n), 3 * replies.transponder + axis] = g[:, axis]
    if solve_speed:
        jacobian[:, -1] = -c0 * replies.twtt
    variance = _line_of_sight_variance(replies, x, u_tx, u_rx, c, twtt_sigma)
    return residual, jacobian, variance, position, c, x


__all__ = ["MAX_ITERATIONS", "OUTLIER_FACTOR_RANGE", "POSITION_TOLERANCE", "SCALE_TOLERANCE"]
