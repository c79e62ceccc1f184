"""What a hostile tester found refused unclearly, or not at all: each a one-line refusal (exit 2, nothing written) or
a clear message.

* a log's range below what the configuration's channel measures (orchestrator/logs/receiver_log.py, range_floor.py);
* a times-of-arrival record in which no ping can be positioned (orchestrator/tracks/replay.py);
* ``sblsim run --export-log`` whose export fails: the run's folder goes with it (orchestrator/commands/run.py);
* a budget whose receiver heard nothing (orchestrator/montecarlo/budget.py);
* a row nobody heard in a random-interval record, a long interface mismatch, and options with no effect.
"""

from __future__ import annotations

import errno
import os
import re
from collections import namedtuple
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models import COMPONENTS
from sblsim.models.declarations import ModelError
from sblsim.models.errors import ConfigError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.receiver.interface import OPTIONAL_OUTPUTS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.connections import ConnectionMismatch, check_interface
from sblsim.orchestrator.cosim.plan import load_plan
from sblsim.orchestrator.design.problem import check_problem
from sblsim.orchestrator.io import output, plots
from sblsim.orchestrator.logs import log_export
from sblsim.orchestrator.logs.range_floor import range_floor
from sblsim.orchestrator.logs.receiver_log import read_log
from tests.helpers import problem_with
from tests.orchestrator.test_design_telemetry import SMALL  # the small L-shaped lake, a range test's curve

HEADER = "time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("sblsim: error: ") and "Traceback" not in err, err
    return err


# --------------------------------------------------------------------------- a log's negative range

def test_a_range_within_the_channels_floor_is_taken_and_one_below_it_refused(tmp_path):
    """The semicircle's one-way channel (sigma_range 0.1 m): its noise reaches 8 sigma = 0.8 m below 0, no further;
    with a jittering two-way turnaround (50 ms) the floor is c * 0.05 / 2 = 37.5 m lower."""
    acoustics = load_plan("semicircle")["acoustics"]
    floor, fall, _ = range_floor(acoustics)
    assert floor == pytest.approx(-8.0 * acoustics["sigma_range"]) and fall == 0.0
    jittered = load_plan("semicircle", ["acoustics.ranging=twtt", "acoustics.turnaround_sigma=0.01"])["acoustics"]
    c = jittered["sound_speed_assumed"]
    assert range_floor(jittered)[0] == pytest.approx(-(c * jittered["turnaround"] / 2.0 + 8.0 * 0.1))
    log = tmp_path / "log.csv"
    log.write_text(HEADER + "0.1,1,6,1,0,1,2\n0.2,2,-0.5,1,0,1,2\n")
    assert read_log(log, 4, acoustics=acoustics).range[1] == -0.5
    log.write_text(HEADER + "0.1,1,6,1,0,1,2\n0.2,2,-1,1,0,1,2\n")
    with pytest.raises(ModelError, match=r"line 3: range_m: -1 is outside the allowed range \[-0\.8, 1e\+07\]"):
        read_log(log, 4, acoustics=acoustics)
    assert read_log(log, 4, acoustics=jittered).range[1] == -1.0  # a two-way jitter measures it


# --------------------------------------------------------------------------- no ping positioned

R4 = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0]])
NAMES = ["R1", "R2", "R3", "R4"]


def _toa_files(tmp_path: Path, heard_by_one: bool) -> tuple[Path, Path, Path]:
    """40 pings of a tag inside four receivers (each heard by one receiver only, or by all), its truth and the
    receivers' file."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)
    toa, truth, emissions = tt.simulate_pings(R4, 40, s, np.random.default_rng(2), start=np.array([100.0, 75.0]),
                                              speed=0.2, detection=1.0)
    if heard_by_one:
        one = np.full_like(toa, np.nan)
        rows = np.arange(len(toa))
        one[rows, rows % 4] = toa[rows, rows % 4]
        toa = one
    pd.DataFrame(toa, columns=NAMES).to_csv(tmp_path / "toa.csv", index=False, na_rep="NA", float_format="%.9f")
    pd.DataFrame({"name": NAMES, "x_m": R4[:, 0], "y_m": R4[:, 1]}).to_csv(tmp_path / "r.csv", index=False)
    np.savetxt(tmp_path / "truth.txt", np.column_stack([truth, emissions]), header="x y t", comments="")
    return tmp_path / "toa.csv", tmp_path / "r.csv", tmp_path / "truth.txt"


def test_a_record_in_which_no_ping_can_be_positioned_is_refused_with_nothing_written(tmp_path, capsys):
    toa, receivers, truth = _toa_files(tmp_path, heard_by_one=True)
    out = tmp_path / "out"
    assert main(["replay", str(toa), "--format", "toa", "--receivers", str(receivers), "--truth", str(truth),
                 "--sound-speed", "1480", "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert "no ping could be positioned" in err and "40 pings" in err and "heard by at least 3" in err, err
    assert not out.exists()
    with pytest.raises(ModelError, match="no ping could be positioned"):
        sblsim.replay_toa(toa, receivers=receivers, sound_speed=1480.0, out=out)
    assert not out.exists()


def test_a_truth_beside_no_ping_scores_nothing_and_says_so(tmp_path, capsys):
    """A truth that ends before the first ping (inside the ±30 s the lag search allows): no ping is scored, the
    console says so instead of failing on the scores that are not there."""
    toa, receivers, truth = _toa_files(tmp_path, heard_by_one=False)
    early = tmp_path / "early.txt"
    rows = np.loadtxt(truth, skiprows=1)
    first = float(pd.read_csv(toa).min(axis=1).min())
    np.savetxt(early, np.column_stack([rows[:5, :2], first - 20.0 + np.arange(5)]), header="x y t", comments="")
    out = tmp_path / "out"
    assert main(["replay", str(toa), "--format", "toa", "--receivers", str(receivers), "--truth", str(early),
                 "--sound-speed", "1480", "--out", str(out)]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "no ping inside the truth's times" in printed and (out / "score.json").is_file(), printed


# --------------------------------------------------------------------------- a failed export


def test_a_run_whose_log_export_fails_leaves_no_run_folder(tmp_path, capsys, monkeypatch):
    """A full disk under the log (every write of it raises ENOSPC): the log's refusal, and the run's own folder not
    left behind (its files move into place only once the log is written)."""
    def full(writers, parents=True):
        def fail(tmp):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return output.write_together({path: fail for path in writers}, parents)

    monkeypatch.setattr(log_export, "write_together", full)
    # the figures stand for themselves (one file, not matplotlib's seconds): the run's folder has them all the same
    monkeypatch.setattr(plots, "save_run_figures", lambda ts, folder, **kw: (folder / "figure.png").write_bytes(b"."))
    out, log = tmp_path / "runs" / "o", tmp_path / "logs" / "log.csv"
    assert main(["run", "semicircle", "--set", "simulation.duration=2", "--out", str(out), "--export-log",
                 str(log)]) == 2
    err = _one_line(capsys)
    assert "--export-log: No space left on device; neither the log nor its truth track was written" in err, err
    assert f"nor were the run's results ({str(out)!r} is as it was)" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no run folder, no staging folder, no log folder


# --------------------------------------------------------------------------- a budget of nothing heard


def test_a_budget_whose_receiver_hears_nothing_is_refused_with_nothing_written(tmp_path, capsys):
    """lbl-field with a source level of 100 dB re 1 uPa at 1 m: no arrival is heard, the receiver makes no fix and
    has no estimate, so there is no error to share out (every row was nan +- nan, the advice a floor's)."""
    out = tmp_path / "budget"
    assert main(["budget", "lbl-field", "--set", "acoustics.source_level=100", "--set", "simulation.duration=9",
                 "--replicates", "2", "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert "heard nothing" in err and "every source on" in err and "platform.system lbl" in err, err
    assert "acoustics.source_level = 100" in err and "2 of its 2 replicates" in err, err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == []
    assert "nan" not in capsys.readouterr().out


# --------------------------------------------------------------------------- a row nobody heard, rbi


def test_a_blank_row_within_one_random_interval_is_no_ping_and_not_refused(tmp_path):
    """A random-interval tag (20-40 s) whose record holds a row nobody heard between two rows one interval apart
    (issue 87: a matrix with empty rows refused whole): a row heard by nobody is no ping (its time is unknown), so it
    makes no second interval, and the record is tracked, nothing set aside, its heard rows placed as the record
    without the blank row places them; a blank row where a ping was missed is tracked too."""
    receivers = R4
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=30.0, acceleration_psd=1e-4)
    toa, _, _ = tt.simulate_pings(receivers, 30, s, np.random.default_rng(5), start=np.array([100.0, 75.0]),
                                  speed=0.05, detection=1.0, ping_type="rbi", burst_interval=(20.0, 40.0))
    pd.DataFrame({"name": NAMES, "x_m": receivers[:, 0], "y_m": receivers[:, 1]}).to_csv(tmp_path / "r.csv",
                                                                                         index=False)
    spurious = np.insert(toa, 4, np.nan, axis=0)  # a row 5 (1-based) nobody heard, rows 4 and 6 one interval apart
    missed = toa.copy()
    missed[4] = np.nan  # ping 5 missed by every receiver: rows 4 and 6 two intervals apart
    for name, matrix in (("spurious", spurious), ("missed", missed), ("whole", toa)):
        pd.DataFrame(matrix, columns=NAMES).to_csv(tmp_path / f"{name}.csv", index=False, na_rep="NA",
                                                   float_format="%.9f")
    options = {"receivers": tmp_path / "r.csv", "sound_speed": 1480.0, "ping_type": "rbi",
               "burst_interval": (20.0, 40.0), "smooth": False}
    assert float(np.nanmin(toa[4]) - np.nanmin(toa[3])) < 40.0  # two intervals would be 40 s at least
    blank = sblsim.replay_toa(tmp_path / "spurious.csv", **options)
    assert blank.summary["pings"] == 31 and blank.summary["set_aside"]["count"] == 0
    whole = sblsim.replay_toa(tmp_path / "whole.csv", **options).estimates
    for estimator in ("fix", "ekf"):  # the EKF's prediction across the blank row composes to the one without it
        mine = blank.estimates[blank.estimates["estimator"] == estimator]
        ref = whole[whole["estimator"] == estimator]
        assert np.array_equal(mine["ping"].to_numpy(), np.where(ref["ping"] >= 4, ref["ping"] + 1, ref["ping"]))
        assert np.allclose(mine[["x", "y"]].to_numpy(), ref[["x", "y"]].to_numpy(), atol=1e-3), estimator
    assert sblsim.replay_toa(tmp_path / "missed.csv", **options).summary["pings"] == 30


# --------------------------------------------------------------------------- a long interface mismatch


def test_an_fmu_far_from_the_receiver_interface_is_refused_in_a_short_line():
    """An FMU of one unrelated input against the receiver's interface: every input and output missing. The
    refusal names the first few and counts the rest (it was one line of thousands of characters)."""
    Port = namedtuple("Port", "name causality type unit")
    expected = COMPONENTS["receiver"].fmu_variables(4)
    # an independent count: every input and output but a later lane's (an FMU without lanes may leave them out)
    # and an optional output's, and the one extra input
    problems = sum(v.causality != "parameter" and not re.match(r"lane\d+_", v.name) and v.name not in OPTIONAL_OUTPUTS
                   for v in expected) + 1
    assert problems > 20
    with pytest.raises(ConnectionMismatch) as error:
        check_interface("receiver", [Port("foreign", "input", "Real", "")], expected, "other.fmu")
    message = str(error.value)
    assert "\n" not in message and len(message) < 600, (len(message), message)
    assert message.startswith("receiver: other.fmu does not match the receiver interface: missing input")
    assert message.endswith(f"... and {problems - 5} more ({problems} in all)"), message
    assert message.count("missing ") == 5


# --------------------------------------------------------------------------- options with no effect


def test_a_depth_sigma_without_a_depth_is_refused(tmp_path, capsys):
    """--depth-sigma weighs a depth: without --tag-depth and without a depth_m column it had no effect."""
    toa, receivers, _ = _toa_files(tmp_path, heard_by_one=False)
    out = tmp_path / "out"
    assert main(["replay", str(toa), "--format", "toa", "--receivers", str(receivers), "--sound-speed", "1480",
                 "--depth-sigma", "0.5", "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert "--depth-sigma: 0.5 m has no effect" in err and "--tag-depth" in err and "depth_m" in err, err
    assert not out.exists()
    with pytest.raises(ConfigError, match="^depth_sigma: 0.5 m has no effect"):
        sblsim.replay_toa(toa, receivers=receivers, sound_speed=1480.0, depth_sigma=0.5)


def test_an_snr_key_beside_a_range_tests_curve_is_refused():
    """A telemetry design's detection curve is its range test's (detection.range_50_m and slope): the SNR model's
    keys have no effect there and are refused as the scenario keys of another detection are; with the SNR model
    (tag.source_level_db, no range test) they are taken."""
    with pytest.raises(ConfigError, match=r"^detection\.frequency_hz: 30000\.0 has no effect") as error:
        check_problem(problem_with(SMALL, detection={"frequency_hz": 30000.0}))
    assert "the detection curve is the range test's" in str(error.value) and "\n" not in str(error.value)
    snr = problem_with(SMALL, detection={"range_50_m": 0.0, "slope": 0.0, "frequency_hz": 30000.0},
                       tag={"source_level_db": 150.0})
    assert check_problem(snr)["detection"]["frequency_hz"] == 30000.0
