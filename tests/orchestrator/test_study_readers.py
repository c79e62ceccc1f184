"""The detection exports a telemetry study brings (:mod:`sblsim.orchestrator.readers.fathom`,
:mod:`sblsim.orchestrator.readers.detections`), each on a file laid out as its vendor's or network's documentation
shows it (Fathom's interleaved record types with their ``_DESC`` lines, glatos's ``vdat_csv_schema`` columns; the
GLATOS and OTN extracts' column names; VUE with ISO times, a byte-order mark and short rows), read against an
independent parse (the csv module and datetime); the format read from the first line; full transmitter IDs (one id
in two code spaces two tags); UTC times (ISO 8601 and epoch) to the microsecond; bad input refused in one line."""

from __future__ import annotations

import csv
import datetime as dt
import io

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import iso_utc, parse_instant, utc_seconds
from sblsim.orchestrator.readers.detections import read_detections, sniff_format
from sblsim.orchestrator.readers.transmitters import match


def _epoch(text: str) -> float:
    """An ISO time's seconds since 1970 UTC by datetime (a zone-less text is UTC)."""
    stamp = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=dt.timezone.utc)
    return stamp.timestamp()


# --------------------------------------------------------------------------------------------------- times

def test_utc_times_against_datetime():
    texts = ["2023-08-31T21:15:42.123456Z", "2023-08-31 21:15:42.5", "2023-08-31T23:15:42+02:00",
             "2023-08-31T16:15:42-0500", "2023-08-31", "2023-08-31 21:15:42 UTC", "2023-08-31T21:15"]
    expected = [_epoch("2023-08-31T21:15:42.123456+00:00"), _epoch("2023-08-31T21:15:42.5"),
                _epoch("2023-08-31T21:15:42"), _epoch("2023-08-31T21:15:42"), _epoch("2023-08-31T00:00:00"),
                _epoch("2023-08-31T21:15:42"), _epoch("2023-08-31T21:15:00")]
    got = utc_seconds(texts, "t", list(range(len(texts))), "time")
    assert np.max(np.abs(got - expected)) < 1e-6
    # written back to the microsecond, and read again to the same seconds
    again = utc_seconds(iso_utc(got), "t", list(range(len(texts))), "time")
    assert np.max(np.abs(again - got)) < 1e-6
    assert iso_utc([1693516542.123456])[0] == "2023-08-31T21:15:42.123456Z"
    epochs = utc_seconds(["1693516542.123456", "1693516543"], "t", [1, 2], "epo")
    assert np.allclose(epochs, [1693516542.123456, 1693516543], rtol=0, atol=1e-6)
    assert parse_instant("2017-01-01T00:00:00Z", "o") == _epoch("2017-01-01T00:00:00Z")


@pytest.mark.parametrize("cells, found", [
    (["2023-02-30T00:00:00Z"], "a date and time that exists"),
    (["31/08/2023 21:15"], "an ISO 8601 time"),
    (["1693516542", "2023-08-31"], "one form per column"),
    (["1e9"], "an ISO 8601 time"),
    (["1969-12-31T23:59:59Z"], "a time from 1970"),
])
def test_bad_times_are_refused_in_one_line(cells, found):
    with pytest.raises(ModelError) as error:
        utc_seconds(cells, "detections: 'x.csv'", [5, 6], "ts")
    message = str(error.value)
    assert found in message and ("line 5" in message or "line 6" in message) and "\n" not in message


# --------------------------------------------------------------------------------------------------- Fathom

#: DET's columns in Fathom's format 2 (glatos's vdat_csv_schema v2.0.0), and DET_SENS's.
DET = ["Device Time (UTC)", "Time", "Time Offset (h)", "Time Correction (s)", "Model", "Serial Number", "Channel",
       "Detection Type", "Full ID", "ID", "Raw Data", "Transmitter Serial", "Signal Strength (dB)", "Noise (dB)",
       "Gain (dB)", "Quality Score", "Station Name", "Latitude", "Longitude", "GPS HDOP"]
DET_SENS = DET + ["Transmitter Type", "Sensor Function", "Sensor Value", "Sensor Unit", "Sensor Precision",
                  "Definition Source"]
TEMP = ["Device Time (UTC)", "Time", "Time Offset (h)", "Time Correction (s)", "Model", "Serial Number",
        "Ambient (deg C)", "Internal (deg C)"]


def _fathom_row(time: str, serial: str, full_id: str, raw: str = "", station: str = "N1") -> list[str]:
    ident = full_id.rpartition("-")[2]
    return [time, time, "+0", "0", "HR2-180", serial, "1", "PPM", full_id, ident, raw, "", "120.5", "45.0", "0",
            "100", station, "60.38", "5.33", ""]


def _fathom(rows: list[list[str]], sens: list[list[str]] = (), temps: list[list[str]] = ()) -> str:
    """A Fathom CSV as Fathom writes it: its first line, the record-type line, each type's _DESC line, then the
    records of the types interleaved."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    out.write("VEMCO DATA LOG,2.0.0,vdat-9.3.0-20240207-74ad8e-release\n")
    w.writerow(["RECORD TYPE"] + ["FIELD"] * (len(DET_SENS)))
    w.writerow(["DATA_SOURCE_FILE_DESC", "File Name", "UUID", "Type"])
    w.writerow(["DET_DESC"] + DET)
    w.writerow(["DET_SENS_DESC"] + DET_SENS)
    w.writerow(["TEMP_DESC"] + TEMP)
    w.writerow(["DATA_SOURCE_FILE", "HR2-180_461396_2021-04-20_173145.vdat", "c1f3", "VDAT"])
    for k, row in enumerate(rows):
        w.writerow(["DET"] + row)
        if k < len(temps):
            w.writerow(["TEMP"] + temps[k])
    for row in sens:
        w.writerow(["DET_SENS"] + row)
    return out.getvalue()


def test_a_fathom_csv_against_the_csv_module(tmp_path):
    rows = [_fathom_row("2021-04-20 17:32:01.123456", "461396", "A69-1602-4555"),
            _fathom_row("2021-04-20 17:32:01.987", "461397", "A69-1602-4555", raw="37"),
            _fathom_row("2021-04-20 17:33:05", "461396", "A69-1601-4555", station="South, deep"),
            _fathom_row("2021-04-20 17:34:00.5", "461396", "A69-1602-4555")]
    temps = [["2021-04-20 17:32:00", "2021-04-20 17:32:00", "+0", "0", "HR2-180", "461396", "9.5", "10.1"]]
    sens_row = _fathom_row("2021-04-20 17:34:00.5", "461396", "A69-1602-4555", raw="40") + \
        ["P", "depth", "12.5", "m", "0.1", "tag definition"]
    alone = _fathom_row("2021-04-20 17:35:00.25", "461397", "A69-1602-7777", raw="41") + \
        ["P", "depth", "13.0", "m", "0.1", "tag definition"]
    path = tmp_path / "fathom.csv"
    path.write_text("\ufeff" + _fathom(rows, [sens_row, alone], temps), encoding="utf-8")
    assert sniff_format(path) == "fathom"
    d = read_detections(path, None)
    f = d.frame
    # the independent parse: the csv module, the DET and DET_SENS lines by their first field
    with open(path, newline="", encoding="utf-8-sig") as handle:
        records = [(k + 1, r) for k, r in enumerate(csv.reader(handle)) if r and r[0] in ("DET", "DET_SENS")]
    det = [(line, r) for line, r in records if r[0] == "DET"]
    assert d.format == "fathom" and len(f) == len(det) + 1  # the DET_SENS record alone is one more detection
    assert f["receiver"].tolist()[:4] == [r[1 + DET.index("Serial Number")] for _, r in det]
    assert f["tag"].tolist() == ["A69-1602-4555", "A69-1602-4555", "A69-1601-4555", "A69-1602-4555",
                                 "A69-1602-7777"]
    assert f["code_space"].tolist()[:3] == ["A69-1602", "A69-1602", "A69-1601"]
    expected = [_epoch(r[1 + DET.index("Device Time (UTC)")]) for _, r in det]
    assert np.max(np.abs(f["time"].to_numpy()[:4] - expected)) < 1e-6
    assert f["line"].tolist()[:4] == [line for line, _ in det]
    # a raw value where the tag's definition is not known; the DET_SENS record's converted value where it is
    assert f["sensor_value"].iloc[1] == 37.0 and f["sensor_unit"].iloc[1] == "raw"
    assert f["sensor_value"].iloc[3] == 12.5 and f["sensor_unit"].iloc[3] == "m"
    assert f["sensor_value"].iloc[4] == 13.0 and f["station"].iloc[2] == "South, deep"
    # one id in two code spaces: two tags
    assert f["tag"].nunique() == 3


@pytest.mark.parametrize("change, found", [
    (lambda t: t.replace("VEMCO DATA LOG", "SOMETHING ELSE", 1), "starts with the line VEMCO DATA LOG"),
    (lambda t: "\n".join(line for line in t.split("\n") if not line.startswith("DET_DESC")), "no DET_DESC line"),
    (lambda t: t.replace("2021-04-20 17:33:05", "2021-04-31 17:33:05", 2), "a date and time that exists"),
    (lambda t: t.replace("A69-1601-4555", "A69-1601-../x", 1), "column Full ID"),
    (lambda t: t.replace("Full ID", "Full Identity", 1), "Full ID missing"),
    (lambda t: t.replace(",", ";"), "DET_DESC line's columns are separated by semicolons"),
    (lambda t: t.replace(",", "\t"), "DET_DESC line's columns are separated by tabs"),
    (lambda t: t.replace(",", ";").replace("\nDET_DESC", '\n"DET_DESC"'), "separated by semicolons"),
])
def test_bad_fathom_files_are_refused_in_one_line(tmp_path, change, found):
    rows = [_fathom_row("2021-04-20 17:32:01", "461396", "A69-1602-4555"),
            _fathom_row("2021-04-20 17:33:05", "461396", "A69-1601-4555")]
    path = tmp_path / "fathom.csv"
    path.write_text(change(_fathom(rows)))
    with pytest.raises(ModelError) as error:
        read_detections(path, "fathom")
    assert found in str(error.value) and "\n" not in str(error.value)


# --------------------------------------------------------------------------------------------------- networks

GLATOS = ("animal_id,detection_timestamp_utc,glatos_array,station_no,transmitter_codespace,transmitter_id,"
          "sensor_value,sensor_unit,deploy_lat,deploy_long,receiver_sn,tag_type,tag_model,tag_serial_number,"
          "common_name_e,capture_location,length,weight,sex,release_group,release_location,release_latitude,"
          "release_longitude,utc_release_date_time,glatos_project_transmitter,glatos_project_receiver,"
          "glatos_tag_recovered,glatos_caught_date,station,min_lag\n"
          "153,2012-04-29 01:48:37.25,TTB,2,A69-9001,32054,,,43.39165,-83.99264,113213,,,,walleye,Tittabawassee "
          "River,0.565,,F,,Tittabawassee,,,2012-03-20 20:00:00,HECWL,HECWL,NO,,TTB-002,258\n"
          "153,2012-04-29 01:52:55,TTB,3,A69-9001,32054,12.5,m,43.39,-83.99,113214,,,,walleye,\"Tittabawassee, "
          "River\",0.565,,F,,Tittabawassee,,,2012-03-20 20:00:00,HECWL,HECWL,NO,,TTB-003,137\n"
          "154,2012-04-29 01:53:00.5,TTB,2,A69-1601,32054,,,43.39165,-83.99264,113213,,,,walleye,x,0.5,,F,,x,,,"
          "2012-03-20 20:00:00,HECWL,HECWL,NO,,TTB-002,1\n")
OTN = ("collectionCode,catalogNumber,scientificName,commonName,dateLastModified,detectedBy,station,receiver,"
       "bottomDepth,receiver_depth,tagName,codeSpace,sensorName,sensorRaw,sensorType,sensorValue,sensorUnit,"
       "dateCollectedUTC,decimalLongitude,decimalLatitude\n"
       "OTN.NSBS,NSBS-Hooker,Prionace glauca,blue shark,2014-12-18,OTN.HFX,HFX047,VR2W-146,151.0,146.0,"
       "A69-9001-24395,A69-9001,,,pinger,,,2014-08-29T06:11:09.125Z,-63.23715,44.2133\n"
       "OTN.NSBS,NSBS-Hooker,Prionace glauca,blue shark,2014-12-18,OTN.HFX,HFX048,147,151.0,146.0,"
       "A69-9001-24395,A69-9001,,,pinger,,,2014-08-29T06:14:43Z,-63.23715,44.2133\n")


def test_a_glatos_extract_against_the_csv_module(tmp_path):
    path = tmp_path / "glatos.csv"
    path.write_text(GLATOS)
    assert sniff_format(path) == "glatos"
    f = read_detections(path, None).frame
    # an extract is put in each receiver's order (by receiver, then time), not kept in the query's
    rows = sorted(csv.DictReader(io.StringIO(GLATOS)), key=lambda r: (r["receiver_sn"],
                                                                     _epoch(r["detection_timestamp_utc"])))
    assert f["receiver"].tolist() == [r["receiver_sn"] for r in rows]
    assert f["tag"].tolist() == [f"{r['transmitter_codespace']}-{r['transmitter_id']}" for r in rows]
    assert np.max(np.abs(f["time"].to_numpy() - [_epoch(r["detection_timestamp_utc"]) for r in rows])) < 1e-6
    assert f["station"].tolist() == [r["station"] for r in rows]
    sensed = [k for k, r in enumerate(rows) if r["sensor_value"]]
    assert f["sensor_value"].iloc[sensed].tolist() == [12.5] and f["sensor_unit"].iloc[sensed].tolist() == ["m"]
    assert f["tag"].nunique() == 2  # 32054 in two code spaces


def test_an_otn_extract_new_and_old_names(tmp_path):
    path = tmp_path / "otn.csv"
    path.write_text(OTN)
    assert sniff_format(path) == "otn"
    f = read_detections(path, None).frame
    assert f["receiver"].tolist() == ["146", "147"] and f["tag"].tolist() == ["A69-9001-24395"] * 2
    assert np.allclose(f["time"], [_epoch("2014-08-29T06:11:09.125Z"), _epoch("2014-08-29T06:14:43Z")], rtol=0,
                       atol=1e-6)
    old = tmp_path / "old.csv"
    old.write_text("catalognumber,station,receiver,tagname,codespace,datecollected,longitude,latitude\n"
                   "NSBS-Hooker,HFX047,VR2W-146,A69-9001-24395,A69-9001,2014-08-29 06:11:09,-63.2,44.2\n")
    g = read_detections(old, None).frame
    assert g["tag"].tolist() == ["A69-9001-24395"] and g["receiver"].tolist() == ["146"]


def test_a_vue_export_with_iso_times_a_bom_and_short_rows(tmp_path):
    text = ("\ufeffDate and Time (UTC),Receiver,Transmitter,Transmitter Name,Transmitter Serial,Sensor Value,"
            "Sensor Unit,Station Name,Latitude,Longitude,Transmitter Type,Sensor Precision\n"
            "2011-04-11T20:17:49.250Z,VR2W-109924,A69-1303-63366,,,,,,+0,+0\n"
            "2011-05-08T05:38:32Z,VR2W-109924,A69-9002-4043,,,5,ADC,,+0,+0\n")
    path = tmp_path / "vue.csv"
    path.write_text(text, encoding="utf-8")
    assert sniff_format(path) == "vue"
    f = read_detections(path, None).frame
    assert f["tag"].tolist() == ["A69-1303-63366", "A69-9002-4043"] and f["receiver"].tolist() == ["109924"] * 2
    assert np.allclose(f["time"], [_epoch("2011-04-11T20:17:49.250Z"), _epoch("2011-05-08T05:38:32Z")], rtol=0,
                       atol=1e-6)
    assert f["sensor_unit"].tolist() == ["", "ADC"] and f["sensor_value"].iloc[1] == 5.0


def test_a_yaps_table_with_ts_only(tmp_path):
    path = tmp_path / "yaps.csv"
    path.write_text("ts,tag,serial\n2019-09-09 16:04:09.412,5125,128371\n2019-09-09 16:04:10.5,5125,128372\n")
    assert sniff_format(path) == "yaps"
    f = read_detections(path, None).frame
    assert np.allclose(f["time"], [_epoch("2019-09-09 16:04:09.412"), _epoch("2019-09-09 16:04:10.5")], rtol=0,
                       atol=1e-6)
    assert f["tag"].tolist() == ["5125"] * 2


@pytest.mark.parametrize("text, form, found", [
    ("detection_timestamp_utc,transmitter_codespace,transmitter_id\n2012-04-29 01:48:37,A69-1601,2\n", "glatos",
     "receiver_sn missing"),
    ("dateCollectedUTC,receiver,tagName\n2014-08-29 06:11:09,146,24395\n", "otn", "column tagName: '24395'"),
    ("dateCollectedUTC,receiver,tagName\n29/08/2014,146,A69-9001-24395\n", "otn", "an ISO 8601 time"),
    ("a,b,c\n1,2,3\n", None, "its first line is no format sblsim reads"),
])
def test_bad_extracts_are_refused_in_one_line(tmp_path, text, form, found):
    path = tmp_path / "x.csv"
    path.write_text(text)
    with pytest.raises(ModelError) as error:
        read_detections(path, form)
    assert found in str(error.value) and "\n" not in str(error.value)


# --------------------------------------------------------------------------------------------------- IDs

def test_a_transmitter_is_found_by_its_full_id_or_its_id():
    tags = {"A69-1602-4555", "A69-1601-7953", "A69-1602-7953", "802510"}
    assert match("A69-1602-4555", tags) == "A69-1602-4555"
    assert match("4555", tags) == "A69-1602-4555"  # one code space has it
    assert match("A69-1601-802510", tags) == "802510"  # the detections have no code space
    assert match("A69-1601-4555", tags) is None  # another code space is another tag
    assert match("a69-1602-4555", tags) == "A69-1602-4555"  # a code space typed in small letters
    assert match("a69-1601-4555", tags) is None
    with pytest.raises(ModelError, match="different code spaces .*A69-1601-7953, A69-1602-7953"):
        match("7953", tags)
