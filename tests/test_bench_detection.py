"""The benchmark's detection chunk (``bench_campaign.py --snr``): it times ``snr`` beside ``fixed`` (eigenrays for
both) for SBL, LBL and USBL, and the two runs it times are what they say."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_campaign  # noqa: E402

from sblsim.orchestrator.cosim.config import load_config  # noqa: E402
from sblsim.orchestrator.cosim.run import run_batch, with_replicates  # noqa: E402


@pytest.mark.slow
def test_the_snr_chunk_times_both_detections_of_every_system(capsys):
    timed = bench_campaign.detection_timing(runs=3, duration=2.0, rounds=1)
    assert list(timed) == ["SBL", "LBL", "USBL"]
    lines = [line for line in capsys.readouterr().out.splitlines() if "per replicate-step" in line]
    assert len(lines) == 3
    columns = ["e_tot_rms", "e_tot_mean", "detected_pct"]
    for (label, (fixed, snr, fixed_run, snr_run)), line in zip(timed.items(), lines):
        assert fixed > 0 and snr > 0 and line.split()[0] == label
        assert f"fixed {fixed * 1e6:7.2f} us" in line and f"snr {snr * 1e6:7.2f} us" in line
        assert f"{snr / fixed:.2f}x" in line and ("within" in line) == (snr / fixed <= bench_campaign.SNR_TARGET)
        a, b = fixed_run.metrics[columns].to_numpy(), snr_run.metrics[columns].to_numpy()
        assert np.all(np.isfinite(a[:, :2])) and np.all(np.isfinite(b)), label
        # the snr run hears by the sonar equation: every packet of the chunk's short ranges is detected
        np.testing.assert_array_equal(b[:, 2], 100.0)
        # the snr run is the configuration's own: the same numbers as a run of it outside the benchmark
        overrides = [*bench_campaign.RAY_SYSTEMS[label], *bench_campaign.SNR_COMMON,
                     *bench_campaign.SNR_OWN.get(label, ()), "acoustics.detection=snr", "simulation.duration=2.0"]
        cfg = load_config("semicircle", overrides, seed=1)
        assert cfg["acoustics"]["detection"] == "snr" and cfg["acoustics"]["water_depth"] == 20.0
        again = run_batch(with_replicates(cfg, range(3)), timeseries=False)
        np.testing.assert_array_equal(again.metrics[columns].to_numpy(), b)
