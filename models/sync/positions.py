"""Each emission of a tag positioned from its synchronised times of arrival: the check of a synchronisation
against the sync tags' known positions (``sync_tags.csv``).

One emission's unknowns are the tag's position ``p`` (2-D or 3-D) and its emission time ``T``; an arrival at
receiver ``j`` is ``a_j = T + |p − p_j| s + ε_j`` with ``s`` the slowness and ``ε_j`` of sigma ``σ_j`` (the
receiver's timing noise), plus, for some arrivals, a multipath excess (an echo or a path around an obstacle: late)
or a false detection. A fix is robust to such arrivals and says what it could not check:

1. **The robust fix, from several starts.** Gauss–Newton with iteratively reweighted least squares, Student-t
   weights ``(ν + 1) / (ν + u²)`` (ν = :data:`NU`, ``u`` the residual over ``σ_j``: the t distribution's maximum
   likelihood, Lange, Little & Taylor 1989, *JASA* 84:881; the loss of the clock fit), from the centroid of the
   receivers that heard the emission and from a metre beside each of them (the ranges' cost has local minima, and a
   single start from the centroid converged to a wrong one 100 m away on the boats array); the start whose solution
   has the lowest t cost is kept. Where that solution has an arrival beyond the critical value ``k`` of the w-test
   (below), the fix is started again from the least squares of the arrivals less each one and each pair (up to
   :data:`LEAVE_OUT_MAX` arrivals: RANSAC's minimal-subset idea, Fischler & Bolles 1981, made exhaustive): with
   two arrivals late by a hundred sigmas the t cost has so many local minima that no start near a receiver reaches
   its lowest. The arrivals beyond ``k`` at the lowest are rejected.
2. **Data snooping** (Baarda 1968, *A testing procedure for use in geodetic networks*, Netherlands Geodetic
   Commission, Publ. Geodesy 2(5); Teunissen 2006, *Testing theory*, ch. 4): the kept arrivals' least squares, each
   arrival's w statistic (its residual over its own sigma ``σ_j √(1 − h_jj)``, ``h`` the hat matrix's diagonal),
   the largest beyond ``k`` rejected and the fix solved again, while the **redundancy** (arrivals less ``dim + 1``
   unknowns) is at least 2: with a redundancy of 1 an outlier can be detected but not identified (every w is the
   same). ``k`` is the two-sided normal critical value of the test size :data:`TEST_SIZE` (0.001, Baarda's: 3.29).
3. **The overall model test**: the kept arrivals' ``χ² = Σ u²`` against the χ² distribution with the redundancy's
   degrees of freedom at the same test size. Failed with a redundancy of 1: the fix is **failed** (an outlier that
   cannot be found), not trusted. Failed with more: the covariance is scaled by the a-posteriori variance factor
   ``χ² / redundancy`` (Koch 1999, *Parameter Estimation and Hypothesis Testing in Linear Models*, 3.2.4); a fix
   that passes keeps its own covariance (scaling every fix by ``max(1, χ²/r)`` would inflate the sigmas of
   consistent fixes as well).
4. **No redundancy, no check**: a fix with ``dim + 1`` arrivals kept (3 in 2-D: x, y and the emission time) fits
   them exactly whatever they are: **unchecked**, reported as such and not trusted (``ok`` false); fewer: **too few**.

The final least squares on the kept arrivals is solved from every start as well and the lowest χ² kept. A fix's
covariance is ``(Jᵀ Σ⁻¹ J)⁻¹`` at its solution (times the variance factor where the overall test failed).

All emissions are solved at once on padded arrays (emissions × starts × the receivers that hear the tag), in chunks
of :data:`CHUNK` rows, each Gauss–Newton step at most :data:`MAX_STEP`.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, fields

import numpy as np
from scipy.special import chdtri, ndtri

#: The largest Gauss–Newton step of a position [m], the most iterations.
MAX_STEP = 200.0
ITERATIONS = 30
#: A solution has converged when its last step is below this [m].
CONVERGED = 1e-2
#: Student-t degrees of freedom of the robust fix (the clock fit's).
NU = 3.0
#: The test size of the w-test and of the overall model test (Baarda's α₀), and the w-test's critical value.
TEST_SIZE = 1e-3
W_CRITICAL = float(-ndtri(TEST_SIZE / 2))
#: The most arrivals of an emission whose leave-one-or-two-out least squares start the robust fix again where its
#: first pass rejects one (C(12, 2) + 12 = 78 starts).
LEAVE_OUT_MAX = 12
#: The most (emission, start) rows solved at once (bounds the memory: rows × receivers × (dim + 1) doubles).
CHUNK = 20000
#: The emissions positioned at once [1] (each one's fix its own: a sync tag's season a block at a time, its
#: (emissions, starts, receivers) arrays a block's: :func:`position_emissions`).
EMISSIONS_BLOCK = 4096
#: A fix's status: trusted; its arrivals fitted exactly (redundancy 0); fewer than dim + 1 arrivals; the overall
#: test failed with a redundancy of 1; no converged solution.
CHECKED, UNCHECKED, TOO_FEW, FAILED, NOT_CONVERGED = "checked", "unchecked", "too few", "failed", "not converged"
#: A fix whose rejected arrival could be swapped for a kept one, both solutions passing the overall test.
AMBIGUOUS = "ambiguous"
#: A fix whose arrivals do not determine it (its normal matrix singular: the receivers that heard it all at one
#: place, or in a line through it in 2-D): its position undetermined in some direction, not trusted.
UNDETERMINED = "undetermined"
#: A normal matrix scaled to a unit diagonal is taken as singular where its smallest eigenvalue is below this share
#: of its largest (a condition number beyond 10¹²: float64 keeps 16 digits, a step or an inverse keeps none).
RCOND = 1e-12


@dataclass
class Fixes:
    """Positioned emissions: ``position`` (E, dim) [m] and ``covariance`` (E, dim, dim) [m²] (NaN where not
    trusted), ``emission_time`` (E,) [s], ``used`` (E, R) bool (the arrivals kept), ``ok`` (E,) bool (``status``
    ``checked``: redundancy ≥ 1, the overall test passed or its variance factor applied, converged), ``redundancy``
    (E,) int (kept arrivals less ``dim + 1``), ``chi2`` (E,) (the kept arrivals' sum of squared standardised
    residuals), ``variance_factor`` (E,) (1, or ``χ²/redundancy`` where the overall test failed), ``status`` (E,)
    str (``checked``, ``unchecked``, ``too few``, ``failed``, ``not converged``) and ``rejected`` (E,) int (the
    arrivals rejected)."""

    position: np.ndarray
    covariance: np.ndarray
    emission_time: np.ndarray
    used: np.ndarray
    ok: np.ndarray
    redundancy: np.ndarray | None = None
    chi2: np.ndarray | None = None
    variance_factor: np.ndarray | None = None
    status: np.ndarray | None = None
    rejected: np.ndarray | None = None


def _scaled_pinv(m: np.ndarray) -> np.ndarray:
    """(N, k, k) the pseudo-inverse of each symmetric matrix of a stack, scaled to a unit diagonal first (Jacobi:
    the position's metres and the emission time's seconds differ by the slowness, 10³), its eigenvalues below
    :data:`RCOND` of the largest left out (a rank-revealing inverse: Golub & Van Loan 2013, *Matrix Computations*,
    4th ed., § 5.5): a direction the arrivals do not determine gets no step; NaN where a matrix is not finite."""
    m = np.asarray(m, float)
    finite = np.isfinite(m).all(axis=(1, 2))
    m = np.where(finite[:, None, None], m, np.eye(m.shape[1]))
    d = np.sqrt(np.abs(np.diagonal(m, axis1=1, axis2=2)))
    d = np.where(d > 0, d, 1.0)
    scale = d[:, :, None] * d[:, None, :]
    inverse = np.linalg.pinv(m / scale, rcond=RCOND, hermitian=True) / scale
    return np.where(finite[:, None, None], inverse, np.nan)


def _solve(m: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``m⁻¹ rhs`` for a stack of normal matrices ``m`` (N, k, k) and ``rhs`` (N, k, 1): LU where every matrix is
    regular, else by :func:`_scaled_pinv` (the minimum-norm step: degenerate geometry, e.g. receivers in degrees,
    never stops the fix)."""
    try:
        return np.linalg.solve(m, rhs)
    except np.linalg.LinAlgError:
        return np.matmul(_scaled_pinv(m), rhs)


def _inverse(m: np.ndarray) -> np.ndarray:
    """The inverse of each matrix of a stack (N, k, k): LU where every one is regular, else :func:`_scaled_pinv`."""
    try:
        return np.linalg.inv(m)
    except np.linalg.LinAlgError:
        return _scaled_pinv(m)


def _determined(m: np.ndarray) -> np.ndarray:
    """(N,) bool: each normal matrix (N, k, k) regular once scaled to a unit diagonal (its condition number below
    1 / :data:`RCOND`)."""
    if not len(m):
        return np.zeros(0, bool)
    m = np.asarray(m, float)
    finite = np.isfinite(m).all(axis=(1, 2))
    m = np.where(finite[:, None, None], m, 0.0)
    d = np.sqrt(np.abs(np.diagonal(m, axis1=1, axis2=2)))
    good = finite & (d > 0).all(axis=1)
    d = np.where(d > 0, d, 1.0)
    eig = np.linalg.eigvalsh(m / (d[:, :, None] * d[:, None, :]))
    return good & (eig[:, 0] > RCOND * eig[:, -1])


def _jacobian(p, receivers, slowness):
    delta = p[:, None, :] - receivers[None, :, :]
    rng = np.maximum(np.linalg.norm(delta, axis=2), 1e-6)
    J = np.concatenate([delta / rng[..., None] * slowness[:, None, None], np.ones(rng.shape + (1,))], axis=2)
    return rng, J


def _gauss_newton(a, mask, receivers, sigma, slowness, p, T, robust: bool):
    """Batched Gauss–Newton (IRLS with Student-t weights if ``robust``) of rows ``a``, ``mask`` (N, R) from ``p``
    (N, dim), ``T`` (N,): the solution, its residuals (N, R) [s], Jacobian (N, R, dim + 1), least-squares
    information (N, dim + 1, dim + 1) and last step [m]. A row whose step is below 0.1 mm is left as it is."""
    dim = p.shape[1]
    p, T = p.copy(), T.copy()
    base = np.where(mask, 1.0 / sigma[None, :] ** 2, 0.0)
    move = np.full(len(p), np.inf)
    active = np.arange(len(p))
    for _ in range(ITERATIONS):
        if not len(active):
            break
        pa, Ta, ba, sa = p[active], T[active], base[active], slowness[active]
        rng, J = _jacobian(pa, receivers, sa)
        residual = np.where(mask[active], a[active] - Ta[:, None] - rng * sa[:, None], 0.0)
        w = ba * (NU + 1) / (NU + residual ** 2 * ba) if robust else ba
        Jw = J * w[..., None]
        info = np.matmul(Jw.transpose(0, 2, 1), J) + 1e-12 * np.eye(dim + 1)
        step = _solve(info, np.matmul(Jw.transpose(0, 2, 1), residual[..., None]))[..., 0]
        m = np.linalg.norm(step[:, :dim], axis=1)
        m = np.where(np.isfinite(m), m, np.inf)
        shrink = np.minimum(1.0, MAX_STEP / np.maximum(m, 1e-12))
        p[active] = pa + np.nan_to_num(step[:, :dim]) * shrink[:, None]
        T[active] = Ta + np.nan_to_num(step[:, dim]) * shrink
        move[active] = m
        active = active[m >= 1e-4]
    rng, J = _jacobian(p, receivers, slowness)
    residual = np.where(mask, a - T[:, None] - rng * slowness[:, None], 0.0)
    return p, T, residual, J, np.matmul((J * base[..., None]).transpose(0, 2, 1), J), move


def _solve_rows(a, mask, receivers, sigma, slowness, p, T, robust: bool):
    """:func:`_gauss_newton` in chunks of :data:`CHUNK` rows."""
    if not len(a):
        return _gauss_newton(a, mask, receivers, sigma, slowness, p, T, robust)
    parts = [_gauss_newton(a[i:i + CHUNK], mask[i:i + CHUNK], receivers, sigma, slowness[i:i + CHUNK],
                           p[i:i + CHUNK], T[i:i + CHUNK], robust) for i in range(0, len(a), CHUNK)]
    return tuple(np.concatenate([q[k] for q in parts]) for k in range(6))


def _starts(mask: np.ndarray, receivers: np.ndarray) -> np.ndarray:
    """(E, S, dim) [m]: the centroid of the receivers that heard each emission, then a metre from each of them
    towards it (on a receiver the range's gradient is undefined); an emission heard by fewer repeats the centroid."""
    E, R = mask.shape
    count = mask.sum(axis=1)
    centroid = (mask @ receivers) / np.maximum(count, 1)[:, None]
    S = 1 + int(count.max(initial=0))
    starts = np.repeat(centroid[:, None, :], S, axis=1)
    e, j = np.nonzero(mask)
    rank = np.cumsum(mask, axis=1)[e, j]  # 1 for an emission's first receiver
    towards = centroid[e] - receivers[j]
    towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-9)
    starts[e, rank] = receivers[j] + towards
    return starts


def _w_statistics(residual: np.ndarray, J: np.ndarray, mask: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(E, R) Baarda's w statistic of each kept arrival: its standardised residual over ``√(1 − h)``, ``h`` the
    whitened hat matrix's diagonal (0 where not kept)."""
    white = np.where(mask, 1.0 / sigma[None, :], 0.0)
    A = J * white[..., None]
    N = np.einsum("nrk,nrl->nkl", A, A) + 1e-12 * np.eye(J.shape[2])
    h = np.einsum("nrk,nkl,nrl->nr", A, _inverse(N), A)
    return np.where(mask, residual * white / np.sqrt(np.clip(1.0 - h, 1e-12, None)), 0.0)


def _t_cost(residual: np.ndarray, mask: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(N,) the Student-t negative log-likelihood Σ (ν+1)/2 log(1 + u²/ν) of the rows' kept residuals [s]."""
    return np.where(mask, (NU + 1) / 2 * np.log1p((residual / sigma[None, :]) ** 2 / NU), 0.0).sum(axis=1)


def _leave_out_starts(a, mask, receivers, sigma, slowness, p, T, cost):
    """The robust fix started also from the least squares of the arrivals less each one and each pair (while dim + 2
    remain; RANSAC's idea, Fischler & Bolles 1981, *Comm. ACM* 24:381, exhaustively over the small subsets): two
    arrivals late by a hundred sigmas leave the t cost so many local minima that no start near the receivers may
    reach its lowest. Returns the rows' (p, T, residual, cost) of the lowest t cost."""
    N, dim = p.shape
    row, left = [], []
    for n in range(N):
        heard = np.flatnonzero(mask[n])
        drop = [(i,) for i in heard]
        if len(heard) - 2 >= dim + 2:
            drop += list(itertools.combinations(heard, 2))
        row += [n] * len(drop)
        left += drop
    row = np.asarray(row, np.int64)
    sub = mask[row].copy()
    for k, d in enumerate(left):
        sub[k, list(d)] = False
    q, U, *_ = _solve_rows(a[row], sub, receivers, sigma, slowness[row], p[row], T[row], robust=False)
    q, U, residual, _, _, _ = _solve_rows(a[row], mask[row], receivers, sigma, slowness[row], q, U, robust=True)
    trial = np.where(np.isfinite(q).all(axis=1), _t_cost(residual, mask[row], sigma), np.inf)
    best = np.full(N, -1)
    low = cost.copy()
    for k in np.argsort(trial):  # the lowest trial of each row, where below the row's cost
        if trial[k] < low[row[k]]:
            low[row[k]] = trial[k]
            best[row[k]] = k
    p, T = p.copy(), T.copy()
    rng = np.linalg.norm(p[:, None, :] - receivers[None], axis=2)
    res = np.where(mask, a - T[:, None] - rng * slowness[:, None], 0.0)
    take = best >= 0
    p[take], T[take], res[take] = q[best[take]], U[best[take]], residual[best[take]]
    return p, T, res, low


def _not_separable(a, heard, mask, receivers, sigma, slowness, p, T, info, factor, redundancy) -> np.ndarray:
    """(E,) bool: a fix whose rejection cannot be told from another: a rejected arrival ``k`` restored and a kept
    one ``j`` left out instead gives a solution that passes the overall test too, farther from the fix than its
    χ²_dim critical value in the fix's own covariance (Teunissen 2006, ch. 4: an outlier identifiable only if its
    w-test is separable from the others'). One receiver alone on one side of the array is the typical case: drop
    it, or the one beside it, and either fits."""
    E, dim = p.shape
    e, k = np.nonzero(heard & ~mask & (redundancy >= 1)[:, None])
    if not len(e):
        return np.zeros(E, bool)
    kept = mask[e]
    pair_e = np.repeat(e, kept.sum(axis=1))
    pair_k = np.repeat(k, kept.sum(axis=1))
    pair_j = np.nonzero(kept)[1]
    swap = mask[pair_e].copy()
    swap[np.arange(len(pair_e)), pair_k] = True
    swap[np.arange(len(pair_e)), pair_j] = False
    q, _, residual, _, _, move = _solve_rows(a[pair_e], swap, receivers, sigma, slowness[pair_e], p[pair_e],
                                             T[pair_e], robust=False)
    chi2 = np.where(swap, (residual / sigma[None, :]) ** 2, 0.0).sum(axis=1)
    passes = (move < CONVERGED) & (chi2 <= chdtri(redundancy[pair_e], TEST_SIZE))
    cov = _inverse(info[pair_e] + 1e-12 * np.eye(dim + 1))[:, :dim, :dim] * factor[pair_e, None, None]
    d = q - p[pair_e]
    far = np.einsum("nk,nkl,nl->n", d, _inverse(cov), d) > chdtri(dim, TEST_SIZE)
    out = np.zeros(E, bool)
    out[pair_e[passes & far]] = True
    return out


def position_emissions(arrival: np.ndarray, receivers: np.ndarray, sigma: np.ndarray, slowness: np.ndarray
                       ) -> Fixes:
    """Position each emission robustly, with its redundancy and the overall test (the module docstring);
    :data:`EMISSIONS_BLOCK` emissions at a time (each one's fix its own, so a season's arrays are a block's).

    Parameters
    ----------
    arrival : numpy.ndarray
        (E, R) [s] the synchronised times of arrival, NaN where not heard.
    receivers : numpy.ndarray
        (R, dim) [m] the receivers' positions.
    sigma : numpy.ndarray
        (R,) [s] each receiver's timing sigma.
    slowness : numpy.ndarray
        (E,) [s/m] 1 / the sound speed of each emission.

    Returns
    -------
    Fixes
        Per emission; ``ok`` only where the fix was checked (redundancy ≥ 1) and passed.

    Raises
    ------
    ValueError
        Arrays of inconsistent shapes (a programming error: the callers build them).
    """
    arrival = np.asarray(arrival, float)
    receivers = np.asarray(receivers, float)
    sigma, slowness = np.asarray(sigma, float), np.asarray(slowness, float)
    E, R = arrival.shape
    if receivers.shape[0] != R or sigma.shape != (R,) or slowness.shape != (E,):
        raise ValueError("position_emissions: arrival (E, R), receivers (R, dim), sigma (R,), slowness (E,)")
    cols = np.flatnonzero(np.isfinite(arrival).any(axis=0))  # only the receivers that hear this tag
    if E <= EMISSIONS_BLOCK:
        return _positioned(arrival, cols, receivers, sigma, slowness)
    # each emission's fix its own: a block of emissions at a time, the memory of a block's (E, S, R) arrays
    blocks = [_positioned(arrival[lo:lo + EMISSIONS_BLOCK], cols, receivers, sigma, slowness[lo:lo + EMISSIONS_BLOCK])
              for lo in range(0, E, EMISSIONS_BLOCK)]
    return Fixes(*(np.concatenate([getattr(b, f.name) for b in blocks]) for f in fields(Fixes)))


def _positioned(arrival: np.ndarray, cols: np.ndarray, receivers: np.ndarray, sigma: np.ndarray,
                slowness: np.ndarray) -> Fixes:
    """:func:`position_emissions` of the emissions ``arrival`` (E, R) on the receivers ``cols`` (those that hear
    the tag at all)."""
    E, R = arrival.shape
    dim = receivers.shape[1]
    heard = np.isfinite(arrival)
    a, mask0, rec, sig = np.where(heard, arrival, 0.0)[:, cols], heard[:, cols], receivers[cols], sigma[cols]
    count0 = mask0.sum(axis=1)
    starts = _starts(mask0, rec)
    S = starts.shape[1]
    # each start's emission time: the median of its arrivals less their travel times from it (the robust weights of
    # the first step are then the start's, not those of a time off by the ranges)
    flight = np.linalg.norm(starts[:, :, None, :] - rec[None, None], axis=3) * slowness[:, None, None]
    with warnings.catch_warnings():  # an emission heard by none: its start time 0
        warnings.simplefilter("ignore", RuntimeWarning)
        T0 = np.nanmedian(np.where(mask0[:, None, :], a[:, None, :] - flight, np.nan), axis=2) if E and len(rec) \
            else np.zeros((E, S))
    T0 = np.where(np.isfinite(T0), T0, 0.0).reshape(E * S)

    def every_start(mask: np.ndarray, robust: bool):
        rows = (np.repeat(a, S, axis=0), np.repeat(mask, S, axis=0))
        return _solve_rows(*rows, rec, sig, np.repeat(slowness, S), starts.reshape(E * S, dim), T0,
                           robust)

    # 1. the robust fix from every start; the lowest t cost kept, the arrivals beyond the w-test's value rejected
    pS, TS, resS, _, _, moveS = every_start(mask0, robust=True)
    u = resS / sig[None, :]
    cost = np.where(np.repeat(mask0, S, axis=0), (NU + 1) / 2 * np.log1p(u ** 2 / NU), 0.0).sum(axis=1)
    cost = np.where(np.isfinite(cost) & np.isfinite(pS).all(axis=1), cost, np.inf).reshape(E, S)
    pick = np.arange(E) * S + np.argmin(cost, axis=1)
    p, T = pS[pick], TS[pick]
    best_cost = cost[np.arange(E), np.argmin(cost, axis=1)]
    residual = resS[pick]
    # where that rejects an arrival: also from the least squares of the arrivals less one or two of them
    suspect = np.flatnonzero((mask0 & (np.abs(residual / sig[None, :]) > W_CRITICAL)).any(axis=1)
                             & (count0 <= LEAVE_OUT_MAX))
    if len(suspect):
        p[suspect], T[suspect], residual[suspect], best_cost[suspect] = _leave_out_starts(
            a[suspect], mask0[suspect], rec, sig, slowness[suspect], p[suspect], T[suspect], best_cost[suspect])
    mask = mask0 & (np.abs(residual / sig[None, :]) <= W_CRITICAL)
    # a rejection that would leave no redundancy identifies nothing (any dim + 1 arrivals fit exactly): all kept,
    # the overall test judges
    blind = (mask.sum(axis=1) < dim + 2) & (count0 >= dim + 2)
    mask[blind] = mask0[blind]
    # 2. data snooping while the redundancy identifies the outlier
    p, T, residual, J, info, move = _solve_rows(a, mask, rec, sig, slowness, p, T, robust=False)
    rows = np.arange(E)  # the fixes still snooped: solved again only where an arrival was rejected
    for _ in range(int(count0.max(initial=0))):
        w = np.abs(_w_statistics(residual[rows], J[rows], mask[rows], sig))
        worst = np.argmax(w, axis=1)
        bad = (w[np.arange(len(rows)), worst] > W_CRITICAL) & (mask[rows].sum(axis=1) - (dim + 1) >= 2)
        if not bad.any():
            break
        rows, worst = rows[bad], worst[bad]
        mask[rows, worst] = False
        p[rows], T[rows], residual[rows], J[rows], info[rows], move[rows] = _solve_rows(
            a[rows], mask[rows], rec, sig, slowness[rows], p[rows], T[rows], robust=False)
    chi2 = np.where(mask, (residual / sig[None, :]) ** 2, 0.0).sum(axis=1)
    # the kept arrivals' least squares from every start: the lowest χ² of the converged solutions
    pS, TS, resS, _, infoS, moveS = every_start(mask, robust=False)
    chiS = np.where(np.repeat(mask, S, axis=0), (resS / sig[None, :]) ** 2, 0.0).sum(axis=1)
    chiS = np.where((moveS < CONVERGED) & np.isfinite(pS).all(axis=1), chiS, np.inf).reshape(E, S)
    best = np.argmin(chiS, axis=1)
    better = (chiS[np.arange(E), best] < chi2 - 1e-9) | ~(move < CONVERGED)
    pick = np.arange(E) * S + best
    p = np.where(better[:, None], pS[pick], p)
    T = np.where(better, TS[pick], T)
    info = np.where(better[:, None, None], infoS[pick], info)
    move = np.where(better, moveS[pick], move)
    chi2 = np.where(better, chiS[np.arange(E), best], chi2)
    # 3. and 4. the overall test, the redundancy
    redundancy = mask.sum(axis=1) - (dim + 1)
    limit = chdtri(np.maximum(redundancy, 1), TEST_SIZE)
    fail = (redundancy >= 1) & (chi2 > limit)
    factor = np.where(fail & (redundancy >= 2), chi2 / np.maximum(redundancy, 1), 1.0)
    status = np.full(E, CHECKED, dtype=object)
    status[fail & (redundancy == 1)] = FAILED
    status[_not_separable(a, mask0, mask, rec, sig, slowness, p, T, info, factor, redundancy)] = AMBIGUOUS
    status[redundancy == 0] = UNCHECKED
    status[redundancy < 0] = TOO_FEW
    status[(redundancy >= 0) & ~((move < CONVERGED) & np.isfinite(p).all(axis=1))] = NOT_CONVERGED
    checked = np.flatnonzero(status == CHECKED)
    status[checked[~_determined(info[checked])]] = UNDETERMINED
    ok = status == CHECKED
    covariance = np.full((E, dim, dim), np.nan)
    if ok.any():
        covariance[ok] = _inverse(info[ok] + 1e-12 * np.eye(dim + 1))[:, :dim, :dim] * factor[ok, None, None]
    p, T = p.copy(), T.copy()
    p[~ok] = np.nan
    T[~ok] = np.nan
    used = np.zeros((E, R), bool)
    used[:, cols] = mask
    return Fixes(p, covariance, T, used, ok, redundancy, np.where(redundancy >= 0, chi2, np.nan), factor, status,
                 count0 - mask.sum(axis=1))


__all__ = ["AMBIGUOUS", "CHECKED", "CHUNK", "EMISSIONS_BLOCK", "FAILED", "Fixes", "ITERATIONS", "MAX_STEP",
           "NOT_CONVERGED", "NU", "RCOND", "TEST_SIZE", "TOO_FEW", "UNCHECKED", "UNDETERMINED", "W_CRITICAL",
           "position_emissions"]
