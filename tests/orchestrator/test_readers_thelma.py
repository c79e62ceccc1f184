"""Thelma Biomedical's TBR exports (both layouts actel reads: ``processThelmaOldFile``, ``processThelmaNewFile``) read
into detections, each against an expectation computed here with plain pandas from the same rows: the time from the
Unix timestamp and the millisecond (not the date's whole second alone), the code space before the protocol's dash,
``-`` as missing, the format told from the header (not VUE's, whose date column Thelma's share)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.detections import read_detections, sniff_format

OLD = """Date and Time (UTC),TBR Serial Number,Unix Timestamp (UTC),Millisecond,CodeType,Id,Data,Signal to Noise Ratio
2020-09-14 06:10:02,811,1600063802,17,R64K,305,-,31
2020-09-14 06:10:04,811,1600063804,998,R64K,306,-,18
2020-09-14 06:11:30,811,1600063890,450,S256,77,143,25
2020-09-14 06:12:00,811,1600063920,0,S256,77,-,40
"""
NEW = """Date and Time (UTC),Unix Timestamp (UTC),ID,Data,Protocol,SNR,Receiver
2022-05-02T11:00:00Z,1651489200.250,1204,-,R64K-69kHz,29,TBR700-1050
2022-05-02T11:00:01Z,1651489201875,1205,-,R64K-69kHz,33,TBR700-1050
2022-05-02T11:00:09Z,1651489209.5,88,200,S256-69kHz,21,1050
"""


def _write(tmp_path, text: str, name: str = "tbr.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _old_expected(text: str) -> pd.DataFrame:
    t = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)
    data = pd.to_numeric(t["Data"].replace("-", np.nan))
    return pd.DataFrame({"receiver": t["TBR Serial Number"], "tag": t["CodeType"] + "-" + t["Id"],
                         "time": t["Unix Timestamp (UTC)"].astype(float) + t["Millisecond"].astype(float) / 1000,
                         "sensor_value": data.astype(float)})


def test_the_old_layout_is_read_with_its_milliseconds(tmp_path):
    d = read_detections(_write(tmp_path, OLD), None)
    want = _old_expected(OLD)
    assert d.format == "thelma"
    assert d.frame["receiver"].tolist() == want["receiver"].tolist()
    assert d.frame["tag"].tolist() == want["tag"].tolist()
    np.testing.assert_allclose(d.frame["time"], want["time"], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(d.frame["sensor_value"].to_numpy(), want["sensor_value"].to_numpy())
    assert d.frame["sensor_unit"].tolist() == ["raw" if np.isfinite(v) else "" for v in want["sensor_value"]]
    assert d.frame["line"].tolist() == [2, 3, 4, 5]
    assert d.ignored_columns == ["Signal to Noise Ratio"]
    dates = pd.to_datetime(pd.read_csv(io.StringIO(OLD))["Date and Time (UTC)"], utc=True)
    seconds = (dates - pd.Timestamp("1970-01-01", tz="UTC")).dt.total_seconds()
    assert (np.floor(d.frame["time"]) == seconds).all()  # the same second as the date


def test_the_old_layout_without_unix_times_takes_the_date_and_its_millisecond(tmp_path):
    text = OLD.replace("1600063802", "NA").replace("1600063804", "-")  # as actel's own tests write it
    d = read_detections(_write(tmp_path, text), None)
    np.testing.assert_allclose(d.frame["time"], _old_expected(OLD)["time"], rtol=0, atol=1e-6)


def test_the_new_layout_is_read_seconds_or_milliseconds(tmp_path):
    d = read_detections(_write(tmp_path, NEW), "thelma")
    t = pd.read_csv(io.StringIO(NEW), dtype=str, keep_default_na=False)
    unix = t["Unix Timestamp (UTC)"]
    want = np.where(unix.str.contains(r"\."), unix.astype(float), unix.astype(float) / 1000)
    np.testing.assert_allclose(d.frame["time"], want, rtol=0, atol=1e-6)
    assert d.frame["tag"].tolist() == (t["Protocol"].str.split("-").str[0] + "-" + t["ID"]).tolist()
    assert d.frame["code_space"].tolist() == ["R64K", "R64K", "S256"]
    assert d.frame["receiver"].tolist() == t["Receiver"].str.split("-").str[-1].tolist()
    assert np.isnan(d.frame["sensor_value"].iloc[0]) and d.frame["sensor_value"].iloc[2] == 200


def test_both_layouts_are_told_from_the_header_not_taken_for_vue(tmp_path):
    assert sniff_format(_write(tmp_path, OLD, "old.csv")) == "thelma"
    assert sniff_format(_write(tmp_path, NEW, "new.csv")) == "thelma"
    vue = "Date and Time (UTC),Receiver,Transmitter\n2022-05-02 11:00:00,VR2W-1,A69-1602-5\n"
    assert sniff_format(_write(tmp_path, vue, "vue.csv")) == "vue"


def test_a_date_and_a_unix_time_of_different_seconds_are_refused(tmp_path):
    text = NEW.replace("2022-05-02T11:00:09Z", "2022-05-02T11:00:10Z")
    with pytest.raises(ModelError) as err:
        read_detections(_write(tmp_path, text), None)
    message = str(err.value)
    assert "\n" not in message and "line 4" in message and "Unix Timestamp (UTC)" in message


def test_a_bad_id_is_refused_with_its_line_and_column(tmp_path):
    with pytest.raises(ModelError, match=r"line 3 column Id: 'x y'"):
        read_detections(_write(tmp_path, OLD.replace(",306,", ",x y,")), None)


def test_a_folder_of_receivers_files_in_different_formats_is_one_table(tmp_path):
    from sblsim.orchestrator.readers.study_files import read_many, study_files

    vue = "Date and Time (UTC),Receiver,Transmitter\n2020-09-14 06:10:03.5,VR2W-900,A69-1602-5\n"
    for name, text in (("a_old.csv", OLD), ("b_new.csv", NEW), ("c_vue.csv", vue)):
        _write(tmp_path, text, name)
    (tmp_path / "notes.txt").write_text("not a detections file")
    files = study_files(tmp_path, receivers=tmp_path / "deployments.csv")
    d = read_many(files.detections)
    assert d.format == "thelma+vue"
    assert [Path(f).name for f in d.frame["file"].astype(str)] == ["a_old.csv"] * 4 + ["b_new.csv"] * 3 + ["c_vue.csv"]
    assert d.frame["line"].tolist() == [2, 3, 4, 5, 2, 3, 4, 2]
    assert d.frame["receiver"].tolist() == ["811"] * 4 + ["1050"] * 3 + ["900"]
    assert any("notes.txt" in n for n in files.notes)
