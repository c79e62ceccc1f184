"""The knots of a receiver's clock fitted from a study's moving tags' pings (no sync tag): every :data:`WINDOW`
between the study's first and last detection (:func:`knot_times`), those between which the pings fitted are too
few merged (:func:`merged`), each receiver's arrivals touching each knot (:func:`knot_counts`), and how far the
clocks depart from a line over a stretch's length where the pings tie them (:func:`departure`); the clock's offset
is linear between its knots (a study's clocks taken as logged and fitted from its pings). Knots as a spline's: de
Boor, "A Practical Guide to Splines", Springer, 1978, ch. III (piecewise linear interpolation, its error
``h² max|f''| / 8`` at a knot spacing ``h``: a wander of ±10 ms over a day, 0.8 ms at 3 h).
"""

from __future__ import annotations

import numpy as np

from sblsim.models.tracking.refinement_terms import Unknowns

#: [s] the longest span between a clock's knots (a coarse alignment's windows too: a clock drifting by 20 ppm moves
#: by 0.2 s in one).
WINDOW = 3 * 3600.0
#: The fewest pings fitted in a stretch between two knots of a clock (:func:`merged`).
MIN_BIN_PINGS = 30
#: The fewest pings fitted from each window of the grid that holds as many, whatever a season's cap
#: (:func:`spread_pings`): twice :data:`MIN_BIN_PINGS`, so that no window is merged for want of pings the cap left
#: out.
WINDOW_PINGS = 2 * MIN_BIN_PINGS


def knot_times(span: tuple[float, float]) -> np.ndarray:
    """(K + 1,) [s] the knots of clocks fitted as logged (no coarse alignment): the study's first and last detection
    ``span`` and every :data:`WINDOW` between, evenly (a coarse alignment's windows' edges too; a span under a second
    taken as a second). A clock's rate follows its crystal's temperature, which a drift corrected at offload as a
    line leaves: at 1 ppm a day's swing is ±14 ms, 20 m of range."""
    end = max(span[1], span[0] + 1.0)
    return np.linspace(span[0], end, max(int(np.ceil((end - span[0]) / WINDOW)), 1) + 1)


def merged(grid: np.ndarray, times: np.ndarray, least: int | None = None) -> np.ndarray:
    """(K + 1,) [s] the knots of ``grid`` (G + 1,) [s] a clock's offset is fitted at, from the pings fitted (their
    ``times`` (P,) [s], each beyond the grid's ends at its end): a knot between two stretches of fewer than
    ``least`` pings each (None: :data:`MIN_BIN_PINGS`) dropped (a run of them one stretch, its knots those its
    neighbours tie), and a first or last stretch of fewer joined to the next (its outer knot tied by nothing else);
    the grid's ends always kept (fewer pings in all: its ends alone, an offset and a drift). A clock's offsets at
    two knots that a few pings alone tie trade with those pings' places: the pings of an animal passing once in a
    day away from the array took offsets 0.2 s off."""
    least = MIN_BIN_PINGS if least is None else least
    counts = stretch_counts(grid, times)
    keep = np.ones(len(grid), bool)
    keep[1:-1] = (counts[:-1] >= least) | (counts[1:] >= least)
    for end in (0, -1):  # (the first stretch, then the last)
        at = np.flatnonzero(keep)
        if len(at) > 2 and np.add.reduceat(counts, at[:-1])[end] < least:
            keep[at[1] if end == 0 else at[-2]] = False
    return grid[keep]


def spread_pings(times: np.ndarray, grid: np.ndarray, most: int) -> np.ndarray:
    """(n,) int the pings fitted of a season's (their ``times`` (P,) [s]; every one, in its order, where they are
    ``most`` or fewer): the same number ``q`` from each window of ``grid`` (G + 1,) [s] that holds as many, each
    window's own pings spread evenly in time, and every ping of a window that holds fewer (a ping beyond the grid's
    ends in the end's window), ``q`` the largest that keeps them within ``most`` (the budget the sparse windows leave
    to the others) but never below :data:`WINDOW_PINGS`; in time order. A season's pings taken evenly in time take them
    where the animals are: at 20,000 of a 13 weeks' study, 27 a window on average and fewer where the animals are
    away, so that :func:`merged` dropped knots the pings left out would have tied."""
    if len(times) <= most:
        return np.arange(len(times))
    order = np.argsort(times, kind="stable")
    window = np.clip(np.searchsorted(grid, times[order], side="right") - 1, 0, len(grid) - 2)
    counts = np.bincount(window, minlength=len(grid) - 1)
    low, high = 0, int(counts.max())  # (the largest q within ``most``, by bisection: the fills grow with q)
    while low < high:
        mid = (low + high + 1) // 2
        low, high = (mid, high) if np.minimum(counts, mid).sum() <= most else (low, mid - 1)
    quota = max(low, WINDOW_PINGS)
    starts = np.r_[0, np.cumsum(counts)]
    return np.concatenate([order[a + (np.linspace(0, b - a - 1, quota).astype(int) if b - a > quota else
                                      np.arange(b - a))] for a, b in zip(starts[:-1], starts[1:])])


def stretch_counts(edges: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(K,) the pings (their ``times`` (P,) [s]) in each stretch between the knots ``edges`` (K + 1,) [s], one beyond
    the ends in the end's stretch (its offset the end's), the last stretch closed at its end."""
    return np.histogram(np.clip(times, edges[0], edges[-1]), edges)[0]


def knot_counts(heard: np.ndarray, times: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(R, K + 1) each receiver's arrivals touching each knot at ``edges`` (K + 1,) [s] (a ping in ``[edges[j],
    edges[j + 1])`` the knots j and j + 1, its offset linear between them; one beyond the ends the end's; ``heard``
    (P, R), ``times`` (P,) [s]): a deployment's knots outside its own time are tied by the prior alone."""
    bins = Unknowns.of(heard.shape[1], True, edges, False).bins(times, len(times))[0]  # (the fit's own)
    out = np.zeros((len(edges), heard.shape[1]), np.int64)
    np.add.at(out, bins, heard)
    np.add.at(out, bins + 1, heard)
    return out.T


def departure(edges: np.ndarray, offsets: np.ndarray, tied: np.ndarray, length: float,
              sigma: np.ndarray | None = None) -> float:
    """[s] the RMS of the clocks' departures from their chords of ``length`` [s]: each clock's offset at each of its
    knots ``t`` less the mean of its offsets at ``t ± length / 2``, over every knot whose chord lies within the knots
    the clock is tied at; the error at its middle of a clock taken as linear across a stretch of that ``length``
    (piecewise linear interpolation: de Boor, ch. III), seen where the pings tie the clocks. ``edges`` (K + 1,) [s]
    the knots, ``offsets`` (R, K + 1) [s] each clock's offset at them (linear between), ``tied`` (R, K + 1) bool the
    knots each clock's own arrivals touch (:func:`knot_counts`), ``sigma`` (R, K + 1) [s] the offsets' σ (None:
    exact): the departures' mean square less what that noise alone gives (each chord's three offsets taken
    independent; 0 where the noise explains it all). NaN where no chord fits (no knot of a clock as far as half the
    ``length`` from both ends of its tied knots: how the clocks bend over such a length is not seen)."""
    half, parts, noise = 0.5 * length, [], []
    sigma = np.zeros_like(offsets) if sigma is None else sigma
    for x, m, s in zip(offsets, tied, sigma):
        t, v, var = edges[m], x[m], s[m] ** 2
        if len(t) < 2:
            continue
        centre = t[(t - half >= t[0] - 1e-6 * half) & (t + half <= t[-1] + 1e-6 * half)]  # (round-off's margin)
        ends = [np.interp(centre + side, t, v) for side in (-half, half)]
        parts.append(np.interp(centre, t, v) - 0.5 * (ends[0] + ends[1]))
        noise.append(np.interp(centre, t, var) + 0.25 * (np.interp(centre - half, t, var) +
                                                         np.interp(centre + half, t, var)))
    gone = np.concatenate(parts) if parts else np.array([])
    return float(np.sqrt(max(np.mean(gone ** 2) - np.mean(np.concatenate(noise)), 0.0))) if len(gone) else \
        float("nan")


__all__ = ["MIN_BIN_PINGS", "WINDOW", "WINDOW_PINGS", "departure", "knot_counts", "knot_times", "merged",
           "spread_pings", "stretch_counts"]
