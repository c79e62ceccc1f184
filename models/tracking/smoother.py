"""The robust fixed-interval smoother: a track's maximum a-posteriori states with heavy-tailed times of arrival,
solved as the banded system it is.

References
----------
Baktoft et al. 2017 (YAPS: the state-space model fitted to every time of arrival); Lange, Little, Taylor, "Robust
statistical modeling using the t distribution", JASA 84(408), 1989; Bell, "The iterated Kalman smoother as a
Gauss-Newton method", SIAM J. Optim. 4(3), 1994.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solveh_banded

from sblsim.models.declarations import ModelError
from sblsim.models.receiver.toa_bound import predict, process_noise
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.toa import _evaluate_arrivals

#: Degrees of freedom of the Student-t error of a time of arrival in the robust smoother (:func:`robust_smooth`): a
#: heavy tail (a late multipath arrival 10 σ off weighs 4 / 103 of a good one), the common robust choice (Lange,
#: Little, Taylor 1989).
ROBUST_DOF = 3.0


#: Gauss-Newton iterations of the robust smoother, at most (of the start it keeps, its screening steps among them).
ROBUST_ITERATIONS = 100


#: The weight from which the robust smoother counts an arrival as kept (not weighed down as an outlier): a
#: normalised residual within √(10 (ν + 1) − ν) ≈ 6.1 σ at ν = 3.
ROBUST_KEPT_WEIGHT = 0.1


#: The robust smoother stops when an iteration lowers its cost by less than this share.
ROBUST_TOLERANCE = 1e-9


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
        ``x`` (the Laplace approximation; each arrival's share its :func:`observed_information`, the model's
        second derivatives left out as in Gauss-Newton).
    weights : ndarray, (m, n)
        Each time of arrival's weight at the end, ``(ν + 1) / (ν + z²)`` (1 for an arrival as expected, near 0
        for an outlier; 0 where not heard).
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
    """

    x: np.ndarray
    P: np.ndarray | None
    weights: np.ndarray
    cost: float
    iterations: int
    start: int
    start_names: tuple[str, ...] = ()
    P_lag: np.ndarray | None = None


def observed_information(z: np.ndarray, dof: float = ROBUST_DOF) -> np.ndarray:
    """Each time of arrival's share of the robust smoother's observed information, its Student-t log-likelihood's
    second derivative: ``(ν + 1) (ν − z²) / (ν + z²)²`` [1], and 0 where that is negative (``|z| > √ν``).

    The Gauss-Newton weight ``(ν + 1) / (ν + z²)`` is the same at ``z = 0`` and larger everywhere else: over
    Student-t errors it is 1 on average against the observed information's ``(ν + 1) / (ν + 3)`` (2/3 at ν = 3, the
    Fisher information of the t's location: Lange, Little, Taylor 1989), so a covariance from those weights is too
    small by a third (a NEES 1.5 times too large). Clipped at 0: an arrival that the track disagrees with by more
    than √ν σ adds no information (it would make the Hessian indefinite).

    Parameters
    ----------
    z : ndarray, (h,)
        The arrivals' normalised residuals [1].
    dof : float
        ν.

    Returns
    -------
    ndarray, (h,)
    """
    return np.maximum((dof + 1.0) * (dof - z**2) / (dof + z**2) ** 2, 0.0)


def _process(settings: TrackerSettings, dim: int, schedule: PingSchedule) -> np.ndarray:
    """The inverses of the Cholesky factors of the tracker's process noise Q_k over each step of ``schedule`` at the
    nominal interval (:func:`~sblsim.models.receiver.toa_bound.process_noise`): (m − 1, s, s)."""
    Q = process_noise(schedule.steps(settings.interval), settings.acceleration_psd, schedule.te_sigma,
                      schedule.drift_sigma, dim)
    return np.linalg.inv(np.linalg.cholesky(Q))


def _interval_prior(settings: TrackerSettings, X: np.ndarray) -> float:
    """The first ping's interval's normalised distance from the nominal one, ``(Δ_0 − Δ) / σ_Δ`` (the filters'
    start, :meth:`ToaTracker.initial`)."""
    return float((X[0, -1] - settings.interval) / settings.sigma_interval)


def _robust_terms(toa, heard, receivers, settings, X, Li, dof, schedule):
    """The robust smoother's residuals at the states X (m, s): the arrivals' normalised ones z (h,), the weights
    (h,), the TOA Jacobians (h, dim + 1) [1/σ units], the whitened process residuals e (m − 1, s) and the
    transitions' Jacobians F (m − 1, s, s); and the cost."""
    dim = receivers.shape[1]
    k, i = heard
    model, J = _evaluate_arrivals(receivers[i], settings.sound_speed, X[k, :dim], X[k, -2])
    z = (toa[k, i] - model) / settings.sigma_toa
    Jz = -J / settings.sigma_toa
    predicted, F = predict(X[:-1], dim, schedule.count, schedule.offset)
    e = np.einsum("kij,kj->ki", Li, X[1:] - predicted)
    cost = float((dof + 1.0) * np.log1p(z**2 / dof).sum() + (e**2).sum() + _interval_prior(settings, X) ** 2)
    return z, (dof + 1.0) / (dof + z**2), Jz, e, F, cost


def _per_ping(m: int, pings: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The sums of ``values`` (h, ...) per ping of the arrivals ``pings`` (h,), sorted (as :func:`numpy.nonzero`
    gives them): (m, ...), 0 for a ping none arrived from."""
    out = np.zeros((m,) + values.shape[1:])
    if len(pings):
        first = np.flatnonzero(np.r_[True, pings[1:] != pings[:-1]])
        out[pings[first]] = np.add.reduceat(values, first, axis=0)
    return out


def _normal_blocks(m, s, dim, heard, w, Jz, Li, prev, settings):
    """The Gauss-Newton Hessian of the robust cost, block tridiagonal: diagonal blocks (m, s, s) and the blocks
    (k, k + 1) (m − 1, s, s); ``Li`` (m − 1, s, s) the steps' whitening, ``prev`` (m − 1, s, s) the whitened process
    residuals' Jacobians with respect to the previous state, ``−L_k⁻¹ F_k``; the first interval's prior."""
    D = np.zeros((m, s, s))
    cols = list(range(dim)) + [s - 2]
    outer = w[:, None, None] * Jz[:, :, None] * Jz[:, None, :]
    D[np.ix_(np.arange(m), cols, cols)] += _per_ping(m, heard[0], outer)
    # e_k's Jacobian with respect to x_k is L_k⁻¹, with respect to x_k−1 is −L_k⁻¹ F_k
    D[1:] += np.einsum("kji,kjl->kil", Li, Li)
    D[:-1] += np.einsum("kji,kjl->kil", prev, prev)
    D[0, -1, -1] += 1.0 / settings.sigma_interval**2
    B = np.einsum("kji,kjl->kil", prev, Li)
    return D, B


def _banded_solve(D, B, g):
    """Solve ``N δ = g`` for the symmetric positive definite block-tridiagonal N (diagonal blocks D (m, s, s), upper
    blocks B (m − 1, s, s)) by LAPACK's banded Cholesky (:func:`scipy.linalg.solveh_banded`); δ (m, s)."""
    m, s = D.shape[:2]
    u = 2 * s - 1
    ab = np.zeros((u + 1, m * s))
    starts = np.arange(m) * s
    for a in range(s):
        for b in range(a, s):
            ab[u + a - b, starts + b] = D[:, a, b]
        for b in range(s):
            ab[u + a - s - b, starts[1:] + b] = B[:, a, b]
    return solveh_banded(ab, g.ravel()).reshape(m, s)


def _damped_solve(D, B, g):
    """:func:`_banded_solve` of the Gauss-Newton step, damped where the system is numerically indefinite (a track far
    from its arrivals, each weighed down to nothing): ``μ diag(N)`` added (Levenberg–Marquardt; Nocedal & Wright,
    *Numerical Optimization*, Springer 2006, § 10.3), μ from 10⁻¹² up by tenfold steps to 1 after an undamped try;
    None if none holds."""
    s = D.shape[1]
    diagonal = np.einsum("kii->ki", D)
    for mu in [None, *10.0 ** np.arange(-12, 1)]:  # first undamped (a 10⁻¹² ridge)
        damped = D + 1e-12 * np.eye(s) if mu is None else D + np.einsum("ki,ij->kij", mu * (diagonal + 1.0), np.eye(s))
        try:
            step = _banded_solve(damped, B, g)
        except np.linalg.LinAlgError:
            continue
        if np.isfinite(step).all():
            return step
    return None


def _inverse(a: np.ndarray) -> np.ndarray:
    """The inverse of a block, its pseudo-inverse where it is singular."""
    try:
        return np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(a)


def _block_covariance(D, B, lag=False):
    """The diagonal blocks (m, s, s) of N⁻¹ for the block-tridiagonal N of :func:`_banded_solve` (the block
    elimination and its backward pass: the Rauch-Tung-Striebel recursion in information form); with ``lag`` also
    its blocks (k + 1, k) (m − 1, s, s), ``−(S_k⁻¹ B_k N⁻¹_k+1,k+1)ᵀ``."""
    m = len(D)
    Sinv = np.empty_like(D)
    Sinv[0] = _inverse(D[0])
    for k in range(1, m):
        Sinv[k] = _inverse(D[k] - B[k - 1].T @ Sinv[k - 1] @ B[k - 1])
    cov = np.empty_like(D)
    cross = np.empty((max(m - 1, 0),) + D.shape[1:])
    cov[-1] = Sinv[-1]
    for k in range(m - 2, -1, -1):
        G = Sinv[k] @ B[k]
        cross[k] = -(G @ cov[k + 1]).T
        cov[k] = Sinv[k] + G @ cov[k + 1] @ G.T
    cov = 0.5 * (cov + cov.transpose(0, 2, 1))
    return (cov, cross) if lag else cov


def robust_smooth(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, starts: list[np.ndarray],
                  dof: float = ROBUST_DOF, iterations: int = ROBUST_ITERATIONS, covariance: bool = True,
                  schedule: PingSchedule | None = None) -> RobustTrack:
    """The robust fixed-interval smoother: the track's maximum a-posteriori states with heavy-tailed times of arrival.

    Over the whole record at once (YAPS's approach, Baktoft et al. 2017: the state-space model fitted to every
    time of arrival, here its MAP rather than its marginal likelihood), the states ``x_k = [p, v, t_e, Δ]`` of
    :class:`ToaTracker` minimise

        ``Σ_k ‖L_k⁻¹ (x_k − f_k(x_k−1))‖² + Σ_(k,i) heard (ν + 1) ln(1 + z_ki² / ν) + ((Δ_0 − Δ) / σ_Δ)²``,
        ``z_ki = (toa_ki − t_e,k − ‖p_k − r_i‖ / c) / σ_toa``,

    the tracker's motion model over each step of the ping schedule (``f_k``, ``Q_k = L_k L_kᵀ`` over the step's
    duration at the nominal interval Δ, :mod:`sblsim.models.tracking.schedule`: the ping type, gaps), the filters'
    prior of the first interval (σ_Δ ``sigma_interval``) and a Student-t error of ν degrees of
    freedom for each time of arrival (σ_toa its scale): a late multipath arrival is weighed down where the rest of
    the track disagrees with it, with no gate and no restart. Gauss-Newton with iteratively reweighted least
    squares (weights ``(ν + 1) / (ν + z²)``, the EM weights of the Student-t; Lange, Little, Taylor, "Robust
    statistical modeling using the t distribution", JASA 84(408), 1989), the step halved until the cost falls,
    each step solved as the banded system it is (the normal matrix is block tridiagonal over the pings: the
    iterated Kalman smoother as a Gauss-Newton method, Bell, SIAM J. Optim. 4(3), 1994), the covariance by the
    block recursion (the Rauch-Tung-Striebel backward pass in information form) from the arrivals' observed
    information (:func:`observed_information`), not their Gauss-Newton weights. The cost is not convex: each
    start given takes :data:`ROBUST_SCREEN` steps, and the one of the lowest cost then goes on to the end.

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

    Returns
    -------
    RobustTrack

    Raises
    ------
    ModelError
        If no start is given, a start is not finite or of the wrong shape.
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    m, (n, dim) = len(toa), receivers.shape
    s = 2 * dim + 2
    if not starts:
        raise ModelError("robust smoother: no starting track")
    heard = np.nonzero(np.isfinite(toa))
    if schedule is None:
        schedule = PingSchedule.stable(m, settings.interval, settings.jitter, settings.interval_drift)
    Li = _process(settings, dim, schedule)
    runs = []
    for start in starts:
        X = np.array(start, float)
        if X.shape != (m, s) or not np.isfinite(X).all():
            raise ModelError(f"robust smoother: a starting track of shape {X.shape} or not finite; allowed: "
                             f"({m}, {s}), finite")
        runs.append({"X": X, "terms": _robust_terms(toa, heard, receivers, settings, X, Li, dof, schedule),
                     "done": 0,
                     "converged": False})

    def iterate(run, count):
        """Up to ``count`` more Gauss-Newton steps of a start (stopping where it has converged)."""
        X, (z, w, Jz, e, F, cost) = run["X"], run["terms"]
        for _ in range(count):
            if run["converged"]:
                return
            prev = -np.einsum("kij,kjl->kil", Li, F)
            D, B = _normal_blocks(m, s, dim, heard, w, Jz, Li, prev, settings)
            g = np.zeros((m, s))  # the gradient's half: Jᵀ W r
            g[:, list(range(dim)) + [s - 2]] += _per_ping(m, heard[0], (w * z)[:, None] * Jz)
            g[1:] += np.einsum("ki,kij->kj", e, Li)
            g[0, -1] += _interval_prior(settings, X) / settings.sigma_interval
            g[:-1] += np.einsum("kji,kj->ki", prev, e)
            step = _damped_solve(D, B, -g)
            if step is None:  # no damping makes the system positive definite: stopped where it is
                run["converged"] = True
                return
            scale = 1.0
            while scale > 1e-6:
                trial = X + scale * step
                terms = _robust_terms(toa, heard, receivers, settings, trial, Li, dof, schedule)
                if terms[-1] < cost:
                    break
                scale *= 0.5
            else:  # no step lowers the cost: a minimum
                run["converged"] = True
                return
            gain = cost - terms[-1]
            X, (z, w, Jz, e, F, cost) = trial, terms
            run.update(X=X, terms=terms, done=run["done"] + 1, converged=gain <= ROBUST_TOLERANCE * cost)

    # each start a few steps, then the one of the lowest cost to the end (the ranking of the starts' costs is
    # settled within a few steps)
    for run in runs:
        iterate(run, min(ROBUST_SCREEN, iterations))
    index = int(np.argmin([run["terms"][-1] for run in runs]))
    best = runs[index]
    iterate(best, iterations - best["done"])
    X, (z, w, Jz, _, F, cost) = best["X"], best["terms"]
    P = lag = None
    if covariance:
        P, lag = _block_covariance(*_normal_blocks(m, s, dim, heard, observed_information(z, dof), Jz, Li,
                                                   -np.einsum("kij,kjl->kil", Li, F), settings), lag=True)
    weights = np.zeros((m, n))
    weights[heard] = w
    return RobustTrack(X, P, weights, cost, best["done"], index, P_lag=lag)


__all__ = ["ROBUST_COARSE_ITERATIONS", "ROBUST_COARSE_SCALE", "ROBUST_DOF", "ROBUST_ITERATIONS", "ROBUST_KEPT_WEIGHT",
           "ROBUST_SCREEN", "ROBUST_TOLERANCE", "RobustTrack", "observed_information", "robust_smooth"]
