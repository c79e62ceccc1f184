"""``receiver.latency``: the diver sees the receiver's outputs of L = latency / T steps ago.

The orchestrator delays the recorded receiver outputs after a run (``run``, ``run_batch``, campaigns, both
engines); the metrics come from the delayed outputs. A latency that is not a whole number of sampling times
or lies outside [0, 60] s stops with one line, the receiver never receives the key, and ``ssp export``
refuses a latency above 0. The runs are short (5 s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.fmus.build import fmu_path
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.campaign import run_campaign
from sblsim.orchestrator.campaign.plan import batch_key
from sblsim.orchestrator.campaign.study import load_study
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import ConfigError, load_config, section_variables
from sblsim.orchestrator.cosim.metrics import RUN_METRICS, nees
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import apply_latency, run, run_batch, with_replicates
from sblsim.orchestrator.cosim.ssp import SspError, export_ssp

SHORT = ["simulation.duration=5", "acoustics.loss_pct=20", "acoustics.outlier_pct=5"]
#: Every recorded output of the receiver a diver sees, in the time series (its slot diagnostics nis and gated
#: are not delayed).
RECEIVER_COLUMNS = ["est_x", "est_y", "est_z", "est_vx", "est_vy", "est_vz", "est_valid", "instr_x", "instr_y",
                    "instr_z", "instr_valid", "pos_std", "cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz"]
STEPS = 7  # the latency in sampling times (T = 0.1 s)
#: A user's receiver model (``model:PATH.py``): the example of docs/extending.md.
EXAMPLE_MODEL = Path(__file__).parents[2] / "docs" / "examples" / "constant_position.py"


def config(latency: float = 0.0, extra: tuple[str, ...] = ()) -> dict:
    return load_config("random", [*SHORT, *extra, f"receiver.latency={latency}"], seed=4)


@pytest.fixture(scope="module")
def pair():
    """The same two replicates without and with a latency of STEPS sampling times."""
    return (run(config(), replicates=[0, 1]), run(config(STEPS * 0.1), replicates=[0, 1]))


def by_replicate(result, replicate: int) -> pd.DataFrame:
    series = result.timeseries
    return series[series["replicate"] == replicate].reset_index(drop=True)


def test_the_key_is_in_every_receivers_section_with_unit_range_and_default():
    for receiver in ("ekf", "ekf-seq", "ukf", "lsq"):
        (latency,) = [v for v in section_variables("receiver", receiver) if v.name == "latency"]
        assert (latency.unit, latency.min, latency.max, latency.start, latency.scope) == ("s", 0.0, 60.0, 0.0,
                                                                                          "config")
        assert latency.description
        assert load_config("semicircle", [f"receiver={receiver}"])["receiver"]["latency"] == 0.0
    assert make_plan(config(STEPS * 0.1)).latency_steps == STEPS


def test_the_estimate_at_step_k_is_the_one_of_step_k_minus_L(pair):
    plain, delayed = pair
    assert plain.steps == delayed.steps == 50
    for replicate in (0, 1):
        a, b = by_replicate(plain, replicate), by_replicate(delayed, replicate)
        for column in RECEIVER_COLUMNS:
            x, y = a[column].to_numpy(), b[column].to_numpy()
            np.testing.assert_array_equal(y[STEPS:], x[:-STEPS], err_msg=column)
            np.testing.assert_array_equal(y[:STEPS], np.repeat(x[:1], STEPS), err_msg=column)  # the first row
        assert a["est_x"].nunique() > 10  # the estimate moves: the shift is seen
        # the truth, the channel and the platform are not delayed
        others = [c for c in a.columns if c not in RECEIVER_COLUMNS and not c.startswith(("e_", "instr_e_"))]
        pd.testing.assert_frame_equal(a[others], b[others])


def test_e_tot_mean_and_nees_are_computed_from_the_delayed_estimates(pair):
    plain, delayed = pair
    for replicate in (0, 1):
        a = by_replicate(plain, replicate)
        source = np.maximum(np.arange(len(a)) - STEPS, 0)  # independent of apply_latency
        truth = a[["true_x", "true_y", "true_z"]].to_numpy()
        est = a[["est_x", "est_y", "est_z"]].to_numpy()[source]
        cov = a[[f"cov_{ab}" for ab in ("xx", "xy", "xz", "yy", "yz", "zz")]].to_numpy()[source]
        row = delayed.metrics[delayed.metrics["replicate"] == replicate].iloc[0]
        e_tot = np.sqrt(np.sum((truth - est) ** 2, axis=1))
        assert np.isnan(e_tot[0])  # the estimate before the first fix (none), held as the first row is
        np.testing.assert_allclose(row["e_tot_mean"], np.nanmean(e_tot), rtol=1e-12)
        np.testing.assert_allclose(row["e_tot_rms"], np.sqrt(np.nanmean(e_tot ** 2)), rtol=1e-12)
        epsilon = nees(truth - est, cov)
        np.testing.assert_allclose(row["nees_mean"], np.nanmean(epsilon), rtol=1e-12)
        np.testing.assert_allclose(by_replicate(delayed, replicate)["e_tot"], e_tot, rtol=0, atol=1e-12)
        plain_row = plain.metrics[plain.metrics["replicate"] == replicate].iloc[0]
        assert row["e_tot_mean"] > plain_row["e_tot_mean"]  # the diver moves while the receiver computes


def test_apply_latency_shifts_only_the_receiver_and_holds_the_first_row():
    rec = {"time": np.arange(1.0, 5.0), "receiver.est_x": np.arange(8.0).reshape(4, 2),
           "target.pos_x": np.arange(8.0).reshape(4, 2)}
    assert apply_latency(rec, 0) is rec
    out = apply_latency(rec, 1)
    np.testing.assert_array_equal(out["receiver.est_x"], [[0, 1], [0, 1], [2, 3], [4, 5]])
    assert out["target.pos_x"] is rec["target.pos_x"] and out["time"] is rec["time"]
    np.testing.assert_array_equal(rec["receiver.est_x"], np.arange(8.0).reshape(4, 2))  # the input is kept
    np.testing.assert_array_equal(apply_latency(rec, 10)["receiver.est_x"], np.tile([[0, 1]], (4, 1)))


@pytest.mark.parametrize("value, message", [
    ("0.25", r"^receiver\.latency: 0\.25 s is not a whole number of sampling times \(T = 0\.1 s\); "
             r"give 0\.2 or 0\.3 s$"),
    ("61", r"^receiver\.latency: 61\.0 is outside the allowed range \[0, 60\] s$"),
    ("-0.1", r"^receiver\.latency: -0\.1 is outside the allowed range \[0, 60\] s$"),
    ("59.95", r"^receiver\.latency: 59\.95 s is not a whole number .*; give 59\.9 or 60 s$"),
])
def test_a_bad_latency_stops_with_one_line_naming_the_key(value, message):
    with pytest.raises(ConfigError, match=message):
        load_config("semicircle", [f"receiver.latency={value}"])


def test_with_an_ekf_rate_ratio_the_latency_is_still_a_whole_number_of_sampling_times():
    """The record holds one row per T: a latency of one receiver step T / 2 cannot be shown, one T can."""
    with pytest.raises(ConfigError, match=r"^receiver\.latency: 0\.05 s .*once per T, not per T / 2\); "
                                          r"give 0 or 0\.1 s$"):
        load_config("semicircle", ["simulation.ekf_rate_ratio=2", "receiver.latency=0.05"])
    plan = make_plan(load_config("semicircle", ["simulation.ekf_rate_ratio=2", "receiver.latency=0.1"]))
    assert plan.latency_steps == 1


def test_the_command_line_says_the_same_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "semicircle", "--set", "receiver.latency=0.25", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sblsim: error: receiver.latency:") and "\n" not in err and not out.exists()


def test_the_receiver_component_never_receives_the_key():
    for receiver in ("ekf", "ekf-seq", "ukf", "lsq", f"model:{EXAMPLE_MODEL}"):
        cfg = load_config("semicircle", [f"receiver={receiver}", "receiver.latency=1"])
        assert cfg["receiver"]["latency"] == 1.0
        assert "latency" not in make_plan(cfg).component_parameters("receiver")
        assert "latency" not in make_plan(cfg).component_parameters("receiver", frozenset(cfg["receiver"]))


def test_a_users_receiver_fmu_gets_the_latency_from_the_orchestrator(fmu_dir):
    """sblsim's lsq FMU as a user's ``fmu:PATH``: the key is accepted, not passed, and applied."""
    user = f"fmu:{fmu_path(fmu_dir, 'receiver_lsq')}"
    cfg = load_config("random", [*SHORT, f"receiver={user}", "receiver.latency=0.3"], seed=4)
    assert "latency" not in make_plan(cfg).component_parameters("receiver")
    builtin = load_config("random", [*SHORT, "receiver=lsq", "receiver.latency=0.3"], seed=4)
    a, b = run(cfg).timeseries, run(builtin).timeseries
    np.testing.assert_allclose(a[RECEIVER_COLUMNS].to_numpy(float), b[RECEIVER_COLUMNS].to_numpy(float), rtol=0,
                               atol=1e-9)
    undelayed = run(load_config("random", [*SHORT, f"receiver={user}"], seed=4)).timeseries
    np.testing.assert_array_equal(a["est_x"].to_numpy()[3:], undelayed["est_x"].to_numpy()[:-3])


def test_both_engines_give_the_same_delayed_numbers(pair, fmu_dir):
    _, local = pair
    fmu = run(config(STEPS * 0.1), "fmu", replicates=[0, 1], fmu_dir=fmu_dir)
    numbers = [c for c in local.timeseries.columns if local.timeseries[c].dtype.kind in "fiub"]
    np.testing.assert_allclose(fmu.timeseries[numbers].to_numpy(float), local.timeseries[numbers].to_numpy(float),
                               rtol=0, atol=1e-9, equal_nan=True)
    metrics = ["replicate", *RUN_METRICS]
    np.testing.assert_allclose(fmu.metrics[metrics].to_numpy(float), local.metrics[metrics].to_numpy(float),
                               rtol=0, atol=1e-9, equal_nan=True)


def test_run_batch_and_a_campaign_apply_it_too(pair, tmp_path):
    _, delayed = pair
    batch = run_batch(with_replicates(config(STEPS * 0.1), [0, 1]), timeseries=False)
    np.testing.assert_array_equal(batch.metrics[list(RUN_METRICS)].to_numpy(float),
                                  delayed.metrics[list(RUN_METRICS)].to_numpy(float))
    # runs of different latencies are not one batch: a campaign plans them apart, run_batch refuses them
    assert batch_key(config(0.0)) != batch_key(config(0.5))
    with pytest.raises(ModelError, match=r"^receiver\.latency: must be the same for every run of a batch"):
        run_batch([config(0.0), config(0.5)], timeseries=False)
    study = load_study({
        "study": {"name": "latency", "scenarios": ["random"], "replicates": 2, "seed": 4, "design": "full",
                  "set": SHORT},
        "factors": [{"name": "lag", "key": "receiver.latency", "low": 0.0, "high": STEPS * 0.1}]})
    runs = run_campaign(study, tmp_path / "c", workers=1, progress=False).runs.sort_values(["cell", "replicate"])
    for cell in range(study.cells):
        cfg = study.cell_config("random", cell)
        alone = run(cfg, replicates=[0, 1]).metrics
        got = runs[runs["cell"] == cell]
        np.testing.assert_array_equal(got[list(RUN_METRICS)].to_numpy(float),
                                      alone[list(RUN_METRICS)].to_numpy(float))
    assert set(runs["lag_value"]) == {0.0, STEPS * 0.1}


def test_ssp_export_refuses_a_latency(tmp_path, capsys):
    cfg = load_config("semicircle", ["receiver.latency=1"])
    with pytest.raises(SspError, match=r"^receiver\.latency: 1 s cannot be exported"):
        export_ssp(cfg, tmp_path / "x.ssp", tmp_path / "no-fmus")
    assert main(["ssp", "export", "semicircle", "--set", "receiver.latency=1", "--out", str(tmp_path / "y.ssp")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sblsim: error: receiver.latency:") and "\n" not in err
    assert not list(tmp_path.glob("*.ssp*"))


def test_the_slot_diagnostics_stay_with_their_slots(pair):
    """NIS and gate judge a slot, not what the diver sees: a latency changes neither them nor their statistics."""
    plain, delayed = pair
    np.testing.assert_array_equal(plain.timeseries["nis"], delayed.timeseries["nis"])
    for name in ("nis_mean", "gated_pct", "updates"):
        np.testing.assert_array_equal(plain.metrics[name], delayed.metrics[name], err_msg=name)
    assert (plain.metrics["e_tot_mean"] != delayed.metrics["e_tot_mean"]).all()
