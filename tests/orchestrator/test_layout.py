"""Other beacon layouts run without code changes (local engine); the FMUs built for 4 refuse clearly."""

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.config import load_config
from sblsim.orchestrator.run import beacon_count, run

SIX = "10 0 1; 0 10 1; -10 0 1; 0 -10 1; 0 0 15; 7 7 1"


def _six_beacon_config():
    return load_config("semicircle", ["platform.layout=custom", f'platform.beacon_offsets="{SIX}"',
                                      "simulation.duration=6"], seed=2)


def test_custom_six_beacon_layout_runs_round_robin_over_six():
    cfg = _six_beacon_config()
    assert beacon_count(cfg) == 6
    ts = run(cfg, "local").timeseries
    expected = (np.arange(len(ts)) % 6) + 1
    np.testing.assert_array_equal(ts["beacon_id"].to_numpy(), expected)
    # beacon 5 sits 15 m below the platform reference (calm-sea offsets plus the broadcast noise)
    fifth = ts[ts["beacon_id"] == 5]
    assert np.all(np.abs(fifth["beacon_z"] - 15.0) < 1.0)
    assert np.all(np.isfinite(ts["est_x"]))


def test_custom_layout_on_four_beacon_fmus_is_refused(fmu_dir):
    with pytest.raises(ModelError, match="6 beacons, but the FMUs carry 4; run it on the local engine"):
        run(_six_beacon_config(), "fmu", fmu_dir=fmu_dir)
