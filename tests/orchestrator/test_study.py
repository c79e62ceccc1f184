"""A telemetry study in one command (``sblsim track``, :func:`sblsim.track`) on a simulated study written as its
people bring one (:mod:`sblsim.orchestrator.telemetry.simulate`: deployments in lat/lon with dates and a
redeployment, a VUE export and a Fathom CSV of the same detections on drifting clocks, a tag sheet of every ping
type): every tag tracked, its errors against the simulated truth within its own stated uncertainty; ``tracks.csv``
the tags' own tracks together; the UTC times the inputs'; lat/lon pyproj's; the GeoJSON the tracks'; the same tracks
from both exports; a tag never detected a row saying so; bad input refused in one line with nothing written. The
boats study from its lat/lon deployments and tag sheet (slow)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pyproj import Transformer

import sblsim
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.telemetry.simulate import simulate_study
from tests.helpers import check_tag_rows

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A small simulated study (9 receivers, one redeployed; a tag of each ping type; 6 hours) written both ways,
    and the study run on its VUE export."""
    folder = tmp_path_factory.mktemp("study")
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.25, redeployed=1, seed=4)
    files = sim.write(folder / "vue", "vue")
    sim.write(folder / "fathom", "fathom")
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"],
                          out=folder / "out", workers=1)
    check_tag_rows(result.tags, result.tracks, [str(p) for p in files.values()])
    return sim, files, result, folder


def _truth_at(sim, result, tag: str, epoch: np.ndarray) -> np.ndarray:
    """The simulated position of ``tag`` at the track's times (on the reference receiver's clock, which the
    synchronisation takes as UTC): the truth's true times read on that clock, interpolated."""
    reference = result.summary["clocks"]["reference_receiver"]
    k = int(np.flatnonzero(result.receivers["receiver"].to_numpy() == reference)[0])
    return sim.truth_at(tag, epoch, k)


@pytest.mark.slow
def test_every_tag_tracked_within_its_own_uncertainty(study):
    sim, _, result, _ = study
    tags = result.tags
    assert (tags["status"] == "tracked").all() and len(tags) == 3
    assert sorted(tags["ping_type"]) == ["pbi", "rbi", "sbi"]  # each the sheet's, given (not inferred)
    for tag, rows in result.tracks.groupby("tag"):
        truth = _truth_at(sim, result, tag, rows["epoch_s"].to_numpy())
        error = np.hypot(rows["x"] - truth[:, 0], rows["y"] - truth[:, 1]).to_numpy()
        drms = np.hypot(rows["sigma_x"], rows["sigma_y"]).to_numpy()
        # against an independent truth: the RMS error within 1.5 times the RMS of the track's own DRMS, below 0.5 m
        assert np.sqrt(np.mean(error**2)) < 1.5 * np.sqrt(np.mean(drms**2)), tag
        assert np.sqrt(np.mean(error**2)) < 0.5 and (rows["quality"] == "flagged").mean() < 0.05, tag


@pytest.mark.slow
def test_the_detections_outside_a_deployment_are_set_aside_and_counted(study):
    sim, _, result, _ = study
    aside = result.summary["detections"]["reasons"]
    # the redeployed receiver logs its own sync tag five times on deck; a clock a second behind the deployment's
    # time may put a first detection before it
    assert aside["outside_deployment"] >= 5 and aside["receiver_not_in_table"] == 0
    moved = sim.deployments["ins_serial_no"][sim.deployments["ins_serial_no"].duplicated()].iloc[0]
    assert aside["per_serial"][moved] >= 5
    assert result.summary["receivers"]["redeployed"] == [moved]
    assert sorted(result.receivers.loc[result.receivers["serial"] == moved, "receiver"]) == [f"{moved}.1",
                                                                                           f"{moved}.2"]


@pytest.mark.slow
def test_tracks_csv_is_the_tags_own_tracks_with_utc_times_and_lat_lon(study):
    sim, files, result, folder = study
    out = folder / "out"
    tracks = pd.read_csv(out / "tracks.csv", dtype={"tag": str, "time_utc": str})
    assert {"tag", "time_utc", "epoch_s", "lat", "lon", "x", "y", "sigma_x", "sigma_y", "quality"} <= set(tracks)
    own = []
    for row in result.tags.itertuples():
        t = pd.read_csv(out / row.folder / "track.csv", dtype={"time_utc": str})
        own.append(t.assign(tag=row.tag))
    own = pd.concat(own)[list(tracks.columns)].sort_values(["tag", "epoch_s"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(tracks, own)
    # the UTC texts are the epoch seconds, to the microsecond
    assert np.max(np.abs(utc_seconds(tracks["time_utc"], "t", list(range(len(tracks))), "time_utc")
                         - tracks["epoch_s"])) < 1e-6
    # latitude and longitude are pyproj's of x, y in the frame study.json states
    crs = json.loads((out / "study.json").read_text())["frame"]["crs"]
    lon, lat = Transformer.from_crs(crs, "EPSG:4326", always_xy=True).transform(tracks["x"], tracks["y"])
    assert np.max(np.abs(lat - tracks["lat"])) < 1e-9 and np.max(np.abs(lon - tracks["lon"])) < 1e-9
    # the GeoJSON's lines are the rows not flagged, longitude before latitude
    shapes = json.loads((out / "tracks.geojson").read_text())
    lines = {f["properties"]["tag"]: f["geometry"]["coordinates"] for f in shapes["features"]
             if f["properties"]["kind"] == "track"}
    points = [f for f in shapes["features"] if f["properties"]["kind"] == "receiver"]
    assert len(points) == len(sim.deployments)
    for tag, rows in tracks.groupby("tag"):
        ok = rows[rows["quality"] != "flagged"]
        assert np.allclose(lines[tag], np.c_[ok["lon"], ok["lat"]], rtol=0, atol=1e-8)


@pytest.mark.slow
def test_the_reference_receivers_arrivals_are_its_logged_utc_times(study):
    """At the reference receiver (offset 0 by definition) a tag's times of arrival plus the matrix's origin are the
    times the export logged, to the microsecond the export writes."""
    sim, files, result, folder = study
    reference = result.summary["clocks"]["reference_receiver"]
    logged = pd.read_csv(files["detections"], dtype=str)
    logged = logged[logged["Receiver"].str.endswith("-" + reference.split(".")[0])]
    for row in result.tags.itertuples():
        summary = json.loads((folder / "out" / row.folder / "toa.json").read_text())
        toa = pd.read_csv(folder / "out" / row.folder / "toa.txt", sep=" ", na_values="NA")
        if reference not in toa:
            continue
        heard = toa[reference].dropna().to_numpy() + summary["origin_epoch_s"]
        mine = logged[logged["Transmitter"] == row.tag]["Date and Time (UTC)"]
        times = utc_seconds(mine, "vue", list(range(len(mine))), "t")
        assert len(heard) and np.max(np.min(np.abs(heard[:, None] - times[None]), axis=1)) < 2e-6


@pytest.mark.slow
def test_the_same_tracks_from_the_fathom_export(study, tmp_path):
    _, files, result, folder = study
    other = sblsim.track(folder / "fathom" / "detections.csv", receivers=files["deployments"], tags=files["tags"],
                         workers=1)
    check_tag_rows(other.tags, other.tracks)
    assert other.summary["detections"]["format"] == "fathom"
    pd.testing.assert_frame_equal(other.tracks, result.tracks, check_exact=False, rtol=0, atol=1e-6)


@pytest.mark.slow
def test_the_same_tracks_from_a_store_of_the_export(study, tmp_path):
    """``sblsim store`` then ``sblsim track STORE``: the study of the file, every track to the bit."""
    _, files, result, folder = study
    kept = sblsim.store(files["detections"], out=tmp_path / "store")
    assert kept.info["rows"] == result.summary["detections"]["rows"]
    other = sblsim.track(tmp_path / "store", receivers=files["deployments"], tags=files["tags"], workers=1)
    assert other.summary["detections"]["format"] == "vue"
    pd.testing.assert_frame_equal(other.tracks, result.tracks, check_exact=True)
    pd.testing.assert_frame_equal(other.tags.drop(columns="wall_time_s"),
                                  result.tags.drop(columns="wall_time_s"), check_exact=True)


@pytest.mark.slow
def test_a_study_written_to_a_folder_keeps_each_tags_track_alone_and_writes_its_files_whole(study):
    """Written to a folder, each tag's files are written as it ends and its track alone kept in memory (a season's
    tags never in memory together): the same tracks and files as the study kept whole (no folder)."""
    _, files, result, folder = study
    whole = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1)
    pd.testing.assert_frame_equal(result.tracks, whole.tracks, check_exact=True)
    where = dict(zip(result.tags["tag"], result.tags["folder"]))
    for tag, light in result.tracked.items():
        assert light.estimates is None and whole.tracked[tag].estimates is not None
        written = (folder / "out" / where[tag] / "estimates.csv").read_text()
        assert written == whole.tracked[tag].estimates.to_csv(index=False)


@pytest.mark.slow
def test_the_command_writes_the_tracks_a_tag_at_a_time_as_the_table_returned(study):
    """``sblsim track`` keeps no tag's track and writes ``tracks.csv``, ``tracks.geojson`` and the map from the tags'
    own files (orchestrator/telemetry/study_tracks.py): the same bytes as ``sblsim.track`` writes from the table it
    returns, and that table's rows; with 2 workers as with 1 (the receivers' tags in the order asked, not the order
    the workers ended them in)."""
    from sblsim.orchestrator.cli import main

    _, files, result, folder = study
    assert main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tags",
                 str(files["tags"]), "--out", str(folder / "command"), "--workers", "2"]) == 0
    for name in ("tracks.csv", "tracks.geojson", "map.png"):
        assert (folder / "command" / name).read_bytes() == (folder / "out" / name).read_bytes(), name
    assert (folder / "out" / "tracks.csv").read_text() == result.tracks.to_csv(index=False)


@pytest.mark.slow
def test_a_tag_never_detected_is_a_row_saying_so(study):
    _, files, _, _ = study
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"],
                          tag="1000,A69-1602-9999", workers=1)
    check_tag_rows(result.tags, result.tracks, [str(p) for p in files.values()])
    rows = result.tags.set_index("transmitter")
    assert rows.loc["1000", "status"] == "tracked" and rows.loc["1000", "tag"] == "A69-1602-1000"
    assert rows.loc["A69-1602-9999", "status"] == "refused" and rows.loc["A69-1602-9999", "reason_code"] == \
        "never_detected"
    assert "never detected" in rows.loc["A69-1602-9999", "reason"]


@pytest.mark.slow
@pytest.mark.parametrize("extra, edit, found", [
    ([], lambda d: d.assign(deploy_lat=95.0), "column deploy_lat: '95"),
    (["--format", "fathom"], None, "starts with the line VEMCO DATA LOG"),
    (["--crs", "EPSG:999999"], None, "not a CRS pyproj knows"),
    (["--tag", "a,a"], None, "distinct"),
    (["--tag", "A69-1602-9999"], None, "none of the tags asked for (A69-1602-9999) is detected"),
    (["--sound-speed", "1480", "--temperature", "10", "--salinity", "0"], None, "--temperature: only where"),
])
def test_bad_input_is_refused_in_one_line_and_nothing_written(study, tmp_path, capsys, extra, edit, found):
    from sblsim.orchestrator.cli import main

    _, files, _, _ = study
    receivers = files["deployments"]
    if edit is not None:
        receivers = tmp_path / "deployments.csv"
        edit(pd.read_csv(files["deployments"], dtype=str)).to_csv(receivers, index=False)
    code = main(["track", str(files["detections"]), "--receivers", str(receivers), "--tags", str(files["tags"]),
                 "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and found in err[0], err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_the_command_line_says_what_it_did(study, tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    _, files, _, _ = study
    assert main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tags",
                 str(files["tags"]), "--out", str(tmp_path / "o"), "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert "study of" in out and "set aside" in out and "UTM zone" in out and "3 of 3 tags tracked" in out
    for name in ("study.json", "tracks.csv", "tags.csv", "receivers.csv", "tracks.geojson", "map.png", "sync"):
        assert (tmp_path / "o" / name).exists(), name


@pytest.mark.slow
def test_the_boats_study_from_its_lat_lon_deployments_and_tag_sheet(tmp_path):
    """The boats data's deployments.csv is pyproj's conversion of hydrophones.csv (ETRS89 / UTM 33N) to the
    millimetre, and the study tracks both animals in one call, synchronised as ``sblsim sync`` synchronises."""
    data = ROOT / "data" / "boats-norway"
    table = pd.read_csv(data / "hydrophones.csv", dtype=str)
    sheet = pd.read_csv(data / "deployments.csv", dtype=str)
    assert sheet["ins_serial_no"].tolist() == table["serial"].tolist()
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:25833", always_xy=True).transform(
        sheet["deploy_long"].astype(float), sheet["deploy_lat"].astype(float))
    assert np.max(np.hypot(x - table["x_m"].astype(float), y - table["y_m"].astype(float))) < 1e-3
    result = sblsim.track(data / "detections.csv", receivers=data / "deployments.csv", tags=data / "tags.csv",
                          out=tmp_path / "study")
    check_tag_rows(result.tags, result.tracks)
    assert result.tags["status"].tolist() == ["tracked", "tracked"]
    assert result.tags["tag"].tolist() == ["4555", "7953"]
    alone = sblsim.sync(data / "detections.csv", receivers=data / "deployments.csv")
    assert result.summary["clocks"]["median_abs_residual_m"] == alone.summary["median_abs_residual_m"]
    assert np.isfinite(result.tracks["lat"]).all() and (result.tracks["lat"].between(60.37, 60.39)).all()


def test_a_depth_sensor_reaches_the_tracker_only_in_3d(tmp_path):
    """A depth sensor's raw values converted by the sheet's slope and intercept (a value in metres kept), and the
    depth per ping written into the matrix the tracker reads (a ``depth_m`` column, the receivers' serials numbers
    kept as the header) only where the receivers have depths; in 2-D it is said in a note and left out."""
    from sblsim.orchestrator.readers.tag_sheet import TagSpec
    from sblsim.orchestrator.readers.toa_matrix import read_toa
    from sblsim.orchestrator.sync.matrix_files import write_toa_files
    from sblsim.orchestrator.sync.toa import ToaOutcome
    from sblsim.orchestrator.telemetry.study import _tag_detections

    spec = TagSpec("A69-9002-1", sensor="depth", slope=0.5, intercept=-1.0)
    mine = pd.DataFrame({"sensor_value": [10.0, 4.5, np.nan], "sensor_unit": ["ADC", "m", ""]})
    depth = _tag_detections(mine, spec)
    assert np.allclose(depth["sensor_value"][:2], [4.0, 4.5]) and np.isnan(depth["sensor_value"][2])
    assert depth["sensor_unit"].tolist() == ["m", "m", ""]
    pings = pd.DataFrame({"depth_m": [4.0, np.nan]})
    toa = np.array([[0.1, np.nan], [2.0, 2.1]])
    for dim, expected in ((3, [4.0, np.nan]), (2, None)):
        matrix = ToaOutcome(toa, ["1623", "1626"], np.zeros((2, dim)), pings, {"tag": "A"}, 0.0)
        notes: list[str] = []
        write_toa_files(matrix, tmp_path / str(dim), notes)
        read = read_toa(tmp_path / str(dim) / "toa.txt")
        if expected is None:
            assert read.depth is None and read.names is None and "not used by the tracker" in notes[0]
        else:
            assert read.names == ["1623", "1626"] and np.allclose(read.depth, expected, equal_nan=True) and not notes
        assert np.allclose(read.toa, toa, equal_nan=True)


@pytest.mark.slow
def test_a_sheet_s_interval_the_detections_contradict_is_said_and_taken_with_force_interval(study, tmp_path):
    """The rbi tag (100-200 s) stated as 300-600 s on the sheet: its row of tags.csv refused naming the interval its
    detections show (no silent drop of its pings as echoes); with ``force_interval`` (``--force-interval``) it is
    tracked and a note says how many detections the stated interval drops."""
    _, files, _, folder = study
    sheet = pd.read_csv(files["tags"])
    rbi = sheet.index[(sheet["ping_type"] == "rbi") & (sheet["role"] == "animal")][0]
    sheet.loc[rbi, ["min_delay", "max_delay"]] = [300, 600]
    wrong = tmp_path / "tags.csv"
    sheet.to_csv(wrong, index=False)
    name = sheet.loc[rbi, "transmitter"]
    common = dict(receivers=files["deployments"], tags=wrong, tag=name, sync=folder / "out" / "sync", workers=1)
    refused = sblsim.track(files["detections"], **common)
    check_tag_rows(refused.tags, refused.tracks, [str(files["detections"]), str(wrong)])
    # the folder's reference receiver named in study.json (issue 98 item 14): the one sync.json names
    made = json.loads((folder / "out" / "sync" / "sync.json").read_text())["reference_receiver"]
    assert refused.summary["clocks"]["reference_receiver"] == made
    row = refused.tags.iloc[0]
    assert row["reason_code"] == "interval_contradicted"
    assert row["status"] == "refused" and "300:600 s stated, but the detections' steps" in row["reason"]
    low, high = (float(v) for v in row["reason"].split(" show ")[1].split(" s ")[0].split("-"))
    assert 90 <= low and high <= 210  # the tag's own 100-200 s
    assert "--force-interval" in row["reason"]
    forced = sblsim.track(files["detections"], force_interval=True, **common)
    check_tag_rows(forced.tags, forced.tracks)
    assert forced.tags.iloc[0]["status"] == "tracked"
    said = [note for note in forced.summary["notes"] if "taken (--force-interval)" in note]
    assert len(said) == 1 and said[0].startswith(f"tag {forced.tags.iloc[0]['tag']}:")
    with pytest.raises(sblsim.ConfigError, match="^force_interval: 'yes' is not True or False$"):
        sblsim.track(files["detections"], force_interval="yes", **common)


@pytest.mark.slow
@pytest.mark.parametrize("how", [{"workers": 2}, {"workers": 2, "scheduler": "local"}],
                         ids=["2 worker processes", "a local Dask cluster"])
def test_worker_processes_and_a_dask_cluster_write_the_study_of_one_process(study, tmp_path, how):
    """The study in two worker processes, and on a local Dask cluster (each worker sent its tag's files): every
    track's file to the byte as the fixture's study made in one process."""
    _, files, _, folder = study
    sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], out=tmp_path / "o", **how)
    one, many = folder / "out", tmp_path / "o"
    assert (many / "tracks.csv").read_bytes() == (one / "tracks.csv").read_bytes()
    tags = sorted(p.name for p in (one / "tags").iterdir() if (p / "track.csv").is_file())
    assert tags and tags == sorted(p.name for p in (many / "tags").iterdir() if (p / "track.csv").is_file())
    for tag in tags:
        for name in ("track.csv", "estimates.csv"):
            assert (many / "tags" / tag / name).read_bytes() == (one / "tags" / tag / name).read_bytes(), (tag, name)


def test_the_simulated_truth_is_read_on_a_deployments_clock():
    """``truth_at``: an animal's true samples at their times as deployment k's clock reads them, and half way between
    two samples the mean of the two (its clock's offset and drift applied, not the true time)."""
    sim = simulate_study(n_receivers=4, n_tags=1, days=0.02, redeployed=0, seed=3)
    tag = next(iter(sim.truth))
    truth = sim.truth[tag]
    tau, xy = truth["tau"].to_numpy(), truth[["x", "y"]].to_numpy()
    a, b = sim.clocks.loc[2, ["a", "b"]]
    read = sim.origin + tau + a + b * tau  # deployment 2's clock at the true times
    np.testing.assert_allclose(sim.truth_at(tag, read, 2), xy, rtol=0, atol=1e-6)
    middle = 0.5 * (tau[:-1] + tau[1:])
    np.testing.assert_allclose(sim.truth_at(tag, sim.origin + middle + a + b * middle, 2),
                               0.5 * (xy[:-1] + xy[1:]), rtol=0, atol=1e-6)
    unread = sim.truth_at(tag, sim.origin + middle, 2)  # the true times taken as the clock's: off by its offset
    assert np.abs(unread - 0.5 * (xy[:-1] + xy[1:])).max() > 1e-3


def test_a_simulated_studys_sync_tags_given_as_reference_tags():
    """``with_reference_tags``: the sync tags of the deployments asked for are reference tags of the sheet at their
    stations, their sync-tag cells emptied and no other; the positions given are the deployments' latitude and
    longitude (pyproj's inverse of the study's UTM zone, independently); the study's own tables untouched."""
    sim = simulate_study(n_receivers=4, n_tags=1, days=0.02, redeployed=0, seed=3)
    before = (sim.deployments.copy(), sim.sheet.copy())
    off = sim.positions[:, :2] + np.array([3.0, -2.0])
    deployments, sheet, references = sim.with_reference_tags([2, 0], off)
    assert references == [sim.deployments["transmitter"].iloc[2], sim.deployments["transmitter"].iloc[0]]
    assert deployments["transmitter"].tolist() == ["", sim.deployments["transmitter"].iloc[1], "",
                                                   sim.deployments["transmitter"].iloc[3]]
    mine = sheet.set_index("transmitter")
    for tag, k in zip(references, [2, 0]):
        assert mine.loc[tag, "role"] == "reference"
        assert mine.loc[tag, "receiver"] == sim.deployments["station"].iloc[k]
    others = sheet[~sheet["transmitter"].isin(references)]
    assert (others["receiver"] == "").all() and (others["role"] != "reference").all()
    inverse = Transformer.from_crs(sim.frame.crs, "EPSG:4326", always_xy=True)
    lon, lat = inverse.transform(off[:, 0], off[:, 1])
    np.testing.assert_allclose(deployments["deploy_lat"], lat, rtol=0, atol=1e-9)
    np.testing.assert_allclose(deployments["deploy_long"], lon, rtol=0, atol=1e-9)
    pd.testing.assert_frame_equal(sim.deployments, before[0])
    pd.testing.assert_frame_equal(sim.sheet, before[1])
    unmoved, _, _ = sim.with_reference_tags([1])
    assert unmoved[["deploy_lat", "deploy_long"]].equals(sim.deployments[["deploy_lat", "deploy_long"]])
