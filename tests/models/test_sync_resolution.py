"""The detection times' rounding found (models/sync/resolution.py) and said where it spoils positioning."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.sync.resolution import QUANTA, common_quantum, resolution_warning, time_quantum


@pytest.mark.parametrize("q", QUANTA)
def test_times_rounded_to_a_quantum_give_that_quantum(q):
    """Epoch times 2024 rounded to q (as an export rounds them) give q; the same times unrounded give 0."""
    rng = np.random.default_rng(1)
    raw = 1.7e9 + np.sort(rng.uniform(0, 86400 * 3, 500))
    assert time_quantum(np.round(raw / q) * q) == q
    assert time_quantum(raw) == 0.0


def test_batches_rounded_apart_combine_as_their_times_together():
    """Two batches of times on two grids (0.05 s and 0.02 s: neither a multiple of the other), each batch's quantum
    found alone, combine (:func:`common_quantum`) to the quantum of all their times found at once, for every pair of
    :data:`QUANTA`; a batch finer than a millisecond makes the whole so."""
    rng = np.random.default_rng(3)
    raw = 1.7e9 + np.sort(rng.uniform(0, 86400, 600))
    for a in QUANTA:
        for b in QUANTA:
            first, second = np.round(raw[:300] / a) * a, np.round(raw[300:] / b) * b
            alone = [time_quantum(first), time_quantum(second)]
            assert alone == [a, b]
            assert common_quantum(alone) == time_quantum(np.r_[first, second]), (a, b)
    assert common_quantum([0.05, 0.02]) == 0.01 and common_quantum([0.05, 0.0]) == 0.0 and common_quantum([]) == 0.0


def test_the_warning_weighs_the_rounding_against_the_travel_time():
    """Whole seconds across a 400 m array (0.27 s at 1,480 m/s): said, with the rounding's σ q/√12 in ms and metres
    computed here; milliseconds: not said; tenths of a second across a 40 km array: not said."""
    rng = np.random.default_rng(2)
    raw = 1.7e9 + np.sort(rng.uniform(0, 86400, 300))
    line = resolution_warning(np.round(raw), 400.0 / 1480.0, 1480.0, "det.csv")
    sigma = 1.0 / np.sqrt(12.0)
    assert line is not None and line.startswith("det.csv: every time is a whole multiple of 1 s")
    assert f"{1000 * sigma:.3g} ms" in line and f"{sigma * 1480:.3g} m of range" in line and "\n" not in line
    assert resolution_warning(np.round(raw, 3), 400.0 / 1480.0, 1480.0, "det.csv") is None
    assert resolution_warning(np.round(raw, 1), 40000.0 / 1480.0, 1480.0, "det.csv") is None
    assert resolution_warning(raw, 400.0 / 1480.0, 1480.0, "det.csv") is None


def test_one_receiver_is_said_as_such():
    """One receiver has no travel time across an array: the rounding said without a nonsense 0 ms."""
    raw = 1.7e9 + np.random.default_rng(2).uniform(0, 3600, 200)
    line = resolution_warning(np.round(raw), 0.0, 1480.0, "det.csv")
    assert line is not None and "one receiver" in line and "0 ms" not in line
