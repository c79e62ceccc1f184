"""The robust smoother's normal equations and their solves: the Gauss-Newton Hessian, block tridiagonal over the
pings, by its nonzero entries, the gradient, and the step solved as the banded system it is (LAPACK's banded
Cholesky), damped where the system is numerically indefinite.

References
----------
Bell, "The iterated Kalman smoother as a Gauss-Newton method", SIAM J. Optim. 4(3), 1994 (the block tridiagonal
normal matrix); Nocedal & Wright, *Numerical Optimization*, Springer 2006, § 10.3 (Levenberg–Marquardt damping).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solveh_banded

from sblsim.models.tracking.smoother_cost import _depth_residual, _interval_prior, _Problem

#: Pings whose band entries :func:`_banded_solve` copies across at once (their band 96 KiB in 2-D).
ACROSS = 256


def _normal_blocks(problem: _Problem, X: np.ndarray, sums: np.ndarray, T: np.ndarray, lo: int = 0,
                   hi: int | None = None) -> tuple:
    """The Gauss-Newton Hessian of the robust cost, block tridiagonal (Bell 1994), by its nonzero entries over the
    pings ``lo:hi`` (default all): ``D`` {(i, j): (hi − lo,)} of the diagonal blocks (i ≤ j, the state's indices) and
    ``B`` {(i, j): (min(hi, m − 1) − lo,)} of the blocks (k, k + 1); the arrivals' per-ping sums ``sums``
    (:func:`~sblsim.models.tracking.smoother_cost._arrival_sums`' columns ``w J_x J_y``, all pings), the steps'
    durations ``T`` (m − 1,) at X's intervals.

    A step's whitened residual ``e_k = L_k⁻¹ (x_k+1 − f(x_k))`` has the Jacobian ``L_k⁻¹`` in ``x_k+1`` and
    ``−M_k = −L_k⁻¹ F_k`` in ``x_k`` (F_k: ``∂p/∂v = T``, ``∂p/∂Δ = n v``, ``∂t_e/∂Δ = n``); so the blocks gain
    ``M_kᵀ M_k`` (k), ``L_k⁻ᵀ L_k⁻¹`` (k + 1) and ``−M_kᵀ L_k⁻¹`` (k, k + 1), written out entry by entry."""
    P, dim = problem, problem.dim
    s, m = P.s, P.m
    hi = m if hi is None else hi
    te, dl = s - 2, s - 1
    rows, brows = hi - lo, max(min(hi, m - 1) - lo, 0)
    D, B = {}, {}
    known = P.entries  # the entries' keys of an earlier call: their arrays at once, zero
    if known is not None:
        store = np.zeros((len(known[0]) + len(known[1]), rows))
        D.update(zip(known[0], store))
        B.update(zip(known[1], store[len(known[0]):, :brows]))

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
    if known is None:
        P.entries = (tuple(D), tuple(B))  # the same keys every call (the state's size and the model's entries)
    return D, B


def _gradient(problem: _Problem, X: np.ndarray, sums: np.ndarray, e: np.ndarray, T: np.ndarray, lo: int = 0,
              hi: int | None = None) -> np.ndarray:
    """The robust cost's gradient's half, ``Jᵀ W r``, over the pings ``lo:hi`` (default all): (hi − lo, s)
    (:func:`_normal_blocks`' Jacobians; the arrivals' per-ping sums ``w z J_x``,
    :func:`~sblsim.models.tracking.smoother_cost._arrival_sums`' last columns, and the process residuals e, all
    pings)."""
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
    g = _gradient(problem, X, sums, e, T, lo, hi)
    return D, B, np.negative(g, out=g)


def _held_system(held: np.ndarray, system, lo: int, hi: int) -> tuple:
    """``system(lo, hi)`` (:func:`_step_system`'s) with the rows ``held`` (m,) bool fixed: their diagonal blocks the
    identity, their couplings to the rows beside and their right-hand side zero, so that the step leaves them where
    they are and the other rows' step is the one conditioned on them (a window of a track re-solved, the rest held)."""
    D, B, g = system(lo, hi)
    here = held[lo:hi]
    if here.any():
        for (i, j), value in D.items():
            value[here] = 1.0 if i == j else 0.0
        g[here] = 0.0
    if len(B):
        rows = len(next(iter(B.values())))
        touched = here[:rows] | held[lo + 1:lo + 1 + rows]  # the blocks (k, k + 1) with k or k + 1 held
        if touched.any():
            for value in B.values():
                value[touched] = 0.0
    return D, B, g


def _given_system(D: dict, B: dict, g: np.ndarray):
    """:func:`_banded_solve`'s ``system`` of the entries ``D``, ``B`` over all pings (:func:`_normal_blocks`) and the
    right-hand side g (m, s)."""
    def system(lo, hi):
        return {key: v[lo:hi] for key, v in D.items()}, {key: v[lo:hi] for key, v in B.items()}, g[lo:hi]
    return system


def _banded_solve(problem: _Problem, system, ridge: np.ndarray | float = 0.0, out: np.ndarray | None = None
                  ) -> np.ndarray:
    """Solve ``(N + diag(ridge)) δ = g`` for the symmetric positive definite block-tridiagonal N by LAPACK's banded
    Cholesky (:func:`scipy.linalg.solveh_banded`, its lower form, bandwidth s + 1 in :func:`_band_order`); δ (m, s).
    ``system(lo, hi)`` gives N's entries over the pings ``lo:hi`` as :func:`_normal_blocks` does, and g's rows
    (hi − lo, s); ``ridge`` (m, s) or a number is added to N's diagonal. The band and the right-hand side are written
    a chunk of pings at a time into the problem's buffers (which the solve then overwrites); δ into ``out`` (m, s)
    where given.

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
    # a chunk's band entries first as rows over its pings (each entry's values contiguous), then copied across
    # :data:`ACROSS` pings at a time (their band in the processor's cache): written an entry at a time into the band
    # (a ping's s (u + 1) entries side by side), each entry would be a strided pass over the chunk's band
    across = np.empty((s * (u + 1), max((hi - lo for lo, hi, *_ in problem.chunks()), default=0)))
    for lo, hi, *_ in problem.chunks():
        D, B, g = system(lo, hi)
        rows = across[:, :hi - lo]
        rows.fill(0.0)
        local = ridge[lo:hi] if np.ndim(ridge) else ridge
        for (i, j), value in D.items():
            first, second = sorted((place[i], place[j]))
            if i == j:
                value = value + (local[:, i] if np.ndim(local) else local)
            rows[first * (u + 1) + second - first] = value
        for (i, j), value in B.items():  # N[(k, i), (k + 1, j)] → lower N[(k + 1, j), (k, i)]
            rows[place[i] * (u + 1) + s + place[j] - place[i], :len(value)] = value
        flat = problem.band[lo * s:hi * s].reshape(hi - lo, s * (u + 1))
        for a in range(0, hi - lo, ACROSS):
            flat[a:a + ACROSS] = rows[:, a:a + ACROSS].T
        problem.rhs[lo:hi, place] = g
    solved = solveh_banded(problem.band.T, problem.rhs.reshape(-1), overwrite_ab=True, overwrite_b=True, lower=True,
                           check_finite=False)
    return np.take(solved.reshape(m, s), place, axis=1, out=out, mode="clip")


def _damped_solve(problem: _Problem, system, out: np.ndarray | None = None):
    """:func:`_banded_solve` of the Gauss-Newton step, damped where the system is numerically indefinite (a track far
    from its arrivals, each weighed down to nothing): ``μ diag(N)`` added (Levenberg–Marquardt; Nocedal & Wright,
    *Numerical Optimization*, Springer 2006, § 10.3), μ from 10⁻¹² up by tenfold steps to 1 after an undamped try;
    None if none holds. The step into ``out`` (m, s) where given."""
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
            step = _banded_solve(problem, system, ridge, out)
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
