"""No hang of a calibration: antenna positions in km refused at the door (SeaGap's example and a GARPOS survey,
each scaled by this test), a number of bases above what the survey determines or a solve holds refused before any
solve, and the moving-ocean solve's iterations reported (the numbers unchanged by the report); Ctrl-C during a
moving-ocean search: ``tests/orchestrator/test_interrupt.py``. And a box-in study that disagrees with its bound
suggests no survey sigma."""

from __future__ import annotations

import shutil
import sys
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from sblsim.models.calibration import Perturbation, solve
from sblsim.models.calibration.ocean import bases_of
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.surveys import solution
from sblsim.orchestrator.surveys.calibrate import calibrate, load_survey
from sblsim.orchestrator.surveys.simulate import load_simulated, replicate, run_simulated

sys.path.insert(0, str(Path(__file__).parent))
from test_calibrate_garpos import _write as write_garpos  # noqa: E402 (the GARPOS survey of that test)

EXAMPLE = files("sblsim.orchestrator.surveys").joinpath("data", "seagap")
#: obsdata.inp's antenna East, North, Up at transmit and at receive (0-based fields; SeaGap's Dataformat).
ANTENNA_FIELDS = (3, 4, 5, 10, 11, 12)


def _example_in_km(folder: Path) -> np.ndarray:
    """SeaGap's example copied to ``folder`` with its antenna positions divided by 1000; returns obsdata's numbers."""
    shutil.copytree(str(EXAMPLE), folder)
    rows = [line.split() for line in (folder / "obsdata.inp").read_text().splitlines() if line.strip()]
    for cells in rows:
        for j in ANTENNA_FIELDS:
            cells[j] = repr(float(cells[j]) / 1000.0)
    (folder / "obsdata.inp").write_text("\n".join(" ".join(c) for c in rows) + "\n")
    return np.array(rows, dtype=float)


def _in_km(path: Path, names: list[str]) -> list[str]:
    """The lines of a CSV file (a comment line, then its header) with the columns ``names`` divided by 1000."""
    lines = path.read_text().splitlines()
    header = lines[1].split(",")
    columns = [header.index(n) for n in names]
    scaled = lines[:2]
    for line in lines[2:]:
        cells = line.split(",")
        for j in columns:
            cells[j] = repr(float(cells[j]) / 1000.0)
        scaled.append(",".join(cells))
    return scaled


def _no_solve(monkeypatch) -> None:
    """Make a calibration's solve fail the test: a refusal at the door is one that no solve precedes (checked by
    what ran, not by a clock)."""
    def solve_began(*args, **kwargs):
        raise AssertionError("a solve began before the refusal")

    monkeypatch.setattr(solution, "solve", solve_began)


def _one_line_refusal(capsys, monkeypatch, args: list[str], out: Path) -> str:
    _no_solve(monkeypatch)
    status = main([*args, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert status == 2, err
    assert len(err.splitlines()) == 1 and err.startswith("sblsim: error: "), err
    assert not out.exists()
    return err


def test_a_seagap_folder_in_km_is_refused_at_the_door(tmp_path, capsys, monkeypatch):
    obs = _example_in_km(tmp_path / "km")
    err = _one_line_refusal(capsys, monkeypatch, ["calibrate", str(tmp_path / "km"), "--format", "seagap"],
                            tmp_path / "o")
    assert "obsdata: the antenna's East, North, Up (fields 4-6 and 11-13) [m]: transponder 1's ranges" in err
    assert "are the positions in km where metres are expected?" in err
    # the spread of transponder 1's ranges, computed here from the file: half its TWTT at 1300 m/s, 5 to 95 %
    ranges = 0.5 * 1300.0 * obs[obs[:, 0] == 1, 1]
    spread = np.percentile(ranges, 95) - np.percentile(ranges, 5)
    assert f"span {spread:.4g} m" in err
    # the transducer (the antenna, now within tens of metres, plus its lever arm) moves far less than that
    antenna = np.vstack((obs[obs[:, 0] == 1][:, 3:6], obs[obs[:, 0] == 1][:, 10:13]))
    lever = float(np.linalg.norm(np.loadtxt(EXAMPLE.joinpath("tr-ant.inp"))))
    assert np.linalg.norm(np.ptp(antenna, axis=0)) + 2 * lever < 0.2 * spread


def test_a_garpos_survey_in_km_is_refused_and_in_metres_passes(tmp_path, capsys, monkeypatch):
    write_garpos(tmp_path / "g")
    scaled = _in_km(tmp_path / "g" / "obs.csv", [f"ant_{a}{w}" for w in "01" for a in "enu"])
    files_of = [str(tmp_path / "g" / "obs.csv"), "--format", "garpos", "--initcfg", str(tmp_path / "g" / "initcfg.ini"),
                "--svp", str(tmp_path / "g" / "svp.csv")]
    # in metres: past the door
    assert len(load_survey(files_of[0], "garpos", initcfg=files_of[4], svp=files_of[6]).log.frame) == 320
    (tmp_path / "g" / "obs.csv").write_text("\n".join(scaled) + "\n")
    err = _one_line_refusal(capsys, monkeypatch, ["calibrate", *files_of], tmp_path / "o")
    assert "obs: ant_e0, ant_n0, ant_u0, ant_e1, ant_n1, ant_u1 [m]: transponder M1" in err


XIE = files("sblsim.orchestrator.surveys").joinpath("data", "xie", "gnssa_data_20210723.txt")
#: A Xie line's transducer North, East, Up at transmit and at receive (0-based fields; the module's FIELDS).
XIE_POSITIONS = (1, 2, 3, 8, 9, 10)


def test_a_xie_file_in_km_is_refused_at_the_door_and_in_metres_passes(tmp_path, capsys, monkeypatch):
    """Survey A's file as the authors give it solves past the door; its transducer positions divided by 1000 (the
    travel times kept) are refused in one line before any solve, naming the fields and the ranges' spread."""
    lines = XIE.read_text().splitlines()
    assert len(load_survey(str(XIE), "xie").log.frame) == 555
    scaled = []
    for line in lines:
        cells = line.split()
        if line.startswith("#") or len(cells) != 15:
            scaled.append(line)
            continue
        for j in XIE_POSITIONS:
            cells[j] = repr(float(cells[j]) / 1000.0)
        scaled.append(" ".join(cells))
    km = tmp_path / "km.txt"
    km.write_text("\n".join(scaled) + "\n")
    err = _one_line_refusal(capsys, monkeypatch, ["calibrate", str(km), "--format", "xie"], tmp_path / "o")
    assert "the transducer's North, East, Up at transmit and at receive (fields 2-4 and 9-11) [m]: transponder 1" \
        in err and "are the positions in km where metres are expected?" in err
    # the spread of its ranges, computed here from the file: half its TWTT at 1300 m/s, 5 to 95 %
    rows = np.array([line.split() for line in lines if not line.startswith("#") and len(line.split()) == 15],
                    dtype=float)
    ranges = 0.5 * 1300.0 * rows[:, 14]
    assert f"span {np.percentile(ranges, 95) - np.percentile(ranges, 5):.4g} m" in err


def test_a_sblsim_log_in_km_is_refused_and_in_metres_passes(tmp_path, capsys, monkeypatch):
    """A synthetic CSV log (a 300 m circle around a point 120 m from a transponder 100 m deep: its ranges span
    about 240 m) solves; the same log with its positions in km is refused at the door, naming the log's position
    columns. (A circle centred over the transponder keeps every range the same: no check of the units can see
    them there.)"""
    from test_calibrate import _circle, _log_of

    from sblsim.orchestrator.surveys.log import write_log

    good = tmp_path / "good.csv"
    write_log(_log_of(_circle(np.random.default_rng(2), np.array([120.0, 0.0, -100.0]), n=40)), good)
    assert main(["calibrate", str(good), "--out", str(tmp_path / "ok")]) == 0
    capsys.readouterr()
    scaled = _in_km(good, [f"{w}_{a}_m" for w in ("tx", "rx") for a in "enu"])
    km = tmp_path / "km.csv"
    km.write_text("\n".join(scaled) + "\n")
    err = _one_line_refusal(capsys, monkeypatch, ["calibrate", str(km)], tmp_path / "o")
    assert "the log's tx_e_m, tx_n_m, tx_u_m, rx_e_m, rx_n_m, rx_u_m [m]: transponder 1's ranges" in err


def test_n_bases_above_the_survey_s_pings_is_refused_naming_the_most_it_determines(tmp_path, capsys, monkeypatch):
    # SeaGap's example: its pings are obsdata's distinct transmit times, counted here from the file
    obs = np.loadtxt(EXAMPLE.joinpath("obsdata.inp"))
    pings = len(np.unique(obs[:, 2]))
    most = 3 + pings // 4
    err = _one_line_refusal(capsys, monkeypatch, ["calibrate", "seagap-example", "--set", "solver.n_bases=5000"],
                            tmp_path / "o")
    assert err.startswith(f"sblsim: error: solver.n_bases: 5000 bases are more than the log determines: at most "
                          f"{most} for its {pings} pings over ")
    err = _one_line_refusal(capsys, monkeypatch, ["calibrate", "seagap-example", "--set", "solver.n_bases=0",
                                                  "--set", "solver.knot_interval=1"], tmp_path / "o")
    assert "solver.knot_interval: 1 s gives" in err and f"at most {most} for its {pings} pings" in err


def test_the_bound_on_the_bases_is_where_the_pings_put_it(monkeypatch):
    """A simulated figure-eight of 20 minutes, a ping every 4 s (301 pings): 3 + 301 // 4 = 78 bases solve, 79 are
    refused, and a search is refused before its first candidate is solved."""
    pings = 1200 // 4 + 1
    ocean = ["survey.pattern=figure-eight", "survey.ntd_sigma_s=1e-4", "solver.perturbation=ntd",
             "solver.outlier_factor=100"]
    survey, _ = replicate(load_simulated("box-in", [*ocean, f"solver.n_bases={3 + pings // 4}"]), 0)
    assert len(np.unique(survey.log.frame["t_tx_s"])) == pings
    result = calibrate(survey)
    assert result.solution["n_bases"] == 3 + pings // 4
    _no_solve(monkeypatch)
    for bases in (f"{4 + pings // 4}", f"[6, {4 + pings // 4}]"):
        survey, _ = replicate(load_simulated("box-in", [*ocean, f"solver.n_bases={bases}"]), 0)
        with pytest.raises(ModelError, match=f"solver.n_bases: {4 + pings // 4} bases are more than the log "
                                             f"determines: at most {3 + pings // 4} for its {pings} pings"):
            calibrate(survey)


def test_a_design_too_large_to_solve_is_refused():
    """A day of a ping every second determines 21,603 bases (capped at 5000), but 5000 columns of 86,401 dense rows
    are 3.5 GB: the bases allowed are those within 10,000,000 cells."""
    t = np.arange(0.0, 86401.0)
    most = 10_000_000 // len(t)
    assert bases_of(Perturbation("ntd", n_bases=most), t, t + 4.0)[0] == most
    with pytest.raises(ModelError, match=f"n_bases: {most + 1} bases are more than a solve of the log holds: at "
                                         f"most {most} for its {len(t)} replies"):
        bases_of(Perturbation("ntd", n_bases=most + 1), t, t + 4.0, "the log")
    # GARPOS's gradients are splines: five columns per basis with both
    most = 10_000_000 // len(t) // 5
    with pytest.raises(ModelError, match=f"at most {most} for"):
        bases_of(Perturbation("garpos", n_bases=most + 1, gradient="shallow+deep"), t, t + 4.0)


def test_the_moving_ocean_s_iterations_are_reported_and_change_nothing():
    sim = load_simulated("box-in", ["survey.pattern=figure-eight", "survey.ntd_sigma_s=1e-4",
                                    "solver.perturbation=ntd", "solver.outlier_factor=100", "solver.n_bases=8"])
    survey, _ = replicate(sim, 0)
    seen = []
    reported = calibrate(survey, lambda done, total: seen.append((done, total)))
    quiet = calibrate(survey)
    sol = reported.segments[0][3]
    assert sol.iterations >= 2 and seen == [(k, 0) for k in range(1, sol.iterations + 1)]  # one per iteration
    assert np.array_equal(sol.position, quiet.segments[0][3].position)
    assert np.array_equal(sol.covariance, quiet.segments[0][3].covariance)
    # the model's own callback: one call per Gauss-Newton iteration of each fit
    calls = []
    again = solve(survey.log.replies(survey.ids), survey.apriori, survey.solver["sound_speed_mps"], outlier_factor=None,
                  perturbation=Perturbation("ntd", n_bases=8), progress=calls.append)
    assert calls == [1] * again.iterations and np.array_equal(again.position, sol.position)
    # a search reports every candidate's iterations (the first solved in full, each candidate, the chosen one)
    sim = load_simulated("box-in", ["survey.pattern=figure-eight", "survey.ntd_sigma_s=1e-4", "solver.perturbation=ntd",
                                    "solver.outlier_factor=100", "solver.n_bases=[6, 8, 10]"])
    survey, _ = replicate(sim, 0)
    seen.clear()
    calibrate(survey, lambda done, total: seen.append(done))
    assert seen == list(range(1, len(seen) + 1)) and len(seen) >= 3 + 1


@pytest.mark.slow
def test_a_study_far_from_its_bound_suggests_no_survey_sigma(tmp_path, capsys):
    """The default circle with a moving ocean solved: the NTD and the depth are one unknown on one circle, so the
    bound is thousands of metres while the replicates err by decimetres; a still ocean's study agrees."""
    moving = ["survey.ntd_sigma_s=2e-4", "solver.perturbation=ntd"]
    result, table = run_simulated(load_simulated("box-in", moving), 5)
    ratio = np.sqrt(np.mean(table["e_n_m"] ** 2 + table["e_e_m"] ** 2)) / np.sqrt(np.mean(table["pcrb_h_m"] ** 2))
    assert ratio < 1 / 3
    assert result.solution["lbl_set"] is None and not result.solution["bound_agreement"]["agrees"]
    assert [w for w in result.warnings if "no survey sigma is suggested" in w]
    # one replicate: its horizontal 1-sigma against its bound
    one, _ = run_simulated(load_simulated("box-in", moving))
    t, bound = one.solution["transponders"][0], one.solution["errors"][0]["pcrb_h_m"]
    assert np.hypot(t["sigma_e_m"], t["sigma_n_m"]) < bound / 3 and one.solution["lbl_set"] is None
    # the command says so instead of the --set line
    assert main(["calibrate", "box-in", "--replicates", "5", *sum((["--set", m] for m in moving), []),
                 "--out", str(tmp_path / "o")]) == 0
    captured = capsys.readouterr()
    assert "no survey error suggested for an LBL design" in captured.out and "--set platform" not in captured.out
    assert "disagree by a factor" in captured.err
    still, table = run_simulated(load_simulated("box-in"), 5)
    ratio = np.sqrt(np.mean(table["e_n_m"] ** 2 + table["e_e_m"] ** 2)) / np.sqrt(np.mean(table["pcrb_h_m"] ** 2))
    value = still.solution["survey_sigma_m"]
    assert 1 / 3 <= ratio <= 3 and still.solution["lbl_set"] == f"platform.survey_sigma={value:.4g}"
