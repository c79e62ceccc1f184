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
from functools import partial

import numpy as np
from scipy.linalg import solveh_banded
from scipy.sparse import csr_matrix

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.schedule import PingSchedule

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


#: Pings per chunk of the robust smoother's passes over the arrivals and over its banded system: a chunk's arrays
#: stay in the processor's cache (over whole records of 10⁶ pings each operation would be bound by memory).
CHUNK = 8192


class _Problem:
    """What every Gauss-Newton step of :func:`robust_smooth` shares: the arrivals, flattened (h of them: the ping
    ``k`` (h,), sorted, and receiver ``i`` (h,) of each, its time ``toa`` (h,) [s] and its receiver's coordinates
    ``r``, one (h,) array per axis [m]), the chunks of pings the passes take (:meth:`chunks`: :data:`CHUNK` pings
    each, with the sparse sum over each ping's arrivals), and the whitening of each step's process noise ``L_k⁻¹``,
    stored by its few distinct entries (m − 1,) each: per axis ``[[a, 0], [b, c]]`` on (position, velocity) (the
    inverse of the Cholesky factor of the white-noise acceleration's ``q [T³/3, T²/2; T²/2, T]`` over the step at
    the nominal interval, :func:`~sblsim.models.receiver.toa_bound.process_noise`), ``1 / σ_te`` on the emission
    time and ``1 / σ_drift`` on the interval; and the buffers the steps reuse (the band, its right-hand side, the
    arrivals' cost terms). Nothing of size m × m, nor (m, s, s) but the covariance's own blocks."""

    def __init__(self, toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, schedule: PingSchedule,
                 depth: np.ndarray | None = None):
        self.m, self.dim = len(toa), receivers.shape[1]
        self.s = 2 * self.dim + 2
        # the pings with a depth reading: their height z = −depth, weighed by 1 / depth_sigma
        known = np.zeros(self.m, bool) if depth is None else np.isfinite(depth)
        self.depth_at = np.flatnonzero(known)
        self.height = -np.asarray(depth, float)[self.depth_at] if depth is not None else np.zeros(0)
        self.depth_w = 1.0 / settings.depth_sigma
        self.k, self.i = (v.astype(np.int32) for v in np.nonzero(np.isfinite(toa)))  # m < 2³¹
        self.toa = toa[self.k, self.i]
        self.r = [receivers[self.i, a] for a in range(self.dim)]
        self.band = self.rhs = self.logs = self.values = self.squares = self._chunks = None
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
        # the Hessian's entries that depend on the schedule alone (:func:`_normal_blocks`)
        a, b, c, n, tw, dw = self.a, self.b, self.c, self.count, self.te_w, self.dr_w
        self.A2, self.bc, self.cc, self.tw2, self.dw2 = a * a + b * b, b * c, c * c, tw**2, dw**2
        self.tw2n, self.delta = self.tw2 * n, (tw * n) ** 2 + self.dw2

    def chunks(self) -> list[tuple]:
        """The chunks of pings in order, each ``(lo, hi, a0, a1, S)``: the pings ``lo:hi``, their arrivals
        ``a0:a1``, and ``S`` (hi − lo, a1 − a0), sparse, whose product with the arrivals' values sums them per ping
        (in the arrivals' order, from 0: :func:`numpy.bincount`'s numbers, several columns at once)."""
        if self._chunks is None:
            edges = np.r_[np.arange(0, self.m, CHUNK), self.m]
            starts = np.searchsorted(self.k, np.arange(self.m + 1)).astype(np.int32)
            longest = int(np.diff(starts[edges]).max(initial=0))
            ones, index = np.ones(longest), np.arange(longest, dtype=np.int32)
            self._chunks = []
            for lo, hi in zip(edges[:-1], edges[1:]):
                a0, a1 = int(starts[lo]), int(starts[hi])
                S = csr_matrix((ones[:a1 - a0], index[:a1 - a0], starts[lo:hi + 1] - a0), shape=(hi - lo, a1 - a0))
                self._chunks.append((int(lo), int(hi), a0, a1, S))
        return self._chunks

    def steps(self, lo: int, hi: int) -> tuple:
        """The steps (from ping j to j + 1) that touch the pings ``lo:hi``: ``j0:j1``, those that add to their rows as
        the step's first ping (``early``, into the steps' arrays, and ``to_early``, into the rows) and as its second
        (``late``, ``to_late``)."""
        j0, j1 = max(lo, 1) - 1, min(hi, self.m - 1)
        return (j0, j1, slice(lo - j0, None), slice(0, max(j1 - lo, 0)), slice(0, hi - 1 - j0),
                slice(j0 + 1 - lo, hi - lo))


def _arrivals(problem: _Problem, X: np.ndarray, lo: int, hi: int, a0: int, a1: int) -> tuple:
    """The arrivals ``a0:a1`` (those of the pings ``lo:hi``) at the states X (m, s): their normalised residuals z
    (a,) and the position columns of their Jacobians [1/σ units], one (a,) array per axis (the emission time's
    column is −1/σ_toa); by the operations of :func:`~sblsim.models.tracking.toa.toa_function`'s algorithm in its
    order (as :func:`~sblsim.models.tracking.toa._ranges`: the same numbers)."""
    P, settings = problem, problem.settings
    c, sigma = settings.sound_speed, settings.sigma_toa
    kk = P.k[a0:a1] - lo
    d = [X[lo:hi, a][kk] - P.r[a][a0:a1] for a in range(P.dim)]
    squares = np.square(d[0])
    for da in d[1:]:
        squares += np.square(da)
    rho = np.sqrt(squares)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = (1.0 / (2.0 * rho)) / c
    for da in d:  # −(2 d) ((1 / (2 ρ)) / c) / σ, in place
        da *= 2.0
        da *= scale
        np.negative(da, out=da)
        da /= sigma
    rho /= c
    z = P.toa[a0:a1] - (X[lo:hi, -2][kk] + rho)
    z /= sigma
    return z, d


def _arrival_chunk(problem: _Problem, X: np.ndarray, dof: float, chunk: tuple, sums: np.ndarray,
                   information: bool = False, weights: np.ndarray | None = None):
    """:func:`_arrival_sums` over one chunk of pings (:meth:`_Problem.chunks`): its rows of ``sums`` filled, its
    arrivals' cost terms ``ln(1 + z² / ν)`` into the problem's buffer (not with ``information``)."""
    P = problem
    lo, hi, a0, a1, S = chunk
    z, J = _arrivals(P, X, lo, hi, a0, a1)
    J.append(-1.0 / P.settings.sigma_toa)  # the emission time's column of every Jacobian
    z2 = z**2
    robust = (dof + 1.0) / (dof + z2)
    if weights is not None:
        weights[a0:a1] = robust
    w = observed_information(z, dof) if information else robust
    values = P.values[:a1 - a0, :sums.shape[1]]
    row = 0
    for x in range(len(J)):
        wx = w * J[x]
        for y in range(x, len(J)):
            np.multiply(wx, J[y], out=values[:, row])
            row += 1
    if not information:
        wz = w * z
        for x in range(len(J)):
            np.multiply(wz, J[x], out=values[:, row + x])
        z2 /= dof
        np.log1p(z2, out=P.logs[a0:a1])
    sums[lo:hi] = S @ values


def _arrival_sums(problem: _Problem, X: np.ndarray, dof: float, information: bool = False,
                  weights: np.ndarray | None = None) -> np.ndarray:
    """The arrivals' share of the robust cost's Gauss-Newton Hessian and of its gradient at the states X, per
    ping, in one pass over chunks of pings (:data:`CHUNK`): ``sums`` (m, q), the sums over each ping's arrivals of
    ``w J_x J_y`` (the pairs x ≤ y of the columns ``p, t_e``, in order) then of ``w z J_x`` (not with
    ``information``), with the Gauss-Newton weights ``w = (ν + 1) / (ν + z²)``, or the arrivals' observed
    information (:func:`observed_information`) with ``information``. ``weights`` (h,): filled with the
    Gauss-Newton weights."""
    P, cols = problem, problem.dim + 1
    q = cols * (cols + 1) // 2 + (0 if information else cols)
    _buffers(P)
    sums = np.empty((P.m, q))
    for chunk in P.chunks():
        _arrival_chunk(P, X, dof, chunk, sums, information, weights)
    return sums


def _buffers(problem: _Problem):
    """The buffers the passes reuse: each chunk's arrivals' values (a, q), every arrival's cost term (h,) and every
    process residual's square (m − 1, s)."""
    P, cols = problem, problem.dim + 1
    if P.logs is None:
        P.logs, P.squares = np.empty(len(P.k)), np.empty((P.m - 1, P.s))
        P.values = np.empty((max((a1 - a0 for _, _, a0, a1, _ in P.chunks()), default=0),
                             cols * (cols + 1) // 2 + cols))


def _process_residuals(problem: _Problem, X: np.ndarray, T: np.ndarray, e: np.ndarray, j: int, k: int):
    """The whitened process residuals of the steps ``j:k`` into ``e`` (m − 1, s): ``L⁻¹ (x_k+1 − f(x_k))``, per axis
    position and velocity, then the emission time and the interval, at the steps' durations T (m − 1,)."""
    P, dim = problem, problem.dim
    Xc = np.ascontiguousarray(X[j:k + 1].T)  # (s, k − j + 1): each state's row contiguous
    Xa, Xb, Tj = Xc[:, :-1], Xc[:, 1:], T[j:k]
    out = np.empty((P.s, k - j))
    for p in range(dim):  # x_k+1 − f(x_k), an axis at a time
        v = dim + p
        rp = Xb[p] - (Xa[p] + Tj * Xa[v])
        out[p] = P.a[j:k] * rp
        out[v] = P.b[j:k] * rp + P.c[j:k] * (Xb[v] - Xa[v])
    out[-2] = P.te_w[j:k] * (Xb[-2] - (Xa[-2] + Tj))
    out[-1] = P.dr_w[j:k] * (Xb[-1] - Xa[-1])
    e[j:k] = out.T
    np.square(e[j:k], out=P.squares[j:k])


def _robust_terms(problem: _Problem, X: np.ndarray, dof: float) -> tuple:
    """The robust smoother's terms at the states X (m, s), in one pass over chunks of pings: the arrivals' per-ping
    sums (:func:`_arrival_sums`), the whitened process residuals e (m − 1, s) (:func:`_process_residuals`), the
    steps' durations T (m − 1,) at X's intervals (the transitions' Jacobians F follow from T and the velocities,
    :func:`~sblsim.models.receiver.toa_bound.predict`) and the cost."""
    P, cols = problem, problem.dim + 1
    _buffers(P)
    sums = np.empty((P.m, cols * (cols + 1) // 2 + cols))
    T = P.count * X[:-1, -1] + P.offset
    e = np.empty((P.m - 1, P.s))
    for chunk in P.chunks():
        _arrival_chunk(P, X, dof, chunk, sums)
        _process_residuals(P, X, T, e, chunk[0], min(chunk[1], P.m - 1))
    cost = float((dof + 1.0) * P.logs.sum() + P.squares.sum() + _interval_prior(P.settings, X) ** 2
                 + (_depth_residual(P, X) ** 2).sum())
    return sums, e, T, cost


def _arrival_jacobians(problem: _Problem, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every arrival's normalised residual z (h,) and TOA Jacobian (h, dim + 1) [1/σ units] at the states X (one
    pass, :func:`_arrivals`: for the survey's consider covariance)."""
    z, J = _arrivals(problem, X, 0, problem.m, 0, len(problem.k))
    return z, np.column_stack([*J, np.full(len(z), -1.0 / problem.settings.sigma_toa)])


def _depth_residual(problem: _Problem, X: np.ndarray, at: slice = slice(None)) -> np.ndarray:
    """The depth readings' normalised residuals ``(z_k − (−depth_k)) / σ_depth`` at the pings that have one (``at``
    of them)."""
    return (X[problem.depth_at[at], 2] - problem.height[at]) * problem.depth_w


def _normal_blocks(problem: _Problem, X: np.ndarray, sums: np.ndarray, T: np.ndarray, lo: int = 0,
                   hi: int | None = None) -> tuple:
    """The Gauss-Newton Hessian of the robust cost, block tridiagonal (Bell 1994), by its nonzero entries over the
    pings ``lo:hi`` (default all): ``D`` {(i, j): (hi − lo,)} of the diagonal blocks (i ≤ j, the state's indices) and
    ``B`` {(i, j): (min(hi, m − 1) − lo,)} of the blocks (k, k + 1); the arrivals' per-ping sums ``sums``
    (:func:`_arrival_sums`' columns ``w J_x J_y``, all pings), the steps' durations ``T`` (m − 1,) at X's intervals.

    A step's whitened residual ``e_k = L_k⁻¹ (x_k+1 − f(x_k))`` has the Jacobian ``L_k⁻¹`` in ``x_k+1`` and
    ``−M_k = −L_k⁻¹ F_k`` in ``x_k`` (F_k: ``∂p/∂v = T``, ``∂p/∂Δ = n v``, ``∂t_e/∂Δ = n``); so the blocks gain
    ``M_kᵀ M_k`` (k), ``L_k⁻ᵀ L_k⁻¹`` (k + 1) and ``−M_kᵀ L_k⁻¹`` (k, k + 1), written out entry by entry."""
    P, dim = problem, problem.dim
    s, m = P.s, P.m
    hi = m if hi is None else hi
    te, dl = s - 2, s - 1
    rows, brows = hi - lo, max(min(hi, m - 1) - lo, 0)
    D, B = {}, {}

    def add(blocks, key, value, at=slice(None)):
        """Add ``value`` to the entry ``key`` of the blocks (the rows ``at`` of them)."""
        key = (min(key), max(key)) if blocks is D else key
        if key not in blocks:
            blocks[key] = np.zeros(rows if blocks is D else brows)
        blocks[key][at] += value

    cols = list(range(dim)) + [te]
    column = 0
    for x in range(dim + 1):
        for y in range(x, dim + 1):
            add(D, (cols[x], cols[y]), sums[lo:hi, column])
            column += 1
    j0, j1, early, to_early, late, to_late = P.steps(lo, hi)
    n, a, b, c, A2, bc, cc, tw2, dw2, tw2n, delta = (v[j0:j1] for v in (P.count, P.a, P.b, P.c, P.A2, P.bc, P.cc,
                                                                        P.tw2, P.dw2, P.tw2n, P.delta))
    T = T[j0:j1]
    bT = b * T + c
    PV, VV = a * (a * T) + b * bT, (a * T) ** 2 + bT**2
    for ax in range(dim):
        p, v = ax, dim + ax
        nv = n * X[j0:j1, v]
        add(D, (p, p), A2[early], to_early)
        add(D, (p, v), PV[early], to_early)
        add(D, (v, v), VV[early], to_early)
        add(D, (p, dl), (nv * A2)[early], to_early)
        add(D, (v, dl), (nv * PV)[early], to_early)
        delta = delta + (a * nv) ** 2 + (b * nv) ** 2
        add(D, (p, p), A2[late], to_late)
        add(D, (p, v), bc[late], to_late)
        add(D, (v, v), cc[late], to_late)
        add(B, (p, p), -A2[early])
        add(B, (p, v), -bc[early])
        add(B, (v, p), -PV[early])
        add(B, (v, v), -(bT * c)[early])
        add(B, (dl, p), -(nv * A2)[early])
        add(B, (dl, v), -(nv * b * c)[early])
    add(D, (te, te), tw2[early], to_early)
    add(D, (te, dl), tw2n[early], to_early)
    add(D, (dl, dl), delta[early], to_early)
    add(D, (te, te), tw2[late], to_late)
    add(D, (dl, dl), dw2[late], to_late)
    add(B, (te, te), -tw2[early])
    add(B, (dl, te), -(n * tw2)[early])
    add(B, (dl, dl), -dw2[early])
    if lo == 0:
        D[(dl, dl)][0] += 1.0 / P.settings.sigma_interval**2
    first, last = np.searchsorted(P.depth_at, (lo, hi))
    if last > first:
        D[(2, 2)][P.depth_at[first:last] - lo] += P.depth_w**2
    return D, B


def _gradient(problem: _Problem, X: np.ndarray, sums: np.ndarray, e: np.ndarray, T: np.ndarray, lo: int = 0,
              hi: int | None = None) -> np.ndarray:
    """The robust cost's gradient's half, ``Jᵀ W r``, over the pings ``lo:hi`` (default all): (hi − lo, s)
    (:func:`_normal_blocks`' Jacobians; the arrivals' per-ping sums ``w z J_x``, :func:`_arrival_sums`' last
    columns, and the process residuals e, all pings)."""
    P, dim = problem, problem.dim
    hi = P.m if hi is None else hi
    g = np.zeros((hi - lo, P.s))
    first = sums.shape[1] - (dim + 1)
    for x, col in enumerate(list(range(dim)) + [P.s - 2]):
        g[:, col] += sums[lo:hi, first + x]
    j0, j1, early, to_early, late, to_late = P.steps(lo, hi)
    n, a, b, c, tw, dw = (v[j0:j1] for v in (P.count, P.a, P.b, P.c, P.te_w, P.dr_w))
    e, T = e[j0:j1], T[j0:j1]
    interval = 0.0  # Σ_axes n v (L⁻ᵀ e)_p: the interval's share through the positions
    for p in range(dim):
        v = dim + p
        ep, ev = e[:, p], e[:, v]
        lp = a * ep + b * ev  # (L⁻ᵀ e) on the position
        g[to_late, p] += lp[late]
        g[to_late, v] += (c * ev)[late]
        g[to_early, p] -= lp[early]
        g[to_early, v] -= ((a * T) * ep + (b * T + c) * ev)[early]
        interval = interval + n * X[j0:j1, v] * lp
    g[to_late, -2] += (tw * e[:, -2])[late]
    g[to_late, -1] += (dw * e[:, -1])[late]
    g[to_early, -2] -= (tw * e[:, -2])[early]
    g[to_early, -1] -= (interval + tw * n * e[:, -2] + dw * e[:, -1])[early]
    if lo == 0:
        g[0, -1] += _interval_prior(P.settings, X) / P.settings.sigma_interval
    first, last = np.searchsorted(P.depth_at, (lo, hi))
    if last > first:
        g[P.depth_at[first:last] - lo, 2] += _depth_residual(P, X, slice(first, last)) * P.depth_w
    return g


def _band_order(dim: int) -> np.ndarray:
    """Each state index's place in the banded system, ``[p_1, v_1, p_2, v_2, …, t_e, Δ]``: a block of s unknowns
    then reaches s + 1 places into the next (an axis's position and velocity side by side), against 3 dim + 2 in
    the state's own order."""
    place = np.empty(2 * dim + 2, int)
    place[:dim], place[dim:2 * dim], place[-2:] = 2 * np.arange(dim), 2 * np.arange(dim) + 1, [2 * dim, 2 * dim + 1]
    return place


def _step_system(problem: _Problem, X: np.ndarray, sums: np.ndarray, e: np.ndarray, T: np.ndarray, lo: int,
                 hi: int) -> tuple:
    """The Gauss-Newton step's system over the pings ``lo:hi`` (:func:`_banded_solve`'s ``system``): the Hessian's
    entries (:func:`_normal_blocks`) and minus the gradient (:func:`_gradient`)."""
    D, B = _normal_blocks(problem, X, sums, T, lo, hi)
    return D, B, -_gradient(problem, X, sums, e, T, lo, hi)


def _given_system(D: dict, B: dict, g: np.ndarray):
    """:func:`_banded_solve`'s ``system`` of the entries ``D``, ``B`` over all pings (:func:`_normal_blocks`) and the
    right-hand side g (m, s)."""
    def system(lo, hi):
        return {key: v[lo:hi] for key, v in D.items()}, {key: v[lo:hi] for key, v in B.items()}, g[lo:hi]
    return system


def _banded_solve(problem: _Problem, system, ridge: np.ndarray | float = 0.0) -> np.ndarray:
    """Solve ``(N + diag(ridge)) δ = g`` for the symmetric positive definite block-tridiagonal N by LAPACK's banded
    Cholesky (:func:`scipy.linalg.solveh_banded`, its lower form, bandwidth s + 1 in :func:`_band_order`); δ (m, s).
    ``system(lo, hi)`` gives N's entries over the pings ``lo:hi`` as :func:`_normal_blocks` does, and g's rows
    (hi − lo, s); ``ridge`` (m, s) or a number is added to N's diagonal. The band and the right-hand side are written
    a chunk of pings at a time into the problem's buffers (which the solve then overwrites).

    Raises
    ------
    numpy.linalg.LinAlgError
        Where N is not positive definite.
    """
    m, s = problem.m, problem.s
    place = _band_order((s - 2) // 2)
    u = s + 1
    if problem.band is None:  # ab's transpose: ab itself in Fortran order, which LAPACK takes in place
        problem.band, problem.rhs = np.empty((m * s, u + 1)), np.empty((m, s))
    for lo, hi, *_ in problem.chunks():
        D, B, g = system(lo, hi)
        view = problem.band[lo * s:hi * s].reshape(hi - lo, s, u + 1)
        view.fill(0.0)
        local = ridge[lo:hi] if np.ndim(ridge) else ridge
        for (i, j), value in D.items():
            first, second = sorted((place[i], place[j]))
            if i == j:
                value = value + (local[:, i] if np.ndim(local) else local)
            view[:, first, second - first] = value
        for (i, j), value in B.items():  # N[(k, i), (k + 1, j)] → lower N[(k + 1, j), (k, i)]
            view[:len(value), place[i], s + place[j] - place[i]] = value
        problem.rhs[lo:hi, place] = g
    solved = solveh_banded(problem.band.T, problem.rhs.reshape(-1), overwrite_ab=True, overwrite_b=True, lower=True,
                           check_finite=False)
    return solved.reshape(m, s)[:, place]


def _damped_solve(problem: _Problem, system):
    """:func:`_banded_solve` of the Gauss-Newton step, damped where the system is numerically indefinite (a track far
    from its arrivals, each weighed down to nothing): ``μ diag(N)`` added (Levenberg–Marquardt; Nocedal & Wright,
    *Numerical Optimization*, Springer 2006, § 10.3), μ from 10⁻¹² up by tenfold steps to 1 after an undamped try;
    None if none holds."""
    diagonal = None
    for mu in [None, *10.0 ** np.arange(-12, 1)]:  # first undamped (a 10⁻¹² ridge)
        if mu is not None and diagonal is None:  # N's diagonal (m, s), the state's order
            diagonal = np.zeros((problem.m, problem.s))
            for lo, hi, *_ in problem.chunks():
                for (i, j), value in system(lo, hi)[0].items():
                    if i == j:
                        diagonal[lo:hi, i] = value
        ridge = 1e-12 if mu is None else mu * (diagonal + 1.0)
        try:
            step = _banded_solve(problem, system, ridge)
        except np.linalg.LinAlgError:
            continue
        if np.isfinite(step).all():
            return step
    return None


def _dense_blocks(problem: _Problem, blocks) -> tuple[np.ndarray, np.ndarray]:
    """The Hessian's blocks themselves, diagonal (m, s, s) and (k, k + 1) (m − 1, s, s), from ``blocks(lo, hi)``, its
    entries over the pings ``lo:hi`` (:func:`_normal_blocks`), a chunk of pings at a time."""
    m, s = problem.m, problem.s
    Dd, Bd = np.empty((m, s, s)), np.empty((max(m - 1, 0), s, s))
    for lo, hi, *_ in problem.chunks():
        D, B = blocks(lo, hi)
        d, b = np.zeros((hi - lo, s, s)), np.zeros((min(hi, m - 1) - lo, s, s))
        for (i, j), value in D.items():
            d[:, i, j] = d[:, j, i] = value
        for (i, j), value in B.items():
            b[:, i, j] = value
        Dd[lo:hi], Bd[lo:lo + len(b)] = d, b
    return Dd, Bd


def _inverse(a: np.ndarray) -> np.ndarray:
    """The inverses of blocks (k, s, s), their pseudo-inverses where one is singular."""
    try:
        return np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(a)


#: Blocks per chunk of the covariance's cyclic reduction (each level's operations a chunk at a time: the
#: temporaries stay small).
REDUCTION_CHUNK = 4096


def _block_covariance(D: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The diagonal blocks (m, s, s) of N⁻¹ for the symmetric positive definite block-tridiagonal N of diagonal blocks D
    (m, s, s) and upper blocks B (m − 1, s, s), and its blocks (k + 1, k) (m − 1, s, s): in place, D and B
    overwritten with them and returned.

    By block cyclic reduction (all blocks of a level at once, log₂ m levels; Heller, "Some aspects of the cyclic
    reduction algorithm for block tridiagonal linear systems", SIAM J. Numer. Anal. 13(4), 1976): the odd rows are
    eliminated (the Schur complement on the even ones is again block tridiagonal, half the size), the even rows'
    blocks of the inverse found, then the odd rows' from them, ``Σ_oo = D_o⁻¹ − Y₁ Σ_(o−1),o − Y₂ Σ_(o+1),o`` and
    ``Σ_o,e = −(Y₁ Σ_(o−1),e + Y₂ Σ_(o+1),e)`` with ``Y₁ = D_o⁻¹ N_o,(o−1)``, ``Y₂ = D_o⁻¹ N_o,(o+1)``. The same
    blocks as the Rauch-Tung-Striebel recursion in information form, without a Python step per ping. Each level
    keeps ``D_o⁻¹``, ``Y₁`` and ``Y₂`` where ``D_o``, ``N_(o−1),o`` and ``N_o,(o+1)`` were, and its even rows' Schur
    complement where theirs were; beside the output, one array of half the blocks per level (the even rows'
    couplings, m blocks over all levels), its operations a chunk of :data:`REDUCTION_CHUNK` blocks at a time."""
    _reduce(D, B)
    for lo in range(0, len(D), REDUCTION_CHUNK):
        block = D[lo:lo + REDUCTION_CHUNK]
        block[...] = 0.5 * (block + block.transpose(0, 2, 1))
    return D, B


def _reduce(D: np.ndarray, B: np.ndarray):
    """:func:`_block_covariance`'s recursion, in place: D (m, s, s) becomes the diagonal blocks of N⁻¹, B (m − 1, s, s)
    its blocks (k + 1, k)."""
    m, s = len(D), D.shape[1]
    if m == 1:
        D[:] = _inverse(D)
        return
    even, odd, before, after = D[0::2], D[1::2], B[0::2], B[1::2]  # before[j]: N_(o−1),o; after[j]: N_o,(o+1)
    no, nx = m // 2, (m - 1) // 2  # odd rows, odd rows with a next one (o = 2 j + 1)
    coupling = np.empty((nx, s, s))  # N'_(o−1),(o+1), then Σ_(o+1),(o−1)
    for c0 in range(0, no, REDUCTION_CHUNK):
        c1 = min(c0 + REDUCTION_CHUNK, no)
        x1 = min(c1, nx)
        Di = _inverse(odd[c0:c1])
        Y1 = Di @ before[c0:c1].transpose(0, 2, 1)  # D_o⁻¹ N_o,(o−1)
        Y2 = Di[:x1 - c0] @ after[c0:x1]  # D_o⁻¹ N_o,(o+1)
        even[c0:c1] -= before[c0:c1] @ Y1
        even[c0 + 1:x1 + 1] -= after[c0:x1].transpose(0, 2, 1) @ Y2
        coupling[c0:x1] = -(before[c0:x1] @ Y2)
        odd[c0:c1], before[c0:c1], after[c0:x1] = Di, Y1, Y2
    _reduce(even, coupling)  # the even rows: Σ_ee, and Σ_(e+2),e in coupling
    for c0 in range(0, no, REDUCTION_CHUNK):
        c1 = min(c0 + REDUCTION_CHUNK, no)
        x1 = min(c1, nx)
        Di, Y1, Y2 = odd[c0:c1], before[c0:c1], after[c0:x1]
        between = coupling[c0:x1]  # Σ_(o+1),(o−1)
        to_before = -(Y1 @ even[c0:c1])  # Σ_o,(o−1)
        to_before[:x1 - c0] -= Y2 @ between
        to_after = -(Y1[:x1 - c0] @ between.transpose(0, 2, 1) + Y2 @ even[c0 + 1:x1 + 1])  # Σ_o,(o+1)
        cov = Di - Y1 @ to_before.transpose(0, 2, 1)
        cov[:x1 - c0] -= Y2 @ to_after.transpose(0, 2, 1)
        odd[c0:c1], before[c0:c1], after[c0:x1] = cov, to_before, to_after.transpose(0, 2, 1)


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
            S = _banded_solve(problem, _given_system(D, B, u), 1e-12)
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
    return _survey_share(problem, X, dof, np.asarray(settings.survey_sigma, float))


def _survey_share(problem: _Problem, X: np.ndarray, dof: float, survey: np.ndarray) -> np.ndarray:
    """:func:`_survey_covariance` at the states X (its Hessian from the arrivals' observed information)."""
    z, Jz = _arrival_jacobians(problem, X)
    sums = _arrival_sums(problem, X, dof, information=True)
    D, B = _normal_blocks(problem, X, sums, problem.count * X[:-1, -1] + problem.offset)
    return _survey_covariance(problem, D, B, observed_information(z, dof), Jz, survey)


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
        sums, e, T, cost = _robust_terms(problem, X, dof)
        for _ in range(count):
            if run["converged"]:
                return
            step = _damped_solve(problem, partial(_step_system, problem, X, sums, e, T))
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
            X, (sums, e, T, cost) = trial, terms
            run.update(X=X, cost=cost, done=run["done"] + 1, converged=gain <= ROBUST_TOLERANCE * cost)

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
    X, cost = best["X"], best["cost"]  # the cost at X (its residuals' own)
    w = np.empty(len(problem.k))
    sums = _arrival_sums(problem, X, dof, information=True, weights=w)  # the Gauss-Newton weights beside
    problem.band = problem.rhs = problem.logs = problem.values = problem.squares = None  # the steps' buffers
    P = lag = None
    if covariance:
        blocks = partial(_normal_blocks, problem, X, sums, problem.count * X[:-1, -1] + problem.offset)
        P, lag = _block_covariance(*_dense_blocks(problem, blocks))
        if settings.survey_sigma is not None:
            z, Jz = _arrival_jacobians(problem, X)
            P += _survey_covariance(problem, *blocks(0, m), observed_information(z, dof), Jz,
                                    np.asarray(settings.survey_sigma, float))
    weights = np.zeros((m, n))
    weights[problem.k, problem.i] = w
    return RobustTrack(X, P, weights, cost, best["done"], index, P_lag=lag)


__all__ = ["ROBUST_COARSE_ITERATIONS", "ROBUST_COARSE_SCALE", "ROBUST_DOF", "ROBUST_ITERATIONS",
           "ROBUST_KEPT_WEIGHT", "ROBUST_SCREEN", "ROBUST_TOLERANCE", "RobustTrack", "observed_information",
           "robust_smooth", "survey_covariance"]
