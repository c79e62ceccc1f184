"""actel's workspace read as a study's files (actel's manual and ``exampleWorkspace``'s layout, written here with
invented values): the deployments joined with the stations (release sites no receivers), ``Start`` and ``Stop`` in
the study's time zone (a local time across a summer-time change converted right; without ``--tz`` refused in one
line, exit 2 through the command), ``Stop`` kept, the biometrics as a tag sheet, actel's standard detections, a
folder of files read as one table, and the folder and the files given one by one giving the same study inputs.
Each against an expectation computed here (the standard library's ``zoneinfo``, plain pandas)."""

from __future__ import annotations

import io
from datetime import datetime
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.actel import read_actel_deployments, read_biometrics
from sblsim.orchestrator.readers.detections import read_detections, sniff_format
from sblsim.orchestrator.readers.study_files import read_study, study_files

ZONE = "Europe/Copenhagen"
SPATIAL = '''"Station.name","Latitude","Longitude","x","y","Array","Section","Type"
"North gate",55.70012,12.60105,NA,NA,"A1","Fjord","Hydrophone"
"Mid channel",55.70230,12.60480,NA,NA,"A1","Fjord","Hydrophone"
"South bank",55.69890,12.60720,NA,NA,"A2","Fjord","Hydrophone"
"Pier",55.69950,12.59800,NA,NA,"A1","","Release"
'''
# the first deployment starts in winter time (UTC+1) and ends in summer time (UTC+2); the last has no Stop
DEPLOYMENTS = '''"Receiver","Station.name","Start","Stop"
"VR2W-300101","North gate","2021-03-20 09:30:00","2021-04-02 16:45:00"
"300102","Mid channel","2021-03-20 10:00","2021-04-02 17:00:00"
"300103","South bank","2021-03-20 10:15:00",""
'''
BIOMETRICS = '''"Release.date","Release.site","Serial.nr","Signal","Code.space","Group","Total.Length.mm"
"2021-03-22 08:00:00","Pier",21001,610,"R64K","wild",410
"2021-03-22 08:05","Pier",21002,"611|612","R64K","wild",395
'''
DETECTIONS = {
    "300101": '''"Timestamp","Receiver","CodeSpace","Signal","Sensor.Value","Sensor.Unit"
"2021-03-23 10:00:01",300101,"R64K",610,NA,NA
"2021-03-23 10:01:32.5",300101,"R64K",611,4.5,"m"
"2021-03-23T10:02:50Z",300101,"R64K",610,NA,NA
''',
    "300102": '''"Timestamp","Receiver","CodeSpace","Signal","Sensor.Value","Sensor.Unit"
"2021-03-23 10:00:01.25",300102,"R64K",610,NA,NA
"2021-03-23 10:02:50.5",300102,"R64K",610,NA,NA
''',
}


def _workspace(tmp_path, single: bool = False):
    folder = tmp_path / "workspace"
    (folder / "detections").mkdir(parents=True)
    for name, text in (("spatial.csv", SPATIAL), ("deployments.csv", DEPLOYMENTS), ("biometrics.csv", BIOMETRICS)):
        (folder / name).write_text(text)
    for serial, text in DETECTIONS.items():
        (folder / "detections" / f"{serial}.csv").write_text(text)
    return folder


def _local(text: str) -> float:
    """A wall time in the study's zone as seconds since 1970 UTC, by the standard library."""
    for form in ("%Y-%m-%d %H:%M:%S", "%Y-%m-%d %H:%M"):
        try:
            return datetime.strptime(text, form).replace(tzinfo=ZoneInfo(ZONE)).timestamp()
        except ValueError:
            continue
    raise AssertionError(text)


def test_deployments_are_joined_with_their_stations_in_the_study_time_zone(tmp_path):
    folder = _workspace(tmp_path)
    d = read_actel_deployments(folder / "deployments.csv", folder / "spatial.csv", ZONE)
    given = pd.read_csv(io.StringIO(DEPLOYMENTS), dtype=str, keep_default_na=False)
    stations = pd.read_csv(io.StringIO(SPATIAL)).set_index("Station.name")
    t = d.table
    assert t["serial"].tolist() == given["Receiver"].str.split("-").str[-1].tolist()
    assert t["station"].tolist() == given["Station.name"].tolist()
    np.testing.assert_allclose(t["lat"], stations.loc[given["Station.name"], "Latitude"], atol=1e-9)
    np.testing.assert_allclose(t["lon"], stations.loc[given["Station.name"], "Longitude"], atol=1e-9)
    np.testing.assert_allclose(t["start"], [_local(s) for s in given["Start"]], atol=1e-6)
    # the Stop in summer time (UTC+2), the Start in winter time (UTC+1): both right, and the Stop kept
    assert t["end"].iloc[0] == _local("2021-04-02 16:45:00")
    assert t["end"].iloc[0] - t["start"].iloc[0] == (datetime(2021, 4, 2, 16, 45) - datetime(2021, 3, 20, 9, 30)
                                                     ).total_seconds() - 3600
    assert np.isinf(t["end"].iloc[2]) and t["end"].iloc[2] > 0  # an empty Stop: open, and said
    assert any("without a Stop" in n and "line 4" in n for n in d.notes)
    assert "Pier" not in set(t["station"])  # a release site is no receiver
    assert any("release site" in n for n in d.notes)


def test_times_with_their_offset_need_no_time_zone(tmp_path):
    folder = _workspace(tmp_path)
    (folder / "deployments.csv").write_text(DEPLOYMENTS.replace('09:30:00"', '09:30:00+01:00"')
                                            .replace('10:00"', '10:00+01:00"').replace('10:15:00"', '10:15:00Z"')
                                            .replace('16:45:00"', '16:45:00+02:00"')
                                            .replace('17:00:00"', '17:00:00+02:00"'))
    d = read_actel_deployments(folder / "deployments.csv", folder / "spatial.csv", None)
    assert d.table["start"].iloc[0] == _local("2021-03-20 09:30:00")
    assert d.table["end"].iloc[1] == _local("2021-04-02 17:00:00")
    assert d.table["start"].iloc[2] == datetime.fromisoformat("2021-03-20T10:15:00+00:00").timestamp()


def test_local_times_without_a_time_zone_are_refused_in_one_line(tmp_path):
    folder = _workspace(tmp_path)
    with pytest.raises(ModelError) as err:
        read_actel_deployments(folder / "deployments.csv", folder / "spatial.csv", None)
    message = str(err.value)
    assert "\n" not in message and "line 2 column Start" in message and "--tz" in message


@pytest.mark.parametrize("wall, said", [("2021-03-28 02:30:00", "skips"), ("2021-10-31 02:30:00", "passes twice")])
def test_a_wall_time_the_zone_skips_or_repeats_is_refused(tmp_path, wall, said):
    folder = _workspace(tmp_path)
    (folder / "deployments.csv").write_text(DEPLOYMENTS.replace("2021-04-02 16:45:00", wall))
    with pytest.raises(ModelError, match=rf"line 2 column Stop: .* {said}"):
        read_actel_deployments(folder / "deployments.csv", folder / "spatial.csv", ZONE)


@pytest.mark.parametrize("station, why", [("Pier", "is a release site"), ("Nowhere", "is not listed")])
def test_a_deployment_at_a_release_site_or_an_unknown_station_is_refused(tmp_path, station, why):
    folder = _workspace(tmp_path)
    (folder / "deployments.csv").write_text(DEPLOYMENTS.replace('"Mid channel"', f'"{station}"'))
    with pytest.raises(ModelError, match=rf"line 3 column Station.name: the station '{station}' {why}"):
        read_actel_deployments(folder / "deployments.csv", folder / "spatial.csv", ZONE)


def test_deployments_joined_by_hand_keep_their_stop(tmp_path):
    joined = pd.read_csv(io.StringIO(DEPLOYMENTS), dtype=str, keep_default_na=False).merge(
        pd.read_csv(io.StringIO(SPATIAL), dtype=str)[["Station.name", "Latitude", "Longitude"]], on="Station.name")
    path = tmp_path / "receivers.csv"
    joined.to_csv(path, index=False)
    files = study_files([tmp_path / "x.csv"], receivers=path)
    (tmp_path / "x.csv").write_text(DETECTIONS["300101"])
    deployments, _, _, _ = read_study(files, tz=ZONE)
    assert deployments.table["end"].iloc[0] == _local("2021-04-02 16:45:00")


def test_the_biometrics_are_a_tag_sheet_each_signal_a_transmitter(tmp_path):
    folder = _workspace(tmp_path)
    sheet = read_biometrics(folder / "biometrics.csv", ZONE)
    rows = pd.read_csv(io.StringIO(BIOMETRICS), dtype=str)
    want = [f"{space}-{signal}" for space, signals in zip(rows["Code.space"], rows["Signal"])
            for signal in signals.split("|")]
    assert [t.transmitter for t in sheet.tags] == want
    assert all(t.role == "animal" and t.ping_type is None for t in sheet.tags)  # ping type inferred
    assert [t.line for t in sheet.tags] == [2, 3, 3]
    released = pd.to_datetime(sheet.releases["release_utc"], utc=True)
    assert released.iloc[0].timestamp() == _local("2021-03-22 08:00:00")
    assert released.iloc[2].timestamp() == _local("2021-03-22 08:05")
    assert sheet.releases["release_site"].tolist() == ["Pier"] * 3
    with pytest.raises(ModelError, match="line 2 column Release.date"):
        read_biometrics(folder / "biometrics.csv", None)


def test_a_signal_listed_twice_is_refused(tmp_path):
    path = tmp_path / "biometrics.csv"
    path.write_text(BIOMETRICS.replace('"611|612"', '"611|610"'))
    with pytest.raises(ModelError, match="lines 2 and 3: transmitter R64K-610 is listed twice"):
        read_biometrics(path, ZONE)


def test_actel_detections_are_read_against_plain_pandas(tmp_path):
    path = tmp_path / "300101.csv"
    path.write_text(DETECTIONS["300101"])
    d = read_detections(path, None)
    t = pd.read_csv(io.StringIO(DETECTIONS["300101"]), dtype={"Signal": str, "Receiver": str})
    stamps = pd.to_datetime(t["Timestamp"], utc=True, format="ISO8601")
    assert d.format == "actel" and sniff_format(path) == "actel"
    np.testing.assert_allclose(d.frame["time"], (stamps - pd.Timestamp(0, tz="UTC")).dt.total_seconds(), atol=1e-6)
    assert d.frame["tag"].tolist() == (t["CodeSpace"] + "-" + t["Signal"]).tolist()
    assert d.frame["receiver"].tolist() == t["Receiver"].tolist()
    np.testing.assert_array_equal(d.frame["sensor_value"].to_numpy(), t["Sensor.Value"].to_numpy(float))
    assert d.frame["sensor_unit"].tolist() == t["Sensor.Unit"].fillna("").tolist()


def test_a_file_of_no_known_format_is_refused_naming_the_formats(tmp_path):
    path = tmp_path / "odd.csv"
    path.write_text("when,who,what\n2021-01-01,1,2\n")
    with pytest.raises(ModelError) as err:
        read_detections(path, None)
    message = str(err.value)
    assert "\n" not in message and "actel" in message and "Thelma" in message and "VUE" in message


def test_the_folder_and_the_files_one_by_one_give_the_same_study(tmp_path):
    folder = _workspace(tmp_path)
    whole = read_study(study_files(folder), tz=ZONE)
    files = sorted((folder / "detections").iterdir())
    apart = read_study(study_files(files, receivers=folder / "deployments.csv", spatial=folder / "spatial.csv",
                                   tags=folder / "biometrics.csv"), tz=ZONE)
    pd.testing.assert_frame_equal(whole[0].table, apart[0].table)
    pd.testing.assert_frame_equal(whole[1].frame, apart[1].frame)
    assert [t.transmitter for t in whole[2].tags] == [t.transmitter for t in apart[2].tags]
    frame = whole[1].frame
    assert len(frame) == sum(text.count("\n") - 1 for text in DETECTIONS.values())
    assert frame["file"].astype(str).tolist() == [str(p) for p in files for _ in range(len(
        pd.read_csv(p)))]  # each row's file and line kept
    assert frame["line"].tolist() == [2, 3, 4, 2, 3]


def test_many_files_judge_each_clock_alone_and_drop_a_detection_an_earlier_file_holds(tmp_path):
    first = DETECTIONS["300101"]
    later = first.splitlines()[0] + "\n" + first.splitlines()[3] + "\n" + \
        '"2021-03-23 09:00:00",300101,"R64K",610,NA,NA\n"2021-03-23 09:01:30",300101,"R64K",610,NA,NA\n'
    (tmp_path / "a.csv").write_text(first)
    (tmp_path / "b.csv").write_text(later)  # one row a.csv holds, then the clock set back an hour (a reset)
    files = study_files(tmp_path, receivers=tmp_path / "none.csv")
    from sblsim.orchestrator.readers.study_files import read_many

    d = read_many(files.detections)
    assert d.duplicates == 1 and len(d.frame) == 3 + 2
    assert [(r["file"], r["line"], r["clock_part"]) for r in d.clock_resets] == [(str(tmp_path / "b.csv"), 3, 2)]
    parts = d.frame.groupby("file", observed=True)["clock_part"].unique()  # the reset's part after a.csv's
    assert parts[str(tmp_path / "a.csv")].tolist() == [1] and parts[str(tmp_path / "b.csv")].tolist() == [2]


def test_no_receivers_and_no_workspace_is_refused(tmp_path):
    (tmp_path / "a.csv").write_text(DETECTIONS["300101"])
    with pytest.raises(ModelError, match="receivers: none given"):
        study_files(tmp_path / "a.csv")


def test_the_command_refuses_local_times_without_tz_in_one_line(tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    folder = _workspace(tmp_path)
    status = main(["track", str(folder), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert len(err) == 1 and "carries no UTC offset" in err[0] and "--tz" in err[0]
    assert not (tmp_path / "out").exists()
