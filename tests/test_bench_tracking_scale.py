"""The tracking benchmark at scale (``bench_tracking_scale.py``), run small: its robust track is the simulated tag's
to within the timing noise's own position scale (scored here against the simulation made again), its per-ping
times and ratios are those of its stages, its baseline measured in the same run, and a bad size is one line,
exit 2."""

import subprocess
import sys
from pathlib import Path

import numpy as np

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import bench_tracking_scale  # noqa: E402


def test_the_robust_track_of_a_small_record_is_the_tag_s_and_its_times_add_up():
    r = bench_tracking_scale.measure(2000, seed=3, sizes=2)
    assert r["sizes"] == [200, 2000] and r["pings"] == 2000
    assert {"track_s", "fixes_s", "schedule_s", "robust_s", "peak_gib", "per_ping_us", "ratio", "rms_m",
            "ekf_rts_per_ping_us", "target_s", "target_gib"} <= set(r)
    # the track's error against the truth simulated again (the same seed), not the benchmark's own figure
    _, _, truth, emissions, settings = bench_tracking_scale.simulate(2000, seed=3)
    x = r["robust"].x
    error = np.hypot(*(x[:, :2] - truth).T)
    rms = float(np.sqrt(np.mean(error**2)))
    assert np.isclose(r["rms_m"], rms, rtol=1e-12)
    # below the position scale of one arrival's timing noise (σ_toa c = 0.22 m): the track uses ~6.4 per ping
    assert rms < settings.sigma_toa * bench_tracking_scale.SOUND_SPEED
    assert np.abs(x[:, -2] - emissions).max() < 1e-3  # every emission time to within a millisecond
    for run in r["runs"]:
        assert np.isclose(run["fixes_s"] + run["schedule_s"] + run["robust_s"], run["track_s"], rtol=1e-9)
        assert np.isclose(run["per_ping_us"], 1e6 * run["track_s"] / run["pings"], rtol=1e-12)
        assert run["peak_bytes"] > 0
    assert r["ratio"][0] == 1.0 and np.isclose(r["ratio"][1], r["per_ping_us"][1] / r["per_ping_us"][0], rtol=1e-12)
    # the baseline in the same run (the splice rounds re-solving the whole record): its own CPU time, the ratio of
    # the two, and today's track within a micrometre of it on this record
    # the EKF's baseline (its TOA model called per ping as before): the same records to the last bit, its time beside
    assert r["ekf_rts_same"] is True and r["ekf_rts_baseline_per_ping_us"] > 0.0
    assert np.isclose(r["ekf_rts_ratio"], r["ekf_rts_per_ping_us"] / r["ekf_rts_baseline_per_ping_us"], rtol=1e-9)
    # the bounds' baseline (a step's terms made inside the recursion as before): the same bounds to the last bit
    assert r["bound_same"] is True and r["bound_per_ping_us"] > 0.0 and r["bound_baseline_per_ping_us"] > 0.0
    assert np.isclose(r["bound_ratio"], r["bound_per_ping_us"] / r["bound_baseline_per_ping_us"], rtol=1e-9)
    for run in r["runs"]:
        base = run["baseline"]
        assert base["pings"] == run["pings"] and base["track_cpu_s"] > 0.0 and run["splice_cpu_s"] >= 0.0
        assert np.isclose(run["cpu_ratio"], run["track_cpu_s"] / base["track_cpu_s"], rtol=1e-12)
        assert 0.0 <= run["moved_m"] < 1e-6 and 0.0 <= run["moved_te_m"] < 1e-6
    assert r["cpu_ratio"] == r["runs"][-1]["cpu_ratio"]


def test_a_bad_size_is_one_line_exit_2():
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_tracking_scale.py"), "--pings", "10"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "--pings: must be at least 100" in done.stderr and done.stdout == ""
