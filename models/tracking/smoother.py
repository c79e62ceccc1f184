"""The robust fixed-interval smoother: a track's maximum a-posteriori states with heavy-tailed times of arrival,
solved as the banded system it is (the Gauss-Newton driver: its starts screened, the step's line search, the stop).

Its parts: the problem and its sums over the arrivals (:mod:`~sblsim.models.tracking.smoother_cost`), the normal
equations and their banded solves (:mod:`~sblsim.models.tracking.smoother_system`), the covariances
(:mod:`~sblsim.models.tracking.smoother_covariance`).

References
----------
Baktoft et al. 2017 (YAPS: the state-space model fitted to every time of arrival); Lange, Little, Taylor, "Robust
statistical modeling using the t distribution", JASA 84(408), 1989; Bell, "The iterated Kalman smoother as a
Gauss-Newton method", SIAM J. Optim. 4(3), 1994.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.depth import checked_depth
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.smoother_cost import (
    ROBUST_DOF,
    _arrival_jacobians,
    _arrival_sums,
    _information,
    _Problem,
    _robust_terms,
    _trial_cost,
    _trial_sums,
)
from sblsim.models.tracking.smoother_covariance import _block_covariance, _survey_covariance
from sblsim.models.tracking.smoother_system import _damped_solve, _dense_blocks, _normal_blocks, _step_system

#: Gauss-Newton iterations of the robust smoother, at most (of the start it keeps, its screening steps among them).
ROBUST_ITERATIONS = 100


#: The weight from which the robust smoother counts an arrival as kept (not weighed down as an outlier): a
#: normalised residual within √(10 (ν + 1) − ν) ≈ 6.1 σ at ν = 3.
ROBUST_KEPT_WEIGHT = 0.1


#: The robust smoother stops when an iteration lowers its cost by less than this share: scipy's ``least_squares``'
#: default ``ftol`` (Virtanen et al., Nature Methods 17, 2020). At 10⁶ pings (a cost of about 7·10⁶) a step then
#: gains less than 0.07 of the negative log-likelihood and moves the track by micrometres; 10⁻⁹ took 33 steps there
#: against 18, for an RMS error the same to 1 µm (benchmarks/bench_tracking_scale.py).
ROBUST_TOLERANCE = 1e-8


#: Gauss-Newton iterations of each start before the robust smoother keeps the one of the lowest cost.
ROBUST_SCREEN = 20


#: The timing noise's scale of the robust smoother's graduated start (:func:`graduated_start`), in σ_toa.
ROBUST_COARSE_SCALE = 10.0


#: Gauss-Newton iterations of the graduated start's coarse solve.
ROBUST_COARSE_ITERATIONS = 20


@dataclass
class RobustTrack:
    """What :func:`robust_smooth` returns, over the pings it was given (m pings, state size s = 2 dim + 2).

    Attributes
    ----------
    x : ndarray, (m, s)
        The maximum a-posteriori states ``[p, v, t_e, Δ]`` [m, m/s, s, s].
    P : ndarray, (m, s, s), or None
        Their covariances (None when not asked for): the diagonal blocks of the inverse of the cost's Hessian at
        ``x`` (the Laplace approximation; each arrival's share its
        :func:`~sblsim.models.tracking.smoother_cost.observed_information`, the model's second derivatives left out
        as in Gauss-Newton).
    weights : ndarray, (m, n)
        Each time of arrival's weight at the end, ``(ν + 1) / (ν + z²)`` (1 for an arrival as expected, near 0
        for an outlier; 0 where not heard); with late arrivals modelled the EM weight ``(1 − γ) w_t + γ`` (a late
        arrival explained by its delay near 1).
    cost : float
        The cost at ``x`` (:func:`robust_smooth`) [1].
    iterations : int
        The Gauss-Newton iterations of the start kept.
    start : int
        Which of the starts given gave ``x`` (the lowest cost).
    start_names : tuple of str
        What each start was (:func:`robust_track`: ``fixes``, ``graduated``, ``rts``; empty when not named).
    P_lag : ndarray, (m − 1, s, s), or None
        The covariances of successive states, ``cov(x_k+1, x_k)`` (with ``P``; the lag-one blocks of the same
        inverse).
    converged : bool
        Whether the start kept stopped by itself (a step gaining less than :data:`ROBUST_TOLERANCE` of the cost, or
        none lowering it), not at the ``iterations`` allowed.
    """

    x: np.ndarray
    P: np.ndarray | None
    weights: np.ndarray
    cost: float
    iterations: int
    start: int
    start_names: tuple[str, ...] = ()
    P_lag: np.ndarray | None = None
    converged: bool = True



def robust_smooth(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, starts: list[np.ndarray],
                  dof: float = ROBUST_DOF, iterations: int = ROBUST_ITERATIONS, covariance: bool = True,
                  schedule: PingSchedule | None = None, depth: np.ndarray | None = None,
                  student_start: bool = True) -> RobustTrack:
    """The robust fixed-interval smoother: the track's maximum a-posteriori states with heavy-tailed times of arrival.

    Over the whole record at once (YAPS's approach, Baktoft et al. 2017: the state-space model fitted to every
    time of arrival, here its MAP rather than its marginal likelihood), the states ``x_k = [p, v, t_e, Δ]`` of
    :class:`ToaTracker` minimise

        ``Σ_k ‖L_k⁻¹ (x_k − f_k(x_k−1))‖² + Σ_(k,i) heard (ν + 1) ln(1 + z_ki² / ν) + ((Δ_0 − Δ) / σ_Δ)²``,
        ``z_ki = (toa_ki − t_e,k − ‖p_k − r_i‖ / c) / σ_toa``,

    (and, where the tag reads its depth, ``Σ_k ((z_k + depth_k) / σ_depth)²``: the receivers' z up, ``depth_sigma``
    of the settings), the tracker's motion model over each step of the ping schedule (``f_k``, ``Q_k = L_k L_kᵀ``
    over the step's duration at the nominal interval Δ, :mod:`sblsim.models.tracking.schedule`: the ping type,
    gaps), the filters' prior of the first interval (σ_Δ ``sigma_interval``) and a Student-t error of ν degrees of
    freedom for each time of arrival (σ_toa its scale): a late multipath arrival is weighed down where the rest of
    the track disagrees with it, with no gate and no restart. Gauss-Newton with iteratively reweighted least
    squares (weights ``(ν + 1) / (ν + z²)``, the EM weights of the Student-t; Lange, Little, Taylor, "Robust
    statistical modeling using the t distribution", JASA 84(408), 1989), the step halved until the cost falls,
    each step solved as the banded system it is (the normal matrix is block tridiagonal over the pings: the
    iterated Kalman smoother as a Gauss-Newton method, Bell, SIAM J. Optim. 4(3), 1994), the covariance by the
    block recursion (the Rauch-Tung-Striebel backward pass in information form) from the arrivals' observed
    information (:func:`~sblsim.models.tracking.smoother_cost.observed_information`), not their Gauss-Newton
    weights. The cost is not convex: each start given takes :data:`ROBUST_SCREEN` steps, and the one of the lowest
    cost then goes on to the end.

    With the settings' ``delay_share`` > 0 an arrival may also be late by an exponential delay (multipath: the
    mixture of :mod:`~sblsim.models.tracking.arrival_model`, its core's ν the settings' ``delay_dof``), each term
    ``(ν + 1) ln(1 + z²/ν)`` then that mixture's ``−2 ln p(z)`` (the same constant off), its Gauss-Newton weights the
    mixture's EM weights and its covariance the mixture's observed information; the Student-t's own minimum (this
    smoother with ``delay_share`` 0 from the same starts) is then screened as one more start.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
        The motion model, ``sound_speed``, ``sigma_toa`` and the nominal ``interval``.
    starts : list of ndarray, each (m, 2 dim + 2)
        Starting tracks (finite), e.g. the RTS smoother's states.
    dof : float
        ν.
    iterations : int
        Gauss-Newton iterations at most (of the start kept, its screening steps among them).
    covariance : bool
        Compute the covariance ``P`` (else None: a start's states alone, :func:`graduated_start`).
    schedule : PingSchedule, optional
        The steps between the rows (:class:`~sblsim.models.tracking.schedule.PingSchedule`, m − 1 steps; default
        one stable interval each).
    depth : ndarray, (m,), optional
        The tag's depth-sensor reading per ping [m], positive down, NaN where none (receivers in 3-D).
    student_start : bool
        With late arrivals modelled, screen the Student-t's own minimum as one more start (False: the starts given
        alone, e.g. starts already near a minimum of this cost).

    Returns
    -------
    RobustTrack
        With the settings' ``survey_sigma``, ``P`` holds the receivers' survey error as a consider covariance
        (:func:`~sblsim.models.tracking.smoother_covariance._survey_covariance`).

    Raises
    ------
    ModelError
        If no start is given, a start is not finite or of the wrong shape, or a depth is given with receivers in
        2-D.
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    m, (n, dim) = len(toa), receivers.shape
    s = 2 * dim + 2
    if not starts:
        raise ModelError("robust smoother: no starting track")
    if schedule is None:
        schedule = PingSchedule.stable(m, settings.interval, settings.jitter, settings.interval_drift)
    checked_depth(depth, m, dim)
    given = len(starts)
    if settings.delay_share > 0.0 and student_start:  # the Student-t's minimum one more start (the mixture's cost
        # is steep for early residuals: from a start far off, Gauss-Newton on it can stall where the Student-t's
        # does not)
        first = robust_smooth(toa, receivers, replace(settings, delay_share=0.0), starts, dof, iterations, False,
                              schedule, depth)
        starts = [*starts, first.x]
    problem = _Problem(toa, receivers, settings, schedule, depth)
    runs = []
    for start in starts:
        X = np.array(start, float)
        if X.shape != (m, s) or not np.isfinite(X).all():
            raise ModelError(f"robust smoother: a starting track of shape {X.shape} or not finite; allowed: "
                             f"({m}, {s}), finite")
        # a start's terms are made where its steps begin (its cost for the ranking with them)
        runs.append({"X": X, "cost": None, "done": 0, "converged": False})
    last = {"run": None, "terms": None}  # the terms at the states of the start that stepped last

    def iterate(run, count):
        """Up to ``count`` more Gauss-Newton steps of a start (stopping where it has converged); its cost known."""
        X = run["X"]
        if last["run"] is run:
            sums, e, T, cost = last["terms"]
        else:  # another start's terms no longer kept
            last.update(run=None, terms=None)
        if last["run"] is not run and (run["cost"] is None or not (run["converged"] or count <= 0)):
            sums, e, T, cost = _robust_terms(problem, X, dof)
            run["cost"] = cost
        if run["converged"] or count <= 0:
            return
        # a trial's process residuals, durations and states written into a second set of arrays, the two swapped when
        # a step is taken; its per-ping sums over the step's own (no longer needed once the step is solved)
        spare, trial = (sums, np.empty_like(e), np.empty_like(T)), np.empty_like(X)
        step = np.empty_like(X)
        for _ in range(count):
            if run["converged"]:
                break
            step = _damped_solve(problem, partial(_step_system, problem, X, sums, e, T), step)
            if step is None:  # no damping makes the system positive definite: stopped where it is
                run["converged"] = True
                break
            scale = 1.0
            while scale > 1e-6:  # each trial's cost alone, its sums for the next step where it is taken
                np.multiply(step, scale, out=trial)
                trial += X
                lower = _trial_cost(problem, trial, dof, spare)
                if lower < cost:
                    _trial_sums(problem, dof, sums)
                    terms = (*spare, lower)
                    break
                scale *= 0.5
            else:  # no step lowers the cost: a minimum
                run["converged"] = True
                break
            gain = cost - terms[-1]
            spare, (sums, e, T, cost) = (sums, e, T), terms  # the sums the same array in both
            X, trial = trial, X
            run.update(X=X, cost=cost, done=run["done"] + 1, converged=gain <= ROBUST_TOLERANCE * cost)
        last.update(run=run, terms=(sums, e, T, cost))

    # each start a few steps, then the one of the lowest cost to the end (the ranking of the starts' costs is
    # settled within a few steps)
    for run in runs:
        iterate(run, min(ROBUST_SCREEN, iterations))
    index = int(np.argmin([run["cost"] for run in runs]))
    best = runs[index]
    for run in runs:  # the other starts' states no longer needed
        if run is not best:
            run["X"] = None
    iterate(best, iterations - best["done"])
    last.update(run=None, terms=None)
    X, cost = best["X"], best["cost"]  # the cost at X (its residuals' own)
    w = np.empty(len(problem.k))
    sums = _arrival_sums(problem, X, dof, information=True, weights=w)  # the Gauss-Newton weights beside
    problem.band = problem.rhs = problem.logs = problem.values = problem.squares = None  # the steps' buffers
    problem.z = problem.J = problem.rows = None
    P, lag = _covariance(problem, X, sums, dof) if covariance else (None, None)
    weights = np.zeros((m, n))
    weights[problem.k, problem.i] = w
    return RobustTrack(X, P, weights, cost, best["done"], index if index < given else first.start, P_lag=lag,
                       converged=bool(best["converged"]))


def _covariance(problem: _Problem, X: np.ndarray, sums: np.ndarray, dof: float) -> tuple[np.ndarray, np.ndarray]:
    """:class:`RobustTrack`'s ``P`` (m, s, s) and ``P_lag`` (m − 1, s, s) at the states X (m, s): the diagonal and
    lag-one blocks of the inverse of the cost's Hessian from the arrivals' observed information ``sums`` (m, q)
    (:func:`~sblsim.models.tracking.smoother_cost._arrival_sums` with ``information``), the receivers' survey error
    added to ``P`` as a consider covariance where the problem's settings give one."""
    settings = problem.settings
    blocks = partial(_normal_blocks, problem, X, sums, problem.durations(X))
    P, lag = _block_covariance(*_dense_blocks(problem, blocks))
    if settings.survey_sigma is not None:
        z, Jz = _arrival_jacobians(problem, X)
        P += _survey_covariance(problem, *blocks(0, problem.m), _information(problem, z, dof), Jz,
                                np.asarray(settings.survey_sigma, float))
    return P, lag


def with_covariance(track: RobustTrack, toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings,
                    schedule: PingSchedule | None = None, depth: np.ndarray | None = None,
                    dof: float = ROBUST_DOF) -> RobustTrack:
    """A track :func:`robust_smooth` solved without its covariances (``covariance`` False) with them: ``P`` and
    ``P_lag`` at its states, the same numbers as :func:`robust_smooth` makes with ``covariance``. For a search that
    re-solves a record several times and keeps one answer (:func:`~sblsim.models.tracking.starts.robust_track`):
    the covariance made once, for the track kept, and no earlier track's (m, s, s) blocks held while it re-solves.

    Parameters
    ----------
    track : RobustTrack
        :func:`robust_smooth`'s answer (m pings).
    toa, receivers, settings, schedule, depth, dof
        As the track was solved with (:func:`robust_smooth`).

    Returns
    -------
    RobustTrack
        ``track`` with ``P`` and ``P_lag``.
    """
    toa = np.asarray(toa, float)
    if schedule is None:
        schedule = PingSchedule.stable(len(toa), settings.interval, settings.jitter, settings.interval_drift)
    problem = _Problem(toa, np.asarray(receivers, float), settings, schedule, depth)
    sums = _arrival_sums(problem, track.x, dof, information=True)
    problem.logs = problem.values = problem.squares = problem.z = problem.J = problem.rows = None  # the pass's buffers
    P, lag = _covariance(problem, track.x, sums, dof)
    return replace(track, P=P, P_lag=lag)


__all__ = ["ROBUST_COARSE_ITERATIONS", "ROBUST_COARSE_SCALE", "ROBUST_ITERATIONS", "ROBUST_KEPT_WEIGHT",
           "ROBUST_SCREEN", "ROBUST_TOLERANCE", "RobustTrack", "robust_smooth", "with_covariance"]
