"""The readers' bounds are by shape, not by size (orchestrator/io/log_tables.py): a calibration log, a replay's log
and its truth track are read in pieces of bounded memory whatever their length, a line too long or too wide is
refused in one line in whichever piece it lies (counted to its end without being held), and a log is refused only
where the memory here cannot hold its rows, said before it is read.

The fast tests read small files in pieces of a few bytes (every row its own piece, lines split across pieces)
against an independent reading of the same text (the csv module, pandas), and show the whole-table limits no longer
refuse these logs. The slow one is the issue's: a GNSS-Acoustic log of 10**6 replies simulated by the project's own
box-in survey, read and solved by ``sblsim calibrate`` in under 1 GiB, its solution within its sigmas of the truth
(its time is measured, docs/calibration.md, not asserted).
"""

from __future__ import annotations

import csv
import functools
import io
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.io import log_tables, tables
from sblsim.orchestrator.logs import receiver_log, truth_track
from sblsim.orchestrator.surveys import log as survey_log
from sblsim.orchestrator.surveys.simulate import load_simulated, replicate

#: Survey A's file of 2021-07-23 (the package's data).
XIE_FILE = Path(survey_log.__file__).parent / "data" / "xie" / "gnssa_data_20210723.txt"


def _pieces(monkeypatch, module, size: int) -> None:
    """``module`` reads its tables in pieces of ``size`` bytes (a few: every line its own piece, or split)."""
    monkeypatch.setattr(module, "table_chunks", functools.partial(log_tables.table_chunks, chunk_bytes=size))


def _refusal(call, *args, **kwargs) -> str:
    with pytest.raises(ModelError) as caught:
        call(*args, **kwargs)
    message = str(caught.value)
    assert "\n" not in message
    return message


# --------------------------------------------------------------------------- a table in pieces

TEXT = ('\ufeff#% [run]\n#% seed = 3\n# the title\n\n"time_s",note,x\r\n'
        '1.5,"a, b",2\n# a comment between rows\n\n2.5,"",3\n' + "".join(f"{k}.25,n{k},{k * k}\n" for k in range(40))
        + "99,last,1")  # a BOM, a configuration, a title, CRLF, quoted commas, comments and blank lines, no final end


def _independent(text: str) -> tuple[list[str], list[list[str]], list[str], str, str]:
    """The header, rows and places of the text as the documented rules read it, by the csv module line by line."""
    lines = text.lstrip("\ufeff").split("\n")
    config, title, header, rows, places = [], "", None, [], []
    for number, line in enumerate(lines, start=1):
        line = line.removesuffix("\r")
        if not line.strip():
            continue
        if line.strip().startswith("#"):
            if header is None and line.startswith("#%"):
                config.append(line[3:])
            elif header is None and not title:
                title = line.strip("# ")
            continue
        cells = [c.strip() for c in next(csv.reader([line.strip()], skipinitialspace=True))]
        if header is None:
            header = cells
        else:
            rows.append(cells)
            places.append(f"line {number}")
    return header, rows, places, "\n".join(config), title


@pytest.mark.parametrize("size", [1, 7, 64, 2**20])
def test_a_table_read_in_pieces_is_the_table_read_whole(tmp_path, size):
    path = tmp_path / "t.csv"
    path.write_bytes(TEXT.encode())
    header, rows, places, config, title = _independent(TEXT)
    pieces = list(log_tables.table_chunks(path, "log", size))
    assert all(p.header == header and p.config == config and p.title == title for p in pieces)
    assert [c for p in pieces for _, c in p.rows] == rows
    assert [w for p in pieces for w, _ in p.rows] == places
    whole = log_tables.read_table(path, "log")
    assert (whole.header, [c for _, c in whole.rows], whole.config, whole.title) == (header, rows, config, title)


def test_a_parquet_table_in_pieces_holds_its_rows_as_text(tmp_path):
    frame = pd.DataFrame({"time_s": np.arange(1000) * 0.5, "beacon_id": pd.array([1, None] * 500, "Int64")})
    path = tmp_path / "t.parquet"
    frame.to_parquet(path)
    pieces = list(log_tables.table_chunks(path, "log", 300))
    assert len(pieces) > 1
    rows = [r for p in pieces for r in p.rows]
    assert [w for w, _ in rows] == [f"row {k}" for k in range(1, 1001)]
    assert [c for _, c in rows] == [[repr(0.5 * k), "1" if k % 2 == 0 else ""] for k in range(1000)]
    assert log_tables.table_length(path, "log") == 1000


def _read_all(pieces, *args, **kwargs) -> list:
    return list(pieces(*args, **kwargs))


def test_a_line_too_wide_or_too_long_is_refused_in_any_piece_with_its_count(tmp_path):
    """Each line beyond the pieces it spans (3 MB): counted to its end, never held, refused in one line with its
    line number and its exact count (str.count of the same text)."""
    commas = "a,b\n1,2\n" + "," * 3_000_000 + "\n3,4\n"
    long = "a,b\n1,2\n3,4\n" + "7" * 3_000_000 + "\r\n5,6\n"
    spaces = "1 2\n" + "x " * 1_500_000 + "\n"
    for size in (5, 2**20, 2**23):
        (tmp_path / "c.csv").write_text(commas)
        message = _refusal(_read_all, log_tables.table_chunks, tmp_path / "c.csv", "log", size)
        assert f"'{tmp_path / 'c.csv'}' line 3 holds {commas.splitlines()[2].count(',') + 1:,} cells; allowed at " \
               f"most {tables.MAX_LINE_CELLS:,} cells a line" in message, message
        (tmp_path / "l.csv").write_text(long, newline="")
        message = _refusal(_read_all, log_tables.table_chunks, tmp_path / "l.csv", "log", size)
        assert f"line 4 is {len(long.splitlines()[3]):,} bytes long; allowed at most {tables.MAX_LINE_BYTES:,}" \
            in message, message
        (tmp_path / "s.txt").write_text(spaces)
        message = _refusal(_read_all, log_tables.line_chunks, tmp_path / "s.txt", "log", delimiter=" ",
                           chunk_bytes=size)
        assert f"line 2 holds {len(spaces.splitlines()[1].split()):,} cells" in message, message


def test_a_line_of_many_commas_in_a_calibration_log_is_refused_by_the_command(tmp_path, capsys):
    path = tmp_path / "hostile.csv"
    good = _simulated_log(tmp_path)
    text = good.read_text()
    path.write_text(text + "," * (3 * 2**20) + "\n")
    assert main(["calibrate", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"line {text.count(chr(10)) + 1} holds {3 * 2**20 + 1:,} cells" in err[0], err
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- the readers

def _simulated_log(tmp_path: Path, suffix: str = ".csv") -> Path:
    """A log of the project's simulated box-in survey (10 minutes, a reply every 4 s)."""
    survey, _ = replicate(load_simulated("box-in", ["survey.duration_s=600"]), 0)
    path = tmp_path / f"box-in{suffix}"
    survey_log.write_log(survey.log, path)
    return path


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_calibration_log_read_in_pieces_is_its_table(tmp_path, monkeypatch, suffix):
    """Pieces of 200 bytes (a reply or two each) against pandas' reading of the same file."""
    path = _simulated_log(tmp_path, suffix)
    expected = pd.read_csv(path, comment="#") if suffix == ".csv" else pd.read_parquet(path)
    _pieces(monkeypatch, survey_log, 200)
    log = survey_log.read_survey_log(path)
    assert len(expected) == len(log.frame) > 100
    expected["transponder"] = expected["transponder"].astype(str)
    pd.testing.assert_frame_equal(log.frame, expected[list(survey_log.LOG_COLUMNS)], check_dtype=False)
    first = 3 if suffix == ".csv" else 1  # a title line and a header before the rows
    assert log.where == [f"{'line' if suffix == '.csv' else 'row'} {k + first}" for k in range(len(expected))]


def test_the_whole_table_limits_no_longer_refuse_a_log(tmp_path, monkeypatch):
    """The cells, rows and bytes a table read whole may hold, made tiny: a calibration log, a replay's log and its
    truth track are read all the same (they refused such a file before: ``holds 17,000,017 cells; allowed at most
    16,777,216 cells in a table``)."""
    survey = _simulated_log(tmp_path)
    log = tmp_path / "log.csv"
    log.write_text("time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,beacon_d_m,depth_m\n"
                   + "".join(f"{0.1 * k!r},1,6,1,0,1,2\n" for k in range(1, 60)))
    truth = tmp_path / "truth.csv"
    truth.write_text("time_s,n_m,e_m,d_m\n" + "".join(f"{0.1 * k!r},1,2,3\n" for k in range(60)))
    for name, value in (("MAX_CELLS", 50), ("MAX_LOG_ROWS", 5), ("MAX_LOG_BYTES", 100)):
        monkeypatch.setattr(tables, name, value)
    assert len(survey_log.read_survey_log(survey).frame) == pd.read_csv(survey, comment="#").shape[0]
    assert len(receiver_log.read_log(log, 1).time) == 59
    assert len(truth_track.read_truth(truth)[0]) == 60
    with pytest.raises(ModelError):  # a table read whole keeps them
        log_tables.read_table(truth, "--truth")


def test_a_replay_log_read_in_pieces_sorts_and_drops_across_them(tmp_path, monkeypatch):
    """Rows out of order and duplicates that span pieces of 40 bytes (a row each): the arrival order, the first of
    each (time_s, beacon_id) kept, against pandas (a stable sort, drop_duplicates)."""
    rng = np.random.default_rng(5)
    t = np.round(np.arange(200) * 0.1 + rng.uniform(-0.3, 0.3, 200), 3)
    beacon = rng.integers(1, 4, 200)
    t[53], beacon[53] = t[50], beacon[50]  # a duplicate 3 rows later (within the reorder window)
    frame = pd.DataFrame({"time_s": t, "beacon_id": beacon, "range_m": rng.uniform(5, 9, 200).round(3),
                          "beacon_n_m": 1.0, "beacon_e_m": 0.0, "beacon_d_m": 1.0, "depth_m": 2.0})
    path = tmp_path / "log.csv"
    frame.to_csv(path, index=False)
    _pieces(monkeypatch, receiver_log, 40)
    log = receiver_log.read_log(path, 3)
    expected = frame.assign(line=np.arange(200) + 2).sort_values("time_s", kind="stable")
    expected = expected.drop_duplicates(["time_s", "beacon_id"])
    np.testing.assert_array_equal(log.time, expected["time_s"])
    np.testing.assert_array_equal(log.beacon, expected["beacon_id"])
    np.testing.assert_array_equal(log.range, expected["range_m"])
    assert log.where == [f"line {k}" for k in expected["line"]]
    assert log.counts["duplicate"] == 1 and log.counts["rows"] == 200
    assert log.counts["out_of_order"] == int(np.sum(t < np.maximum.accumulate(t)))


def test_a_truth_track_is_checked_across_its_pieces(tmp_path, monkeypatch):
    truth = tmp_path / "truth.csv"
    times = [0.1 * k for k in range(30)]
    times[17] = times[16]
    truth.write_text("time_s,n_m,e_m,d_m\n" + "".join(f"{t!r},1,2,3\n" for t in times))
    _pieces(monkeypatch, truth_track, 20)
    assert f"line 19: time_s {times[17]:.10g} s does not come after the row before" in _refusal(
        truth_track.read_truth, truth)


def test_a_log_the_memory_here_cannot_hold_is_refused_before_it_is_read(tmp_path, monkeypatch):
    """Counted by its lines (a pass over its bytes) before a cell is parsed: refused in one line naming the rows, the
    memory they need and the memory available."""
    truth = tmp_path / "truth.csv"
    truth.write_text("time_s,n_m,e_m,d_m\n" + "".join(f"{k},1,2,3\n" for k in range(1000)) + "x,y\n")  # bad at the end
    monkeypatch.setattr(truth_track, "available_memory", lambda: 100 * truth_track.TRUTH_ROW_BYTES)
    message = _refusal(truth_track.read_truth, truth)
    assert f"{str(truth)!r} holds up to 1,002 rows" in message and "available here" in message, message
    survey = _simulated_log(tmp_path)
    monkeypatch.setattr(survey_log, "available_memory", lambda: 100 * survey_log.ROW_BYTES)
    assert f"holds up to {survey.read_text().count(chr(10)):,} rows" in _refusal(survey_log.read_survey_log, survey)


#: ``sblsim ARGS`` in a process of its own that says its peak resident memory [kB] last on standard error: its
#: address space's high-water mark (``VmHWM``; not ``getrusage``'s, which a process started from this one's large
#: address space inherits on Linux).
PEAK_CODE = ("import sys\nfrom sblsim.orchestrator.cli import main\nstatus = main(sys.argv[1:])\n"
             "print(next(line.split()[1] for line in open('/proc/self/status') if line.startswith('VmHWM')), "
             "file=sys.stderr)\nsys.exit(status)\n")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="the peak memory is read from Linux's /proc")
def test_a_line_of_200_million_commas_is_refused_in_bounded_memory(tmp_path):
    """The hostile shape the bounds exist for, after a genuine header and reply: refused by the command in one line
    with its exact count, its line scanned, never held (the command's peak memory below 0.5 GiB: the file is 200 MB),
    nothing written."""
    good = _simulated_log(tmp_path).read_text().splitlines()
    path = tmp_path / "commas.csv"
    with open(path, "w") as handle:
        handle.write("\n".join(good[:3]) + "\n")
        for _ in range(200):
            handle.write("," * 1_000_000)
        handle.write("\n")
    proc = subprocess.run([sys.executable, "-c", PEAK_CODE, "calibrate", str(path), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=600)
    *lines, peak = proc.stderr.splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr[-2000:]
    assert f"line 4 holds {200_000_001:,} cells; allowed at most {tables.MAX_LINE_CELLS:,} cells a line" in lines[0]
    assert int(peak) * 1024 < 2**29, peak
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- a million replies

#: What the command runs with beside the defaults: the solver's one-at-a-time outlier rejection re-solves the whole
#: log once per reply it rejects (thousands at 10**6 replies: hours) and its running solution is a Python step per
#: reply; both are the solver's, not the reader's: set aside here (a factor of 100 sigmas rejects nothing).
SOLVER = ["--set", "solver.running=false", "--set", "solver.outlier_factor=100"]


def _calibrate(log: Path, out: Path) -> tuple[dict, float, float]:
    """``sblsim calibrate LOG`` in a process of its own: its solution, its peak resident memory [bytes] and time [s]."""
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", PEAK_CODE, "calibrate", str(log), "--out", str(out), *SOLVER],
                          capture_output=True, text=True, timeout=3600)
    took = time.perf_counter() - start
    assert proc.returncode == 0, proc.stderr[-3000:]
    peak = int(proc.stderr.splitlines()[-1]) * 1024  # Linux: kilobytes
    return json.loads((out / "solution.json").read_text()), peak, took


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="the peak memory is read from Linux's /proc")
def test_a_log_of_a_million_replies_is_read_and_solved_in_under_1_gib(tmp_path):
    """Two days of the simulated box-in, a reply every 0.17 s (2 x 500,001 replies, the transponder where the a-priori
    says), written as one calibration log of 17,000,034 cells (refused before as more than 2**24), solved by the
    command in under 1 GiB, its position within 3 sigmas of the truth. Its time is measured, not asserted (the
    first half's solve took two fifths to two thirds of the whole's: docs/calibration.md)."""
    sim = load_simulated("box-in", ["survey.duration_s=86400", "survey.ping_period_s=0.1728",
                                    "survey.apriori_sigma_m=0"])
    frames = []
    for day in range(2):
        survey, simulated = replicate(sim, day)
        frame = survey.log.frame
        frame["ping"] += day * len(frame)
        frame[["t_tx_s", "t_rx_s"]] += day * 86400.0
        frames.append(frame)
    truth = simulated.truth[0]
    whole = tmp_path / "whole.csv"
    survey_log.write_log(survey_log.SurveyLog(pd.concat(frames, ignore_index=True), "two days"), whole)
    del frames, survey, simulated
    assert pd.read_csv(whole, comment="#", nrows=5).shape[1] * 1_000_002 > tables.MAX_CELLS
    s_whole, peak, t_whole = _calibrate(whole, tmp_path / "o-whole")
    assert s_whole["log"]["rows"] == 1_000_002
    assert peak <= 2**30, peak
    b = s_whole["transponders"][0]
    for axis in "enu":
        at_whole = b[f"apriori_{axis}_m"] + b[f"{axis}_m"]
        assert abs(at_whole - truth["enu".index(axis)]) <= 3 * b[f"sigma_{axis}_m"], (axis, at_whole)
    print(f"whole: {t_whole:.0f} s, peak {peak / 2**20:.0f} MiB", file=sys.stderr)


def test_survey_a_and_a_garpos_survey_read_in_pieces_are_read_whole(tmp_path, monkeypatch):
    """Survey A's text file in pieces of 300 bytes (a line or two) against numpy's reading of it; a GARPOS observation
    file in pieces of 500 bytes against the reader in one piece (its rows flagged, of other stations, spanning the
    pieces: every piece's count kept)."""
    from sblsim.orchestrator.surveys import garpos, xie
    from tests.orchestrator.test_calibrate_garpos import _write

    text = XIE_FILE.read_text()
    numbers = np.loadtxt(io.StringIO(text), comments="#")
    monkeypatch.setattr(xie, "line_chunks", functools.partial(log_tables.line_chunks, chunk_bytes=300))
    log = xie.read_xie(XIE_FILE)
    assert len(log.frame) == len(numbers)
    np.testing.assert_array_equal(log.frame["twtt_s"].to_numpy(), numbers[:, 14])
    np.testing.assert_array_equal(log.frame["tx_n_m"].to_numpy(), numbers[:, 1])
    _write(tmp_path / "g")
    obs = tmp_path / "g" / "obs.csv"
    lines = obs.read_text().splitlines()
    for k in range(3, len(lines), 7):  # every 7th reply flagged, every 11th of a station the site does not have
        lines[k] = lines[k].replace(",False,", ",True,")
    for k in range(5, len(lines), 11):
        cells = lines[k].split(",")
        lines[k] = ",".join(cells[:3] + ["Z9"] + cells[4:])
    obs.write_text("\n".join(lines) + "\n")
    files = obs, tmp_path / "g" / "initcfg.ini", tmp_path / "g" / "svp.csv"
    whole = garpos.read_garpos(*files)
    _pieces(monkeypatch, garpos, 500)
    pieces = garpos.read_garpos(*files)
    pd.testing.assert_frame_equal(pieces.log.frame, whole.log.frame)
    assert pieces.log.where == whole.log.where and pieces.left_out == whole.left_out
    assert whole.left_out == {"flagged": len(range(3, len(lines), 7)), "unknown_transponder": len(
        [k for k in range(5, len(lines), 11) if ",True," not in lines[k]])}
