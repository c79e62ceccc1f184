"""Every table reader is bounded in memory, not only in bytes (orchestrator/io/tables.py ``check_cells``): a line of
too many cells, a line too long, or a table of too many cells is refused in one line naming the file, the limit and
the count, before pandas (or the csv module) builds a cell. The counts are checked against an independent count of
the same text (``str.count``, ``str.split``, the csv module); the limits are lowered for the small tables here. The
slow tests run ``sblsim sync`` on 100 MB of commas under an address-space limit, and ``sblsim track`` on 2^25 cells of
two characters (every count passed: the parse's own memory) within 1 GiB; the table pandas parses from the text's
UTF-8 pieces is checked against pandas on the whole text."""

from __future__ import annotations

import csv
import io
import random
import re
import resource
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.errors import ConfigError
from sblsim.models.target.core import WAYPOINTS
from sblsim.models.target.trajectories import MAX_LINE_CHARS, read_trajectory_file
from sblsim.orchestrator.design import area_file
from sblsim.orchestrator.io import log_tables, tables
from sblsim.orchestrator.logs import receiver_log, truth_track
from sblsim.orchestrator.readers import cells, detections, input_rows, receivers_file, time_series
from sblsim.orchestrator.readers import toa_matrix as toa
from sblsim.orchestrator.readers.burst_sequence import read_burst_sequence
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.hydrophones import read_hydrophones
from sblsim.orchestrator.readers.sound_speed import read_sound_speed
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet
from sblsim.orchestrator.sync.clocks import read_clocks

REPO = Path(__file__).resolve().parents[2]


def _refusal(call, *args, error=ModelError) -> str:
    with pytest.raises(error) as caught:
        call(*args)
    message = str(caught.value)
    assert "\n" not in message, message
    return message


def _cells(text: str, delimiter: str = ",") -> list[int]:
    """Each line's cells, counted independently of the code: its commas and one, or its words."""
    lines = re.split(r"\r\n|\n|\r", text)
    lines = lines[:-1] if lines and lines[-1] == "" else lines
    return [line.count(",") + 1 if delimiter == "," else len(line.split()) for line in lines]


# --------------------------------------------------------------------------- the shared count


def _naive(data: bytes, delimiter: str, comments: bool) -> list[tuple[int, int]]:
    text = data.decode("latin-1")
    lines = re.split(r"\r\n|\n|\r", text)
    lines = lines[:-1] if lines and lines[-1] == "" else lines
    return [(0 if comments and line.startswith("#") else _cells(line, delimiter)[0] if line else
             (1 if delimiter == "," else 0), len(line)) for line in lines]


def test_the_count_agrees_with_an_independent_one_across_piece_boundaries(monkeypatch):
    monkeypatch.setattr(tables, "_PIECE", 7)  # pieces of 7 bytes: every line and run crosses their edges
    rng = random.Random(5)
    for _ in range(3000):
        data = bytes(rng.choice(b",, a#\n\r\t") for _ in range(rng.randint(0, 40)))
        delimiter, comments = rng.choice([",", " "]), rng.random() < 0.5
        most, longest, total = rng.randint(1, 6), rng.randint(0, 8), rng.randint(0, 30)
        expected = _naive(data, delimiter, comments)
        bad = next((k for k, (cells, size) in enumerate(expected) if cells > most or size > longest), None)
        counted = sum(cells for cells, _ in expected)
        try:
            got = tables.check_cells(data, "f.csv", "table", delimiter, max_line_cells=most, max_cells=total,
                                     max_line_bytes=longest, comments=comments)
        except ModelError as exc:
            message = str(exc)
            if bad is not None:
                cells, size = expected[bad]
                shown = (f"line {bad + 1} holds {cells:,} cells; allowed at most {most:,} cells a line" if cells > most
                         else f"line {bad + 1} is {size:,} bytes long; allowed at most {longest:,} bytes a line")
                assert shown in message, (data, message, expected)
            else:
                assert counted > total and f"holds {counted:,} cells; allowed at most {total:,}" in message, message
        else:
            assert bad is None and counted <= total and got == counted, (data, expected, got)


def test_a_whitespace_table_counts_its_words_and_auto_follows_the_first_row():
    text = "# a b c d e f g\n t  x\ty \n0 1 2\n"
    assert tables.check_cells(text.encode(), "gps.txt", "truth", " ", comments=True) == sum(_cells(text, " ")[1:])
    wide = "H1 H2 H3\n" + " ".join(["1.5"] * 9) + "\n"
    message = _refusal(lambda: tables.check_cells(wide.encode(), "toa.txt", "toa", "auto", max_line_cells=8))
    assert "'toa.txt' line 2 holds 9 cells; allowed at most 8 cells a line" in message
    commas = "H1,H2\n" + ",".join(["1"] * 9) + "\n"  # the first row holds a comma: commas counted
    message = _refusal(lambda: tables.check_cells(commas.encode(), "toa.csv", "toa", "auto", max_line_cells=8))
    assert "line 2 holds 9 cells" in message


# --------------------------------------------------------------------------- each reader

def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode())
    return path


#: reader, file name, a genuine header and row, and the module attribute holding its table's limit.
READERS = {
    "detections": (lambda p: detections.read_detections(p, "yaps"), "det.csv", "epo,frac,tag,serial",
                   "1693519201,0.06,7953,1623", (detections, "MAX_DETECTION_CELLS")),
    "detections sniffed": (lambda p: detections.read_detections(p, None), "det.csv", "epo,frac,tag,serial",
                           "1693519201,0.06,7953,1623", (detections, "MAX_DETECTION_CELLS")),
    "receivers": (read_hydrophones, "rx.csv", "serial,sync_tag,x_m,y_m", "1623,,1.5,2.5",
                  (tables, "MAX_CELLS")),
    "deployments": (read_deployments, "dep.csv", "ins_serial_no,transmitter,deploy_lat,deploy_long",
                    "1623,,60.38,5.33", (tables, "MAX_CELLS")),
    "tag sheet": (read_tag_sheet, "tags.csv", "transmitter,role,name", "4555,animal,cod", (tables, "MAX_CELLS")),
    "sound speed": (read_sound_speed, "ss.csv", "epo,sound_speed_m_s", "1587877200,1421.3",
                    (tables, "MAX_CELLS")),
    "toa matrix": (toa.read_toa, "toa.csv", "H1,H2", "1.5,2.5", (input_rows, "MAX_MATRIX_CELLS")),
    "toa receivers": (receivers_file.read_receivers, "hyd.csv", "hydrophone,x_m,y_m", "H1,0,0",
                      (input_rows, "MAX_TOA_CELLS")),
    "truth track": (lambda p: time_series.read_track(p, "truth"), "gps.csv", "x,y,t", "1,2,0.5",
                    (input_rows, "MAX_TOA_CELLS")),
    "sound-speed series": (time_series.read_sound_speed_series, "c.csv", "time_s,sound_speed_m_s", "0,1480",
                           (input_rows, "MAX_TOA_CELLS")),
    "burst sequence": (read_burst_sequence, "b.csv", "interval_s,note", "1.5,a", (input_rows, "MAX_TOA_CELLS")),
    # a replay's log and truth track are read in pieces: no table bound, their rows' memory checked instead
    # (tests/orchestrator/test_large_logs.py)
    "log": (lambda p: receiver_log.read_log(p, 1), "log.csv", "time_s,beacon_id,range_m,beacon_n_m,beacon_e_m,"
            "beacon_d_m,depth_m", "0.1,1,7.7,1.1,-0.1,1.2,2.0", None),
    "log truth": (truth_track.read_truth, "truth.csv", "time_s,n_m,e_m,d_m", "0.1,-4.9,-5.0,2.0", None),
}


@pytest.mark.parametrize("reader", READERS)
def test_a_line_of_too_many_cells_is_refused_naming_the_count(tmp_path, reader):
    read, name, header, row, limit = READERS[reader]
    most = input_rows.MAX_ROW_CELLS if limit and limit[0] is input_rows else tables.MAX_LINE_CELLS
    text = f"{header}\n{row}\n{row}{',' * most}\n{row}\n"
    path = _write(tmp_path, name, text)
    cells = _cells(text)[2]
    assert cells > most
    message = _refusal(read, path)
    assert f"{str(path)!r} line 3 holds {cells:,} cells; allowed at most {most:,} cells a line" in message, message


@pytest.mark.parametrize("reader", [name for name, spec in READERS.items() if spec[4] is not None])
def test_a_table_of_too_many_cells_is_refused_naming_the_count(tmp_path, monkeypatch, reader):
    read, name, header, row, (module, limit) = READERS[reader]
    monkeypatch.setattr(module, limit, 60)
    text = header + "\n" + "".join(f"{row}\n" for _ in range(30))
    path = _write(tmp_path, name, text)
    total = sum(_cells(text))
    assert total > 60
    message = _refusal(read, path)
    assert f"{str(path)!r} holds {total:,} cells; allowed at most 60 cells in a table" in message, message


def test_sync_s_own_tables_and_the_sniffed_first_line_are_counted(tmp_path):
    folder = tmp_path / "sync"
    folder.mkdir()
    text = "receiver,bin,start,end,offset_start_s,offset_end_s\n" + "1623" + "," * 600 + "\n"
    (folder / "offsets.csv").write_text(text)
    message = _refusal(read_clocks, folder)
    assert f"line 2 holds {_cells(text)[1]:,} cells; allowed at most 512 cells a line" in message
    path = _write(tmp_path, "wide.csv", "," * 5000 + "\n")  # the 64 KiB a format is sniffed from
    assert "line 1 holds 5,001 cells" in _refusal(detections.sniff_format, path)


def test_a_line_too_long_is_refused_before_it_is_parsed(tmp_path):
    path = _write(tmp_path, "det.csv", "epo,frac,tag,serial\n" + "7" * (tables.MAX_LINE_BYTES + 1) + "\n")
    message = _refusal(detections.read_detections, path)
    assert f"line 2 is {tables.MAX_LINE_BYTES + 1:,} bytes long; allowed at most {tables.MAX_LINE_BYTES:,}" in message


def test_a_first_row_spanning_lines_and_a_padded_table_are_counted_as_pandas_would_make_them(tmp_path, monkeypatch):
    names = [",".join(f"{letter}{k}" for k in range(300)) for letter in "cd"]
    text = f'serial,"x\ny",{names[0]},"p\nq",{names[1]}\n1,2\n'  # each line at most 302 cells, the row 603
    width = len(next(csv.reader(io.StringIO(text))))  # the csv module's reading of the first row
    assert width > tables.MAX_LINE_CELLS >= max(_cells(text))
    message = _refusal(read_hydrophones, _write(tmp_path, "rx.csv", text))
    assert f"its first row holds {width:,} cells; allowed at most {tables.MAX_LINE_CELLS:,} cells a row" in message
    # a short row is padded to the header's cells: the table pandas would build, not the file's cells, is bounded
    monkeypatch.setattr(tables, "MAX_CELLS", 2000)
    header = "serial,sync_tag,x_m,y_m," + ",".join(f"note{k}" for k in range(96))
    text = header + "\n" + "1\n" * 50
    assert sum(_cells(text)) <= 2000 < 51 * 100 == len(pd.read_csv(io.StringIO(text), header=None).stack(
        future_stack=True))
    message = _refusal(read_hydrophones, _write(tmp_path, "padded.csv", text))
    assert "holds 51 lines of 100 cells" in message and "allowed at most 2,000 cells in a table" in message


def test_a_parquet_log_is_refused_from_its_metadata(tmp_path, monkeypatch):
    wide = tmp_path / "wide.parquet"
    pd.DataFrame({f"c{k}": [1.0] for k in range(600)}).to_parquet(wide)
    assert "holds 1 rows of 600 columns; allowed at most 512 columns" in _refusal(log_tables.read_table, wide, "log")
    assert "holds 1 rows of 600 columns; allowed at most 512 columns" in _refusal(truth_track.read_truth, wide)
    monkeypatch.setattr(tables, "MAX_CELLS", 100)
    long = tmp_path / "long.parquet"
    pd.DataFrame({"time_s": range(30), "n_m": 0.0, "e_m": 0.0, "d_m": 0.0}).to_parquet(long)
    assert "holds 30 rows of 4 columns; allowed at most 512 columns and 100 cells" in _refusal(log_tables.read_table,
                                                                                                 long, "--truth")


def test_a_design_area_and_a_trajectory_file_are_bounded(tmp_path, monkeypatch):
    text = "north_m,east_m\n0,0\n" + "0" + ",0" * 600 + "\n"
    message = _refusal(area_file.read_area, _write(tmp_path, "area.csv", text), error=ConfigError)
    assert f"site.area.file: {str(tmp_path / 'area.csv')!r} line 3 holds {_cells(text)[2]:,} cells" in message
    monkeypatch.setattr(area_file, "MAX_CELLS", 20)
    text = "north_m,east_m\n" + "0,0\n10,0\n10,10\n" * 4
    message = _refusal(area_file.read_area, _write(tmp_path, "area.csv", text), error=ConfigError)
    assert f"holds {sum(_cells(text))} cells; allowed at most 20 cells in a table" in message
    path = _write(tmp_path, "traj.csv", "time,north,east,down\n0,0,0,1\n" + "," * (MAX_LINE_CHARS + 10) + "\n")
    message = _refusal(read_trajectory_file, path, WAYPOINTS)
    assert f"line 3 is longer than {MAX_LINE_CHARS:,} characters; allowed at most {MAX_LINE_CHARS:,}" in message


def test_a_long_cell_of_a_toa_matrix_costs_its_bytes_not_the_matrix_s_width(tmp_path):
    # a text matrix as wide as its widest cell would take 28 x 20,000 x 400 kB here; the cells are one pandas column
    rows = ["NA 0 " + " ".join(["1.5"] * 26)] * 20_000
    rows[5] = "9" * 100_000 + rows[5][2:]  # a number too large to be finite
    path = _write(tmp_path, "toa.txt", "\n".join(rows) + "\n")
    message = _refusal(toa.read_toa, path)
    assert f"line 6 column 1: {'9' * 40!r} is not allowed; allowed: a finite number" in message


# --------------------------------------------------------------------------- the command line, in a subprocess

def _limit_memory():  # the child's address space: 1.5 GiB, so that an unbounded reader fails instead of swelling
    resource.setrlimit(resource.RLIMIT_AS, (3 * 2**29, 3 * 2**29))


@pytest.mark.slow
def test_sync_on_100_mb_of_commas_is_refused_in_one_line_within_1_5_gib(tmp_path):
    hostile = tmp_path / "detections.csv"
    hostile.write_bytes(b"," * 100_000_000)
    receivers = REPO / "data" / "boats-norway" / "hydrophones.csv"
    proc = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "sync", str(hostile), "--receivers",
                           str(receivers), "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          preexec_fn=_limit_memory, timeout=600)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert f"line 1 holds {100_000_001:,} cells; allowed at most {tables.MAX_LINE_CELLS:,} cells a line" in lines[0]
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- the parse's own memory (issue 98 item 13)

@pytest.mark.parametrize("text", [
    "serial,name\n1,åsa\n2,\"two\nlines\"\r\n3,°C Ø\n\n4,end",
    "a,b,c\n" + "".join(f"{k},é{k},\"x,{k}\"\n" for k in range(50)),
    "tag,note\r\n1,\"\"\"quoted\"\"\"\r\n2,日本\r\n",
])
def test_the_table_parsed_from_its_utf8_pieces_is_the_text_s(text):
    """The text handed to pandas a few characters at a time as UTF-8 (characters of two and three bytes cut between
    pieces, a quoted cell over lines, CRLF, a blank line) is the table pandas makes of the whole text."""
    expected = pd.read_csv(io.StringIO(text), header=None, dtype=object, keep_default_na=False, na_filter=False,
                           skip_blank_lines=False)
    for piece in (1, 3, 7, 1 << 20):
        got = pd.read_csv(io.BufferedReader(cells._Utf8(text, piece), buffer_size=5), encoding="utf-8",
                          **cells._CSV)
        assert got.astype(object).values.tolist() == expected.values.tolist(), piece
    header, body, lines = cells.text_table(text, "t.csv", "table", 100)
    assert header == [h.strip() for h in expected.iloc[0].tolist()] and len(body) == len(lines)


def _peak_child(args: list[str]) -> tuple[subprocess.CompletedProcess, float]:
    """A command run in a child of a fresh interpreter: its result and its peak resident memory [GiB]
    (``RUSAGE_CHILDREN`` of that interpreter, whose only child it is)."""
    probe = ("import resource, subprocess, sys; p = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
             "sys.stdout.write(repr((p.returncode, p.stderr, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)))")
    run = subprocess.run([sys.executable, "-c", probe, *args], capture_output=True, text=True, timeout=900)
    code, err, kib = eval(run.stdout)  # noqa: S307 - our own probe's repr of a tuple
    return subprocess.CompletedProcess(args, code, "", err), kib / 2**20


@pytest.mark.slow
def test_2_25_tiny_cells_of_detections_are_refused_within_1_gib(tmp_path):
    """A detections file of 2^25 cells of two characters (32 a row, the cells' bound: 100 MB) passes every count
    and is refused at its first cell; ``sblsim track`` peaked at 1.07 GiB with the text parsed from an
    ``io.StringIO``, now under 1 GiB."""
    header = "epo,frac,tag,serial," + ",".join(f"c{k}" for k in range(28))
    rows = detections.MAX_DETECTION_CELLS // 32 - 1
    path = tmp_path / "detections.csv"
    with open(path, "w") as handle:
        handle.write(header + "\n")
        handle.write((",".join(["ab"] * 32) + "\n") * rows)
    assert (rows + 1) * 32 == detections.MAX_DETECTION_CELLS
    proc, peak = _peak_child([sys.executable, "-m", "sblsim.orchestrator.cli", "track", str(path), "--receivers",
                              str(REPO / "data" / "boats-norway" / "deployments.csv"), "--out", str(tmp_path / "o")])
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr[-2000:]
    assert "line 2 column epo: 'ab' is not allowed" in lines[0], lines[0]
    assert peak < 1.0, f"{peak:.2f} GiB"
