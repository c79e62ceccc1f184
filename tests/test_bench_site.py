"""The site benchmark (``bench_site.py``): it times the scenario's own run, and its digest of the run's series is
that of the same run made here (the check by which ``--against`` says two revisions give the same numbers)."""

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import bench_site  # noqa: E402

from sblsim.orchestrator.commands.common import load  # noqa: E402
from sblsim.orchestrator.commands.run import run  # noqa: E402


@pytest.mark.slow
def test_the_site_run_is_timed_and_its_digest_is_the_runs():
    timed = bench_site.timed(bench_site._here, "lbl-field", 1)
    series = run(load("lbl-field", seed=0)).timeseries.select_dtypes("number").to_numpy(dtype=float)
    assert timed["seconds"] > 0 and timed["steps"] == len(series) > 100
    assert timed["digest"] == hashlib.sha256(np.ascontiguousarray(series).tobytes()).hexdigest()
    other = run(load("lbl-field", seed=1)).timeseries.select_dtypes("number").to_numpy(dtype=float)
    assert timed["digest"] != hashlib.sha256(np.ascontiguousarray(other).tobytes()).hexdigest()


def test_a_bad_repeat_count_is_one_line_exit_2():
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_site.py"), "--repeats", "0"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and "--repeats: must be at least 1" in done.stderr and done.stdout == ""
