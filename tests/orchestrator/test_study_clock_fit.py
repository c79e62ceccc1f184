"""Clocks taken as logged, fitted from the moving tags' own pings (orchestrator/telemetry/study_offsets.py): a study
whose sync tags nobody hears, or whose deployments name none, on clocks off by tens of milliseconds was tracked with
every fix tens of metres off and a σ of one or two (the clocks' error in no σ); its clocks are now fitted from its
animals' pings where the pings left out say they help, and clocks that are right are checked and left as logged."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models.tracking.timing import SIGMA_TOA
from sblsim.orchestrator.telemetry.simulate import simulate_study

DATA = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


def _study(tmp_path, offset: float, drift: float, unheard: bool, depths: bool = False, receivers: int = 9,
           moved: float = 0.0, days: float = 0.25, wander: float = 0.0, survey_seed: int = 99,
           away: tuple[float, float] | None = None):
    """A simulated GLATOS study (``receivers``, 3 animals, ``days``, the clocks' ``wander`` [s] about their lines)
    whose sync tags are never heard (``unheard``: their rows dropped from the detections) or never named (the
    deployments' ``transmitter`` emptied), with ``depths`` its deployments' ``instrument_depth`` (5 m: the tags' too,
    the simulation being in one plane) and ``bottom_depth`` (20 to 36 m), each deployment's position off by
    ``moved`` [m per axis, σ] (its survey's error, drawn with ``survey_seed``), the animals away between the
    hours ``away`` but for the first one's pings in five minutes at its middle, run through the CLI; the simulation,
    the study's folder and its ``study.json``."""
    from sblsim.orchestrator import cli

    sim = simulate_study(n_receivers=receivers, n_tags=3, days=days, redeployed=0, seed=5, offset=offset,
                         drift=drift, wander=wander)
    if unheard:
        sim.detections = sim.detections[~sim.detections["transmitter"].isin(sim.deployments["transmitter"])]
    if away is not None:
        hours = (sim.detections["time"] - sim.origin) / 3600.0
        inside = (hours > away[0]) & (hours < away[1])
        middle = (hours - sum(away) / 2).between(0.0, 300.0 / 3600.0)
        once = inside & middle & (sim.detections["transmitter"] == sim.sheet["transmitter"].iloc[0])
        sim.detections = sim.detections[~inside | once].reset_index(drop=True)
    files = sim.write(tmp_path / "in", "glatos")
    sheet = pd.read_csv(files["deployments"], dtype=str, keep_default_na=False)
    if not unheard:
        sheet = sheet.assign(transmitter="")
    if depths:
        sheet = sheet.assign(instrument_depth=5.0, bottom_depth=20.0 + 2.0 * np.arange(len(sheet)))
    if moved:
        north, east = np.random.default_rng(survey_seed).normal(0.0, moved, (2, len(sheet)))
        sheet["deploy_lat"] = (sheet["deploy_lat"].astype(float) + north / 111_320.0).map("{:.10f}".format)
        sheet["deploy_long"] = (sheet["deploy_long"].astype(float) + east / (
            111_320.0 * np.cos(np.radians(sheet["deploy_lat"].astype(float))))).map("{:.10f}".format)
    sheet.to_csv(files["deployments"], index=False)
    out = tmp_path / "study"
    assert cli.main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tags",
                     str(files["tags"]), "--out", str(out)]) == 0
    return sim, out, json.loads((out / "study.json").read_text())


def _errors(sim, out: object, reference: str) -> pd.DataFrame:
    """Each track row's error [m] against the simulated truth (on the reference receiver's clock) and its NEES."""
    tracks = pd.read_csv(out / "tracks.csv")
    deployment = int(np.flatnonzero(sim.clocks["serial"].astype(str) == reference)[0])
    parts = []
    for tag, rows in tracks.groupby("tag"):
        e = rows[["x", "y"]].to_numpy() - sim.truth_at(tag, rows["epoch_s"].to_numpy(), deployment)
        parts.append(pd.DataFrame({"tag": tag, "epoch_s": rows["epoch_s"].to_numpy(), "error": np.hypot(*e.T),
                                   "quality": rows["quality"].to_numpy(),
                                   "nees": (e[:, 0] / rows["sigma_x"]) ** 2 + (e[:, 1] / rows["sigma_y"]) ** 2}))
    return pd.concat(parts)


def test_clocks_off_by_tens_of_milliseconds_are_fitted_from_the_animals_pings(tmp_path, capsys):
    """Sync tags named but never heard (a network's extract of a tag project), each clock off by up to ±30 ms and
    drifting by up to 5 ppm (0.1 s over the study). Taken as logged, every fix was tens of metres off with a σ of one
    or two (NEES in the thousands). Now each clock's offset at the study's first and last detection comes back
    within 0.3 ms of the simulated clock's, less the time base's; every animal's median error is below 0.5 m and
    its rows' NEES (2-D) in [1, 4]; the study says what it did (``clocks.source``, a note, the console)."""
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    sim, out, study = _study(tmp_path, 0.03, 5e-6, unheard=True)
    clocks = study["clocks"]
    assert clocks["source"] == FITTED and clocks["receivers"] == 9 and not clocks["not_synchronised"], clocks
    reference = clocks["reference_receiver"]
    _offsets_agree(sim, clocks, 3e-4)
    assert clocks["largest_offset_s"] > 0.02  # (off by tens of milliseconds indeed)
    errors = _errors(sim, out, reference)
    for tag, rows in errors.groupby("tag"):
        assert rows["error"].median() < 0.5 and 1.0 <= rows["nees"].mean() <= 4.0, (tag, rows.describe())
    assert any(n.startswith("the receivers' clocks, taken as logged, were off: fitted from 3 moving tags'")
               for n in study["notes"]), study["notes"]
    said = capsys.readouterr()
    assert "more than the noise explains" not in said.err  # (the pings fit the clocks: no misfit said)
    assert "clocks fitted from 3 moving tags' 448 pings against" in said.out
    assert "taken as logged, no sync tag heard by two receivers, they were off by up to" in said.out
    assert "were off: fitted from 3 moving tags'" in said.out + said.err


def test_clocks_that_are_right_are_checked_and_kept_as_logged(tmp_path, capsys):
    """No sync tag named and the clocks right (synchronised already, as the note says they are taken): the pings
    left out fit clocks fitted from the others no better, so the clocks stay as logged and the study says it
    checked them (``clocks.checked``, a console line); the tracks are the clocks as logged's (0.2 m)."""
    from sblsim.orchestrator.telemetry.study_clocks import NO_SYNC_TAG

    sim, out, study = _study(tmp_path, 0.0, 0.0, unheard=False)
    clocks = study["clocks"]
    assert clocks["source"] == NO_SYNC_TAG, clocks
    held = clocks["checked"]["held_out"]
    assert not held["helps"] and held["fitted_chi2_per_dof"] > 0.95 * held["logged_chi2_per_dof"], held
    assert ("clocks taken as logged (no sync tag in the receivers file): the moving tags' pings left out fit them as "
            "well as clocks fitted from the others") in capsys.readouterr().out
    errors = _errors(sim, out, str(sim.clocks["serial"].iloc[0]))
    assert errors.groupby("tag")["error"].median().max() < 0.5


@pytest.mark.parametrize("survey_seed", [pytest.param(99, marks=pytest.mark.slow), 104])
def test_pings_the_fitted_clocks_leave_misfit_are_said_to_exceed_the_tracks_sigma(tmp_path, capsys, survey_seed):
    """The deployments' positions off by 2 m per axis (σ) and no survey error stated, clocks ±20 ms, two draws of
    the survey's error: the fit takes the clocks (the tracks a median 1-2.3 m off, as the sync tags' study of the
    same positions, 1.5-1.6 m), but their σ do not hold their error (NEES in the hundreds), and the pings left out
    misfit the clocks at the timing noise taken: said in one warning naming what to state. The second draw's
    misfit (a χ² per degree of freedom of 3.98) was under the first threshold, 4: nothing was said."""
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    sim, out, study = _study(tmp_path, 0.02, 0.0, unheard=False, moved=2.0, survey_seed=survey_seed)
    assert study["clocks"]["source"] == FITTED
    assert _errors(sim, out, study["clocks"]["reference_receiver"])["nees"].mean() > 20  # (the warning is owed)
    warning = [line for line in capsys.readouterr().err.splitlines() if "more than the noise explains" in line]
    assert len(warning) == 1 and warning[0].startswith("sblsim: warning: the moving tags' pings left out fit the "
                                                       "clocks") and "--survey-sigma M" in warning[0], warning
    assert "more than the noise explains" in (out / "report.html").read_text()  # (the page's warnings too)


def _offsets_agree(sim, clocks: dict, within: float) -> None:
    """Each fitted clock's offset at each knot (``offsets_s`` at ``knot_times_s``) within ``within`` [s] of the
    simulated clock's less the time base's (the simulation's own, :meth:`SimulatedStudy.offset`)."""
    reference = clocks["reference_receiver"]
    tau = np.array(clocks["knot_times_s"]) - sim.origin
    truth = {str(serial): sim.offset(k, tau) for k, serial in enumerate(sim.clocks["serial"])}
    for name, knots in clocks["offsets_s"].items():
        assert np.abs(np.array(knots) - (truth[name] - truth[reference])).max() < within, (name, knots, truth[name])


def test_a_clock_that_wanders_about_its_line_is_followed_a_knot_every_window(tmp_path, capsys):
    """A day, each clock off by up to ±10 ms and drifting by 0.1 ppm (within the time the sound crosses the array: no
    coarse alignment), and wandering about that line by up to ±10 ms over one to three days (a crystal's rate
    following the water's temperature). Fitted at the study's ends alone (a line), the clocks were off by up to 7 ms
    at those knots and 13 ms between them: the fixes a median 1.4 m off (RMS 3.4 m), NEES 180-280, 15 % of the rows
    flagged. A knot every :data:`WINDOW` follows it: each clock within 0.5 ms of the simulated one at every knot
    (0.37 ms), every animal's median error below 0.5 m (0.16-0.19 m) and its NEES (2-D) in [1, 4] (2.1-2.5), under
    5 % flagged (none)."""
    from sblsim.models.sync.knots import WINDOW
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    sim, out, study = _study(tmp_path, 0.01, 1e-7, unheard=True, days=1.0, wander=0.01)
    clocks = study["clocks"]
    assert clocks["source"] == FITTED and not clocks["as_logged"].get("coarse"), clocks
    assert np.diff(clocks["knot_times_s"]).max() <= WINDOW and clocks["receivers"] == 9, clocks
    _offsets_agree(sim, clocks, 5e-4)
    errors = _errors(sim, out, clocks["reference_receiver"])
    for tag, rows in errors.groupby("tag"):
        assert rows["error"].median() < 0.5 and 1.0 <= rows["nees"].mean() <= 4.0, (tag, rows.describe())
        assert (rows["quality"] == "flagged").mean() < 0.05, tag
    assert "more than the noise explains" not in capsys.readouterr().err  # (the knots fit the pings: no misfit)


@pytest.mark.slow
def test_a_clock_is_not_fitted_where_the_pings_are_too_few_to_tie_it(tmp_path, capsys):
    """The wandering clocks of a day, the animals away from the 6th to the 18th hour but for one's pings in five
    minutes at noon: with a knot every window the clocks at the knots in that stretch were tied by those few pings
    alone (they traded with their places: off by tens of milliseconds), and the noon pings lay metres off with a σ
    of decimetres (measured: clocks up to 95 ms off at the knots, the noon rows 13-14 m off, NEES 12,000-20,000).
    The stretch is one now, its knots those its neighbours tie (each clock within 0.5 ms of the simulated one
    there: 0.36 ms); the rows outside it as in a study without the stretch (a median below 0.5 m, NEES in [1, 4]);
    the noon rows nearer (2.5-3.6 m), their clocks linear across the stretch, which is said (a wander there is in
    no σ: NEES 180-460)."""
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    sim, out, study = _study(tmp_path, 0.01, 1e-7, unheard=True, days=1.0, wander=0.01, away=(6.0, 18.0))
    clocks = study["clocks"]
    assert clocks["source"] == FITTED and clocks["receivers"] == 9, clocks
    fitted = (np.array(clocks["fitted_knot_times_s"]) - sim.origin) / 3600.0
    assert not ((fitted > 6.5) & (fitted < 17.5)).any() and (np.abs(fitted - 6.0) < 0.1).any(), fitted
    base = int(np.flatnonzero(sim.clocks["serial"].astype(str) == clocks["reference_receiver"])[0])
    for k, serial in enumerate(sim.clocks["serial"].astype(str)):
        tau = fitted * 3600.0
        got = np.interp(sim.origin + tau, clocks["knot_times_s"], clocks["offsets_s"][serial])
        assert np.abs(got - (sim.offset(k, tau) - sim.offset(base, tau))).max() < 5e-4, serial
    errors = _errors(sim, out, clocks["reference_receiver"])
    hours = ((errors["epoch_s"] - sim.origin) / 3600.0).to_numpy()
    away = (hours > 6.0) & (hours < 18.0)
    assert away.sum() >= 2
    for tag, rows in errors[~away].groupby("tag"):
        assert rows["error"].median() < 0.5 and 1.0 <= rows["nees"].mean() <= 4.0, (tag, rows.describe())
    assert errors[away]["error"].max() < 10.0, errors[away]
    (stretch,) = clocks["sparse_stretches"]  # (said: the clocks linear across it)
    assert stretch["pings"] == away.sum() and abs((stretch["end_s"] - stretch["start_s"]) / 3600.0 - 12.0) < 0.1
    said = capsys.readouterr()
    assert "the clocks linear across 1 stretch of too few pings to follow them (the longest 12 h" in said.out + said.err
    # the clocks bend over 12 h (±10 ms over one to three days: 2.4 ms measured) more than the timing noise, so the
    # noon rows, whose error is in no σ, are flagged; no other row is
    assert stretch["rows_flagged"] and stretch["departure_s"] > 10 * SIGMA_TOA, stretch
    assert "a moving tag's rows in 1 of them flagged clocks_interpolated" in said.out + said.err
    tracks = pd.read_csv(out / "tracks.csv", keep_default_na=False)
    inside = (tracks["epoch_s"] > stretch["start_s"]) & (tracks["epoch_s"] < stretch["end_s"])
    flagged = tracks["quality_reason"].astype(str).str.contains("clocks_interpolated")
    assert inside.sum() == away.sum() and (flagged == inside).all() and (tracks["quality"][inside] == "flagged").all()


def test_the_stretches_said_are_those_the_knots_were_merged_across():
    """``clocks.sparse_stretches``: each stretch between the fit's knots spanning more than one window of the grid,
    with the pings fitted in it (18 h away with two pings; none where every window holds enough), how far the
    clocks depart from a line over its length where the pings tie them (:func:`~sblsim.models.sync.knots.departure`
    of the offsets given) and whether a moving tag's rows in it are flagged: not for clocks that are lines, for
    clocks wandering by ±5 ms over a day (above the timing noise), and where the departure is not seen (the stretch
    as long as the tied time's half); :func:`interpolated` gives the flagged ones of clocks fitted alone."""
    from sblsim.models.sync.knots import MIN_BIN_PINGS, WINDOW, departure, merged
    from sblsim.orchestrator.telemetry.clock_stretches import sparse_stretches
    from sblsim.orchestrator.telemetry.study_offsets import FITTED, interpolated

    grid = np.arange(21) * WINDOW + 1.7e9
    counts = [MIN_BIN_PINGS, MIN_BIN_PINGS, 0, 0, 0, 2, 0, 0] + [MIN_BIN_PINGS] * 12
    times = np.concatenate([np.linspace(grid[j] + 1.0, grid[j + 1] - 1.0, n) for j, n in enumerate(counts)])
    edges = merged(grid, times)
    tau = (edges - edges[0])[None]
    lines, sine = 0.01 + 2e-7 * tau * np.array([[1.0], [-3.0]]), 0.005 * np.sin(2 * np.pi * tau / 86400.0 + [[0.0],
                                                                                                          [1.0]])
    tied, sigma, spread = np.ones(lines.shape, bool), 1.5e-4, np.full(lines.shape, 1e-6)
    stretch = {"start_s": grid[2], "end_s": grid[8], "pings": 2}
    assert sparse_stretches(edges, grid, times, lines, tied, spread, sigma) == [
        stretch | {"departure_s": 0.0, "rows_flagged": False}]
    bent = departure(edges, sine, tied, grid[8] - grid[2], spread)
    assert bent > sigma and sparse_stretches(edges, grid, times, sine, tied, spread, sigma) == [
        stretch | {"departure_s": bent, "rows_flagged": True}]
    short = grid[:11]  # (the stretch alone in the middle of the tied time: no chord of its length)
    assert sparse_stretches(merged(short, times), short, times, lines[:, :6], tied[:, :6], spread[:, :6], sigma) == [
        stretch | {"departure_s": None, "rows_flagged": True}]
    dense = np.linspace(grid[0], grid[-1], 30 * MIN_BIN_PINGS)
    assert sparse_stretches(merged(grid, dense), grid, dense, np.zeros((2, 21)), np.ones((2, 21), bool),
                            np.zeros((2, 21)), sigma) == []
    bends = [stretch | {"rows_flagged": True}, {"start_s": 1.0, "end_s": 2.0, "pings": 0, "rows_flagged": False}]
    assert interpolated({"source": FITTED, "sparse_stretches": bends}) == [(grid[2], grid[8])]
    assert interpolated({"source": "as logged", "sparse_stretches": bends}) == []


def test_a_tag_s_options_from_clocks_fitted_from_the_pings():
    """:func:`fitted_options`: a moving tag's stretches of interpolated clocks (those flagged alone), every tag's
    study speed (the fit's σ and :data:`~sblsim.models.tracking.calibration.MAX_SIGMA` in quadrature), none where the
    speed was given or the clocks are not fitted from the pings."""
    from sblsim.models.tracking.calibration import MAX_SIGMA
    from sblsim.orchestrator.telemetry.study_offsets import FITTED, fitted_options, study_speed

    stretches = [{"start_s": 1.0, "end_s": 2.0, "pings": 1, "departure_s": None, "rows_flagged": True},
                 {"start_s": 3.0, "end_s": 4.0, "pings": 2, "departure_s": 0.0, "rows_flagged": False}]
    info = {"source": FITTED, "sound_speed_m_s": 1478.7, "sound_speed_sigma_m_s": 3.0, "sparse_stretches": stretches}
    speed = (1478.7, float(np.hypot(3.0, MAX_SIGMA)))
    assert study_speed(info) == speed
    assert fitted_options(info, True) == {"clocks_interpolated": [(1.0, 2.0)], "study_speed": speed}
    assert fitted_options(info, False) == {"study_speed": speed}
    given = info | {"sound_speed_sigma_m_s": None}
    assert study_speed(given) is None and fitted_options(given, True) == {"clocks_interpolated": [(1.0, 2.0)]}
    assert fitted_options(info | {"source": "as logged"}, True) == {}


@pytest.mark.slow
def test_four_receivers_take_the_study_s_speed_where_their_pings_cannot_calibrate_it(tmp_path):
    """Four receivers: no ping is heard by the five a tag's calibration needs, so each tag fell back on 1,500 m/s,
    51 m/s uncertain (the water's 1,480 m/s): a median 0.54-0.88 m from the truth with a σ of 1.4-1.9 m (NEES
    0.9-1.2; seeds 6 and 7: 0.58-0.74 m, NEES 0.5-0.9). The clocks' fit from the pings fits the speed's scale with
    them (1,478.7 m/s, 3.6 m/s uncertain), and each tag now takes it as its fallback: every tag at that speed, each
    a median below 0.45 m (0.28-0.32 m measured) with a NEES (2-D) in [1, 4.5] (3.2-4.1; seeds 6 and 7: 0.24-0.29 m,
    NEES 2.0-3.1)."""
    sim, out, study = _study(tmp_path, 0.01, 1e-7, unheard=True, receivers=4)
    clocks = study["clocks"]
    assert abs(clocks["sound_speed_m_s"] - 1480.0) < 5.0 and clocks["sound_speed_sigma_m_s"] > 0.0, clocks
    tags = pd.read_csv(out / "tags.csv")
    assert (tags["sound_speed_source"] == "fallback").all()
    assert np.allclose(tags["sound_speed_m_s"], clocks["sound_speed_m_s"]), tags["sound_speed_m_s"]
    for tag, rows in _errors(sim, out, clocks["reference_receiver"]).groupby("tag"):
        assert rows["error"].median() < 0.45 and 1.0 <= rows["nees"].mean() <= 4.5, (tag, rows.describe())


def test_clocks_off_by_seconds_are_aligned_from_the_tags_detections_then_fitted(tmp_path):
    """Each clock off by up to ±2 s and drifting by up to 20 ppm (a receiver's raw clock: half a second over the six
    hours), no sync tag named: a ping's arrivals are seconds apart and the tags were refused as logged (their
    intervals contradicted). The pairs' lags align the clocks to within the time the sound crosses the array, the
    pings' fixes then fit them: each clock's offset within 1 ms of the simulated one at every knot, every animal's
    median error below 0.5 m and its NEES (2-D) in [1, 4]."""
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    sim, out, study = _study(tmp_path, 2.0, 2e-5, unheard=False)
    clocks = study["clocks"]
    assert clocks["source"] == FITTED and clocks["as_logged"]["coarse"]["largest_lag_s"] > 1.0, clocks
    assert clocks["receivers"] == 9 and len(clocks["knot_times_s"]) == 2  # (the coarse windows' middles)
    _offsets_agree(sim, clocks, 1e-3)
    errors = _errors(sim, out, clocks["reference_receiver"])
    for tag, rows in errors.groupby("tag"):
        assert rows["error"].median() < 0.5 and 1.0 <= rows["nees"].mean() <= 4.0, (tag, rows.describe())


def test_a_3d_study_s_clocks_are_fitted_with_each_ping_at_its_tracker_s_depth(tmp_path):
    """The deployments give each receiver's depth (``instrument_depth`` 5 m) and the bottom's (20 to 36 m), as a
    GLATOS or OTN sheet does: a 3-D study, whose clocks were not fitted (fitted in the plane, the offsets took up the
    depths) and whose fixes on clocks off by ±30 ms were 27 to 34 m off with NEES in the thousands. Each ping is now
    held at the depth its tracker takes (its own fix with the prior, mid-water here: 10 m from the truth, which the
    arrivals pull it back from): each clock's offset within 0.3 ms of the simulated one at every knot, every
    animal's median error below 0.5 m and its NEES (2-D) in [1, 4]."""
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    sim, out, study = _study(tmp_path, 0.03, 5e-6, unheard=False, depths=True)
    clocks = study["clocks"]
    assert study["water_depth"]["source"] == "bottom_depth"
    assert clocks["source"] == FITTED and clocks["receivers"] == 9, clocks
    _offsets_agree(sim, clocks, 3e-4)
    errors = _errors(sim, out, clocks["reference_receiver"])
    for tag, rows in errors.groupby("tag"):
        assert rows["error"].median() < 0.5 and 1.0 <= rows["nees"].mean() <= 4.0, (tag, rows.describe())


def test_clocks_seconds_apart_that_no_fit_ties_are_named_in_each_refused_tag_s_reason(tmp_path, capsys):
    """Three receivers (no ping heard by the four a fit needs) whose clocks are off by up to ±2 s: the tags are
    positioned on the clocks as logged, which split every ping's arrivals, and refused; each refused row's reason
    names the clocks (by how much they disagree, that no fit ties them) beside its counts, and the study says why no
    fit was made (every moving tag refused, by code). With the clocks right no reason names them."""
    from sblsim.orchestrator.telemetry.study_clocks import NO_SYNC_TAG

    _, out, study = _study(tmp_path / "off", 2.0, 2e-5, unheard=False, receivers=3)
    lag = study["clocks"]["coarse"]["largest_lag_s"]
    assert study["clocks"]["source"] == NO_SYNC_TAG and lag > 1.0, study["clocks"]
    assert study["clocks"]["checked"]["reason"] == ("no moving tag's pings to fit from, every moving tag refused "
                                                    "(too_few_receivers_at_once 3)")
    tags = pd.read_csv(out / "tags.csv")
    assert (tags["status"] == "refused").all() and (tags["reason_code"] == "too_few_receivers_at_once").all()
    named = f"the receivers' clocks as logged disagree by up to {lag:.3g} s"
    assert all(r.startswith("0 of ") and named in r for r in tags["reason"]), tags["reason"].tolist()
    assert named in capsys.readouterr().err
    _, out, study = _study(tmp_path / "right", 0.0, 0.0, unheard=False, receivers=3)
    assert "coarse" not in study["clocks"]
    assert not pd.read_csv(out / "tags.csv")["reason"].fillna("").str.contains("disagree").any()


@pytest.mark.slow
def test_the_boats_clocks_without_their_sync_tags_come_from_the_animals_pings(tmp_path):
    """The boats' raw detections (data/boats-norway) less every sync tag's row: the receivers' clocks, off by up to
    56 s, are tied from the cod's and the lobster's pings alone; taken as logged, every tag was refused (never more
    than two receivers at once). Against the study synchronised from the sync tags (an independent clock): most
    receivers synchronised, each tag's rows that both call ok within a median 5 m of the synchronised study's
    (measured: 3.1 and 4.3 m), the difference's NEES (2-D, both σ) below 5 (measured: 2.9 and 3.2)."""
    from sblsim.orchestrator import cli
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    table = pd.read_csv(DATA / "detections.csv")
    table[table["species"] != "Sync"].to_csv(tmp_path / "detections.csv", index=False)
    sheet = ["--receivers", str(DATA / "deployments.csv"), "--tags", str(DATA / "tags.csv")]
    assert cli.main(["track", str(tmp_path / "detections.csv"), *sheet, "--out", str(tmp_path / "fit")]) == 0
    assert cli.main(["track", str(DATA / "detections.csv"), *sheet, "--out", str(tmp_path / "sync")]) == 0
    clocks = json.loads((tmp_path / "fit" / "study.json").read_text())["clocks"]
    reference = json.loads((tmp_path / "sync" / "study.json").read_text())["clocks"]["reference_receiver"]
    assert clocks["source"] == FITTED and clocks["receivers"] >= 12, clocks
    fit, sync = (pd.read_csv(tmp_path / f / "tracks.csv") for f in ("fit", "sync"))
    # the fit's times on its time base's clock, put on the synchronisation's reference's
    fit["epoch_s"] += np.interp(fit["epoch_s"], clocks["knot_times_s"], clocks["offsets_s"][reference])
    for tag in (4555, 7953):
        a = fit[fit["tag"] == tag].sort_values("epoch_s")
        b = sync[sync["tag"] == tag].sort_values("epoch_s")
        both = pd.merge_asof(a, b, on="epoch_s", direction="nearest", tolerance=1.0, suffixes=("", "_s"))
        both = both[(both["quality"] == "ok") & (both["quality_s"] == "ok")]
        dx, dy = both["x"] - both["x_s"], both["y"] - both["y_s"]
        nees = dx**2 / (both["sigma_x"] ** 2 + both["sigma_x_s"] ** 2) + dy**2 / (both["sigma_y"] ** 2
                                                                                 + both["sigma_y_s"] ** 2)
        assert len(both) > 200 and np.hypot(dx, dy).median() < 5.0 and nees.mean() < 5.0, (tag, len(both))


def test_each_ping_s_depth_held_in_a_3d_fit_is_the_one_its_tracker_would_take():
    """:func:`held_heights` on pings simulated here (a tag at 10 m among receivers at 5 and 40 m, 0.1 ms of noise, a
    fifth of the arrivals missing): where the receivers' depths span enough to determine the tag's, each ping's
    own fix's depth (median within 1 m of the truth, where the receivers' mean is 12.5 m off); a depth sensor's
    reading where a ping has one; receivers in one plane with no water depth, their own depth (the tracker's prior);
    with the water's depth given, within the column."""
    from types import SimpleNamespace

    from sblsim.orchestrator.telemetry.study_offsets import held_heights

    rng = np.random.default_rng(4)
    xy = np.array([[0, 0], [400, 0], [400, 400], [0, 400], [200, -50], [450, 200], [200, 450], [-50, 200]], float)
    deep = np.c_[xy, np.repeat([-5.0, -40.0], 4)]
    places = np.c_[rng.uniform(50, 350, (300, 2)), np.full(300, -10.0)]
    names = [f"r{k}" for k in range(len(xy))]

    def matrix(receivers, pings=None):
        toa = 100.0 + 5.0 * np.arange(len(places))[:, None] + np.linalg.norm(
            places[:, None] - receivers[None], axis=2) / 1480.0 + 1e-4 * rng.normal(size=(len(places), len(xy)))
        toa[rng.uniform(size=toa.shape) < 0.2] = np.nan
        return SimpleNamespace(toa=toa, positions=receivers, names=names, summary={"tag": "t"},
                               pings=pd.DataFrame(index=range(len(places))) if pings is None else pings)

    for water in (None, {"source": "bottom_depth", "per_tag_m": {"t": 45.0}}):  # (the tag's, as its tracker's)
        held = held_heights(matrix(deep), water, 1480.0, 1e-4)
        assert np.median(np.abs(held + 10.0)) < 1.0 and np.abs(np.median(held) - deep[:, 2].mean()) > 8.0, water
        assert held.min() >= -45.0 if water else (held <= 0.0).all()
    readings = np.where(np.arange(len(places)) % 2, 12.0, np.nan)
    held = held_heights(matrix(deep, pd.DataFrame({"depth_m": readings})), None, 1480.0, 1e-4)
    assert (held[1::2] == -12.0).all() and np.median(np.abs(held[::2] + 10.0)) < 1.0
    flat = np.c_[xy, np.full(len(xy), -5.0)]
    assert (held_heights(matrix(flat), None, 1480.0, 1e-4) == -5.0).all()
    held = held_heights(matrix(flat), {"source": "given", "water_depth_m": 30.0}, 1480.0, 1e-4)
    assert ((held >= -30.0) & (held <= 0.0)).all()


@pytest.mark.slow
def test_a_redeployed_array_s_clocks_are_fitted_with_a_time_base_at_every_knot(tmp_path):
    """Eight of 9 receivers recovered in the study's middle third and deployed again an hour later at another
    station (each deployment a clock of its own), 12 hours, clocks off by up to ±1 s: the time base (the deployment
    heard most) spans half the study and left the other half's knots tied to it by nothing, so that half's
    deployments were loosely tied and dropped (measured: 9 of 17 not synchronised, 219 of 624 rows flagged). Each
    knot now takes the deployment heard most near it where the time base is not: every deployment synchronised but
    at most one, each one's offsets at the knots its arrivals touch within 1 ms of the simulated clocks' less that
    knot's base's, every animal's median error below 0.5 m and its NEES (2-D) in [1, 4]."""
    from sblsim.orchestrator import cli
    from sblsim.orchestrator.telemetry.study_offsets import FITTED

    sim = simulate_study(n_receivers=9, n_tags=3, days=0.5, redeployed=9, seed=5, offset=1.0, drift=5e-6)
    files = sim.write(tmp_path / "in", "glatos")
    sheet = pd.read_csv(files["deployments"], dtype=str, keep_default_na=False)
    sheet.assign(transmitter="").to_csv(files["deployments"], index=False)
    out = tmp_path / "study"
    assert cli.main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--tags",
                     str(files["tags"]), "--out", str(out)]) == 0
    clocks = json.loads((out / "study.json").read_text())["clocks"]
    assert clocks["source"] == FITTED and len(clocks["not_synchronised"]) <= 1, clocks["not_synchronised"]
    assert len(set(clocks["time_base_by_knot"])) > 1
    # each deployment's own clock (``serial.k``: the k-th deployment of that serial), at the knots
    tau = np.array(clocks["knot_times_s"]) - sim.origin
    truth, seen, times = {}, {}, sim.clocks["serial"].astype(str).value_counts()
    for row in sim.clocks.itertuples():  # (a serial deployed once: its name alone)
        k = seen[str(row.serial)] = seen.get(str(row.serial), 0) + 1
        truth[f"{row.serial}.{k}" if times[str(row.serial)] > 1 else str(row.serial)] = row.a + row.b * tau
    bases = np.array([truth[n] for n in clocks["time_base_by_knot"]])[np.arange(len(tau)), np.arange(len(tau))]
    detections = pd.read_csv(out / "tags.csv")  # (the tags tracked)
    assert (detections["status"] == "tracked").all()
    for name, knots in clocks["offsets_s"].items():
        error = np.abs(np.array(knots) - (truth[name] - bases))
        assert np.sort(error)[:2].max() < 1e-3, (name, error)  # (at least the two knots its own arrivals touch)
    serial, _, k = clocks["reference_receiver"].partition(".")
    deployment = int(np.flatnonzero(sim.clocks["serial"].astype(str) == serial)[int(k or 1) - 1])
    tracks = pd.read_csv(out / "tracks.csv")
    for tag, rows in tracks.groupby("tag"):
        e = rows[["x", "y"]].to_numpy() - sim.truth_at(tag, rows["epoch_s"].to_numpy(), deployment)
        ok = (rows["quality"] == "ok").to_numpy()
        nees = (e[:, 0] / rows["sigma_x"]) ** 2 + (e[:, 1] / rows["sigma_y"]) ** 2
        assert np.median(np.hypot(*e[ok].T)) < 0.5 and 1.0 <= nees[ok].mean() <= 4.0, tag
