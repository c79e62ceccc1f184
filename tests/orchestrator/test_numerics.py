"""Numerics that cannot blow up silently, and outputs that cannot be lost.

* Every receiver at the smallest and largest allowed R (and P0) stays finite, its reported position
  covariance symmetric positive-definite, and the run is not flagged as diverged.
* A planted divergence (a receiver started 500 m off with a prior that trusts it) is flagged, in
  ``summary.json`` and on the command line.
* ``--force`` replaces an earlier run; the staging folders of a killed process are removed.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run

COV = ("cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz")


def covariances(ts) -> np.ndarray:
    c = {k: ts[k].to_numpy() for k in COV}
    return np.stack([np.stack([c["cov_xx"], c["cov_xy"], c["cov_xz"]], -1),
                     np.stack([c["cov_xy"], c["cov_yy"], c["cov_yz"]], -1),
                     np.stack([c["cov_xz"], c["cov_yz"], c["cov_zz"]], -1)], -2)


@pytest.mark.parametrize("receiver", ["ekf", "ekf-seq", "ukf", "lsq"])
@pytest.mark.parametrize("sigma", [1e-3, 1000.0])
def test_extreme_allowed_values_stay_finite_and_positive_definite(receiver, sigma):
    overrides = ["simulation.duration=30", "acoustics.loss_pct=20", "acoustics.outlier_pct=5", f"receiver={receiver}",
                 f"receiver.sigma_range={sigma}", f"receiver.sigma_depth={sigma}"]
    if receiver != "lsq":
        overrides += [f"receiver.p0_position={sigma}", f"receiver.p0_velocity={sigma}"]
    result = run(load_config("random", overrides, seed=3), replicates=[0, 1])
    ts = result.timeseries
    estimate = ts[[f"est_{a}" for a in ("x", "y", "z", "vx", "vy", "vz")]].to_numpy()
    for replicate in (0, 1):  # NaN before the first fix (no estimate), finite from it on
        own = estimate[ts["replicate"].to_numpy() == replicate]
        fixed = np.isfinite(own).all(axis=1)
        assert fixed.any() and fixed[np.argmax(fixed):].all() and np.isnan(own[~fixed]).all()
    P = covariances(ts)
    if receiver == "lsq":  # no covariance before its first fix
        P = P[ts["instr_valid"].to_numpy(bool)]
    assert len(P) > 100
    assert np.isfinite(P).all()
    assert np.all(np.linalg.eigvalsh(P) > 0), "a reported covariance is not positive-definite"
    assert not result.metrics["diverged"].any()


@pytest.mark.slow
def test_a_planted_divergence_is_flagged(tmp_path, capsys):
    args = ["run", "semicircle", "--set", "simulation.duration=30", "--set", "receiver.q_horizontal=0",
            "--set", "receiver.q_vertical=0", "--set", "receiver.p0_position=0.001", "--set", "receiver.x0_x=500"]
    assert main([*args, "--out", str(tmp_path / "bad")]) == 0
    err = capsys.readouterr().err
    assert "warning: the ekf receiver diverged" in err
    assert json.loads((tmp_path / "bad" / "summary.json").read_text())["diverged"] is True
    assert main([*args[:4], "--out", str(tmp_path / "good")]) == 0
    assert "diverged" not in capsys.readouterr().err
    summary = json.loads((tmp_path / "good" / "summary.json").read_text())
    assert summary["diverged"] is False


@pytest.mark.slow
def test_summary_json_is_strict_json(tmp_path):
    """A metric without a value (lsq at T = 1 s with every packet lost: no fix) is null, not NaN."""
    out = tmp_path / "run"
    assert main(["run", "semicircle", "--set", "simulation.duration=5", "--set", "acoustics.loss_pct=100",
                 "--out", str(out)]) == 0
    text = (out / "summary.json").read_text()
    assert "NaN" not in text
    summary = json.loads(text, parse_constant=lambda name: pytest.fail(f"non-standard JSON constant {name}"))
    assert summary["instr_e_tot_mean"] is None and summary["gated_pct"] is None


@pytest.mark.slow
def test_force_replaces_an_earlier_run_and_stale_staging_folders_are_removed(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["run", "semicircle", "--set", "simulation.duration=2", "--out", str(out)]
    assert main(args) == 0
    first = (out / "summary.json").read_text()
    assert main(args) == 2 and "add --force" in capsys.readouterr().err
    assert (out / "summary.json").read_text() == first
    dead = tmp_path / ".run.999999999.x1"  # a staging folder of a process that is gone
    alive = tmp_path / f".run.{os.getppid()}.x2"  # one of a process that still runs
    for folder in (dead, alive):
        folder.mkdir()
        (folder / "summary.json").write_text("half")
    assert main([*args[:-2], "--set", "simulation.duration=3", "--out", str(out), "--force"]) == 0
    assert json.loads((out / "summary.json").read_text())["steps"] == 30
    assert not dead.exists() and alive.exists()


@pytest.mark.slow
def test_a_receiver_that_never_made_a_fix_is_flagged(tmp_path, capsys):
    """Every packet lost: lsq has no estimate (never its starting guess); summary.json counts no update, its error
    metrics have no value and the CLI says so."""
    out = tmp_path / "lost"
    assert main(["run", "semicircle", "--set", "receiver=lsq", "--set", "simulation.duration=5",
                 "--set", "acoustics.loss_pct=100", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["updates"] == 0 and summary["fix_steps"] == 0
    assert summary["e_tot_rms"] is None and summary["diverged"] is False
    assert "sblsim: warning: the lsq receiver never made a fix" in err, err
    good = tmp_path / "good"
    assert main(["run", "semicircle", "--set", "receiver=lsq", "--set", "simulation.duration=5",
                 "--out", str(good)]) == 0
    assert "never made a fix" not in capsys.readouterr().err
    assert json.loads((good / "summary.json").read_text())["updates"] > 0


@pytest.mark.slow
def test_a_diver_beyond_the_geometry_is_flagged_not_diverged(tmp_path, capsys):
    """A diver 10 km from a 6 m array: the real accuracy there, not a divergence; flagged and warned. (Its ranges
    travel 6.7 s: a sampling time of 1 s holds them in flight.)"""
    out = tmp_path / "far"
    assert main(["run", "semicircle", "--set", "target.radius=10000", "--set", "simulation.duration=200",
                 "--set", "simulation.sampling_time=1", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["beyond_geometry"] is True and summary["diverged"] is False
    assert summary["max_distance"] == pytest.approx(10000.0)
    assert "sblsim: warning: the diver went 10000 m from the platform, 1667 times" in err, err
    near = tmp_path / "near"
    assert main(["run", "semicircle", "--set", "simulation.duration=20", "--out", str(near)]) == 0
    assert "warning" not in capsys.readouterr().err
    assert json.loads((near / "summary.json").read_text())["beyond_geometry"] is False
