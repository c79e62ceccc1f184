"""Simulated calibration surveys (``sblsim calibrate box-in|CONFIG.toml``): the simulation against independent
computations, the solver against the truth and the bound, the replicates' table, the survey error an LBL design
takes, and the refusals."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from sblsim.models.calibration import boxin, crb
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.surveys.log import read_survey_log
from sblsim.orchestrator.surveys.simulate import (
    REPLICATE_COLUMNS,
    load_simulated,
    replicate,
    run_simulated,
    solve_replicate,
)

NOISE_FREE = ["platform.gps_sigma=0", "platform.imu_sigma_deg=0", "survey.turnaround_jitter_s=0",
              "survey.twtt_sigma_s=0"]


@pytest.mark.parametrize("pattern", ["circle", "box", "figure-eight"])
def test_a_noise_free_survey_recovers_the_truth(pattern):
    sim = load_simulated("box-in", NOISE_FREE + [f"survey.pattern={pattern}"])
    outcome = solve_replicate(sim, 0)
    s = outcome.simulated
    assert np.linalg.norm(s.truth - s.apriori) > 1.0  # the solver had to move from the a-priori position
    error = np.array([outcome.row[k] for k in ("e_n_m", "e_e_m", "e_u_m")])
    assert np.max(np.abs(error)) < 1e-6, error


def test_the_simulated_replies_are_the_two_legs_of_a_moving_transducer():
    sim = load_simulated("box-in", NOISE_FREE)
    s = boxin.simulate(sim.survey, sim.platform, 3)
    c, x = sim.survey["sound_speed_mps"], s.truth[0]
    legs = np.linalg.norm(s.true.tx - x, axis=1) + np.linalg.norm(s.true.rx - x, axis=1)
    np.testing.assert_allclose(c * s.measured.twtt, legs, rtol=0, atol=1e-9)
    # the receive time: transmit + both legs + the turnaround (POSIX times in float64 resolve 0.24 us)
    np.testing.assert_allclose(s.t_rx - s.t_tx, legs / c + sim.survey["turnaround_s"], rtol=0, atol=5e-7)
    # the transducer moved between transmit and receive: by the speed times the time between
    moved = np.linalg.norm(s.true.rx - s.true.tx, axis=1)
    np.testing.assert_allclose(moved, sim.survey["speed_mps"] * (s.t_rx - s.t_tx), rtol=1e-3)
    # the antenna on the circle, the transducer the lever arm (1 m) below it
    r = np.hypot(s.true.tx[:, 0], s.true.tx[:, 1])
    np.testing.assert_allclose(r, sim.survey["radius_m"], rtol=1e-6)
    np.testing.assert_allclose(s.true.tx[:, 2], -sim.platform["transducer_depth"], atol=1e-12)


def test_the_errors_follow_the_platform_model():
    """GNSS Gauss-Markov variance and correlation, the attitude noise through the lever arm: against theory."""
    rng = np.random.default_rng(5)
    t = np.cumsum(np.full(20000, 2.0))
    e = boxin.gnss_errors(t, 0.3, "gauss-markov", 20.0, rng)
    assert abs(np.std(e) / 0.3 - 1) < 0.05
    lag = np.mean(e[1:, 0] * e[:-1, 0]) / np.mean(e[:, 0] ** 2)
    assert abs(lag - math.exp(-2.0 / 20.0)) < 0.02
    white = boxin.gnss_errors(t, 0.3, "white", 20.0, rng)
    assert abs(np.mean(white[1:, 0] * white[:-1, 0])) / 0.09 < 0.03
    # a vertical arm h: roll and pitch move it by h*sigma in East and North whatever the heading, not Up
    angles = np.column_stack((np.zeros(4), np.zeros(4), np.radians([0.0, 30.0, 90.0, 200.0])))
    sd = boxin.lever_sigma(angles, np.array([0.0, 0.0, 2.0]), math.radians(1.0))
    np.testing.assert_allclose(sd[:, :2], 2.0 * math.radians(1.0), rtol=1e-12)
    np.testing.assert_allclose(sd[:, 2], 0.0, atol=1e-15)
    # the lever arm hangs below the antenna (ENU Up -h), a roll to starboard swings it to port
    turned = boxin.lever_enu(np.array([[math.radians(10.0), 0.0, 0.0]]), np.array([0.0, 0.0, 2.0]))
    np.testing.assert_allclose(turned[0], [-2.0 * math.sin(math.radians(10.0)), 0.0,
                                           -2.0 * math.cos(math.radians(10.0))], atol=1e-12)


def test_the_bound_is_the_inverse_information_of_the_two_legs():
    """crb against a finite-difference Jacobian of the two-leg ranges and the line-of-sight variances."""
    sim = load_simulated("box-in", ["survey.duration_s=300"])
    s = boxin.simulate(sim.survey, sim.platform, 0)
    x = s.truth[0]

    def ranges(point):
        return np.linalg.norm(s.true.tx - point, axis=1) + np.linalg.norm(s.true.rx - point, axis=1)

    h = 1e-2
    jac = np.column_stack([(ranges(x + h * d) - ranges(x - h * d)) / (2 * h) for d in np.eye(3)])
    u_tx = (s.true.tx - x) / np.linalg.norm(s.true.tx - x, axis=1)[:, None]
    u_rx = (s.true.rx - x) / np.linalg.norm(s.true.rx - x, axis=1)[:, None]
    var = (np.sum((u_tx * s.true.tx_sigma) ** 2, axis=1) + np.sum((u_rx * s.true.rx_sigma) ** 2, axis=1)
           + (s.sound_speed * s.twtt_sigma) ** 2)
    expected = np.linalg.inv(jac.T @ (jac / var[:, None]))
    np.testing.assert_allclose(crb(s.true, s.truth, s.sound_speed, twtt_sigma=s.twtt_sigma), expected, rtol=1e-6)


@pytest.fixture(scope="module")
def two_hundred():
    return run_simulated(load_simulated("box-in"), 200)


@pytest.mark.slow
def test_200_replicates_meet_the_bound_and_are_consistent(two_hundred):
    _, table = two_hundred
    assert list(table.columns) == list(REPLICATE_COLUMNS) and len(table) == 200
    rms_h = math.sqrt(np.mean(table["e_n_m"] ** 2 + table["e_e_m"] ** 2))
    bound = math.sqrt(np.mean(table["pcrb_h_m"] ** 2))
    assert abs(rms_h / bound - 1.0) < 0.15, (rms_h, bound)
    assert 1.5 <= table["nees"].mean() <= 4.5
    # a survey with ten times the GNSS error: the errors and the bound both grow (the bound is not a constant)
    noisy = run_simulated(load_simulated("box-in", ["platform.gps_sigma=1.0"]), 40)[1]
    assert noisy["pcrb_h_m"].mean() > 5 * table["pcrb_h_m"].mean()
    assert math.sqrt(np.mean(noisy["e_n_m"] ** 2 + noisy["e_e_m"] ** 2)) > 5 * rms_h


@pytest.mark.slow
def test_a_wrong_sound_speed_biases_the_depth_not_the_bound(two_hundred):
    _, table = two_hundred
    biased = run_simulated(load_simulated("box-in", ["survey.sound_speed_error_mps=3"]), 20)[1]
    # a faster assumed speed makes every range longer: the transponder comes out deeper, by far more than its RMS
    assert biased["e_u_m"].mean() < -10 * math.sqrt(np.mean(table["e_u_m"] ** 2))
    np.testing.assert_allclose(biased["pcrb_h_m"], table["pcrb_h_m"][:20], rtol=1e-12)


def test_a_wrong_sound_speed_puts_the_depth_where_the_documented_rule_says():
    """docs/calibration.md: every range (1 + eps) long, the GNSS holding the horizontal distances R, so the depth D
    takes the whole excess of each slant range: dD = eps (R^2 + D^2) / D (1.2 m for the box-in's circle, not the
    0.6 m of eps D)."""
    sim = load_simulated("box-in", NOISE_FREE + ["survey.sound_speed_error_mps=3"])
    outcome = solve_replicate(sim, 0)
    s = outcome.simulated
    eps = 3.0 / sim.survey["sound_speed_mps"]
    # the geometry of the replies, from the true transducer positions and the true transponder
    d = s.truth[0] - np.vstack([s.true.tx, s.true.rx])
    R2, D = np.mean(d[:, 0] ** 2 + d[:, 1] ** 2), -np.mean(d[:, 2])
    rule = eps * (R2 + D**2) / D
    assert rule == pytest.approx(1.2, abs=0.01)
    assert -outcome.row["e_u_m"] == pytest.approx(rule, rel=0.01), (outcome.row, rule)
    assert abs(outcome.row["e_n_m"]) < 0.02 * rule and abs(outcome.row["e_e_m"]) < 0.02 * rule


@pytest.mark.slow
def test_the_survey_sigma_passed_on_is_the_replicates_rms(two_hundred):
    """One calibration's own sigma (what `sblsim calibrate box-in` passes on without replicates) is the RMS
    error per axis over replicates, within its sampling error."""
    result, table = two_hundred
    single = load_simulated("box-in")
    one, _ = run_simulated(single)
    rms_axis = math.sqrt(np.mean(table["e_n_m"] ** 2 + table["e_e_m"] ** 2 + table["e_u_m"] ** 2) / 3)
    assert abs(one.solution["survey_sigma_m"] / rms_axis - 1) < 0.15, (one.solution["survey_sigma_m"], rms_axis)
    assert result.solution["survey_sigma_m"] == pytest.approx(rms_axis, rel=1e-12)
    assert result.solution["lbl_set"] == f"platform.survey_sigma={rms_axis:.4g}"


def test_replicates_are_reproducible_and_differ():
    sim = load_simulated("box-in", ["survey.duration_s=200"])
    a = run_simulated(sim, 3)[1]
    b = run_simulated(load_simulated("box-in", ["survey.duration_s=200"]), 3)[1]
    pd.testing.assert_frame_equal(a, b)
    assert a["e_n_m"].nunique() == 3
    other = run_simulated(load_simulated("box-in", ["survey.duration_s=200", "survey.seed=2"]), 3)[1]
    assert not np.allclose(a["e_n_m"], other["e_n_m"])


@pytest.mark.slow
def test_the_command_writes_the_replicates_and_the_log(tmp_path, capsys):
    config = tmp_path / "mine.toml"
    config.write_text('[survey]\npattern = "box"\nduration_s = 400.0\n[platform]\ngps_sigma = 0.05\n')
    assert main(["calibrate", str(config), "--replicates", "5", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    table = pd.read_parquet(tmp_path / "o" / "replicates.parquet")
    assert list(table.columns) == list(REPLICATE_COLUMNS) and list(table["replicate"]) == [0, 1, 2, 3, 4]
    solution = json.loads((tmp_path / "o" / "solution.json").read_text())
    assert solution["simulation"]["survey"]["pattern"] == "box"
    assert solution["simulation"]["platform"]["gps_sigma"] == 0.05
    assert solution["errors"][0]["e_n_m"] == pytest.approx(table["e_n_m"][0], abs=1e-15)
    t, truth = solution["transponders"][0], solution["truth"][0]
    assert t["n_m"] + t["apriori_n_m"] - truth["n_m"] == pytest.approx(table["e_n_m"][0], abs=1e-12)
    assert f"--set {solution['lbl_set']}" in out
    # the simulated log reads back as a log, replicate 0's
    log = read_survey_log(tmp_path / "o" / "survey_log.csv")
    sim = load_simulated(str(config))
    np.testing.assert_allclose(log.frame["twtt_s"], replicate(sim, 0)[0].log.frame["twtt_s"], rtol=1e-15)


@pytest.mark.parametrize("argv,message", [
    (["--set", "survey.radius_m=0"], "survey.radius_m: 0.0 is outside the allowed range [1, 20000] m"),
    (["--set", "survey.pattern=spiral"], "survey.pattern: 'spiral' is not allowed; one of circle, box, figure-eight"),
    (["--set", "survey.colour=1"], "survey.colour: unknown key"),
    (["--set", "platform.gps_model=pink"], "platform.gps_model: 'pink' is not allowed"),
    (["--set", "platform.imu_sigma_deg=-1"], "platform.imu_sigma_deg: -1.0 is outside the allowed range [0, 180] deg"),
    (["--set", "survey.ping_period_s=true"], "survey.ping_period_s: expected a number"),
    (["--set", "solver.sound_speed_mps=1500"], "solver.sound_speed_mps: a simulated survey's solver takes"),
    (["--set", "acoustics.sound_speed=1500"], "'acoustics.sound_speed' is not a key of a simulated survey"),
    (["--replicates", "0"], "--replicates: 0 is outside the allowed range [1, 100000]"),
    (["--format", "xie"], "--format: a simulated survey has no log format"),
])
def test_bad_settings_are_refused_in_one_line(tmp_path, capsys, argv, message):
    assert main(["calibrate", "box-in", "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("text,message", [
    ("[survey\n", "is not valid TOML"),
    ("[vessel]\nspeed = 1\n", "vessel: unknown table of a simulated survey"),
    ("survey = 3\n", "survey: expected a table"),
    ("[survey]\nduration_s = 1e9\n", "survey.duration_s: 1000000000.0 is outside the allowed range [10, 86400] s"),
    (b"[survey]\ntitle = \"\xff\"\n", "is not valid TOML"),
])
def test_bad_config_files_are_refused_in_one_line(tmp_path, capsys, text, message):
    config = tmp_path / "bad.toml"
    if isinstance(text, bytes):
        config.write_bytes(text)
    else:
        config.write_text(text)
    assert main(["calibrate", str(config), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


def test_a_folder_a_missing_file_and_replicates_of_a_log_are_refused(tmp_path, capsys):
    (tmp_path / "d.toml").mkdir()
    assert main(["calibrate", str(tmp_path / "d.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "is not a regular file" in capsys.readouterr().err
    assert main(["calibrate", str(tmp_path / "none.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["calibrate", "xie-2021-07-23", "--replicates", "3", "--out", str(tmp_path / "o")]) == 2
    assert "--replicates: only a simulated survey" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv,message", [
    # a noise-free circle at one radius: the speed's variance comes out negative (a numerically singular normal
    # matrix), which once printed numpy's warning of a square root before the refusal
    ([*NOISE_FREE, "survey.depth_m=3000", "survey.radius_m=30", "survey.duration_s=600"],
     "solve_sound_speed: the replies of the log do not determine the sound speed"),
    # a box of 1 m: Gauss-Newton diverges (its legs overflowed, numpy warned twice) before the refusal
    (["platform.gps_sigma=0", "platform.imu_sigma_deg=0", "survey.twtt_sigma_s=0", "survey.pattern=box",
      "survey.radius_m=1", "survey.sound_speed_error_mps=20", "survey.duration_s=600", "solver.rigid=true"],
     "the log: the replies do not determine the unknowns"),
])
def test_an_undetermined_sound_speed_is_refused_in_one_line_without_numpy_warnings(tmp_path, capsys, argv, message):
    import warnings

    items = [a for item in [*argv, "solver.solve_sound_speed=true"] for a in ("--set", item)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["calibrate", "box-in", "--out", str(tmp_path / "o"), *items]) == 2
    assert [str(w.message) for w in caught] == []
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith(f"sblsim: error: {message}"), err
    assert not (tmp_path / "o").exists()
