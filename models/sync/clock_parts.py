"""A receiver's clock parts (its time went back in the file's order: a reset kept in its logging order) aligned to
the other receivers' for the emissions' grouping: each later part's coarse shift, the mode of the differences between
its arrivals and a sync tag's at another receiver (:mod:`sblsim.models.sync.breaks`). Units: seconds [s].
"""

from __future__ import annotations

import numpy as np

#: The bins [s] in which a later clock part's coarse shift is looked for (:func:`part_shifts`).
PART_BIN = 2.0


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


__all__ = ["PART_BIN", "part_shifts"]
