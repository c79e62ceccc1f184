"""The detection times' rounding found (models/sync/resolution.py) and said where it spoils positioning."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.sync.resolution import QUANTA, resolution_warning, time_quantum


@pytest.mark.parametrize("q", QUANTA)
def test_times_rounded_to_a_quantum_give_that_quantum(q):
    """Epoch times 2024 rounded to q (as an export rounds them) give q; the same times unrounded give 0."""
    rng = np.random.default_rng(1)
    raw = 1.7e9 + np.sort(rng.uniform(0, 86400 * 3, 500))
    assert time_quantum(np.round(raw / q) * q) == q
    assert time_quantum(raw) == 0.0


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
