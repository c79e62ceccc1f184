"""A network's detection extract in any row order (:mod:`sblsim.orchestrator.readers.network`, GLATOS's layout from
the GLATOS data dictionary): an extract sorted by tag and the same rows sorted by time give one frame, each row's
order by receiver and time and its line checked against an expectation built here with the csv module and datetime;
exact duplicates (one row in two extracts) dropped and counted; a byte-order mark and an ERDDAP units row; a
receiver's own log (VUE) still judged in the order it logged and a YAPS table's duplicates kept (the boats' rule);
one serial deployed at many stations over the years, each detection at its deployment; the count in study.json."""

from __future__ import annotations

import csv
import datetime as dt
import io

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.assign import assign
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import LOGGED, SORTED, read_detections

HEADER = ("animal_id,detection_timestamp_utc,glatos_array,station_no,transmitter_codespace,transmitter_id,"
          "sensor_value,sensor_unit,deploy_lat,deploy_long,receiver_sn,tag_type,tag_model,tag_serial_number,"
          "common_name_e,capture_location,length,weight,sex,release_group,release_location,release_latitude,"
          "release_longitude,utc_release_date_time,glatos_project_transmitter,glatos_project_receiver,"
          "glatos_tag_recovered,glatos_caught_date,station,min_lag")
START = dt.datetime(2021, 5, 3, 6, 0, 0, tzinfo=dt.timezone.utc)


def _epoch(text: str) -> float:
    return dt.datetime.fromisoformat(text).replace(tzinfo=dt.timezone.utc).timestamp()


def _rows(seed: int = 4, n: int = 60) -> list[dict]:
    """Invented detections of three tags at four receivers (whole seconds, as GLATOS exports them; no two of one
    receiver at one second)."""
    rng = np.random.default_rng(seed)
    seconds = np.sort(rng.choice(20_000, n, replace=False))
    rows = []
    for k, s in enumerate(seconds):
        tag = ("A69-1601", str(7001 + k % 3))
        receiver = str(450100 + int(rng.integers(4)))
        rows.append({"animal_id": f"F{tag[1]}", "detection_timestamp_utc":
                     (START + dt.timedelta(seconds=int(s))).strftime("%Y-%m-%d %H:%M:%S"),
                     "glatos_array": "LKX", "station_no": receiver[-1], "transmitter_codespace": tag[0],
                     "transmitter_id": tag[1], "sensor_value": "", "sensor_unit": "", "deploy_lat": "45.1",
                     "deploy_long": "-83.2", "receiver_sn": receiver, "station": f"LKX-00{receiver[-1]}"})
    return rows


def _text(rows: list[dict], bom: bool = False) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, HEADER.split(","), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return ("\ufeff" if bom else "") + out.getvalue()


def _expected(text: str) -> pd.DataFrame:
    """The rows of a GLATOS extract (the csv module) in each receiver's order: by receiver, then time, ties in the
    file's order; each with its line (the header's is 1); an exact repeat (receiver, tag, time) after its first
    dropped."""
    rows = list(csv.DictReader(io.StringIO(text.lstrip("\ufeff"))))
    table = [(r["receiver_sn"], f"{r['transmitter_codespace']}-{r['transmitter_id']}",
              _epoch(r["detection_timestamp_utc"]), r["station"], k + 2) for k, r in enumerate(rows)]
    table.sort(key=lambda t: (t[0], t[2]))  # Python's sort is stable
    seen, kept = set(), []
    for t in table:
        if t[:3] not in seen:
            seen.add(t[:3])
            kept.append(t)
    return pd.DataFrame(kept, columns=["receiver", "tag", "time", "station", "line"])


def _read(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return read_detections(path, None)


def _same(frame: pd.DataFrame, expected: pd.DataFrame, lines: bool = True) -> None:
    assert frame["receiver"].tolist() == expected["receiver"].tolist()
    assert frame["tag"].tolist() == expected["tag"].tolist()
    assert np.max(np.abs(frame["time"].to_numpy() - expected["time"].to_numpy())) < 1e-6
    assert frame["station"].tolist() == expected["station"].tolist()
    if lines:
        assert frame["line"].tolist() == expected["line"].tolist()


def test_an_extract_sorted_by_tag_and_by_time_give_one_frame_in_each_receivers_order(tmp_path):
    rows = _rows()
    by_tag = sorted(rows, key=lambda r: (r["transmitter_id"], r["detection_timestamp_utc"]))
    a = _read(tmp_path, "by_tag.csv", _text(by_tag))
    b = _read(tmp_path, "by_time.csv", _text(rows))
    assert a.format == b.format == "glatos" and a.row_order == b.row_order == SORTED
    # the same detections, in the same order; each its own file's line
    _same(a.frame, _expected(_text(by_tag)))
    _same(b.frame, _expected(_text(rows)))
    columns = ["receiver", "tag", "time", "station", "code_space"]
    pd.testing.assert_frame_equal(a.frame[columns], b.frame[columns])
    # no clock judged in a query's order: none reset, no clock part
    assert a.clock_resets == [] and "clock_part" not in a.frame and a.duplicates == 0
    # each receiver's times never go back
    assert (a.frame.groupby("receiver")["time"].diff().dropna() >= 0).all()


def test_exact_duplicates_in_two_extracts_joined_are_dropped_and_counted(tmp_path):
    rows = _rows(seed=9)
    twice = [dict(r) for r in rows[10:25]]
    joined = rows + twice  # the second extract overlaps the first by 15 detections
    d = _read(tmp_path, "joined.csv", _text(joined))
    assert d.duplicates == len(twice) == len(joined) - len(d.frame)
    _same(d.frame, _expected(_text(joined)))  # each kept row the first in the file (its line)
    single = _read(tmp_path, "single.csv", _text(rows))
    assert d.frame.drop(columns="line").equals(single.frame.drop(columns="line"))
    # the same time at one receiver for two tags is no duplicate
    other = dict(rows[3], transmitter_id="7999")
    e = _read(tmp_path, "two_tags.csv", _text(rows + [other]))
    assert e.duplicates == 0 and len(e.frame) == len(rows) + 1


def test_a_byte_order_mark_and_an_erddap_units_row_in_an_extract(tmp_path):
    rows = _rows(seed=2, n=12)
    d = _read(tmp_path, "bom.csv", _text(rows, bom=True))
    _same(d.frame, _expected(_text(rows)))
    units = {k: "" for k in HEADER.split(",")} | {"detection_timestamp_utc": "UTC", "deploy_lat": "degrees_north",
                                                   "deploy_long": "degrees_east"}
    e = _read(tmp_path, "units.csv", _text([units] + rows))
    expected = _expected(_text(rows))
    expected["line"] += 1  # the rows one line further down
    _same(e.frame, expected)
    units["detection_timestamp_utc"] = "days since 2000-01-01"
    with pytest.raises(ModelError) as error:
        _read(tmp_path, "days.csv", _text([units] + rows))
    assert "line 2 column detection_timestamp_utc" in str(error.value) and "utc" in str(error.value)
    assert "\n" not in str(error.value)


def test_a_receivers_own_log_is_still_judged_in_the_order_it_logged(tmp_path):
    """A VUE export is a receiver's log: sorted by tag, its clock would go back between tags (refused, as before);
    in its order it is read as logged. A YAPS table's exact repeats are kept (taken as logged)."""
    head = ("Date and Time (UTC),Receiver,Transmitter,Transmitter Name,Transmitter Serial,Sensor Value,Sensor Unit,"
            "Station Name,Latitude,Longitude\n")
    logged = [(f"2021-05-03 06:{m:02d}:05", f"A69-1601-{7001 + m % 2}") for m in range(20)]
    by_tag = sorted(logged, key=lambda r: r[1])
    body = "".join(f"{t},VR2W-450101,{tag},,,,,,0,0\n" for t, tag in by_tag)
    with pytest.raises(ModelError, match=r"clock goes back .* sorted by tag"):
        _read(tmp_path, "vue_by_tag.csv", head + body)
    ok = _read(tmp_path, "vue.csv", head + "".join(f"{t},VR2W-450101,{tag},,,,,,0,0\n" for t, tag in logged))
    assert ok.row_order == LOGGED and ok.frame["line"].tolist() == list(range(2, len(logged) + 2))
    yaps = _read(tmp_path, "yaps.csv", "epo,frac,tag,serial\n1620021605,0.25,51,A\n1620021605,0.25,51,A\n"
                                       "1620021665,0.5,51,A\n")
    assert yaps.row_order == LOGGED and yaps.duplicates == 0 and len(yaps.frame) == 3


def test_one_serial_redeployed_over_years_each_detection_at_its_deployment(tmp_path):
    """GLATOS receiver locations: serial 450101 at three stations in three seasons, 450102 once; an extract sorted
    by tag: each detection at the deployment whose window holds it (expected here by a loop over the windows)."""
    seasons = [("2019-04-01 12:00:00", "2019-11-01 12:00:00", "LKX-001", "45.10", "-83.20"),
               ("2020-04-02 12:00:00", "2020-10-30 12:00:00", "LKX-002", "45.11", "-83.21"),
               ("2021-04-03 12:00:00", "", "LKX-003", "45.12", "-83.22")]
    sheet = io.StringIO()
    sheet.write("station,glatos_array,station_no,consecutive_deploy_no,intend_lat,intend_long,deploy_lat,deploy_long,"
                "recover_lat,recover_long,deploy_date_time,recover_date_time,bottom_depth,riser_length,"
                "instrument_depth,ins_model_no,glatos_ins_frequency,ins_serial_no,deployed_by,comments,"
                "glatos_seasonal,glatos_project,glatos_vps\n")
    for k, (start, end, station, lat, lon) in enumerate(seasons):
        sheet.write(f"{station},LKX,{k + 1},{k + 1},,,{lat},{lon},,,{start},{end},,,,VR2W,69,450101,,,YES,LKXP,NO\n")
    sheet.write("LKX-009,LKX,9,1,,,45.13,-83.23,,,2019-04-01 12:00:00,2021-12-01 00:00:00,,,,VR2W,69,450102,,,NO,"
                "LKXP,NO\n")
    (tmp_path / "receivers.csv").write_text(sheet.getvalue())
    deployments = read_deployments(tmp_path / "receivers.csv")
    assert "1 of 4 deployments without a recovery date: open" in " ".join(deployments.notes)
    rng = np.random.default_rng(1)
    rows = []
    for k, when in enumerate(np.sort(rng.uniform(_epoch("2019-03-01 00:00:00"), _epoch("2022-01-01 00:00:00"), 80))):
        stamp = dt.datetime.fromtimestamp(int(when), dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
        rows.append({"detection_timestamp_utc": stamp, "transmitter_codespace": "A69-1601",
                     "transmitter_id": str(7001 + k % 2), "receiver_sn": str(450101 + k % 2),
                     "station": "x"})
    text = _text(sorted(rows, key=lambda r: r["transmitter_id"]))
    (tmp_path / "det.csv").write_text(text)
    assigned = assign(read_detections(tmp_path / "det.csv", None), deployments)
    windows = {"450101": [("450101.1", *seasons[0][:2]), ("450101.2", *seasons[1][:2]), ("450101.3", *seasons[2][:2])],
               "450102": [("450102", "2019-04-01 12:00:00", "2021-12-01 00:00:00")]}
    expected = []
    for r in _expected(text).itertuples():
        inside = [name for name, a, b in windows[r.receiver] if _epoch(a) <= r.time and (not b or r.time <= _epoch(b))]
        if inside:
            expected.append((inside[0], r.tag, r.time))
    got = assigned.detections.frame
    assert list(zip(got["receiver"], got["tag"], got["time"])) == expected
    assert 0 < len(expected) < len(rows)  # some before the first season and between seasons, set aside


def test_the_duplicates_dropped_are_said_in_the_studys_summary(tmp_path):
    from sblsim.orchestrator.telemetry.study import _summary
    from sblsim.orchestrator.telemetry.study_detections import Tally

    rows = _rows(seed=5, n=20)
    d = _read(tmp_path, "joined.csv", _text(rows + rows[:4]))
    (tmp_path / "receivers.csv").write_text("serial,lat,lon\n" + "".join(
        f"{450100 + k},45.1{k},-83.2{k}\n" for k in range(4)))
    deployments = read_deployments(tmp_path / "receivers.csv")
    summary = _summary(d, deployments, Tally.of(d, assign(d, deployments)), {}, None, [])
    assert summary["detections"]["duplicates"] == 4 and summary["detections"]["rows"] == len(rows)
