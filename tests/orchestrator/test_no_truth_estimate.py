"""No receiver output is the truth: before its first fix a receiver has no estimate (NaN), and the metrics skip it.

* Every built-in receiver, on every designed positioning system, in a noisy run: no step's estimate equals the true
  position (the starting guess ``x0_*`` is tied to the diver's true start, so a receiver reporting it before its first
  fix reports the truth), and the steps before the first fix are NaN.
* A short static ``compare`` of ``lsq``: its RMS e_tot is the RMS over the steps with a fix only, computed here from
  the run's timeseries (the steps from the first multilateration fix on; lsq's estimate is its fix), not the
  RMS over every step with the pre-fix steps counted at zero error.
* The divergence flag does not take the steps before the first fix for a lost diver.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import sblsim
from sblsim.models import RECEIVER_MODELS

STATIC = {"target.trajectory": "file", "target.waypoints": "0 5 5 5; 100 5 5 5", "simulation.duration": 3.5}


def _estimate_and_truth(ts):
    return ts[["est_x", "est_y", "est_z"]].to_numpy(), ts[["true_x", "true_y", "true_z"]].to_numpy()


#: Every built-in receiver on every positioning system that takes it (an inverted LBL needs a state for the pinger's
#: emission epoch: ekf-seq and ukf only; the run refuses the others).
CASES = [(system, receiver) for system in ("sbl", "usbl", "lbl", "ilbl") for receiver in RECEIVER_MODELS
         if system != "ilbl" or receiver in ("ekf-seq", "ukf")]


@pytest.mark.parametrize(("system", "receiver"), CASES)
def test_no_estimate_of_a_noisy_run_is_the_truth(receiver, system):
    result = sblsim.run("semicircle", seed=3, set={**STATIC, "simulation.duration": 2.0, "platform.system": system,
                                                   "simulation.receiver": receiver})
    est, truth = _estimate_and_truth(result.timeseries)
    assert not np.any(np.all(est == truth, axis=1)), "a step whose estimate is the true position"
    assert not np.any(est == truth), "an axis of an estimate equal to the truth's"
    defined = np.isfinite(est).all(axis=1)
    assert defined.any() and not defined[0]  # no estimate at the start, one after the first fix
    first = int(np.argmax(defined))
    assert defined[first:].all()  # once fixed, always an estimate (no NaN after the first fix)
    assert not result.metrics["diverged"].any()


def test_the_short_static_compare_is_the_rms_over_fixed_steps_only():
    table = sblsim.compare("semicircle", receivers="lsq", set=STATIC, replicates=1, seed=5).table
    ts = sblsim.run("semicircle", seed=5, set={**STATIC, "simulation.receiver": "lsq"}).timeseries
    est, truth = _estimate_and_truth(ts)
    fixed = np.maximum.accumulate(ts["instr_valid"].to_numpy(bool))  # from lsq's first fix on
    assert 0 < fixed.sum() < len(fixed)
    error = np.sqrt(np.sum((truth - est) ** 2, axis=1))
    expected = math.sqrt(float(np.mean(error[fixed] ** 2)))
    got = float(table["rms_e_tot"].iloc[0])
    assert got == pytest.approx(expected, rel=1e-12, abs=0)
    counted_at_zero = math.sqrt(float(np.sum(error[fixed] ** 2)) / len(error))  # what the pre-fix truth gave
    assert abs(got - counted_at_zero) > 1e-3
