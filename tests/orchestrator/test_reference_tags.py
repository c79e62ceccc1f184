"""Reference tags as the study's own accuracy check (issue 97, item 2): a study's reference tags at a known position
(the tag sheet's ``lat``, ``lon``; a ``receiver`` column naming a deployment; a deployment's sync-tag cell naming
it) and its sync tags left out of the synchronisation in turn are scored in ``reference_tags.csv``, ``study.json``'s
``reference_tags`` and the console, per tag and pooled.

The study is simulated (:func:`sblsim.orchestrator.telemetry.simulate.simulate_study`): three of its sync tags, each
at its receiver's true position, given as reference tags. Every figure is checked against a scoring made here with
numpy from ``tracks.csv``, each tag's ``summary.json`` covariance and ``estimates.csv``, the simulated positions (the
truth), and the synchronisation's own ``sync_tags.csv``."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet
from sblsim.orchestrator.telemetry.outputs import write_study
from sblsim.orchestrator.telemetry.reference_tags import beyond, given_sync_tags, score_reference, sync_rows
from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study import run_study
from sblsim.orchestrator.telemetry.study_report import reference_lines

#: The stated survey error of the reference tag given by latitude and longitude [m].
SURVEY = 0.5
#: The deployments whose sync tags are the reference tags: the grid's middle and two sides' middles.
AT = (4, 1, 3)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A 6-hour study of 9 receivers on a 3 × 3 grid: the sync tags of the middle one and of two at the sides' middles
    given as reference tags, the first by its true position in latitude and longitude (and a survey σ), the second by
    a ``receiver`` column naming its station (both their deployments' sync-tag cells emptied), the third by its
    deployment's sync-tag cell (it stays a sync tag)."""
    folder = tmp_path_factory.mktemp("reference")
    sim = simulate_study(n_receivers=9, n_tags=0, days=0.25, redeployed=0, seed=4)
    files = sim.write(folder / "in", "vue")
    deployments = sim.deployments.copy()
    refs = deployments["transmitter"].iloc[list(AT)].tolist()
    deployments.loc[list(AT[:2]), "transmitter"] = ""
    deployments.to_csv(files["deployments"], index=False, float_format="%.10f")
    lat, lon = sim.frame.to_latlon(sim.positions[AT[:1], 0], sim.positions[AT[:1], 1])
    sheet = sim.sheet.copy()
    sheet.loc[sheet["transmitter"].isin(refs), "role"] = "reference"
    sheet["lat"], sheet["lon"], sheet["survey_sigma_m"], sheet["receiver"] = "", "", "", ""
    first = sheet.index[sheet["transmitter"] == refs[0]][0]
    sheet.loc[first, ["lat", "lon", "survey_sigma_m"]] = [f"{lat[0]:.10f}", f"{lon[0]:.10f}", f"{SURVEY:g}"]
    sheet.loc[sheet["transmitter"] == refs[1], "receiver"] = deployments.loc[AT[1], "station"]
    sheet.to_csv(files["tags"], index=False)
    outcome = run_study(files["detections"], files["deployments"], files["tags"], workdir=folder / "out",
                        chosen=refs, workers=1)
    write_study(outcome, folder / "out")
    return sim, refs, outcome, folder / "out"


def _read(out, name: str) -> pd.DataFrame:
    return pd.read_csv(out / name, dtype={"tag": str, "receiver": str})


@pytest.mark.slow
def test_each_reference_tag_is_scored_against_its_known_position(study):
    sim, refs, outcome, out = study
    scored = _read(out, "reference_tags.csv")
    tracks = _read(out, "tracks.csv")
    tags = _read(out, "tags.csv").set_index("tag")
    rows = scored[scored["kind"] == "reference"].set_index("tag")
    assert sorted(rows.index) == sorted(refs)
    for k, tag in enumerate(refs):
        truth = sim.positions[AT[k]]
        mine = tracks[tracks["tag"] == tag]
        place = mine[["x", "y"]].to_numpy(float)[0]  # a still tag: one place on every row
        still = json.loads((out / tags.loc[tag, "folder"] / "summary.json").read_text())["motion"]["still"]
        survey = SURVEY if k == 0 else 0.0
        P = np.asarray(still["covariance"], float)[:2, :2] + survey**2 * np.eye(2)
        e = place - truth
        row = rows.loc[tag]
        assert row["truth_x_m"] == pytest.approx(truth[0], abs=1e-3)  # lat, lon back in the frame to a mm
        assert row["truth_y_m"] == pytest.approx(truth[1], abs=1e-3)
        assert row["error_m"] == pytest.approx(np.hypot(*e), abs=1e-3)
        assert row["nees"] == pytest.approx(e @ np.linalg.solve(P, e), rel=1e-3, abs=1e-6)
        assert row["sigma_m"] == pytest.approx(np.sqrt(np.trace(P)), rel=1e-6)
        flagged = int((mine["quality"] == "flagged").sum())
        assert (row["rows"], row["flagged"]) == (len(mine), flagged)
        est = pd.read_csv(out / tags.loc[tag, "folder"] / "estimates.csv")
        fixes = est.loc[est["estimator"] == "fix", ["x", "y"]].dropna().to_numpy(float)
        assert row["single_fix_median_error_m"] == pytest.approx(np.median(np.linalg.norm(fixes - truth, axis=1)),
                                                                 abs=1e-3)
        assert row["error_m"] < 1.0 and row["nees"] < beyond()  # the simulated tag is where its truth says
    assert rows.loc[refs[0], "truth"] == "the tag sheet's lat, lon"
    assert rows.loc[refs[0], "survey_sigma_m"] == SURVEY
    assert "receiver" in rows.loc[refs[1], "truth"] and "sync-tag cell" in rows.loc[refs[2], "truth"]
    # the third is still a sync tag: the clocks were fitted with its arrivals, said
    assert list(rows.loc[refs, "in_sync"]) == [False, False, True]


def _held(values) -> int:
    """The bytes ``values`` (a NumPy or Arrow-backed pandas array) keeps alive: a view's whole base, a slice's whole
    buffers."""
    arrow = getattr(values, "_pa_array", None)
    if arrow is not None:
        return arrow.get_total_buffer_size()
    while isinstance(getattr(values, "base", None), np.ndarray):
        values = values.base
    return getattr(values, "nbytes", 0)


@pytest.mark.slow
def test_written_a_tag_at_a_time_the_reference_tags_rows_are_in_the_tracks(study, tmp_path):
    """A study that keeps no tag's track (``sblsim track``: tracks.csv from the tags' own files) keeps its reference
    tags whole for their scoring and writes their rows too: its files are the study's kept whole."""
    sim, refs, _, out = study
    files = {name: out.parent / "in" / f"{name}.csv" for name in ("detections", "deployments", "tags")}
    outcome = run_study(files["detections"], files["deployments"], files["tags"], workdir=tmp_path, chosen=refs,
                        workers=1, write_tags=True, keep_tracks=False)
    assert outcome.tracks is None and outcome.parts is not None
    for matrix in outcome.matrices.values():  # a written tag's rows let go, not held on by a view of them
        assert len(matrix.toa) == len(matrix.pings) == 0 and matrix.toa.base is None
        for block in matrix.pings._mgr.blocks:  # (pandas' blocks: a NumPy array's base, an Arrow array's buffers)
            assert _held(block.values) < 1024
    residuals = outcome.sync.residuals.copy()
    write_study(outcome, tmp_path)  # (its residuals kept on disk while its tracks and report are made)
    pd.testing.assert_frame_equal(outcome.sync.residuals, residuals)  # the outcome's, back
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]  # nothing of it left in the folder
    assert set(_read(tmp_path, "tracks.csv")["tag"]) >= set(refs[:2])
    for name in ("tracks.csv", "reference_tags.csv", "tracks.geojson"):
        assert (tmp_path / name).read_text() == (out / name).read_text(), name


@pytest.mark.slow
def test_the_pooled_figures_and_the_console_line(study):
    sim, refs, outcome, out = study
    scored = _read(out, "reference_tags.csv")
    rows = scored[scored["kind"] == "reference"]
    pooled = json.loads((out / "study.json").read_text())["reference_tags"]["reference"]
    assert pooled["tags"] == 3
    assert pooled["median_error_m"] == pytest.approx(np.median(rows["error_m"]))
    assert pooled["nees_mean"] == pytest.approx(np.mean(rows["nees"]))
    assert pooled["flagged"] == rows["flagged"].sum() and pooled["rows"] == rows["rows"].sum()
    lines = [line for line, _ in reference_lines(outcome.summary["reference_tags"])]
    said = [line for line in lines if line.startswith("  reference tags: ")]
    assert said == [said[0]] and f"median error {np.median(rows['error_m']):.2g} m" in said[0]
    assert f"NEES {np.mean(rows['nees']):.2g}" in said[0]


@pytest.mark.slow
def test_the_sync_tags_left_out_are_the_synchronisations_own(study):
    """The sync tags' leave-one-out taken from the synchronisation's sync_tags.csv as it is: each tag's one place
    (its error recomputed here against the simulated position, which is its receiver's in the table), pooled with
    the reference tags as still tags, and where a tag has no place its single-emission fixes."""
    sim, refs, outcome, out = study
    loo = _read(out, "sync/sync_tags.csv").set_index("tag")
    scored = _read(out, "reference_tags.csv")
    rows = scored[scored["kind"] == "sync_left_out"].set_index("tag")
    assert len(loo) and sorted(rows.index) == sorted(loo.index)
    assert refs[0] not in rows.index and refs[1] not in rows.index  # no longer sync tags
    assert (rows["scored_by"] == "one place").all()
    place = rows.loc[loo.index, ["x_m", "y_m"]].to_numpy(float)
    truth = sim.positions[[int(str(t).rsplit("-", 1)[1]) - 60000 for t in loo.index]][:, :2]  # its deployment's
    assert np.allclose(rows.loc[loo.index, "error_m"], np.hypot(*(place - truth).T), atol=1e-4)  # (the sheet's
    # latitudes and longitudes to 10 decimals: 10 µm)
    assert np.allclose(rows.loc[loo.index, "error_m"], loo["place_error_m"])
    assert np.allclose(rows.loc[loo.index, "nees"], loo["place_nees"])
    assert np.allclose(rows.loc[loo.index, "single_fix_median_error_m"], loo["median_error_m"])
    assert (rows.loc[loo.index, "flagged"] == loo["place_flagged"]).all()
    pooled = outcome.summary["reference_tags"]["sync_left_out"]
    assert pooled["median_error_m"] == pytest.approx(loo["place_error_m"].median())
    assert pooled["nees_mean"] == pytest.approx(loo["place_nees"].mean())
    both = outcome.summary["reference_tags"]["still"]
    still = scored[scored["scored_by"] == "one place"]
    assert both["tags"] == len(still) == len(loo) + 3
    assert both["nees_mean"] == pytest.approx(still["nees"].mean())
    lines = [line for line, _ in reference_lines(outcome.summary["reference_tags"])]
    said = [line for line in lines if line.startswith("  still tags together")]
    assert len(said) == 1 and f"NEES {still['nees'].mean():.2g} " in said[0]
    fixes = sync_rows(loo.reset_index().drop(columns=["place_error_m"]))  # a table without places: the fixes
    assert [r["error_m"] for r in fixes] == pytest.approx(loo["median_error_m"].tolist())
    assert all(r["scored_by"] == "single-emission fixes" for r in fixes)


@pytest.mark.slow
def test_a_given_synchronisations_sync_tags_are_read_as_hostile_cells(study, tmp_path):
    """``--sync DIR``: its folder's sync_tags.csv read back (each cell checked) gives the same rows."""
    sim, refs, outcome, out = study
    loo = _read(out, "sync/sync_tags.csv")
    given = given_sync_tags(out / "sync")
    assert given["tag"].tolist() == loo["tag"].tolist()
    assert np.allclose(given["nees_mean"], loo["nees_mean"]) and (given["inside_array"] == loo["inside_array"]).all()
    assert pd.DataFrame(sync_rows(given))["error_m"].tolist() == pytest.approx(loo["place_error_m"].tolist())
    assert (given["place_verdict"] == loo["place_verdict"]).all()
    assert given_sync_tags(tmp_path) is None  # a folder without one: none
    loo["nees_mean"] = loo["nees_mean"].astype(object)
    loo.loc[0, "nees_mean"] = "-3"
    loo.to_csv(tmp_path / "sync_tags.csv", index=False)
    with pytest.raises(ModelError, match="line 2 column nees_mean: '-3' is not allowed"):
        given_sync_tags(tmp_path)


@pytest.mark.slow
def test_a_reference_tag_far_from_its_position_is_said(study):
    """The same track scored against a position 30 m off: beyond its σ, and a warning says it."""
    sim, refs, outcome, out = study
    folder = outcome.tags.set_index("tag").loc[refs[1], "folder"]
    truth = {"truth": "the tag sheet's lat, lon", "receiver": "", "xyz": np.r_[sim.positions[AT[1]] + [30.0, 0.0],
                                                                              np.nan],
             "lat": np.nan, "lon": np.nan, "survey": float("nan"), "in_sync": False}
    row = score_reference(refs[1], outcome.outcomes[folder], truth)
    place = np.asarray(outcome.outcomes[folder].summary["motion"]["still"]["place"])[:2]
    assert row["error_m"] == pytest.approx(np.linalg.norm(place - sim.positions[AT[1]] - [30.0, 0.0]))
    assert row["nees"] > beyond() and row["beyond_sigma"]
    scored = outcome.summary["reference_tags"] | {"tags": [row]}
    warnings = [line for line, warning in reference_lines(scored) if warning]
    assert len(warnings) == 1 and f"reference tag {refs[1]} is {row['error_m']:.3g} m from" in warnings[0]


def test_a_reference_tag_tracked_as_moving_is_scored_row_by_row():
    """A track's rows not flagged: the median of their errors, the mean of their NEES on sigma_x, sigma_y."""
    track = pd.DataFrame({"x": [1.0, 2.0, -1.0, 50.0], "y": [0.0, 1.0, 0.5, 50.0], "sigma_x": [1.0, 2.0, 1.0, 1.0],
                          "sigma_y": [1.0, 1.0, 0.5, 1.0], "quality": ["ok", "ok", "ok", "flagged"]})
    outcome = SimpleNamespace(track=track, summary={"motion": {"model": "random walk"}},
                              estimates=pd.DataFrame({"estimator": ["fix"], "x": [3.0], "y": [4.0]}))
    truth = {"truth": "t", "receiver": "", "xyz": np.array([0.0, 0.0, np.nan]), "lat": 0.0, "lon": 0.0,
             "survey": 1.0, "in_sync": False}
    row = score_reference("A", outcome, truth)
    ok = track.iloc[:3]
    d = ok[["x", "y"]].to_numpy()
    var = ok[["sigma_x", "sigma_y"]].to_numpy() ** 2 + 1.0
    assert row["error_m"] == pytest.approx(np.median(np.hypot(d[:, 0], d[:, 1])))
    assert row["nees"] == pytest.approx(np.mean((d**2 / var).sum(axis=1)))
    assert (row["rows"], row["flagged"], row["single_fix_median_error_m"]) == (4, 1, 5.0)


def test_the_sheets_surveyed_position_is_read_as_a_hostile_cell(tmp_path):
    sheet = tmp_path / "tags.csv"
    sheet.write_text("transmitter,role,lat,lon,depth_m,survey_sigma_m,station\n1,reference,60.5,5.25,3,0.4,\n"
                     "2,reference,NA,NA,,,ST01\n")
    first, second = read_tag_sheet(sheet).tags
    assert (first.lat, first.lon, first.depth, first.survey_sigma, first.receiver) == (60.5, 5.25, 3.0, 0.4, "")
    assert np.isnan(second.lat) and second.receiver == "ST01"
    for body, said in (("1,reference,60.5,,,,\n", "line 2: a surveyed position needs both lat and lon"),
                       ("1,reference,95,5,,,\n", "line 2 column lat: '95' is not allowed"),
                       ("1,reference,60,5,,-1,\n", "line 2 column survey_sigma_m: '-1' is not allowed")):
        sheet.write_text("transmitter,role,lat,lon,depth_m,survey_sigma_m,station\n" + body)
        with pytest.raises(ModelError, match=said):
            read_tag_sheet(sheet)


#: The survey error stated for the study (``--survey-sigma`` without the refinement) [m per axis].
STATED = 2.0


@pytest.mark.slow
def test_a_stated_survey_error_is_in_every_sigma(study):
    """The same study with the receivers' survey error stated (``survey_sigma`` without ``refine_positions``): the
    reference tags at a deployment take it as their position's error, the one with its own (the sheet's) keeps it,
    each NEES against a scoring made here with it (at a deployment, less the place's covariance with that receiver's
    survey error, from the place's gains: one error, counted once); each still tag's covariance holds the receivers'
    survey term (larger than without it in every direction); the sync tags left out are the same fixes with the
    stated error in their NEES (errors unchanged, NEES lower, ``survey_sigma_m`` said)."""
    sim, refs, plain, out = study
    folder = out.parent
    outcome = run_study(folder / "in" / "detections.csv", folder / "in" / "deployments.csv", folder / "in" / "tags.csv",
                        workdir=folder / "stated", chosen=refs, workers=1, survey_sigma=STATED)
    write_study(outcome, folder / "stated")
    scored = _read(folder / "stated", "reference_tags.csv")
    before = _read(out, "reference_tags.csv")
    left, before = (t[t["kind"] == "sync_left_out"].set_index("tag") for t in (scored, before))
    scored = scored[scored["kind"] == "reference"].set_index("tag")
    tags = _read(folder / "stated", "tags.csv").set_index("tag")
    tracks = _read(folder / "stated", "tracks.csv")
    for k, tag in enumerate(refs):
        summary = json.loads((folder / "stated" / tags.loc[tag, "folder"] / "summary.json").read_text())
        still = summary["motion"]
        place = tracks.loc[tracks["tag"] == tag, ["x", "y"]].to_numpy(float)[0]  # a still tag: one place
        survey = SURVEY if k == 0 else STATED
        P = np.asarray(still["still"]["covariance"], float)[:2, :2]
        e = place - sim.positions[AT[k]][:2]
        # at a deployment, one survey error moved the place and is the position's: their covariance taken out
        at = summary["receivers"].index(scored.loc[tag, "receiver"]) if k else None
        X = 0.0 if at is None else STATED * survey * np.asarray(still["still"]["survey_gains"], float)[at, :2]
        assert scored.loc[tag, "survey_sigma_m"] == survey
        C = P + survey**2 * np.eye(2) - X - np.transpose(X)
        assert scored.loc[tag, "nees"] == pytest.approx(e @ np.linalg.solve(C, e), rel=1e-3, abs=1e-6)
        plain_still = json.loads((out / _read(out, "tags.csv").set_index("tag").loc[tag, "folder"] /
                                  "summary.json").read_text())["motion"]["still"]
        grown = P - np.asarray(plain_still["covariance"], float)[:2, :2]
        assert np.linalg.eigvalsh(grown).min() > 0, (tag, grown)  # the survey's consider term
        assert "survey" in still["consider_terms"]
    assert len(left) and (left["survey_sigma_m"] == STATED).all()
    assert np.allclose(left["error_m"], before.loc[left.index, "error_m"])
    assert (left["nees"] < before.loc[left.index, "nees"]).all()
    assert outcome.summary["reference_tags"]["reference"]["nees_mean"] == pytest.approx(
        scored.loc[refs, "nees"].mean())


@pytest.mark.slow
def test_the_survey_error_the_synchronisation_sees_is_taken_where_none_is_stated(tmp_path):
    """A study whose deployments are each off by N(0, 2 m) per axis and which states no survey error: its
    synchronisation sees one in its residuals and takes it (``clocks.survey_sigma_from`` ``"seen"``), so the study
    is the one made with that error stated (``reference_tags.csv`` and ``tracks.csv`` the same), and differs from
    the study with ``survey_sigma=0`` (the positions taken as exact: the tracks' places the same, their σ smaller,
    no survey term); given that synchronisation as a folder (``sync``), the study takes the error it took."""
    sim = simulate_study(n_receivers=9, n_tags=1, days=0.25, redeployed=0, seed=4)
    files = sim.write(tmp_path / "in", "vue")
    off = sim.positions[:, :2] + 2.0 * np.random.default_rng(11).normal(size=(len(sim.positions), 2))
    deployments, sheet, refs = sim.with_reference_tags(AT[:1], off)
    deployments.to_csv(files["deployments"], index=False, float_format="%.10f")
    sheet.to_csv(files["tags"], index=False)
    chosen = refs + [t for t in sim.sheet["transmitter"] if t not in set(sim.deployments["transmitter"])]
    found = {}
    for label, survey in (("default", None), ("exact", 0.0)):
        found[label] = run_study(files["detections"], files["deployments"], files["tags"], workdir=tmp_path / label,
                                 chosen=chosen, workers=1, survey_sigma=survey)
        write_study(found[label], tmp_path / label)
    clocks = found["default"].summary["clocks"]
    assert clocks["survey_error"]["seen"] and clocks["survey_sigma_from"] == "seen"
    seen = clocks["survey_sigma_m"]
    assert seen == clocks["survey_error"]["survey_sigma_m"] and 1.0 <= seen <= 3.5
    assert found["exact"].summary["clocks"]["survey_sigma_from"] == "stated"
    stated = run_study(files["detections"], files["deployments"], files["tags"], workdir=tmp_path / "stated",
                       chosen=chosen, workers=1, survey_sigma=seen)
    write_study(stated, tmp_path / "stated")
    for name in ("reference_tags.csv", "tracks.csv"):
        pd.testing.assert_frame_equal(_read(tmp_path / "default", name), _read(tmp_path / "stated", name))
    taken, exact = (_read(tmp_path / label, "tracks.csv") for label in ("default", "exact"))
    assert np.allclose(taken[["x", "y"]], exact[["x", "y"]])
    assert (taken["sigma_x"] ** 2 + taken["sigma_y"] ** 2 > exact["sigma_x"] ** 2 + exact["sigma_y"] ** 2).all()
    scored = _read(tmp_path / "default", "reference_tags.csv").set_index("tag")
    assert scored.loc[refs[0], "survey_sigma_m"] == pytest.approx(seen)
    assert np.isnan(_read(tmp_path / "exact", "reference_tags.csv").set_index("tag").loc[refs[0], "survey_sigma_m"])
    tags = _read(tmp_path / "exact", "tags.csv").set_index("tag")
    summary = json.loads((tmp_path / "exact" / tags.loc[refs[0], "folder"] / "summary.json").read_text())
    assert "survey" not in summary["motion"]["consider_terms"]
    # given the default study's synchronisation as a folder (--sync DIR): the error it took, taken again
    given = run_study(files["detections"], files["deployments"], files["tags"], workdir=tmp_path / "given",
                      sync=tmp_path / "default" / "sync", chosen=chosen, workers=1)
    assert given.summary["clocks"]["survey_sigma_from"] == "seen" and given.summary["clocks"]["survey_sigma_m"] == seen
    write_study(given, tmp_path / "given")
    pd.testing.assert_frame_equal(_read(tmp_path / "given", "tracks.csv"), taken)


#: The survey's error put into the deployments of the moving tags' test [m per horizontal axis].
OFF = 2.0


def _nees(study, sim) -> np.ndarray:
    """Every tracked row's 2-D NEES against the tag's true path read on the reference receiver's clock."""
    names = study.deployments.table["receiver"].astype(str).tolist()
    k = names.index(study.summary["clocks"]["reference_receiver"])  # the simulation's order: none redeployed
    found = []
    for tag in study.tags.itertuples():
        assert tag.status == "tracked", tag.reason
        rows = study.tracks[study.tracks["tag"] == tag.tag]
        error = rows[["x", "y"]].to_numpy() - sim.truth_at(tag.tag, rows["epoch_s"], k)
        found.append(np.sum((error / rows[["sigma_x", "sigma_y"]].to_numpy()) ** 2, axis=1))
    return np.concatenate(found)


@pytest.mark.slow
def test_the_survey_error_seen_makes_the_moving_tags_nees_consistent(tmp_path):
    """Where the receivers' positions are off, the survey error the synchronisation sees, taken (the default where
    none is stated), makes the moving tags' NEES against their truth a consistent one's, where with the positions
    taken as exact (``survey_sigma=0``) it is not (benchmarks/bench_survey_tracks.py runs 20 arrays)."""
    taken, exact, seen = [], [], []
    for seed in range(1, 5):
        sim = simulate_study(n_receivers=9, n_tags=4, days=0.25, redeployed=0, seed=seed)
        files = sim.write(tmp_path / f"{seed}", "vue")
        off = sim.positions[:, :2] + OFF * np.random.default_rng(100 + seed).normal(size=(len(sim.positions), 2))
        lat, lon = sim.frame.to_latlon(off[:, 0], off[:, 1])
        sim.deployments.assign(deploy_lat=lat, deploy_long=lon).to_csv(files["deployments"], index=False,
                                                                       float_format="%.10f")
        animals = [t for t in sim.sheet["transmitter"] if t not in set(sim.deployments["transmitter"])]
        for found, survey in ((taken, None), (exact, 0.0)):
            study = run_study(files["detections"], files["deployments"], files["tags"], chosen=animals, workers=1,
                              workdir=tmp_path / f"{seed}-{survey}", survey_sigma=survey)
            found.append(_nees(study, sim))
            if survey is None:
                clocks = study.summary["clocks"]
                assert clocks["survey_sigma_from"] == "seen"
                seen.append(clocks["survey_sigma_m"])
    taken, exact = np.mean(np.concatenate(taken)), np.mean(np.concatenate(exact))
    print(f"moving tags' NEES on positions off by {OFF} m: {taken:.2f} with the survey error seen taken "
          f"({', '.join(f'{s:.2f}' for s in seen)} m), {exact:.2f} with the positions taken as exact")
    assert 0.5 * OFF < np.sqrt(np.mean(np.square(seen))) < 1.5 * OFF
    assert 1.0 <= taken <= 3.5  # a consistent σ: 2
    assert exact > 2.0 * taken

#: The survey error put into every deployment of the Monte Carlo and stated to its studies [m per horizontal axis].
TRUTH_SURVEY = 2.0
#: The Monte Carlo's arrays, each with three reference tags (benchmarks/bench_reference_tags.py runs more).
ARRAYS = 12


def _truth_array(seed: int, folder) -> list[tuple[float, float]]:
    """One study of 16 receivers on positions off by :data:`TRUTH_SURVEY`: each reference tag's NEES as scored and of
    its place against its true position on the place's covariance alone."""
    sim = simulate_study(n_receivers=16, n_tags=0, days=0.25, redeployed=0, seed=seed)
    files = sim.write(folder / "in", "vue")
    rng = np.random.default_rng(100 + seed)
    off = sim.positions[:, :2] + TRUTH_SURVEY * rng.normal(size=(len(sim.positions), 2))
    at = np.sort(rng.choice(len(sim.deployments), 3, replace=False))
    deployments, sheet, references = sim.with_reference_tags(at, off)
    deployments.to_csv(files["deployments"], index=False, float_format="%.10f")
    sheet.to_csv(files["tags"], index=False)
    outcome = run_study(files["detections"], files["deployments"], files["tags"], workdir=folder / "work",
                        chosen=references, workers=1, survey_sigma=TRUTH_SURVEY)
    write_study(outcome, folder / "out")
    scored = pd.read_csv(folder / "out" / "reference_tags.csv", dtype={"tag": str}).set_index("tag")
    tags = pd.read_csv(folder / "out" / "tags.csv", dtype={"tag": str}).set_index("tag")
    tracks = pd.read_csv(folder / "out" / "tracks.csv", dtype={"tag": str})
    found = []
    for tag, k in zip(references, at):
        assert scored.loc[tag, "kind"] == "reference" and scored.loc[tag, "survey_sigma_m"] == TRUTH_SURVEY
        still = json.loads((folder / "out" / tags.loc[tag, "folder"] / "summary.json").read_text())["motion"]
        P = np.asarray(still["still"]["covariance"], float)[:2, :2]
        e = tracks.loc[tracks["tag"] == tag, ["x", "y"]].to_numpy(float)[0] - sim.positions[k, :2]
        found.append((float(scored.loc[tag, "nees"]), float(e @ np.linalg.solve(P, e))))
    return found


@pytest.mark.slow
def test_the_reference_tags_score_holds_where_the_positions_are_off(tmp_path):
    """The reference tags' score confirmed by a Monte Carlo (issue 97, item 3): over 12 arrays (36 reference
    tags at receivers 2 m off per axis, that error stated), the mean NEES as scored lies within χ²(72)/36's 99 %
    interval, and that of the places against their true positions no higher and at least 1 (the issue's [1, 3];
    their covariance holds the receivers' jackknife beside the survey's term, on the large side: docs/telemetry.md)."""
    found = np.array([row for seed in range(1, ARRAYS + 1) for row in _truth_array(seed, tmp_path / str(seed))])
    n = len(found)
    low, high = chi2.ppf(0.005, 2 * n) / n, chi2.ppf(0.995, 2 * n) / n
    scored, truth = found.mean(axis=0)
    print(f"{n} reference tags: NEES {scored:.2f} as scored, {truth:.2f} against the truth "
          f"(99 % of consistent studies: {low:.2f} to {high:.2f})")
    assert low <= scored <= high
    assert 1.0 <= truth <= high
