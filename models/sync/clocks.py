"""Receiver clocks synchronised from sync tags: the model, the emissions grouped, the robust sparse solve.

The model follows the structure of the sync model of YAPS (Baktoft, Gjelland, Økland & Thygesen 2017, *Positioning
of aquatic animals based on time-of-arrival and random walk models using YAPS*, Sci. Rep. 7:14294, and its R
package's sync model): the arrival of sync-tag emission ``e`` at receiver ``j``, logged on ``j``'s own clock, is

    r_ej = T_e + d_ij / c + o_j(r_ej) + ε_ej,

with ``T_e`` the emission time (an unknown per emission, on the reference receiver's clock), ``d_ij`` the distance
from the sync tag ``i`` (at its receiver's known position) to receiver ``j``, ``c`` the sound speed, ``o_j`` the
receiver's **clock offset** (the reference receiver's is 0: the "timekeeper") and ``ε`` a heavy-tailed error
(multipath arrivals are late; false detections anywhere).

What is chosen here, and why:

* ``o_j`` is **piecewise linear in time bins and continuous across them**: one value per bin edge (a knot), the
  **drift** [s/s] constant within a bin. YAPS fits an offset and a slope (and a quadratic term) per bin, each bin on
  its own; a crystal's offset is continuous (a jump, a reset or a download, is a **break**: the clock split into
  segments there, :mod:`sblsim.models.sync.breaks`), so sharing each edge
  between two bins halves the unknowns and lets a bin with few sync detections be **bridged** by its neighbours.
  The offset is a function of the receiver's own clock (``o_j(r)``: the correction to subtract from a time it
  logged), which keeps the model linear: the unknowns enter linearly, so one weighted least-squares solve per
  reweighting step fits them, no starting point needed.
* the drift changes little from one bin to the next: a weak prior on the knots' second differences (the drift's
  change between adjacent bins, σ ``drift_change`` × the bin width) bridges a gap in the data and keeps the normal
  equations positive definite; it is 20 times the timing noise over an hour's bin, so the data decide wherever
  they exist.
* the sound speed is given per arrival (a constant, or a temperature/sound-speed series), or **estimated** as one
  slowness ``1/c``, which enters linearly (``d_ij · s``).
* robust: iteratively reweighted least squares with Student-t weights (ν = 3) on each residual standardised by its
  receiver's scale (the median absolute deviation, corrected for the leverage of the emission time, which the
  emission's other arrivals share), until no knot moves by a twentieth of the smallest scale, then the
  arrivals beyond ``reject`` scales **rejected** and the rest fitted by
  least squares, each receiver's noise scale re-estimated from its kept residuals; the covariance of that final
  weighted fit gives the sigmas.
* the receivers' horizontal positions **fixed** (the table's) or **refined** (:class:`Geometry`): each receiver's
  shift from the table's position an unknown pair with a Gaussian prior of the survey's sigma (a network adjustment
  with a priori information: Tapley, Schutz & Born 2004, *Statistical Orbit Determination*, ch. 4.6), its sync tag
  at the same position (the model's assumption: the tag hangs at its receiver). The distance is not linear in the
  positions: each solve is a Gauss–Newton step, linearised at the current positions (``d ≈ d₀ + u·(δ_tag −
  δ_receiver)``, ``u`` the horizontal unit vector from the receiver to the tag; depths fixed). The arrivals fix
  the array's shape only: a translation or a rotation of the whole array changes no distance, so the datum is
  fixed by the prior alone (a finite survey sigma is required; the array's mean shift and rotation come out near
  the table's with a sigma of about the survey sigma over √receivers).
* sparse: the emission times are eliminated (each is in its own arrivals' rows only: a diagonal block), leaving the
  knots' normal equations (receivers × bins), assembled with :mod:`scipy.sparse`; the reweighting's solves by
  :func:`scipy.sparse.linalg.splu`, the last one with the sigmas densely (Cholesky and the inverse) up to
  :data:`DENSE_LIMIT` unknowns and beyond by :func:`~sblsim.models.sync.selected_inversion.selected_inverse`: in
  time order the knots' normal equations are block tridiagonal (an edge's receivers couple to the next edges' only),
  so the inverse's entries the sigmas need (each knot's variance, its covariance with the next edge's) cost
  blocks × block³, not unknowns³ (a month of 70 receivers: 50,000 knots).
"""

from __future__ import annotations

from dataclasses import dataclass
from time import perf_counter

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg

from sblsim.models.declarations import ModelError
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.selected_inversion import SelectedCovariance, selected_inverse

#: The refusal where the clocks' normal equations are singular (a clock, or the sound speed, that the arrivals kept
#: leave free: a sync tag left out, or rejections, can leave a receiver's bin without an arrival tying it).
SINGULAR = ("sync: the clocks' normal equations are singular (a clock or the sound speed that the arrivals kept leave "
            "undetermined); allowed: sync-tag arrivals that tie every synchronised receiver's clock in every bin")

#: The most unknowns whose covariance is a dense inverse (2000² doubles, 32 MB); beyond,
#: :func:`~sblsim.models.sync.selected_inversion.selected_inverse`.
DENSE_LIMIT = 2000
#: Student-t degrees of freedom of the reweighting, and the rejection threshold [standardised residuals].
NU = 3.0
REJECT = 4.0
#: The smallest noise scale a receiver is given [s] (a millisecond-resolution logger rounds to 0.5 ms).
MIN_SCALE = 1e-6
#: A steady clock's drift prior, as a share of the drift prior's sigma (``fit_clocks``'s ``steady``).
STEADY = 1e-3


@dataclass
class Geometry:
    """The receivers' positions refined with the clocks (the module docstring).

    Attributes
    ----------
    source : numpy.ndarray
        (n,) int, the receiver at which each arrival's sync tag sits.
    positions : numpy.ndarray
        (R, dim) [m] the table's (the survey's) positions; dim 2 or 3 (depths fixed).
    sigma : float or numpy.ndarray
        [m] the survey's horizontal sigma per axis: the prior of each receiver's shift from its table position; one
        for all, or (R,) one per receiver (a tiny one holds a receiver at the table's position).
    shift : numpy.ndarray, optional
        (R, 2) [m] the shifts to start from (default 0: the table).
    site : numpy.ndarray, optional
        (clocks,) int, the receiver (row of ``positions``) of each clock the fit is given, where a receiver's clock
        was split into segments at a break (:mod:`sblsim.models.sync.breaks`): its segments share one position;
        default one clock per receiver.
    """

    source: np.ndarray
    positions: np.ndarray
    sigma: float | np.ndarray
    shift: np.ndarray | None = None
    site: np.ndarray | None = None


def fit_clocks(receiver: np.ndarray, emission: np.ndarray, time: np.ndarray, distance: np.ndarray,
               slowness: np.ndarray | None, used: np.ndarray, synchronised: np.ndarray, reference: int,
               bin_width: float, drift_change: float = 1e-6, reject: float = REJECT, max_iterations: int = 20,
               keep: np.ndarray | None = None, scale: np.ndarray | None = None, sigmas: bool = True,
               geometry: Geometry | None = None, timings: dict | None = None,
               steady: np.ndarray | None = None, ties: np.ndarray | None = None) -> ClockFit:
    """Fit the receivers' clocks to the sync tags' arrivals (the module docstring's model).

    Parameters
    ----------
    receiver, emission : numpy.ndarray
        (n,) int, each arrival's receiver (in [0, R)) and emission (in [0, E)).
    time : numpy.ndarray
        (n,) [s] the arrival on its receiver's clock, from an origin the caller chose (at most days away: the
        precision of a double).
    distance : numpy.ndarray
        (n,) [m] from the sync tag to the receiver (with ``geometry``, recomputed from its positions).
    slowness : numpy.ndarray or None
        (n,) [s/m] 1 / the sound speed at each arrival; None: one slowness estimated.
    used : numpy.ndarray
        (n,) bool, the arrivals to fit (not a later duplicate, at a synchronised receiver).
    synchronised : numpy.ndarray
        (R,) bool, the receivers to synchronise (tied to the reference:
        :func:`~sblsim.models.sync.emissions.connected`).
    reference : int
        The reference receiver (its offset 0).
    bin_width : float
        [s] the time bins' width.
    drift_change : float
        [s/s] the prior sigma of the drift's change from one bin to the next.
    reject : float
        The standardised residual beyond which an arrival is rejected.
    max_iterations : int
        The reweighting's most steps.
    keep, scale : numpy.ndarray, optional
        (n,) bool and (R,) [s]: the arrivals kept and the receivers' scales of an earlier fit: no reweighting, the
        kept arrivals' least squares only (a fit with some arrivals left out, e.g. a sync tag's).
    sigmas : bool
        Compute the offsets' and drifts' sigmas (a dense inverse up to :data:`DENSE_LIMIT` unknowns, beyond it the
        selected inverse of the block-tridiagonal normal equations:
        :func:`~sblsim.models.sync.selected_inversion.selected_inverse`); else NaN.
    geometry : Geometry, optional
        Refine the receivers' horizontal positions with the clocks, a prior of the survey's sigma at the table's
        positions (the module docstring); default the positions fixed. The shifts' covariance is always computed.
    timings : dict, optional
        Filled with the seconds of the stages (``reweighting``, ``least_squares``, ``covariance``: the last
        solve's, with the sigmas) for a benchmark.
    steady : numpy.ndarray, optional
        (R,) bool, the clocks whose offset is a constant (its drift held at 0 within :data:`STEADY` of the drift
        prior): the reference receiver's segments after a break of its clock (the same crystal as the time base;
        :mod:`sblsim.models.sync.breaks`). Default none.
    ties : numpy.ndarray, optional
        (T, 3) int: two clocks and a bin whose drifts in that bin are tied by the drift prior's sigma (a clock's two
        segments either side of a break: its crystal runs on at its rate). Default none.

    Returns
    -------
    ClockFit

    Raises
    ------
    ModelError
        Fewer than two synchronised receivers, no arrival used, or normal equations singular (:data:`SINGULAR`).
    """
    n_receivers = len(synchronised)
    used = used & synchronised[receiver]
    if synchronised.sum() < 2 or not used.any():
        raise ModelError("sync: fewer than two receivers hear common sync-tag emissions; nothing to synchronise")
    rows = np.flatnonzero(used)
    rec, em, t, d = receiver[rows], emission[rows], time[rows], distance[rows]
    start = np.floor(t.min() / bin_width) * bin_width
    n_bins = max(1, int(np.ceil((t.max() - start) / bin_width + 1e-12)))
    edges = start + bin_width * np.arange(n_bins + 1)
    k = np.clip(np.floor((t - start) / bin_width).astype(np.int64), 0, n_bins - 1)
    f = (t - edges[k]) / bin_width
    free = synchronised.copy()
    free[reference] = False
    base = np.full(n_receivers, -1, np.int64)
    base[free] = np.arange(free.sum()) * (n_bins + 1)
    n_knots = int(free.sum()) * (n_bins + 1)
    estimate = slowness is None
    first = n_knots + int(estimate)  # the first shift's column
    # with the positions refined, each clock's receiver (its site: the segments of a broken clock share one)
    n_sites = 0 if geometry is None else len(geometry.positions)
    site = np.arange(n_receivers) if geometry is None or geometry.site is None else np.asarray(geometry.site)
    p = first + 2 * n_sites
    on = base[rec] >= 0
    r_on = np.flatnonzero(on)
    cols = np.r_[base[rec[on]] + k[on], base[rec[on]] + k[on] + 1]
    vals = np.r_[1 - f[on], f[on]]
    rr = np.r_[r_on, r_on]
    s_given = None if estimate else slowness[rows]
    emissions, em_local = np.unique(em, return_inverse=True)
    # with the positions refined, each emission's observations are taken from its first arrival (the emission time
    # absorbs the constant): times of 10⁶ s otherwise cancel to the millimetres the positions' equations resolve
    anchor = np.zeros(len(emissions))
    if geometry is not None:
        anchor = np.full(len(emissions), np.inf)
        np.minimum.at(anchor, em_local, t)
    E = sp.csr_matrix((np.ones(len(t)), (np.arange(len(t)), em_local)), shape=(len(t), len(emissions)))
    prior = _prior(free, base, n_bins, p, drift_change * bin_width, steady, ties)
    # the knots in time order (each edge's receivers together: the normal equations are block tridiagonal in that
    # order) and each knot's pair with the next edge's (the drift's covariance)
    n_free = int(free.sum())
    order = (np.arange(n_free)[None, :] * (n_bins + 1) + np.arange(n_bins + 1)[:, None]).ravel()
    pairs = (np.arange(n_free)[:, None] * (n_bins + 1) + np.arange(n_bins)[None, :]).ravel()
    pairs = np.c_[pairs, pairs + 1]
    dense_limit = DENSE_LIMIT
    if geometry is not None:
        survey = np.broadcast_to(np.asarray(geometry.sigma, float), (n_sites,))
        if not np.isfinite(survey).all() or (survey <= 0).any():
            raise ModelError("sync: the survey sigma must be finite and positive (the prior fixes the datum)")
        prior = prior + sp.diags(np.r_[np.zeros(first), np.repeat(survey ** -2, 2)])
        src = geometry.source[rows]
        at = site[rec]
        shift = np.zeros((n_sites, 2)) if geometry.shift is None else np.array(geometry.shift, float)
    s_now = 1.0 / 1480.0

    def design(shift: np.ndarray | None, s_now: float):
        """The design matrix and the observations, linearised at the current shifts and slowness."""
        if geometry is None:
            dd = d
        else:
            where = np.array(geometry.positions, float)
            where[:, :2] += shift
            diff = where[src] - where[at]
            dd = np.linalg.norm(diff, axis=1)
            ok = (dd > 1e-6) & (src != at)
            u = np.where(ok[:, None], diff[:, :2] / np.where(ok, dd, 1.0)[:, None], 0.0)
        y = t.copy() if estimate else t - dd * s_given
        r_, c_, v_ = [rr], [cols], [vals]
        if estimate:
            r_.append(np.arange(len(t)))
            c_.append(np.full(len(t), n_knots))
            v_.append(dd)
        if geometry is not None:
            s = np.full(len(t), s_now) if estimate else s_given
            y = y + s * np.sum(u * (shift[src] - shift[at]), axis=1)
            m = np.flatnonzero(ok)
            for axis in (0, 1):
                r_ += [m, m]
                c_ += [first + 2 * src[m] + axis, first + 2 * at[m] + axis]
                v_ += [s[m] * u[m, axis], -s[m] * u[m, axis]]
        B = sp.csr_matrix((np.concatenate(v_), (np.concatenate(r_), np.concatenate(c_))), shape=(len(t), p))
        return B, (y - anchor[em_local] if geometry is not None else y), dd

    def solve(w: np.ndarray, B, y, covariance: bool = False, shifts: bool = False):
        W = sp.diags(w)
        D = np.asarray(E.T @ w).ravel()
        Dinv = sp.diags(1.0 / np.maximum(D, 1e-300))
        NEB = (E.T @ W @ B).tocsr()
        S = (B.T @ W @ B - NEB.T @ Dinv @ NEB + prior).tocsc()
        ety = E.T @ (w * y)
        rhs = B.T @ (w * y) - NEB.T @ (ety / np.maximum(D, 1e-300))
        cov = shift_cov = None
        if covariance and p <= dense_limit:
            try:
                factor = scipy.linalg.cho_factor(S.toarray(), lower=True, check_finite=False)
            except np.linalg.LinAlgError:  # not positive definite: a clock the arrivals leave free
                raise ModelError(SINGULAR) from None
            x = scipy.linalg.cho_solve(factor, rhs, check_finite=False)
            full = scipy.linalg.cho_solve(factor, np.eye(p), check_finite=False)
            cov = SelectedCovariance(np.diag(full)[:n_knots].copy(), full[pairs[:, 0], pairs[:, 1]],
                                     full[n_knots:, n_knots:])
            if shifts:
                shift_cov = full[first:, first:]
        elif p > dense_limit:  # the block-tridiagonal factorisation (faster than splu's at this size)
            try:
                x, selected = selected_inverse(S, n_knots, order, rhs, pairs if covariance else None)
            except np.linalg.LinAlgError:
                raise ModelError(SINGULAR) from None
            cov = selected if covariance else None
            if shifts:
                shift_cov = selected.border[int(estimate):, int(estimate):]
        else:
            try:
                lu = scipy.sparse.linalg.splu(S)
            except RuntimeError:  # SuperLU: "Factor is exactly singular"
                raise ModelError(SINGULAR) from None
            x = lu.solve(rhs)
            if shifts:
                shift_cov = lu.solve(np.eye(p)[:, first:])[first:]
        T = (ety - NEB @ x) / np.maximum(D, 1e-300)
        return x, T, D, cov, shift_cov

    def update(x: np.ndarray):
        """The current slowness and shifts from a solve."""
        nonlocal s_now, shift
        if estimate:
            s_now = float(x[n_knots])
        moved = 0.0
        if geometry is not None:
            new = x[first:].reshape(n_sites, 2)
            moved = float(np.max(np.abs(new - shift)))
            shift = new
        return moved

    shift_now = lambda: shift if geometry is not None else None  # noqa: E731
    given = keep is not None
    timings = {} if timings is None else timings
    tick = perf_counter()
    scale = np.full(n_receivers, 1e-3) if scale is None else np.where(np.isfinite(scale), scale, 1e-3)
    tw = np.ones(len(t))
    previous = None
    iterations = 0
    for step in range(1, 0 if given else max_iterations + 1):
        iterations = step
        w = tw / scale[rec] ** 2
        B, y, _ = design(shift_now(), s_now)
        x, T, D, _, _ = solve(w, B, y)
        update(x)
        residual = y - B @ x - T[em_local]
        one = np.clip(1 - w / D[em_local], 0.0, 1.0)
        scale = _scales(residual, one, rec, n_receivers, robust=True)
        u = np.where(one > 1e-9, residual / np.sqrt(np.maximum(one, 1e-9)) / scale[rec], 0.0)
        tw = (NU + 1) / (NU + u ** 2)
        if previous is not None and np.max(np.abs(x[:n_knots] - previous[:n_knots]), initial=0.0) \
                < 0.05 * scale[synchronised].min():
            break
        previous = x
    keep = keep[rows] if given else np.abs(u) <= reject
    timings["reweighting"] = perf_counter() - tick
    tick = perf_counter()
    # the kept arrivals' least squares, each receiver's scale from its own; with the positions refined, Gauss-Newton
    # steps until no shift moves by a millimetre; the covariance in the pass after the last
    # beyond DENSE_LIMIT every block solve gives the shifts' covariance (the border's): without the sigmas (a
    # leave-one-out refit) the pass that converges is the last
    quick = geometry is not None and not sigmas and p > dense_limit
    last = False
    for passes in range(1, 21):
        w = keep / scale[rec] ** 2
        B, y, dd = design(shift_now(), s_now)
        if last:
            timings["least_squares"] = perf_counter() - tick
            tick = perf_counter()
        x, T, D, cov, shift_cov = solve(w, B, y, covariance=last and sigmas,
                                        shifts=(last or quick) and geometry is not None)
        moved = update(x)
        residual = y - B @ x - T[em_local]
        one = np.clip(1 - w / np.maximum(D[em_local], 1e-300), 0.0, 1.0)
        scale = _scales(np.where(keep, residual, np.nan), one, rec, n_receivers, robust=False)
        if last:
            timings["covariance"] = perf_counter() - tick
            break
        last = (passes >= 2 and moved < 1e-3) or passes == 19
        if quick and last:
            timings["least_squares"] = timings["covariance"] = perf_counter() - tick
            break
    u = np.where(one > 1e-9, residual / np.sqrt(np.maximum(one, 1e-9)) / scale[rec], 0.0)

    knots = np.full((n_receivers, n_bins + 1), np.nan)
    sigma = np.full((n_receivers, n_bins + 1), np.nan)
    drift_sigma = np.full((n_receivers, n_bins), np.nan)
    knots[reference] = sigma[reference] = drift_sigma[reference] = 0.0
    for count, j in enumerate(np.flatnonzero(free)):
        block = slice(base[j], base[j] + n_bins + 1)
        knots[j] = x[block]
        if cov is not None:
            diag = cov.variance[block]
            sigma[j] = np.sqrt(diag)
            following = cov.following[count * n_bins:(count + 1) * n_bins]
            drift_sigma[j] = np.sqrt(np.maximum(diag[1:] + diag[:-1] - 2 * following, 0.0)) / bin_width
    drift = np.diff(knots, axis=1) / bin_width
    counts = np.zeros((n_receivers, n_bins), np.int64)
    np.add.at(counts, (rec[keep], k[keep]), 1)
    n = len(time)
    full = np.full(n, np.nan)
    residual_all, standard_all, kept_all = full.copy(), full.copy(), np.zeros(n, bool)
    residual_all[rows], standard_all[rows], kept_all[rows] = residual, u, keep
    emission_time = np.full(int(emission.max()) + 1 if len(emission) else 0, np.nan)
    emission_time[emissions] = T + anchor
    s_hat = s_sigma = None
    if estimate:
        s_hat = float(x[n_knots])
        s_sigma = float(np.sqrt(cov.border[0, 0])) if cov is not None else None
    shift_out = shift_covariance = distance_all = None
    if geometry is not None:
        shift_out = shift.copy()
        shift_covariance = np.stack([shift_cov[2 * j:2 * j + 2, 2 * j:2 * j + 2] for j in range(n_sites)])
        distance_all = full.copy()
        distance_all[rows] = dd
    return ClockFit(edges, knots, sigma, drift, drift_sigma, counts, emission_time, residual_all, standard_all,
                    kept_all, scale, s_hat, s_sigma, iterations, shift_out, shift_covariance, distance_all,
                    shift_covariance_all=None if geometry is None else np.array(shift_cov))


def _prior(free: np.ndarray, base: np.ndarray, n_bins: int, p: int, sigma: float,
           steady: np.ndarray | None = None, ties: np.ndarray | None = None) -> sp.csr_matrix:
    """The knots' prior information: each free receiver's second differences of its knots, of sigma ``sigma``;
    a ``steady`` one's first differences too, of sigma :data:`STEADY` × ``sigma``; each tie's two clocks' first
    differences in its bin, the one less the other, of sigma ``sigma`` (both free)."""
    rows, cols, vals = [], [], []
    count = 0
    for j in np.flatnonzero(free):
        for k in range(1, n_bins if n_bins >= 2 else 1):
            rows += [count] * 3
            cols += [base[j] + k - 1, base[j] + k, base[j] + k + 1]
            vals += [1.0, -2.0, 1.0]
            count += 1
        if steady is not None and steady[j]:
            for k in range(n_bins):
                rows += [count] * 2
                cols += [base[j] + k, base[j] + k + 1]
                vals += [1.0 / STEADY, -1.0 / STEADY]
                count += 1
    for a, b, k in ([] if ties is None else np.asarray(ties, np.int64)):
        if free[a] and free[b] and 0 <= k < n_bins:
            rows += [count] * 4
            cols += [base[a] + k + 1, base[a] + k, base[b] + k + 1, base[b] + k]
            vals += [1.0, -1.0, -1.0, 1.0]
            count += 1
    if not count:
        return sp.csr_matrix((p, p))
    L = sp.csr_matrix((vals, (rows, cols)), shape=(count, p))
    return (L.T @ L) / sigma ** 2


def _scales(residual: np.ndarray, one: np.ndarray, rec: np.ndarray, n_receivers: int, robust: bool) -> np.ndarray:
    """Each receiver's noise scale [s]: its residuals over √(1 − leverage), by the median absolute deviation
    (``robust``) or the root mean square (NaN residuals left out); a receiver with fewer than 10 the median of
    the others'."""
    scale = np.full(n_receivers, np.nan)
    ok = (one > 0.05) & np.isfinite(residual)
    z = np.where(ok, residual / np.sqrt(np.where(ok, one, 1.0)), np.nan)
    for j in range(n_receivers):
        values = z[(rec == j) & ok]
        if len(values) >= 10:
            scale[j] = 1.4826 * np.median(np.abs(values)) if robust else np.sqrt(np.mean(values ** 2))
    fallback = np.nanmedian(scale) if np.isfinite(scale).any() else 1e-3
    return np.maximum(np.where(np.isfinite(scale), scale, fallback), MIN_SCALE)


__all__ = ["DENSE_LIMIT", "Geometry", "NU", "REJECT", "STEADY", "fit_clocks"]
