"""Still tags tracked (orchestrator/tracks/track.py with ``motion="stationary"``, models/tracking/still_tag.py):
simulated times of arrival of a tag at a fixed place in water whose sound speed changes by ±5 m/s over a day (none
flagged, an honest σ), of one moved 20 m half way (flagged from its move, said, its second place in the summary) and
of an animal (moving: every row flagged)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sblsim.orchestrator.tracks.track import track
from sblsim.orchestrator.tracks.variants import write_toa

RECEIVERS = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 800.0], [0.0, 800.0], [500.0, 400.0], [250.0, 700.0],
                      [800.0, 150.0], [650.0, 750.0]])
NAMES = [f"H{k + 1}" for k in range(len(RECEIVERS))]
TAG = np.array([780.0, 560.0])
SIGMA = 1e-4


def _record(tmp_path: Path, seed: int, n: int = 720, move: np.ndarray | None = None,
            walk: float | None = None, receivers: int = len(RECEIVERS)) -> tuple[Path, Path, np.ndarray]:
    """A tag's times of arrival (a ping every 120 ± 24 s over a day, each of the first ``receivers`` receivers
    hearing 80 % of them with 0.1 ms noise) in water of 1,480 ± 5 m/s (a sine over the day, random phase): the TOA
    file, the receivers file and the tag's place at each ping."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(96.0, 144.0, n))
    c = 1480.0 + 5.0 * np.sin(2 * np.pi * t / 86400.0 + rng.uniform(0, 2 * np.pi))
    places = np.repeat(TAG[None], n, axis=0)
    if move is not None:
        places[n // 2:] += move
    if walk is not None:
        places = places + np.cumsum(rng.normal(scale=walk, size=(n, 2)), axis=0)
    toa = t[:, None] + np.linalg.norm(places[:, None] - RECEIVERS[None, :receivers], axis=2) / c[:, None]
    toa = toa + SIGMA * rng.normal(size=toa.shape)
    toa[rng.random(toa.shape) > 0.8] = np.nan
    write_toa(tmp_path / "toa.txt", toa, NAMES[:receivers])
    rows = "\n".join(f"{name},{x:g},{y:g}" for name, (x, y) in zip(NAMES, RECEIVERS[:receivers]))
    (tmp_path / "receivers.csv").write_text("name,x_m,y_m\n" + rows + "\n")
    return tmp_path / "toa.txt", tmp_path / "receivers.csv", places


@pytest.mark.slow
def test_still_tags_in_changing_water_are_not_flagged_and_their_sigma_is_honest(tmp_path):
    """20 still tags, the sound speed calibrated from their pings: at most 5 % of the rows flagged (none
    ``tag_moved``), and the mean 2-D NEES of the place against the truth with the covariance reported (its own and
    the consider terms: the speed's, the receivers' jackknife) in [1, 3]; each row's σ is that covariance's."""
    nees, flagged, rows = [], 0, 0
    for seed in range(20):
        toa, receivers, places = _record(tmp_path, seed)
        outcome = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False)
        still = outcome.summary["motion"]["still"]
        assert still["verdict"] == "still" and not outcome.summary["motion"]["moved"], still
        rows += len(outcome.track)
        flagged += int((outcome.track["quality"] == "flagged").sum())
        assert not outcome.track["quality_reason"].str.contains("tag_moved").any()
        e = np.asarray(still["place"]) - places[0]
        covariance = np.asarray(still["covariance"])
        nees.append(float(e @ np.linalg.solve(covariance, e)))
        np.testing.assert_allclose(outcome.track[["sigma_x", "sigma_y"]].to_numpy()[0],
                                   np.sqrt(np.diag(covariance)), rtol=1e-9)
    assert flagged <= 0.05 * rows and 1.0 <= np.mean(nees) <= 3.0, (flagged, rows, np.mean(nees), nees)


@pytest.mark.slow
def test_a_tag_moved_20_m_half_way_is_flagged_from_its_move(tmp_path, capsys):
    """A still tag dragged 20 m east at its 360th ping: ``sblsim replay --motion stationary`` flags its rows from
    within 3 pings of the move (``tag_moved``), the rows before it ``ok``; the summary's second place is within 1 m of
    where it went, and one warning line says so."""
    from sblsim.orchestrator.cli import main

    toa, receivers, places = _record(tmp_path, 3, move=np.array([20.0, 0.0]))
    out = tmp_path / "out"
    assert main(["replay", str(toa), "--format", "toa", "--receivers", str(receivers), "--motion", "stationary",
                 "--toa-sigma", str(SIGMA), "--out", str(out)]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "the tag moved" in line]
    rows = np.genfromtxt(out / "track.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    moved = np.char.find(rows["quality_reason"].astype(str), "tag_moved") >= 0
    first = int(np.argmax(moved))
    assert abs(first - 360) <= 3 and moved[first:].all(), first
    assert (rows["quality"][:first] == "ok").all()
    change = json.loads((out / "summary.json").read_text())["motion"]["still"]["change"]
    assert np.linalg.norm(np.asarray(change["second_place"]) - places[-1]) < 1.0, change
    assert len(said) == 1 and f"after ping {change['split_ping'] - 1}" in said[0], said
    assert f"rows from ping {first} flagged" in said[0] and change["split_ping"] == first, (said, change)
    assert np.allclose([rows["x"][first], rows["y"][first]], change["second_place"])


def test_on_five_receivers_the_pings_between_two_trusted_fixes_are_placed_by_their_arrivals(tmp_path):
    """Five receivers (four corners and the centre): the pings before a move of 20 m at ping 360 include a run
    without a trusted fix (the last still trusted fix 14 pings before it in this seed), which was all flagged (13
    pings early); the pings between are each given to the place their arrivals fit, so the rows are flagged from
    within 3 pings of the move and those before it are ``ok``."""
    toa, receivers, _ = _record(tmp_path, 3, move=np.array([20.0, 0.0]), receivers=5)
    outcome = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False)
    change = outcome.summary["motion"]["still"]["change"]
    moved = outcome.track["quality_reason"].str.contains("tag_moved").to_numpy()
    first = int(np.argmax(moved))
    assert abs(first - 360) <= 3 and moved[first:].all() and first == change["split_ping"], (first, change)
    assert (outcome.track["quality"].to_numpy()[:first] == "ok").all()
    assert change["split_ping"] - 1 - change["last_still_ping"] > 3, change  # a gap of untrusted pings it closed


def test_a_still_tag_whose_fixes_cannot_be_trusted_is_unchecked_not_still(tmp_path, capsys):
    """Three receivers: each ping's fix is exact whatever its arrivals (none to spare), so none is trusted and the
    verdict cannot test the fixes' wander: ``unchecked`` (not ``still``), every row flagged ``motion_unchecked``,
    one warning line; the place is still given. Four receivers hear enough for the verdict: ``still``."""
    from sblsim.orchestrator.cli import main

    toa, receivers, places = _record(tmp_path, 2, n=200, receivers=3)
    out = tmp_path / "out"
    assert main(["replay", str(toa), "--format", "toa", "--receivers", str(receivers), "--motion", "stationary",
                 "--toa-sigma", str(SIGMA), "--sound-speed", "1480", "--out", str(out)]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "whether the tag moved is unchecked" in line]
    still = json.loads((out / "summary.json").read_text())["motion"]["still"]
    rows = np.genfromtxt(out / "track.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert still["verdict"] == "unchecked" and still["trusted_fixes"] < 10, still
    assert len(rows) > 150 and (rows["quality"] == "flagged").all()
    assert (np.char.find(rows["quality_reason"].astype(str), "motion_unchecked") >= 0).all()
    assert len(said) == 1 and f"{still['trusted_fixes']} trusted single-ping fixes" in said[0], said
    assert np.linalg.norm(np.asarray(still["place"]) - places[0]) < 1.0
    toa, receivers, _ = _record(tmp_path, 2, n=200, receivers=4)
    outcome = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False, sound_speed=1480.0)
    assert outcome.summary["motion"]["still"]["verdict"] == "still"
    assert not outcome.track["quality_reason"].fillna("").str.contains("motion_unchecked").any()


def test_an_animal_tracked_as_still_is_moving(tmp_path):
    """A random walk of 2 m per ping tracked as a still tag: moving the whole time, every row flagged
    ``tag_moved``."""
    toa, receivers, _ = _record(tmp_path, 5, walk=2.0)
    outcome = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False)
    assert outcome.summary["motion"]["still"]["verdict"] == "moving" and outcome.summary["motion"]["moved"]
    assert outcome.track["quality_reason"].str.contains("tag_moved").all()


def test_four_receivers_calibrate_a_still_tags_speed_from_it_as_one_place(tmp_path):
    """Four receivers (no ping heard by the five a ping-by-ping calibration needs): tracked as still, the speed is
    calibrated from the pings as one place, within 3 m/s of the water's mean, the place within χ²(2)'s 99.9 % of the
    truth under its reported covariance, no row flagged; tracked as moving, the same record keeps the default
    speed's fallback (the pings' one place is a still tag's alone)."""
    toa, receivers, places = _record(tmp_path, 3, receivers=4)
    outcome = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False)
    speed = outcome.summary["sound_speed"]
    assert speed["source"] == "calibrated" and "as one place" in speed["method"], speed
    assert abs(speed["sound_speed_m_s"] - 1480.0) < 3.0, speed
    still = outcome.summary["motion"]["still"]
    e = np.asarray(still["place"]) - places[0]
    assert still["verdict"] == "still" and e @ np.linalg.solve(np.asarray(still["covariance"]), e) < 13.8, still
    assert (outcome.track["quality"] == "ok").all(), outcome.track["quality_reason"].value_counts()
    moving = track(toa, receivers, toa_sigma=SIGMA, other_filters=False, smooth=False)
    assert moving.summary["sound_speed"]["source"] == "fallback", moving.summary["sound_speed"]


def test_the_speeds_change_is_fitted_and_not_also_a_consider_term(tmp_path):
    """A day's record: the summary's fitted change spans the water's ±5 m/s about the calibrated speed, and the
    calibrated speed's error is no consider term (the fit holds it); two hours of pings: no change fitted (null)
    and the speed's consider term back."""
    toa, receivers, _ = _record(tmp_path, 2)
    day = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False).summary
    c = day["sound_speed"]["sound_speed_m_s"]
    low, high = day["motion"]["still"]["speed_change_m_s"]
    truth = 1480.0 + 5.0 * np.array([-1.0, 1.0]) - c  # the water's least and largest, about the calibrated speed
    assert np.allclose([low, high], truth, atol=1.0), (low, high, truth)
    assert day["sound_speed"].get("sigma_m_s") and "sound speed" not in day["motion"]["consider_terms"]
    toa, receivers, _ = _record(tmp_path, 2, n=50)  # about 100 minutes: fewer than two knots' spacing
    short = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False).summary
    assert short["motion"]["still"]["speed_change_m_s"] is None
    assert "sound speed" in short["motion"]["consider_terms"]
