"""The accuracy limit in runs, ``sblsim compare``, ``sblsim map``, and the receiver as a study factor."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from sblsim.models.fisher import horizontal_std
from sblsim.models.platform.geometry import lever_arms
from sblsim.orchestrator.analysis import compute
from sblsim.orchestrator.campaign import run_campaign
from sblsim.orchestrator.campaign.study import load_study
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run, run_batch, with_replicates
from sblsim.orchestrator.maps import accuracy_map, grid


@pytest.mark.parametrize("receiver", ["ekf", "ekf-seq", "ukf", "lsq"])
def test_no_receiver_beats_the_bound_on_trajectories_drawn_from_the_motion_model(receiver):
    """random-walk: E[MSE − PCRB²] ≥ 0 over trajectories; 40 runs, the mean difference not below −3 standard
    errors. The bound is tight for ekf-seq (its RMS within 15 % of the PCRB's)."""
    cfg = load_config("random-walk", [f"receiver={receiver}", "simulation.sampling_time=0.5",
                                      "simulation.duration=60"], seed=4)
    m = run_batch(with_replicates(cfg, range(40)), timeseries=False).metrics
    diff = m["e_tot_rms"] ** 2 - m["pcrb_rms"] ** 2
    assert diff.mean() > -3.0 * diff.std(ddof=1) / math.sqrt(len(diff))
    if receiver == "ekf-seq":
        ratio = math.sqrt((m["e_tot_rms"] ** 2).mean() / (m["pcrb_rms"] ** 2).mean())
        assert 0.85 < ratio < 1.15


def test_the_bound_of_a_run_follows_its_configuration():
    """A better sensor set lowers the bound; the bound does not depend on the receiver that ran."""
    base = ["simulation.duration=30"]
    runs = {rx: run(load_config("semicircle", base + [f"receiver={rx}"], seed=1)) for rx in ("ekf", "ekf-seq")}
    np.testing.assert_array_equal(runs["ekf"].timeseries["pcrb"], runs["ekf-seq"].timeseries["pcrb"])
    better = run(load_config("semicircle", base + ["platform.gps_sigma=0.01", "acoustics.sigma_range=0.02"], seed=1))
    assert better.metrics["pcrb_rms"][0] < runs["ekf"].metrics["pcrb_rms"][0]
    # past the prior's first second (which weighs on a 30 s RMS: the first packet arrives in the second step),
    # less than half of it
    settled = lambda r: r.timeseries["pcrb"][r.timeseries["time"] > 1.0].mean()  # noqa: E731
    assert settled(better) < 0.5 * settled(runs["ekf"])


def test_compare_tabulates_each_receiver_as_its_own_runs_do(tmp_path, capsys):
    out = tmp_path / "cmp"
    code = main(["compare", "semicircle", "--receivers", "ekf,ekf-seq,lsq", "--replicates", "3", "--seed", "2",
                 "--set", "simulation.duration=20", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    table = pd.read_csv(out / "compare.csv")
    assert table["receiver"].tolist() == ["ekf", "ekf-seq", "lsq"]
    assert (out / "compare.png").stat().st_size > 10_000 and "| ekf-seq |" in (out / "compare.md").read_text()
    for row in table.itertuples():
        cfg = load_config("semicircle", ["simulation.duration=20", f"receiver={row.receiver}"], seed=2)
        m = run(cfg, replicates=range(3)).metrics  # each replicate on its own
        assert row.rms_e_tot == pytest.approx(np.sqrt(np.mean(m["e_tot_rms"] ** 2)), rel=1e-12)
        assert row.rms_e_tot_sd == pytest.approx(np.std(m["e_tot_rms"], ddof=1), rel=1e-12)
        assert row.nees == pytest.approx(m["nees_mean"].mean(), rel=1e-12)
        assert row.nees_sd == pytest.approx(np.std(m["nees_mean"], ddof=1), rel=1e-12)
        assert row.ratio_to_pcrb == pytest.approx(row.rms_e_tot / np.sqrt(np.mean(m["pcrb_rms"] ** 2)), rel=1e-12)
        assert row.us_per_step > 0
    printed = capsys.readouterr().out
    assert "RMS / PCRB" in printed and "| lsq |" in printed
    assert "seed 2" in printed.splitlines()[0]


@pytest.mark.parametrize("args, message", [
    (["--receivers", "ekf,kalman"], "--receivers: 'kalman' is not allowed"),
    (["--receivers", "ekf,ekf"], "--receivers: 'ekf,ekf' names a receiver twice"),
    (["--replicates", "0"], "--replicates: 0 is outside the allowed range [1, 100000]"),
    (["--set", "receiver.alpha=0.5"], "receiver.alpha: not a parameter of the ekf receiver"),
])
def test_compare_refuses_bad_input_with_one_line(args, message, tmp_path, capsys):
    code = main(["compare", "semicircle", *args, "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err and not (tmp_path / "c").exists()


def test_map_writes_the_fisher_map_of_each_compared_value(tmp_path, capsys):
    out = tmp_path / "map"
    code = main(["map", "semicircle", "--extent", "20", "--step", "2", "--levels", "0.5,1",
                 "--compare", "platform.baseline=1,3", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    frame = pd.read_csv(out / "map.csv")
    assert sorted(frame["platform.baseline"].unique()) == [1, 3] and len(frame) == 2 * 21 * 21
    assert (out / "map.png").stat().st_size > 20_000
    for value, part in frame.groupby("platform.baseline"):
        cfg = load_config("semicircle", [f"platform.baseline={value}"])
        arms = lever_arms(cfg["platform"])
        p = make_plan(cfg).bound
        row = part.sample(1, random_state=0).iloc[0]
        expected = horizontal_std(np.array([[row.north, row.east, row.depth]]), arms, arms, p["noise_variance"],
                                  p["attitude_variance"], p["depth_variance"])[0]
        assert row.drms == pytest.approx(expected, rel=1e-12) and row.depth == cfg["target"]["depth"]
    # a longer baseline gives a better fix everywhere on the map
    wide = frame.pivot_table(index=["east", "north"], columns="platform.baseline", values="drms")
    assert (wide[3] < wide[1]).all()
    assert "within 1 m" in capsys.readouterr().out


def test_map_accuracy_grows_with_distance_and_is_symmetric_for_the_cross():
    cfg = load_config("semicircle")
    east, north = grid(30.0, 1.0)
    m = accuracy_map(cfg, east, north)
    centre = len(east) // 2
    assert m[centre, centre + 10] < m[centre, centre + 20] < m[centre, -1]
    np.testing.assert_allclose(m, m[:, ::-1], rtol=1e-9)  # East-West mirror
    np.testing.assert_allclose(m, m.T, rtol=1e-9)  # the cross at heading 0 is symmetric about the diagonal


def test_map_of_a_trajectory_file_is_drawn_at_the_files_depth(tmp_path, capsys):
    """target.depth does not apply to a trajectory file: the map takes its waypoints' median depth (8 m), and a
    deeper diver is farther from the beacons, so its fix below the platform is worse than at 5 m."""
    (tmp_path / "path.csv").write_text("time,north,east,down\n0,5,0,8\n30,5,10,8\n60,5,20,8\n")
    overrides = ["target.trajectory=file", f"target.trajectory_file={tmp_path / 'path.csv'}"]
    code = main(["map", "semicircle", *(a for o in overrides for a in ("--set", o)), "--extent", "10", "--step",
                 "1", "--out", str(tmp_path / "m")])
    assert code == 0, capsys.readouterr().err
    assert "maps at 8 m depth (the median depth" in capsys.readouterr().out
    frame = pd.read_csv(tmp_path / "m" / "map.csv")
    assert set(frame["depth"]) == {8.0}
    cfg = load_config("semicircle", overrides)
    east, north = grid(10.0, 1.0)
    np.testing.assert_allclose(frame["drms"].to_numpy(), accuracy_map(cfg, east, north, depth=8.0).ravel())
    assert not np.allclose(accuracy_map(cfg, east, north, depth=5.0), accuracy_map(cfg, east, north, depth=8.0))
    code = main(["map", "semicircle", *(a for o in overrides for a in ("--set", o)), "--extent", "10", "--step",
                 "1", "--depth", "3", "--out", str(tmp_path / "m3")])
    assert code == 0 and set(pd.read_csv(tmp_path / "m3" / "map.csv")["depth"]) == {3.0}


@pytest.mark.parametrize("args, message", [
    (["--depth", "-1"], "--depth: -1.0 is outside the allowed range [0, 11000] m"),
    (["--extent", "0"], "--extent: 0.0 m is outside the allowed range (0, 100000]"),
    (["--step", "50"], "--step: 50.0 m is outside the allowed range (0, extent = 30]"),
    (["--step", "0.01"], "--step: 0.01 m gives"),
    (["--levels", "1,x"], "--levels: expected comma-separated accuracies"),
    (["--levels", "-1"], "--levels: expected positive accuracies"),
    (["--compare", "baseline=1,2"], "--compare: expected SECTION.KEY=V1,V2"),
    (["--compare", "platform.baseline=1,-2"], "platform.baseline"),
])
def test_map_refuses_bad_input_with_one_line(args, message, tmp_path, capsys):
    code = main(["map", "semicircle", *args, "--out", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err and not (tmp_path / "m").exists()


STUDY = {"study": {"name": "rx", "scenarios": ["semicircle"], "replicates": 3, "seed": 5,
                   "set": ["simulation.duration=10"]},
         "factors": [{"name": "rx", "key": "simulation.receiver", "low": "ekf", "high": "ekf-seq"},
                     {"name": "T", "key": "simulation.sampling_time", "low": 0.1, "high": 1.0}]}


@pytest.mark.slow
def test_a_campaign_with_the_receiver_as_a_factor_runs_and_analyses(tmp_path):
    study = load_study(STUDY)
    out = tmp_path / "camp"
    result = run_campaign(study, out, workers=1, progress=False)
    runs = result.runs
    assert (runs["receiver"] == runs["rx_value"]).all()  # the receiver that ran is the factor's level
    assert sorted(runs["rx_value"].unique()) == ["ekf", "ekf-seq"]
    assert set(runs.loc[runs["rx"] == 1, "rx_value"]) == {"ekf-seq"}
    # each row is the run of its own configuration
    row = runs[(runs["rx"] == 1) & (runs["T"] == 1)].iloc[1]
    cfg = load_config("semicircle", ["simulation.duration=10", "receiver=ekf-seq", "simulation.sampling_time=1.0",
                                     f"run.cell={int(row['cell'])}", f"run.replicate={int(row['replicate'])}"], seed=5)
    single = run(cfg).metrics.iloc[0]
    for name in ("e_tot_rms", "nees_mean", "pcrb_rms"):
        assert single[name] == row[name]
    analysis = compute(out)
    fit = analysis.fits["semicircle"]
    assert {"rx", "T", "rx:T"} <= set(fit.effects["term"])
    factor = next(f for f in analysis.study.factors if f.name == "rx")
    assert (factor.low, factor.high) == ("ekf", "ekf-seq")
    estimators = set(analysis.tables["estimator"])
    assert "ekf+ekf-seq" in estimators and "instrumentation" in estimators
    from sblsim.orchestrator.analysis import write

    written = write(analysis, tmp_path / "report")
    report = (written / "report.md").read_text()
    assert "ekf-seq" in report and (written / "figures" / "semicircle_main_effects.png").is_file()


def test_a_factor_on_a_receiver_key_is_checked_against_each_receiver_of_the_study():
    study = json.loads(json.dumps(STUDY))
    study["factors"].append({"name": "alpha", "key": "receiver.alpha", "low": 0.5, "high": 1.0})
    from sblsim.orchestrator.campaign.errors import StudyError

    with pytest.raises(StudyError, match="factors.alpha.key: 'receiver.alpha' is not a parameter of the ekf receiver"):
        load_study(study)
    study["factors"][0]["low"] = "ukf"  # ukf vs ekf-seq: ekf-seq has no alpha either
    with pytest.raises(StudyError, match="not a parameter of the ekf-seq receiver"):
        load_study(study)
    study["factors"][0]["high"] = "ekf"
    study["factors"][0]["low"] = "kalman"
    with pytest.raises(Exception, match="factors.rx.low: 'kalman' is not allowed"):
        load_study(study)
    study["factors"][0].update(low="ekf", high="ukf", name="receiver")
    study["factors"].pop()
    with pytest.raises(StudyError, match="factors.0..name: 'receiver' is a column of the results"):
        load_study(study)
