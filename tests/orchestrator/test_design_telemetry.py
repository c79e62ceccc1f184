"""``sblsim design`` of a telemetry array (``candidates.systems = ["ilbl"]``): the predicted DRMS against an
independent Fisher computation, receivers only in the water, the sync graph, what an unmeetable prescription
fails, the water's file readers, the refusals, and the Monte Carlo of the worked case."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.errors import ConfigError
from tests.helpers import problem_with

#: A small lake: an L of 300 m × 300 m without its North-East quarter (concave), a logistic detection curve.
L_LAKE = "0 0; 0 300; 150 300; 150 150; 300 150; 300 0"
SMALL = {
    "design": {"name": "pond"},
    "site.area": {"polygon": L_LAKE},
    "detection": {"range_50_m": 350.0, "slope": 0.02, "sync_p": 0.5, "sigma_toa_s": 1e-4, "sound_speed": 1480.0},
    "work_area": {"shape": "site", "points": 8},
    "prescription": {"drms_m": 2.0, "coverage_pct": 90.0, "positioning_yield_pct": 80.0},
    "candidates": {"systems": ["ilbl"], "receivers": [4, 7]},
    "search": {"generations": 6, "seed": 3},
    "monte_carlo": {"replicates": 10, "path": False},
}


def _problem(**changes):
    return problem_with(SMALL, **changes)


def _inside(vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Even-odd ray casting, independent of the project's polygon code (boundary excluded by a margin)."""
    x, y = points[:, 0][:, None], points[:, 1][:, None]
    a, b = vertices, np.roll(vertices, -1, axis=0)
    crosses = ((a[:, 1] > y) != (b[:, 1] > y)) & (
        x < a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / np.where(b[:, 1] == a[:, 1], 1.0, b[:, 1] - a[:, 1]))
    return crosses.sum(axis=1) % 2 == 1


def _lake() -> np.ndarray:
    return np.array([[float(v) for v in r.split()] for r in L_LAKE.split(";")])


def _fisher_drms(point, receivers, sigma, weights) -> float:
    """DRMS of (x, y) from the full 3 × 3 information of (x, y, c t_e), inverted (no Schur complement)."""
    d = point - receivers
    r = np.linalg.norm(d, axis=1)
    H = np.column_stack([d / r[:, None], np.ones(len(r))])
    J = (H * (weights / sigma**2)[:, None]).T @ H
    cov = np.linalg.inv(J)
    return float(np.sqrt(cov[0, 0] + cov[1, 1]))


def _logistic(d):
    return 1.0 / (1.0 + np.exp(0.02 * (d - 350.0)))


def test_the_ilbl_designs_predicted_drms_is_an_independent_fisher_computation():
    """At every work-area point of the proposed design: the averaged information's DRMS and the RMS over the fixed
    pings (every pattern of ≥ 3 receivers enumerated, each weighted by its probability) equal a full 3 × 3 Fisher
    inversion with the emission time unknown, to 1e-9 (the RMS over patterns: 1e-6); design.json's quantiles are
    those of the latter."""
    result = sblsim.design(None, **_problem())
    best = result.run.best
    points, receivers = result.run.resolved.points, best.receivers
    sigma = 1480.0 * 1e-4
    assert len(receivers) <= 10  # every pattern enumerated: exact
    fixed = []
    for j, point in enumerate(points):
        q = _logistic(np.linalg.norm(point - receivers, axis=1))
        assert best.drms_expected[j] == pytest.approx(_fisher_drms(point, receivers, sigma, q), rel=1e-9)
        total, mass = 0.0, 0.0
        for bits in itertools.product((False, True), repeat=len(receivers)):
            heard = np.array(bits)
            if heard.sum() < 3:
                continue
            p = float(np.prod(np.where(heard, q, 1.0 - q)))
            total += p * _fisher_drms(point, receivers[heard], sigma, np.ones(heard.sum())) ** 2
            mass += p
        fixed.append(np.sqrt(total / mass))
        # near-collinear patterns of three (condition ~1e9) carry the rounding of two different inversions
        assert best.drms_fixed[j] == pytest.approx(fixed[-1], rel=1e-6)
        assert best.positioning_yield[j] == pytest.approx(mass, rel=1e-9)
    predicted = result.designs[0]["predicted"]
    assert predicted["drms_p50_m"] == pytest.approx(np.percentile(fixed, 50, method="higher"), rel=1e-6)
    assert predicted["drms_p95_m"] == pytest.approx(np.percentile(fixed, 95, method="higher"), rel=1e-6)


@pytest.mark.slow
def test_receivers_are_never_outside_the_water_and_the_sync_graph_is_connected():
    """Every count searched (``search.pareto``) in a concave lake, with a margin from the shore: each receiver
    inside the lake by an independent ray casting, at least the margin from every edge; the design that meets
    has a connected sync graph where each receiver hears two others with probability ≥ sync_p."""
    result = sblsim.design(None, **_problem(search={"pareto": True}, **{"site.area": {"min_shore_m": 20.0}}))
    lake = _lake()
    for design in result.run.searched:
        r = design.receivers
        assert _inside(lake, r).all()
        a, b = lake, np.roll(lake, -1, axis=0)
        t = np.clip(np.einsum("mkj,kj->mk", r[:, None] - a, b - a) / np.sum((b - a) ** 2, axis=1), 0, 1)
        assert np.linalg.norm(r[:, None] - (a + t[..., None] * (b - a)), axis=-1).min() >= 20.0 - 1e-9
    meeting = [d for d in result.designs if d["meets"]]
    assert meeting
    r = np.array(meeting[0]["receivers_m"])
    p = _logistic(np.linalg.norm(r[:, None] - r[None], axis=-1))
    linked = (p >= 0.5) & ~np.eye(len(r), dtype=bool)
    assert linked.sum(axis=1).min() >= 2
    seen, todo = {0}, [0]
    while todo:
        for j in np.flatnonzero(linked[todo.pop()]):
            if j not in seen:
                seen.add(int(j))
                todo.append(int(j))
    assert seen == set(range(len(r)))
    assert meeting[0]["predicted"]["sync_coverage"] == 1.0 and meeting[0]["predicted"]["sync_met"]
    assert sorted(map(tuple, meeting[0]["sync_links"])) == [(i, j) for i, j in zip(*np.nonzero(np.triu(linked)))]


@pytest.mark.parametrize("changes, part", [
    ({"prescription": {"drms_m": 0.001}}, "drms"),
    ({"prescription": {"positioning_yield_pct": 100.0, "drms_m": 1000.0}}, "positioning_yield"),
    ({"detection": {"sync_p": 1.0}}, "sync_coverage"),
])
def test_an_unmeetable_prescription_names_the_criterion_that_fails(changes, part):
    result = sblsim.design(None, **_problem(candidates={"receivers": [4, 4]}, **changes))
    assert not result.document["meets"]
    fails = result.designs[0]["fails"]
    assert part in [f["part"] for f in fails]
    assert "no count of receivers meets" in result.summary and part.split("_")[0] in result.summary.lower()


def test_the_water_from_a_csv_or_geojson_file(tmp_path):
    """The same lake given as a polygon, a CSV of (north, east) and a GeoJSON (east, north) gives the same work
    area; a relative file is read from the design file's folder."""
    from sblsim.orchestrator.design.area_file import read_area

    lake = _lake()
    (tmp_path / "lake.csv").write_text("north_m,east_m\n# an L\n" + "\n".join(f"{n},{e}" for n, e in lake) + "\n")
    ring = [[e, n] for n, e in lake] + [[lake[0][1], lake[0][0]]]
    (tmp_path / "lake.geojson").write_text(json.dumps({"type": "Feature", "properties": {},
                                                       "geometry": {"type": "Polygon", "coordinates": [ring]}}))
    for name in ("lake.csv", "lake.geojson"):
        geometry = read_area(tmp_path / name)
        assert geometry.area == pytest.approx(3 * 150.0 * 150.0)
        assert geometry.contains(__import__("shapely").Point(50.0, 250.0))  # North 50, East 250: water
        assert not geometry.contains(__import__("shapely").Point(250.0, 250.0))  # the missing quarter
    text = "\n".join(f"[{section}]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in values.items())
                     for section, values in _problem(**{"site.area": {"polygon": ""}}).items()
                     if section != "site.area")
    (tmp_path / "pond.toml").write_text(text + '\n[site.area]\nfile = "lake.csv"\n')
    from sblsim.orchestrator.design.problem import check_problem, read_problem
    from sblsim.orchestrator.design.telemetry import resolve

    by_file = resolve(check_problem(read_problem(tmp_path / "pond.toml")))
    by_polygon = resolve(check_problem(_problem()))
    np.testing.assert_array_equal(by_file.points, by_polygon.points)
    # the design file's folder holding a symbolic link to a file elsewhere: refused, naming the key and the target
    (tmp_path / "designs").mkdir()
    (tmp_path / "designs" / "pond.toml").write_text((tmp_path / "pond.toml").read_text())
    (tmp_path / "designs" / "lake.csv").symlink_to(tmp_path / "lake.csv")
    with pytest.raises(ConfigError, match=r"site\.area\.file: 'lake\.csv' leads through a symbolic link"):
        read_problem(tmp_path / "designs" / "pond.toml")


@pytest.mark.parametrize("content, message", [
    ("north_m,east_m\n0,0\n0,1\n", "vertices"),
    ("north_m,east_m\n0,0\n0,nan\n1,1\n", "not finite"),
    ("north_m,east_m\n0,0\n0,1,2\n1,1\n", "line 3: 3 cells"),
    ("x,y\n0,0\n0,1\n1,1\n", "allowed north_m, east_m"),
    ("0,0\n10,10\n0,10\n10,0\n", "not a valid polygon"),
])
def test_a_bad_water_file_is_refused_in_one_line(tmp_path, content, message):
    from sblsim.orchestrator.design.area_file import read_area

    (tmp_path / "a.csv").write_text(content)
    with pytest.raises(ConfigError, match="site.area.file") as error:
        read_area(tmp_path / "a.csv")
    assert message in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize("content, message", [
    ('{"type": "Point", "coordinates": [0, 0]}', "Polygon"),
    ('{"type": "Polygon", "coordinates": [[[0, 0], [0, NaN], [1, 1], [0, 0]]]}', "not valid GeoJSON"),
    ("[" * 100000 + "]" * 100000, "not valid GeoJSON"),
    ("[1, 2]", "a GeoJSON list"),
])
def test_a_bad_geojson_is_refused_in_one_line(tmp_path, content, message):
    from sblsim.orchestrator.design.area_file import read_area

    (tmp_path / "a.geojson").write_text(content)
    with pytest.raises(ConfigError, match="site.area.file") as error:
        read_area(tmp_path / "a.geojson")
    assert message in str(error.value)
    with pytest.raises(ConfigError, match="site.area.file.*no such file"):
        read_area(tmp_path / "missing.csv")


@pytest.mark.parametrize("changes, message", [
    ({"candidates": {"systems": ["ilbl", "lbl"]}}, "candidates.systems: .*ilbl .*alone"),
    ({"detection": {"range_50_m": 0.0, "slope": 0.0}}, "detection: missing"),
    ({"detection": {"table": "0 1; 100 0"}}, "detection.range_50_m: given with detection.table"),
    ({"detection": {"range_50_m": 0.0, "slope": 0.0, "table": "0 0.5; 100 0.9"}}, "detection.table: .*rise"),
    ({"site.area": {"file": "lake.csv"}}, "site.area: give the water as site.area.polygon or site.area.file"),
    ({"site.area": {"polygon": "0 0; 1 1"}}, "site.area.polygon: 2 vertices"),
    ({"site.area": {"shore": 3}}, "site.area.shore: not a key of \\[site.area\\]"),
    ({"candidates": {"receivers": [9, 4]}}, "candidates.receivers: the fewest"),
    ({"work_area": {"shape": "circle"}}, "work_area.shape: 'circle' for an ilbl design"),
    ({"detection": {"sync_p": 0.0}}, "detection.sync_p"),
    ({"design": {"scenario": "lbl-field"}}, "design.scenario: an ilbl design .*reads no base scenario"),
    ({"design": {"set": ["acoustics.sigma_range=0.1"]}}, "design.set: an ilbl design"),
    ({"site.area": {"origin": "95 5"}}, "site.area.origin: '95 5'; allowed 'latitude longitude'"),
    ({"site.area": {"origin": "60.38"}}, "site.area.origin"),
])
def test_a_bad_telemetry_problem_is_refused_naming_its_key(changes, message):
    with pytest.raises(ConfigError, match=message):
        sblsim.design(None, **_problem(**changes))


def test_a_base_scenario_is_refused_for_a_telemetry_design():
    with pytest.raises(ConfigError, match="^scenario: an ilbl design"):
        sblsim.design(None, scenario="lbl-field", **_problem())


def test_the_command_line_refuses_in_one_line_and_writes_nothing(tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    (tmp_path / "bad.toml").write_text('[candidates]\nsystems = ["ilbl", "usbl"]\n')
    status = main(["design", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "out")])
    assert status == 2 and not (tmp_path / "out").exists()
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "candidates.systems" in err


def test_the_walk_of_the_path_stays_in_the_water():
    """The path's animal walks ~10 m a ping in the concave lake for 2,000 pings: every position inside it by an
    independent ray casting, and it goes round (both arms of the L visited)."""
    from sblsim.orchestrator.design.problem import check_problem
    from sblsim.orchestrator.design.telemetry import resolve
    from sblsim.orchestrator.design.telemetry_confirm import walk

    problem = resolve(check_problem(_problem()))
    positions = walk(problem, np.arange(2000) * 30.0, np.random.default_rng(1))
    assert _inside(_lake(), positions).all()
    assert (positions[:, 0] > 200.0).any() and (positions[:, 1] > 200.0).any()
    assert np.median(np.linalg.norm(np.diff(positions, axis=0), axis=1)) == pytest.approx(9.0)


@pytest.mark.slow
def test_the_telemetry_design_writes_its_outputs(tmp_path):
    result = sblsim.design(None, **_problem(monte_carlo={"path": True}), out=tmp_path / "d")
    document = json.loads((tmp_path / "d" / "design.json").read_text())
    best = document["designs"][0]
    assert best["system"] == "ilbl" and best["scenario"] is None and best["meets"]
    assert {"positioning_yield", "sync_coverage"} <= set(best["predicted"])
    assert all({"simulated_yield", "predicted_yield", "ratio"} <= set(m) for m in best["monte_carlo"])
    (path,) = best["path"]
    assert path["pings"] == 250 and 0 < path["fixes"] <= 250 and path["simulated_yield"] >= path["simulated_fixed"]
    assert 0 < path["tracked_pings"] <= 250 and 1.5 <= path["tracked_nees"] <= 4.5, path  # the tracker's own
    assert (tmp_path / "d" / "designs.csv").exists() and (tmp_path / "d" / "layout.png").exists()
    assert result.table["count"].iloc[0] == len(best["receivers_m"]) and result.table["meets"].iloc[0]
    # receivers.csv: the design's receivers as a study gives them, x east and y north; no lat, lon without an origin
    table = pd.read_csv(tmp_path / "d" / "receivers.csv")
    first = table[table["design"] == best["name"]]
    assert np.array_equal(first[["y_m", "x_m"]].to_numpy(), np.array(best["receivers_m"]))
    assert first["lat"].isna().all()


@pytest.mark.slow
def test_a_design_placed_by_its_origin_gives_its_receivers_lat_lon(tmp_path):
    """``site.area.origin``: the receivers' lat, lon are the origin's UTM coordinates plus (east, north), back
    through pyproj (computed here with pyproj's own transformer)."""
    from pyproj import Transformer

    sblsim.design(None, **_problem(**{"site.area": {"polygon": L_LAKE, "origin": "60.38 5.34"}}), out=tmp_path / "d")
    table = pd.read_csv(tmp_path / "d" / "receivers.csv")
    x0, y0 = Transformer.from_crs("EPSG:4326", "EPSG:32631", always_xy=True).transform(5.34, 60.38)
    lon, lat = Transformer.from_crs("EPSG:32631", "EPSG:4326", always_xy=True).transform(x0 + table["x_m"],
                                                                                        y0 + table["y_m"])
    assert np.max(np.abs(table["lat"] - lat)) < 1e-9 and np.max(np.abs(table["lon"] - lon)) < 1e-9


@pytest.mark.slow
def test_the_lake_hald_array_is_confirmed_by_simulated_tags():
    """The worked case: the proposed array meets, and at its worst and median points and along an animal's walk
    the simulated tags' DRMS is within [0.85, 1.15] of the predicted and their yield within 5 percentage
    points."""
    result = sblsim.design("lake-hald-array")
    best = result.designs[0]
    assert best["meets"] and len(best["monte_carlo"]) == 2
    for row in best["monte_carlo"] + best["path"]:
        assert 0.85 <= row["ratio"] <= 1.15, row
        assert abs(row["simulated_yield"] - row["predicted_yield"]) <= 0.05, row
        assert abs(row["simulated_fixed"] - row["predicted_fixed"]) <= 0.05, row


def test_the_built_in_lake_hald_array_is_lake_halds_stated_case():
    """``lake-hald-array``'s water, detection table, timing and sync probability are ``lake_hald``'s constants (the
    water's vertices (x, y) given as (North, East) = (y, x))."""
    from sblsim.models.design import lake_hald as lh
    from sblsim.orchestrator.design.problem import check_problem, read_problem

    sections = check_problem(read_problem("lake-hald-array"))
    vertices = np.array([[float(v) for v in r.split()] for r in sections["site.area"]["polygon"].split(";")])
    np.testing.assert_array_equal(vertices[:, ::-1], np.array(lh.LAKE_HALD_AREA))
    table = np.array([[float(v) for v in r.split()] for r in sections["detection"]["table"].split(";")])
    np.testing.assert_array_equal(table, np.array(lh.LAKE_HALD_DETECTION))
    assert sections["detection"]["sigma_toa_s"] == lh.LAKE_HALD_SIGMA_TOA
    assert sections["detection"]["sound_speed"] == lh.LAKE_HALD_SOUND_SPEED
    assert sections["detection"]["sync_p"] == lh.LAKE_HALD_SYNC_P
    assert sections["candidates"]["systems"] == ["ilbl"] and sections["work_area"]["shape"] == "site"


@pytest.mark.slow
def test_the_path_is_tracked_as_the_replay_tracks_a_recorded_tag(tmp_path):
    """``track_path`` (the design's confirmation by the tracker) on 300 pings of a random burst interval U(20, 40) s
    among 6 receivers, each heard with probability 0.8, the tag circling inside the array: its RMS equals
    ``sblsim.replay_toa``'s on the same pings written to files (the replay's own pipeline, scored against the truth
    file), the track consistent with its covariance (mean NEES in [1, 4]) and within 1.5 times the smoothing
    bound."""
    from sblsim.models.tracking.ekf import TrackerSettings
    from sblsim.models.tracking.simulate import simulate_pings
    from sblsim.orchestrator.design.telemetry_tracking import track_path
    from sblsim.orchestrator.tracks.variants import write_toa

    receivers = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 250.0], [0.0, 250.0], [150.0, 120.0], [90.0, 230.0]])
    settings = TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, acceleration_psd=1e-4)
    def circle(t):  # 80 m round the array's middle in an hour (0.14 m/s)
        a = 2.0 * np.pi * np.asarray(t) / 3600.0
        return np.column_stack([150.0 + 80.0 * np.cos(a), 125.0 + 80.0 * np.sin(a)])

    toa, positions, emissions = simulate_pings(receivers, 300, settings, np.random.default_rng(3), detection=0.8,
                                               ping_type="rbi", burst_interval=(20.0, 40.0), path=circle)
    row = track_path(receivers, toa, positions, emissions, 1480.0, 1.5e-4, (20.0, 40.0))
    names = [f"R{k + 1}" for k in range(len(receivers))]
    write_toa(tmp_path / "toa.txt", toa, names)
    (tmp_path / "receivers.csv").write_text("name,x_m,y_m\n" + "".join(
        f"{n},{x:.6f},{y:.6f}\n" for n, (x, y) in zip(names, receivers)))
    np.savetxt(tmp_path / "truth.txt", np.column_stack([positions, emissions]), header="x y t", comments="")
    replay = sblsim.replay_toa(tmp_path / "toa.txt", receivers=tmp_path / "receivers.csv",
                               truth=tmp_path / "truth.txt", sound_speed=1480.0, ping_type="rbi",
                               burst_interval=(20.0, 40.0))
    # the replay scores the pings whose estimated emission lies within the truth file's times (the first may not)
    assert 0 <= row["tracked_pings"] - replay.score["n_scored"] <= 2, (row, replay.score["n_scored"])
    assert row["tracked_rms_m"] == pytest.approx(replay.score["rms_m"], rel=0.02), (row, replay.score["rms_m"])
    assert 1.0 <= row["tracked_nees"] <= 4.0 and row["tracked_ratio"] <= 1.5, row
