"""The tracker's inputs beyond the times of arrival (readers/toa_matrix.py, tracks/track.py): a ``depth_m`` column of
the tag's depth readings, the receivers' ``sigma_m`` survey errors, read against independent parses and carried to
the track; and their refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.receiver import toa_tracking as tt
from sblsim.orchestrator.readers.receivers_file import read_receivers
from sblsim.orchestrator.readers.toa_matrix import read_toa

R3 = np.array([[0.0, 0.0, -2.0], [200.0, 0.0, -15.0], [200.0, 150.0, -4.0], [0.0, 150.0, -20.0], [100.0, 75.0, -8.0],
               [60.0, 140.0, -3.0], [140.0, 20.0, -12.0], [30.0, 80.0, -6.0]])
NAMES = [f"R{k + 1}" for k in range(len(R3))]


def _files(tmp_path: Path, seed: int = 2, sigma: bool = True) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    """A simulated tag in 3-D (80 pings) with its depth readings (0.3 m noise) as a depth_m column, the receivers'
    file with z_m (and sigma_m, 0.5 m); the truth and the readings."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)
    rng = np.random.default_rng(seed)
    toa, truth, _ = tt.simulate_pings(R3, 80, s, rng, start=np.array([100.0, 75.0, -10.0]), speed=0.2,
                                      detection=0.6)
    depth = -truth[:, 2] + 0.3 * rng.normal(size=len(truth))
    depth[5] = np.nan
    table = pd.DataFrame(toa, columns=NAMES)
    table["depth_m"] = depth
    table.to_csv(tmp_path / "toa.csv", index=False, na_rep="NA", float_format="%.9f")
    receivers = pd.DataFrame({"name": NAMES, "x_m": R3[:, 0], "y_m": R3[:, 1], "z_m": R3[:, 2]})
    if sigma:
        receivers["sigma_m"] = 0.5
        receivers.loc[2, "sigma_m"] = np.nan
    receivers.to_csv(tmp_path / "receivers.csv", index=False)
    return tmp_path / "toa.csv", tmp_path / "receivers.csv", truth, depth


def test_the_depth_column_and_the_survey_errors_read_as_pandas_reads_them(tmp_path):
    toa_path, receivers_path, _, depth = _files(tmp_path)
    matrix = read_toa(toa_path)
    independent = pd.read_csv(toa_path)
    assert matrix.names == NAMES and np.allclose(matrix.depth, independent["depth_m"], equal_nan=True)
    assert np.allclose(matrix.toa, independent[NAMES].to_numpy(), equal_nan=True, rtol=0, atol=1e-9)
    receivers = read_receivers(receivers_path)
    assert np.allclose(receivers.sigma, pd.read_csv(receivers_path)["sigma_m"], equal_nan=True)
    assert receivers.names == NAMES and receivers.positions.shape == (8, 3)
    toml = tmp_path / "receivers.toml"
    toml.write_text('[[receiver]]\nname = "A"\nx_m = 0\ny_m = 0\nsigma_m = 0.2\n'
                    '[[receiver]]\nname = "B"\nx_m = 100\ny_m = 0\n')
    assert np.allclose(read_receivers(toml).sigma, [0.2, np.nan], equal_nan=True)


def test_a_tags_whole_sensitivity_is_never_made(tmp_path, monkeypatch):
    """A tag's sensitivity to the survey's errors ((pings, states, receivers × dim + 1) numbers: 0.1 GiB for a
    season's tag) is never made whole: the EKF's and the RTS smoother's consider terms come from it a block of pings at
    a time (``consider_terms_along``, smoothed), and the whole record's :func:`filter_sensitivity` is not called
    (fails on the code that made it whole and took the terms from it)."""
    from sblsim.models.tracking import filter_consider

    whole, along = [], []
    real_along = filter_consider.consider_terms_along

    def along_spy(*args, **kwargs):
        along.append(args[7] if len(args) > 7 else kwargs.get("smoothed", False))
        return real_along(*args, **kwargs)

    monkeypatch.setattr(filter_consider, "filter_sensitivity", lambda *a, **k: whole.append(1))
    monkeypatch.setattr(filter_consider, "consider_terms_along", along_spy)
    toa_path, receivers_path, _, _ = _files(tmp_path)
    result = sblsim.replay_toa(toa_path, receivers=receivers_path, sound_speed=1480.0, survey_sigma=0.25)
    assert {"ekf", "rts", "robust"} <= set(result.estimates["estimator"])
    assert not whole and True in along


@pytest.mark.slow
def test_a_tag_with_depth_readings_and_surveyed_receivers_is_tracked_at_its_depth(tmp_path):
    """The replay takes the readings (the track's height within 0.4 m RMS of the truth: the readings' own 0.3 m,
    smoothed) and the survey errors (their share of every estimator's sigma: larger than without them)."""
    toa_path, receivers_path, truth, _ = _files(tmp_path)
    result = sblsim.replay_toa(toa_path, receivers=receivers_path, sound_speed=1480.0, survey_sigma=0.25)
    summary = result.summary
    assert summary["depth"] == {"source": "sensor (depth_m)", "readings": 79, "sigma_m": 0.3}
    assert summary["survey_sigma_m"] == {n: (0.25 if n == "R3" else 0.5) for n in NAMES}
    track = result.track
    k = len(truth) - len(track)
    assert np.sqrt(np.mean((track["z"].to_numpy() - truth[k:, 2]) ** 2)) <= 0.4
    (tmp_path / "plain").mkdir()
    _, plain, _, _ = _files(tmp_path / "plain", sigma=False)
    exact = sblsim.replay_toa(toa_path, receivers=plain, sound_speed=1480.0)
    assert exact.summary["survey_sigma_m"] is None
    assert (track["sigma_x"].median() > exact.track["sigma_x"].median()), (track["sigma_x"].median(),
                                                                             exact.track["sigma_x"].median())
    # every estimator's rows hold it: the causal filters' and the RTS smoother's too (filter_consider)
    for name, rows in result.estimates.groupby("estimator"):
        other = exact.estimates[exact.estimates["estimator"] == name]
        assert rows["sigma_x"].median() > 1.05 * other["sigma_x"].median(), (name, rows["sigma_x"].median(),
                                                                              other["sigma_x"].median())


@pytest.mark.parametrize("case,options,message", [
    ("2-D receivers", ["--tag-depth", "5"], "depth_m: the tag's depth needs the receivers' depths"),
    ("depth column", ["--tag-depth", "5"], "tag_depth: not with a depth_m column"),
    ("depth column", ["--depth-sigma", "0"], "--depth-sigma: 0"),
    ("depth column", ["--survey-sigma", "-1"], "--survey-sigma: -1"),
    ("bad depth", [], "column depth_m: -20 is not allowed; allowed: a finite number in [-10, 11000]"),
])
def test_bad_depths_and_survey_errors_are_refused_in_one_line(tmp_path, capsys, case, options, message):
    from sblsim.orchestrator.cli import main

    toa_path, receivers_path, _, _ = _files(tmp_path)
    if case == "2-D receivers":
        pd.read_csv(receivers_path).drop(columns=["z_m"]).to_csv(receivers_path, index=False)
        table = pd.read_csv(toa_path).drop(columns=["depth_m"])
        table.to_csv(toa_path, index=False, na_rep="NA")
    elif case == "bad depth":
        table = pd.read_csv(toa_path)
        table.loc[3, "depth_m"] = -20.0
        table.to_csv(toa_path, index=False, na_rep="NA")
    code = main(["replay", str(toa_path), "--format", "toa", "--receivers", str(receivers_path), "--sound-speed",
                 "1480", "--out", str(tmp_path / "o"), *options])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], (case, err)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_the_summary_says_the_depth_was_estimated_without_readings(tmp_path):
    toa_path, receivers_path, _, _ = _files(tmp_path)
    pd.read_csv(toa_path).drop(columns=["depth_m"]).to_csv(toa_path, index=False, na_rep="NA")
    result = sblsim.replay_toa(toa_path, receivers=receivers_path, sound_speed=1480.0, out=tmp_path / "o")
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["depth"] == {
        "source": "estimated with the position"}
    assert result.summary["survey_sigma_m"]["R1"] == 0.5



#: 8 receivers moored 1-5 m deep over 200 x 150 m (a lake's array).
SHALLOW = np.column_stack([R3[:, :2], -np.array([1.0, 4.5, 2.0, 5.0, 3.0, 1.5, 4.0, 2.5])])


def _shallow_array(tmp_path: Path) -> tuple[Path, Path, Path, np.ndarray]:
    """A tag 2 m deep crossing :data:`SHALLOW` at 0.5 m/s, a ping every 2 s for 400 s, 0.15 ms of noise: the times
    of arrival, the receivers and the truth files, and the truth (m, 3)."""
    rng = np.random.default_rng(1)
    m, c = 200, 1480.0
    t = 10.0 + 2.0 * np.arange(m)
    heading = 0.6 + np.cumsum(0.05 * rng.normal(size=m))
    xy = np.array([40.0, 30.0]) + np.cumsum(np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    truth = np.column_stack([xy, np.full(m, -2.0)])
    toa = t[:, None] + np.linalg.norm(truth[:, None] - SHALLOW[None], axis=2) / c + 1.5e-4 * rng.normal(size=(m, 8))
    pd.DataFrame(toa, columns=NAMES).to_csv(tmp_path / "toa.csv", index=False, float_format="%.9f")
    pd.DataFrame({"name": NAMES, "x_m": SHALLOW[:, 0], "y_m": SHALLOW[:, 1], "z_m": SHALLOW[:, 2]}).to_csv(
        tmp_path / "receivers.csv", index=False)
    pd.DataFrame({"x": xy[:, 0], "y": xy[:, 1], "t": t}).to_csv(tmp_path / "truth.csv", index=False)
    return tmp_path / "toa.csv", tmp_path / "receivers.csv", tmp_path / "truth.csv", truth


@pytest.mark.slow
def test_a_depth_the_receivers_do_not_determine_is_taken_with_a_prior_and_said(tmp_path, capsys):
    """Receivers moored 1-5 m deep, a tag among their heights, no depth given: the summary and one console line say
    the depth was taken with a prior at the receivers' mean depth (read here with pandas), no row's depth σ is below
    the prior's, and the horizontal track is as good as with the tag's true depth given (within 10 % and 2 cm RMS)."""
    from sblsim.orchestrator.cli import main

    toa_path, receivers_path, truth_path, _ = _shallow_array(tmp_path)
    common = ["replay", str(toa_path), "--format", "toa", "--receivers", str(receivers_path), "--truth",
              str(truth_path), "--sound-speed", "1480", "--smooth"]
    assert main([*common, "--out", str(tmp_path / "prior")]) == 0
    err = capsys.readouterr().err.splitlines()
    said = [line for line in err if "do not determine the tag's depth" in line]
    assert len(said) == 1 and said[0].startswith("sblsim: warning: "), err
    summary = json.loads((tmp_path / "prior" / "summary.json").read_text())
    depth = summary["depth"]
    assert depth["source"] == "prior (the arrivals do not determine it)"
    assert np.isclose(depth["depth_m"], -pd.read_csv(receivers_path)["z_m"].mean())
    track = pd.read_csv(tmp_path / "prior" / "track.csv")
    assert (track["sigma_z"] >= depth["sigma_m"] - 1e-9).all()
    assert main([*common, "--tag-depth", "2", "--out", str(tmp_path / "given")]) == 0
    assert "do not determine" not in capsys.readouterr().err
    given = json.loads((tmp_path / "given" / "summary.json").read_text())
    assert given["depth"]["source"] == "given (one depth)"
    rms = {name: json.loads((tmp_path / name / "score.json").read_text())["rms_m"] for name in ("prior", "given")}
    assert rms["prior"] <= 1.1 * rms["given"] + 0.02, rms


@pytest.mark.parametrize("kind", ["rbi", "sbi"])
def test_a_record_whose_first_and_last_rows_nobody_heard_is_tracked(tmp_path, kind):
    """Rows no receiver heard before the first heard row and after the last (a receiver left out, detections lost at
    the ends of a record) take the heard rows' median step (a step of no duration has no process noise: the smoother
    refused such a record with LinAlgError): the record is tracked, its heard rows as without the blank rows, and
    the last row by the motion model alone."""
    receivers = R3[:6, :2]
    names = NAMES[:6]
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)
    def circle(t):  # 50 m round the array's middle in an hour
        a = 2.0 * np.pi * np.asarray(t) / 3600.0
        return np.column_stack([100.0 + 50.0 * np.cos(a), 75.0 + 50.0 * np.sin(a)])

    toa, truth, emissions = tt.simulate_pings(receivers, 60, s, np.random.default_rng(4), detection=0.9,
                                              ping_type=kind, burst_interval=(20.0, 40.0), path=circle)
    pd.DataFrame({"name": names, "x_m": receivers[:, 0], "y_m": receivers[:, 1]}).to_csv(tmp_path / "r.csv",
                                                                                         index=False)
    np.savetxt(tmp_path / "truth.txt", np.column_stack([truth, emissions]), header="x y t", comments="")
    blank = toa.copy()
    blank[[0, 1, -1]] = np.nan
    rows = {}
    for name, matrix in (("blank", blank), ("cut", blank[2:-1])):
        pd.DataFrame(matrix, columns=names).to_csv(tmp_path / f"{name}.csv", index=False, na_rep="NA",
                                                   float_format="%.9f")
        rows[name] = sblsim.replay_toa(tmp_path / f"{name}.csv", receivers=tmp_path / "r.csv",
                                       truth=tmp_path / "truth.txt", sound_speed=1480.0, ping_type=kind,
                                       burst_interval=(20.0, 40.0) if kind == "rbi" else None,
                                       acceleration_psd=1e-3)  # given: EM's q not moved by the blank rows' steps
    robust = {name: r.estimates[r.estimates.estimator == "robust"].set_index("ping") for name, r in rows.items()}
    blank_rows, cut_rows = robust["blank"], robust["cut"].rename(index=lambda k: k + 2)  # the cut's row 0 is row 2
    assert blank_rows.index[-1] == 59 and cut_rows.index[-1] == 58  # the track runs to the last row, blank or not
    both = cut_rows.index.intersection(blank_rows.index)
    assert len(both) >= 50
    e = np.hypot(blank_rows.x[both] - cut_rows.x[both], blank_rows.y[both] - cut_rows.y[both])
    assert e.max() < 0.05, e.max()  # the blank rows add motion-model steps only
    errors = np.hypot(blank_rows.x[both] - truth[both, 0], blank_rows.y[both] - truth[both, 1])
    assert np.median(errors) < 0.5, np.median(errors)
    # the last row, heard by none, held by the motion model alone: later than the one before, less certain
    last, before = blank_rows.loc[59], blank_rows.loc[58]
    assert last.receivers_heard == 0 and last.time > before.time, (last, before)
    assert np.hypot(last.sigma_x, last.sigma_y) > np.hypot(before.sigma_x, before.sigma_y), (last, before)


@pytest.mark.slow
def test_a_sound_speed_given_that_the_pings_contradict_is_said_and_kept(tmp_path, capsys):
    """A tag simulated at 1,480 m/s among six receivers: given 1,480 m/s, the summary holds the pings' own
    calibration (within 3 of its σ of the truth) and no warning; given 1,495 m/s (1 % off), one console line says the
    two disagree by more than SPEED_CHECK_SIGMAS of the calibration's σ, and the track still takes 1,495 m/s."""
    from sblsim.orchestrator.cli import main
    from sblsim.orchestrator.tracks.speed import SPEED_CHECK_SIGMAS

    receivers = R3[:6, :2]
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)
    toa, _, _ = tt.simulate_pings(receivers, 300, s, np.random.default_rng(6), speed=0.2, detection=0.9)
    pd.DataFrame(toa, columns=NAMES[:6]).to_csv(tmp_path / "toa.csv", index=False, na_rep="NA", float_format="%.9f")
    pd.DataFrame({"name": NAMES[:6], "x_m": receivers[:, 0], "y_m": receivers[:, 1]}).to_csv(tmp_path / "r.csv",
                                                                                             index=False)
    said = {}
    for given in (1480.0, 1495.0):
        out = tmp_path / f"c{given:.0f}"
        assert main(["replay", str(tmp_path / "toa.csv"), "--format", "toa", "--receivers", str(tmp_path / "r.csv"),
                     "--sound-speed", f"{given:g}", "--out", str(out)]) == 0
        said[given] = [line for line in capsys.readouterr().err.splitlines() if "sound speed given" in line]
        speed = json.loads((out / "summary.json").read_text())["sound_speed"]
        assert speed["sound_speed_m_s"] == given and speed["source"] == "given"
        assert abs(speed["calibrated_m_s"] - 1480.0) <= 3.0 * speed["calibrated_sigma_m_s"], speed
        assert speed["disagrees"] == (abs(given - speed["calibrated_m_s"]) > SPEED_CHECK_SIGMAS *
                                      speed["calibrated_sigma_m_s"])
    assert said[1480.0] == [] and len(said[1495.0]) == 1 and said[1495.0][0].startswith("sblsim: warning: "), said
