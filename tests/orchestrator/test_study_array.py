"""The array a study uses is what was in the water (:mod:`sblsim.orchestrator.readers.in_water`): each deployment of
a sheet used or not, with its cause, against a by-hand reading of the same rows; the frame chosen over the used
deployments (pyproj's projection to it, here); the assignment's receivers only the used ones; and a small simulated
study given its own deployments and again with a network's sheet around them (other serials, other years, far
away): the same tracks, the same frame, every other deployment listed as not used."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from pyproj import Transformer

from sblsim.orchestrator.io.frames import CHOSEN_GIVEN, CHOSEN_UTM
from sblsim.orchestrator.io.times import iso_utc, utc_seconds
from sblsim.orchestrator.readers.assign import assign
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.in_water import NOT_USED, in_water
from sblsim.orchestrator.telemetry.outputs import write_study
from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study import run_study

DAY = "2023-09-01T00:00:00Z"
NORWAY, LAKES = (60.3816, 5.3387), (44.5, -82.5)  # UTM 31N; the sheet's whole extent is centred in the Atlantic


def _at(hours) -> np.ndarray:
    return utc_seconds([DAY], "", [1], "")[0] + np.asarray(hours, float) * 3600


def _sheet(tmp_path):
    """Deployments near the study (100, 200, 300: one each) and far away (100 and 400 years before, 500 open)."""
    rows = [
        ("A", "100", *NORWAY, -1, 30, "A69-1601-1"),          # the study's window: used
        ("B", "200", NORWAY[0] + 0.002, NORWAY[1], -5, 2, ""),  # recovered before 200 logged: no detection in it
        ("C", "300", NORWAY[0], NORWAY[1] + 0.004, -1, 30, ""),  # never detected
        ("D", "100", *LAKES, -9000, -8000, "A69-1601-9"),      # 100 a year before, far away: outside the span
        ("E", "400", LAKES[0] + 0.1, LAKES[1], -9000, -8000, ""),  # never detected (first cause)
        ("F", "200", NORWAY[0] - 0.002, NORWAY[1], 3, 40, ""),  # 200 redeployed: used
    ]
    frame = pd.DataFrame(rows, columns=["station", "ins_serial_no", "deploy_lat", "deploy_long", "start", "end",
                                        "transmitter"])
    frame["deploy_date_time"] = iso_utc(_at(frame.pop("start")))
    frame["recover_date_time"] = iso_utc(_at(frame.pop("end")))
    path = tmp_path / "deployments.csv"
    frame.to_csv(path, index=False, float_format="%.10f")
    return path


def _detections() -> Detections:
    """100 and 200 heard an animal; 200 at 1 h is before its redeployment and after its recovery (set aside);
    999 is not in the sheet."""
    serial = ["100", "100", "100", "200", "200", "200", "999"]
    hours = [0.5, 4.0, 9.0, 2.5, 5.0, 8.0, 4.0]
    frame = pd.DataFrame({"receiver": serial, "tag": "A69-1602-7", "code_space": "", "time": _at(hours),
                          "sensor_value": np.nan, "sensor_unit": "", "line": np.arange(2, 9)})
    return Detections(frame, "d.csv", "vue")


def test_each_deployment_is_used_or_not_with_its_cause(tmp_path):
    sheet = read_deployments(_sheet(tmp_path))
    data = _detections()
    array = in_water(data, assign(data, sheet), sheet)
    # by hand from the same rows: a deployment is used where a detection of its serial lies in its window; else
    # its serial never logged, else its window misses the kept detections' span, else nothing in its window
    raw = pd.read_csv(tmp_path / "deployments.csv", dtype=str)
    start = utc_seconds(raw["deploy_date_time"], "", list(range(len(raw))), "")
    end = utc_seconds(raw["recover_date_time"], "", list(range(len(raw))), "")
    t, s = data.frame["time"].to_numpy(), data.frame["receiver"].to_numpy()
    inside = (s[None] == raw["ins_serial_no"].to_numpy()[:, None]) & (t[None] >= start[:, None]) \
        & (t[None] <= end[:, None])
    used = inside.any(axis=1)
    kept = t[inside.any(axis=0)]
    cause = np.where(used, "", np.where(~raw["ins_serial_no"].isin(s), "serial_never_detected",
                                        np.where((end < kept.min()) | (start > kept.max()), "outside_detections_span",
                                                 "no_detection_in_window")))
    written = array.deployments.written()
    assert written["station"].tolist() == raw["station"].tolist()  # every deployment of the sheet, in its order
    assert written["used"].tolist() == used.tolist() == [True, False, False, False, False, True]
    assert written["not_used"].tolist() == cause.tolist()
    assert set(cause) - {""} == set(NOT_USED)  # each cause met once at least
    assert written["detections"].tolist() == inside.sum(axis=1).tolist()
    summary = array.deployments.summary()
    assert summary["in_sheet"] == 6 and summary["used"] == summary["deployments"] == 2
    assert summary["not_used"] == {"count": 4, "serial_never_detected": 2, "outside_detections_span": 1,
                                   "no_detection_in_window": 1}
    # the array: the used deployments only, for the clocks and the tags as for the map
    assert array.deployments.table["station"].tolist() == ["A", "F"]
    assert array.assigned.hydrophones["receiver"].tolist() == array.deployments.table["receiver"].tolist()
    assert np.array_equal(array.assigned.hydrophones[["x", "y"]].to_numpy(),
                          array.deployments.table[["x", "y"]].to_numpy())
    line = array.line()
    assert "2 of 6 deployments" in line and "2 serial never detected" in line and "\n" not in line


def test_the_frame_is_chosen_over_the_used_deployments(tmp_path):
    path = _sheet(tmp_path)
    sheet = read_deployments(path)
    data = _detections()
    array = in_water(data, assign(data, sheet), sheet)
    assert sheet.frame.crs != "EPSG:32631"  # the whole sheet's centre is far out at sea, in another zone
    frame = array.deployments.frame
    assert frame.crs == "EPSG:32631" and frame.chosen == CHOSEN_UTM
    raw = pd.read_csv(path)
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32631", always_xy=True).transform(raw["deploy_long"],
                                                                                     raw["deploy_lat"])
    table = array.deployments.table
    assert np.max(np.hypot(table["x"] - x[[0, 5]], table["y"] - y[[0, 5]])) < 1e-3
    written = array.deployments.written()  # every deployment in that frame, the used and the others
    assert np.max(np.hypot(written["x_m"] - x, written["y_m"] - y)) < 1e-3
    assert array.deployments.summary()["frame"]["crs"] == "EPSG:32631"
    # a frame given is kept, and so are its x and y (the sheet's deployments near the study: a frame undistorted
    # over them)
    near = tmp_path / "near.csv"
    raw[raw["station"].isin(["A", "B", "C", "F"])].to_csv(near, index=False, float_format="%.10f")
    given = read_deployments(near, frame="EPSG:32632")
    kept = in_water(data, assign(data, given), given).deployments
    assert kept.frame.crs == "EPSG:32632" and kept.frame.chosen == CHOSEN_GIVEN
    assert np.array_equal(kept.table[["x", "y"]].to_numpy(), given.table.loc[[0, 3], ["x", "y"]].to_numpy())


def _network(sim, count: int, seed: int = 2) -> pd.DataFrame:
    """A network's other deployments around a study's: ``count`` of other serials in other years far away (half
    with a sync tag), and the study's first two serials deployed there a year before."""
    rng = np.random.default_rng(seed)
    start = utc_seconds(["2016-01-01T00:00:00Z"], "", [1], "")[0] + rng.uniform(0, 5 * 365 * 86400, count)
    others = pd.DataFrame({
        "station": [f"FAR-{k:04d}" for k in range(count)],
        "ins_serial_no": [str(800000 + k) for k in range(count)],
        "deploy_lat": LAKES[0] + rng.uniform(-2, 2, count), "deploy_long": LAKES[1] + rng.uniform(-4, 4, count),
        "deploy_date_time": iso_utc(start), "recover_date_time": iso_utc(start + rng.uniform(30, 300, count) * 86400),
        "transmitter": [f"A69-1601-{90000 + k}" if k % 2 else "" for k in range(count)]})
    serials = sim.deployments["ins_serial_no"].drop_duplicates().head(2).to_numpy()
    before = pd.DataFrame({"station": ["OLD-1", "OLD-2"], "ins_serial_no": serials,
                           "deploy_lat": LAKES[0], "deploy_long": [LAKES[1], LAKES[1] + 0.1],
                           "deploy_date_time": "2023-05-01T00:00:00Z", "recover_date_time": "2023-10-01T00:00:00Z",
                           "transmitter": ""})
    return pd.concat([before, others], ignore_index=True)


@pytest.fixture(scope="module")
def twice(tmp_path_factory):
    """A small simulated study (6 receivers, one redeployed; one tag; 2.4 hours) run with its own deployments and
    with 150 other deployments of a network around them."""
    folder = tmp_path_factory.mktemp("array")
    sim = simulate_study(n_receivers=6, n_tags=1, days=0.1, redeployed=1, seed=4)
    files = sim.write(folder / "files", "vue")
    network = pd.concat([sim.deployments, _network(sim, 150)], ignore_index=True)
    network.to_csv(folder / "network.csv", index=False, float_format="%.10f")
    runs = {}
    for name, sheet in (("own", files["deployments"]), ("network", folder / "network.csv")):
        (folder / name).mkdir()
        runs[name] = run_study(files["detections"], sheet, files["tags"], workdir=folder / name, workers=1)
    write_study(runs["network"], folder / "network")
    return sim, network, runs, folder


@pytest.mark.slow
def test_a_network_sheet_changes_no_track(twice):
    sim, network, runs, _ = twice
    own, more = runs["own"], runs["network"]
    assert (own.tags["status"] == "tracked").all()
    pd.testing.assert_frame_equal(own.tracks, more.tracks)
    assert own.summary["frame"] == more.summary["frame"]
    # the same reference deployment (its name SERIAL.2 where the network deployed its serial before)
    station = [o.deployments.table.set_index("receiver").loc[o.summary["clocks"]["reference_receiver"], "station"]
               for o in (own, more)]
    assert station[0] == station[1]
    assert len(more.deployments.table) == len(own.deployments.table) == len(sim.deployments)


@pytest.mark.slow
def test_the_network_s_other_deployments_are_listed_as_not_used(twice):
    sim, network, runs, folder = twice
    written = pd.read_csv(folder / "network" / "receivers.csv", dtype={"serial": str, "station": str},
                          keep_default_na=False)
    assert written["station"].tolist() == network["station"].tolist()
    ours = network["station"].isin(sim.deployments["station"]).to_numpy()
    assert written["used"].tolist() == ours.tolist()
    # the network's serials never logged; the study's own serials a year before logged, out of the span
    expected = np.where(ours, "", np.where(network["ins_serial_no"].isin(sim.deployments["ins_serial_no"]),
                                           "outside_detections_span", "serial_never_detected"))
    assert written["not_used"].tolist() == expected.tolist()
    summary = json.loads((folder / "network" / "study.json").read_text())
    study = summary["receivers"]
    assert study["used"] == len(sim.deployments) and study["in_sheet"] == len(network)
    assert study["not_used"] == {"count": 152, "serial_never_detected": 150, "outside_detections_span": 2}
    said = [n for n in summary["notes"] if f"{len(sim.deployments)} of {len(network)} deployments" in n]
    assert len(said) == 1 and "and 142 more)" in said[0]
    assert "152 not used (150 serial never detected, 2 outside the detections' time span: " in said[0]


@pytest.mark.slow
def test_sblsim_sync_takes_the_same_array(twice):
    """``sblsim sync`` on the network's sheet synchronises the study's own deployments only, as the study does: the
    same clocks as with the study's own sheet, the others said in a note."""
    from sblsim.orchestrator.readers.detections import read_detections
    from sblsim.orchestrator.sync.study_sync import synchronise_study

    sim, network, _, folder = twice
    data = read_detections(folder / "files" / "detections.csv", None)
    own = synchronise_study(data, read_deployments(folder / "files" / "deployments.csv"))
    more = synchronise_study(data, read_deployments(folder / "network.csv"))
    pd.testing.assert_frame_equal(own.offsets.drop(columns="receiver"), more.offsets.drop(columns="receiver"))
    assert more.summary["receivers_file"]["used"] == len(sim.deployments)
    assert any(f"{len(sim.deployments)} of {len(network)} deployments" in n for n in more.summary["notes"])
