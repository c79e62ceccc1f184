"""A plain piece parsed by Arrow's CSV reader (:mod:`sblsim.orchestrator.store.plain`) gives the text reader's cells
and lines; a piece not plain is left to the text reader; a file mixing both is stored as the whole-file reader reads
it. The readers' per-distinct-cell work (:func:`~sblsim.orchestrator.readers.cells.per_value`) and the times' one
pattern give what the column-wide work gives."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import per_value, text_table
from sblsim.orchestrator.readers.detections import read_detections
from sblsim.orchestrator.store import plain
from sblsim.orchestrator.store import reading as reading_module
from sblsim.orchestrator.store.ingest import ingest
from sblsim.orchestrator.store.plain import fathom_detections, plain_body
from sblsim.orchestrator.store.query import Store
from sblsim.orchestrator.telemetry.simulate import fathom_text, simulate_study, vue_text

HEAD = "Date and Time (UTC),Receiver,Transmitter,Sensor Value,Sensor Unit,Station Name"
ROWS = ["2024-06-03 00:00:28.948075,VR2AR-461000,A69-1602-1049,,, north ",
        "2024-06-03 00:00:39.616019,VR2AR-461001,A69-1601-60005,4.5,m,",
        " 2024-06-03T00:01:00Z ,461002,A69-1602-1049,,,S 3"]


def _text_reader(piece: str, first_line: int) -> tuple[pd.DataFrame, list[int]]:
    header, body, lines = text_table(HEAD + "\n" + piece, "f", "detections", 10**6, first_line=first_line - 1)
    return body, lines


def test_a_plain_piece_is_the_text_readers_cells_and_lines():
    piece = "\n".join(ROWS * 50) + "\n"
    got = plain_body(piece.encode(), 6, 7)
    assert got is not None
    want = _text_reader(piece, 7)
    pd.testing.assert_frame_equal(got[0], want[0])
    assert got[1] == want[1] == list(range(7, 157))
    last = "\n".join(ROWS)  # a last line without its line end
    pd.testing.assert_frame_equal(plain_body(last.encode(), 6, 2)[0], _text_reader(last, 2)[0])


@pytest.mark.parametrize("piece", [
    '2024-06-03 00:00:28,"VR2AR-461000",A69-1602-1049,,,\n',  # a quote
    ROWS[0] + "\r\n" + ROWS[1] + "\r\n",  # carriage returns
    ROWS[0] + "\n\n" + ROWS[1] + "\n",  # a blank line (the text reader skips it: the lines differ)
    "\n" + ROWS[0] + "\n" + ROWS[1] + "\n",  # a blank line first
    ROWS[0] + "\n ,  ,,,,\n" + ROWS[1] + "\n",  # a row of blank cells (dropped by the text reader)
    ROWS[0] + "\n2024-06-03 00:00:28,VR2AR-461000,A69-1602-1049\n",  # a short row (padded by the text reader)
    ROWS[0] + ",extra\n",  # a long row (refused by the text reader)
    ROWS[0].replace("north", "n\xf8rd") + "\n",  # not UTF-8 once encoded in Latin-1
])
def test_a_piece_not_plain_is_left_to_the_text_reader(piece):
    data = piece.encode("latin-1") if "\xf8" in piece else piece.encode()
    assert plain_body(data, 6, 2) is None


def test_a_row_of_blank_cells_after_a_blank_first_cell_is_told_apart():
    piece = ROWS[0] + "\n ,VR2AR-461000,A69-1602-1049,,,\n"  # its first cell blank, the row not: still plain
    got = plain_body(piece.encode(), 6, 2)
    assert got is not None and got[1] == [2, 3]


def test_a_line_longer_than_allowed_is_left_to_the_text_reader(monkeypatch):
    monkeypatch.setattr(plain, "MAX_LINE_BYTES", 80)
    short = "\n".join(ROWS[1:2] * 20) + "\n"  # 61-byte lines, a piece longer than the limit
    assert plain_body(short.encode(), 6, 2) is not None
    long = short + ROWS[0] + "x" * 40 + "\n"
    assert plain_body(long.encode(), 6, 2) is None
    assert plain_body((ROWS[0] + "x" * 200).encode(), 6, 2) is None  # one line, no line end


def test_the_piece_limits_are_the_text_readers():
    piece = ("\n".join(ROWS) + "\n").encode()
    assert plain_body(piece, 6, 2, max_cells=17) is None and plain_body(piece, 6, 2, max_cells=18) is not None
    assert plain_body(piece, 6, 2, max_rows=2) is None


def test_a_file_of_plain_and_other_pieces_is_stored_as_the_whole_file_reader_reads_it(tmp_path, monkeypatch):
    d = simulate_study(n_receivers=4, n_tags=3, days=0.1, seed=5).detections.reset_index(drop=True)
    lines = vue_text(d).splitlines()
    k = len(lines) // 3
    lines[k] = lines[k].replace("VR2", '"VR2', 1).replace(",A69", '",A69', 1)  # a quoted cell
    lines.insert(2 * k, "")  # a blank line
    text = "\n".join(lines[:k + 40]) + "\n" + "\r\n".join(lines[k + 40:k + 80]) + "\r\n" + "\n".join(lines[k + 80:])
    path = tmp_path / "detections.csv"
    path.write_bytes(text.encode())
    parsed = []

    def spy(*args, **kwargs):
        got = plain_body(*args, **kwargs)
        parsed.append(got is not None)
        return got

    monkeypatch.setattr(reading_module, "plain_body", spy)
    ingest(path, tmp_path / "store", piece_bytes=4096)
    assert any(parsed) and not all(parsed)  # both readers used
    want = read_detections(path, None)
    pd.testing.assert_frame_equal(Store(tmp_path / "store").detections().frame, want.frame)


def test_per_value_is_the_column_wide_map_in_its_order_and_index():
    rng = np.random.default_rng(2)
    cells = pd.Series(rng.choice(["VR2W-1", " VR2AR-22 ", "x-y-3", "4"], 400), index=np.arange(400) * 3 + 1,
                      dtype=str)
    for function in (lambda v: v.str.strip(), lambda v: v.str.replace(r"^.*-", "", regex=True),
                     lambda v: v.str.fullmatch(r"[A-Z0-9]+-[0-9]+").fillna(False)):
        pd.testing.assert_series_equal(per_value(cells, function), function(cells))
    distinct = pd.Series([f"r{k}" for k in range(50)], dtype=str)  # few repeats: mapped over the column
    pd.testing.assert_series_equal(per_value(distinct, lambda v: v.str.upper()), distinct.str.upper())


def test_times_pandas_parses_as_they_are_and_normalised_ones_agree():
    plain_forms = ["2024-06-03 00:00:28.948075", "2024-06-03T00:00:28.948075Z", "2024-06-03T02:00:28.948075+02:00",
                   "2024-06-03", "2024-06-03 00:00"]
    other = ["2024-06-03 00:00:28,948075", "2024-06-03 00:00:28.948075 UTC", "2024-06-03T02:00:28.948075 +0200",
             "2024-06-03", "2024-06-03 00:00 Z"]
    lines = list(range(2, 7))
    got = utc_seconds(pd.Series(plain_forms, dtype=str), "f", lines, "t")
    assert np.array_equal(got, utc_seconds(pd.Series(other, dtype=str), "f", lines, "t"))
    want = [pd.Timestamp("2024-06-03 00:00:28.948075", tz="UTC").value / 1e9] * 3 + \
        [pd.Timestamp("2024-06-03", tz="UTC").value / 1e9, pd.Timestamp("2024-06-03 00:00", tz="UTC").value / 1e9]
    assert np.allclose(got, want, rtol=0, atol=1e-6)


def test_a_fathom_piece_is_reduced_to_its_detections_lines():
    lines = ["DET,2024-06-03 00:00:28,VR2AR,461000,A69-1602-1049", "TEMP,2024-06-03 00:00:28,VR2AR,461000,9.5,10.0",
             "DET,2024-06-03 00:00:39,VR2AR,461000,A69-1601-60005", "DETX,1,2", " DET,3,4",
             "DET,2024-06-03 00:00:45,VR2AR,461001,A69-1602-1063"]
    data, at = fathom_detections(("\n".join(lines) + "\n").encode())
    assert at.tolist() == [0, 2, 5]  # the csv module would choose the same: the rows whose first field is DET
    assert data.decode().splitlines() == [lines[k] for k in (0, 2, 5)]
    assert fathom_detections(("\n".join(lines)).encode())[1].tolist() == [0, 2, 5]  # no last line end
    for other in ("DET_SENS,2024-06-03 00:00:28,461000,A69-1602-1049,4.5,m", "DET_DESC,Device Time (UTC)",
                  'DET,"2024-06-03 00:00:28",VR2AR,461000,A69-1602-1049', "TEMP" + ",1" * 600, ""):  # "": blank
        assert fathom_detections(("\n".join(lines[:2] + [other] + lines[2:]) + "\n").encode()) is None
    assert fathom_detections(b"TEMP,1,2\nTEMP,3,4\n") is None  # no detection: the text reader's
    assert fathom_detections(("\n" + "\n".join(lines) + "\n").encode()) is None  # a blank line first
    short = fathom_detections(b"DET,1\nD\nDE\nDET\nDET,2\nDE")  # lines shorter than a record's name, one last
    assert short[0] == b"DET,1\nDET,2\n" and short[1].tolist() == [0, 4]


def test_a_fathom_file_with_sensor_records_and_odd_lines_is_stored_as_the_whole_file_reader_reads_it(
        tmp_path, monkeypatch):
    d = simulate_study(n_receivers=4, n_tags=3, days=0.1, seed=6).detections.reset_index(drop=True)
    lines = fathom_text(d).splitlines()
    lines.insert(3, "DET_SENS_DESC,Device Time (UTC),Serial Number,Full ID,Sensor Value,Sensor Unit")
    n = len(lines)
    for k, tag in ((n // 5, None), (n // 2, "A69-1602-9")):  # a sensor detection of a DET record's, one of its own
        k += lines[k].startswith("TEMP")
        cells = lines[k].split(",")
        lines.insert(k + 1, f"DET_SENS,{cells[1]},{cells[6]},{tag or cells[9]},4.5,m")
    k = 3 * n // 4
    lines[k] = lines[k].replace(",PPM,", ',"PPM",', 1)  # a quoted cell
    path = tmp_path / "detections.csv"
    path.write_text("\n".join(lines) + "\n")
    plain_pieces = []

    def spy(piece, *args, **kwargs):
        got = fathom_detections(piece, *args, **kwargs)
        plain_pieces.append(got is not None)
        return got

    monkeypatch.setattr(reading_module, "fathom_detections", spy)
    ingest(path, tmp_path / "store", piece_bytes=4096)
    assert any(plain_pieces) and not all(plain_pieces)
    want = read_detections(path, None)
    assert (want.frame["sensor_unit"] == "m").sum() >= 2
    pd.testing.assert_frame_equal(Store(tmp_path / "store").detections().frame, want.frame)
