"""A pseudo-random tag's burst sequence (``pbi``: the intervals the maker gives, repeating) aligned to the steps of
the rows' first arrivals: the phase found, each step matched to the sum of the intervals it spans (pings nobody
heard bridged). Units: seconds [s].

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017,
doi:10.1038/s41598-017-14278-z (the ping types).
"""

from __future__ import annotations

import numpy as np

from sblsim.models.declarations import ModelError

#: Most missed pings one step of a ``pbi`` sequence's alignment bridges.
PBI_MAX_MISSED = 64
#: The first steps over which every phase of a pseudo-random tag's sequence is tried (:func:`align_sequence`).
PBI_PHASE_STEPS = 256


def align_sequence(steps: np.ndarray, sequence: np.ndarray, crossing: float) -> tuple[np.ndarray, np.ndarray]:
    """A pseudo-random tag's interval sequence aligned to the rows' first-arrival steps.

    Every phase of the (repeating) sequence is tried on the first :data:`PBI_PHASE_STEPS` steps: from it, each step
    of the rows takes as many of the next intervals (1 to :data:`PBI_MAX_MISSED`: pings nobody heard) as bring their
    sum nearest to the step; a step matches when that sum is within twice the crossing time. The phase with the most
    matches there aligns the whole record (one pass, not one per phase: a long record's alignment in linear time),
    and where that matches under half of the steps every phase is tried over the whole record.

    Parameters
    ----------
    steps : ndarray, (k,)
        The rows' first-arrival steps [s] (:func:`~sblsim.models.tracking.schedule.first_arrival_steps`).
    sequence : ndarray, (L,)
        The tag's intervals [s], positive.
    crossing : float
        The array's crossing time [s].

    Returns
    -------
    durations : ndarray, (k,)
        Each step's duration [s]: the sequence's sum where it matched, the first-arrival step elsewhere.
    matched : ndarray of bool, (k,)

    Raises
    ------
    ModelError
        A sequence of non-positive or non-finite intervals, or one no phase of which matches half the steps.
    """
    if not (np.isfinite(sequence).all() and (sequence > 0).all()):
        raise ModelError("burst sequence: allowed: positive intervals [s]")
    L, tolerance = len(sequence), 2.0 * crossing
    period, partial = float(sequence.sum()), np.r_[0.0, np.cumsum(sequence)]
    mean = period / L

    def elapsed(a: np.ndarray | int) -> np.ndarray:
        """The sum of the first ``a`` intervals of the repeating sequence [s]."""
        return (np.asarray(a) // L) * period + partial[np.asarray(a) % L]

    ahead = np.arange(1, PBI_MAX_MISSED + 1)

    def walk(phase: int, steps: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
        """The steps aligned from ``phase``: the matches, the durations and which matched."""
        j, durations, matched = phase, np.array(steps, float), np.zeros(len(steps), bool)
        for k, d in enumerate(steps):
            sums = elapsed(j + ahead) - elapsed(j)
            r = int(np.argmin(np.abs(sums - d)))
            if abs(sums[r] - d) <= tolerance:
                durations[k], matched[k] = sums[r], True
                j += r + 1
            else:  # lost the sequence here: the nearest whole ping count by the mean interval
                j += max(int(round(d / mean)), 1)
        return int(matched.sum()), durations, matched

    # the phase chosen on the first PBI_PHASE_STEPS steps (every phase tried there), then the whole record aligned
    # from it; every phase over the whole record where that matches under half of the steps
    steps = np.asarray(steps, float)
    head = steps[:PBI_PHASE_STEPS]
    phase = max(range(L), key=lambda f: (walk(f, head)[0], -f))
    best = walk(phase, steps)
    if len(steps) > PBI_PHASE_STEPS and best[0] < 0.5 * len(steps):
        for other in range(L):
            found = walk(other, steps)
            if found[0] > best[0]:
                best = found
    if best[0] < 0.5 * len(steps):
        raise ModelError(f"burst sequence: {max(best[0], 0)} of {len(steps)} steps match the sequence at its best "
                         "phase; allowed: the tag's own sequence (its intervals in order)")
    return best[1], best[2]


__all__ = ["PBI_MAX_MISSED", "PBI_PHASE_STEPS", "align_sequence"]
