"""``sblsim calibrate``: survey A against its authors' own script, a synthetic survey with a known transponder,
pairing by identity, hostile logs and the command's outputs and refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models.calibration import Replies, solve
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.surveys.calibrate import calibrate, load_survey
from sblsim.orchestrator.surveys.log import LOG_COLUMNS, SurveyLog, read_survey_log, write_log

# The authors' results on survey A, 2021-07-23 (Xie et al. 2023, Figure 8 e: fixed sound speed 1499.3 m/s, the four
# non-overlapping segments), from their own script run outside this project on the same file:
#   git clone https://github.com/suruixie/sfg_gnssa_sw (commit 51e9b13a896428bb230c48a9d5d64ec6056d675c)
#   python pos20210723.py -i data/gnssa_data_20210723.txt
# with print statements added after each segment (S1_est_neu0, len(res), res_wrms) and at the end (S1_wMeanN,
# S1_wMeanE); the rejected pings are the segment's rows missing from its kept S1_tneusss0neusss1T. Offsets in
# metres from the a-priori point (0, 0, 0): (start, end, north, east, kept, rows, rejected row indices).
AUTHORS_SEGMENTS = [
    ("2021-07-23T19:34:30Z", "2021-07-23T19:50:50Z", -0.002737668262505284, -0.006499593075424947, 94, 98,
     [24, 25, 26, 48]),
    ("2021-07-23T19:50:50Z", "2021-07-23T20:06:30Z", 0.006622247845833258, -0.0013403551010519284, 94, 94, []),
    ("2021-07-23T20:11:40Z", "2021-07-23T20:33:30Z", 0.0026445216067397903, 0.021720579177962565, 124, 130,
     [254, 276, 335, 337, 351, 357]),
    ("2021-07-23T20:33:30Z", "2021-07-23T20:55:10Z", -0.007760633893577898, 0.008878542424165432, 127, 129,
     [439, 441]),
]
AUTHORS_COMBINED_NE = (-0.0003075880112074898, 0.00564768208743797)
# RMS of the kept pings' residuals c T - r1 - r2 over the four segments, divided by c [s]
AUTHORS_TWTT_RMS_S = 2.3742415961518953e-05


@pytest.fixture(scope="module")
def survey_a():
    return calibrate(load_survey("xie-2021-07-23"))


def test_survey_a_equals_the_authors_script(survey_a):
    s = survey_a.solution
    assert len(s["segments"]) == len(AUTHORS_SEGMENTS)
    for seg, (start, end, n, e, kept, rows, _) in zip(s["segments"], AUTHORS_SEGMENTS):
        assert (seg["start"], seg["end"]) == (start, end)
        assert abs(seg["n_m"] - n) < 0.01 and abs(seg["e_m"] - e) < 0.01, (seg, n, e)
        assert seg["pings_used"] == kept and seg["pings_used"] + seg["pings_rejected"] == rows
    r = survey_a.residuals
    for k, (*_, rejected) in enumerate(AUTHORS_SEGMENTS, start=1):
        part = r[r["segment"] == k]
        assert sorted(part.loc[~part["used"], "ping"]) == rejected
    t = s["transponders"][0]
    assert abs(t["n_m"] - AUTHORS_COMBINED_NE[0]) < 0.01 and abs(t["e_m"] - AUTHORS_COMBINED_NE[1]) < 0.01
    assert s["pings_used"] == sum(a[4] for a in AUTHORS_SEGMENTS)
    assert abs(s["twtt_residual_rms_s"] / AUTHORS_TWTT_RMS_S - 1) < 0.10


def _circle(rng, truth, n=360, radius=300.0, c=1500.0, sigma=(0.02, 0.02, 0.05), twtt_sigma=0.0):
    """A circle of transducer positions around a transponder, exact two-leg times, noisy positions."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    tx = np.column_stack((radius * np.sin(a), radius * np.cos(a), np.zeros(n)))
    rx = np.column_stack((radius * np.sin(a + 0.004), radius * np.cos(a + 0.004), np.full(n, 0.1)))
    twtt = (np.linalg.norm(tx - truth, axis=1) + np.linalg.norm(rx - truth, axis=1)) / c
    twtt = twtt + rng.normal(0, twtt_sigma, n) if twtt_sigma else twtt
    s = np.tile(sigma, (n, 1))
    return Replies(tx + rng.normal(0, 1, (n, 3)) * s, s, rx + rng.normal(0, 1, (n, 3)) * s, s, twtt,
                   np.zeros(n, int))


def test_a_synthetic_survey_recovers_its_transponder_within_its_covariance():
    rng = np.random.default_rng(7)
    truth = np.array([4.0, -3.0, -310.0])
    apriori = [[0.0, 0.0, -300.0]]
    nees = []
    for _ in range(200):
        sol = solve(_circle(rng, truth), apriori, 1500.0, outlier_factor=None)
        err = sol.position[0] - truth
        nees.append(err @ np.linalg.solve(sol.covariance, err))
    assert abs(sol.offset[0] - (truth - apriori[0])).max() < 0.05
    assert 2.5 < np.mean(nees) < 3.5, np.mean(nees)


def test_a_sound_speed_scale_is_recovered():
    rng = np.random.default_rng(3)
    truth = np.array([1.0, 2.0, -500.0])
    # two circles, one wide and one near overhead: one circle alone cannot tell depth from sound speed
    a, b = (_circle(rng, truth, radius=r, c=1512.0, sigma=(0.01, 0.01, 0.01)) for r in (700.0, 60.0))
    both = Replies(*(np.concatenate((getattr(a, k), getattr(b, k))) for k in
                     ("tx", "tx_sigma", "rx", "rx_sigma", "twtt", "transponder")))
    sol = solve(both, [[0, 0, -480.0]], 1500.0, solve_sound_speed=True)
    assert sol.converged
    assert abs(sol.sound_speed - 1512.0) < 4 * sol.sound_speed_sigma + 1e-9
    assert abs(sol.sound_speed - 1512.0) < 1.0 and np.abs(sol.position[0] - truth).max() < 0.5


def _log_of(replies: Replies, ids=("1",), ping=None) -> SurveyLog:
    n = len(replies)
    t = 1.6e9 + np.arange(n) * 10.0
    frame = pd.DataFrame({
        "ping": np.arange(n) if ping is None else ping, "transponder": [ids[k] for k in replies.transponder],
        "t_tx_s": t,
        "tx_e_m": replies.tx[:, 0], "tx_n_m": replies.tx[:, 1], "tx_u_m": replies.tx[:, 2],
        "tx_sigma_e_m": replies.tx_sigma[:, 0], "tx_sigma_n_m": replies.tx_sigma[:, 1],
        "tx_sigma_u_m": replies.tx_sigma[:, 2], "t_rx_s": t + 0.6,
        "rx_e_m": replies.rx[:, 0], "rx_n_m": replies.rx[:, 1], "rx_u_m": replies.rx[:, 2],
        "rx_sigma_e_m": replies.rx_sigma[:, 0], "rx_sigma_n_m": replies.rx_sigma[:, 1],
        "rx_sigma_u_m": replies.rx_sigma[:, 2], "twtt_s": replies.twtt})
    return SurveyLog(frame[list(LOG_COLUMNS)], "synthetic")


def _two_transponders(rng):
    a = _circle(rng, np.array([50.0, 0.0, -200.0]), n=120)
    b = _circle(rng, np.array([-50.0, 10.0, -205.0]), n=120)
    return Replies(np.vstack((a.tx, b.tx)), np.vstack((a.tx_sigma, b.tx_sigma)), np.vstack((a.rx, b.rx)),
                   np.vstack((a.rx_sigma, b.rx_sigma)), np.concatenate((a.twtt, b.twtt)),
                   np.concatenate((np.zeros(120, int), np.ones(120, int))))


@pytest.mark.slow
def test_a_shuffled_log_gives_the_same_solution(tmp_path):
    """Two transponders replying to the same pings: shuffled rows are paired with their transponder by id."""
    replies = _two_transponders(np.random.default_rng(1))
    log = _log_of(replies, ids=("A", "B"), ping=np.concatenate((np.arange(120), np.arange(120))))
    log.frame["t_tx_s"] = 1.6e9 + log.frame["ping"] * 10.0
    log.frame["t_rx_s"] = log.frame["t_tx_s"] + 0.6
    ordered, shuffled = tmp_path / "ordered.csv", tmp_path / "shuffled.csv"
    write_log(log, ordered)
    write_log(SurveyLog(log.frame.sample(frac=1.0, random_state=5), "s"), shuffled)
    outs = []
    for path in (ordered, shuffled):
        assert main(["calibrate", str(path), "--out", str(tmp_path / path.stem)]) == 0
        outs.append(json.loads((tmp_path / path.stem / "solution.json").read_text()))
    def placed(out):
        return {t["id"]: [t["apriori_e_m"] + t["e_m"], t["apriori_n_m"] + t["n_m"], t["apriori_u_m"] + t["u_m"],
                          t["sigma_e_m"], t["sigma_n_m"], t["sigma_u_m"]] for t in out["transponders"]}

    first, second = placed(outs[0]), placed(outs[1])
    assert sorted(first) == ["A", "B"]
    for name in first:
        assert first[name] == pytest.approx(second[name], abs=1e-9)
    assert first["A"][:3] == pytest.approx([50.0, 0.0, -200.0], abs=0.05)
    assert first["B"][:3] == pytest.approx([-50.0, 10.0, -205.0], abs=0.05)
    assert outs[0]["pings_used"] == outs[1]["pings_used"] == 120


def _good_csv(tmp_path) -> Path:
    path = tmp_path / "good.csv"
    write_log(_log_of(_circle(np.random.default_rng(2), np.array([0.0, 0.0, -100.0]), n=40)), path)
    return path


def _with_cell(path: Path, line: int, column: str, text: str) -> Path:
    lines = path.read_text().splitlines()
    header = lines[1].split(",")
    cells = lines[line - 1].split(",")
    cells[header.index(column)] = text
    lines[line - 1] = ",".join(cells)
    bad = path.with_name(f"bad_{column}.csv")
    bad.write_text("\n".join(lines) + "\n")
    return bad


@pytest.mark.parametrize("column,text,message", [
    ("twtt_s", "abc", "line 7: twtt_s: 'abc' is not a number"),
    ("twtt_s", "-0.1", "line 7: twtt_s: -0.1 is outside the allowed range"),
    ("tx_sigma_u_m", "0", "line 7: tx_sigma_u_m: 0 is outside the allowed range"),
    ("rx_e_m", "nan", "line 7: rx_e_m: 'nan' is not a finite number"),
    ("ping", "2.5", "line 7: ping: '2.5' is not a whole number"),
    ("transponder", "../x", "line 7: transponder: '../x' is not an id"),
])
def test_a_bad_cell_is_refused_naming_its_line_and_column(tmp_path, capsys, column, text, message):
    bad = _with_cell(_good_csv(tmp_path), 7, column, text)
    assert main(["calibrate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


def test_missing_columns_duplicates_and_oversize_are_refused(tmp_path, capsys, monkeypatch):
    good = _good_csv(tmp_path)
    frame = pd.read_csv(good, comment="#")
    frame.drop(columns=["twtt_s", "rx_u_m"]).to_csv(tmp_path / "short.csv", index=False)
    assert main(["calibrate", str(tmp_path / "short.csv"), "--out", str(tmp_path / "o")]) == 2
    assert "lacks the columns rx_u_m, twtt_s" in capsys.readouterr().err
    pd.concat([frame, frame.iloc[[3]]]).to_csv(tmp_path / "twice.csv", index=False)
    assert main(["calibrate", str(tmp_path / "twice.csv"), "--out", str(tmp_path / "o")]) == 2
    assert "line 42: ping 3 has a second reply from transponder '1' (the first: line 5)" in capsys.readouterr().err
    import sblsim.orchestrator.surveys.log as log_module  # a log of any length is read; one the memory here cannot

    monkeypatch.setattr(log_module, "available_memory", lambda: 10 * log_module.ROW_BYTES)  # hold: refused first
    assert main(["calibrate", str(good), "--out", str(tmp_path / "o")]) == 2
    assert "holds up to 42 rows, about 0 MiB in memory to read; 0 MiB is available here" in capsys.readouterr().err
    (tmp_path / "folder.csv").mkdir()
    assert main(["calibrate", str(tmp_path / "folder.csv"), "--out", str(tmp_path / "o")]) == 2
    assert "is a directory" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_bad_line_of_a_xie_file_is_refused(tmp_path, capsys):
    from importlib.resources import files

    text = files("sblsim.orchestrator.surveys").joinpath("data/xie/gnssa_data_20211210.txt").read_text()
    lines = text.splitlines()
    lines[5] = lines[5].rsplit(None, 1)[0] + " 0.1x"
    (tmp_path / "a.txt").write_text("\n".join(lines) + "\n")
    assert main(["calibrate", str(tmp_path / "a.txt"), "--format", "xie", "--out", str(tmp_path / "o")]) == 2
    assert "line 6: twtt_s: '0.1x' is not a number" in capsys.readouterr().err
    lines[5] = " ".join(lines[5].split()[:10])
    (tmp_path / "a.txt").write_text("\n".join(lines) + "\n")
    assert main(["calibrate", str(tmp_path / "a.txt"), "--format", "xie", "--out", str(tmp_path / "o")]) == 2
    assert "line 6 has 10 fields, the format 15" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_the_command_writes_the_named_keys_and_its_log_reads_back(tmp_path, survey_a):
    assert main(["calibrate", "xie-2021-07-23", "--out", str(tmp_path / "a")]) == 0
    s = json.loads((tmp_path / "a" / "solution.json").read_text())
    for key in ("transponders", "segments", "twtt_residual_rms_s", "pings_used", "pings_rejected",
                "sound_speed_mps"):
        assert key in s
    assert set(s["transponders"][0]) >= {"id", "n_m", "e_m", "u_m", "sigma_n_m", "sigma_e_m", "sigma_u_m"}
    assert set(s["segments"][0]) >= {"start", "end", "n_m", "e_m", "u_m", "pings_used"}
    assert s["transponders"] == survey_a.solution["transponders"]
    for name in ("residuals.csv", "track.png", "residuals_time.png", "residuals_elevation.png"):
        assert (tmp_path / "a" / name).stat().st_size > 0
    # survey A through the sblsim log format (Parquet): the same solution
    write_log(survey_a.survey.log, tmp_path / "a.parquet")
    pd.testing.assert_frame_equal(read_survey_log(tmp_path / "a.parquet").frame, survey_a.survey.log.frame)


@pytest.mark.parametrize("argv,message", [
    (["--set", "solver.sound_speed_mps=900"], "solver.sound_speed_mps: 900 is outside the allowed range [1300, 1800]"),
    (["--set", "solver.outlier_factor=true"], "solver.outlier_factor: True is outside the allowed range"),
    (["--set", "solver.rigid=1"], "solver.rigid: 1 is not true or false"),
    (["--set", "acoustics.sound_speed=1500"], "'acoustics.sound_speed' is not a calibration key"),
    (["--set", "solver.segments=[[\"2021-07-23T19:00:00\", \"2021-07-23T20:00:00Z\"]]"], "must be UTC"),
    (["--format", "xie"], "--format: the built-in survey xie-2021-07-23 has its own format"),
])
def test_bad_settings_are_refused_in_one_line(tmp_path, capsys, argv, message):
    assert main(["calibrate", "xie-2021-07-23", "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


def test_an_unknown_format_is_refused(tmp_path, capsys):
    assert main(["calibrate", str(_good_csv(tmp_path)), "--format", "rinex", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "--format: 'rinex' is not one of sblsim, xie" in err


def test_the_solver_keys_are_declared_and_documented_as_they_are_checked():
    """Every solver setting is a Variable declaration (a configuration key), docs/calibration.md's table lists each
    once with its unit and default, and a value outside its declared range is refused naming the range."""
    import re

    from sblsim.models.declarations import ModelError, Variable
    from sblsim.orchestrator.surveys.calibrate import SOLVER_KEYS, SOLVER_VARIABLES, solver_defaults, solver_value

    assert all(isinstance(v, Variable) and not v.in_fmu for v in SOLVER_VARIABLES)
    text = (Path(__file__).resolve().parents[2] / "docs" / "calibration.md").read_text()
    rows = {m[0]: [c.strip() for c in m[1].split("|")]
            for m in re.findall(r"^\| `solver\.(\w+)` \|(.*)\|$", text, flags=re.M)}
    assert set(rows) == set(SOLVER_KEYS)
    defaults = solver_defaults()
    for name, v in SOLVER_KEYS.items():
        unit, _allowed, default = rows[name][:3]
        assert unit == ("" if v.unit in ("", "1") else v.unit), name
        if v.type == "Real" and name != "running_prior_sigma_m":
            assert float(default.split()[0]) == defaults[name], (name, default)
        if v.type in ("Real", "Integer") and v.max is not None:
            with pytest.raises(ModelError, match=rf"solver\.{name}: .* is outside the allowed range"):
                solver_value(name, v.max * 2 + 1)


GRADIENT_REFUSED = "solver.gradient: deep needs solver.perturbation (ntd or garpos)"


@pytest.mark.parametrize("source,argv,toml", [
    ("xie-2021-07-23", ["--set", "solver.gradient=deep"], None),  # a built-in survey's command line
    ("box-in", ["--set", "solver.gradient=deep"], None),  # a simulated survey's
    ("mine.toml", [], '[solver]\ngradient = "deep"\n'),  # a simulated survey's own [solver]
    ("mine.toml", ["--set", "solver.perturbation=none"], '[solver]\nperturbation = "ntd"\ngradient = "deep"\n'),
])
def test_a_gradient_without_a_perturbation_is_refused_not_ignored(tmp_path, capsys, monkeypatch, source, argv, toml):
    """solver.gradient is the perturbation's: without solver.perturbation it would be recorded and unused."""
    monkeypatch.chdir(tmp_path)
    if toml is not None:
        (tmp_path / source).write_text(toml)
    assert main(["calibrate", source, "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [f"sblsim: error: {GRADIENT_REFUSED}: the gradients are the perturbation's; "
                                "without one it is none"], err
    assert not (tmp_path / "o").exists()


def test_the_api_refuses_a_gradient_without_a_perturbation():
    import sblsim
    from sblsim.orchestrator.surveys.calibrate import check_solver, solver_defaults

    with pytest.raises(sblsim.SblsimError, match=r"^solver\.gradient: shallow\+deep needs solver\.perturbation"):
        sblsim.calibrate("box-in", set={"solver.gradient": "shallow+deep"})
    with pytest.raises(sblsim.SblsimError, match=r"^solver\.gradient: deep needs"):
        sblsim.calibrate("xie-2021-07-23", set={"solver.gradient": "deep"})
    # with a perturbation the gradient is taken
    for kind in ("ntd", "garpos"):
        settings = {**solver_defaults(), "perturbation": kind, "gradient": "deep"}
        assert check_solver(settings) is settings
