"""The array solution: the transponders' positions (and a sound-speed scale) by weighted least squares,
Gauss-Newton with Xie et al.'s outlier rule.

:func:`solve` is the package's solver: its model, weights, outlier rule and covariance are described in
:mod:`sblsim.models.calibration`; given a :class:`~sblsim.models.calibration.replies.Perturbation` it solves the
moving ocean with the positions (:mod:`sblsim.models.calibration.ocean`).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from sblsim.models.calibration.determination import check_determination, determination
from sblsim.models.calibration.legs import SOUND_SPEED_RANGE, LegModel, StraightRay
from sblsim.models.calibration.measurement import (
    MAX_ITERATIONS,
    POSITION_TOLERANCE,
    SCALE_TOLERANCE,
    _check,
    _directions,
    _model,
    _unknowns,
)
from sblsim.models.calibration.ocean import SEPARATE, Step, _check_perturbation, _solve_perturbed
from sblsim.models.calibration.replies import Perturbation, Replies, Solution
from sblsim.models.declarations import ModelError

#: A solved sound speed (``solve_sound_speed``) must lie in :data:`SOUND_SPEED_RANGE` (sea water's physical range)
#: with a 1-sigma of at most this [m/s]; otherwise the replies do not determine it (e.g. a circle at one
#: radius: every reply at one elevation angle, so that depth and speed trade one for the other) and the solution
#: is refused. Surveys that determine it give 0.05-1 m/s (NCL1, Xie et al.'s days, a box or figure-eight).
MAX_SOUND_SPEED_SIGMA = 10.0
#: The largest condition number of the normal matrix scaled to a unit diagonal with which a solved sound speed is
#: taken as determined (surveys that determine it: 10² to 10³; a noise-free circle at one radius: 10¹⁵).
MAX_SCALED_CONDITION = 1e12


def _check_solved_speed(speed: float, sigma: float, what: str) -> None:
    """Refuse a solved sound speed outside the physical range or not determined by the replies
    (:data:`MAX_SOUND_SPEED_SIGMA`)."""
    lo, hi = SOUND_SPEED_RANGE
    if np.isfinite(speed) and np.isfinite(sigma) and lo <= speed <= hi and sigma <= MAX_SOUND_SPEED_SIGMA:
        return
    raise ModelError(f"solve_sound_speed: the replies of {what} do not determine the sound speed: its estimate "
                     f"{speed:.6g} m/s (1-sigma {sigma:.3g} m/s) must lie in the physical range [{lo:g}, {hi:g}] m/s "
                     f"with a 1-sigma of at most {MAX_SOUND_SPEED_SIGMA:g} m/s (replies at one elevation angle, e.g. a "
                     "circle at one radius, cannot separate depth from speed): give the sound speed and solve it "
                     "false, or survey at several distances")


def _gauss_newton(replies: Replies, apriori: np.ndarray, theta: np.ndarray, c0: float, rigid: bool,
                  solve_speed: bool, legs: LegModel, twtt_sigma: float, what: str) -> tuple[np.ndarray, int, bool]:
    for iteration in range(1, MAX_ITERATIONS + 1):
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging step overflows: stopped here
            residual, jacobian, variance, *_ = _model(replies, apriori, theta, c0, rigid, solve_speed, legs,
                                                      twtt_sigma)
        if not (np.all(np.isfinite(residual)) and np.all(np.isfinite(jacobian))):
            return theta, iteration, False  # diverged: the caller's outlier rule, or its refusal
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
          twtt_sigma: float = 0.0, legs: LegModel | None = None, what: str = "calibration",
          perturbation: Perturbation | None = None, progress: Step | None = None) -> Solution:
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
    perturbation : Perturbation or None
        Solve a sound-speed perturbation in time with the positions (:class:`Perturbation`; the replies need their
        times): the residuals, weights and statistics are then the perturbation's (SeaGap's nadir-normalised
        time with equal weights, or GARPOS's log time with its covariance and prior), the outlier rule judges the
        TWTT residuals [s] against their RMS, ``twtt_sigma`` is not used. None: the model above.
    progress : callable or None
        ``progress(1)`` after each Gauss-Newton iteration of a perturbation's solve (a report of the work, which
        also lets a Ctrl-C through between iterations).

    Returns
    -------
    Solution

    Raises
    ------
    ModelError
        A value outside its range, fewer replies than unknowns + 1, more bases than the replies' pings determine
        (:func:`~sblsim.models.calibration.ocean.bases_of`), or replies that do not determine the unknowns
        (with ``solve_sound_speed``: a sound speed outside :data:`SOUND_SPEED_RANGE` or with a 1-sigma above
        :data:`MAX_SOUND_SPEED_SIGMA`).
    """
    solution = _solve(replies, apriori, sound_speed, rigid=rigid, solve_sound_speed=solve_sound_speed,
                      outlier_factor=outlier_factor, twtt_sigma=twtt_sigma, legs=legs, what=what,
                      perturbation=perturbation, progress=progress)
    judge(solution, what)
    return solution


def judge(solution: Solution, what: str) -> None:
    """Refuse a solution that did not converge or whose unknowns the survey cannot separate
    (:func:`~sblsim.models.calibration.determination.check_determination`; a least-squares solution without a
    perturbation only for its convergence and its rank: its speed scale has its own rule,
    :data:`MAX_SOUND_SPEED_SIGMA`).

    Raises
    ------
    ModelError
        One line naming what cannot be separated and the survey that would separate it.
    """
    det = solution.determination
    if det is None:
        return
    if solution.perturbation is not None:
        check_determination(det, what, SEPARATE)
    elif not det.converged:
        check_determination(det, what, "more replies, from more directions, or a-priori positions nearer the truth")


def _solve(replies: Replies, apriori: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
           rigid: bool = False, solve_sound_speed: bool = False, outlier_factor: float | None = 3.0,
           twtt_sigma: float = 0.0, legs: LegModel | None = None, what: str = "calibration",
           perturbation: Perturbation | None = None, progress: Step | None = None) -> Solution:
    """:func:`solve` without :func:`judge` (a search's first candidate, judged once chosen)."""
    apriori = np.asarray(apriori, dtype=float)
    _check(replies, apriori, float(sound_speed), outlier_factor, float(twtt_sigma))
    legs = legs or StraightRay()
    if perturbation is not None:
        _check_perturbation(perturbation, replies, solve_sound_speed)
        return _solve_perturbed(replies, apriori, float(sound_speed), rigid, legs, perturbation, outlier_factor, what,
                                progress=progress)
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
        start = theta
        try:
            theta, iterations, converged = _gauss_newton(subset, apriori, start, sound_speed, rigid,
                                                         solve_sound_speed, legs, twtt_sigma, what)
        except ModelError:
            if outlier_factor is None:
                raise
            converged = False
        if not converged and outlier_factor is not None and used.sum() > p + 1:
            # Gauss-Newton diverged (a gross outlier): as Xie et al.'s script, judge the replies after one step
            # from the start, drop the worst and solve again from the start
            residual, jacobian, variance, *_ = _model(subset, apriori, start, sound_speed, rigid, solve_sound_speed,
                                                      legs, twtt_sigma)
            w = 1.0 / variance
            try:
                one = start + np.linalg.solve(jacobian.T @ (w[:, None] * jacobian), jacobian.T @ (w * residual))
            except np.linalg.LinAlgError:
                raise ModelError(f"{what}: the replies do not determine the unknowns (the normal matrix is "
                                 "singular): more replies, from more directions, are needed") from None
            residual = _model(subset, apriori, one, sound_speed, rigid, solve_sound_speed, legs, twtt_sigma)[0]
            rows = np.flatnonzero(used)
            used[rows[np.abs(residual) == np.max(np.abs(residual))]] = False
            theta = start
            continue
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
    normal = ju.T @ (wu[:, None] * ju)
    q = np.linalg.inv(normal)
    dof = int(used.sum()) - p
    factor = float(np.sum(wu * ru**2) / dof)
    covariance = q * factor
    variance = np.diag(covariance)
    if solve_sound_speed:  # a numerically singular normal matrix (a negative variance, or noise-free replies that
        # leave its scaled condition number beyond MAX_SCALED_CONDITION with a residual of zero): no sigma, refused
        scale = np.sqrt(np.diag(normal))
        singular = np.linalg.cond(normal / np.outer(scale, scale)) > MAX_SCALED_CONDITION
        speed_sigma = sound_speed * np.sqrt(variance[-1]) if variance[-1] >= 0.0 and not singular else np.nan
        _check_solved_speed(float(c), float(speed_sigma), what)
    if not np.all(variance >= 0.0):  # born of a numerically singular normal matrix: refused, never a NaN sigma
        raise ModelError(f"{what}: the replies do not determine the positions (a negative variance: the normal "
                         "matrix is numerically singular): more replies, from more directions, are needed")
    sd = np.sqrt(variance)
    det = determination(normal, 3 if rigid else 3 * k, ["sound-speed scale"] if solve_sound_speed else [], rigid,
                        converged, iterations)
    sigma = np.tile(sd[:3], (k, 1)) if rigid else sd[:3 * k].reshape(k, 3)
    elevation, azimuth, scatter = _directions(replies, x, residual, w, used, k)
    return Solution(position=position, offset=position - apriori, sigma=sigma, covariance=covariance,
                    sound_speed=float(c), sound_speed_sigma=float(sound_speed * sd[-1]) if solve_sound_speed else 0.0,
                    used=used, residual_m=residual, residual_s=residual / c, weight=w, elevation=elevation,
                    azimuth=azimuth, wrms_m=wrms, variance_factor=factor, scatter=scatter, iterations=iterations,
                    converged=converged, determination=det)


__all__ = ["MAX_SCALED_CONDITION", "MAX_SOUND_SPEED_SIGMA", "judge", "solve"]
