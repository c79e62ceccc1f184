"""The raw-detection readers of ``sblsim sync`` (:mod:`sblsim.orchestrator.readers.detections`) against independent
parses: the boats files by the csv module and numpy.genfromtxt, a VUE export written here by its dates computed with
datetime; hostile files refused in one line; a receiver clock going back reported, not sorted."""

from __future__ import annotations

import csv
import datetime as dt
import os
from pathlib import Path

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers import detections as reader
from sblsim.orchestrator.readers.detections import read_detections, reset_line
from sblsim.orchestrator.readers.hydrophones import read_hydrophones
from sblsim.orchestrator.readers.sound_speed import read_sound_speed

BOATS = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


def test_the_boats_detections_against_the_csv_module():
    d = read_detections(BOATS / "detections.csv")
    with open(BOATS / "detections.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(d.frame) == len(rows) == 45202
    f = d.frame
    assert f["receiver"].tolist() == [r["serial"] for r in rows]
    assert f["tag"].tolist() == [r["tag"] for r in rows]
    expected = np.array([int(r["epo"]) + float(r["frac"]) for r in rows])
    assert np.max(np.abs(f["time"].to_numpy() - expected)) < 1e-6
    assert f["line"].tolist() == list(range(2, len(rows) + 2))
    assert (f["species"] == "Sync").sum() == 25668 and d.ignored_columns == [] and d.format == "yaps"
    assert f["sensor_value"].isna().all()


def test_the_boats_receivers_and_sound_speed_against_genfromtxt():
    h = read_hydrophones(BOATS / "hydrophones.csv")
    raw = np.genfromtxt(BOATS / "hydrophones.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert h["receiver"].tolist() == [str(s) for s in raw["serial"]]
    assert np.array_equal(h[["x", "y"]].to_numpy(), np.c_[raw["x_m"], raw["y_m"]])
    assert h["z"].isna().all()
    tags = ["" if v == -1 else str(v) for v in raw["sync_tag"]]  # genfromtxt's missing integer: -1
    assert h["sync_tag"].tolist() == tags and tags.count("") == 3
    times, speeds = read_sound_speed(BOATS / "sound_speed.csv")
    ss = np.genfromtxt(BOATS / "sound_speed.csv", delimiter=",", skip_header=1)
    assert np.array_equal(times, ss[:, 0]) and np.array_equal(speeds, ss[:, 1])


VUE = ("Date and Time (UTC),Receiver,Transmitter,Transmitter Name,Transmitter Serial,Sensor Value,Sensor Unit,"
       "Station Name,Latitude,Longitude\n"
       "2023-08-31 22:00:01.125,VR2W-128355,A69-1602-59335,cod 1,1234567,12.5,m,North 1,60.7,5.3\n"
       "2023-08-31 22:00:03,VR2W-128356,A69-1602-59335,cod 1,1234567,,,\"South, deep\",60.7,5.3\n"
       "\n"
       "2023-08-31 22:00:04.5,VR2Tx-480001,A69-1601-61001,sync,,,,North 1,60.7,5.3\n")


def _epoch(text: str) -> float:
    return dt.datetime.fromisoformat(text).replace(tzinfo=dt.timezone.utc).timestamp()


def test_a_vue_export_with_milliseconds_and_a_sensor_value(tmp_path):
    path = tmp_path / "vue.csv"
    path.write_text(VUE)
    d = read_detections(path, "vue")
    f = d.frame
    assert f["receiver"].tolist() == ["128355", "128356", "480001"]
    assert f["receiver_model"].tolist() == ["VR2W", "VR2W", "VR2Tx"]
    assert f["tag"].tolist() == ["A69-1602-59335", "A69-1602-59335", "A69-1601-61001"]  # full IDs
    assert f["code_space"].tolist() == ["A69-1602", "A69-1602", "A69-1601"]
    expected = [_epoch("2023-08-31 22:00:01.125"), _epoch("2023-08-31 22:00:03"), _epoch("2023-08-31 22:00:04.5")]
    assert np.max(np.abs(f["time"].to_numpy() - expected)) < 1e-6
    assert f["sensor_value"].iloc[0] == 12.5 and np.isnan(f["sensor_value"].iloc[1])
    assert f["sensor_unit"].tolist() == ["m", "", ""] and f["station"].iloc[1] == "South, deep"
    assert f["line"].tolist() == [2, 3, 5]
    assert set(d.ignored_columns) == {"Transmitter Name", "Transmitter Serial", "Latitude", "Longitude"}


def test_a_vue_export_written_in_latin_1_is_read_with_its_degree_sign(tmp_path):
    """VUE on Windows writes its export in Latin-1: a temperature tag's unit °C is the byte 0xB0, no UTF-8."""
    path = tmp_path / "vue.csv"
    path.write_bytes(VUE.replace("12.5,m,", "12.5,°C,").encode("latin-1"))
    assert b"\xb0C" in path.read_bytes()
    f = read_detections(path, "vue").frame
    assert f["sensor_unit"].tolist() == ["°C", "", ""] and f["sensor_value"].iloc[0] == 12.5
    assert f["receiver"].tolist() == ["128355", "128356", "480001"]


def test_a_vue_export_in_a_time_zone_is_converted_to_utc(tmp_path):
    path = tmp_path / "vue.csv"
    path.write_text(VUE.replace("(UTC)", "(UTC+02:00)"))
    f = read_detections(path, "vue").frame
    assert abs(f["time"].iloc[0] - (_epoch("2023-08-31 22:00:01.125") - 7200)) < 1e-6


def _yaps(tmp_path: Path, rows: str, name: str = "d.csv") -> Path:
    path = tmp_path / name
    path.write_text("epo,frac,tag,serial\n" + rows)
    return path


def test_a_clock_going_back_is_kept_as_a_new_part_not_sorted(tmp_path):
    # receivers interleaved, each in its own order: read, no clock parts
    fine = _yaps(tmp_path, "100,0.5,7,A\n99,0.1,7,B\n101,0,7,A\n102,0.25,7,B\n")
    assert len(read_detections(fine).frame) == 4 and read_detections(fine).clock_resets == []
    # A's time goes back at line 6 (a reset kept in its logging order): its rows from there a second clock part,
    # the rows' order kept
    back = _yaps(tmp_path, "100,0.5,7,A\n99,0.1,7,B\n3700,0,7,A\n102,0.25,7,B\n101,0.5,7,A\n", "back.csv")
    d = read_detections(back)
    assert d.frame["time"].tolist() == [100.5, 99.1, 3700.0, 102.25, 101.5]
    assert d.frame["clock_part"].tolist() == [1, 1, 1, 1, 2]
    (reset,) = d.clock_resets
    assert (reset["receiver"], reset["line"], reset["previous_line"], reset["step_s"]) == ("A", 6, 4, -3598.5)
    assert "receiver A: its time goes back 3598.5 s at line 6" in reset_line(reset)


@pytest.mark.parametrize("rows, found", [
    ("100,1.0,7,A\n", "line 2 column frac: '1.0'"),
    ("-100,0.5,7,A\n", "line 2 column epo: '-100'"),
    ("1e9,0.5,7,A\n", "line 2 column epo: '1e9'"),
    ("100,0.5,../../etc/passwd,A\n", "line 2 column tag"),
    ("100,nan,7,A\n", "line 2 column frac: 'nan'"),
    ("100,0.5,7,\n", "line 2 column serial: ''"),
    ("100,0.5,7,A,extra,more\n", "does not parse as CSV"),
    ("100,0.5,7,A\n100,0.5,7\x00,A\n", "NUL byte"),
    ("", "holds a header and no detections"),
])
def test_hostile_detections_are_refused_in_one_line(tmp_path, rows, found):
    path = _yaps(tmp_path, rows)
    with pytest.raises(ModelError) as error:
        read_detections(path)
    assert found in str(error.value) and "\n" not in str(error.value)


def test_a_missing_column_a_duplicate_header_and_a_bad_format_are_refused(tmp_path):
    for text, found in (("epo,frac,tag\n1,0,7\n", "serial missing"), ("epo,frac,tag,serial,tag\n1,0,7,A,8\n",
                                                                       "given twice")):
        path = tmp_path / "h.csv"
        path.write_text(text)
        with pytest.raises(ModelError, match=found):
            read_detections(path)
    with pytest.raises(ModelError, match="format"):
        read_detections(tmp_path / "h.csv", "lotek")


def test_large_files_and_non_regular_files_are_refused_before_reading(tmp_path, monkeypatch):
    path = _yaps(tmp_path, "100,0.5,7,A\n" * 50)
    monkeypatch.setattr(reader, "MAX_DETECTION_BYTES", 200)
    with pytest.raises(ModelError, match="allowed at most 0 MiB"):
        read_detections(path)
    monkeypatch.undo()
    monkeypatch.setattr(reader, "MAX_DETECTIONS", 10)
    with pytest.raises(ModelError, match="has 50 rows"):
        read_detections(path)
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    with pytest.raises(ModelError, match="not a regular file"):
        read_detections(fifo)
    with pytest.raises(ModelError, match="is a directory"):
        read_detections(tmp_path)


def test_bad_vue_cells_are_refused(tmp_path):
    path = tmp_path / "vue.csv"
    for old, new, found in (("2023-08-31 22:00:03", "2023-02-30 22:00:03", "a date and time that exists"),
                            ("2023-08-31 22:00:03", "31/08/2023 22:00", "an ISO 8601 time"),
                            ("12.5,m", "inf,m", "column Sensor Value: 'inf'"),
                            ("(UTC)", "(CET)", "Date and Time (UTC)")):
        path.write_text(VUE.replace(old, new, 1))
        with pytest.raises(ModelError) as error:
            read_detections(path, "vue")
        assert found in str(error.value) and "\n" not in str(error.value)


def test_bad_receivers_and_sound_speed_are_refused(tmp_path):
    path = tmp_path / "h.csv"
    for text, found in (("serial,sync_tag,x_m,y_m\nA,7,0,0\nA,8,1,1\n", "receiver A is given twice"),
                        ("serial,sync_tag,x_m,y_m\nA,7,0,0\nB,7,1,1\n", "sync tag 7 is at two receivers"),
                        ("serial,sync_tag,x,y\nA,7,1e8,0\n", "line 2 column x: '1e8'"),
                        ("serial,sync_tag,lat,lon\nA,7,1,0\n", "needs serial, x_m and y_m")):
        path.write_text(text)
        with pytest.raises(ModelError, match=found):
            read_hydrophones(path)
    ok = tmp_path / "ok.csv"
    ok.write_text("idx,serial,sync_tag,x,y,z\n1,A,7,0,0,-5\n2,B,,10,0,-6\n")
    h = read_hydrophones(ok)
    assert h["sync_tag"].tolist() == ["7", ""] and h["z"].tolist() == [-5.0, -6.0]
    for text, found in (("epo,ss\n1,1500\n1,1501\n", "line 3: the time 1 s does not increase"),
                        ("epo,ss\n1,2000\n", "line 2 column ss: '2000'"), ("t,c\n1,1500\n", "needs epo")):
        path.write_text(text)
        with pytest.raises(ModelError, match=found):
            read_sound_speed(path)
