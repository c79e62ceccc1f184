"""The search for a clock break: each arrival's offset sample against the other receivers', and one clock's best
jump in its samples (the steps 1 to 3 of :mod:`sblsim.models.sync.breaks`).

A clock's samples in its own time order are a change-point problem: a mean shift in a series with a smooth trend
(Bai & Perron 1998, *Estimating and testing linear models with multiple structural changes*, Econometrica 66:47).
Isolated late arrivals are set aside first; the rest are fitted by weighted least squares with the clock model, a
constant per sync tag and a jump from each gap on, every gap's jump and chi-square drop at once
(:func:`scan`). Units: seconds [s] throughout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clocks import MIN_SCALE

#: The fewest samples (outliers not counted) on each side of a break.
MIN_SIDE = 10
#: A sample this many sigmas off the lines through its sync tag's two previous and two next samples is an outlier.
SPIKE = 6.0


@dataclass
class _Jump:
    """The best jump of one clock: the arrivals (indices) after it and before it (those compared), the bracket, its
    size and statistic."""

    row: int
    after: np.ndarray
    before: np.ndarray
    last: float
    first: float
    size: float
    statistic: float


def offset_samples(fit: ClockFit, rows: np.ndarray, emission: np.ndarray, time: np.ndarray, distance: np.ndarray,
                   slowness: np.ndarray | None, used: np.ndarray) -> np.ndarray:
    """(n,) [s] each arrival's offset sample less its clock's fitted offset (the module docstring's step 1): its
    emission time (its time less its clock's offset and its travel time) less the emission's time from the *other*
    clocks' kept arrivals (weighted by their clocks' noise scales); NaN where no other kept arrival hears the
    emission, or the arrival is not used or its clock not synchronised.

    Parameters
    ----------
    fit : ClockFit
        The clocks fitted to ``rows`` (:func:`~sblsim.models.sync.clocks.fit_clocks`).
    rows, emission : numpy.ndarray
        (n,) int, each arrival's clock row and emission.
    time, distance : numpy.ndarray
        (n,) [s] the arrival on its clock and [m] its distance (the fit's own where it refined the positions).
    slowness : numpy.ndarray or None
        (n,) [s/m]; None: the fit's estimate.
    used : numpy.ndarray
        (n,) bool, the arrivals fitted.
    """
    n = len(time)
    out = np.full(n, np.nan)
    ok = used & (rows >= 0)
    ok[ok] = np.isfinite(fit.knots[rows[ok], 0])
    if not ok.any():
        return out
    idx = np.flatnonzero(ok)
    d = fit.distance[idx] if fit.distance is not None else distance[idx]
    s = np.full(len(idx), fit.slowness) if slowness is None else slowness[idx]
    x = time[idx] - fit.offset(rows[idx], time[idx]) - d * s
    em, local = np.unique(emission[idx], return_inverse=True)
    anchor = np.full(len(em), np.inf)
    np.minimum.at(anchor, local, x)
    x = x - anchor[local]  # small numbers: the sums below keep their digits
    w = np.where(fit.kept[idx], 1.0 / fit.scale[rows[idx]] ** 2, 0.0)
    sw = np.bincount(local, w, len(em))
    swx = np.bincount(local, w * x, len(em))
    others = sw[local] - w
    good = others > 1e-12 * np.maximum(sw[local], 1e-300)
    out[idx[good]] = x[good] - (swx[local][good] - w[good] * x[good]) / others[good]
    return out


def _noise(z: np.ndarray) -> float:
    """A series' noise sigma [s] from its second differences (blind to a slope, robust to a step and to spikes):
    1.4826 × their median absolute value / √6."""
    if len(z) < 4:
        return np.nan
    return 1.4826 * float(np.median(np.abs(np.diff(z, 2)))) / np.sqrt(6.0)


def _clean(t: np.ndarray, z: np.ndarray, pair: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's weight 1/σ² [1/s²] (its sync tag's noise, :func:`_noise`) and whether it is an isolated
    outlier: more than :data:`SPIKE` sigmas (of the extrapolation) off both the line through its tag's two previous
    samples and the line through its two next, on the same side (a step has one side's line through it, a slope
    both; a late arrival sticks out of both); a tag heard fewer than four times is left out (weight 0)."""
    w = np.zeros(len(z))
    spike = np.zeros(len(z), bool)
    for p in np.unique(pair):
        k = np.flatnonzero(pair == p)
        if len(k) < 4:
            spike[k] = True
            continue
        k = k[np.argsort(t[k], kind="stable")]
        v = z[k]
        sigma = max(_noise(v), MIN_SCALE)
        back = np.full(len(v), np.nan)
        ahead = np.full(len(v), np.nan)
        back[2:] = v[2:] - (2 * v[1:-1] - v[:-2])
        ahead[:-2] = v[:-2] - (2 * v[1:-1] - v[2:])
        limit = SPIKE * sigma * np.sqrt(6.0)
        spike[k] = (np.sign(back) == np.sign(ahead)) & (np.minimum(np.abs(back), np.abs(ahead)) > limit)
        w[k] = 1.0 / sigma ** 2
    return w, spike


def scan(t: np.ndarray, z: np.ndarray, pair: np.ndarray, w: np.ndarray, edges: np.ndarray, prior_sigma: float,
         min_side: int = MIN_SIDE) -> dict | None:
    """One clock's best jump (the module docstring's step 2): the weighted least squares of its samples with the
    clock model, a constant per pair and a jump from each gap on, for every gap at once.

    Parameters
    ----------
    t, z : numpy.ndarray
        (n,) [s] the samples' times on the clock, sorted, and their values (:func:`offset_samples`).
    pair : numpy.ndarray
        (n,) int, each sample's sync tag (a constant each).
    w : numpy.ndarray
        (n,) [1/s²] the weights (1/σ²), all positive.
    edges : numpy.ndarray
        (K+1,) [s] the bins' edges (equal widths).
    prior_sigma : float
        [s] the sigma of the knots' second differences (the drift prior of
        :func:`~sblsim.models.sync.clocks.fit_clocks`).
    min_side : int
        The fewest samples on each side of a jump.

    Returns
    -------
    dict or None
        ``gap`` (the first sample after the jump), ``size`` [s], ``size_sigma`` [s], ``statistic`` (√F), ``level``
        (n,) [s] the model with the jump at each sample before the jump is added (its pre-jump level), or None
        where there are too few samples.
    """
    n = len(t)
    width = edges[1] - edges[0]
    b = np.clip(np.floor((t - edges[0]) / width).astype(np.int64), 0, len(edges) - 2)
    f = (t - edges[b]) / width
    b = b - b.min()
    m = int(b.max()) + 2  # the knots of the bins the samples span
    tags, pl = np.unique(pair, return_inverse=True)
    main = int(np.argmax(np.bincount(pl, w)))
    ci = np.where(pl < main, pl, pl - 1)
    ci[pl == main] = -1
    n_c = len(tags) - 1
    q = m + n_c
    if n < 2 * min_side or n - q - 1 < min_side:
        return None
    wa, wb = w * (1 - f), w * f
    N = np.zeros((q, q))
    np.add.at(N, (b, b), wa * (1 - f))
    np.add.at(N, (b, b + 1), wa * f)
    np.add.at(N, (b + 1, b), wa * f)
    np.add.at(N, (b + 1, b + 1), wb * f)
    has = ci >= 0
    c = m + ci[has]
    np.add.at(N, (b[has], c), wa[has])
    np.add.at(N, (c, b[has]), wa[has])
    np.add.at(N, (b[has] + 1, c), wb[has])
    np.add.at(N, (c, b[has] + 1), wb[has])
    np.add.at(N, (c, c), w[has])
    if m >= 3:
        L = np.zeros((m - 2, m))
        k = np.arange(m - 2)
        L[k, k], L[k, k + 1], L[k, k + 2] = 1.0, -2.0, 1.0
        N[:m, :m] += L.T @ L / prior_sigma ** 2
    N += np.eye(q) * 1e-12 * np.max(np.diag(N))

    def design_t(v: np.ndarray) -> np.ndarray:
        """Zᵀ v."""
        out = np.zeros(q)
        out[:m] = np.bincount(b, v * (1 - f), m) + np.bincount(b + 1, v * f, m)
        out[m:] = np.bincount(ci[has], v[has], n_c) if n_c else 0.0
        return out

    def design(x: np.ndarray) -> np.ndarray:
        """Z x."""
        return x[b] * (1 - f) + x[b + 1] * f + np.where(has, x[m + np.maximum(ci, 0)] if n_c else 0.0, 0.0)

    try:
        factor = scipy.linalg.cho_factor(N, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    G = scipy.linalg.cho_solve(factor, np.eye(q), check_finite=False)
    x0 = G @ design_t(w * z)
    e = z - design(x0)
    # the objective at the fit without a jump: the weighted residuals' squares and the prior's
    chi0 = float(np.sum(w * e ** 2)) + (float(np.sum((L @ x0[:m]) ** 2)) / prior_sigma ** 2 if m >= 3 else 0.0)

    def suffix(a: np.ndarray) -> np.ndarray:
        """(n + 1,) the sums from each index to the end (0 at n)."""
        return np.r_[np.cumsum(a[::-1])[::-1], 0.0]

    num = suffix(w * e)[:n]  # hᵀ M z = hᵀ W e: the residual-maker M = W − W Z N⁻¹ Zᵀ W takes z to W e
    total = suffix(w)[:n]
    # the knots' part of Zᵀ W h_g: the bins after g's (R) and g's own bin from g on (alpha, beta)
    # (each bin's row of Zᵀ W, two entries: its own knot's and the next's; R[b] the sum of the rows after bin b)
    own, later = np.bincount(b, wa, m - 1), np.bincount(b, wb, m - 1)
    R = np.zeros((m - 1, m))
    R[np.arange(m - 1), np.arange(m - 1)] = own
    R[np.arange(m - 1), np.arange(1, m)] = later
    R[:-1] = np.cumsum(R[::-1], axis=0)[::-1][1:]
    R[-1] = 0.0
    nxt = np.searchsorted(b, b, side="right")
    sa, sb = suffix(wa), suffix(wb)
    alpha, beta = sa[:n] - sa[nxt], sb[:n] - sb[nxt]
    GAA, GAC, GCC = G[:m, :m], G[:m, m:], G[m:, m:]

    def after_bins(M: np.ndarray) -> np.ndarray:
        """R @ M by the rows' suffix sums: O(bins × columns), not a product of dense matrices."""
        rows = own[:, None] * M[:-1] + later[:, None] * M[1:]
        out = np.zeros_like(rows)
        out[:-1] = np.cumsum(rows[::-1], axis=0)[::-1][1:]
        return out

    V = after_bins(GAA)
    s_bin = np.einsum("ij,ij->i", V, R)
    quad = (s_bin[b] + 2 * (alpha * V[b, b] + beta * V[b, b + 1]) + alpha ** 2 * GAA[b, b]
            + 2 * alpha * beta * GAA[b, b + 1] + beta ** 2 * GAA[b + 1, b + 1])
    if n_c:
        onehot = np.zeros((n, n_c))
        onehot[np.flatnonzero(has), ci[has]] = w[has]
        aC = np.cumsum(onehot[::-1], axis=0)[::-1]
        Y = after_bins(GAC)
        cross = Y[b] + alpha[:, None] * GAC[b] + beta[:, None] * GAC[b + 1]
        quad += 2 * np.einsum("gi,gi->g", cross, aC) + np.einsum("gi,ij,gj->g", aC, GCC, aC)
    den = total - quad
    valid = np.zeros(n, bool)
    valid[min_side:n - min_side + 1] = True
    valid[1:] &= t[1:] > t[:-1]
    valid[0] = False
    valid &= den > 1e-9 * total
    if not valid.any():
        return None
    chi = np.where(valid, num ** 2 / np.where(valid, den, 1.0), -np.inf)
    g = int(np.argmax(chi))
    dof = n - q - 1
    rest = max(chi0 - chi[g], 1e-300) / dof
    size = float(num[g] / den[g])
    # the model with the jump: x = x0 − G a_g size
    a = np.zeros(q)
    if g < n:
        bg = b[g]
        a[:m] = R[bg]
        a[bg] += alpha[g]
        a[bg + 1] += beta[g]
        if n_c:
            a[m:] = aC[g]
    level = design(x0 - G @ a * size)
    return {"gap": g, "size": size, "size_sigma": float(np.sqrt(rest / den[g])),
            "statistic": float(np.sqrt(chi[g] / rest)), "level": level}


def _best(fit: ClockFit, rows: np.ndarray, emission: np.ndarray, time: np.ndarray, distance: np.ndarray,
          slowness: np.ndarray | None, used: np.ndarray, tag: np.ndarray, prior_sigma: float,
          threshold: float) -> _Jump | None:
    """The clock with the largest break statistic above ``threshold`` and its jump, or None."""
    z_all = offset_samples(fit, rows, emission, time, distance, slowness, used)
    best = None
    for row in np.flatnonzero(np.isfinite(fit.knots[:, 0])):
        idx = np.flatnonzero((rows == row) & np.isfinite(z_all))
        if len(idx) < 2 * MIN_SIDE:
            continue
        idx = idx[np.lexsort((emission[idx], time[idx]))]
        t, z, pair = time[idx], z_all[idx], tag[idx]
        w, spike = _clean(t, z, pair)
        keep = ~spike & (w > 0)
        if keep.sum() < 2 * MIN_SIDE:
            continue
        found = scan(t[keep], z[keep], pair[keep], w[keep], fit.edges, prior_sigma)
        if found is None or found["statistic"] < threshold or (best is not None and
                                                                found["statistic"] <= best.statistic):
            continue
        size, kk = found["size"], np.flatnonzero(keep)
        g0, g1 = kk[found["gap"] - 1], kk[found["gap"]]  # the kept samples either side of the jump
        after = np.arange(len(idx)) >= g1
        # the samples the two segments both may hold go where they fit: the outliers between the two kept ones,
        # and where the time went back every sample the jump's width around them
        level = np.interp(t, t[keep], found["level"])
        near = np.zeros(len(idx), bool)
        near[g0 + 1:g1] = True
        if size < 0:
            near |= (t >= t[g1] - 2 * abs(size)) & (t <= t[g0] + 2 * abs(size))
        after[near] = np.abs(z[near] - level[near] - size) < np.abs(z[near] - level[near])
        if size >= 0 and t[~after].max() > t[after].min():  # not one cut in time: the outliers by their times
            after = t > 0.5 * (t[g0] + t[g1])
        if after.all() or not after.any():
            continue
        best = _Jump(int(row), idx[after], idx[~after], float(t[~after].max()), float(t[after].min()), size,
                     found["statistic"])
    return best

__all__ = ["MIN_SIDE", "SPIKE", "offset_samples", "scan"]
