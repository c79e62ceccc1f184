"""A clock break too near a clock's end or start to fit a segment (:mod:`sblsim.models.sync.end_breaks`) on small
simulations (:func:`sblsim.models.sync.simulate.simulate_sync`, one receiver's clock jumping with ~5 of its
sync-tag arrivals beyond the jump): found, its size and instant against the simulation's truth, exactly the
arrivals beyond it set aside, the receiver's times there in no segment, the offsets before it as without the jump;
no clock cut on 20 seeds without a jump."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from sblsim.models.sync.end_breaks import cut_ends
from tests.helpers import simulated_clocks

N, HOURS, SEED, RECEIVER, BEYOND = 8, 6.0, 11, 4, 5


@lru_cache(maxsize=None)
def _fit(seed: int, jump: tuple[int, float, float] | None = None, hours: float = HOURS,
         interval: tuple[float, float] = (540.0, 660.0)):
    """A simulated array of :data:`N` receivers (:func:`tests.helpers.simulated_clocks`: sync tags every
    ``interval`` [s]), the clocks fitted with their breaks against receiver 0, then cut at their ends
    (:func:`cut_ends`)."""
    sim, origin, t, used, emission, distance, slowness, fit = simulated_clocks(N, hours, seed, jump, interval)
    cut, ends = cut_ends(fit, sim.receiver, emission, t, distance, slowness, used, sim.tag)
    return sim, origin, t, used, fit, cut, ends


def _jump_time(at_start: bool, seed: int = SEED, interval: tuple[float, float] = (540.0, 660.0)) -> float:
    """[s] a true time with :data:`BEYOND` of :data:`RECEIVER`'s used arrivals after it (before it at the start),
    midway between two of its arrivals (the jump-free simulation's: the draws are the same with a jump)."""
    sim, _, _, used, *_ = _fit(seed, interval=interval)
    tau = np.sort(sim.true_time(sim.receiver, sim.time)[used & (sim.receiver == RECEIVER)])
    k = BEYOND if at_start else len(tau) - BEYOND
    return float(0.5 * (tau[k - 1] + tau[k]))


@pytest.mark.parametrize("at_start, size", [(False, 0.5), (False, -20.0), (False, 5e-3), (True, 0.5),
                                            (True, -20.0)])
def test_a_jump_near_a_clocks_end_found_and_the_arrivals_beyond_it_set_aside(at_start, size):
    """+0.5 s, −20 s and +5 ms with 5 arrivals after the jump, +0.5 s and −20 s with 5 before it: the change-point
    search finds nothing (too few arrivals on one side), the end's check finds one break at the receiver, its size
    within 3 of its sigmas and 1 ms of the truth, its instant within its stated interval of the true one (on
    receiver 0's clock); the arrivals set aside (clock row -1) are exactly those beyond the jump, the receiver's
    own times from its last good arrival on (up to its first at the start; widened by the jump where its time went
    back) in no segment (``rows_at`` -1) and its others in its row; the offsets of the rest within 2 sigmas of the
    same simulation's without the jump (at the start, the clock kept being the one after the jump, less the
    jump)."""
    tau_b = _jump_time(at_start)
    sim, origin, t, used, fit, cut, ends = _fit(SEED, (RECEIVER, tau_b, size))
    assert fit.breaks is None
    (end,) = ends
    assert end.receiver == RECEIVER and end.at_start == at_start and end.arrivals == BEYOND
    assert abs(end.size - size) <= min(3 * end.size_sigma, 1e-3)
    instant = tau_b + sim.offset0[0] + sim.drift[0] * tau_b - origin
    assert abs(end.time - instant) <= end.time_within and end.time_within < 600.0
    beyond = (sim.after if not at_start else ~sim.after) & (sim.receiver == RECEIVER)
    assert np.array_equal(used & (cut.clock < 0), used & beyond)
    mine = sim.receiver == RECEIVER
    rows = cut.rows_at(sim.receiver[mine], t[mine])
    before, after = t[mine & ~beyond & used], t[mine & beyond]
    if at_start:  # its times up to its first good arrival set aside (and the jump's where its time went back)
        assert after.max() < end.aside_to <= before.min() + max(0.0, -size) + 2e-3 and end.aside_from == -np.inf
        held = t[mine] >= end.aside_to
    else:  # its times from its last good arrival on (less the jump where its time went back)
        assert after.min() > end.aside_from >= before.max() + min(0.0, size) - 2e-3 and end.aside_to == np.inf
        held = t[mine] <= end.aside_from
    assert (rows[beyond[mine]] == -1).all() and (rows[held] == RECEIVER).all() and (rows[~held] == -1).all()
    clean = _fit(SEED)[4]
    span = cut.span[RECEIVER]
    inside = (cut.edges >= span[0]) & (cut.edges <= span[1])  # the edges the cut clock still holds
    for row in range(N):
        hold = inside if row == RECEIVER else np.ones(len(cut.edges), bool)
        # at the start the clock kept is the one after the jump: its offset at a reading the clean one's plus the
        # jump over the two clocks' rates (the truth's)
        moved = size * (1 + sim.drift[0]) / (1 + sim.drift[row]) if at_start and row == RECEIVER else 0.0
        sigma = np.hypot(cut.knot_sigma[row, hold], clean.knot_sigma[row, hold])
        assert (np.abs(cut.knots[row, hold] - clean.knots[row, hold] - moved) <= 2 * sigma + 1e-9).all(), row


@pytest.mark.parametrize("seed, size", [(0, 0.5), (1, 0.5), (2, 0.5), (1, -20.0), (2, 5e-3)])
def test_the_arrivals_beyond_a_jump_near_the_end_pull_no_split_from_the_search(seed, size):
    """A denser array (sync tags every 200 to 300 s: ~20 arrivals an hour at a receiver) whose receiver jumps with
    5 of its arrivals after it: those 5, rejected by the fit, would pull the change-point search's best gap to its
    10 samples from the end (before, on each of these: a split there, its later segment 5 to 9 arrivals; on the boats
    data a spurious one of 1 ms, 40 min before a real jump of 0.5 s); they are left out of the search, so no clock is
    split, the end's check finds the one break, its size within 3 of its sigmas and 1 ms of the truth, and sets
    aside exactly the arrivals beyond it."""
    dense = (200.0, 300.0)
    sim, _, _, used, fit, cut, ends = _fit(seed, (RECEIVER, _jump_time(False, seed, dense), size), interval=dense)
    assert fit.breaks is None
    (end,) = ends
    assert end.receiver == RECEIVER and not end.at_start and end.arrivals == BEYOND
    assert abs(end.size - size) <= min(3 * end.size_sigma, 1e-3)
    assert np.array_equal(used & (cut.clock < 0), used & sim.after & (sim.receiver == RECEIVER))


@pytest.mark.slow
def test_no_clock_cut_without_a_jump_on_20_seeds():
    """20 simulations without a jump (seeds 100 to 119, 4 h each): no clock of their 160 cut, the fit returned as
    it was."""
    cut_clocks = 0
    for seed in range(100, 120):
        _, _, _, _, fit, cut, ends = _fit(seed, hours=4.0)
        cut_clocks += len(ends)
        assert cut is fit
    assert cut_clocks / (20 * N) == 0.0
