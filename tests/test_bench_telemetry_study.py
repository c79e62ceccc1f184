"""The telemetry study benchmark (``bench_telemetry_study.py``), run small: every tag tracked, its errors the ones
computed here again from the simulation (made again with the same seed) and within the tracks' own sigma, each
track near its smoothing bound, its time per ping the wall time over the pings; a bad size one line, exit 2."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import bench_telemetry_study  # noqa: E402

from sblsim.orchestrator.telemetry.simulate import simulate_study  # noqa: E402


@pytest.mark.slow
def test_a_small_study_is_tracked_scored_and_bounded(tmp_path):
    r = bench_telemetry_study.run(6, 3, 0.15, 1, seed=2, workers=1, format="fathom", folder=tmp_path)
    assert r["tracked"] == 3 and r["receivers"] == 6 and r["set_aside"] >= 5  # the deck detections
    assert np.isclose(r["per_ping_ms"], 1e3 * r["wall_s"] / r["pings"], rtol=1e-12)
    sim = simulate_study(n_receivers=6, n_tags=3, days=0.15, redeployed=1, seed=2)
    tracks = pd.read_csv(tmp_path / "out" / "tracks.csv", dtype={"tag": str})
    receivers = pd.read_csv(tmp_path / "out" / "receivers.csv", dtype=str)
    reference = json.loads((tmp_path / "out" / "study.json").read_text())["clocks"]["reference_receiver"]
    k = int(np.flatnonzero(receivers["receiver"].to_numpy() == reference)[0])
    for entry in r["per_tag"]:
        truth = sim.truth[entry["tag"]]
        mine = tracks[tracks["tag"] == entry["tag"]]
        clock = sim.clock_time(k, truth["tau"].to_numpy())
        error = np.hypot(mine["x"] - np.interp(mine["epoch_s"], clock, truth["x"]),
                         mine["y"] - np.interp(mine["epoch_s"], clock, truth["y"]))
        assert np.isclose(entry["rms_m"], np.sqrt(np.mean(error**2)), rtol=1e-9)
        assert entry["rms_m"] < 1.5 * entry["sigma_rms_m"] and 0.5 < entry["ratio"] < 1.5


def test_a_bad_size_is_one_line_exit_2():
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_telemetry_study.py"), "--receivers", "2"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "--receivers: at least 4" in done.stderr and done.stdout == ""
