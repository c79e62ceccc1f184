"""The campaign benchmark's compiled floor (``benchmarks/ekf_floor.c``): the plain-C EKF predict + update computes
FilterPy's ``ExtendedKalmanFilter`` step on the same inputs (state and covariance to 1e-12 over 20 steps), the check
that says so fails for a step of other inputs, and the timing returns a step's seconds."""

import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import ekf_floor  # noqa: E402


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return ekf_floor.build(tmp_path_factory.mktemp("floor"))


def test_the_c_step_is_filterpys(lib):
    assert ekf_floor.check_floor(lib) <= ekf_floor.TOLERANCE
    # the filter moves (a check of two filters standing still would prove nothing)
    x, P = ekf_floor.c_filter(lib)()
    start = ekf_floor.problem()
    assert np.max(np.abs(x - start["x"])) > 1e-3 and np.max(np.abs(P - start["P"])) > 0.1


@pytest.mark.parametrize("changed", ["z", "R", "Q"])
def test_the_check_fails_for_a_step_of_other_inputs(lib, changed):
    values = ekf_floor.problem()
    values[changed] = values[changed] * (1 + 1e-9)
    with pytest.raises(AssertionError, match="differs from FilterPy's"):
        ekf_floor.check_floor(lib, values)


def test_a_step_is_timed(lib):
    seconds = ekf_floor.c_step(lib, filters=20, steps=20, rounds=2)
    assert 0 < seconds < 1e-3
