"""The running solution (:func:`running`): the least-squares solution's measurement model as a static-state
Kalman filter, one scalar update per reply, and how far it ends from the least-squares solution
(:func:`running_disagreement`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from sblsim.models.calibration.legs import LegModel, StraightRay
from sblsim.models.calibration.measurement import MAX_ITERATIONS, POSITION_TOLERANCE, _check, _model, _unknowns
from sblsim.models.calibration.replies import Replies, Solution
from sblsim.models.declarations import ModelError

#: The running solution's prior 1-sigma of the a-priori positions accepted [m] and its default (wide against
#: the metre an a-priori position is usually off, not so wide that the first, far from linear, replies mislead).
PRIOR_SIGMA_RANGE = (1e-3, 1e4)
PRIOR_SIGMA_M = 10.0
#: The running solution's prior 1-sigma of the sound-speed scale [1] (0.1: 150 m/s at 1500 m/s).
PRIOR_SCALE_SIGMA = 0.1
#: The passes of the running solution accepted (1: the extended Kalman filter; more: re-linearised).
PASSES_RANGE = (1, 20)
#: The running solution's last positions agree with the least-squares solution of the same replies when no axis
#: differs by more than this many combined 1-sigma :math:`\sqrt{\sigma_{run}^2 + \sigma_{WLS}^2}` (the built-in
#: surveys stay within 2.2); farther, it did not converge from the prior (an a-priori position far outside
#: ``prior_sigma``) and its states are no solution (:func:`running_disagreement`).
RUNNING_AGREEMENT_SIGMA = 10.0


@dataclass
class Running:
    """The running solution (:func:`running`): the state after each reply.

    Attributes
    ----------
    state : numpy.ndarray, shape (n, p)
        The unknowns after each reply (3 per transponder, or 3 for a rigid shift, as offsets from the a-priori
        positions [m]; then the speed scale [1]).
    sigma : numpy.ndarray, shape (n, p)
        Their 1-sigma after each reply (the square roots of the covariance's diagonal) [m, 1].
    covariance : numpy.ndarray, shape (p, p)
        The covariance after the last reply [m², 1].
    position, position_sigma : numpy.ndarray, shape (n, k, 3)
        The transponders' positions (local ENU [m]) and their 1-sigma per axis [m] after each reply.
    innovation : numpy.ndarray, shape (n,)
        Each reply's innovation, the range residual :math:`s c_0 T - \\ell_{tx} - \\ell_{rx}` predicted by the
        state before it [m].
    innovation_variance : numpy.ndarray, shape (n,)
        Its variance :math:`S_i = H_i P_{i-1} H_i^\\top + \\sigma_i^2` [m²].
    nis : numpy.ndarray, shape (n,)
        The normalised innovation squared :math:`\\nu_i^2 / S_i` [1] (chi-square with 1 degree of freedom when the
        model and its noise are right).
    sound_speed : numpy.ndarray, shape (n,)
        The sound speed after each reply [m/s] (:math:`c_0` when it is not solved).
    passes : int
        The passes made (1: the extended Kalman filter).
    """

    state: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray
    position: np.ndarray
    position_sigma: np.ndarray
    innovation: np.ndarray
    innovation_variance: np.ndarray
    nis: np.ndarray
    sound_speed: np.ndarray
    passes: int


def running(replies: Replies, apriori: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
            rigid: bool = False, solve_sound_speed: bool = False, twtt_sigma: float = 0.0,
            legs: LegModel | None = None, prior_sigma: float = PRIOR_SIGMA_M, iterated: bool = True,
            passes: int = 1, what: str = "calibration") -> Running:
    """The running solution of :func:`solve`'s measurement model: a static-state Kalman filter, one scalar update
    per reply, in the replies' order.

    The state :math:`\\theta` is :func:`solve`'s unknowns (the offsets of each transponder, or one rigid shift,
    from the a-priori positions [m]; then the speed scale :math:`s`), static: no process noise. The prior is
    :math:`\\hat\\theta_0 = 0` (:math:`s = 1`) with covariance :math:`P_0 = \\mathrm{diag}(\\sigma_p^2, \\ldots,
    \\sigma_s^2)`, :math:`\\sigma_p` = ``prior_sigma`` and :math:`\\sigma_s` = :data:`PRIOR_SCALE_SIGMA`. Reply
    :math:`i` is one scalar update, linearised at the current estimate by the same leg model, Jacobian and
    line-of-sight variance as :func:`solve` (``_model``):

    .. math:: \\nu_i = s\\,c_0 T_i - \\ell_{tx} - \\ell_{rx}, \\quad S_i = H_i P_{i-1} H_i^\\top + \\sigma_i^2,
              \\quad K_i = P_{i-1} H_i^\\top / S_i,

    .. math:: \\hat\\theta_i = \\hat\\theta_{i-1} + K_i \\nu_i, \\quad
              P_i = (I - K_i H_i) P_{i-1} (I - K_i H_i)^\\top + K_i \\sigma_i^2 K_i^\\top

    (the Joseph form), with :math:`H_i` the Jacobian of the predicted path :math:`\\ell_{tx} + \\ell_{rx} - s c_0
    T_i`. ``iterated`` (the default) makes each update the iterated extended Kalman filter's: the update is
    re-linearised at its own result, :math:`\\theta^{(j+1)} = \\hat\\theta_{i-1} + K^{(j)} [\\nu(\\theta^{(j)}) -
    H^{(j)} (\\hat\\theta_{i-1} - \\theta^{(j)})]` with :math:`K^{(j)}, H^{(j)}, \\sigma_i^{(j)}` at
    :math:`\\theta^{(j)}`, until it moves less than :data:`POSITION_TOLERANCE` (Gauss-Newton on the prior and
    the one reply): with a prior metres wide the first replies are far from linear, and the plain extended filter
    (``iterated=False``) can lock onto a wrong point; the innovation and its variance are those at
    :math:`\\hat\\theta_{i-1}`. With a linear model this is recursive least squares: the last state is the
    weighted least-squares solution with the prior as one more observation. With ``passes`` > 1 the filter is run
    again from the same prior, each reply linearised at the previous pass's last state :math:`\\bar\\theta` (the
    innovation :math:`\\nu_i(\\bar\\theta) - H_i(\\hat\\theta_{i-1} - \\bar\\theta)`, the variance at
    :math:`\\bar\\theta`): each pass is one Gauss-Newton step of the batch problem with the prior, so the last
    state converges to :func:`solve`'s (to the prior's pull, :math:`\\sim\\sigma^2_{\\mathrm{WLS}}/\\sigma_p^2` of
    the offset); its running states are then no longer causal. No outlier rule: give it the replies :func:`solve` kept.

    Parameters
    ----------
    replies : Replies
        The replies (n rows), in the order they are taken (time).
    apriori : array_like, shape (k, 3)
        The a-priori positions, local ENU [m] (the prior's mean).
    sound_speed : float
        :math:`c_0` [m/s], in :data:`SOUND_SPEED_RANGE`.
    rigid, solve_sound_speed, twtt_sigma, legs, what
        As :func:`solve`.
    prior_sigma : float
        The prior 1-sigma of the a-priori positions per axis [m], in :data:`PRIOR_SIGMA_RANGE`.
    iterated : bool
        Iterate each update (the iterated extended Kalman filter); False: the extended Kalman filter.
    passes : int
        1: one causal pass; more: passes re-linearised at the previous pass's last state, in :data:`PASSES_RANGE`.

    Returns
    -------
    Running

    Raises
    ------
    ModelError
        A value outside its range, no reply, or a leg the leg model cannot trace.

    Source: Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
    Wiley, 2001: ch. 5 (the Kalman filter, the Joseph form, the NIS test), ch. 3.4 (recursive least squares as
    the static Kalman filter), ch. 10.3 (the extended and the iterated filters).
    """
    apriori = np.asarray(apriori, dtype=float)
    _check(replies, apriori, float(sound_speed), None, float(twtt_sigma))
    lo, hi = PRIOR_SIGMA_RANGE
    if isinstance(prior_sigma, bool) or not (np.isfinite(prior_sigma) and lo <= prior_sigma <= hi):
        raise ModelError(f"prior_sigma_m: {prior_sigma!r} is outside the allowed range [{lo:g}, {hi:g}] m")
    lo, hi = PASSES_RANGE
    if isinstance(passes, bool) or not isinstance(passes, (int, np.integer)) or not lo <= passes <= hi:
        raise ModelError(f"passes: {passes!r} is outside the allowed range [{lo}, {hi}]")
    if len(replies) == 0:
        raise ModelError(f"{what}: no reply for the running solution")
    legs = legs or StraightRay()
    k = len(apriori)
    p = _unknowns(k, rigid, solve_sound_speed)
    n = len(replies)
    prior = np.zeros(p)
    p0 = np.full(p, float(prior_sigma) ** 2)
    if solve_sound_speed:
        prior[-1] = 1.0
        p0[-1] = PRIOR_SCALE_SIGMA**2
    reference = None
    for _ in range(passes):
        theta, cov = prior.copy(), np.diag(p0)
        states, sigmas = np.zeros((n, p)), np.zeros((n, p))
        innovation, variance_s = np.zeros(n), np.zeros(n)
        eye = np.eye(p)
        for i in range(n):
            one = replies.subset(np.array([i]))
            at = theta if reference is None else reference
            for iteration in range(MAX_ITERATIONS if iterated and reference is None else 1):
                residual, jacobian, variance, *_ = _model(one, apriori, at, float(sound_speed), rigid,
                                                          solve_sound_speed, legs, float(twtt_sigma))
                h = jacobian[0]
                nu = residual[0] - h @ (theta - at)  # the innovation linearised at ``at``
                ph = cov @ h
                s = float(h @ ph + variance[0])
                gain = ph / s
                if iteration == 0:
                    innovation[i], variance_s[i] = nu, s
                updated = theta + gain * nu
                step = np.abs(updated - at)
                at = updated
                if np.max(step[:-1] if solve_sound_speed else step) <= POSITION_TOLERANCE:
                    break
            theta = at
            a = eye - np.outer(gain, h)
            cov = a @ cov @ a.T + variance[0] * np.outer(gain, gain)
            # noise-free replies (sigma 0) leave round-off below zero on the diagonal: a sigma of 0
            states[i], sigmas[i] = theta, np.sqrt(np.clip(np.diag(cov), 0.0, None))
        reference = theta
    if rigid:
        offset = np.repeat(states[:, None, :3], k, axis=1)
        offset_sigma = np.repeat(sigmas[:, None, :3], k, axis=1)
    else:
        offset = states[:, :3 * k].reshape(n, k, 3)
        offset_sigma = sigmas[:, :3 * k].reshape(n, k, 3)
    speed = float(sound_speed) * (states[:, -1] if solve_sound_speed else np.ones(n))
    return Running(state=states, sigma=sigmas, covariance=cov, position=apriori[None] + offset,
                   position_sigma=offset_sigma, innovation=innovation, innovation_variance=variance_s,
                   nis=innovation**2 / variance_s, sound_speed=speed, passes=int(passes))


def running_disagreement(run: Running, solution: Solution) -> tuple[np.ndarray, np.ndarray]:
    """How far the running solution ends from the least-squares solution of the same replies, per transponder.

    Parameters
    ----------
    run : Running
        :func:`running` of the replies :func:`solve` kept.
    solution : Solution
        :func:`solve`'s solution.

    Returns
    -------
    distance : numpy.ndarray, shape (k,)
        From the running solution's last position to the least-squares position [m].
    sigmas : numpy.ndarray, shape (k,)
        The largest per-axis difference in combined 1-sigma :math:`\\sqrt{\\sigma_{run}^2 + \\sigma_{WLS}^2}` [1]
        (above :data:`RUNNING_AGREEMENT_SIGMA`: the running solution did not converge).
    """
    difference = run.position[-1] - solution.position
    combined = np.sqrt(run.position_sigma[-1] ** 2 + solution.sigma ** 2)
    scaled = np.divide(np.abs(difference), combined, out=np.full_like(difference, np.inf), where=combined > 0.0)
    scaled[difference == 0.0] = 0.0
    return np.linalg.norm(difference, axis=1), np.max(scaled, axis=1)


__all__ = ["PASSES_RANGE", "PRIOR_SCALE_SIGMA", "PRIOR_SIGMA_M", "PRIOR_SIGMA_RANGE", "RUNNING_AGREEMENT_SIGMA",
           "Running", "running", "running_disagreement"]
