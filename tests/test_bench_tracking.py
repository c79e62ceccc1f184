"""The tracking benchmark (``bench_tracking.py``): it times the replay and, on the same pings, the robust smoother
against the EKF with the RTS smoother; its figures are those runs' (the ratio of the two times, the track's RMS
error that of a replay), and a bad repeat count is one line, exit 2."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import bench_tracking  # noqa: E402

THINNED = "H2,H4,H6,H7,H11,H12,H17,H23"


@pytest.mark.slow
def test_the_replay_and_the_smoothers_are_timed_on_the_same_pings():
    r = bench_tracking.measure(1, THINNED, warm=False)
    assert r["pings"] == 3244 and r["replay_s"] > 0 and r["ekf_rts_s"] > 0 and r["robust_s"] > 0
    assert np.isclose(r["ratio"], r["robust_s"] / r["ekf_rts_s"], rtol=1e-12)
    # the track's RMS error is the replay's, scored here against the GPS
    track, gps = r["result"].track, np.genfromtxt(BENCHMARKS.parent / "data" / "lake-hald" / "gps.txt", skip_header=1)
    t = track["time"].to_numpy()
    inside = (t >= gps[0, 2]) & (t <= gps[-1, 2])
    e = np.hypot(track["x"].to_numpy() - np.interp(t, gps[:, 2], gps[:, 0]),
                 track["y"].to_numpy() - np.interp(t, gps[:, 2], gps[:, 1]))[inside]
    assert np.isclose(r["rms_m"], np.sqrt(np.mean(e**2)), rtol=1e-12)


def test_a_bad_repeat_count_is_one_line_exit_2():
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_tracking.py"), "--repeats", "0"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "--repeats: must be at least 1" in done.stderr and done.stdout == ""
