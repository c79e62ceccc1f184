"""OTN's files as published (:mod:`sblsim.orchestrator.readers.otn`, :mod:`sblsim.orchestrator.readers.deployments`),
written here from OTN's layouts (the detection extracts' documentation, the ERDDAP receiver deployment table) with
invented values: the 2025 and the older detection extracts read alike (the older's time zone column), receiver cells
annotated after the serial, the extract not matched to animals; the receiver deployment table with its units row,
``NaN`` depths, ``time`` and ``recovery_datetime_utc``, a quoted comment over two lines, a receiver without a serial
set aside, open deployments counted, a byte-order mark; each against an expectation built here with the csv module
and datetime; a stated unit the reader does not read and a station sheet without serials refused in one line."""

from __future__ import annotations

import csv
import datetime as dt
import io

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import SORTED, read_detections

NEW = ("collectionCode,catalogNumber,scientificName,commonName,dateLastModified,detectedBy,station,receiver,"
       "bottomDepth,receiver_depth,tagName,codeSpace,sensorName,sensorRaw,sensorType,sensorValue,sensorUnit,"
       "dateCollectedUTC,decimalLongitude,decimalLatitude,geometry,localArea,notes,citation,unqDetecID")
OLD = ("collectioncode,catalognumber,scientificname,commonname,datelastmodified,detectedby,receiver_group,station,"
       "receiver,bottom_depth,receiver_depth,tagname,codespace,sensorname,sensorraw,sensortype,sensorvalue,sensorunit,"
       "datecollected,timezone,longitude,latitude,yearcollected,local_area,notes,citation,unqdetecid")
#: Invented detections: (station, receiver cell, tag, time).
DETECTIONS = [("QRS012", "771", "A69-9001-51234", "2019-07-02 03:04:05"),
              ("QRS013", "772(lost/found)", "A69-9001-51234", "2019-07-02 03:05:10"),
              ("QRS012", "771", "A69-9001-51235", "2019-07-01 23:59:59"),
              ("QRS013", "772(lost/found)", "A69-9001-51235", "2019-07-01 22:10:00"),
              ("QRS014", "VR2W-773", "A69-9001-51234", "2019-07-02 01:00:00")]


def _epoch(text: str) -> float:
    stamp = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    return (stamp if stamp.tzinfo else stamp.replace(tzinfo=dt.timezone.utc)).timestamp()


def _write(path, header: str, rows: list[dict], bom: bool = False) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, header.split(","), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    path.write_text(("\ufeff" if bom else "") + out.getvalue(), encoding="utf-8")
    return out.getvalue()


def _new_rows() -> list[dict]:
    return [{"collectionCode": "OTN.XYZ", "catalogNumber": f"XYZ-{tag[-1]}", "station": station, "receiver": cell,
             "tagName": tag, "codeSpace": "A69-9001", "sensorType": "pinger", "dateCollectedUTC": when,
             "decimalLongitude": "-61.5", "decimalLatitude": "43.9", "citation": "Someone, A. 2020. \"A line\", more."}
            for station, cell, tag, when in DETECTIONS]


def _expected(text: str, receiver: str, tag: str, time: str) -> list[tuple]:
    """(serial, note, tag, time, line) per detection by the csv module, in each receiver's order."""
    out = []
    for k, r in enumerate(csv.DictReader(io.StringIO(text))):
        cell = r[receiver]
        serial, note = (cell.split("(")[0], cell.split("(")[1].rstrip(")")) if "(" in cell else (cell, "")
        out.append((serial.split("-")[-1], note, r[tag], _epoch(r[time]), k + 2))
    return sorted(out, key=lambda t: (t[0], t[3]))


def _frame_rows(frame) -> list[tuple]:
    note = frame["receiver_note"] if "receiver_note" in frame else [""] * len(frame)
    return list(zip(frame["receiver"], note, frame["tag"], frame["time"], frame["line"]))


def test_the_2025_and_the_older_extracts_read_alike(tmp_path):
    text = _write(tmp_path / "new.csv", NEW, _new_rows())
    new = read_detections(tmp_path / "new.csv", None)
    assert new.format == "otn" and new.row_order == SORTED
    assert _frame_rows(new.frame) == _expected(text, "receiver", "tagName", "dateCollectedUTC")
    old_rows = [{"collectioncode": "XYZ", "station": r["station"], "receiver": r["receiver"], "tagname": r["tagName"],
                 "codespace": r["codeSpace"], "datecollected": r["dateCollectedUTC"], "timezone": "UTC",
                 "longitude": "-61.5", "latitude": "43.9", "citation": r["citation"]} for r in _new_rows()]
    text = _write(tmp_path / "old.csv", OLD, old_rows, bom=True)
    old = read_detections(tmp_path / "old.csv", None)
    assert old.format == "otn"
    assert _frame_rows(old.frame) == _expected(text, "receiver", "tagname", "datecollected")
    columns = ["receiver", "tag", "code_space", "time", "station", "receiver_note"]
    assert new.frame[columns].equals(old.frame[columns])
    # the annotated receiver: its serial read, the note kept and counted
    assert set(new.frame.loc[new.frame["receiver_note"] != "", "receiver"]) == {"772"}
    assert any("2 detections" in n and "772(lost/found)" in n for n in new.notes)


def test_the_older_extracts_time_zone_must_be_utc(tmp_path):
    rows = [{"receiver": "771", "tagname": "A69-9001-51234", "codespace": "A69-9001", "timezone": zone,
             "datecollected": f"2019-07-02 03:0{k}:00"} for k, zone in enumerate(["UTC", "UTC", "AST"])]
    _write(tmp_path / "zone.csv", OLD, rows)
    with pytest.raises(ModelError) as error:
        read_detections(tmp_path / "zone.csv", None)
    said = str(error.value)
    assert "line 4 column timezone: 'AST'" in said and "allowed: UTC" in said and "\n" not in said


def test_an_extract_not_matched_to_animals(tmp_path):
    path = tmp_path / "unmatched.csv"
    path.write_text("catalognumber,station,datecollected,collectornumber,fieldnumber,longitude,latitude\n"
                    "XYZ-1,QRS012,2019-07-02 03:04:05,771,A69-9001-51234,-61.5,43.9\n"
                    "XYZ-1,QRS013,2019-07-02 03:00:00,772,A69-1601-51234,-61.5,43.9\n")
    f = read_detections(path, None).frame
    assert list(zip(f["receiver"], f["tag"], f["code_space"])) == [("771", "A69-9001-51234", "A69-9001"),
                                                                   ("772", "A69-1601-51234", "A69-1601")]


RECEIVERS = ("deployment_project_reference,datacenter_reference,deployment_id,deployment_guid,receiver_manufacturer,"
             "receiver_model,frequencies_monitored,receiver_coding_scheme,receiver_serial_number,latitude,longitude,"
             "time,recovery_datetime_utc,array_name,receiver_reference_type,receiver_reference_id,bottom_depth,depth,"
             "deployment_comments,deployed_by,expected_receiver_life")
UNITS = ",,,,,,,,,degrees_north,degrees_east,UTC,UTC,,,,m,m,,,"


def _receivers(path, units: str = UNITS, bom: bool = True, comment: str = "recovered by a trawler;\nsent back",
               serial: str = "") -> str:
    rows = [("771", "43.91", "-61.51", "2019-05-01T12:00:00Z", "2019-11-01T12:00:00Z", "120.0", "115.0", ""),
            (serial, "43.92", "-61.52", "2019-05-01T13:00:00Z", "", "NaN", "NaN", "no response; presumed lost"),
            ("772", "43.93", "-61.53", "2019-05-02T12:00:00Z", "2019-11-02T12:00:00Z", "NaN", "110.0", comment),
            ("773", "43.94", "-61.54", "2019-05-02T13:00:00Z", "", "131.5", "NaN", ""),
            ("771", "43.95", "-61.55", "2019-11-03T12:00:00Z", "", "140.0", "135.0", "")]
    out = io.StringIO()
    out.write(RECEIVERS + "\n" + (units + "\n" if units else ""))
    writer = csv.writer(out, lineterminator="\n")
    for s, lat, lon, start, end, bottom, depth, note in rows:
        writer.writerow(["XYZ", "OTN", f"QRS-{s}", "g", "VEMCO", "VR2W", "69", "MAP-114", s, lat, lon, start, end,
                         "QRS", "mooring", "QRS_1", bottom, depth, note, "", "NaN"])
    path.write_text(("\ufeff" if bom else "") + out.getvalue(), encoding="utf-8")
    return out.getvalue()


def test_an_otn_receiver_deployment_table_as_published(tmp_path):
    text = _receivers(tmp_path / "receivers.csv")
    d = read_deployments(tmp_path / "receivers.csv")
    # the expectation: the csv module's records after the units row, each with the line it starts on
    reader = csv.reader(io.StringIO(text))
    header, records, start = next(reader), [], reader.line_num + 1
    for row in reader:
        records.append((start, dict(zip(header, row))))
        start = reader.line_num + 1
    records = [(line, r) for line, r in records[1:] if r["receiver_serial_number"]]  # the units row; no serial

    def value(cell: str) -> float:
        return np.nan if cell in ("", "NaN") else float(cell)

    t = d.table
    assert t["serial"].tolist() == [r["receiver_serial_number"] for _, r in records]
    assert t["line"].tolist() == [line for line, _ in records]
    assert t["lat"].tolist() == [float(r["latitude"]) for _, r in records]
    assert np.allclose(t["z"], [-value(r["depth"]) for _, r in records], equal_nan=True)
    assert np.allclose(t["bottom_depth"], [value(r["bottom_depth"]) for _, r in records], equal_nan=True)
    assert t["start"].tolist() == [_epoch(r["time"]) for _, r in records]
    assert t["end"].tolist() == [_epoch(r["recovery_datetime_utc"]) if r["recovery_datetime_utc"] else np.inf
                                 for _, r in records]
    assert t["receiver"].tolist() == ["771.1", "772", "773", "771.2"]  # one serial twice: one receiver per deployment
    notes = " | ".join(d.notes)
    assert "line 2: the units row under the header skipped" in notes
    assert "1 deployments without a serial (receiver_serial_number empty: line 4) set aside" in notes
    assert "2 of 4 deployments without a recovery date: open" in notes


def test_a_receiver_table_without_a_units_row_or_a_bom_reads_the_same(tmp_path):
    _receivers(tmp_path / "a.csv")
    _receivers(tmp_path / "b.csv", units="", bom=False, comment="one line", serial="NaN")
    a, b = read_deployments(tmp_path / "a.csv").table, read_deployments(tmp_path / "b.csv").table
    assert a.drop(columns="line").equals(b.drop(columns="line"))
    # the units row above every row, the comment's second line above the rows after it
    assert (a["line"] - b["line"]).tolist() == [1, 1, 2, 2]


def test_a_stated_unit_not_read_is_refused_in_one_line(tmp_path):
    _receivers(tmp_path / "feet.csv", units=UNITS.replace(",m,m,", ",ft,m,"))
    with pytest.raises(ModelError) as error:
        read_deployments(tmp_path / "feet.csv")
    said = str(error.value)
    assert "line 2 column bottom_depth: the units row gives 'ft'" in said and "allowed: m" in said
    assert "\n" not in said


def test_a_table_whose_every_serial_is_empty_is_refused(tmp_path):
    (tmp_path / "none.csv").write_text(RECEIVERS + "\n" + UNITS + "\n" + ",,,,,,,,,43.9,-61.5,2019-05-01T12:00:00Z,"
                                       ",,,,NaN,NaN,,,\n")
    with pytest.raises(ModelError, match="no row names a receiver's serial"):
        read_deployments(tmp_path / "none.csv")


def test_a_station_sheet_without_serials_is_refused_naming_the_table_that_has_them(tmp_path):
    path = tmp_path / "stations.csv"
    path.write_text("collectioncode,seriescode,ocean,station_name,station_type,stn_lat,stn_long,stationstatus,locality,"
                    "model,instrumenttype,deploy_date,last_download,recovery_date,downloads,off_set\n"
                    "QRS,S1,N SEA,QRS012,receiver,43.91,-61.51,open,Offshore bank,VR2W,rx,2019-05-01,"
                    "2019-11-01,2019-11-01,2,1.5\n")
    with pytest.raises(ModelError) as error:
        read_deployments(path)
    said = str(error.value)
    assert "station sheet" in said and "put at receivers by serial" in said and "receiver_serial_number" in said
    assert "\n" not in said
