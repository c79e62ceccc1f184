"""The knots of a clock fitted from a study's moving tags' pings (models/sync/knots.py): every window between the
study's ends, merged where the pings are too few to tie a clock's offsets (a stretch the animals left, a sparse end),
and the arrivals touching each knot, each against a count made here."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.sync.knots import MIN_BIN_PINGS, WINDOW, knot_counts, knot_times, merged


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
