"""The robust smoother's problem and its sums over the arrivals: the arrivals flattened and chunked by ping, their
normalised residuals and Jacobians, their per-ping sums of the Gauss-Newton Hessian's and gradient's entries, the
whitened process residuals and the cost (:func:`~sblsim.models.tracking.smoother.robust_smooth`).

References
----------
Lange, Little, Taylor, "Robust statistical modeling using the t distribution", JASA 84(408), 1989 (the Student-t
error and its weights); Baktoft et al. 2017 (YAPS: the state-space model fitted to every time of arrival).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix

from sblsim.models.tracking.arrival_model import ArrivalModel
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.toa import checked_sigma, per_receiver, reference_sigma

#: Degrees of freedom of the Student-t error of a time of arrival in the robust smoother
#: (:func:`~sblsim.models.tracking.smoother.robust_smooth`): a heavy tail (a late multipath arrival 10 σ off weighs
#: 4 / 103 of a good one), the common robust choice (Lange, Little, Taylor 1989).
ROBUST_DOF = 3.0


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
    """What every Gauss-Newton step of :func:`~sblsim.models.tracking.smoother.robust_smooth` shares: the arrivals,
    flattened (h of them: the ping ``k`` (h,), sorted, and receiver ``i`` (h,) of each, its time ``toa`` (h,) [s] and
    its receiver's coordinates ``r``, one (h,) array per axis [m]), the chunks of pings the passes take (:meth:`chunks`:
    :data:`CHUNK` pings each, with the sparse sum over each ping's arrivals), and the whitening of each step's process
    noise ``L_k⁻¹``, stored by its few distinct entries (m − 1,) each: per axis ``[[a, 0], [b, c]]`` on (position,
    velocity) (the inverse of the Cholesky factor of the white-noise acceleration's ``q [T³/3, T²/2; T²/2, T]`` over the
    step at the nominal interval, :func:`~sblsim.models.receiver.toa_bound.process_noise`), ``1 / σ_te`` on the emission
    time and ``1 / σ_drift`` on the interval; and the buffers the steps reuse (the band, its right-hand side, the
    arrivals' cost terms). Nothing of size m × m, nor (m, s, s) but the covariance's own blocks. ``sigma``: the
    timing noise [s], one, or each arrival's (h,) where the settings give one per receiver (:meth:`scale`)."""

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
        sigma = checked_sigma(settings.sigma_toa, receivers.shape[0])
        self.sigma = sigma[self.i] if per_receiver(sigma) else sigma
        self.band = self.rhs = self.logs = self.values = self.rows = self.squares = self.z = self.J = None
        self.entries = None  # the Hessian's entries' keys (smoother_system._normal_blocks)
        self._chunks = None
        self.heard = np.bincount(self.k, minlength=self.m)  # each ping's arrivals (:func:`_arrivals`' gathers)
        self.settings, self.count, self.offset = settings, schedule.count, schedule.offset
        self._delay = None  # the arrival model with late arrivals (:meth:`delay`)
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
        # the Hessian's entries that depend on the schedule alone (smoother_system._normal_blocks)
        a, b, c, n, tw, dw = self.a, self.b, self.c, self.count, self.te_w, self.dr_w
        self.A2, self.bc, self.cc, self.tw2, self.dw2 = a * a + b * b, b * c, c * c, tw**2, dw**2
        self.tw2n, self.delta = self.tw2 * n, (tw * n) ** 2 + self.dw2

    def delay(self) -> ArrivalModel | None:
        """The arrivals' error with the settings' late arrivals (``delay_share`` > 0; its core's ν the settings'
        ``delay_dof``, in place of the ν the passes are given), else None (the Student-t alone: its own, faster,
        operations)."""
        settings = self.settings
        if settings.delay_share <= 0.0:
            return None
        if self._delay is None:
            self._delay = ArrivalModel(settings.delay_dof, settings.delay_share,
                                       settings.delay_mean / reference_sigma(settings.sigma_toa))
        return self._delay

    def scale(self, a0: int, a1: int) -> float | np.ndarray:
        """The timing noise [s] of the arrivals ``a0:a1``: the one value, or theirs (a1 − a0,)."""
        return self.sigma[a0:a1] if per_receiver(self.sigma) else self.sigma

    def durations(self, X: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The steps' durations ``n_k Δ_k + o_k`` [s] (m − 1,) at the states X (m, s) (their intervals Δ the last
        column), into ``out`` where given."""
        T = np.multiply(self.count, X[:-1, -1], out=out)
        T += self.offset
        return T

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


def _arrivals(problem: _Problem, X: np.ndarray, lo: int, hi: int, a0: int, a1: int, keep: bool = False) -> tuple:
    """The arrivals ``a0:a1`` (those of the pings ``lo:hi``) at the states X (m, s): their normalised residuals z
    (a,) and the position columns of their Jacobians [1/σ units], one (a,) array per axis (the emission time's
    column is −1/σ_toa); by the operations of :func:`~sblsim.models.tracking.toa.toa_function`'s algorithm in its
    order (as :func:`~sblsim.models.tracking.toa._ranges`: the same numbers). With ``keep``, written into the
    problem's buffers ``z`` (h,) and ``J`` (dim, h) (:func:`_trial_cost`)."""
    P, settings = problem, problem.settings
    c, sigma = settings.sound_speed, P.scale(a0, a1)
    heard = P.heard[lo:hi]  # each ping's value repeated for its arrivals (in order: the pings' own)
    if keep:
        d = [np.subtract(np.repeat(X[lo:hi, a], heard), P.r[a][a0:a1], out=P.J[a, a0:a1]) for a in range(P.dim)]
    else:
        d = [np.repeat(X[lo:hi, a], heard) - P.r[a][a0:a1] for a in range(P.dim)]
    squares = np.square(d[0])
    work = np.empty_like(squares)
    for da in d[1:]:
        squares += np.square(da, out=work)
    rho = np.sqrt(squares, out=squares)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.multiply(rho, 2.0, out=work)  # (1 / (2 ρ)) / c
        np.divide(1.0, scale, out=scale)
        scale /= c
    for da in d:  # −(2 d) ((1 / (2 ρ)) / c) / σ, in place (−2 d exact, and the rounding even in the sign)
        da *= -2.0
        da *= scale
        da /= sigma
    rho /= c
    rho += np.repeat(X[lo:hi, -2], heard)
    z = np.subtract(P.toa[a0:a1], rho, out=P.z[a0:a1] if keep else rho)
    z /= sigma
    return z, d


def _chunk_sums(problem: _Problem, z: np.ndarray, J: list, dof: float, chunk: tuple, sums: np.ndarray,
                information: bool = False, weights: np.ndarray | None = None, late: tuple | None = None):
    """A chunk's rows of :func:`_arrival_sums`' ``sums`` from its arrivals' normalised residuals z (a,) and their
    Jacobians' position columns J (:func:`_arrivals`); ``late``: with late arrivals modelled, their EM weights and
    half gradients at z where already computed (:func:`_cost_terms`)."""
    P = problem
    lo, hi, a0, a1, S = chunk
    J = [*J, -1.0 / P.scale(a0, a1)]  # the emission time's column of every Jacobian
    model = P.delay()
    if model is None:
        z2 = z**2
        robust = np.add(dof, z2, out=z2)  # (ν + 1) / (ν + z²)
        np.divide(dof + 1.0, robust, out=robust)
        gradient = None
    else:  # the late arrivals' EM weight and half gradient (arrival_model)
        robust, gradient = late if late is not None else model.terms(z)[1:]
    if weights is not None:
        weights[a0:a1] = robust
    w = _information(P, z, dof) if information else robust
    # each product a contiguous row, then the rows side by side (a, q) for the sparse sum (a column at a time into
    # an array of rows of q would be strided: nearly twice the time)
    rows = P.rows[:sums.shape[1], :a1 - a0]
    wx = np.empty_like(z)
    row = 0
    for x in range(len(J)):
        np.multiply(w, J[x], out=wx)
        for y in range(x, len(J)):
            np.multiply(wx, J[y], out=rows[row])
            row += 1
    if not information:
        wz = np.multiply(w, z, out=wx) if gradient is None else gradient
        for x in range(len(J)):
            np.multiply(wz, J[x], out=rows[row + x])
    values = P.values[:(a1 - a0) * sums.shape[1]].reshape(a1 - a0, sums.shape[1])
    values[...] = rows.T
    sums[lo:hi] = S @ values


def _arrival_chunk(problem: _Problem, X: np.ndarray, dof: float, chunk: tuple, sums: np.ndarray,
                   information: bool = False, weights: np.ndarray | None = None):
    """:func:`_arrival_sums` over one chunk of pings (:meth:`_Problem.chunks`): its rows of ``sums`` filled, its
    arrivals' cost terms ``ln(1 + z² / ν)`` into the problem's buffer (not with ``information``)."""
    lo, hi, a0, a1, S = chunk
    z, J = _arrivals(problem, X, lo, hi, a0, a1)
    late = None if information else _cost_terms(problem, z, dof, a0, a1)
    _chunk_sums(problem, z, J, dof, chunk, sums, information, weights, late)


def _cost_terms(problem: _Problem, z: np.ndarray, dof: float, a0: int, a1: int) -> tuple | None:
    """The arrivals ``a0:a1``'s cost terms ``ln(1 + z² / ν)`` into the problem's buffer ``logs``; with late
    arrivals, :meth:`~sblsim.models.tracking.arrival_model.ArrivalModel.terms`' cost over ν + 1, and its EM weights
    and half gradients returned (for :func:`_chunk_sums`; else None)."""
    model = problem.delay()
    if model is not None:
        cost, h, g = model.terms(z)
        problem.logs[a0:a1] = cost / (dof + 1.0)
        return h, g
    z2 = np.square(z, out=problem.logs[a0:a1])
    z2 /= dof
    np.log1p(z2, out=z2)
    return None


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
    """The buffers the passes reuse: each chunk's arrivals' values (a, q) and the same as rows (q, a), every
    arrival's cost term (h,), residual (h,) and Jacobian's position columns (dim, h) (a trial's,
    :func:`_trial_cost`), and every process residual's square (m − 1, s)."""
    P, cols = problem, problem.dim + 1
    if P.logs is None:
        P.logs, P.squares = np.empty(len(P.k)), np.empty((P.m - 1, P.s))
        P.z, P.J = np.empty(len(P.k)), np.empty((P.dim, len(P.k)))
        longest, q = max((a1 - a0 for _, _, a0, a1, _ in P.chunks()), default=0), cols * (cols + 1) // 2 + cols
        P.values, P.rows = np.empty(longest * q), np.empty((q, longest))


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


def _robust_terms(problem: _Problem, X: np.ndarray, dof: float, into: tuple | None = None) -> tuple:
    """The robust smoother's terms at the states X (m, s), in one pass over chunks of pings: the arrivals' per-ping
    sums (:func:`_arrival_sums`), the whitened process residuals e (m − 1, s) (:func:`_process_residuals`), the
    steps' durations T (m − 1,) at X's intervals (the transitions' Jacobians F follow from T and the velocities,
    :func:`~sblsim.models.receiver.toa_bound.predict`) and the cost. ``into``: the arrays ``(sums, e, T)`` of an
    earlier call to write them into (of 10⁶ pings each new array would cost its pages' faults again), else new."""
    P, cols = problem, problem.dim + 1
    _buffers(P)
    if into is None:
        sums, e, T = np.empty((P.m, cols * (cols + 1) // 2 + cols)), np.empty((P.m - 1, P.s)), np.empty(P.m - 1)
    else:
        sums, e, T = into
    P.durations(X, T)
    for chunk in P.chunks():
        _arrival_chunk(P, X, dof, chunk, sums)
        _process_residuals(P, X, T, e, chunk[0], min(chunk[1], P.m - 1))
    return sums, e, T, _cost(P, X, dof)


def _cost(problem: _Problem, X: np.ndarray, dof: float) -> float:
    """The cost at the states X from the terms of the last pass (the arrivals' ``logs``, the process residuals'
    ``squares``) and the priors."""
    P = problem
    return float((dof + 1.0) * P.logs.sum() + P.squares.sum() + _interval_prior(P.settings, X) ** 2
                 + (_depth_residual(P, X) ** 2).sum())


def _trial_cost(problem: _Problem, X: np.ndarray, dof: float, into: tuple) -> float:
    """The cost at a trial's states X (m, s) alone (a line search's trial that may not be taken), in one pass over
    chunks of pings: the arrivals' residuals and Jacobians kept in the problem's buffers, the process residuals
    and the steps' durations into ``into`` ``(sums, e, T)`` (:func:`_robust_terms`'s), for :func:`_trial_sums` to
    complete the terms where the trial is taken (the same numbers as :func:`_robust_terms`)."""
    P = problem
    _buffers(P)
    _, e, T = into
    P.durations(X, T)
    for chunk in P.chunks():
        lo, hi, a0, a1, _ = chunk
        z, _ = _arrivals(P, X, lo, hi, a0, a1, keep=True)
        _cost_terms(P, z, dof, a0, a1)
        _process_residuals(P, X, T, e, lo, min(hi, P.m - 1))
    return _cost(P, X, dof)


def _trial_sums(problem: _Problem, dof: float, sums: np.ndarray):
    """The arrivals' per-ping sums (:func:`_arrival_sums`) of the trial whose cost :func:`_trial_cost` made last,
    into ``sums`` (m, q), from its kept residuals and Jacobians."""
    P = problem
    for chunk in P.chunks():
        a0, a1 = chunk[2], chunk[3]
        _chunk_sums(P, P.z[a0:a1], list(P.J[:, a0:a1]), dof, chunk, sums)


def _arrival_jacobians(problem: _Problem, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every arrival's normalised residual z (h,) and TOA Jacobian (h, dim + 1) [1/σ units] at the states X (one
    pass, :func:`_arrivals`: for the survey's consider covariance)."""
    z, J = _arrivals(problem, X, 0, problem.m, 0, len(problem.k))
    return z, np.column_stack([*J, -1.0 / problem.sigma if per_receiver(problem.sigma) else
                               np.full(len(z), -1.0 / problem.sigma)])


def _information(problem: _Problem, z: np.ndarray, dof: float) -> np.ndarray:
    """The arrivals' observed information at their normalised residuals z (h,): the Student-t's
    (:func:`observed_information`) or, with late arrivals, the mixture's."""
    model = problem.delay()
    return observed_information(z, dof) if model is None else model.information(z)


def _depth_residual(problem: _Problem, X: np.ndarray, at: slice = slice(None)) -> np.ndarray:
    """The depth readings' normalised residuals ``(z_k − (−depth_k)) / σ_depth`` at the pings that have one (``at``
    of them)."""
    return (X[problem.depth_at[at], 2] - problem.height[at]) * problem.depth_w


__all__ = ["CHUNK", "ROBUST_DOF", "observed_information"]
