"""A study's receivers as the field keeps them (:mod:`sblsim.orchestrator.readers.deployments`) and its tag sheet
(:mod:`sblsim.orchestrator.readers.tag_sheet`): the projection to the study's frame against pyproj called here (to
the millimetre and back), the UTM zone of the array's centre, GLATOS and OTN deployment sheets, one serial at two
stations (a redeployment), each detection at its deployment and those outside set aside and counted, a sync tag
redeployed with its receiver; the tag sheet's ping types, sensors and files; bad input refused in one line."""

from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest
from pyproj import Transformer

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.assign import assign
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet

LAT, LON = 60.3816, 5.3387  # the boats array's place (Norway), in UTM zone 31N


def _table(path, rows: list[dict]) -> None:
    pd.DataFrame(rows).to_csv(path, index=False, float_format="%.10f")


def test_lat_lon_are_projected_to_the_utm_zone_of_the_centre_to_the_millimetre(tmp_path):
    rng = np.random.default_rng(3)
    lat, lon = LAT + rng.uniform(-0.003, 0.003, 8), LON + rng.uniform(-0.006, 0.006, 8)
    path = tmp_path / "receivers.csv"
    _table(path, [{"serial": f"R{k}", "lat": a, "lon": b} for k, (a, b) in enumerate(zip(lat, lon))])
    d = read_deployments(path)
    assert d.frame.crs == "EPSG:32631" and "UTM zone 31N" in d.summary()["frame"]["name"]
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32631", always_xy=True).transform(lon, lat)
    # the file holds 10 decimals of a degree (about 0.01 mm): the projection agrees with pyproj's to a millimetre
    assert np.max(np.hypot(d.table["x"] - x, d.table["y"] - y)) < 1e-3
    back_lat, back_lon = d.frame.to_latlon(d.table["x"].to_numpy(), d.table["y"].to_numpy())
    assert np.max(np.abs(back_lat - lat)) < 1e-8 and np.max(np.abs(back_lon - lon)) < 1e-8  # < 1 mm
    # the frame's scale factor at the centre, as pyproj's Proj.get_factors gives it
    assert abs(d.summary()["frame"]["scale_factor"] - 0.99980) < 1e-5
    given = read_deployments(path, frame="EPSG:25832")
    x2, y2 = Transformer.from_crs("EPSG:4326", "EPSG:25832", always_xy=True).transform(lon, lat)
    assert given.frame.crs == "EPSG:25832" and np.max(np.hypot(given.table["x"] - x2, given.table["y"] - y2)) < 1e-3


def test_projected_positions_gain_lat_lon_and_leave_a_crs_that_distorts_them(tmp_path):
    """The boats' table is in ETRS89 / UTM 33N, whose scale at 5.3° E is 1.0031: its positions are taken to the UTM
    zone of the array (31N) through latitude and longitude (pyproj's transformations the reference), said."""
    path = tmp_path / "h.csv"
    path.write_text("serial,sync_tag,x_m,y_m\nA,7,-31369.421,6732996.807\nB,,-30820.127,6732778.068\n")
    d = read_deployments(path, crs="EPSG:25833")
    lon, lat = Transformer.from_crs("EPSG:25833", "EPSG:4326", always_xy=True).transform([-31369.421, -30820.127],
                                                                                          [6732996.807, 6732778.068])
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32631", always_xy=True).transform(lon, lat)
    assert d.frame.crs == "EPSG:32631" and any("EPSG:25833" in n for n in d.notes)
    assert np.allclose(d.table["x"], x, rtol=0, atol=1e-3) and np.allclose(d.table["y"], y, rtol=0, atol=1e-3)
    assert np.allclose(d.table["lat"], lat, rtol=0, atol=1e-9) and np.allclose(d.table["lon"], lon, rtol=0, atol=1e-9)
    moved = read_deployments(path, crs="EPSG:25833", frame="EPSG:32631")
    x, y = Transformer.from_crs("EPSG:25833", "EPSG:32631", always_xy=True).transform([-31369.421], [6732996.807])
    assert abs(moved.table["x"].iloc[0] - x[0]) < 1e-3 and abs(moved.table["y"].iloc[0] - y[0]) < 1e-3
    local = read_deployments(path)
    assert local.frame is None and local.table["lat"].isna().all() and local.table["sync_tag"].tolist() == ["7", ""]


def test_glatos_and_otn_deployment_sheets(tmp_path):
    glatos = tmp_path / "receiver_locations.csv"
    glatos.write_text(
        "station,glatos_array,station_no,consecutive_deploy_no,intend_lat,intend_long,deploy_lat,deploy_long,"
        "recover_lat,recover_long,deploy_date_time,recover_date_time,bottom_depth,riser_length,instrument_depth,"
        "ins_model_no,glatos_ins_frequency,ins_serial_no,deployed_by,comments,glatos_seasonal,glatos_project,"
        "glatos_vps\n"
        "WHT-009,WHT,9,1,,,43.74216,-82.50791,,,2010-09-22 18:05:00,2012-08-15 16:52:00,12.5,,11.0,VR2W,69,109450,"
        ",,NO,HECWL,NO\n"
        "WHT-010,WHT,10,1,,,43.74316,-82.50691,,,2010-09-22 18:15:00,,13.0,,12.0,VR2W,69,109451,,,NO,HECWL,NO\n")
    d = read_deployments(glatos)
    t = d.table
    assert t["serial"].tolist() == ["109450", "109451"] and t["station"].tolist() == ["WHT-009", "WHT-010"]
    assert t["z"].tolist() == [-11.0, -12.0] and t["bottom_depth"].tolist() == [12.5, 13.0]
    assert t["start"].iloc[0] == utc_seconds(["2010-09-22 18:05:00"], "", [1], "")[0] and np.isinf(t["end"].iloc[1])
    assert d.frame.crs == "EPSG:32617"
    otn = tmp_path / "otn.csv"
    otn.write_text("OTN_ARRAY,STATION_NO,DEPLOY_DATE_TIME   (yyyy-mm-ddThh:mm:ss),DEPLOY_LAT,DEPLOY_LONG,"
                   "BOTTOM_DEPTH,INSTRUMENT_DEPTH,INS_MODEL_NO,INS_SERIAL_NO,RECOVER_DATE_TIME (yyyy-mm-ddThh:mm:ss),"
                   "TRANSMITTER\n"
                   "HFX,001,2019-05-01T10:00:00,44.47833,-63.53333,60,55,VR2AR,546310,2019-10-01T10:00:00,"
                   "A69-1601-60123\n")
    o = read_deployments(otn)
    assert o.table["serial"].tolist() == ["546310"] and o.table["sync_tag"].tolist() == ["A69-1601-60123"]
    assert o.table["station"].tolist() == ["001"] and o.table["z"].tolist() == [-55.0]


def _redeployed(tmp_path):
    """Receiver 100 at station N until noon, then at station S; receiver 200 from the start, its sync tag S200."""
    path = tmp_path / "deployments.csv"
    _table(path, [
        {"station": "N", "ins_serial_no": "100", "deploy_lat": LAT, "deploy_long": LON,
         "deploy_date_time": "2023-09-01T00:00:00Z", "recover_date_time": "2023-09-01T12:00:00Z",
         "transmitter": "A69-1601-100"},
        {"station": "S", "ins_serial_no": "100", "deploy_lat": LAT - 0.001, "deploy_long": LON,
         "deploy_date_time": "2023-09-01T12:30:00Z", "recover_date_time": "2023-09-02T00:00:00Z",
         "transmitter": "A69-1601-100"},
        {"station": "E", "ins_serial_no": "200", "deploy_lat": LAT, "deploy_long": LON + 0.002,
         "deploy_date_time": "2023-09-01T00:00:00Z", "recover_date_time": "", "transmitter": "A69-1601-200"},
    ])
    return path


def test_a_redeployment_and_the_detections_outside_every_deployment(tmp_path):
    d = read_deployments(_redeployed(tmp_path))
    assert d.table["receiver"].tolist() == ["100.1", "100.2", "200"]
    assert d.summary()["redeployed"] == ["100"]
    day = utc_seconds(["2023-09-01T00:00:00Z"], "", [1], "")[0]
    hours = np.array([-1.0, 1.0, 11.9, 12.2, 13.0, 25.0, 5.0, 30.0, 6.0, 6.5, 14.0])
    frame = pd.DataFrame({
        "receiver": ["100", "100", "100", "100", "100", "100", "200", "200", "999", "200", "200"],
        "tag": ["A69-1602-5"] * 6 + ["A69-1602-5", "A69-1602-5", "A69-1602-5", "A69-1601-100", "A69-1601-100"],
        "code_space": "", "time": day + hours * 3600, "sensor_value": np.nan, "sensor_unit": "",
        "line": np.arange(2, 13)})
    a = assign(Detections(frame, "d.csv", "vue"), d)
    kept = a.detections.frame
    # by hand: 100 at 01:00 and 11:54 is its first deployment, at 13:00 its second; 12:12 (between), -1 h and
    # 25 h (outside) set aside; 200 open-ended; 999 not in the table
    assert kept["receiver"].tolist() == ["100.1", "100.1", "100.2", "200", "200", "200", "200"]
    assert kept["serial"].tolist() == ["100", "100", "100", "200", "200", "200", "200"]
    assert a.set_aside["outside_deployment"] == 3 and a.set_aside["receiver_not_in_table"] == 1
    assert a.set_aside["per_serial"] == {"100": 3, "999": 1}
    # the sync tag redeployed with its receiver is one sync tag per deployment, named as the detections name it
    assert a.hydrophones["sync_tag"].tolist() == ["A69-1601-100.1", "A69-1601-100.2", "A69-1601-200"]
    assert kept["tag"].tolist()[-2:] == ["A69-1601-100.1", "A69-1601-100.2"]
    assert np.array_equal(a.mask, np.isin(np.arange(11), [1, 2, 4, 6, 7, 9, 10]))


@pytest.mark.parametrize("rows, found", [
    ([{"serial": "A", "lat": 95.0, "lon": 5.0}], "column lat: '95"),
    ([{"serial": "A", "lat": 60.0, "lon": 5.0}, {"serial": "A", "lat": 60.1, "lon": 5.0}],
     "receiver A is deployed twice at once"),
    ([{"serial": "A", "lat": 60.0, "lon": 5.0, "sync_tag": "7"}, {"serial": "B", "lat": 60.1, "lon": 5.0,
                                                                  "sync_tag": "7"}], "sync tag 7 is deployed twice"),
    ([{"serial": "A", "lat": 60.0, "lon": 5.0, "deploy_date_time": "2023-09-02", "recover_date_time": "2023-09-01"}],
     "is not after the deployment"),
    ([{"serial": "A", "latitude": 60.0}], "the header needs a serial"),
    ([{"serial": "../etc", "lat": 60.0, "lon": 5.0}], "column serial"),
])
def test_bad_deployments_are_refused_in_one_line(tmp_path, rows, found):
    path = tmp_path / "d.csv"
    _table(path, rows)
    with pytest.raises(ModelError) as error:
        read_deployments(path)
    assert found in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize("crs, frame, found", [
    ("EPSG:999999", None, "not a CRS pyproj knows"),
    ("EPSG:4326", None, "the header needs a serial"),  # x_m, y_m in a geographic CRS: no positions
    (None, "EPSG:4326", "frame: given for positions without a CRS"),
    ("EPSG:25833", "EPSG:4326", "is not a projected CRS in metres"),
])
def test_bad_crs_and_frames_are_refused_in_one_line(tmp_path, crs, frame, found):
    path = tmp_path / "h.csv"
    path.write_text("serial,x_m,y_m\nA,-31369.4,6732996.8\n")
    with pytest.raises(ModelError) as error:
        read_deployments(path, crs, frame)
    assert found in str(error.value) and "\n" not in str(error.value)


# --------------------------------------------------------------------------------------------------- tag sheet

def test_a_tag_sheet_of_every_ping_type_role_and_sensor(tmp_path):
    (tmp_path / "seq.txt").write_text("interval_s\n30\n45\n60\n")
    path = tmp_path / "tags.csv"
    path.write_text("transmitter,ping_type,min_delay,max_delay,interval,burst_sequence,role,sensor_type,"
                    "sensor_slope,sensor_intercept,name\n"
                    "A69-1602-1,,60,120,,,animal,P,0.6065,-2.4262,cod\n"
                    "A69-1602-2,,30,30,,,,,,,\n"
                    "A69-1602-3,pbi,,,,seq.txt,animal,,,,\n"
                    "A69-1601-4,,540,660,,,sync,,,,\n"
                    "A69-1601-5,,,,600,,reference,,,,fixed\n"
                    "6,,,,,,,,,,\n")
    sheet = read_tag_sheet(path)
    t = {s.transmitter: s for s in sheet.tags}
    assert (t["A69-1602-1"].ping_type, t["A69-1602-1"].burst_interval) == ("rbi", (60.0, 120.0))
    assert (t["A69-1602-2"].ping_type, t["A69-1602-2"].interval) == ("sbi", 30.0)
    assert t["A69-1602-3"].ping_type == "pbi" and t["A69-1602-3"].shortest_interval() == 30.0
    assert t["A69-1601-4"].role == "sync" and t["A69-1601-5"].motion == "stationary"
    assert t["6"].ping_type is None and t["6"].role == "animal" and t["6"].motion == "moving"
    assert [s.transmitter for s in sheet.of_role("animal", "reference")] == ["A69-1602-1", "A69-1602-2",
                                                                            "A69-1602-3", "A69-1601-5", "6"]
    # a raw value converted by the sheet's slope and intercept (Vemco's depth = slope x raw + intercept); a value
    # given in metres taken as it is; a temperature not a depth
    depth = t["A69-1602-1"].depths(np.array([40.0, 12.5, np.nan]), np.array(["ADC", "m", ""]))
    assert np.allclose(depth[:2], [0.6065 * 40 - 2.4262, 12.5]) and np.isnan(depth[2])
    with pytest.raises(ModelError, match="no sensor_slope and sensor_intercept"):
        t["A69-1602-1"].__class__("X", sensor="depth", line=9).depths(np.array([3.0]), np.array(["raw"]))


@pytest.mark.parametrize("row, found", [
    ("A,rbi,60,,,", "min_delay 60 and max_delay nan"),
    ("A,rbi,,,,", "ping_type rbi needs min_delay < max_delay"),
    ("A,sbi,60,120,,", "a stable interval has one delay"),
    ("A,pbi,,,,", "ping_type pbi needs burst_sequence"),
    ("A,,,,../outside.txt,", "outside the folder of the tag sheet"),
    ("A,,,,/etc/hostname,", "outside the folder of the tag sheet"),
    ("A,abi,,,,", "column ping_type: 'abi'"),
    ("A,,,,,whale", "column role: 'whale'"),
    ("A,,0.01,0.02,,", "column min_delay: '0.01'"),
    ("A,,,,,\nA,,,,,", "transmitter A is listed twice"),
])
def test_bad_tag_sheets_are_refused_in_one_line(tmp_path, row, found):
    folder = tmp_path / "sheet"
    folder.mkdir()
    (tmp_path / "outside.txt").write_text("30\n")
    path = folder / "tags.csv"
    path.write_text("transmitter,ping_type,min_delay,max_delay,burst_sequence,role\n" + row + "\n")
    with pytest.raises(ModelError) as error:
        read_tag_sheet(path)
    assert found in str(error.value) and "\n" not in str(error.value)


def test_a_sequence_file_linked_out_of_the_sheets_folder_is_refused(tmp_path):
    folder = tmp_path / "sheet"
    folder.mkdir()
    (tmp_path / "private.txt").write_text("30\n")
    os.symlink(tmp_path / "private.txt", folder / "seq.txt")
    path = folder / "tags.csv"
    path.write_text("transmitter,ping_type,burst_sequence\nA,pbi,seq.txt\n")
    with pytest.raises(ModelError, match="outside the folder of the tag sheet"):
        read_tag_sheet(path)
