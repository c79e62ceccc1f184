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


def _interval_prior(settings: TrackerSettings, X: np.ndarray) -> float:
    """The first ping's interval's normalised distance from the nominal one, ``(Δ_0 − Δ) / σ_Δ`` (the filters'
    start, :meth:`ToaTracker.initial`)."""
    return float((X[0, -1] - settings.interval) / settings.sigma_interval)


class _Problem:
    """What every Gauss-Newton step of :func:`robust_smooth` shares: the arrivals, flattened (h of them: the ping
    ``k`` (h,), sorted, and receiver ``i`` (h,) of each, its time ``toa`` (h,) [s] and its receiver's position
    (h, dim) [m]), and the whitening of each step's process noise ``L_k⁻¹``, stored by its few distinct entries
    (m − 1,) each: per axis ``[[a, 0], [b, c]]`` on (position, velocity) (the inverse of the Cholesky factor of the
    white-noise acceleration's ``q [T³/3, T²/2; T²/2, T]`` over the step at the nominal interval,
    :func:`~sblsim.models.receiver.toa_bound.process_noise`), ``1 / σ_te`` on the emission time and ``1 / σ_drift``
    on the interval. Nothing of size m × m, nor (m, s, s) but the covariance's own blocks."""

    def __init__(self, toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, schedule: PingSchedule,
                 depth: np.ndarray | None = None):
        self.m, self.dim = len(toa), receivers.shape[1]
        self.s = 2 * self.dim + 2
        # the pings with a depth reading: their height z = −depth, weighed by 1 / depth_sigma
        known = np.zeros(self.m, bool) if depth is None else np.isfinite(depth)
        self.depth_at = np.flatnonzero(known)
        self.height = -np.asarray(depth, float)[self.depth_at] if depth is not None else np.zeros(0)
        self.depth_w = 1.0 / settings.depth_sigma
        self.k, self.i = np.nonzero(np.isfinite(toa))
        self.toa, self.at = toa[self.k, self.i], receivers[self.i]
        self.settings, self.count, self.offset = settings, schedule.count, schedule.offset
        T = schedule.steps(settings.interval)
        q = settings.acceleration_psd
        with np.errstate(divide="ignore", invalid="ignore"):
            l11 = np.sqrt(q * T**3 / 3)
            l21 = q * T**2 / 2 / l11
            l22 = np.sqrt(q * T - l21**2)
            self.a, self.b, self.c = 1.0 / l11, -l21 / (l11 * l22), 1.0 / l22
            self.te_w, self.dr_w = 1.0 / np.asarray(schedule.te_sigma, float), 1.0 / np.asarray(schedule.drift_sigma,
                                                                                                  float)
        if not all(np.isfinite(v).all() for v in (self.a, self.b, self.c, self.te_w, self.dr_w)):
            raise np.linalg.LinAlgError("robust smoother: a step's process noise is not positive definite")

    def per_ping(self, values: np.ndarray) -> np.ndarray:
        """The sums of ``values`` (h,) per ping: (m,), 0 for a ping none arrived from."""
        return np.bincount(self.k, weights=values, minlength=self.m)


def _robust_terms(problem: _Problem, X: np.ndarray, dof: float):
    """The robust smoother's residuals at the states X (m, s): the arrivals' normalised ones z (h,), the weights
    (h,), the TOA Jacobians (h, dim + 1) [1/σ units], the whitened process residuals e (m − 1, s) (per axis
    position and velocity, then the emission time and the interval) and the steps' durations T (m − 1,) at X's
    intervals (the transitions' Jacobians F follow from T and the velocities,
    :func:`~sblsim.models.receiver.toa_bound.predict`); and the cost."""
    P, dim, settings = problem, problem.dim, problem.settings
    model, J = _evaluate_arrivals(P.at, settings.sound_speed, X[P.k, :dim], X[P.k, -2])
    z = (P.toa - model) / settings.sigma_toa
    Jz = -J / settings.sigma_toa
    T = P.count * X[:-1, -1] + P.offset
    r = np.empty((len(T), 2 * dim + 2))  # x_k+1 − f(x_k), the state's order
    r[:, :dim] = X[1:, :dim] - (X[:-1, :dim] + T[:, None] * X[:-1, dim:2 * dim])
    r[:, dim:2 * dim] = X[1:, dim:2 * dim] - X[:-1, dim:2 * dim]
    r[:, -2] = X[1:, -2] - (X[:-1, -2] + T)
    r[:, -1] = X[1:, -1] - X[:-1, -1]
    e = np.empty_like(r)
    e[:, :dim] = P.a[:, None] * r[:, :dim]
    e[:, dim:2 * dim] = P.b[:, None] * r[:, :dim] + P.c[:, None] * r[:, dim:2 * dim]
    e[:, -2], e[:, -1] = P.te_w * r[:, -2], P.dr_w * r[:, -1]
    cost = float((dof + 1.0) * np.log1p(z**2 / dof).sum() + (e**2).sum() + _interval_prior(settings, X) ** 2
                 + (_depth_residual(problem, X) ** 2).sum())
    return z, (dof + 1.0) / (dof + z**2), Jz, e, T, cost


def _depth_residual(problem: _Problem, X: np.ndarray) -> np.ndarray:
    """The depth readings' normalised residuals ``(z_k − (−depth_k)) / σ_depth`` at the pings that have one."""
    return (X[problem.depth_at, 2] - problem.height) * problem.depth_w


def _normal_blocks(problem: _Problem, X: np.ndarray, w: np.ndarray, Jz: np.ndarray, T: np.ndarray) -> tuple:
    """The Gauss-Newton Hessian of the robust cost, block tridiagonal (Bell 1994), by its nonzero entries: ``D``
    {(i, j): (m,)} of the diagonal blocks (i ≤ j, the state's indices) and ``B`` {(i, j): (m − 1,)} of the blocks
    (k, k + 1); the arrivals' weights ``w`` (h,) and Jacobians ``Jz`` (h, dim + 1), the steps' durations ``T``
    (m − 1,) at X's intervals.

    A step's whitened residual ``e_k = L_k⁻¹ (x_k+1 − f(x_k))`` has the Jacobian ``L_k⁻¹`` in ``x_k+1`` and
    ``−M_k = −L_k⁻¹ F_k`` in ``x_k`` (F_k: ``∂p/∂v = T``, ``∂p/∂Δ = n v``, ``∂t_e/∂Δ = n``); so the blocks gain
    ``M_kᵀ M_k`` (k), ``L_k⁻ᵀ L_k⁻¹`` (k + 1) and ``−M_kᵀ L_k⁻¹`` (k, k + 1), written out entry by entry."""
    P, dim = problem, problem.dim
    s, m = P.s, P.m
    te, dl = s - 2, s - 1
    D, B = {}, {}

    def add(blocks, key, value, rows=slice(None)):
        """Add ``value`` to the entry ``key`` of the blocks (``rows`` of them)."""
        key = (min(key), max(key)) if blocks is D else key
        if key not in blocks:
            blocks[key] = np.zeros(m if blocks is D else m - 1)
        blocks[key][rows] += value

    cols = list(range(dim)) + [te]
    for x in range(dim + 1):
        for y in range(x, dim + 1):
            add(D, (cols[x], cols[y]), P.per_ping(w * Jz[:, x] * Jz[:, y]))
    n, a, b, c, tw, dw = P.count, P.a, P.b, P.c, P.te_w, P.dr_w
    early, late = slice(None, -1), slice(1, None)
    A2, bT = a * a + b * b, b * T + c
    PV, VV = a * (a * T) + b * bT, (a * T) ** 2 + bT**2
    delta = (tw * n) ** 2 + dw**2
    for ax in range(dim):
        p, v = ax, dim + ax
        nv = n * X[:-1, v]
        add(D, (p, p), A2, early)
        add(D, (p, v), PV, early)
        add(D, (v, v), VV, early)
        add(D, (p, dl), nv * A2, early)
        add(D, (v, dl), nv * PV, early)
        delta = delta + (a * nv) ** 2 + (b * nv) ** 2
        add(D, (p, p), A2, late)
        add(D, (p, v), b * c, late)
        add(D, (v, v), c * c, late)
        add(B, (p, p), -A2)
        add(B, (p, v), -b * c)
        add(B, (v, p), -PV)
        add(B, (v, v), -bT * c)
        add(B, (dl, p), -nv * A2)
        add(B, (dl, v), -nv * b * c)
    add(D, (te, te), tw**2, early)
    add(D, (te, dl), tw**2 * n, early)
    add(D, (dl, dl), delta, early)
    add(D, (te, te), tw**2, late)
    add(D, (dl, dl), dw**2, late)
    add(B, (te, te), -(tw**2))
    add(B, (dl, te), -n * tw**2)
    add(B, (dl, dl), -(dw**2))
    D[(dl, dl)][0] += 1.0 / P.settings.sigma_interval**2
    if len(P.depth_at):
        D[(2, 2)][P.depth_at] += P.depth_w**2
    return D, B


def _gradient(problem: _Problem, X: np.ndarray, z: np.ndarray, w: np.ndarray, Jz: np.ndarray, e: np.ndarray,
              T: np.ndarray) -> np.ndarray:
    """The robust cost's gradient's half, ``Jᵀ W r`` (m, s) (:func:`_normal_blocks`' Jacobians)."""
    P, dim = problem, problem.dim
    g = np.zeros((P.m, P.s))
    for x, col in enumerate(list(range(dim)) + [P.s - 2]):
        g[:, col] += P.per_ping(w * z * Jz[:, x])
    n, a, b, c = P.count, P.a[:, None], P.b[:, None], P.c[:, None]
    ep, ev = e[:, :dim], e[:, dim:2 * dim]
    lp = a * ep + b * ev  # (L⁻ᵀ e) on the positions
    g[1:, :dim] += lp
    g[1:, dim:2 * dim] += c * ev
    g[1:, -2] += P.te_w * e[:, -2]
    g[1:, -1] += P.dr_w * e[:, -1]
    g[:-1, :dim] -= lp
    g[:-1, dim:2 * dim] -= (a * T[:, None]) * ep + (b * T[:, None] + c) * ev
    g[:-1, -2] -= P.te_w * e[:, -2]
    g[:-1, -1] -= (n[:, None] * X[:-1, dim:2 * dim] * lp).sum(axis=1) + P.te_w * n * e[:, -2] + P.dr_w * e[:, -1]
    g[0, -1] += _interval_prior(P.settings, X) / P.settings.sigma_interval
    if len(P.depth_at):
        g[P.depth_at, 2] += _depth_residual(P, X) * P.depth_w
    return g


def _band_order(dim: int) -> np.ndarray:
    """Each state index's place in the banded system, ``[p_1, v_1, p_2, v_2, …, t_e, Δ]``: a block of s unknowns
    then reaches s + 1 places into the next (an axis's position and velocity side by side), against 3 dim + 2 in
    the state's own order."""
    place = np.empty(2 * dim + 2, int)
    place[:dim], place[dim:2 * dim], place[-2:] = 2 * np.arange(dim), 2 * np.arange(dim) + 1, [2 * dim, 2 * dim + 1]
    return place


def _banded_solve(D: dict, B: dict, g: np.ndarray, ridge: np.ndarray | float = 0.0) -> np.ndarray:
    """Solve ``(N + diag(ridge)) δ = g`` for the symmetric positive definite block-tridiagonal N
    (:func:`_normal_blocks`' entries; ``ridge`` (m, s) or a number, added to the diagonal) by LAPACK's banded Cholesky
    (:func:`scipy.linalg.solveh_banded`, its lower form, bandwidth s + 1 in :func:`_band_order`); δ (m, s).

    Raises
    ------
    numpy.linalg.LinAlgError
        Where N is not positive definite.
    """
    m, s = g.shape
    place = _band_order((s - 2) // 2)
    u = s + 1
    columns = np.zeros((m * s, u + 1))  # ab's transpose: ab itself in Fortran order, which LAPACK takes in place
    ab, view = columns.T, columns.reshape(m, s, u + 1)
    for (i, j), value in D.items():
        lo, hi = sorted((place[i], place[j]))
        view[:, lo, hi - lo] = value
    diagonal = view[:, place, 0]  # (m, s): N's diagonal, the state's order
    view[:, place, 0] = diagonal + ridge
    for (i, j), value in B.items():  # N[(k, i), (k + 1, j)] → lower N[(k + 1, j), (k, i)]
        view[:-1, place[i], s + place[j] - place[i]] = value
    rhs = np.empty_like(g)
    rhs[:, place] = g
    return solveh_banded(ab, rhs.ravel(), overwrite_ab=True, lower=True, check_finite=False).reshape(m, s)[:, place]


def _damped_solve(D, B, g):
    """:func:`_banded_solve` of the Gauss-Newton step, damped where the system is numerically indefinite (a track far
    from its arrivals, each weighed down to nothing): ``μ diag(N)`` added (Levenberg–Marquardt; Nocedal & Wright,
    *Numerical Optimization*, Springer 2006, § 10.3), μ from 10⁻¹² up by tenfold steps to 1 after an undamped try;
    None if none holds."""
    m, s = g.shape
    diagonal = np.stack([D.get((i, i), np.zeros(m)) for i in range(s)], axis=1)
    for mu in [None, *10.0 ** np.arange(-12, 1)]:  # first undamped (a 10⁻¹² ridge)
        ridge = 1e-12 if mu is None else mu * (diagonal + 1.0)
        try:
            step = _banded_solve(D, B, g, ridge)
        except np.linalg.LinAlgError:
            continue
        if np.isfinite(step).all():
            return step
    return None


def _dense_blocks(D: dict, B: dict, m: int, s: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_normal_blocks`' entries as the blocks themselves: diagonal (m, s, s) and (k, k + 1) (m − 1, s, s)."""
    Dd, Bd = np.zeros((m, s, s)), np.zeros((max(m - 1, 0), s, s))
    for (i, j), value in D.items():
        Dd[:, i, j] = Dd[:, j, i] = value
    for (i, j), value in B.items():
        Bd[:, i, j] = value
    return Dd, Bd


def _inverse(a: np.ndarray) -> np.ndarray:
    """The inverses of blocks (k, s, s), their pseudo-inverses where one is singular."""
    try:
        return np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(a)


def _block_covariance(D, B, lag=False):
    """The diagonal blocks (m, s, s) of N⁻¹ for the symmetric block-tridiagonal N of diagonal blocks D (m, s, s) and
    upper blocks B (m − 1, s, s); with ``lag`` also its blocks (k + 1, k) (m − 1, s, s).

    By block cyclic reduction (all blocks of a level at once, log₂ m levels; Heller, "Some aspects of the cyclic
    reduction algorithm for block tridiagonal linear systems", SIAM J. Numer. Anal. 13(4), 1976): the odd rows are
    eliminated (the Schur complement on the even ones is again block tridiagonal, half the size), the even rows'
    blocks of the inverse found, then the odd rows' from them, ``Σ_oo = D_o⁻¹ − Y₁ Σ_(o−1),o − Y₂ Σ_(o+1),o`` and
    ``Σ_o,e = −(Y₁ Σ_(o−1),e + Y₂ Σ_(o+1),e)`` with ``Y₁ = D_o⁻¹ N_o,(o−1)``, ``Y₂ = D_o⁻¹ N_o,(o+1)``. The same
    blocks as the Rauch-Tung-Striebel recursion in information form, without a Python step per ping."""
    cov, cross = _cyclic_reduction(np.asarray(D, float), np.asarray(B, float))
    cov = 0.5 * (cov + cov.transpose(0, 2, 1))
    return (cov, cross) if lag else cov


def _cyclic_reduction(D: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_block_covariance`'s recursion: the diagonal blocks of N⁻¹ (m, s, s) and its blocks (k + 1, k)
    (m − 1, s, s)."""
    m = len(D)
    if m == 1:
        return _inverse(D), np.empty((0,) + D.shape[1:])
    odd = np.arange(1, m, 2)
    has_next = odd + 1 < m
    Di = _inverse(D[odd])
    Bt = B.transpose(0, 2, 1)
    Y1 = Di @ Bt[odd - 1]  # D_o⁻¹ N_o,(o−1)
    Y2 = np.zeros_like(Y1)
    Y2[has_next] = Di[has_next] @ B[odd[has_next]]  # D_o⁻¹ N_o,(o+1)
    reduced = D[0::2].copy()
    reduced[odd // 2] -= B[odd - 1] @ Y1
    nxt = odd[has_next]
    reduced[nxt // 2 + 1] -= Bt[nxt] @ Y2[has_next]
    coupling = -(B[odd - 1][has_next] @ Y2[has_next])  # N'_(o−1),(o+1)
    even_cov, even_cross = _cyclic_reduction(reduced, coupling)
    before = even_cov[odd // 2]  # Σ_(o−1),(o−1)
    after = np.zeros_like(before)
    after[has_next] = even_cov[nxt // 2 + 1]  # Σ_(o+1),(o+1)
    between = np.zeros_like(before)
    between[has_next] = even_cross[odd[has_next] // 2]  # Σ_(o+1),(o−1)
    to_before = -(Y1 @ before + Y2 @ between)  # Σ_o,(o−1)
    to_after = -(Y1 @ between.transpose(0, 2, 1) + Y2 @ after)  # Σ_o,(o+1)
    cov = np.empty_like(D)
    cov[0::2] = even_cov
    cov[odd] = Di - Y1 @ to_before.transpose(0, 2, 1) - Y2 @ to_after.transpose(0, 2, 1)
    cross = np.empty((m - 1,) + D.shape[1:])
    cross[odd - 1] = to_before  # Σ_o,(o−1)
    cross[nxt] = to_after[has_next].transpose(0, 2, 1)  # Σ_(o+1),o
    return cov, cross


def _survey_covariance(problem: _Problem, D: dict, B: dict, information: np.ndarray, Jz: np.ndarray,
                       survey: np.ndarray) -> np.ndarray:
    """The receivers' survey error's share of the track's covariance (m, s, s), a consider covariance (Tapley,
    Schutz & Born, *Statistical Orbit Determination*, Elsevier 2004, § 6.3): receiver i's position error δr_i, the
    same at every ping, moves the whole track by ``δx = −N⁻¹ (∂g/∂r_i) δr_i`` (N the cost's Hessian of the
    covariance, ``D``, ``B``; g its gradient, whose arrivals from receiver i change with r_i as their normalised
    residuals do, ``∂z/∂r_i = −∂z/∂p``), so each axis a adds ``σ_i² S S_kᵀ`` per ping with ``S = N⁻¹ u_(i,a)``:
    one banded solve per receiver and axis."""
    P, dim = problem, problem.dim
    cols = list(range(dim)) + [P.s - 2]
    out = np.zeros((P.m, P.s, P.s))
    for i in np.flatnonzero(survey > 0):
        mine = P.i == i
        for a in range(dim):
            u = np.zeros((P.m, P.s))
            for x, col in enumerate(cols):
                u[:, col] = np.bincount(P.k[mine], weights=-information[mine] * Jz[mine, x] * Jz[mine, a],
                                        minlength=P.m)
            S = _banded_solve(D, B, u, 1e-12)
            out += survey[i] ** 2 * S[:, :, None] * S[:, None, :]
    return out


def survey_covariance(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, X: np.ndarray,
                      schedule: PingSchedule | None = None, depth: np.ndarray | None = None,
                      dof: float = ROBUST_DOF) -> np.ndarray:
    """The receivers' survey error's share of a robust track's covariance at its states (the term
    :func:`robust_smooth` adds to ``P`` where ``settings.survey_sigma`` is given; :func:`_survey_covariance`), for
    a track solved without it.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    settings : TrackerSettings
        With ``survey_sigma`` (n,) [m] (None: a zero term).
    X : ndarray, (m, 2 dim + 2)
        The track's states (:class:`RobustTrack` ``x``).
    schedule, depth, dof
        As :func:`robust_smooth`.

    Returns
    -------
    ndarray, (m, 2 dim + 2, 2 dim + 2)
    """
    toa, X = np.asarray(toa, float), np.asarray(X, float)
    if schedule is None:
        schedule = PingSchedule.stable(len(toa), settings.interval, settings.jitter, settings.interval_drift)
    if settings.survey_sigma is None:
        return np.zeros((len(toa), X.shape[1], X.shape[1]))
    problem = _Problem(toa, np.asarray(receivers, float), settings, schedule, depth)
    z, _, Jz, _, T, _ = _robust_terms(problem, X, dof)
    information = observed_information(z, dof)
    D, B = _normal_blocks(problem, X, information, Jz, T)
    return _survey_covariance(problem, D, B, information, Jz, np.asarray(settings.survey_sigma, float))


def robust_smooth(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, starts: list[np.ndarray],
                  dof: float = ROBUST_DOF, iterations: int = ROBUST_ITERATIONS, covariance: bool = True,
                  schedule: PingSchedule | None = None, depth: np.ndarray | None = None) -> RobustTrack:
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
    depth : ndarray, (m,), optional
        The tag's depth-sensor reading per ping [m], positive down, NaN where none (receivers in 3-D).

    Returns
    -------
    RobustTrack
        With the settings' ``survey_sigma``, ``P`` holds the receivers' survey error as a consider covariance
        (:func:`_survey_covariance`).

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
    if depth is not None and (dim != 3 or np.shape(depth) != (m,)):
        raise ModelError(f"depth_m: {np.shape(depth)} readings for {m} pings at receivers in {dim}-D; allowed: one "
                         "per ping, with the receivers' depths (z_m)")
    problem = _Problem(toa, receivers, settings, schedule, depth)
    runs = []
    for start in starts:
        X = np.array(start, float)
        if X.shape != (m, s) or not np.isfinite(X).all():
            raise ModelError(f"robust smoother: a starting track of shape {X.shape} or not finite; allowed: "
                             f"({m}, {s}), finite")
        # a start's residuals are made again where its steps go on (the same numbers): none kept beside it
        runs.append({"X": X, "cost": _robust_terms(problem, X, dof)[-1], "done": 0, "converged": False})

    def iterate(run, count):
        """Up to ``count`` more Gauss-Newton steps of a start (stopping where it has converged)."""
        if run["converged"] or count <= 0:
            return
        X = run["X"]
        z, w, Jz, e, T, cost = _robust_terms(problem, X, dof)
        for _ in range(count):
            if run["converged"]:
                return
            D, B = _normal_blocks(problem, X, w, Jz, T)
            g = _gradient(problem, X, z, w, Jz, e, T)
            step = _damped_solve(D, B, -g)
            del D, B
            if step is None:  # no damping makes the system positive definite: stopped where it is
                run["converged"] = True
                return
            scale = 1.0
            while scale > 1e-6:
                trial = X + scale * step
                terms = _robust_terms(problem, trial, dof)
                if terms[-1] < cost:
                    break
                scale *= 0.5
            else:  # no step lowers the cost: a minimum
                run["converged"] = True
                return
            gain = cost - terms[-1]
            X, (z, w, Jz, e, T, cost) = trial, terms
            run.update(X=X, cost=cost, done=run["done"] + 1, converged=gain <= ROBUST_TOLERANCE * cost)

    # each start a few steps, then the one of the lowest cost to the end (the ranking of the starts' costs is
    # settled within a few steps)
    for run in runs:
        iterate(run, min(ROBUST_SCREEN, iterations))
    index = int(np.argmin([run["cost"] for run in runs]))
    best = runs[index]
    iterate(best, iterations - best["done"])
    X = best["X"]
    z, w, Jz, _, T, cost = _robust_terms(problem, X, dof)
    P = lag = None
    if covariance:
        information = observed_information(z, dof)
        D, B = _normal_blocks(problem, X, information, Jz, T)
        P, lag = _block_covariance(*_dense_blocks(D, B, m, s), lag=True)
        if settings.survey_sigma is not None:
            P = P + _survey_covariance(problem, D, B, information, Jz, np.asarray(settings.survey_sigma, float))
    weights = np.zeros((m, n))
    weights[problem.k, problem.i] = w
    return RobustTrack(X, P, weights, cost, best["done"], index, P_lag=lag)


__all__ = ["ROBUST_COARSE_ITERATIONS", "ROBUST_COARSE_SCALE", "ROBUST_DOF", "ROBUST_ITERATIONS", "ROBUST_KEPT_WEIGHT",
           "ROBUST_SCREEN", "ROBUST_TOLERANCE", "RobustTrack", "observed_information", "robust_smooth",
           "survey_covariance"]
