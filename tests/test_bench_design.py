"""The design benchmark (``bench_design.py``): the layouts it times are evaluated as the map evaluates them (the
search's compiled evaluation with the site's tabulated detection against ``sblsim map``'s function, the DRMS within
1e-3 where every packet is heard), and a bad option is one line, exit 2."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import bench_design  # noqa: E402


@pytest.mark.slow
def test_the_timed_layouts_are_the_maps_and_the_search_is_faster():
    timed = bench_design.candidate_times(4, 1, map_samples=2)
    assert 0.0 < timed["search"] < timed["map"]
    assert timed["difference"] < 1e-3


def test_a_bad_repeat_count_is_one_line_exit_2():
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_design.py"), "--repeats", "0"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and "--repeats: must be at least 1" in done.stderr and done.stdout == ""
