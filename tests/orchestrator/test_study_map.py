"""The study's map a user reads (:func:`sblsim.orchestrator.telemetry.outputs.study_map`) and its GeoJSON, on a
network's sheet whose array is a dense cluster of used receivers among others not used: only the used drawn, their
labels never overlapping one another, a marker or the map's edge; each tracked tag's receivers ringed (those its
matrix holds arrivals of); the tags not tracked listed beside with their short reason; a north arrow at pyproj's
meridian convergence; axes as offsets in the frame; the title's counts those of the console."""

from __future__ import annotations

import json
from types import SimpleNamespace

import matplotlib
import numpy as np
import pandas as pd
import pytest
from pyproj import Proj

from sblsim.orchestrator.io.times import iso_utc, utc_seconds
from sblsim.orchestrator.readers.assign import assign
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.in_water import in_water
from sblsim.orchestrator.telemetry.outputs import geojson, study_map
from sblsim.orchestrator.telemetry.study import StudyOutcome

matplotlib.use("Agg")

LAT, LON = 60.3816, 5.3387  # UTM zone 31N, east of its central meridian (3° E)
START = "2023-09-01T00:00:00Z"


def _outcome(tmp_path, refused: int = 2) -> tuple[StudyOutcome, pd.DataFrame, dict[str, int]]:
    """60 used receivers in 220 m by 220 m, 20 of them in 10 m by 10 m (their labels cannot all fit), and 40
    others far away and years before; a track of one tag across the array heard by the receivers of its western
    half; ``refused`` tags not tracked."""
    rng = np.random.default_rng(5)
    k = np.arange(60)
    lat, lon = LAT + rng.uniform(0, 0.002, 60), LON + rng.uniform(0, 0.004, 60)
    lat[40:], lon[40:] = LAT + 0.001 + rng.uniform(0, 9e-5, 20), LON + 0.002 + rng.uniform(0, 1.8e-4, 20)
    rows = pd.DataFrame({"station": [f"S{j:02d}" for j in k], "ins_serial_no": [str(5000 + j) for j in k],
                         "deploy_lat": lat, "deploy_long": lon, "deploy_date_time": START,
                         "recover_date_time": "2023-09-03T00:00:00Z"})
    far = pd.DataFrame({"station": [f"F{j:02d}" for j in range(40)],
                        "ins_serial_no": [str(9000 + j) for j in range(40)],
                        "deploy_lat": 44 + rng.uniform(0, 1, 40), "deploy_long": -82 + rng.uniform(0, 1, 40),
                        "deploy_date_time": "2018-05-01T00:00:00Z", "recover_date_time": "2018-10-01T00:00:00Z"})
    path = tmp_path / "network.csv"
    pd.concat([rows, far]).to_csv(path, index=False, float_format="%.10f")
    counts = {str(5000 + j): int(1 + j % 7) for j in k}  # each used receiver's detections
    serial = np.repeat(list(counts), list(counts.values()))
    t0 = utc_seconds([START], "", [1], "")[0]
    data = Detections(pd.DataFrame({"receiver": serial, "tag": "A69-1602-1", "code_space": "",
                                    "time": t0 + 3600 + np.arange(len(serial)), "sensor_value": np.nan,
                                    "sensor_unit": "", "line": np.arange(len(serial)) + 2}), "d.csv", "vue")
    sheet = read_deployments(path)
    array = in_water(data, assign(data, sheet), sheet).deployments
    table = array.table
    west = (table["x"] < table["x"].median()).to_numpy()
    toa = np.full((5, len(table)), np.nan)
    toa[:, west] = 1.0
    matrix = SimpleNamespace(toa=toa, names=table["receiver"].tolist(), summary={"tag": "A69-1602-1"})
    x = np.linspace(table["x"].min(), table["x"].max(), 50)
    y = np.full(50, table["y"].mean())
    lat_t, lon_t = array.frame.to_latlon(x, y)
    tracks = pd.DataFrame({"tag": "A69-1602-1", "time_utc": iso_utc(t0 + np.arange(50) * 60.0), "x": x, "y": y,
                           "lat": lat_t, "lon": lon_t, "quality": np.where(np.arange(50) % 10 == 3, "flagged", "ok")})
    reasons = ["burst interval: the shortest, 635 s, is not longer than twice the array's largest travel time and "
               "tolerance (337 s): pings cannot be told apart; allowed: a shortest interval above twice that",
               "tag: 'A69-1602-77' is never detected inside a deployment in 'd.csv'"]
    tags = pd.DataFrame({"tag": ["A69-1602-1"] + [f"A69-1602-{100 + j}" for j in range(refused)],
                         "transmitter": ["A69-1602-1"] + [f"A69-1602-{100 + j}" for j in range(refused)],
                         "status": ["tracked"] + ["refused"] * refused,
                         "reason": [""] + [reasons[j % 2] for j in range(refused)]})
    summary = {"frame": array.summary()["frame"]}
    outcome = StudyOutcome(tracks, tags, array, summary, {"tag_1": None}, {"tag_1": matrix})
    return outcome, table, counts


@pytest.fixture(scope="module")
def drawn(tmp_path_factory):
    outcome, table, counts = _outcome(tmp_path_factory.mktemp("map"))
    fig = study_map(outcome)
    yield outcome, table, counts, fig
    matplotlib.pyplot.close(fig)


def _origin(ax) -> tuple[float, float]:
    """The map's origin as its axes' labels state it ('x [m] east of 628,000 (EPSG:…)')."""
    return tuple(float(a.get_label().get_text().split(" of ")[1].split(" ")[0].replace(",", ""))
                 for a in (ax.xaxis, ax.yaxis))


def test_only_the_used_receivers_are_drawn_in_offsets_of_the_frame(drawn):
    outcome, table, _, fig = drawn
    ax = fig.axes[0]
    x0, y0 = _origin(ax)
    assert x0 % 1000 == 0 and y0 % 1000 == 0 and x0 <= table["x"].min() and y0 <= table["y"].min()
    points = np.concatenate([np.c_[line.get_xdata(), line.get_ydata()] for line in ax.lines
                             if line.get_marker() == "^"])
    assert len(points) == 60  # the 40 others not at all
    expected = np.c_[table["x"] - x0, table["y"] - y0]
    assert np.allclose(np.sort(points, axis=0), np.sort(expected, axis=0), rtol=0, atol=1e-6)


def test_labels_never_overlap_and_are_the_used_receivers(drawn):
    outcome, table, _, fig = drawn
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    labels = [t for t in ax.texts if t.get_text() in set(table["receiver"])]
    assert 10 <= len(labels) < 60  # a dense grid: some left out, many kept
    boxes = [t.get_window_extent(renderer) for t in labels]
    frame = ax.get_window_extent(renderer)
    for i, a in enumerate(boxes):
        assert frame.x0 <= a.x0 and a.x1 <= frame.x1 and frame.y0 <= a.y0 and a.y1 <= frame.y1
        for b in boxes[i + 1:]:
            assert not a.overlaps(b)
    panel = "\n".join(t.get_text() for t in fig.axes[1].texts)
    assert f"receivers labelled: {len(labels)} of 60" in panel


def test_each_tag_s_receivers_are_ringed_and_the_tags_not_tracked_listed(drawn):
    outcome, table, _, fig = drawn
    ax = fig.axes[0]
    x0, y0 = _origin(ax)
    rings = [line for line in ax.lines if line.get_marker() == "o"]
    assert len(rings) == 1
    heard = table[table["x"] < table["x"].median()]  # the receivers the matrix holds arrivals of
    ringed = np.c_[rings[0].get_xdata(), rings[0].get_ydata()]
    assert np.allclose(np.sort(ringed, axis=0), np.sort(np.c_[heard["x"] - x0, heard["y"] - y0], axis=0))
    panel = "\n".join(t.get_text() for t in fig.axes[1].texts)
    assert "tags not tracked: 2 of 3" in panel and "A69-1602-100: burst interval: the shortest, 635 s" in panel
    assert "A69-1602-101: tag: 'A69-1602-77' is never detected" in panel and "allowed:" not in panel
    assert "deployments: 60 used of 100" in panel and "serial never detected: 40" in panel
    # the title's counts: those the console prints (tracked of asked), and the frame
    title = fig._suptitle.get_text()
    assert "1 of 3 tags tracked" in title and "60 of 100 deployments used" in title and "EPSG:32631" in title


def test_the_north_arrow_points_to_true_north(drawn):
    outcome, table, _, fig = drawn
    ax = fig.axes[0]
    arrow = [t for t in ax.texts if getattr(t, "arrow_patch", None) is not None]
    assert len(arrow) == 1
    dx, dy = arrow[0].xyann  # the tail's offset from the tip [pt]
    angle = np.degrees(np.arctan2(-dx, -dy))
    lat, lon = outcome.deployments.frame.to_latlon(np.array([table["x"].mean()]), np.array([table["y"].mean()]))
    convergence = Proj("EPSG:32631").get_factors(float(lon[0]), float(lat[0])).meridian_convergence
    # east of the zone's central meridian true north lies west of the grid's north
    assert angle < 0 and abs(abs(angle) - abs(convergence)) < 0.01


@pytest.mark.slow
def test_many_tags_not_tracked_fit_beside_the_map(tmp_path):
    outcome, _, _ = _outcome(tmp_path, refused=120)
    fig = study_map(outcome)
    try:
        fig.savefig(tmp_path / "map.png", dpi=110)
        text = fig.axes[1].texts[0]
        box, page = text.get_window_extent(fig.canvas.get_renderer()), fig.bbox
        assert page.y0 <= box.y0 and box.y1 <= page.y1 and box.x1 <= page.x1
        shown = text.get_text()
        listed = shown.count("A69-1602-1")  # the refused tags' entries shown
        assert 10 < listed < 120 and f"… and {120 - listed} more (tags.csv)" in shown
    finally:
        matplotlib.pyplot.close(fig)


def test_the_geojson_holds_the_used_receivers_as_points(tmp_path):
    outcome, table, counts = _outcome(tmp_path)
    shapes = geojson(outcome)
    json.dumps(shapes, allow_nan=False)
    points = [f for f in shapes["features"] if f["properties"]["kind"] == "receiver"]
    assert len(points) == 60
    heard = set(table.loc[table["x"] < table["x"].median(), "receiver"])
    by_name = table.set_index("receiver")
    for f in points:
        p = f["properties"]
        assert p["used"] is True and p["detections"] == counts[p["serial"]]
        assert p["tags_tracked"] == ("A69-1602-1" if p["receiver"] in heard else "")
        assert np.allclose(f["geometry"]["coordinates"], by_name.loc[p["receiver"], ["lon", "lat"]].to_numpy(float),
                           rtol=0, atol=1e-9)
    lines = [f for f in shapes["features"] if f["properties"]["kind"] == "track"]
    assert len(lines) == 1 and len(lines[0]["geometry"]["coordinates"]) == 45  # its 5 flagged rows left out
