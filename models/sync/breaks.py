"""Clock breaks: a receiver whose clock jumps (a reset, a download, a battery change) or goes back, found from its
sync-tag arrivals and split into **clock segments**, each with its own offsets and drifts.

The clock model of :mod:`sblsim.models.sync.clocks` is continuous: a jump of a receiver's clock cannot be fitted,
and the robust fit spreads it over the record (a jump of 0.5 s became a ramp of ±0.1 s, most of its arrivals
rejected). So, after the fit (:func:`fit_with_breaks`):

1. each arrival's **offset sample** (:func:`offset_samples`): its time less its travel time less the emission's
   time estimated from the *other* receivers' kept arrivals on their fitted clocks, less its receiver's fitted
   offset (a smooth curve). The receiver itself is left out of the emission's time, so that a broken clock cannot
   hide its own step there, and a break of the reference receiver shows at the reference (the others agree among
   themselves), not at every other;
2. each clock's samples in its own time order are a change-point problem (a mean shift in a series with a smooth
   trend: Bai & Perron 1998, *Econometrica* 66:47). A sample off both the line through the same sync tag's two
   previous samples and the line through its two next ones, on the same side, by more than :data:`SPIKE` robust
   sigmas is set aside (a late arrival; a step has one of the two lines through it); the rest are fitted by
   weighted least squares with the clock model (the knots over the bins, the drift prior) plus a constant per sync
   tag (a position error of the table is a constant per pair: metres on the boats array) and, for every gap
   between two successive samples, a **jump** from that gap on (:func:`scan`). The jump's estimate and the drop in
   chi-square it brings come for every gap at once from the residual-maker's quadratic forms by suffix sums (the
   knots' part bin by bin), in O(samples × tags² + bins³);
3. the best gap's statistic is the square root of its F ratio (the chi-square drop over the variance of the
   residuals of the model with that jump): a break where it exceeds :data:`THRESHOLD`, with at least
   :data:`MIN_SIDE` samples on each side. A jump below the sync's resolution (a few of its sigmas) is none and
   stays absorbed by the drifts;
4. the clock with the largest statistic is split at that gap (the arrivals after it a new clock row of the same
   receiver: :attr:`~sblsim.models.sync.clocks.ClockFit.site`) and the clocks refitted; the arrivals about the
   break are then put in the segment against whose refitted clock they fit (where the time went back, the two
   segments read the same times), the clocks refitted again if one moved, and all again until no break is left.
   The two segments' drifts in the break's bin are tied by the drift prior (the crystal runs on at its rate:
   ``ties`` in :func:`~sblsim.models.sync.clocks.fit_clocks`), and a later segment of the reference receiver keeps
   its drift (the time base stays its crystal's: ``steady``).

A receiver whose time went back in the file's order (a reset kept in its logging order: its **clock parts**,
``part`` of :func:`fit_with_breaks`) is split at each part before the search, the break's place certain and its
size fitted like any other's (no arrival set aside there: two parts may read the same times, each arrival's part
says which clock read it); its drifts are tied only where the last arrival before and the first after fall in one
bin. Such a part's arrivals are first aligned to the others' for the emissions' grouping by
:func:`part_shifts` (a reset of a day puts them a day from their emissions).

A segment's offsets hold for the times of its receiver's own clock it read
(:attr:`~sblsim.models.sync.clocks.ClockFit.span`, within its part); between the last arrival before a found break
and the first after it (widened by the jump where the time went back: the readings both segments make) a time is in
neither, and a detection there belongs to no synchronised clock (set aside). Units: seconds [s] throughout.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from time import perf_counter

import numpy as np
import scipy.linalg

from sblsim.models.sync.clocks import MIN_SCALE, ClockFit, Geometry, connected, fit_clocks

#: The statistic (√F of the best jump) above which a clock break is taken.
THRESHOLD = 12.0
#: The fewest samples (outliers not counted) on each side of a break.
MIN_SIDE = 10
#: A sample this many sigmas off the lines through its sync tag's two previous and two next samples is an outlier.
SPIKE = 6.0
#: The most breaks found in one fit.
MAX_BREAKS = 20
#: The bins [s] in which a later clock part's coarse shift is looked for (:func:`part_shifts`).
PART_BIN = 2.0


@dataclass
class ClockBreak:
    """A break found in a receiver's clock.

    Attributes
    ----------
    receiver : int
        The receiver (the clock rows' :attr:`~sblsim.models.sync.clocks.ClockFit.site`).
    before, after : int
        The clock rows of the segments before and after it.
    last, first : float
        [s] the receiver's own times of its last arrival before the break and its first after it.
    size, size_sigma : float
        [s] the jump (the clock after less the clock before at the same instant: > 0 it jumped ahead, < 0 its time
        went back) and its sigma.
    time, time_within : float
        [s] the break's instant on the reference clock (the middle of the two arrivals, each synchronised by its
        segment) and half their interval (the instant is within it).
    statistic : float
        √F of the jump when it was found (:data:`THRESHOLD`); NaN for a reset from the file's order.
    part : int or None
        The clock part the break starts where it is a reset from the file's order (``part`` of
        :func:`fit_with_breaks`: its place known, not searched for), else None.
    """

    receiver: int
    before: int
    after: int
    last: float
    first: float
    size: float
    size_sigma: float
    time: float
    time_within: float
    statistic: float
    part: int | None = None


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


def part_shifts(tag: np.ndarray, receiver: np.ndarray, part: np.ndarray, time: np.ndarray, search: float,
                width: float = PART_BIN, steps: dict[tuple[int, int], float] | None = None
                ) -> tuple[np.ndarray, dict[tuple[int, int], int]]:
    """Each later clock part's coarse shift against the other receivers' first parts, for the emissions' grouping:
    the mode (in bins of ``width``, then the median within a bin of it) of the differences between its arrivals and
    those of the same sync tag at the receiver (another, in its first part) hearing that tag most, within
    ±``search``; with random burst intervals only the true shift lines them up (a tag's fixed interval makes it
    ambiguous by multiples of the interval).

    Parameters
    ----------
    tag, receiver, part : numpy.ndarray
        (n,) int, each arrival's sync tag, receiver and clock part (1 first).
    time : numpy.ndarray
        (n,) [s] on its receiver's clock.
    search : float
        [s] the largest shift looked for.
    width : float
        [s] the bins' width: more than the array's largest travel-time difference.
    steps : dict, optional
        Per (receiver, part) the step [s] its time went back by in the file's order (the last row before the reset
        to the first after): the shift is that step less the time the receiver heard nothing, so it is looked for
        only at or below the step (within ``search``), and of the bins that hold at least half the most
        differences, the one nearest the step is taken (a sync tag's steady interval makes the differences pile up
        again at multiples of it, farther from the step).

    Returns
    -------
    shift : numpy.ndarray
        (n,) [s] each arrival's part's shift (its time less it is near the others'); 0 in a first part or where
        none was found.
    matched : dict
        Per (receiver, part) the arrivals that matched at the shift (0: none found).
    """
    shift = np.zeros(len(time))
    matched: dict[tuple[int, int], int] = {}
    first = part == 1
    for j, p in sorted({(int(a), int(b)) for a, b in zip(receiver[~first], part[~first])}):
        mine = (receiver == j) & (part == p)
        diffs = []
        for i in np.unique(tag[mine]):
            others = first & (tag == i) & (receiver != j)
            if not others.any():
                continue
            best = np.bincount(receiver[others]).argmax()
            ref = np.sort(time[others & (receiver == best)])
            t = time[mine & (tag == i)]
            lo, hi = np.searchsorted(ref, t - search), np.searchsorted(ref, t + search)
            for k in range(len(t)):
                diffs.append(t[k] - ref[lo[k]:hi[k]])
        d = np.concatenate(diffs) if diffs else np.zeros(0)
        step = None if steps is None else steps.get((j, p))
        if step is not None:  # the shift is the step less the silent time: at or below the step
            d = d[d <= step + width]
        if len(d) < 3:
            matched[(j, p)] = 0
            continue
        cells = np.floor(d / width).astype(np.int64)
        values, counts = np.unique(cells, return_counts=True)
        top = int(np.argmax(counts))
        if step is not None:  # of the bins near the most, the one nearest the step (the least silent time)
            top = int(np.flatnonzero(counts >= 0.5 * counts[top])[-1])
        near = np.abs(cells - values[top]) <= 1
        around = np.bincount(cells[near] - values[top] + 1, minlength=3)
        if counts[top] < 3:
            matched[(j, p)] = 0
            continue
        centre = (values[top] + 0.5) * width
        centre += 0.5 * width * (around[2] - around[0]) / max(around.sum(), 1)
        inside = np.abs(d - centre) <= width
        shift[mine] = float(np.median(d[inside]))
        matched[(j, p)] = int(inside.sum())
    return shift, matched


def fit_with_breaks(receiver: np.ndarray, emission: np.ndarray, time: np.ndarray, distance: np.ndarray,
                    slowness: np.ndarray | None, used: np.ndarray, synchronised: np.ndarray, reference: int,
                    bin_width: float, tag: np.ndarray, drift_change: float = 1e-6, geometry: Geometry | None = None,
                    threshold: float = THRESHOLD, max_breaks: int = MAX_BREAKS, timings: dict | None = None,
                    part: np.ndarray | None = None) -> ClockFit:
    """The clocks fitted (:func:`~sblsim.models.sync.clocks.fit_clocks`), their breaks found and each broken clock
    split into segments (the module docstring).

    Parameters
    ----------
    receiver, emission, time, distance, slowness, used, synchronised, reference, bin_width, drift_change, geometry
        As :func:`~sblsim.models.sync.clocks.fit_clocks` takes them (``receiver``, ``synchronised`` and
        ``reference`` the receivers').
    tag : numpy.ndarray
        (n,) int, each arrival's sync tag.
    threshold : float
        The statistic above which a break is taken (:data:`THRESHOLD`); ``inf``: none looked for.
    max_breaks : int
        The most breaks taken.
    timings : dict, optional
        As :func:`~sblsim.models.sync.clocks.fit_clocks` fills it (its last fit's), with ``breaks`` [s] the search.
    part : numpy.ndarray, optional
        (n,) int, each arrival's clock part (1 first; a later one after its receiver's time went back in the
        file's order): each later part a clock segment of its own from the start, its break's place known (the
        module docstring). None: one part.

    Returns
    -------
    ClockFit
        Where no break was found the fit of :func:`~sblsim.models.sync.clocks.fit_clocks` itself; else one row per
        clock segment, with :attr:`~sblsim.models.sync.clocks.ClockFit.site`, ``span``, ``clock`` and ``breaks``.

    Raises
    ------
    ModelError
        As :func:`~sblsim.models.sync.clocks.fit_clocks`.
    """
    timings = {} if timings is None else timings
    n_receivers = len(synchronised)
    rows = np.asarray(receiver, np.int64).copy()
    site = list(range(n_receivers))
    span = [[-np.inf, np.inf] for _ in range(n_receivers)]
    linked = np.asarray(synchronised, bool).copy()
    arrival_part = np.ones(len(rows), np.int64) if part is None else np.asarray(part, np.int64)
    row_part = [1] * n_receivers
    found: list[dict] = []
    for j, p in sorted({(int(a), int(b)) for a, b in zip(receiver, arrival_part) if b > 1}):
        # a reset from the file's order: the part its own clock segment, the break between it and the part before
        mine = (receiver == j) & (arrival_part == p)
        earlier = (receiver == j) & (arrival_part < p)
        new = len(site)
        before = max((r for r in range(len(site)) if site[r] == j and row_part[r] < p), key=lambda r: row_part[r])
        site.append(j)
        span.append([-np.inf, np.inf])
        row_part.append(p)
        rows[mine] = new
        last = time[earlier & (arrival_part == row_part[before])]
        found.append({"receiver": j, "before": before, "after": new, "statistic": np.nan, "size": np.nan,
                      "last": float(last.max()) if len(last) else np.nan, "first": float(time[mine].min()),
                      "part": p})

    def refit():
        nonlocal linked
        if len(site) > n_receivers:  # a segment no other clock is tied to is not synchronised
            heard = connected(rows[used & (rows >= 0)], emission[used & (rows >= 0)], len(site), reference)
            linked = heard & np.asarray(synchronised, bool)[np.array(site)]
        geo = None if geometry is None else replace(geometry, site=np.array(site))
        steady = None if len(site) == n_receivers else np.array(site) == reference
        return fit_clocks(np.maximum(rows, 0), emission, time, distance, slowness, used & (rows >= 0), linked,
                          reference, bin_width, drift_change=drift_change, geometry=geo, timings=timings,
                          steady=steady, ties=tied(fit_edges))

    def tied(edges: np.ndarray | None) -> np.ndarray | None:
        """Each break's two segments' drifts tied in the bin of its last arrival before it (a reset's only where
        its first arrival after it is in that bin too: its two parts read different times)."""
        if not found or edges is None:
            return None
        width = edges[1] - edges[0]

        def bin_of(t: float) -> int:
            return int(np.clip((t - edges[0]) // width, 0, len(edges) - 2)) if np.isfinite(t) else -1

        out = [(e["before"], e["after"], bin_of(e["last"])) for e in found
               if "part" not in e or (bin_of(e["last"]) == bin_of(e["first"]) >= 0)]
        return np.array(out, np.int64) if out else None

    fit_edges = None
    fit = refit()
    fit_edges = fit.edges  # the same for every refit: the arrivals' span, whatever their clocks
    searched = 0.0
    while np.isfinite(threshold) and len(found) < max_breaks:
        tick = perf_counter()
        jump = _best(fit, rows, emission, time, distance, slowness, used & (rows >= 0), tag, drift_change * bin_width,
                     threshold)
        searched += perf_counter() - tick
        if jump is None:
            break
        new = len(site)
        site.append(site[jump.row])
        span.append([np.nan, span[jump.row][1]])
        row_part.append(row_part[jump.row])
        rows[jump.after] = new
        for other in found:  # an earlier break after this one now follows the new segment
            if other["before"] == jump.row and other["last"] >= jump.first:
                other["before"] = new
        entry = {"receiver": site[jump.row], "before": jump.row, "after": new, "statistic": jump.statistic,
                 "size": jump.size}
        found.append(entry)
        classified = np.zeros(len(rows), bool)
        classified[jump.after] = classified[jump.before] = True
        same = arrival_part == row_part[jump.row]  # its part's arrivals alone (another part may read these times)
        _bounds(entry, rows, receiver, time, classified, jump.size, span, same)
        fit = refit()
        # the arrivals about the break put where the refitted clocks say they belong (where the time went back, the
        # ones the first cut misplaced), and the clocks refitted if one moved
        size = _measured(fit, entry).size
        size = jump.size if not np.isfinite(size) else size
        wide = 2 * abs(size) + 60.0
        settled, moved = _settle(fit, rows, receiver, used & same, entry, emission, time, distance, slowness,
                                 min(entry["last"], entry["first"]) - wide, max(entry["last"], entry["first"]) + wide)
        if moved:
            _bounds(entry, rows, receiver, time, classified | settled, size, span, same)
            fit = refit()
    timings["breaks"] = searched
    if not found:
        return fit
    return replace(fit, site=np.array(site), span=np.array(span), clock=rows,
                   breaks=[_measured(fit, b) for b in found], part=None if part is None else np.array(row_part))


def _bounds(entry: dict, rows: np.ndarray, receiver: np.ndarray, time: np.ndarray, classified: np.ndarray,
            size: float, span: list, same: np.ndarray) -> None:
    """A break's bracket (``entry``'s ``last`` and ``first``: the last arrival ``classified`` before it, the first
    after it), its two segments' spans (the stretch between them widened by the jump where the time went back:
    the readings both may hold) and the receiver's other arrivals there by their times (-1 in the stretch), of its
    clock part (``same``) alone."""
    before, after = entry["before"], entry["after"]
    mine = (receiver == entry["receiver"]) & np.isin(rows, (before, after, -1)) & same
    mine &= (time >= span[before][0]) & (time <= span[after][1])
    fixed = mine & classified
    entry["last"] = float(time[fixed & (rows == before)].max())
    entry["first"] = float(time[fixed & (rows == after)].min())
    low, high = entry["last"] + min(0.0, size), entry["first"] + max(0.0, -size)
    rest = mine & ~classified
    rows[rest & (time <= low)] = before
    rows[rest & (time >= high)] = after
    rows[rest & (time > low) & (time < high)] = -1
    span[before][1], span[after][0] = low, high


def _settle(fit: ClockFit, rows: np.ndarray, receiver: np.ndarray, used: np.ndarray, entry: dict,
            emission: np.ndarray,
            time: np.ndarray, distance: np.ndarray, slowness: np.ndarray | None, low: float, high: float
            ) -> tuple[np.ndarray, bool]:
    """The break's receiver's ``used`` arrivals with times in [``low``, ``high``] put in the segment (``before``
    or ``after``) against whose refitted clock their emission's time fits them best; the mask of those it could
    compare (the emission fitted) and whether one moved."""
    before, after = entry["before"], entry["after"]
    k = np.flatnonzero(used & (receiver == entry["receiver"]) & np.isin(rows, (before, after, -1)) & (time >= low)
                       & (time <= high))
    out = np.zeros(len(rows), bool)
    if not len(k) or not (np.isfinite(fit.knots[before, 0]) and np.isfinite(fit.knots[after, 0])):
        return out, False
    emitted = fit.emission_time[emission[k]]
    d = distance[k] if fit.distance is None else np.where(np.isfinite(fit.distance[k]), fit.distance[k], distance[k])
    travel = d * (fit.slowness if slowness is None else slowness[k])
    miss_before = np.abs(time[k] - fit.offset(np.full(len(k), before), time[k]) - travel - emitted)
    miss_after = np.abs(time[k] - fit.offset(np.full(len(k), after), time[k]) - travel - emitted)
    ok = np.isfinite(miss_before) & np.isfinite(miss_after)
    choice = np.where(miss_after < miss_before, after, before)
    moved = ok & (choice != rows[k])
    rows[k[ok]] = choice[ok]
    out[k[ok]] = True
    return out, bool(moved.any())


def _reading(fit: ClockFit, row: int, instant: float) -> float:
    """[s] clock ``row``'s reading at the reference clock's ``instant`` (its offset's fixed point)."""
    r = instant
    for _ in range(4):
        r = instant + float(fit.offset(np.array([row]), np.array([r]))[0])
    return r


def _sigma(fit: ClockFit, row: int, time: float) -> float:
    """[s] clock ``row``'s offset sigma at its ``time`` (its knots' interpolated)."""
    width = fit.edges[1] - fit.edges[0]
    k = int(np.clip(np.floor((time - fit.edges[0]) / width), 0, len(fit.edges) - 2))
    f = (time - fit.edges[k]) / width
    return float(fit.knot_sigma[row, k] * (1 - f) + fit.knot_sigma[row, k + 1] * f)


def _measured(fit: ClockFit, found: dict) -> ClockBreak:
    """A break's size and instant from the refitted clocks of its two segments (the scan's where one of them is not
    synchronised)."""
    before, after = found["before"], found["after"]
    if not (np.isfinite(fit.knots[before, 0]) and np.isfinite(fit.knots[after, 0]) and np.isfinite(found["last"])):
        return ClockBreak(found["receiver"], before, after, found["last"], found["first"], found["size"], np.nan,
                          np.nan, np.nan, found["statistic"], found.get("part"))
    t0 = found["last"] - float(fit.offset(np.array([before]), np.array([found["last"]]))[0])
    t1 = found["first"] - float(fit.offset(np.array([after]), np.array([found["first"]]))[0])
    instant = 0.5 * (t0 + t1)
    r0, r1 = _reading(fit, before, instant), _reading(fit, after, instant)
    sigma = np.hypot(_sigma(fit, before, r0), _sigma(fit, after, r1))
    return ClockBreak(found["receiver"], before, after, found["last"], found["first"], r1 - r0, float(sigma),
                      instant, 0.5 * abs(t1 - t0), found["statistic"], found.get("part"))


__all__ = ["ClockBreak", "MAX_BREAKS", "MIN_SIDE", "PART_BIN", "SPIKE", "THRESHOLD", "fit_with_breaks",
           "offset_samples", "part_shifts", "scan"]
