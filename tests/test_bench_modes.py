"""The modes benchmark (``bench_modes.py``), run small: its hypotheses are the arrivals and their pairs counted
again, its NEES the track's against the truth simulated again (the record drawn again from its seed), its ratios
its own times', and a bad argument is one line, exit 2."""

import subprocess
import sys
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import bench_modes  # noqa: E402
import bench_tracking_scale  # noqa: E402


@pytest.mark.slow
def test_the_searches_count_their_hypotheses_and_their_nees_is_the_tracks():
    r = bench_modes.measure(100, seed=2)
    toa, _, truth, _, _ = bench_tracking_scale.simulate(100, 2, (bench_modes.SHARE, bench_modes.EXCESS_M))
    assert np.array_equal(r["toa"], toa, equal_nan=True) and np.array_equal(r["truth"], truth)
    heard = np.isfinite(r["toa"]).sum(axis=1)
    singles = int(heard[heard >= 3].sum())
    pairs = sum(len(list(combinations(range(n), 2))) for n in heard if n >= 4)
    assert [s["hypotheses"] for s in r["searches"]] == [singles, singles + pairs] and pairs > 0
    x, P = r["track"].x[:, :2], r["track"].P[:, :2, :2]
    for s in r["searches"]:
        C = P + r["spread"][s["late"]]
        e = x - truth
        assert np.isclose(s["nees"], np.mean([v @ np.linalg.solve(c, v) for v, c in zip(e, C)]), rtol=1e-9)
        assert np.isclose(s["ratio"], s["cpu_s"] / r["smoother_cpu_s"], rtol=1e-12) and s["cpu_s"] > 0
    assert np.isclose(r["nees_smoother"], np.mean([v @ np.linalg.solve(c, v) for v, c in zip(x - truth, P)]))
    assert r["arrivals"] == int(heard.sum())


@pytest.mark.parametrize("args, message", [(["--pings", "10"], "--pings: must be at least 100"),
                                           (["--share", "1.5"], "--share: 1.5 is outside the allowed range (0, 1)"),
                                           (["--excess", "0"], "--excess: 0.0 must be above 0 m")])
def test_a_bad_argument_is_one_line_exit_2(args, message):
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_modes.py"), *args], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and message in done.stderr and done.stdout == ""
