"""The benchmark's eigenray chunk (``bench_campaign.py --ray``): it times ``ray`` beside ``straight`` for SBL, LBL
and USBL, and the two runs it times are what they say (the rays through the Munk profile change the numbers)."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_campaign  # noqa: E402

from sblsim.orchestrator.cosim.config import load_config  # noqa: E402
from sblsim.orchestrator.cosim.run import run_batch, with_replicates  # noqa: E402


def test_the_ray_chunk_times_both_propagations_of_every_system(capsys):
    timed = bench_campaign.propagation_timing(runs=3, duration=2.0, rounds=1)
    assert list(timed) == ["SBL", "LBL", "USBL"]
    lines = [line for line in capsys.readouterr().out.splitlines() if "per replicate-step" in line]
    assert len(lines) == 3
    for (label, (straight, ray, straight_run, ray_run)), line in zip(timed.items(), lines):
        assert straight > 0 and ray > 0 and line.split()[0] == label
        assert f"{ray / straight:.2f}x" in line
        columns = ["e_tot_rms", "e_tot_mean"]
        a, b = straight_run.metrics[columns].to_numpy(), ray_run.metrics[columns].to_numpy()
        assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and not np.array_equal(a, b), label
        # the ray run is the configuration's own: the same numbers as a run of it outside the benchmark
        overrides = [*bench_campaign.RAY_SYSTEMS[label], "acoustics.sound_speed_profile=munk",
                     "acoustics.propagation=ray", "simulation.duration=2.0"]
        again = run_batch(with_replicates(load_config("semicircle", overrides, seed=1), range(3)), timeseries=False)
        np.testing.assert_array_equal(again.metrics[columns].to_numpy(), b)
