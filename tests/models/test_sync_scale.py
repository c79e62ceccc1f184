"""The receivers' positions against the sync tags' clock-free double differences (:mod:`sblsim.models.sync.scale`), on
simulated clocks offset by up to 2 s and drifting by up to 20 ppm, against the positions the simulation drew."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.errors import ModelError
from sblsim.models.sync import scale
from sblsim.models.sync.simulate import simulate_sync


@pytest.fixture(scope="module")
def sim():
    return simulate_sync(n_receivers=12, hours=12.0, seed=3, offset=2.0, drift=20e-6)


def _scale(sim, positions: np.ndarray) -> scale.Scale:
    distance = np.linalg.norm(positions[sim.tag] - positions[sim.receiver], axis=1)
    return scale.distance_scale(*scale.double_differences(sim.receiver, sim.tag, sim.emission, sim.time, distance,
                                                          sim.sound_speed))


def test_the_true_positions_give_a_scale_of_one_and_kilometres_a_thousand(sim):
    """Every clock offset cancels: the true table's scale is 1 within the timing noise (0.15 ms over distances of
    hundreds of metres: 0.1 %); the table divided by 1,000 gives 1,000 times that, and is refused naming
    kilometres; a table of degrees near 56° N is refused naming degrees."""
    truth = _scale(sim, sim.positions)
    assert truth.items >= 20 and abs(truth.scale - 1.0) < 1e-3, truth
    scale.check_scale(truth, "receivers", sim.positions[:, 0], sim.positions[:, 1], "metres")
    km = _scale(sim, sim.positions / 1e3)
    assert km.scale == pytest.approx(1e3 * truth.scale, rel=1e-9)
    with pytest.raises(ModelError, match="^receivers 'r.csv': .* look like kilometres; allowed: metres$"):
        scale.check_scale(km, "receivers 'r.csv'", sim.positions[:, 0] / 1e3, sim.positions[:, 1] / 1e3, "metres")
    lon, lat = 9.3 + sim.positions[:, 0] / 61_500.0, 56.4 + sim.positions[:, 1] / 111_195.0
    degrees = _scale(sim, np.column_stack([lon, lat]))
    with pytest.raises(ModelError, match="look like degrees"):
        scale.check_scale(degrees, "receivers", lon, lat, "metres")


def test_the_units_named_and_too_few_pairs_left_unchecked():
    assert scale.likely_unit(1e3, False) == "kilometres" and scale.likely_unit(1e-2, False) == "centimetres"
    assert scale.likely_unit(1.1e5, True).startswith("degrees") and scale.likely_unit(1.1e5, False) != "degrees"
    assert scale.looks_like_degrees(np.array([9.30, 9.31]), np.array([56.40, 56.41]))
    assert not scale.looks_like_degrees(np.array([0.0, 400.0]), np.array([0.0, 300.0]))
    assert scale.distance_scale(np.array([1.0, 2.0]), np.array([1.0, 2.0]), np.array([0, 1])) is None
