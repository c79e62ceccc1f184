"""``sblsim track --refine-positions`` (orchestrator/telemetry/study_positions.py): the sync tags' emissions as the
refinement takes them, the verdict that keeps the first positions where the reference or left-out sync tags are worse,
the console's lines and the options' refusals (fast); on a simulated study whose deployments are 1-5 m off (slow):
the tracks' RMS error against the simulated truth back within 1.1 x the true positions', an array surveyed right
left as it is, and with a measured sound speed the array's scale found too."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.sync.identifiability import SURVEY_SIGMA
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study_options import survey_sigma_argument
from sblsim.orchestrator.telemetry.study_positions import StudyRefinement, lines, position_sigmas, sync_pings, verdict
from tests.helpers import check_tag_rows, gauge_free, shape_rms


def test_the_sync_tags_emissions_are_their_arrivals_from_their_receiver():
    """Against a matrix built here: each (tag, emission) a row, each kept arrival in its receiver's column on the
    earliest's origin, the row's receiver the tag's deployment; an arrival not kept, a tag at no receiver and a
    receiver outside the names left out."""
    residuals = pd.DataFrame({
        "receiver": ["A", "B", "C", "A", "C", "B", "Z"],
        "tag": ["S1", "S1", "S1", "S2", "S2", "S9", "S1"],
        "emission": [1, 1, 1, 1, 1, 4, 1],
        "time_sync": [100.0, 100.2, 100.3, 200.0, 200.1, 300.0, 100.5],
        "kept": [True, True, False, True, True, True, True]})
    hydrophones = pd.DataFrame({"receiver": ["A", "B", "C"], "sync_tag": ["S1", "S2", ""]})
    toa, source, times = sync_pings(residuals, hydrophones, ["A", "B", "C"])
    expected = np.array([[0.0, 0.2, np.nan], [100.0, np.nan, 100.1]])
    assert np.allclose(toa, expected, equal_nan=True) and source.tolist() == [0, 1]
    assert times.tolist() == [100.0, 200.0]  # each emission's first kept arrival
    assert sync_pings(residuals.iloc[:0], hydrophones, ["A", "B", "C"]) is None


def _refinement() -> StudyRefinement:
    positions = pd.DataFrame({"receiver": ["A", "B"], "x": [1.0, 12.0], "y": [0.0, 0.0], "survey_x": [0.0, 10.0],
                              "survey_y": [0.0, 0.0], "shift_x": [1.0, 2.0], "shift_y": [0.0, 0.0],
                              "shift_m": [1.0, 2.0], "source": ["moving tags' pings"] * 2, "sigma_x": [0.1, 0.1],
                              "sigma_y": [0.1, 0.1], "refined": [True, True], "reason": ["", ""]})
    summary = {"refined": 2, "receivers": 2, "tags": ["T1"], "pings": 1234, "survey_sigma_m": 3.0,
               "median_shift_m": 1.5, "largest_shift_m": 2.0, "largest_shift_receiver": "B",
               "held_out": {"survey_chi2_per_dof": 40.0, "refined_chi2_per_dof": 1.1, "helps": True}}
    return StudyRefinement(positions, summary)


def test_a_refinement_worse_on_the_reference_tags_is_not_kept():
    """The reference tags' median error 10 % worse (beyond the 5 % allowed): not kept, positions.csv back at the
    surveyed positions; 3 % worse, or better: kept."""
    worse = _refinement()
    assert not verdict(worse, {"reference": {"median_error_m": 1.0}}, {"reference": {"median_error_m": 1.1}})
    p = worse.positions
    assert p["x"].tolist() == [0.0, 10.0] and (p["source"] == "survey").all()
    assert not p["refined"].any() and p["shift_m"].tolist() == [0.0, 0.0]
    assert worse.summary["worse"] == ["reference"] and not worse.summary["kept"]
    for after in (1.03, 0.4):
        kept = _refinement()
        assert verdict(kept, {"reference": {"median_error_m": 1.0}, "sync_left_out": {"median_error_m": 0.5}},
                       {"reference": {"median_error_m": after}, "sync_left_out": {"median_error_m": 0.5}})
        assert kept.positions["x"].tolist() == [1.0, 12.0]


def test_the_console_says_what_was_refined_and_what_was_kept():
    kept = _refinement()
    verdict(kept, {"reference": {"median_error_m": 1.0}}, {"reference": {"median_error_m": 0.5}})
    said = lines(kept.summary)
    assert said[0] == ("positions: 2 of 2 receivers refined from 1 moving tags' 1,234 pings (survey sigma 3 m), "
                       "median shift 1.50 m, largest 2.00 m (B)", False)
    assert ("  reference tags' median error: 1.00 m before the refinement, 0.50 m after", False) in said
    assert not any(warning for _, warning in said)
    worse = _refinement()
    verdict(worse, {"reference": {"median_error_m": 1.0}}, {"reference": {"median_error_m": 2.0}})
    said = lines(worse.summary)
    assert said[0][0].startswith("positions: 2 of 2 receivers the pings would move")
    assert said[-1][1] and "the reference tags' errors are worse on it" in said[-1][0]
    assert lines({"kept": False, "reason": "no moving tag"}) == [("warning: positions not refined: no moving tag",
                                                                   True)]


def test_each_positions_error_is_its_shape_sigma_or_the_surveys():
    """A receiver refined: the survey σ times its sigma_ratio; one held at the survey: the survey σ."""
    positions = pd.DataFrame({"receiver": ["A", "B", "C"], "refined": [True, False, True],
                              "sigma_ratio": [0.1, 0.7, 0.25]})
    assert position_sigmas(positions, 3.0) == pytest.approx({"A": 0.3, "B": 3.0, "C": 0.75})


def test_a_kept_refinement_is_its_synchronisations_positions_as_sblsim_sync_writes_them(tmp_path):
    """The study's ``sync/positions.csv``: the refined positions and each one's error, read back by the readers
    ``sblsim toa`` and a study given the folder use (a receiver held at the survey: its position and the survey σ)."""
    from sblsim.orchestrator.sync.clocks import read_positions
    from sblsim.orchestrator.sync.taken_survey import folder_position_sigmas
    from sblsim.orchestrator.telemetry.study_positions import sync_positions

    positions = pd.DataFrame({"receiver": ["A", "B"], "x": [10.5, 20.0], "y": [1.25, 2.0], "survey_x": [10.0, 20.0],
                              "survey_y": [1.0, 2.0], "refined": [True, False], "sigma_ratio": [0.1, 0.7]})
    sync_positions(positions, 3.0).to_csv(tmp_path / "positions.csv", index=False)
    assert read_positions(tmp_path) == {"A": (10.5, 1.25), "B": (20.0, 2.0)}
    assert folder_position_sigmas(tmp_path, ["A", "B"]) == pytest.approx({"A": 0.3, "B": 3.0})


def test_the_survey_sigma_is_the_prior_or_the_stated_error():
    """With the refinement the survey σ is its prior (3 m unless given, above 0); without, the survey's stated error
    (None unless given: the error the synchronisation sees, else exact; 0: exact), in range or refused."""
    assert survey_sigma_argument(None, True, "--survey-sigma") == SURVEY_SIGMA
    assert survey_sigma_argument(None, False, "--survey-sigma") is None
    assert survey_sigma_argument(1.5, False, "--survey-sigma") == 1.5 == survey_sigma_argument(1.5, True, "s")
    assert survey_sigma_argument(0.0, False, "--survey-sigma") == 0.0
    with pytest.raises(Exception, match="--survey-sigma: 0.0 is outside"):
        survey_sigma_argument(0.0, True, "--survey-sigma")
    with pytest.raises(Exception, match="--survey-sigma: -0.5 is outside"):
        survey_sigma_argument(-0.5, False, "--survey-sigma")


@pytest.mark.parametrize("extra,message", [
    (["--survey-sigma", "2000"], "--survey-sigma: 2000.0 is outside the allowed range"),
    (["--refine-positions", "--survey-sigma", "0"], "--survey-sigma"),
])
def test_the_survey_sigma_is_refused_in_one_line(tmp_path, capsys, extra, message):
    (tmp_path / "d.csv").write_text("epo,frac,tag,serial\n")
    (tmp_path / "r.csv").write_text("serial,sync_tag,x_m,y_m\n")
    code = main(["track", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "r.csv"), *extra, "--out",
                 str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0] and not (tmp_path / "out").exists(), err


def test_the_refinement_with_a_given_synchronisation_is_refused_before_any_work(tmp_path, capsys):
    """``--refine-positions`` synchronises the clocks again round by round; a folder given as ``--sync`` fixes them
    (and its refined positions stood in place of the study's: a refined study kept on the folder's positions, its
    tracks' NEES 37 on a simulated array where the refinement alone gives 1.7). Refused in one line, exit 2, nothing
    written; from Python a ConfigError."""
    (tmp_path / "d.csv").write_text("epo,frac,tag,serial\n")
    (tmp_path / "r.csv").write_text("serial,sync_tag,x_m,y_m\n")
    (tmp_path / "sync").mkdir()
    code = main(["track", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "r.csv"), "--sync",
                 str(tmp_path / "sync"), "--refine-positions", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--refine-positions: not with --sync" in err[0], err
    assert not (tmp_path / "out").exists()
    with pytest.raises(sblsim.ConfigError, match="not with --sync"):
        sblsim.track(tmp_path / "d.csv", receivers=tmp_path / "r.csv", sync=tmp_path / "sync",
                     refine_positions=True, out=tmp_path / "api")
    assert not (tmp_path / "api").exists()


# --------------------------------------------------------------------------- a simulated study, positions off


def _written_off(sim, folder, seed: int):
    """``sim``'s files written into ``folder``/in, and its deployments 1-5 m off (each receiver in a random direction
    drawn from ``seed``; the errors' translation, rotation and scale taken out: what no time of arrival sees where
    the sound speed is calibrated, the survey's) into ``folder``/off: the files, the true positions and the errors."""
    files = sim.write(folder / "in", "vue")
    sheet = pd.read_csv(files["deployments"])
    x, y = sim.frame.from_latlon(sheet["deploy_lat"].to_numpy(), sheet["deploy_long"].to_numpy())
    true = np.c_[x, y]
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=true.shape)
    errors = rng.uniform(1.0, 5.0, len(true))[:, None] * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    errors = gauge_free(errors, true, scale=True)
    lat, lon = sim.frame.to_latlon(true[:, 0] + errors[:, 0], true[:, 1] + errors[:, 1])
    (folder / "off").mkdir()
    sheet.assign(deploy_lat=lat, deploy_long=lon).to_csv(folder / "off" / "deployments.csv", index=False)
    return files, true, errors


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A simulated study (9 receivers each with its sync tag, 3 animals, 6 hours), its deployments as surveyed right
    and 1-5 m off (each receiver in a random direction; the errors' translation, rotation and scale taken out: what
    no time of arrival sees where the sound speed is calibrated, the survey's), and the study on each."""
    folder = tmp_path_factory.mktemp("positions")
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.25, redeployed=0, seed=4)
    files, true, errors = _written_off(sim, folder, 104)
    runs = {}
    for name, receivers, refine in (("right", files["deployments"], False), ("off", folder / "off" /
                                                                             "deployments.csv", False),
                                    ("off refined", folder / "off" / "deployments.csv", True),
                                    ("right refined", files["deployments"], True)):
        # written (positions.csv, the report) where refined; the others, only compared, stay in memory
        out = folder / name.replace(" ", "_") if refine else None
        runs[name] = sblsim.track(files["detections"], receivers=receivers, tags=files["tags"], workers=2,
                                  refine_positions=refine, out=out)
        check_tag_rows(runs[name].tags, runs[name].tracks, [str(p) for p in files.values()])
    return sim, true, errors, runs, folder


def _errors(sim, result) -> tuple[np.ndarray, np.ndarray]:
    """The tracks' rows not flagged against the simulated truth (on the reference receiver's clock, which the
    synchronisation takes as UTC): their errors (n, 2) [m] and their ``sigma_x``, ``sigma_y`` (n, 2) [m]."""
    reference = result.summary["clocks"]["reference_receiver"]
    k = int(np.flatnonzero(result.receivers["receiver"].to_numpy() == reference)[0])
    errors, sigmas = [], []
    for tag, rows in result.tracks.groupby("tag"):
        ok = (rows["quality"] == "ok").to_numpy()
        errors.append(rows[["x", "y"]].to_numpy()[ok] - sim.truth_at(tag, rows["epoch_s"].to_numpy()[ok], k))
        sigmas.append(rows[["sigma_x", "sigma_y"]].to_numpy()[ok])
    return np.concatenate(errors), np.concatenate(sigmas)


def _rms(sim, result) -> float:
    """The tracks' 2-D RMS error [m] against the simulated truth over their rows not flagged."""
    errors, _ = _errors(sim, result)
    return float(np.sqrt(np.mean(np.sum(errors ** 2, axis=1))))


def _nees(sim, result) -> float:
    """The tracks' mean 2-D NEES against the simulated truth over their rows not flagged, on each row's
    ``sigma_x``, ``sigma_y``."""
    errors, sigmas = _errors(sim, result)
    return float(np.mean(np.sum((errors / sigmas) ** 2, axis=1)))


@pytest.mark.slow
def test_the_tracks_come_back_to_the_true_positions_accuracy(simulated):
    """Positions 1-5 m off: the tracks' RMS error several times the true positions'; refined from the study's own
    pings, within 1.1 x, the refined positions within 0.2 m of the truth in the array's shape, the sync tags left out
    no worse, ``positions.csv`` written with every receiver refined."""
    sim, true, _, runs, folder = simulated
    right, off, refined = (_rms(sim, runs[k]) for k in ("right", "off", "off refined"))
    assert off > 3 * right and refined <= 1.1 * right, (right, off, refined)
    summary = runs["off refined"].summary["positions"]
    assert summary["kept"] and summary["refined"] == 9 and summary["held_out"]["helps"], summary
    positions = pd.read_csv(folder / "off_refined" / "positions.csv", dtype={"receiver": str})
    order = [str(s) for s in pd.read_csv(folder / "in" / "deployments.csv")["ins_serial_no"]]
    at = positions.set_index("receiver").loc[order, ["x", "y"]].to_numpy()
    shape = shape_rms(at - true, true, scale=True)
    assert shape < 0.2 and positions["refined"].all(), (shape, positions)
    # the study's sync/ folder, its clocks made on the refined positions, has them and their errors too
    given = pd.read_csv(folder / "off_refined" / "sync" / "positions.csv", dtype={"serial": str}).set_index("serial")
    np.testing.assert_allclose(given.loc[order, ["x_m", "y_m"]].to_numpy(), at)
    np.testing.assert_allclose(given.loc[order, "position_sigma_m"],
                               positions.set_index("receiver").loc[order, "sigma_ratio"] * summary["survey_sigma_m"])
    checks = summary["checks"]["sync_left_out"]
    assert checks["refined_m"] <= 1.05 * checks["survey_m"], checks


@pytest.mark.slow
def test_an_array_surveyed_right_is_left_as_it_is(simulated):
    """The true positions: the held-out pings fit no better, nothing refined, the tracks as without the option."""
    sim, _, _, runs, folder = simulated
    summary = runs["right refined"].summary["positions"]
    assert not summary["kept"] and summary["refined"] == 0, summary
    assert _rms(sim, runs["right refined"]) <= 1.02 * _rms(sim, runs["right"])
    assert not pd.read_csv(folder / "right_refined" / "positions.csv")["refined"].any()
    assert not (folder / "right_refined" / "sync" / "positions.csv").exists()  # its clocks made on the survey's


@pytest.mark.slow
def test_with_a_measured_sound_speed_the_arrays_scale_is_found_too(simulated, tmp_path):
    """The same errors with a 0.5 % dilation of the whole array added (a tape's), the sound speed given as the
    simulation's: the pings tell the scale, and the tracks come back within 1.1 x the true positions' (the same
    given speed)."""
    sim, true, errors, _, folder = simulated
    centre = true.mean(axis=0)
    scaled = true + errors + 0.005 * (true - centre)
    sheet = pd.read_csv(folder / "in" / "deployments.csv")
    lat, lon = sim.frame.to_latlon(scaled[:, 0], scaled[:, 1])
    sheet.assign(deploy_lat=lat, deploy_long=lon).to_csv(tmp_path / "deployments.csv", index=False)
    given = {"sound_speed": 1480.0, "workers": 2}
    right = sblsim.track(folder / "in" / "detections.csv", receivers=folder / "in" / "deployments.csv",
                         tags=folder / "in" / "tags.csv", **given)
    refined = sblsim.track(folder / "in" / "detections.csv", receivers=tmp_path / "deployments.csv",
                           tags=folder / "in" / "tags.csv", refine_positions=True, **given)
    assert _rms(sim, refined) <= 1.1 * _rms(sim, right), (_rms(sim, refined), _rms(sim, right))
    assert not refined.summary["positions"]["sound_speed"]["fitted"]


@pytest.mark.slow
def test_a_study_given_a_refined_synchronisation_takes_each_positions_error(simulated, tmp_path):
    """``sblsim sync --refine-positions`` on the positions 1-5 m off, the sound speed fitted with them, given to the
    study as ``--sync``: each receiver's ``position_sigma_m`` in the study's clocks and in every tag's
    ``receivers.csv`` (``sigma_m``), and the tracks' NEES against the truth a consistent one's (the array's scale,
    which the speed takes up, left out of the σ: with it, 0.08 when written)."""
    sim, _, _, _, folder = simulated
    given = folder / "in"
    sblsim.sync(given / "detections.csv", receivers=folder / "off" / "deployments.csv", refine_positions=True,
                out=tmp_path / "sync")
    positions = pd.read_csv(tmp_path / "sync" / "positions.csv", dtype={"serial": str})
    assert positions["refined"].all() and positions["position_sigma_m"].max() < 0.5, positions
    study = sblsim.track(given / "detections.csv", receivers=folder / "off" / "deployments.csv",
                         tags=given / "tags.csv", sync=tmp_path / "sync", workers=2, out=tmp_path / "study")
    expected = dict(zip(positions["serial"], positions["position_sigma_m"]))
    assert study.summary["clocks"]["position_sigma_m"] == pytest.approx(expected)
    matrices = sorted((tmp_path / "study" / "tags").glob("*/receivers.csv"))
    assert matrices
    for path in matrices:
        table = pd.read_csv(path, dtype={"name": str})
        np.testing.assert_allclose(table["sigma_m"], [expected[n] for n in table["name"]], atol=1e-4)
    assert 1.0 <= _nees(sim, study) <= 4.5, _nees(sim, study)


@pytest.mark.slow
def test_with_few_sync_tags_the_clocks_offsets_are_fitted_bin_by_bin(tmp_path):
    """Sixteen receivers, three with a sync tag, 1-5 m off (seed 4): synchronised on the surveyed positions each
    receiver's clock error changes from bin to bin with the sync tags it hears. Refined with the offsets at the bins'
    edges, the tracks come within 2.5 x the true positions' RMS (2.05 x when written; 4.9 x with one constant offset
    per clock, the refinement before), and the study says the knots it fitted."""
    sim = simulate_study(n_receivers=16, n_tags=2, days=0.25, redeployed=0, seed=4)
    keep = {sim.deployments["transmitter"][k] for k in np.random.default_rng(104).choice(16, size=3, replace=False)}
    dropped = [t for t in sim.deployments["transmitter"] if t not in keep]
    sim.deployments = sim.deployments.assign(transmitter=[t if t in keep else ""
                                                          for t in sim.deployments["transmitter"]])
    sim.detections = sim.detections[~sim.detections["transmitter"].isin(dropped)].reset_index(drop=True)
    files, _, _ = _written_off(sim, tmp_path, 1004)
    right = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=2)
    refined = sblsim.track(files["detections"], receivers=tmp_path / "off" / "deployments.csv", tags=files["tags"],
                           workers=2, refine_positions=True)
    summary = refined.summary["positions"]
    assert summary["kept"] and summary["clock_offset_knots"] == 7, summary
    assert _rms(sim, refined) <= 2.5 * _rms(sim, right), (_rms(sim, refined), _rms(sim, right))
    # the refined positions' own errors in the tracks' σ, correlated as the refinement made them: their NEES a
    # consistent one's (10.3 without them, 4.15 with each receiver's σ alone)
    moving = [o for o in refined.tracked.values() if o.summary["motion"]["model"] == "moving"]
    assert moving and all(o.summary["survey_correlated"] for o in moving)
    assert 1.0 <= _nees(sim, refined) <= 4.5 and 1.0 <= _nees(sim, right) <= 3.0, (_nees(sim, refined),
                                                                                    _nees(sim, right))


def test_the_survey_error_a_study_takes():
    """The stated error wins (0: none, the positions exact); else, without the refinement, a given folder's refined
    positions' errors or the error the synchronisation saw and took; else none."""
    from sblsim.orchestrator.telemetry.study_clocks import taken_survey

    seen = {"survey_sigma_m": 2.39, "survey_sigma_from": "seen"}
    assert taken_survey(None, False, seen) == 2.39
    assert taken_survey(1.5, False, seen) == 1.5 and taken_survey(0.0, False, seen) is None
    assert taken_survey(None, True, seen) is None  # the refinement's prior is the survey's
    assert taken_survey(None, False, {"survey_sigma_m": 1.0, "survey_sigma_from": "stated"}) is None
    assert taken_survey(None, False, {"source": "given"}) is None  # clocks from a folder: nothing seen here
    each = {"A": 0.3, "B": 3.0}  # a folder's refined positions: each one's error, unless one is stated
    assert taken_survey(None, False, {"source": "given", "position_sigma_m": each}) == each
    assert taken_survey(1.5, False, {"source": "given", "position_sigma_m": each}) == 1.5
