"""A later clock part's coarse shift (:func:`sblsim.models.sync.clock_parts.part_shifts`) where the sync tag pings at a
steady interval: the differences pile up at the true shift and again at every multiple of the interval, so the
step the receiver's time went back by in the file's order (the shift less the time it heard nothing) decides."""

from __future__ import annotations

import numpy as np

from sblsim.models.sync.clock_parts import part_shifts


def _study(jump: float, interval: float = 600.0, pings: int = 400, seed: int = 0):
    """One sync tag heard at receivers 0 and 1 (0.2 s apart by travel time, 1 ms noise) every ``interval`` [s];
    receiver 1's clock jumps by ``jump`` [s] halfway (its rows after the jump its part 2)."""
    rng = np.random.default_rng(seed)
    emitted = np.arange(pings) * interval + 5.0
    t0 = emitted + 0.1 + rng.normal(0, 1e-3, pings)
    t1 = emitted + 0.3 + rng.normal(0, 1e-3, pings)
    later = np.arange(pings) >= pings // 2
    t1 = np.where(later, t1 + jump, t1)
    time = np.r_[t0, t1]
    receiver = np.r_[np.zeros(pings, np.int64), np.ones(pings, np.int64)]
    part = np.r_[np.ones(pings, np.int64), np.where(later, 2, 1)]
    tag = np.zeros(2 * pings, np.int64)
    # the step in the file's order: the receiver's first row after the jump less its last before it, which is a fish
    # tag's detection 3 s before the jump (a receiver hears more tags than the sync tag)
    step = jump + 3.0
    return tag, receiver, part, time, step


def test_the_step_picks_the_true_shift_among_the_steady_intervals_multiples():
    jump = -3600.0
    tag, receiver, part, time, step = _study(jump)
    assert step < 0  # the time went back in the file's order
    shift, matched = part_shifts(tag, receiver, part, time, abs(step) + 86400.0, steps={(1, 2): step})
    later = (receiver == 1) & (part == 2)
    # the true shift is the jump plus the travel-time difference (0.2 s)
    assert np.allclose(shift[later], jump + 0.2, atol=0.05)
    assert matched[(1, 2)] > 100
    # the step decides among the interval's multiples: one an interval later (as if the receiver had heard nothing
    # for more than an interval) takes the multiple next to it (the check can fail)
    other, _ = part_shifts(tag, receiver, part, time, abs(step) + 86400.0, steps={(1, 2): step + 600.0})
    assert np.allclose(other[later], jump + 600.0 + 0.2, atol=0.05)


def test_a_short_jump_is_found_below_the_step():
    jump = -20.0
    tag, receiver, part, time, step = _study(jump, seed=1)
    shift, _ = part_shifts(tag, receiver, part, time, abs(step) + 86400.0, steps={(1, 2): step})
    later = (receiver == 1) & (part == 2)
    assert np.allclose(shift[later], jump + 0.2, atol=0.05)
