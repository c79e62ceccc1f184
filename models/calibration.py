"""Calibration of seafloor transponders from the surface: positions from two-way travel times.

A surface transducer (a vessel's or a wave glider's, positioned by GNSS) interrogates seafloor transponders
and records each reply's two-way travel time (TWTT). The transducer moves between the transmission and the
reply, so one TWTT measures two legs,

.. math:: c\\,T_i = \\ell(\\mathbf p_{\\mathrm{tx},i}, \\mathbf x_j) + \\ell(\\mathbf x_j, \\mathbf p_{\\mathrm{rx},i}),

with :math:`T_i` the TWTT without the transponder's turnaround, :math:`c` the sound speed, :math:`\\mathbf x_j`
the replying transponder and :math:`\\ell` the acoustic path length of a leg at speed :math:`c` (for a straight
ray its length :math:`|\\mathbf p - \\mathbf x|`). :func:`solve` estimates the transponders' positions (each, or
one common rigid shift of a known array) and optionally a sound-speed scale :math:`s` (:math:`c = s\\,c_0`) by
weighted least squares (Gauss-Newton) of the range residuals :math:`v_i = s\\,c_0\\,T_i - \\ell_{\\mathrm{tx}} -
\\ell_{\\mathrm{rx}}` [m], with the weights of Xie et al. (2023): the transducer's GNSS 1-sigma projected on the
two lines of sight,

.. math:: \\sigma_i^2 = \\sum_{k\\in\\{e,n,u\\}} (u_{\\mathrm{tx},k}\\,\\sigma_{\\mathrm{tx},k})^2
          + (u_{\\mathrm{rx},k}\\,\\sigma_{\\mathrm{rx},k})^2 + (c\\,\\sigma_T)^2,

(:math:`\\mathbf u` the unit vectors of the legs; :math:`\\sigma_T` an optional TWTT noise, 0 in their work),
and their outlier rule: while the largest :math:`|v_i|` exceeds ``outlier_factor`` times the weighted RMS
:math:`\\sqrt{\\sum w_i v_i^2 / \\sum w_i}`, the reply (or replies) with it is dropped and the solution redone.
The covariance is :math:`(J^\\top W J)^{-1}` scaled by the a posteriori variance of unit weight
:math:`\\sum w_i v_i^2 / (n - p)`. Several solutions (time segments) combine as the authors combine them
(:func:`combine`): a weighted mean with weights one over the squared weighted RMS of the half residuals projected
on North, East and Up.

The leg model is a hook (:class:`StraightRay` is the straight ray at one speed, what Xie et al. use): any object
with a ``legs(points, x)`` method giving the path lengths [m] and their gradients with respect to ``x`` can
replace it, e.g. the eigenrays of a sound-speed profile (:mod:`sblsim.models.acoustics.rays`), times the
reference speed.

Frames: every position is local East, North, Up [m] of the survey's origin, in that column order.

Source: S. Xie, M. Zumberge, G. Sasagawa, D. Voytenko, "Shallow Water Seafloor Geodesy with Wave Glider-Based
GNSS-Acoustic Surveying of a Single Transponder", Earth and Space Science, 2023 (weights, outlier rule, segment
combination); the Gauss-Newton normal equations as in any geodetic adjustment (e.g. Strang & Borre, *Linear
Algebra, Geodesy, and GPS*, 1997, ch. 9).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from sblsim.models.declarations import ModelError

#: The sound speeds accepted [m/s].
SOUND_SPEED_RANGE = (1300.0, 1800.0)
#: The outlier factors accepted (times the weighted RMS).
OUTLIER_FACTOR_RANGE = (1.0, 100.0)
#: Gauss-Newton stops when no position moves more than this [m] (and the speed scale less than
#: :data:`SCALE_TOLERANCE`), or after :data:`MAX_ITERATIONS`.
POSITION_TOLERANCE = 1e-7
SCALE_TOLERANCE = 1e-10
MAX_ITERATIONS = 50


class LegModel(Protocol):
    """What :func:`solve` asks of the propagation: the acoustic path lengths of legs to a point."""

    def legs(self, points: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Path lengths [m] from ``points`` (n, 3) to ``x`` (n, 3) and their gradients w.r.t. ``x`` (n, 3)."""


class StraightRay:
    """A straight ray: a leg's path length is its length (the sound speed is :func:`solve`'s).

    Source: the straight-ray model of Xie et al. (2023), Section 2 (harmonic-mean sound speed).
    """

    def legs(self, points: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lengths and unit vectors of the legs.

        Parameters
        ----------
        points, x : numpy.ndarray, shape (n, 3)
            The legs' ends, local ENU [m].

        Returns
        -------
        length : numpy.ndarray, shape (n,)
            :math:`|\\mathbf x - \\mathbf p|` [m].
        gradient : numpy.ndarray, shape (n, 3)
            Its gradient with respect to ``x``, the unit vector from ``points`` to ``x`` [1].
        """
        d = x - points
        length = np.sqrt(np.sum(d * d, axis=1))
        return length, d / length[:, None]


@dataclass(frozen=True)
class Replies:
    """The replies of a survey as arrays (one row per reply), local ENU [m].

    Attributes
    ----------
    tx, rx : numpy.ndarray, shape (n, 3)
        The transducer at transmit and at the reply's receive time [m].
    tx_sigma, rx_sigma : numpy.ndarray, shape (n, 3)
        Their 1-sigma per axis [m], > 0.
    twtt : numpy.ndarray, shape (n,)
        Two-way travel time without the turnaround [s], > 0.
    transponder : numpy.ndarray of int, shape (n,)
        The replying transponder's index into the a-priori positions (replies are paired by identity).
    """

    tx: np.ndarray
    tx_sigma: np.ndarray
    rx: np.ndarray
    rx_sigma: np.ndarray
    twtt: np.ndarray
    transponder: np.ndarray

    def __len__(self) -> int:
        return len(self.twtt)

    def subset(self, rows: np.ndarray) -> Replies:
        """The replies at ``rows`` (indices or a boolean mask)."""
        return Replies(self.tx[rows], self.tx_sigma[rows], self.rx[rows], self.rx_sigma[rows], self.twtt[rows],
                       self.transponder[rows])


@dataclass
class Solution:
    """A calibration solution (:func:`solve`).

    Attributes
    ----------
    position : numpy.ndarray, shape (k, 3)
        The transponders' positions, local ENU [m].
    offset : numpy.ndarray, shape (k, 3)
        ``position`` minus the a-priori positions [m].
    sigma : numpy.ndarray, shape (k, 3)
        1-sigma of ``position`` per axis from the scaled covariance [m].
    covariance : numpy.ndarray, shape (p, p)
        Covariance of the unknowns (3 per transponder, or 3 for a rigid shift; then the speed scale) [m², 1].
    sound_speed : float
        The sound speed used (estimated when asked) [m/s].
    sound_speed_sigma : float
        Its 1-sigma [m/s] (0 when it was fixed).
    used : numpy.ndarray of bool, shape (n,)
        The replies kept by the outlier rule.
    residual_m : numpy.ndarray, shape (n,)
        :math:`s c_0 T - \\ell_{tx} - \\ell_{rx}` of every reply at the solution [m] (also the rejected ones).
    residual_s : numpy.ndarray, shape (n,)
        The same as a TWTT residual, ``residual_m / sound_speed`` [s].
    weight : numpy.ndarray, shape (n,)
        :math:`1/\\sigma_i^2` [1/m²].
    elevation : numpy.ndarray, shape (n,)
        Elevation of the receive point above the transponder's horizontal [rad].
    azimuth : numpy.ndarray, shape (n,)
        Azimuth of the receive point from the transponder, clockwise from North [rad].
    wrms_m : float
        Weighted RMS of the used residuals [m].
    variance_factor : float
        A posteriori variance of unit weight (1 when the weights are right).
    scatter : numpy.ndarray, shape (k, 3)
        Weighted RMS of the used half residuals projected on East, North, Up per transponder [m] (Xie et al.'s
        weights of the segment combination, :func:`combine`).
    iterations : int
        Gauss-Newton iterations of the last solution.
    converged : bool
        Whether the last solution met the tolerances within :data:`MAX_ITERATIONS`.
    """

    position: np.ndarray
    offset: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray
    sound_speed: float
    sound_speed_sigma: float
    used: np.ndarray
    residual_m: np.ndarray
    residual_s: np.ndarray
    weight: np.ndarray
    elevation: np.ndarray
    azimuth: np.ndarray
    wrms_m: float
    variance_factor: float
    scatter: np.ndarray
    iterations: int
    converged: bool


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
    l_tx, u_tx = legs.legs(replies.tx, x)
    l_rx, u_rx = legs.legs(replies.rx, x)
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


def _gauss_newton(replies: Replies, apriori: np.ndarray, theta: np.ndarray, c0: float, rigid: bool,
                  solve_speed: bool, legs: LegModel, twtt_sigma: float, what: str) -> tuple[np.ndarray, int, bool]:
    for iteration in range(1, MAX_ITERATIONS + 1):
        residual, jacobian, variance, *_ = _model(replies, apriori, theta, c0, rigid, solve_speed, legs, twtt_sigma)
        w = 1.0 / variance
        normal = jacobian.T @ (w[:, None] * jacobian)
        try:
            step = np.linalg.solve(normal, jacobian.T @ (w * residual))
        except np.linalg.LinAlgError:
            raise ModelError(f"{what}: the replies do not determine the unknowns (the normal matrix is singular): "
                             "more replies, from more directions, are needed") from None
        theta = theta + step
        moved = np.abs(step[:-1] if solve_speed else step)
        if np.max(moved) <= POSITION_TOLERANCE and (not solve_speed or abs(step[-1]) <= SCALE_TOLERANCE):
            return theta, iteration, True
    return theta, MAX_ITERATIONS, False


def solve(replies: Replies, apriori: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
          rigid: bool = False, solve_sound_speed: bool = False, outlier_factor: float | None = 3.0,
          twtt_sigma: float = 0.0, legs: LegModel | None = None, what: str = "calibration") -> Solution:
    """Transponder positions from two-way travel times by weighted least squares with the outlier rule.

    Parameters
    ----------
    replies : Replies
        The replies (n rows), paired with transponders by ``replies.transponder``.
    apriori : array_like, shape (k, 3)
        The transponders' a-priori positions, local ENU [m] (the start of Gauss-Newton; offsets are from them).
    sound_speed : float
        The sound speed :math:`c_0` [m/s], in :data:`SOUND_SPEED_RANGE`.
    rigid : bool
        Solve one common shift of all transponders (a known array) instead of each position.
    solve_sound_speed : bool
        Also estimate a sound-speed scale (the result's ``sound_speed`` is then estimated).
    outlier_factor : float or None
        Drop the reply with the largest absolute residual while it exceeds this many weighted RMS
        (:data:`OUTLIER_FACTOR_RANGE`); None keeps every reply.
    twtt_sigma : float
        A TWTT noise added to the weights [s], in [0, 1] (0: the GNSS sigmas only, as Xie et al.).
    legs : LegModel or None
        The propagation (default :class:`StraightRay`).
    what : str
        What errors name (e.g. the segment).

    Returns
    -------
    Solution

    Raises
    ------
    ModelError
        A value outside its range, fewer replies than unknowns + 1, or replies that do not determine the unknowns.
    """
    apriori = np.asarray(apriori, dtype=float)
    _check(replies, apriori, float(sound_speed), outlier_factor, float(twtt_sigma))
    legs = legs or StraightRay()
    k = len(apriori)
    p = _unknowns(k, rigid, solve_sound_speed)
    n = len(replies)
    if n <= p:
        raise ModelError(f"{what}: {n} replies for {p} unknowns; at least {p + 1} are needed")
    theta = np.zeros(p)
    if solve_sound_speed:
        theta[-1] = 1.0
    used = np.ones(n, dtype=bool)
    while True:
        subset = replies.subset(used)
        if used.sum() <= p:
            raise ModelError(f"{what}: the outlier rule left {int(used.sum())} replies for {p} unknowns")
        theta, iterations, converged = _gauss_newton(subset, apriori, theta, sound_speed, rigid, solve_sound_speed,
                                                     legs, twtt_sigma, what)
        residual, _, variance, _, _, _ = _model(subset, apriori, theta, sound_speed, rigid, solve_sound_speed, legs,
                                                twtt_sigma)
        w = 1.0 / variance
        wrms = float(np.sqrt(np.sum(w * residual**2) / np.sum(w)))
        worst = float(np.max(np.abs(residual)))
        if outlier_factor is None or used.sum() < 3 or worst <= outlier_factor * wrms:
            break
        rows = np.flatnonzero(used)
        used[rows[np.abs(residual) == worst]] = False
    residual, jacobian, variance, position, c, x = _model(replies, apriori, theta, sound_speed, rigid,
                                                          solve_sound_speed, legs, twtt_sigma)
    w = 1.0 / variance
    ju, ru, wu = jacobian[used], residual[used], w[used]
    q = np.linalg.inv(ju.T @ (wu[:, None] * ju))
    dof = int(used.sum()) - p
    factor = float(np.sum(wu * ru**2) / dof)
    covariance = q * factor
    sd = np.sqrt(np.diag(covariance))
    sigma = np.tile(sd[:3], (k, 1)) if rigid else sd[:3 * k].reshape(k, 3)
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
    return Solution(position=position, offset=position - apriori, sigma=sigma, covariance=covariance,
                    sound_speed=float(c), sound_speed_sigma=float(sound_speed * sd[-1]) if solve_sound_speed else 0.0,
                    used=used, residual_m=residual, residual_s=residual / c, weight=w, elevation=elevation,
                    azimuth=azimuth, wrms_m=wrms, variance_factor=factor, scatter=scatter, iterations=iterations,
                    converged=converged)


def crb(replies: Replies, positions: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
        rigid: bool = False, solve_sound_speed: bool = False, twtt_sigma: float = 0.0,
        legs: LegModel | None = None) -> np.ndarray:
    """The Cramér-Rao bound of a survey's unknowns: :math:`(J^\\top W J)^{-1}` at the truth.

    The Fisher information of the replies' range residuals (Gaussian, independent, variances
    :math:`\\sigma_i^2` of the line-of-sight projection of :func:`solve`) is :math:`J^\\top W J`, with
    :math:`J` the Jacobian of the two legs at the true positions and :math:`W = \\mathrm{diag}(1/\\sigma_i^2)`.
    Its inverse bounds the covariance of any unbiased estimator of the (static) transponders: for a static
    state the posterior CRB (PCRB) without a prior is this CRB.

    Parameters
    ----------
    replies : Replies
        The replies at the truth: the transducer's true transmit and receive positions [m], their 1-sigma [m]
        (the noise the positions carry), the true TWTTs [s] (used only with ``solve_sound_speed``).
    positions : array_like, shape (k, 3)
        The transponders' true positions, local ENU [m].
    sound_speed : float
        The true sound speed [m/s].
    rigid, solve_sound_speed, twtt_sigma, legs
        As :func:`solve` (``twtt_sigma``: the TWTT noise [s]).

    Returns
    -------
    numpy.ndarray, shape (p, p)
        The bound on the unknowns' covariance (3 per transponder, or 3 for a rigid shift; then the speed scale)
        [m², 1]. The horizontal bound of transponder j is ``sqrt(P[3j, 3j] + P[3j+1, 3j+1])`` [m].

    Raises
    ------
    ModelError
        A value outside its range, or replies that do not determine the unknowns (a singular information).

    Source: the CRB of a nonlinear least-squares problem with Gaussian noise, e.g. S. M. Kay, *Fundamentals of
    Statistical Signal Processing: Estimation Theory*, 1993, ch. 3; P. Tichavsky, C. H. Muravchik, A. Nehorai,
    "Posterior Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans. Signal Process. 46(5), 1998.
    """
    positions = np.asarray(positions, dtype=float)
    _check(replies, positions, float(sound_speed), None, float(twtt_sigma))
    theta = np.zeros(_unknowns(len(positions), rigid, solve_sound_speed))
    if solve_sound_speed:
        theta[-1] = 1.0
    _, jacobian, variance, *_ = _model(replies, positions, theta, float(sound_speed), rigid, solve_sound_speed,
                                       legs or StraightRay(), float(twtt_sigma))
    information = jacobian.T @ (jacobian / variance[:, None])
    try:
        return np.linalg.inv(information)
    except np.linalg.LinAlgError:
        raise ModelError("calibration: the replies do not determine the unknowns (the information is "
                         "singular)") from None


@dataclass(frozen=True)
class Combined:
    """Segment solutions combined (:func:`combine`), per transponder, local ENU [m].

    Attributes
    ----------
    position, sigma : numpy.ndarray, shape (k, 3)
        The weighted mean and its 1-sigma propagated from the segments' covariances (taken as independent) [m].
    scatter : numpy.ndarray, shape (k, 3)
        The weighted standard deviation of the segment solutions about the mean [m] (Xie et al.'s "std"); NaN
        with one segment.
    """

    position: np.ndarray
    sigma: np.ndarray
    scatter: np.ndarray


def combine(solutions: Sequence[Solution]) -> Combined:
    """Combine segment solutions as Xie et al. (2023) do: a weighted mean per axis, weights
    :math:`1/s_k^2` with :math:`s_k` the segment's projected residual RMS (:attr:`Solution.scatter`).

    Parameters
    ----------
    solutions : sequence of Solution
        The segments' solutions of the same transponders (at least one).

    Returns
    -------
    Combined

    Raises
    ------
    ModelError
        No solution.
    """
    if not solutions:
        raise ModelError("segments: no segment to combine")
    x = np.stack([s.position for s in solutions])  # (m, k, 3)
    sd = np.stack([s.sigma for s in solutions])
    w = 1.0 / np.stack([s.scatter for s in solutions]) ** 2
    total = np.sum(w, axis=0)
    mean = np.sum(w * x, axis=0) / total
    sigma = np.sqrt(np.sum(w**2 * sd**2, axis=0)) / total
    m = len(solutions)
    if m > 1:
        scatter = np.sqrt(np.sum(w * (x - mean) ** 2, axis=0) / ((m - 1) * total / m))
    else:
        scatter = np.full_like(mean, np.nan)
    return Combined(mean, sigma, scatter)


__all__ = ["Combined", "LegModel", "MAX_ITERATIONS", "OUTLIER_FACTOR_RANGE", "POSITION_TOLERANCE", "Replies",
           "SCALE_TOLERANCE", "SOUND_SPEED_RANGE", "Solution", "StraightRay", "combine", "crb", "solve"]
