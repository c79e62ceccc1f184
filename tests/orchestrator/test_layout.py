"""Other beacon layouts run without code changes (local engine; both engines: ``test_beacons.py``)."""

import numpy as np
import pytest

from sblsim.models.platform.geometry import platform_offsets
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run

SIX = "10 0 1; 0 10 1; -10 0 1; 0 -10 1; 0 0 15; 7 7 1"


def _six_beacon_config():
    return load_config("semicircle", ["platform.layout=custom", f'platform.beacon_offsets="{SIX}"',
                                      "simulation.duration=6"], seed=2)


def test_a_custom_layout_is_its_offsets_in_their_order():
    """The six offsets as given (East, North, down [m]), in the order the beacons' slots take them: what the run
    below depends on, without its six-beacon library (the fast tier compiles no count the paper's system lacks)."""
    cfg = _six_beacon_config()
    expected = np.array([[10, 0, 1], [0, 10, 1], [-10, 0, 1], [0, -10, 1], [0, 0, 15], [7, 7, 1]], dtype=float)
    assert make_plan(cfg).n_beacons == 6 and cfg["platform"]["beacons"] == 6
    np.testing.assert_array_equal(platform_offsets(cfg["platform"]), expected)


@pytest.mark.slow  # 1 s once compiled; a six-beacon library of its own (20-30 s of compiling on a fresh machine)
def test_custom_six_beacon_layout_runs_round_robin_over_six():
    cfg = _six_beacon_config()
    assert make_plan(cfg).n_beacons == 6
    ts = run(cfg, "local").timeseries
    expected = np.concatenate([[0], np.arange(len(ts) - 1) % 6 + 1])  # each slot arrives in the next step
    np.testing.assert_array_equal(ts["beacon_id"].to_numpy(), expected)
    # beacon 5 sits 15 m below the platform reference (calm-sea offsets plus the broadcast noise)
    fifth = ts[ts["beacon_id"] == 5]
    assert np.all(np.abs(fifth["beacon_z"] - 15.0) < 1.0)
    # an estimate from the first fix on (the first packet, at step 1), none before it
    assert np.isnan(ts["est_x"].iloc[0]) and np.all(np.isfinite(ts["est_x"].iloc[1:]))

