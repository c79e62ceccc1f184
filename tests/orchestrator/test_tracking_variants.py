"""Beyond one recording: Lake Hald changed the way real studies differ (orchestrator/tracks/variants.py), and the
tracker on each against the GPS: the random burst intervals, a gap cut out, receivers with depths; a simulated tag of
every ping type consistent with its own covariance and near its PCRB; a track started 1 km off flagged or right."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sblsim
from sblsim.models.receiver import toa_bound as tb
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import quality as qa
from sblsim.models.tracking import schedule as ps
from sblsim.orchestrator.readers.receivers_file import read_receivers
from sblsim.orchestrator.readers.toa_matrix import read_toa
from sblsim.orchestrator.tracks import variants

DATA = Path(__file__).resolve().parents[2] / "data" / "lake-hald"


#: ``sblsim.replay_toa`` without the causal filters run beside for comparison (the sequential EKF and the UKF, half
#: of a track's time; ``--no-other-filters``, as a study tracks its tags): what these tests check, the robust track,
#: its quality, score and bound, the EKF, RTS and fixes, is the same with them
#: (:func:`test_the_other_filters_left_out_leave_the_track_as_it_is`).
ROBUST = {"other_filters": False}


def test_random_interval_pings_are_a_uniform_draw_apart():
    """On a synthetic matrix of a ping every 0.5 s: the kept pings' steps within U(20, 40) s to the grid's half step,
    their mean and spread those of the uniform (independently: numpy's moments of U(20, 40))."""
    first = np.arange(0.0, 20000.0, 0.5)
    toa = np.column_stack([first + 0.01, first + 0.02, np.full(len(first), np.nan)])
    rows = variants.random_interval_pings(toa, 20.0, 40.0, seed=4)
    steps = np.diff(first[rows])
    assert steps.min() >= 20.0 - 0.25 and steps.max() <= 40.0 + 0.25
    assert abs(steps.mean() - 30.0) < 3 * 20.0 / np.sqrt(12 * len(steps))
    assert abs(steps.std() - 20.0 / np.sqrt(12)) < 0.6
    assert np.array_equal(rows, variants.random_interval_pings(toa, 20.0, 40.0, seed=4))  # seeded


def test_a_cut_gap_removes_the_window_and_the_file_reads_back(tmp_path):
    first = np.arange(0.0, 100.0, 2.0)
    toa = np.column_stack([first + 0.1, first + 0.2])
    toa[5] = np.nan  # a ping nobody heard is kept
    rows = variants.cut_gap(toa, 30.0, 20.0)
    assert [r for r in range(len(first)) if r not in rows] == [15, 16, 17, 18, 19, 20, 21, 22, 23, 24]
    variants.write_toa(tmp_path / "t.txt", toa[rows], ["A", "B"])
    back = read_toa(tmp_path / "t.txt")
    assert back.names == ["A", "B"] and np.allclose(back.toa, toa[rows], equal_nan=True, atol=1e-9)


def lake_hald(tmp_path: Path, name: str, rows: np.ndarray) -> Path:
    matrix = read_toa(DATA / "toa.txt")
    names = matrix.names or read_receivers(DATA / "hydrophones.csv").names
    path = tmp_path / f"{name}.txt"
    variants.write_toa(path, matrix.toa[rows], names)
    return path


def scored(result) -> dict:
    """The track's figures and its rows more than 10 m from the GPS that are not flagged."""
    errors = result.errors[result.errors["estimator"] == "robust"].set_index("ping")["error_2d_m"]
    quality = result.estimates[result.estimates["estimator"] == "robust"].set_index("ping")["quality"]
    wrong_ok = int(((errors > 10.0) & (quality.reindex(errors.index) != "flagged")).sum())
    return {"median": result.score["median_m"], "rms": result.score["rms_m"], "p95": result.score["p95_m"],
            "wrong_ok": wrong_ok}


@pytest.mark.slow
def test_the_other_filters_left_out_leave_the_track_as_it_is(tmp_path):
    """Lake Hald's first 100 pings with and without the comparison filters (``other_filters``): the track, and the
    robust, RTS, EKF and fixes' rows and errors, the same to the last bit; the sequential EKF's and the UKF's rows,
    scores and counts there only with them."""
    path = lake_hald(tmp_path, "first", np.arange(100))
    both, robust = (sblsim.replay_toa(path, receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                                      sound_speed=1420.0, other_filters=kept) for kept in (True, False))
    others = {"ekf-seq", "ukf"}
    assert set(both.estimates["estimator"]) == {"robust", "rts", "ekf", "fix"} | others
    assert set(robust.estimates["estimator"]) == {"robust", "rts", "ekf", "fix"}
    assert both.track.equals(robust.track)
    for table in ("estimates", "errors"):
        whole = getattr(both, table)
        assert whole[~whole["estimator"].isin(others)].reset_index(drop=True).equals(getattr(robust, table))
    assert others <= set(both.score["others"]) and not others & set(robust.score["others"])
    assert {k: v for k, v in both.summary["fixed"].items() if k not in others} == robust.summary["fixed"]


def test_no_other_filters_on_the_command_line(tmp_path, capsys):
    """``--no-other-filters`` reaches the tracking options as ``other_filters`` False (True without it), and a
    receiver's log, which has no such filters, refuses it in one line and writes nothing."""
    from sblsim.orchestrator.cli import _parser, main
    from sblsim.orchestrator.tracks.format_options import toa_arguments

    base = ["replay", str(DATA / "toa.txt"), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv")]
    assert toa_arguments(_parser().parse_args(base))["other_filters"] is True
    assert toa_arguments(_parser().parse_args([*base, "--no-other-filters"]))["other_filters"] is False
    log = tmp_path / "log.csv"
    log.write_text("time_s\n0.0\n")
    assert main(["replay", str(log), "--no-other-filters", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sblsim: error: --no-other-filters: only with --format toa"), err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.parametrize("low,high,median,rms,p95", [(20.0, 40.0, 0.25, 2.0, 5.0), (5.0, 15.0, 0.25, 2.0, 5.0)],
                         ids=["U(20,40)", "U(5,15)"])
def test_lake_hald_at_a_random_burst_interval(tmp_path, low, high, median, rms, p95):
    """The pings kept at a random burst interval (seed 1): the type inferred, the issue's targets met (YAPS: 0.25-0.27
    m median, 5-9 m RMS, 8-21 m at 95 %), no row 10 m off the GPS left unflagged."""
    toa = read_toa(DATA / "toa.txt").toa
    path = lake_hald(tmp_path, "rbi", variants.random_interval_pings(toa, low, high, seed=1))
    result = sblsim.replay_toa(path, receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt", **ROBUST)
    assert result.summary["ping_type"]["type"] == "rbi" and result.summary["ping_type"]["source"] == "inferred"
    figures = scored(result)
    assert figures["median"] <= median and figures["rms"] <= rms and figures["p95"] <= p95, figures
    assert figures["wrong_ok"] == 0, figures


@pytest.mark.slow
def test_lake_hald_with_ten_minutes_cut_out(tmp_path):
    """Ten minutes from the middle of the track removed (rows absent): one gap, two segments, the issue's targets
    (median 0.22, RMS 1, 95 % 1.1 m; before the schedule: 64 km RMS)."""
    toa = read_toa(DATA / "toa.txt").toa
    first = ps.first_arrivals(toa)
    path = lake_hald(tmp_path, "gap", variants.cut_gap(toa, float(np.nanmedian(first)), 600.0))
    result = sblsim.replay_toa(path, receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt", **ROBUST)
    assert len(result.summary["segments"]) == 2 and 590.0 < result.summary["gaps_s"][0] < 615.0
    figures = scored(result)
    assert figures["median"] <= 0.22 and figures["rms"] <= 1.0 and figures["p95"] <= 1.1, figures
    assert figures["wrong_ok"] == 0, figures


def _at_depths(tmp_path: Path, seed: int = 1) -> Path:
    """Lake Hald's receivers moored at depths U(1, 5) m drawn with ``seed`` (the variants' depths)."""
    import pandas as pd

    table = pd.read_csv(DATA / "hydrophones.csv")
    rng = np.random.default_rng(seed)
    table["z_m"] = np.where(table["x_m"].notna(), -rng.uniform(1.0, 5.0, len(table)), np.nan)
    table.to_csv(tmp_path / "hydrophones.csv", index=False)
    return tmp_path / "hydrophones.csv"


@pytest.mark.slow
def test_lake_hald_with_receiver_depths_and_a_2d_truth(tmp_path):
    """The documented input a 3-D array with a 2-D truth (a traceback before): the track within 1.5 times the full
    2-D track's figures (median 0.20, RMS 0.62, 95 % 0.95 m); its bound has a row per ping. Receivers 1-5 m deep do
    not determine the depth of a pinger among them: it is taken with a prior (models/tracking/depth.py)."""
    result = sblsim.replay_toa(DATA / "toa.txt", receivers=_at_depths(tmp_path), truth=DATA / "gps.txt",
                               **ROBUST)
    assert result.summary["dimensions"] == 3 and len(result.bound) == 3244
    assert result.summary["depth"]["source"] == "prior (the arrivals do not determine it)"
    figures = scored(result)
    assert figures["median"] <= 1.5 * 0.20 and figures["rms"] <= 1.5 * 0.62 and figures["p95"] <= 1.5 * 0.95, \
        figures


@pytest.mark.slow
def test_the_8_hydrophones_at_depths_take_the_depth_with_a_prior(tmp_path):
    """The authors' 8 hydrophones moored at depths U(1, 5) m (seed 2; the rule was set on seed 1 and on
    simulations): the depth taken with a prior; the 8 hydrophones' targets (median 0.45 m with 10 % slack, RMS 2,
    95 % 4.5 m) and at most 3 rows more than 10 m from the GPS left ok (the 2-D track's reflection at pings 421-423,
    docs/tracking.md; with the depth estimated freely: 0.53 / 2.76 / 6.89 m and 62 such rows at seed 1)."""
    result = sblsim.replay_toa(DATA / "toa.txt", receivers=_at_depths(tmp_path, seed=2), truth=DATA / "gps.txt",
                               receivers_kept="H2,H4,H6,H7,H11,H12,H17,H23", **ROBUST)
    assert result.summary["depth"]["source"] == "prior (the arrivals do not determine it)"
    figures = scored(result)
    assert figures["median"] <= 0.5 and figures["rms"] <= 2.0 and figures["p95"] <= 4.5, figures
    assert figures["wrong_ok"] <= 3, figures


@pytest.mark.slow
def test_a_random_interval_on_the_8_hydrophones_at_depths_calibrates_with_the_depth_prior(tmp_path, monkeypatch):
    """U(20, 40) s (seed 1) on the 8 hydrophones at depths U(1, 5) m: the calibration made with the depth held (the
    receivers lie in one plane; it fitted each ping's depth freely before: 1,395 m/s) is within 3 of its standard
    errors of the full array's 1,416.9 m/s, and the track's RMS against the GPS is lower than with the speed of the
    calibration without the depth (the plane's rule and the depth given to the calibration patched away)."""
    from sblsim.orchestrator.tracks import track as track_module

    toa = read_toa(DATA / "toa.txt").toa
    path = lake_hald(tmp_path, "rbi", variants.random_interval_pings(toa, 20.0, 40.0, seed=1))
    receivers = _at_depths(tmp_path)

    def run():
        result = sblsim.replay_toa(path, receivers=receivers, truth=DATA / "gps.txt",
                                   receivers_kept="H2,H4,H6,H7,H11,H12,H17,H23", **ROBUST)
        return result.summary, scored(result)

    summary, figures = run()
    assert summary["depth"]["source"] == "prior (the arrivals do not determine it)"
    speed = summary["sound_speed"]
    assert abs(speed["sound_speed_m_s"] - 1416.9) <= 3 * speed["sigma_m_s"], speed
    first = track_module.sound_speed_stage
    monkeypatch.setattr(track_module, "plane_depth", lambda *args, **kwargs: None)
    monkeypatch.setattr(track_module, "sound_speed_stage", lambda toa, positions, *args, **kwargs: first(
        toa, positions, *args[:4], **{k: v for k, v in kwargs.items() if k != "water"}))
    before_summary, before = run()
    assert abs(before_summary["sound_speed"]["sound_speed_m_s"] - 1416.9) > 10.0, before_summary["sound_speed"]
    # (the rows 10 m off left ok are the quality checks' to count, not the speed's: 6 and 4 since a row needs a
    # measurement to spare to check itself, 3 and 3 before, 14 and 19 before unverified rows were flagged)
    assert figures["rms"] < before["rms"], (figures, before)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["8 hydrophones", "50 % removed"])
def test_lake_hald_thinned_with_the_sound_speed_it_calibrates_itself(case):
    """The authors' 8 hydrophones and half of the detections removed (seed 1), each calibrating its own sound speed
    (before: 1,429.8 and 1,426.4 m/s where the full array gives 1,416.9, the tracks 8 and 1.3 m RMS): the speed within
    3 of its own standard errors of the full array's, the 8 hydrophones at the issue's targets (median 0.45, RMS 2,
    95 % 4.5 m), the 50 % within 1.5 times the full track's figures."""
    options = {"receivers_kept": "H2,H4,H6,H7,H11,H12,H17,H23"} if case == "8 hydrophones" else \
        {"drop_detections": 0.5, "seed": 1}
    result = sblsim.replay_toa(DATA / "toa.txt", receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                               **options, **ROBUST)
    speed = result.summary["sound_speed"]
    assert abs(speed["sound_speed_m_s"] - 1416.9) <= 3 * speed["sigma_m_s"] + 0.5, speed
    figures = scored(result)
    targets = (0.45, 2.0, 4.5) if case == "8 hydrophones" else (1.5 * 0.20, 1.5 * 0.627, 1.5 * 0.88)
    assert figures["median"] <= targets[0] and figures["rms"] <= targets[1] and figures["p95"] <= targets[2], \
        figures


@pytest.mark.slow
def test_a_random_interval_on_the_thin_array_combines_its_weak_calibration_with_the_fallback(tmp_path, capsys):
    """The pings kept at U(20, 40) s (seed 1) on the authors' 8 hydrophones: their stretches give the speed to 5.6
    m/s only, above the 5 m/s the calibration accepts alone. It was thrown away for the default 1,500 m/s (83 m/s
    off: the track's median error 5.8 m); combined with that default's spread (51 m/s) it stays within 3 of its
    standard errors of the full array's 1,416.9 m/s, the console says so in one line, and the median error is below
    1.5 m (measured 1.08 m)."""
    import json

    from sblsim.orchestrator.cli import main

    toa = read_toa(DATA / "toa.txt").toa
    path = lake_hald(tmp_path, "rbi", variants.random_interval_pings(toa, 20.0, 40.0, seed=1))
    out = tmp_path / "out"
    assert main(["replay", str(path), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv"), "--truth",
                 str(DATA / "gps.txt"), "--receivers-kept", "H2,H4,H6,H7,H11,H12,H17,H23", "--smooth",
                 "--no-other-filters", "--out", str(out)]) == 0

    summary = json.loads((out / "summary.json").read_text())
    speed = summary["sound_speed"]
    assert speed["source"] == "calibrated with the fallback's prior" and speed["calibrated_sigma_m_s"] > 5.0, speed
    assert abs(speed["sound_speed_m_s"] - 1416.9) <= 3 * speed["sigma_m_s"], speed
    warning = [line for line in capsys.readouterr().err.splitlines() if "determine the sound speed only" in line]
    assert len(warning) == 1 and "the default 1500 m/s" in warning[0]
    assert json.loads((out / "score.json").read_text())["median_m"] <= 1.5


@pytest.mark.slow
def test_the_fixes_spliced_in_bring_a_thin_random_interval_track_out_of_a_wrong_minimum(tmp_path, monkeypatch):
    """U(20, 40) s (seed 1) on the authors' 8 hydrophones: without the fixes spliced in (:data:`SPLICE_ROUNDS` 0) the
    robust smoother stayed where a stretch weighs down most of its arrivals (1,127 against 772, 17.9 m RMS); with
    them its cost is lower and, against the GPS, its RMS and largest error smaller and fewer rows 10 m off."""
    from sblsim.models.tracking import starts

    toa = read_toa(DATA / "toa.txt").toa
    path = lake_hald(tmp_path, "rbi", variants.random_interval_pings(toa, 20.0, 40.0, seed=1))

    def run():
        result = sblsim.replay_toa(path, receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                                   receivers_kept="H2,H4,H6,H7,H11,H12,H17,H23", **ROBUST)
        errors = result.errors[result.errors["estimator"] == "robust"]["error_2d_m"]
        return result.summary["robust_smoother"]["cost"], errors

    cost, errors = run()
    monkeypatch.setattr(starts, "SPLICE_ROUNDS", 0)
    cost_before, before = run()
    assert cost < cost_before - 100.0, (cost, cost_before)
    assert np.sqrt(np.mean(errors**2)) < 0.5 * np.sqrt(np.mean(before**2)) and errors.max() < 0.5 * before.max()
    assert (errors > 10.0).sum() < (before > 10.0).sum()


RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0],
                      [140.0, 20.0], [30.0, 80.0]])


@pytest.mark.slow
def test_the_calibration_is_the_median_of_its_stretches_and_its_sigma_their_spread():
    """Simulated pings at 1,480 m/s: the speed within 3 standard errors; one stretch's arrivals all made late by 2 ms
    at half of the receivers (a wrong speed there) moves the median by less than it moves the one joint fit."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-4)
    toa, _, _ = tt.simulate_pings(RECEIVERS, 400, s, np.random.default_rng(5), speed=0.2, detection=0.9)
    found = tt.calibrate_sound_speed(toa, RECEIVERS, s.sigma_toa)
    assert abs(found.c - 1480.0) <= 3 * found.sigma and len(found.batches) == tt.BATCHES
    assert found.sigma == pytest.approx(1.2533 * np.std(found.batches, ddof=1) / np.sqrt(tt.BATCHES))
    bad = toa.copy()
    bad[:50, ::2] += 2e-3
    median = tt.calibrate_sound_speed(bad, RECEIVERS, s.sigma_toa).c
    joint = tt.calibrate_sound_speed_robust(bad, RECEIVERS, s.sigma_toa)[0]
    assert abs(median - 1480.0) < abs(joint - 1480.0), (median, joint)
    # a record too short for stretches: one joint fit of it all
    short = tt.calibrate_sound_speed(toa[:12], RECEIVERS, s.sigma_toa)
    assert short.batches == () and short.c == tt.calibrate_sound_speed_robust(toa[:12], RECEIVERS, s.sigma_toa)[0]
SEQUENCE = np.array([22.0, 37.0, 29.0, 31.0, 25.0, 39.0, 21.0, 33.0])


def simulated_track(kind: str, seed: int):
    """A tag of a ping type among 8 receivers (60 pings, half of the detections), tracked by the robust smoother, the
    RTS smoother and every causal filter over the schedule built from its own first arrivals; NEES and squared errors
    per estimator, and the smoothing bound's DRMS at the truth."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0 if kind == "sbi" else 30.0,
                           acceleration_psd=1e-5)
    toa, truth, emissions = tt.simulate_pings(RECEIVERS, 60, s, np.random.default_rng(seed), speed=0.05,
                                              detection=0.5, ping_type=kind, burst_interval=(20.0, 40.0),
                                              burst_sequence=SEQUENCE)
    cross = ps.crossing_time(RECEIVERS, s.sound_speed)
    schedule = ps.build_schedule(toa, kind, s.interval, s.jitter, s.interval_drift, cross,
                                 (20.0, 40.0) if kind == "rbi" else None, SEQUENCE if kind == "pbi" else None)
    fx, fe, fc, fu, _ = tt.fix_pings(toa, RECEIVERS, s.sound_speed, s.sigma_toa)
    tracker = tt.ToaTracker(RECEIVERS, s)
    record = tracker.run(toa, (fx, fc, fu.sum(axis=1)), fu, schedule)
    xs, Ps = tracker.smooth(record)
    k0 = record.start
    robust = tt.robust_track(toa[k0:], RECEIVERS, s, (fx[k0:], fe[k0:], fu[k0:]), xs[k0:], schedule.sliced(k0))
    tracks = {"robust": (robust.x[:, :2], robust.P[:, :2, :2]), "rts": (xs[k0:, :2], Ps[k0:, :2, :2])}
    for name, kind_of in tt.CAUSAL_TRACKERS.items():
        other = record if name == "ekf" else kind_of(RECEIVERS, s).run(toa, (fx, fc, fu.sum(axis=1)), fu, schedule)
        assert other.start == k0
        tracks[name] = (other.x_filtered[k0:, :2], other.P_filtered[k0:, :2, :2])
    out = {}
    for name, (k, p, P) in {name: (np.arange(k0, 60), *track) for name, track in tracks.items()}.items():
        ok = np.isfinite(p).all(axis=1)
        e = p[ok] - truth[k][ok]
        out[name] = (np.einsum("ki,kij,kj->k", e, np.linalg.inv(P[ok]), e), (e**2).sum(axis=1))
    velocity = np.gradient(truth, emissions, axis=0)
    bound = tb.pcrb(truth[k0:], velocity[k0:], emissions[k0:], np.isfinite(toa[k0:]), RECEIVERS, s.sound_speed,
                    s.sigma_toa, tb.MotionModel.of(s), schedule.sliced(k0))
    return out, bound.smoothed


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["sbi", "rbi", "pbi"])
def test_every_ping_type_is_consistent_and_near_its_bound_over_20_seeds(kind):
    """20 seeds of each ping type: the 2-D NEES of the robust smoother, the RTS smoother and every causal filter (the
    EKF, the sequential EKF, the UKF) in [1, 3], the robust smoother's RMS within 1.3 times the smoothing PCRB's (the
    bound holds the ping type's emission-time prior). (The UKF linearised once about its prediction: 7.1 at the
    random interval, its sigma points spread over a prediction tens of metres wide.)"""
    nees = {"robust": [], "rts": [], **{name: [] for name in tt.CAUSAL_TRACKERS}}
    squared, bounds = [], []
    for seed in range(20):
        out, smoothed = simulated_track(kind, seed)
        for name in nees:
            nees[name].extend(out[name][0])
        squared.extend(out["robust"][1])
        bounds.extend(smoothed**2)
    for name, values in nees.items():
        assert 1.0 <= np.mean(values) <= 3.0, (kind, name, np.mean(values))
    assert np.sqrt(np.mean(squared)) <= 1.3 * np.sqrt(np.mean(bounds)), (np.sqrt(np.mean(squared)),
                                                                        np.sqrt(np.mean(bounds)))


def test_a_track_started_1_km_off_ends_on_the_truth_or_flagged():
    """The robust smoother started only from a track 1 km off the truth: where it ends more than 10 m from the truth,
    those rows are flagged; none is ok and wrong."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-4)
    toa, truth, emissions = tt.simulate_pings(RECEIVERS, 80, s, np.random.default_rng(11), speed=0.3, detection=0.6)
    fx, fe, fc, fu, chi2 = tt.fix_pings(toa, RECEIVERS, s.sound_speed, s.sigma_toa)
    wrong = np.zeros((80, 6))
    wrong[:, :2] = truth + [1000.0, 0.0]
    wrong[:, 4] = emissions
    wrong[:, 5] = s.interval
    track = tt.robust_smooth(toa, RECEIVERS, s, [wrong])
    trusted = qa.trusted_fixes(fx, fc, fu.sum(axis=1), np.isfinite(toa).sum(axis=1), chi2, 2)
    quality = qa.check_track(track.x[:, 4], track.x[:, :2], track.P[:, :2, :2], fx, fc, trusted,
                             explained=qa.explained(toa, RECEIVERS, track.x[:, :2], s.sound_speed, s.sigma_toa),
                             fix_used=qa.explained(toa, RECEIVERS, fx, s.sound_speed, s.sigma_toa)).quality
    error = np.hypot(*(track.x[:, :2] - truth).T)
    assert not ((error > 10.0) & (quality != "flagged")).any(), (error.round(1), quality)


def _hydrophones(tmp_path: Path, change) -> Path:
    import pandas as pd

    table = pd.read_csv(DATA / "hydrophones.csv")
    change(table)
    path = tmp_path / "receivers.csv"
    table.to_csv(path, index=False)
    return path


def _first_rows(tmp_path: Path, rows: list[int]) -> Path:
    lines = (DATA / "toa.txt").read_text().splitlines()
    path = tmp_path / "toa.txt"
    path.write_text("\n".join(lines[r] for r in rows) + "\n")
    return path


def _far_truth(tmp_path: Path) -> Path:
    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    path = tmp_path / "gps.txt"
    np.savetxt(path, gps + [0.0, 0.0, 1e6], header="x y t", comments="")
    return path


@pytest.mark.parametrize("case,message", [
    ("at one point", "lie within 0 m of each other; allowed: an array at least 1 m across"),
    ("in kilometres", "allowed: an array at least 1 m across (positions in metres)"),
    ("in hectometres", "allowed: the receivers' positions in metres"),
    ("on a line", "lie on one line"),
    ("rows reversed", "is not after row"),
    ("a truth elsewhere", "do not overlap the pings'"),
])
def test_what_cannot_be_tracked_is_refused_in_one_line_and_writes_nothing(tmp_path, capsys, case, message):
    """The tracebacks of before (LinAlgError, TypeError), and the silent wrong answers (collinear receivers, positions
    in km), whether or not the sound speed is given: one line, exit 2, no folder."""
    from sblsim.orchestrator.cli import main

    toa, receivers, truth = DATA / "toa.txt", DATA / "hydrophones.csv", DATA / "gps.txt"
    if case == "at one point":
        receivers = _hydrophones(tmp_path, lambda t: t.update(t[["x_m", "y_m"]].where(t["x_m"].isna(), 0.0)))
    elif case in ("in kilometres", "in hectometres"):
        scale = 1000.0 if case == "in kilometres" else 100.0
        receivers = _hydrophones(tmp_path, lambda t: t.update(t[["x_m", "y_m"]] / scale))
    elif case == "on a line":
        receivers = _hydrophones(tmp_path, lambda t: t.update(t[["y_m"]].where(t["y_m"].isna(), 0.0)))
    elif case == "rows reversed":
        toa = _first_rows(tmp_path, list(range(40, 0, -1)))
    else:
        truth = _far_truth(tmp_path)
    for speed in ([], ["--sound-speed", "1417"]):
        out = tmp_path / f"out{len(speed)}"
        code = main(["replay", str(toa), "--format", "toa", "--receivers", str(receivers), "--truth", str(truth),
                     "--out", str(out), *speed])
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, (case, err)
        assert not out.exists()


def test_two_pings_with_the_speed_given_are_tracked_and_scored(tmp_path, capsys):
    """Two pings (before: an IndexError in the bound's thirds): tracked, scored, written; the motion noise given
    is the one used."""
    import json

    from sblsim.orchestrator.cli import main

    toa = _first_rows(tmp_path, [100, 101])
    assert main(["replay", str(toa), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv"), "--truth",
                 str(DATA / "gps.txt"), "--sound-speed", "1417", "--acceleration-psd", "0.002",
                 "--out", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o" / "score.json").is_file() and "ping type" in capsys.readouterr().out
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["motion"] == {"model": "moving", "acceleration_psd_m2_s3": 0.002, "source": "given"}


@pytest.mark.slow
def test_lake_hald_receivers_surveyed_to_1_m_with_their_survey_error(tmp_path):
    """The hydrophones moved by 1 m per axis (seed 1), as a survey to 1 m gives them: the track the same with or
    without --survey-sigma 1 (the positions as surveyed either way), its NEES against the GPS from far above 3 to
    within [1, 3] with it (before: the covariance knew nothing of the survey)."""
    import pandas as pd

    table = pd.read_csv(DATA / "hydrophones.csv")
    rng = np.random.default_rng(1)
    placed = table["x_m"].notna()
    for axis in ("x_m", "y_m"):
        table.loc[placed, axis] += rng.normal(0.0, 1.0, placed.sum())
    table.to_csv(tmp_path / "hydrophones.csv", index=False)
    plain, surveyed = (sblsim.replay_toa(DATA / "toa.txt", receivers=tmp_path / "hydrophones.csv",
                                         truth=DATA / "gps.txt", survey_sigma=sigma, **ROBUST) for sigma in (None, 1.0))
    assert np.array_equal(plain.track[["x", "y"]].to_numpy(), surveyed.track[["x", "y"]].to_numpy())
    assert plain.score["nees"] > 10.0 and 1.0 <= surveyed.score["nees"] <= 3.0, (plain.score["nees"],
                                                                                  surveyed.score["nees"])
