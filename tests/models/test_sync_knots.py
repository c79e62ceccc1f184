"""The knots of a clock fitted from a study's moving tags' pings (models/sync/knots.py): every window between the
study's ends, merged where the pings are too few to tie a clock's offsets (a stretch the animals left, a sparse end),
the arrivals touching each knot, each against a count made here, and the clocks' departure from their chords against
the sine's closed form."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.sync.knots import (
    MIN_BIN_PINGS,
    WINDOW,
    WINDOW_PINGS,
    departure,
    knot_counts,
    knot_times,
    merged,
    spread_pings,
)


def test_a_knot_every_window_between_the_study_s_ends():
    """The knots of clocks fitted as logged: the study's first and last detection and no two more than
    :data:`WINDOW` apart, evenly spaced, the fewest that are (a study shorter than a window: its two ends)."""
    for length in (10.0, WINDOW - 1.0, WINDOW, WINDOW + 1.0, 7.5 * WINDOW, 91 * 86400.0):
        knots = knot_times((1.7e9, 1.7e9 + length))
        steps = np.diff(knots)
        assert knots[0] == 1.7e9 and knots[-1] == 1.7e9 + length and (steps <= WINDOW + 1e-6).all(), length
        assert np.allclose(steps, steps[0]) and len(steps) == max(1, -(-length // WINDOW)), (length, len(steps))
    assert np.array_equal(knot_times((5.0, 5.0)), [5.0, 6.0])  # (one detection: a second's span)


def test_a_knot_counts_the_arrivals_its_offset_is_interpolated_from():
    """:func:`knot_counts` against a count ping by ping: a ping between two knots (its offset linear between them)
    counts at both, one before the first or after the last knot at the end's (the offset held beyond the ends)."""
    rng = np.random.default_rng(2)
    edges = np.array([0.0, 100.0, 250.0, 400.0])
    times = rng.uniform(-50.0, 450.0, 300)
    heard = rng.random((300, 5)) < 0.6
    expected = np.zeros((5, 4), int)
    for t, row in zip(times, heard):
        j = min(max(int(np.searchsorted(edges, t, side="right")) - 1, 0), 2)
        expected[row, j] += 1
        expected[row, j + 1] += 1
    assert np.array_equal(knot_counts(heard, times, edges), expected)


def _pings(grid: np.ndarray, per_stretch: list[int], seed: int = 0) -> np.ndarray:
    """Times [s] with ``per_stretch[j]`` pings drawn inside the grid's stretch j."""
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.uniform(grid[j] + 1.0, grid[j + 1] - 1.0, n) for j, n in enumerate(per_stretch)])


GRID = np.arange(11) * WINDOW  # (ten stretches)
M = MIN_BIN_PINGS


@pytest.mark.parametrize("per_stretch, kept", [
    ([M] * 10, list(range(11))),  # enough everywhere: every knot
    ([M, M, 0, 0, 0, 2, 0, 0, M, M], [0, 1, 2, 8, 9, 10]),  # a day away: one stretch, its knots the neighbours'
    ([M, M, M, 0, M, M, M, M, M, M], list(range(11))),  # one empty stretch between two full: tied by both
    ([M] * 9 + [5], list(range(9)) + [10]),  # a last stretch of five pings joined to the one before
    ([3, 0, M, M, M, M, M, M, M, M], [0] + list(range(3, 11))),  # a sparse start joined to the next
    ([3] * 10, [0, 10]),  # too few everywhere (30 in all): the ends alone, an offset and a drift
    ([M - 1, 0, 0, 0, 0, 0, 0, 0, 0, M - 1], [0, 10]),
])
def test_a_knot_is_kept_where_the_pings_on_one_side_tie_it(per_stretch, kept):
    """A knot between two stretches of fewer than :data:`MIN_BIN_PINGS` pings each is dropped, and an end
    stretch of fewer is joined to its neighbour; the grid's ends always kept (the knots expected written out)."""
    assert np.array_equal(merged(GRID, _pings(GRID, per_stretch)), GRID[kept])


def test_pings_beyond_the_grid_count_at_its_ends():
    """A ping before the first knot or after the last counts in the end stretch (its offset the end's)."""
    times = np.r_[_pings(GRID, [0] + [M] * 9), np.full(M, -50.0)]
    assert np.array_equal(merged(GRID, times), GRID)
    assert np.array_equal(merged(GRID, times[:-M]), GRID[[0] + list(range(2, 11))])


def test_a_clock_s_departure_from_its_chords_is_the_sine_s():
    """Clocks wandering as sines (amplitude A, angular frequency ω, phase φ) on knots every hour: the departure of
    each from its chord of length 2h at a knot t is A sin(ωt + φ) (1 - cos ωh) in closed form (the chord's ends on
    knots: no interpolation between them); the RMS over the knots whose chord fits, against that form evaluated here.
    Clocks that are lines (an offset and a drift) depart by nothing; a knot the clock's arrivals do not touch is not
    read; a chord longer than the tied time is not seen (NaN)."""
    edges = 1.7e9 + 3600.0 * np.arange(49)  # two days
    tau = edges - edges[0]
    amplitude, omega, phase = np.array([[0.01], [0.004]]), 2 * np.pi / np.array([[86400.0], [1.7 * 86400.0]]), \
        np.array([[0.3], [2.0]])
    offsets = amplitude * np.sin(omega * tau + phase)
    tied = np.ones(offsets.shape, bool)
    for hours in (2, 6, 12):
        h = 0.5 * hours * 3600.0
        fits = (tau - h >= 0.0) & (tau + h <= tau[-1])
        form = (amplitude * np.sin(omega * tau + phase) * (1 - np.cos(omega * h)))[:, fits]
        assert departure(edges, offsets, tied, 2 * h) == pytest.approx(np.sqrt(np.mean(form ** 2)), rel=1e-9), hours
    lines = 0.02 + 3e-6 * tau[None] * np.array([[1.0], [-2.0]])
    assert departure(edges, lines, tied, 6 * 3600.0) == pytest.approx(0.0, abs=1e-12)
    wild = offsets.copy()
    wild[0, 20], tied[0, 20] = 5.0, False  # (a deployment's knot outside its time: tied by the prior alone)
    kept = departure(edges, wild, tied, 6 * 3600.0)
    assert np.isfinite(kept) and kept < 0.01
    assert np.isnan(departure(edges, offsets, np.ones(offsets.shape, bool), 50 * 3600.0))


def test_a_departure_the_knots_noise_explains_is_none():
    """Clocks that are lines seen through noise of σ at each knot: their chords' departures have a mean square of
    1.5 σ² (the knot's and half each end's, independent), which :func:`departure` gives without the σ (within 10 %
    over 20 clocks' 400 knots) and takes away with it (below σ / 4); a sine of 10 σ seen through the same noise comes
    out within 10 % of its own departure."""
    rng = np.random.default_rng(7)
    edges = 3600.0 * np.arange(401)
    sigma = 1e-4
    noisy = 1e-6 * edges[None] * rng.normal(size=(20, 1)) + rng.normal(0.0, sigma, (20, len(edges)))
    tied = np.ones(noisy.shape, bool)
    assert departure(edges, noisy, tied, 4 * 3600.0) == pytest.approx(np.sqrt(1.5) * sigma, rel=0.1)
    spread = np.full(noisy.shape, sigma)
    assert departure(edges, noisy, tied, 4 * 3600.0, spread) < 0.25 * sigma
    sine = 10 * sigma * np.sin(2 * np.pi * edges / 86400.0)[None].repeat(20, axis=0)
    clean = departure(edges, sine, tied, 12 * 3600.0)
    assert departure(edges, sine + noisy, tied, 12 * 3600.0, spread) == pytest.approx(clean, rel=0.1)


@pytest.mark.parametrize("most", [10_000, 900, 400, 50])
def test_a_season_s_pings_are_taken_window_by_window(most):
    """The pings fitted of a season's more than ``most``: from each window the same number q (every ping of one
    that holds fewer), q the largest whose total is within ``most`` (found here by trying every q) but never below
    :data:`WINDOW_PINGS`; a window's own spread evenly (its first and last taken), in time order, none twice; a ping
    beyond the grid's ends in the end's window. Where the pings are no more than ``most``, every one in its order."""
    rng = np.random.default_rng(11)
    grid = np.arange(7) * WINDOW
    counts = [500, 10, 0, 200, 45, 1000]
    times = np.concatenate([rng.uniform(grid[j], grid[j + 1], n) for j, n in enumerate(counts)] +
                           [[-5.0, grid[-1] + 5.0]])  # (one before the grid, one after)
    times = rng.permutation(times)
    kept = spread_pings(times, grid, most)
    if len(times) <= most:
        assert np.array_equal(kept, np.arange(len(times)))
        return
    window = np.clip(np.floor(times / WINDOW).astype(int), 0, 5)
    holds = np.bincount(window, minlength=6)
    q = max([q for q in range(holds.max() + 1) if np.minimum(holds, q).sum() <= most] + [0])
    q = max(q, WINDOW_PINGS)
    assert len(np.unique(kept)) == len(kept) and (np.diff(times[kept]) >= 0).all()
    assert np.array_equal(np.bincount(window[kept], minlength=6), np.minimum(holds, q))
    for j in range(6):
        mine = np.flatnonzero(window == j)
        if len(mine):
            assert times[kept][window[kept] == j].min() == times[mine].min()
            assert times[kept][window[kept] == j].max() == times[mine].max()
    assert len(kept) <= max(most, WINDOW_PINGS * 6)
