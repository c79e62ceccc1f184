"""Receivers' clocks aligned coarsely from the tags they hear together, where no sync tag ties them: each pair's lag
is where the differences between its detections of the same tag pile up.

A ping heard by receivers i and k is logged at ``t_i = t_e + ρ_i / c + o_i`` and ``t_k = t_e + ρ_k / c + o_k``
(``o`` the clocks' offsets): the difference ``t_k − t_i`` is the offsets' difference to within the time the sound
takes across the array (``|ρ_k − ρ_i| / c``). Taken between every detection of a tag at i and every one of the same
tag at k less than ``max_lag`` apart, the differences of one ping's arrivals pile up within that crossing time of the
offsets' difference; those of different pings spread over the tag's intervals (a random or pseudo-random interval's
nowhere; a fixed interval's at its multiples, which another tag's interval, or no peak at all, tells apart). Each
pair's lag is the median of the differences in the densest stretch one crossing time wide, taken where that stretch
holds at least :data:`MIN_PAIRS` and at least :data:`MIN_CONTRAST` times the densest stretch elsewhere; the
receivers' offsets then follow from the pairs' lags by least squares (each weighed by its count), one receiver's
clock the time base, in windows of the record (each its own offsets: a clock drifts). The lags are the offsets'
differences plus each pair's mean travel-time difference, so the offsets are coarse (to within a crossing time): a
start for the fine fit (:mod:`sblsim.orchestrator.telemetry.study_offsets`), which places every ping.

This is the arrival-time cross-correlation by which clocks are aligned without a common reference (the coincidence
histogram of two detection trains: Knapp & Carter, "The generalized correlation method for estimation of time delay",
IEEE Trans. ASSP 24(4), 1976, here on event times rather than waveforms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The least differences in a pair's densest stretch for its lag to be taken, and the least ratio of that stretch's
#: count to the densest stretch's elsewhere (else the pair is ambiguous: a fixed interval's multiples).
MIN_PAIRS, MIN_CONTRAST = 5, 2.0
#: The most differences taken of one tag in one window (a tag pinging every two seconds at twenty receivers gives
#: 10⁸ in three hours): beyond, those of every k-th detection alone.
MAX_DIFFERENCES = 2_000_000


@dataclass(frozen=True)
class CoarseLags:
    """Receivers' offsets from their pairs' lags (:func:`coarse_offsets`).

    Attributes
    ----------
    offsets : numpy.ndarray
        (R, W) [s] each receiver's clock offset from the time base's in each window (NaN: not tied to it).
    centres : numpy.ndarray
        (W,) [s] each window's middle (the time of its offsets).
    pairs : int
        The pairs of receivers whose lag was taken, over every window.
    largest_lag : float
        [s] the largest lag taken, in absolute value (0 where none).
    """

    offsets: np.ndarray
    centres: np.ndarray
    pairs: int
    largest_lag: float


def pair_lag(differences: np.ndarray, crossing: float) -> tuple[float, int]:
    """A pair's lag [s] from the differences (n,) [s] between its detections of the same tags (the module
    docstring) and the count in its densest stretch ``crossing`` [s] wide; NaN where too few or ambiguous."""
    d = np.sort(np.asarray(differences, float))
    if len(d) < MIN_PAIRS:
        return np.nan, 0
    ends = np.searchsorted(d, d + crossing, side="right")
    counts = ends - np.arange(len(d))
    best = int(np.argmax(counts))
    lo, hi = d[best], d[best] + crossing
    outside = (d < lo - crossing) | (d > hi + crossing)  # the densest stretch elsewhere, not overlapping this one
    other = int(counts[outside].max()) if outside.any() else 0
    if counts[best] < MIN_PAIRS or counts[best] < MIN_CONTRAST * other:
        return np.nan, 0
    return float(np.median(d[best:ends[best]])), int(counts[best])


def coarse_offsets(receiver: np.ndarray, tag: np.ndarray, time: np.ndarray, receivers: int, edges: np.ndarray,
                   max_lag: float, crossing: float, base: int) -> CoarseLags:
    """The receivers' clock offsets from the time base's, window by window (the module docstring).

    Parameters
    ----------
    receiver, tag : numpy.ndarray
        (n,) int, each detection's receiver (0 … ``receivers`` − 1) and tag (any int: sync tags left out).
    time : numpy.ndarray
        (n,) [s] each detection's time on its receiver's clock.
    receivers : int
    edges : numpy.ndarray
        (W + 1,) [s] the windows' edges, increasing.
    max_lag : float
        [s] the largest offset between two clocks looked for (differences beyond it are not taken).
    crossing : float
        [s] the time the sound takes across the array (a pair's stretch's width).
    base : int
        The time base's receiver (its offset 0; in a window whose pairs it is in none of, the receiver of the most
        pairs' detections there: a redeployed array's, no deployment spanning the season. An offset common to every
        clock moves no position, and a receiver's offsets outside its own deployment are never read).

    Returns
    -------
    CoarseLags
    """
    receiver, tag, time = np.asarray(receiver, np.int64), np.asarray(tag, np.int64), np.asarray(time, float)
    W = len(edges) - 1
    offsets = np.full((receivers, W), np.nan)
    taken, largest = 0, 0.0
    window = np.clip(np.searchsorted(edges, time, side="right") - 1, 0, W - 1)
    for w in range(W):
        here = window == w
        lags = []
        for t in np.unique(tag[here]):
            rows = np.flatnonzero(here & (tag == t))
            rows = rows[np.argsort(time[rows], kind="stable")]
            tt, rr = time[rows], receiver[rows]
            after = np.searchsorted(tt, tt + max_lag, side="right") - np.arange(len(tt)) - 1  # each one's later ones
            step = max(int(np.ceil(after.sum() / MAX_DIFFERENCES)), 1)  # (a fast tag's: every step-th one's)
            after[np.arange(len(tt)) % step != 0] = 0
            first = np.repeat(np.arange(len(tt)), after)
            second = first + 1 + np.arange(len(first)) - np.repeat(np.cumsum(after) - after, after)
            other = rr[first] != rr[second]
            lags.append((rr[first][other], rr[second][other], tt[second][other] - tt[first][other]))
        if not lags:
            continue
        i, k, d = (np.concatenate(p) for p in zip(*lags))
        low, high = np.minimum(i, k), np.maximum(i, k)
        d = np.where(i == low, d, -d)  # t_high − t_low
        key = low * receivers + high
        rows, weights, lag = [], [], []
        for pair in np.unique(key):
            found, count = pair_lag(d[key == pair], crossing)
            if count:
                rows.append((pair // receivers, pair % receivers))
                weights.append(count)
                lag.append(found)
        if not rows:
            continue
        taken += len(rows)
        largest = max(largest, float(np.abs(lag).max()))
        pairs, weights = np.array(rows), np.array(weights, float)
        here_base = base if (pairs == base).any() else int(np.argmax(np.bincount(  # (the base not deployed here)
            pairs.ravel(), weights=np.repeat(weights, 2), minlength=receivers)))
        offsets[:, w] = _solve(pairs, weights, np.array(lag), receivers, here_base)
    centres = 0.5 * (edges[:-1] + edges[1:])
    return CoarseLags(offsets, centres, taken, largest)


def _solve(pairs: np.ndarray, weights: np.ndarray, lag: np.ndarray, receivers: int, base: int) -> np.ndarray:
    """(R,) [s] the offsets whose differences ``o_k − o_i`` best fit the pairs' (P, 2) lags (P,), weighed, the base's
    0; NaN for a receiver no chain of pairs ties to the base."""
    tied = {base}
    grown = True
    while grown:  # the receivers a chain of pairs reaches from the base
        grown = False
        for i, k in pairs:
            if (i in tied) != (k in tied):
                tied |= {int(i), int(k)}
                grown = True
    out = np.full(receivers, np.nan)
    order = sorted(tied - {base})
    if not order:
        out[base] = 0.0
        return out
    column = {r: j for j, r in enumerate(order)}
    A = np.zeros((len(pairs), len(order)))
    for row, (i, k) in enumerate(pairs):
        if i in column:
            A[row, column[i]] = -1.0
        if k in column:
            A[row, column[k]] = 1.0
    used = np.array([(i in tied) and (k in tied) for i, k in pairs])
    sqrt_w = np.sqrt(weights[used])
    solution = np.linalg.lstsq(A[used] * sqrt_w[:, None], lag[used] * sqrt_w, rcond=None)[0]
    out[order] = solution
    out[base] = 0.0
    return out


__all__ = ["CoarseLags", "MAX_DIFFERENCES", "MIN_CONTRAST", "MIN_PAIRS", "coarse_offsets", "pair_lag"]
