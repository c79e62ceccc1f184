"""``sblsim replay`` and ``sblsim run --export-log`` (docs/log-format.md).

* export-then-replay equals the run, every receiver, SBL, LBL and USBL, on both engines, from CSV and
  Parquet, with a rate ratio above 1 and the Jacobi master;
* a replay with another receiver than the exported run's equals a run with that receiver;
* every kind of flaw of a real log gets its decision: refused (one line naming the line and column, exit 2,
  nothing written) or skipped / sorted with a count;
* a truth track on another time grid is interpolated at the replay's steps, not misaligned.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models import RECEIVERS
from sblsim.models.systems import SYSTEMS as SYSTEMS_BY_NAME
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config, to_toml
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.io.manifest import MANIFEST
from sblsim.orchestrator.logs.configuration import replay_config
from sblsim.orchestrator.logs.log_export import export_log, truth_path
from sblsim.orchestrator.logs.receiver_log import read_log
from sblsim.orchestrator.logs.replay import replay
from sblsim.orchestrator.logs.truth_track import read_truth

TOL = 1e-9  # [m]
#: The receiver's outputs compared with the run's.
OUTPUTS = ("est_x", "est_y", "est_z", "est_vx", "est_vy", "est_vz", "instr_x", "instr_y", "instr_z", "instr_valid",
           "nis", "pos_std", "cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz", "gated")
#: 15 s of the harbour (50 % loss), with multipath so that the gates act.
HARBOUR = ["simulation.duration=15", "acoustics.outlier_pct=10"]
SYSTEMS = {"sbl": [], "lbl": ["platform.system=lbl"], "usbl": ["platform.system=usbl"]}


def replay_file(path: Path, engine: str = "local", receiver: str | None = None, fmu_dir=None, truth=True,
                config=None):
    cfg, _ = replay_config(path, config, receiver)
    log = read_log(path, make_plan(cfg).n_beacons, SYSTEMS_BY_NAME[cfg["platform"]["system"]],
                   cfg["acoustics"]["sound_speed_assumed"])
    return replay(log, cfg, engine, fmu_dir, read_truth(truth_path(path)) if truth else None)


def assert_same_receiver(run_series: pd.DataFrame, replayed: pd.DataFrame) -> None:
    assert len(replayed) == len(run_series)
    np.testing.assert_array_equal(replayed["time"].to_numpy(), run_series["time"].to_numpy())
    for name in OUTPUTS:
        np.testing.assert_allclose(replayed[name].to_numpy(dtype=float), run_series[name].to_numpy(dtype=float),
                                   rtol=0, atol=TOL, err_msg=name)


def export(tmp_path: Path, overrides, engine="local", suffix=".csv", fmu_dir=None, name="log"):
    cfg = load_config("harbour", [*HARBOUR, *overrides], seed=3)
    result = run(cfg, engine, fmu_dir=fmu_dir)
    path = tmp_path / f"{name}{suffix}"
    export_log(result, path)
    return result, path


# --------------------------------------------------------------------------- export, then replay

def shifted_times(line: str, offset: float) -> str:
    """A line of an exported CSV log with its times (``time_s``, ``rx_time``: the first two cells) on a clock
    ``offset`` [s] later."""
    sent, arrival, rest = line.split(",", 2)
    return f"{float(sent) + offset!r},{float(arrival) + offset!r},{rest}"


@pytest.mark.slow
@pytest.mark.parametrize("system", list(SYSTEMS))
@pytest.mark.parametrize("receiver", list(RECEIVERS))
def test_export_then_replay_equals_the_run(tmp_path, receiver, system):
    result, path = export(tmp_path, [*SYSTEMS[system], f"receiver={receiver}"])
    assert not result.timeseries["packet_valid"].all()  # lost packets: depth-only rows
    replayed = replay_file(path)
    assert_same_receiver(result.timeseries, replayed.timeseries)
    # with the run's own truth on the run's grid, the metrics are the run's
    for key in ("e_tot_mean", "e_tot_std", "instr_e_tot_mean", "instr_e_tot_std", "nees_mean", "coverage_95",
                "nis_mean", "gated_pct", "pcrb_rms", "updates", "fix_steps"):
        assert replayed.summary[key] == pytest.approx(result.metrics.iloc[0][key], rel=0, abs=1e-12), key
    log = replayed.summary["log"]
    seq = result.timeseries["packet_seq"]
    delivered = int((seq != seq.shift(fill_value=0)).sum())  # a row per packet the run delivered
    assert log["rows"] == log["used"] == delivered >= len(result.timeseries) - 1
    assert log["depth_only"] == int((~result.timeseries["packet_valid"][seq != seq.shift(fill_value=0)]).sum())
    assert log["duplicate"] == log["unknown_beacon"] == log["same_step"] == log["out_of_order"] == 0


#: Slots shorter than the longest travel time (5.2 ms): packets arrive two in a step (lanes).
CROWDED = ["simulation.sampling_time=0.005", "simulation.duration=3"]


@pytest.mark.parametrize("overrides", [["simulation.ekf_rate_ratio=3"], ["simulation.master=jacobi"],
                                       ["platform.system=usbl", "simulation.ekf_rate_ratio=2"], CROWDED,
                                       [*CROWDED, "simulation.ekf_rate_ratio=3"],
                                       [*CROWDED, "simulation.master=jacobi"]],
                         ids=["ratio3", "jacobi", "usbl-ratio2", "lanes", "lanes-ratio3", "lanes-jacobi"])
def test_export_then_replay_equals_the_run_on_other_grids(tmp_path, overrides):
    """On other grids, and where several packets arrive in one step (the lanes of a delivery: each exported as a
    row, in the order of arrival, and shown together again by the replay)."""
    result, path = export(tmp_path, [*overrides, "receiver=ekf-seq"])
    replayed = replay_file(path)
    assert_same_receiver(result.timeseries, replayed.timeseries)
    if overrides[:len(CROWDED)] == CROWDED:
        lanes = [c for c in result.timeseries if c.startswith("lane") and c.endswith("_packet_seq")]
        assert lanes, "no step delivered two packets"
        assert replayed.summary["log"]["same_step"] == 0
        if "simulation.master=jacobi" not in overrides:  # (a Jacobi replay records what the receiver was handed)
            assert replayed.summary["updates"] == result.metrics.iloc[0]["updates"]


@pytest.mark.parametrize("system", ["sbl", "usbl"])
def test_a_parquet_log_replays_as_its_csv(tmp_path, system):
    result, path = export(tmp_path, [*SYSTEMS[system], "receiver=ukf"], suffix=".parquet")
    assert truth_path(path).name == "log_truth.parquet" and truth_path(path).is_file()
    assert_same_receiver(result.timeseries, replay_file(path).timeseries)


@pytest.mark.parametrize("receiver", ["ekf-seq", "ukf", "lsq"])
def test_a_log_replayed_with_another_receiver_equals_a_run_with_it(tmp_path, receiver):
    """The receiver draws no random numbers and does not act on the channel: a log of the ekf's run replayed
    with another receiver is that receiver's run (its own defaults, e.g. ekf-seq's gate, not the ekf's)."""
    _, path = export(tmp_path, [])
    other = run(load_config("harbour", [*HARBOUR, f"receiver={receiver}"], seed=3))
    replayed = replay_file(path, receiver=receiver)
    assert replayed.config["simulation"]["receiver"] == receiver
    assert replayed.config["receiver"] == other.config["receiver"]
    assert_same_receiver(other.timeseries, replayed.timeseries)


def test_a_user_model_receiver_replays_its_run(tmp_path):
    """A log never names the program a replay runs: the user's model is given again (--receiver)."""
    model = f"model:{Path(__file__).resolve().parents[2] / 'docs' / 'examples' / 'constant_position.py'}"
    result, path = export(tmp_path, [f"receiver={model}"])
    assert_same_receiver(result.timeseries, replay_file(path, receiver=model).timeseries)


@pytest.mark.slow
@pytest.mark.parametrize("system", list(SYSTEMS))
@pytest.mark.parametrize("receiver", list(RECEIVERS))
def test_export_then_replay_equals_the_run_on_the_fmu_engine(tmp_path, fmu_dir, receiver, system):
    result, path = export(tmp_path, [*SYSTEMS[system], f"receiver={receiver}"], "fmu", fmu_dir=fmu_dir)
    replayed = replay_file(path, "fmu", fmu_dir=fmu_dir)
    assert replayed.engine == "fmu"
    assert_same_receiver(result.timeseries, replayed.timeseries)
    local = run(load_config("harbour", [*HARBOUR, *SYSTEMS[system], f"receiver={receiver}"], seed=3))
    assert_same_receiver(local.timeseries, replayed.timeseries)


def test_a_receiver_fmu_replays_its_run(tmp_path, fmu_dir):
    fmu = fmu_dir / "sblsim_receiver_ekf_seq.fmu"
    result, path = export(tmp_path, [f"receiver=fmu:{fmu}"])
    assert_same_receiver(result.timeseries, replay_file(path, receiver=f"fmu:{fmu}").timeseries)


def test_a_log_on_another_clock_replays_the_same(tmp_path):
    """Times of a clock far from 0 (here 2**20 s): the receiver runs on times from the log's start."""
    result, path = export(tmp_path, ["receiver=ekf-seq"])
    lines = path.read_text().splitlines()
    header = next(k for k, line in enumerate(lines) if not line.startswith("#"))
    shifted = lines[:header + 1] + [shifted_times(line, 2.0**20) for line in lines[header + 1:]]
    moved = tmp_path / "moved.csv"
    moved.write_text("\n".join(shifted) + "\n")
    replayed = replay_file(moved, truth=False)
    assert replayed.timeseries["time"].iloc[0] == pytest.approx(2.0**20 + 0.1, abs=1e-6)
    for name in OUTPUTS:
        np.testing.assert_allclose(replayed.timeseries[name].to_numpy(dtype=float),
                                   result.timeseries[name].to_numpy(dtype=float), rtol=0, atol=TOL, err_msg=name)


def test_travel_times_with_the_hardware_sound_speed_give_the_ranges(tmp_path):
    """travel_time_s with a sound_speed_mps column: range = sound speed · travel time (here 1480 m/s, not the
    configuration's 1500); a log that is not an export (pandas' CSV) carries no configuration: --config."""
    result, path = export(tmp_path, ["receiver=ekf-seq"])
    frame = pd.read_csv(path, comment="#")
    frame["sound_speed_mps"] = 1480.0
    frame["travel_time_s"] = frame.pop("range_m") / 1480.0
    frame["beacon_id"] = frame["beacon_id"].astype("Int64")
    travel = tmp_path / "travel.csv"
    frame.to_csv(travel, index=False)
    config = tmp_path / "config.toml"
    config.write_text(to_toml(result.config))
    replayed = replay_file(travel, truth=False, config=str(config))
    for name in ("est_x", "est_y", "est_z"):
        np.testing.assert_allclose(replayed.timeseries[name], result.timeseries[name], rtol=0, atol=TOL)


# --------------------------------------------------------------------------- the truth track

def test_a_truth_track_on_another_grid_is_interpolated_not_misaligned(tmp_path):
    """A truth track sampled at 37 ms from 0.013 s, of a diver moving on a straight line: the replay's truth at
    each step's end is the line's position then (to rounding), and the errors are against it."""
    _, path = export(tmp_path, [])
    t = 0.013 + 0.037 * np.arange(500)
    velocity, start = np.array([0.3, -0.2, 0.01]), np.array([-5.0, -5.0, 2.0])
    track = start + t[:, None] * velocity
    truth = tmp_path / "rtk.csv"
    truth.write_text("# a truth track on its own grid\ntime_s,n_m,e_m,d_m\n"
                     + "".join(",".join(repr(float(v)) for v in (a, *p)) + "\n" for a, p in zip(t, track)))
    cfg, _ = replay_config(path)
    log = read_log(path, make_plan(cfg).n_beacons)
    result = replay(log, cfg, truth=read_truth(truth))
    ts = result.timeseries
    expected = start + ts["time"].to_numpy()[:, None] * velocity
    inside = (ts["time"] >= t[0]) & (ts["time"] <= t[-1])
    assert inside.all()  # 0.1 … 15 s lies within 0.013 … 18.5 s
    np.testing.assert_allclose(ts[["true_x", "true_y", "true_z"]].to_numpy(), expected, rtol=0, atol=1e-12)
    error = np.linalg.norm(expected - ts[["est_x", "est_y", "est_z"]].to_numpy(), axis=1)
    np.testing.assert_allclose(ts["e_tot"], error, rtol=0, atol=1e-12)  # NaN at the same steps: before the first fix
    assert result.summary["e_tot_mean"] == pytest.approx(np.nanmean(error), rel=1e-12)
    assert result.summary["truth"] == {"steps": len(ts), "steps_without": 0}


def test_steps_outside_the_truth_span_have_no_errors(tmp_path):
    result, path = export(tmp_path, [])
    ts = result.timeseries
    part = tmp_path / "part.csv"
    keep = ts[(ts["time"] > 4.95) & (ts["time"] < 10.05)]
    keep[["time", "true_x", "true_y", "true_z"]].set_axis(["time_s", "n_m", "e_m", "d_m"], axis=1).to_csv(
        part, index=False)
    cfg, _ = replay_config(path)
    replayed = replay(read_log(path, 4), cfg, truth=read_truth(part))
    rts = replayed.timeseries
    inside = (rts["time"] > 4.95) & (rts["time"] < 10.05)
    assert replayed.summary["truth"] == {"steps": int(inside.sum()), "steps_without": int((~inside).sum())}
    assert rts.loc[~inside, ["true_x", "e_tot", "instr_e_tot", "pcrb"]].isna().all().all()
    np.testing.assert_allclose(rts.loc[inside, "e_tot"], ts.loc[inside.to_numpy(), "e_tot"], rtol=0, atol=1e-12)
    assert replayed.summary["e_tot_mean"] == pytest.approx(ts.loc[inside.to_numpy(), "e_tot"].mean(), rel=1e-12)
    assert replayed.summary["diverged"] is False


# --------------------------------------------------------------------------- the command line

@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    base = tmp_path_factory.mktemp("replay_cli")
    assert main(["run", "harbour", "--set", "simulation.duration=10", "--out", str(base / "run"),
                 "--export-log", str(base / "h.csv")]) == 0
    return base


def test_run_export_log_writes_the_log_and_its_truth(exported):
    text = (exported / "h.csv").read_text()
    assert text.startswith("# sblsim log, format 1\n") and "docs/log-format.md" in text
    frame = pd.read_csv(exported / "h.csv", comment="#")
    assert list(frame.columns) == ["time_s", "rx_time", "beacon_id", "range_m", "beacon_n_m", "beacon_e_m",
                                   "beacon_d_m", "depth_m"]
    # a row per packet delivered: the last one sent is still in flight when the run ends
    assert len(frame) == 99 and frame["beacon_id"].isna().any()
    assert (frame["rx_time"] > frame["time_s"]).all() and (np.diff(frame["rx_time"]) > 0).all()
    assert frame.loc[frame["beacon_id"].isna(), ["range_m", "beacon_n_m"]].isna().all().all()
    truth = pd.read_csv(exported / "h_truth.csv", comment="#")
    assert list(truth.columns) == ["time_s", "n_m", "e_m", "d_m"] and len(truth) == 100


def test_run_export_log_refuses_an_existing_file_before_any_work(exported, capsys):
    out = exported / "again"
    assert main(["run", "harbour", "--set", "simulation.duration=10", "--out", str(out),
                 "--export-log", str(exported / "h.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sblsim: error: --export-log:") and "--force" in err and len(err.splitlines()) == 1
    assert not out.exists()
    assert main(["run", "harbour", "--out", str(out), "--export-log", str(exported / "h.txt")]) == 2
    assert ".csv or .parquet" in capsys.readouterr().err and not out.exists()


def test_replay_command_writes_the_outputs_of_a_run(exported, capsys):
    out = exported / "replay"
    capsys.readouterr()
    assert main(["replay", str(exported / "h.csv"), "--receiver", "ekf-seq", "--truth",
                 str(exported / "h_truth.csv"), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "receiver ekf-seq" in printed and "99 rows, 99 used" in printed and "e_tot mean" in printed
    names = {p.name for p in out.iterdir()}
    assert names == {"summary.json", "config.toml", "timeseries.parquet", "trajectory_xy.png", "trajectory_3d.png",
                     "errors.png", "error_bounds.png", MANIFEST}
    s = json.loads((out / "summary.json").read_text())
    assert s["receiver"] == "ekf-seq" and s["steps"] == 100 and s["e_tot_mean"] > 0
    assert s["log"]["file"] == "h.csv" and s["truth"] == {"steps": 100, "steps_without": 0}
    run_series = run(load_config("harbour", ["simulation.duration=10", "receiver=ekf-seq"])).timeseries
    assert_same_receiver(run_series, pd.read_parquet(out / "timeseries.parquet"))
    # again into the same folder: refused; without --out, numbered folders
    assert main(["replay", str(exported / "h.csv"), "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err


def test_a_replay_s_figures_are_the_ones_it_writes(exported):
    """``ReplayResult.plot()`` makes the figures ``sblsim replay --truth`` writes (the receiver's label from the plan
    the replay ran), none without a truth track."""
    import matplotlib.pyplot as plt

    from sblsim import replay

    result = replay(exported / "h.csv", receiver="ekf", truth=exported / "h_truth.csv")
    figures = result.plot()
    assert {f"{name}.png" for name in figures} == {"trajectory_xy.png", "trajectory_3d.png", "errors.png",
                                                   "error_bounds.png"}
    for figure in figures.values():
        plt.close(figure)
    assert replay(exported / "h.csv", receiver="ekf").plot() == {}

def test_replay_without_truth_writes_the_track(exported, capsys):
    out = exported / "notruth"
    assert main(["replay", str(exported / "h.csv"), "--out", str(out)]) == 0
    assert "no truth track" in capsys.readouterr().out
    assert {p.name for p in out.iterdir()} == {"summary.json", "config.toml", "timeseries.parquet",
                                               "trajectory_xy.png", MANIFEST}
    s = json.loads((out / "summary.json").read_text())
    assert s["e_tot_mean"] is None and s["nees_mean"] is None and s["diverged"] is None and s["truth"] is None
    assert s["updates"] > 0 and s["nis_mean"] > 0


def test_replay_config_precedence(exported, tmp_path):
    cfg, source = replay_config(exported / "h.csv")
    assert cfg["run"]["scenario"] == "harbour" and "log's own" in source
    cfg, source = replay_config(exported / "h.csv", "square")
    assert cfg["run"]["scenario"] == "square" and source == "--config square"
    bare = tmp_path / "bare.csv"
    bare.write_text("time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n0.1,1,5,1,0,1,2\n")
    cfg, source = replay_config(bare, None, "lsq", ["receiver.sigma_range=0.3"])
    assert cfg["run"]["scenario"] == "semicircle" and cfg["simulation"]["receiver"] == "lsq"
    assert cfg["receiver"]["sigma_range"] == 0.3 and "semicircle" in source


# --------------------------------------------------------------------------- flaws of a real log

HEADER = "time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n"


def rows(*items: str) -> str:
    return HEADER + "".join(f"{item}\n" for item in items)


GOOD = [f"{0.1 * k:.1f},{(k - 1) % 4 + 1},{6 + 0.01 * k},1,0,1,2" for k in range(1, 41)]

#: case -> (file text, text the one-line error holds)
REFUSED = {
    "text in a number": (rows(*GOOD[:5], "0.6,2,abc,1,0,1,2", *GOOD[6:]), "line 7: range_m: 'abc' is not a number"),
    "field count": (rows(*GOOD[:3], "0.4,4,6,1,0,1", *GOOD[4:]), "line 5 has 6 fields, the header 7"),
    "nan depth": (rows(*GOOD[:2], "0.3,3,6,1,0,1,nan", *GOOD[3:]), "line 4: depth_m: 'nan' is not a finite number"),
    "empty time": (rows(",1,6,1,0,1,2", *GOOD), "line 2: time_s is empty"),
    "empty range on a packet row": (rows(*GOOD[:1], "0.2,2,,1,0,1,2"), "line 3: range_m is empty"),
    "empty depth on a depth row": (rows(*GOOD[:1], "0.2,,,,,,"), "line 3: depth_m is empty"),
    "range beyond the input range": (rows(*GOOD[:1], "0.2,2,-2e7,1,0,1,2"), "line 3: range_m: -20000000 is outside"),
    # the semicircle's one-way channel (sigma_range 0.1 m, no jitter, no drift) measures no range below -8 * 0.1 m
    "range below what the channel measures": (rows(*GOOD[:1], "0.2,2,-1,1,0,1,2"),
                                              "line 3: range_m: -1 is outside the allowed range [-0.8, 1e+07]"),
    "travel time below what the channel measures": (
        "time_s,beacon_id,travel_time_s,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n0.1,1,0.004,1,0,1,2\n"
        "0.2,2,-0.001,1,0,1,2\n", "line 3: travel_time_s: -0.001 is outside the allowed range [-0.000533333"),
    "infinite beacon position": (rows("0.1,1,6,inf,0,1,2"), "line 2: beacon_n_m: 'inf' is not a finite number"),
    "missing column": ("time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,depth_m\n0.1,1,6,1,0,2\n",
                       "has no column beacon_d_m"),
    "no range column": ("time_s,beacon_id,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n0.1,1,1,0,1,2\n",
                        "neither of range_m and travel_time_s"),
    "range and travel time": ("time_s,beacon_id,range_m,travel_time_s,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n"
                              "0.1,1,6,0.004,1,0,1,2\n", "both range_m and travel_time_s"),
    "column twice": ("time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m,depth_m\n",
                     "the column 'depth_m' is given twice"),
    "clock jump back": (rows(*GOOD[:20], "0.5,1,6,1,0,1,2", *GOOD[20:]),
                        "line 22: time_s 0.5 s is 1.5 s before line 21's 2 s: a clock jump back"),
    "clock jump forward": (rows(*GOOD[:10], "1e11,1,6,1,0,1,2"), "(a clock jump forward?)"),
    "only a header": (HEADER, "has no row to replay"),
    "only unknown beacons": (rows("0.1,7,6,1,0,1,2", "0.2,0,6,1,0,1,2"), "has no row to replay"),
    "empty file": ("", "holds no header line"),
    "only comments": ("# sblsim log, format 1\n# nothing else\n", "holds no header line"),
    "NUL byte": (rows(*GOOD[:2]) + "0.3,3,6\x00,1,0,1,2\n", "line 4"),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_flawed_log_is_refused_with_one_line(tmp_path, capsys, case):
    text, needle = REFUSED[case]
    log = tmp_path / "flawed.csv"
    log.write_text(text)
    out = tmp_path / "out"
    assert main(["replay", str(log), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("sblsim: error: "), err
    assert "Traceback" not in err and needle in err, (needle, err)
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["flawed.csv"]


def test_a_log_that_is_not_text_or_not_parquet_is_refused(tmp_path, capsys):
    (tmp_path / "binary.csv").write_bytes(b"\xff\xfe\x00\x01garbage")
    (tmp_path / "broken.parquet").write_bytes(b"PAR1 not really")
    (tmp_path / "log.txt").write_text(HEADER)
    for name, needle in (("binary.csv", "not UTF-8 text"), ("broken.parquet", "not a readable Parquet file"),
                         ("log.txt", "must be a .csv or .parquet file"), ("none.csv", "no such file")):
        assert main(["replay", str(tmp_path / name), "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and needle in err, err
    assert not (tmp_path / "out").exists()


def test_a_flawed_truth_track_is_refused(tmp_path, capsys):
    log = tmp_path / "log.csv"
    log.write_text(rows(*GOOD))
    cases = {"back.csv": ("time_s,n_m,e_m,d_m\n0,0,0,1\n1,0,0,1\n1,0,0,1\n", "line 4: time_s 1 s does not come after"),
             "cols.csv": ("time,n,e,d\n0,0,0,1\n1,0,0,1\n", "has no column time_s"),
             "one.csv": ("time_s,n_m,e_m,d_m\n0,0,0,1\n", "needs at least two"),
             "text.csv": ("time_s,n_m,e_m,d_m\n0,0,0,1\n1,x,0,1\n", "line 3: n_m: 'x' is not a number"),
             "elsewhere.csv": ("time_s,n_m,e_m,d_m\n100,0,0,1\n101,0,0,1\n", "cover no step of the log")}
    for name, (text, needle) in cases.items():
        (tmp_path / name).write_text(text)
        assert main(["replay", str(log), "--truth", str(tmp_path / name), "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and needle in err, (name, err)
    assert not (tmp_path / "out").exists()


def test_skipped_and_sorted_rows_are_counted(tmp_path, capsys):
    """Duplicates, unknown beacon ids (0, 5 with 4 beacons, 2.5, a name), rows out of order within the window
    and nine rows in one step (one more than the lanes of a delivery): skipped or sorted, each counted on the
    command line and in summary.json; a gap is stepped through and reported; an unknown column is ignored and
    listed."""
    body = list(GOOD)
    body[10], body[11] = body[11], body[10]  # out of order by one slot
    body.insert(5, body[4])  # a duplicate
    crowd = [f"4.0{j},{j % 4 + 1},{6.2 + 0.01 * j:.2f},1,0,1,2" for j in range(1, 9)]  # 4.01 … 4.08 s
    body += [*crowd, "4.1,2,6.41,1,0,1,2",  # nine rows in the step that ends at 4.1 s
             "4.1,0,6,1,0,1,2", "4.1,5,6,1,0,1,2", "4.1,2.5,6,1,0,1,2", "4.1,B,6,1,0,1,2",  # unknown beacons
             "9.0,2,6.5,1,0,1,2"]  # after a gap of 4.9 s
    text = HEADER.replace("depth_m", "depth_m,temperature_c").replace("\n", "") + "\n" + "".join(
        f"{line},12.5\n" for line in body)
    log = tmp_path / "flawed.csv"
    log.write_text(text)
    out = tmp_path / "out"
    assert main(["replay", str(log), "--config", "harbour", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert "1 duplicated, 4 with an unknown beacon id, 1 in a step that used 8 newer rows" in captured.out
    assert "1 out of order (sorted)" in captured.out
    assert "rows every 0.1 s (median), the longest gap 4.9 s (before its line 56)" in captured.out
    assert "ignored columns: temperature_c" in captured.out
    assert "smaller simulation.sampling_time" in captured.err
    s = json.loads((out / "summary.json").read_text())["log"]
    assert s == {"file": "flawed.csv", "rows": 55, "unknown_beacon": 4, "duplicate": 1, "out_of_order": 1,
                 "used": 49, "depth_only": 0, "same_step": 1, "not_reached": 0,
                 "typical_gap_s": pytest.approx(0.1), "longest_gap_s": pytest.approx(4.9),
                 "longest_gap_before": "line 56", "ignored_columns": ["temperature_c"]}
    ts = pd.read_parquet(out / "timeseries.parquet")
    assert len(ts) == 90 and ts["time"].iloc[-1] == pytest.approx(9.0)
    # the step of 4.1 s showed its eight newest rows on the lanes in time order (4.02 … 4.1 s; 4.01 s skipped), the
    # sorted rows in time order
    step = ts.loc[ts["time"].round(6) == 4.1]
    assert step["range"].item() == pytest.approx(6.22)
    assert [step[f"lane{m}_range"].item() for m in range(2, 9)] == pytest.approx([6.23, 6.24, 6.25, 6.26, 6.27,
                                                                                  6.28, 6.41])
    np.testing.assert_allclose(ts["tx_time"].iloc[9:12], [1.0, 1.1, 1.2])


def test_depth_only_rows_update_with_the_depth(tmp_path):
    """A depth sensor's rows between packets are slots without a packet: the estimate's depth follows them."""
    lines = [HEADER.rstrip()]
    for k in range(1, 101):
        t = 0.1 * k
        lines.append(f"{t!r},{(k - 1) % 4 + 1 if k % 5 == 0 else ''},6,1,0,1,{2.0 + 0.01 * k!r}"
                     if k % 5 == 0 else f"{t!r},,,,,,{2.0 + 0.01 * k!r}")
    log = tmp_path / "depth.csv"
    log.write_text("\n".join(lines) + "\n")
    cfg, _ = replay_config(log, "harbour")
    result = replay(read_log(log, 4), cfg)
    assert result.summary["log"]["depth_only"] == 80
    assert abs(result.timeseries["est_z"].iloc[-1] - 3.0) < 0.05


def test_a_usbl_log_needs_its_angles(tmp_path, capsys):
    log = tmp_path / "usbl.csv"
    log.write_text(rows(*GOOD[:4]))
    assert main(["replay", str(log), "--config", "harbour", "--set", "platform.system=usbl",
                 "--out", str(tmp_path / "out")]) == 2
    assert "has no column azimuth_rad (a USBL log)" in capsys.readouterr().err


# --------------------------------------------------------------------------- docs/replay.md's worked example

def test_the_readme_table_2_comparison_is_what_the_replays_give(tmp_path):
    """docs/replay.md's Table-2-style rows (harbour, seed 1, a log replayed with each receiver against its truth)."""
    readme = (Path(__file__).resolve().parents[2] / "docs" / "replay.md").read_text()
    section = readme[readme.index("## Replay a recorded log"):]
    section = re.sub(r" ?<!--.*?-->", "", section[:section.index("\n## ")])  # the figures' markers (page_figures)
    table = {line.split("|")[1].strip(): [float(v) for v in line.split("|")[2:4]]
             for line in section.splitlines() if line.startswith("| ") and line.count("|") == 4
             and line.split("|")[2].strip()[:1].isdigit()}
    assert set(table) == {"instrumentation (raw multilateration fix)", "ekf (the paper's filter)", "ekf-seq", "ukf",
                          "lsq"}
    result = run(load_config("harbour", seed=1))
    path = tmp_path / "harbour.csv"
    export_log(result, path)
    assert f"{int((~result.timeseries['packet_valid']).sum())} of 800 packets lost" in section
    for receiver in RECEIVERS:
        s = replay_file(path, receiver=receiver).summary
        label = "ekf (the paper's filter)" if receiver == "ekf" else receiver
        assert table[label] == [round(s["e_tot_mean"], 3), round(s["e_tot_std"], 3)], receiver
        assert table["instrumentation (raw multilateration fix)"] == [round(s["instr_e_tot_mean"], 3),
                                                                      round(s["instr_e_tot_std"], 3)]


def test_the_log_format_document_lists_every_column():
    from sblsim.orchestrator.logs.receiver_log import LOG_COLUMNS
    from sblsim.orchestrator.logs.truth_track import TRUTH_COLUMNS

    text = (Path(__file__).resolve().parents[2] / "docs" / "log-format.md").read_text()
    for name in [*LOG_COLUMNS, *TRUTH_COLUMNS]:
        assert f"`{name}`" in text, name


# --------------------------------------------------------------------------- latency, clocks, the text itself

@pytest.mark.parametrize("latency", [0.1, 1.0, 2.5])
def test_a_log_of_a_run_with_latency_replays_to_the_run(tmp_path, latency):
    """The replay delays the receiver's outputs by receiver.latency as the run does (the log's configuration
    carries it): the time series and the metrics are the run's."""
    result, path = export(tmp_path, [f"receiver.latency={latency}", "receiver=ekf-seq"])
    undelayed = run(load_config("harbour", [*HARBOUR, "receiver=ekf-seq"], seed=3))
    assert np.abs(undelayed.timeseries["est_x"] - result.timeseries["est_x"]).max() > 1e-3  # the delay shows
    replayed = replay_file(path)
    assert replayed.config["receiver"]["latency"] == latency
    assert_same_receiver(result.timeseries, replayed.timeseries)
    for key in ("e_tot_mean", "nees_mean", "coverage_95", "fix_steps", "updates"):
        assert replayed.summary[key] == pytest.approx(result.metrics.iloc[0][key], rel=0, abs=1e-12), key


@pytest.mark.parametrize("offset", [1.7e9, 1_700_000_123.4, 3.0e10])
def test_a_log_in_unix_time_replays_to_the_run(tmp_path, offset):
    """Stamps near 1.7e9 s are resolved to 2.4e-7 s only (float64): no row is dropped or moved a step, and the
    receiver's outputs are the run's."""
    result, path = export(tmp_path, ["receiver=ekf-seq"])
    lines = path.read_text().split("\n")
    header = next(k for k, line in enumerate(lines) if line and not line.startswith("#"))
    shifted = lines[:header + 1] + [shifted_times(line, offset) for line in lines[header + 1:] if line]
    moved = tmp_path / "unix.csv"
    moved.write_text("\n".join(shifted) + "\n")
    replayed = replay_file(moved, truth=False)
    log = replayed.summary["log"]
    assert log["used"] == log["rows"] == len(result.timeseries) - 1 and log["same_step"] == 0  # the first
    # step's packet arrives in the second
    assert len(replayed.timeseries) == len(result.timeseries)
    np.testing.assert_allclose(replayed.timeseries["time"].to_numpy() - offset, result.timeseries["time"].to_numpy(),
                               rtol=0, atol=1e-5)
    # the stamps resolve an arrival to spacing(offset) s only, and ekf-seq moves a range back by its age (from
    # tx_time and rx_time) at the diver's speed (below 1 m/s): the estimates agree to that
    tol = max(TOL, 4.0 * float(np.spacing(offset)) * 1.0)
    for name in OUTPUTS:
        np.testing.assert_allclose(replayed.timeseries[name].to_numpy(dtype=float),
                                   result.timeseries[name].to_numpy(dtype=float), rtol=0, atol=tol, err_msg=name)


def test_stamps_too_coarse_for_the_sampling_time_are_refused(tmp_path, capsys):
    log = tmp_path / "coarse.csv"
    log.write_text(HEADER + "".join(f"{2e11 + 0.001 * k!r},1,6,1,0,1,2\n" for k in range(5)))
    assert main(["replay", str(log), "--set", "simulation.sampling_time=0.001", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "too coarse for simulation.sampling_time = 0.001 s" in err, err


def test_a_line_separator_in_a_comment_does_not_split_the_line(tmp_path, capsys):
    """U+2028 (and other boundaries str.splitlines knows) inside a comment: one line, as an editor shows it,
    so a valid log replays and a bad line is named by its real number."""
    text = f"# a comment\u2028with a line separator\x0cand a form feed\n{HEADER}" + "".join(f"{g}\n" for g in GOOD[:20])
    good = tmp_path / "sep.csv"
    good.write_text(text)
    assert main(["replay", str(good), "--out", str(tmp_path / "o")]) == 0
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["log"]["rows"] == 20
    bad = tmp_path / "sep_bad.csv"
    cells = GOOD[4].split(",")
    bad.write_text(text.replace(GOOD[4], ",".join([*cells[:2], "6x", *cells[3:]])), newline="\r\n")
    capsys.readouterr()
    assert main(["replay", str(bad), "--out", str(tmp_path / "o2")]) == 2
    assert "line 7: range_m: '6x' is not a number" in capsys.readouterr().err  # comment, header, 5th row


def test_a_parquet_log_whose_pandas_metadata_disagrees_reads_its_cells(tmp_path):
    """beacon_id stored as text while the pandas metadata says int64: the cells are read as a CSV's are."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    result, path = export(tmp_path, ["receiver=ekf-seq"], suffix=".parquet")
    table = pq.read_table(path)
    ids = pa.array([None if v is None else str(v) for v in table.column("beacon_id").to_pylist()], pa.string())
    text = table.set_column(table.column_names.index("beacon_id"), "beacon_id", ids)
    meta = json.loads(table.schema.metadata[b"pandas"])
    assert any(c["name"] == "beacon_id" and c["pandas_type"] != "unicode" for c in meta["columns"])
    strings = tmp_path / "strings.parquet"
    pq.write_table(text.replace_schema_metadata(table.schema.metadata), strings)
    with pytest.raises(TypeError):  # what reading it through pandas did
        pq.read_table(strings).to_pandas()
    assert_same_receiver(result.timeseries, replay_file(strings, truth=False).timeseries)


def test_a_log_the_memory_here_cannot_hold_is_refused_before_it_is_read(tmp_path, capsys, monkeypatch):
    """A log of any length is read in pieces; one whose rows would not fit in the memory here (made small) is refused
    before it is read, in one line, nothing written: a CSV file by its lines, a Parquet file by its footer's rows."""
    from sblsim.orchestrator.logs import receiver_log

    log = tmp_path / "many.csv"
    log.write_text(HEADER + "".join(f"{0.1 * k!r},1,6,1,0,1,2\n" for k in range(1, 12)))
    parquet = tmp_path / "many.parquet"
    pd.read_csv(log).to_parquet(parquet)
    monkeypatch.setattr(receiver_log, "available_memory", lambda: 10 * receiver_log.LOG_ROW_BYTES)
    for path, rows in ((log, log.read_text().count("\n")), (parquet, 11)):
        assert main(["replay", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and f"{str(path)!r} holds up to {rows} rows" in err, err
        assert "is available here: read it on a machine with more memory, or in parts" in err
    assert not (tmp_path / "o").exists()
    monkeypatch.setattr(receiver_log, "available_memory", lambda: 100 * receiver_log.LOG_ROW_BYTES)
    assert main(["replay", str(log), "--out", str(tmp_path / "o")]) == 0


def test_the_documented_log_limits_are_the_code_s():
    from sblsim.orchestrator.io.tables import MAX_LINE_BYTES, MAX_LINE_CELLS

    doc = (Path(__file__).resolve().parents[2] / "docs" / "log-format.md").read_text()
    assert f"**{MAX_LINE_BYTES // 2**20} MiB**" in doc and f"**{MAX_LINE_CELLS}** cells" in doc
