"""Fathom as written (issue 98 items 5 and 12): every ``*_DESC`` record defines its type's columns until the next
one, so two exports concatenated (the second's columns in another order) are each read under their own header; a
legal quoted line break is read, and every row is named by its line in the file as an editor numbers it. Checked
against the csv module's own parse of the same text."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import text_table
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import read_detections

FIRST = ["Device Time (UTC)", "Model", "Serial Number", "Full ID", "Raw Data", "Station Name"]
#: the second export's DET columns: another order, one column more, one fewer
SECOND = ["Full ID", "Serial Number", "Device Time (UTC)", "Model", "Station Name", "Noise (dB)"]


def _export(header: list[str], rows: list[dict[str, str]]) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    out.write("VEMCO DATA LOG,2.0.0,vdat-9.3.0\n")
    w.writerow(["DET_DESC"] + header)
    for row in rows:
        w.writerow(["DET"] + [row.get(h, "") for h in header])
    return out.getvalue()


def _rows(serial: str, start: int, n: int, station: str) -> list[dict[str, str]]:
    return [{"Device Time (UTC)": f"2021-04-20 17:{start + k:02d}:01.25", "Model": "HR2-180", "Serial Number": serial,
             "Full ID": f"A69-1602-{4550 + k}", "Raw Data": "", "Station Name": station, "Noise (dB)": "40"}
            for k in range(n)]


def test_two_exports_concatenated_are_each_read_under_their_own_header(tmp_path):
    first, second = _rows("461396", 0, 3, "North"), _rows("461397", 10, 4, "South")
    path = tmp_path / "both.csv"
    path.write_text(_export(FIRST, first) + _export(SECOND, second))
    frame = read_detections(path, "fathom").frame
    expected = first + second
    assert frame["receiver"].tolist() == [r["Serial Number"] for r in expected]  # never the model, 'HR2-180'
    assert frame["tag"].tolist() == [r["Full ID"] for r in expected]
    assert frame["station"].tolist() == [r["Station Name"] for r in expected]
    times = utc_seconds([r["Device Time (UTC)"] for r in expected], "test", list(range(len(expected))), "t")
    assert np.allclose(frame["time"].to_numpy(float), times, rtol=0, atol=1e-6)
    # each row's line: the csv module's count over the whole text
    with open(path, newline="") as handle:
        lines = [k + 1 for k, r in enumerate(csv.reader(handle)) if r and r[0] == "DET"]
    assert frame["line"].tolist() == lines


def test_a_record_before_any_header_is_not_read_and_a_header_alone_reads_nothing(tmp_path):
    path = tmp_path / "odd.csv"
    rows = _rows("461396", 0, 2, "N")
    text = "VEMCO DATA LOG,2.0.0,vdat\nDET,2021-04-20 17:00:00,HR2-180,461396,A69-1602-1,,N\n"
    path.write_text(text + _export(FIRST, rows).split("\n", 1)[1] + "DET_DESC," + ",".join(SECOND) + "\n")
    frame = read_detections(path, "fathom").frame
    assert frame["receiver"].tolist() == ["461396", "461396"] and frame["line"].tolist() == [4, 5]


def test_a_quoted_line_break_is_read_and_rows_are_numbered_by_their_lines(tmp_path):
    rows = _rows("461396", 0, 3, "N")
    rows[1]["Station Name"] = "North\nbuoy, deep"  # legal CSV: a quoted cell spanning two lines
    rows[2]["Full ID"] = "A69-1602-x y"  # not a transmitter: its refusal names its line
    path = tmp_path / "broken.csv"
    path.write_text(_export(FIRST, rows))
    with open(path, newline="") as handle:
        reader = csv.reader(handle)
        starts = []
        for row in reader:
            if row and row[0] == "DET":
                starts.append(reader.line_num - row[-1].count("\n") - sum(c.count("\n") for c in row[:-1]))
    with pytest.raises(ModelError) as refused:
        read_detections(path, "fathom")
    assert starts == [3, 4, 6] and "line 6 " in str(refused.value)  # the file's line, not the row's number (5)
    rows[2]["Full ID"] = "A69-1602-4552"
    path.write_text(_export(FIRST, rows))
    frame = read_detections(path, "fathom").frame
    assert frame["station"].tolist()[1] == "North\nbuoy, deep" and frame["line"].tolist() == starts


def test_any_table_numbers_its_rows_by_their_lines(tmp_path):
    text = 'a,b\n1,"x\ny"\n2,z\n\n3,"p\r\nq\nr"\n4,w\n'
    header, body, lines = text_table(text, "t.csv", "test", 100)
    parsed = list(csv.reader(io.StringIO(text, newline="")))
    assert body.to_numpy().tolist() == [r for r in parsed[1:] if r]
    assert lines == [2, 4, 6, 9]
    path = tmp_path / "deployments.csv"
    path.write_text('serial,lat,lon,note\n1,60.1,5.1,"a\nnote"\n2,60.2,5.2,ok\n3,95,5.3,bad latitude\n')
    with pytest.raises(ModelError, match="line 5"):
        read_deployments(path)
