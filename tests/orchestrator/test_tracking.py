"""The inverted-LBL slice: the TOA reader against an independent parse and on hostile files, the TOA model against
numpy, the RTS smoother against FilterPy, the Lake Hald track against GPS and U-MAP, and the simulated pings'
sound-speed calibration and NEES."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import sblsim
from sblsim.models.errors import ModelError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking.quality import REASONS
from sblsim.orchestrator.readers.receivers_file import read_receivers
from sblsim.orchestrator.readers.time_series import read_track
from sblsim.orchestrator.readers.toa_matrix import read_toa

# the recording is in the repository (tests and docs), not in the wheel
DATA = Path(__file__).resolve().parents[2] / "data" / "lake-hald"


def stats(e: np.ndarray) -> tuple[float, float]:
    return float(np.median(e)), float(np.sqrt(np.mean(e**2)))


def test_reader_reads_lake_hald_as_genfromtxt():
    expected = np.genfromtxt(DATA / "toa.txt")
    got = read_toa(DATA / "toa.txt").toa
    assert got.shape == expected.shape == (3244, 28)
    assert np.array_equal(np.isnan(got), np.isnan(expected))
    assert np.array_equal(got[np.isfinite(got)], expected[np.isfinite(expected)])
    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    assert np.array_equal(read_track(DATA / "gps.txt", "truth"), gps[:, [2, 0, 1]])
    r = read_receivers(DATA / "hydrophones.csv")
    assert r.names[13] == "H14" and np.isnan(r.positions[13]).all()
    assert np.allclose(r.positions[1], [143.34, -78.85])


@pytest.mark.parametrize("cell, word", [("nan", "not allowed"), ("inf", "not allowed"), ("-0.5", "not allowed"),
                                        ("/etc/passwd", "not allowed")])
def test_hostile_cells_refused_in_one_line(tmp_path, cell, word):
    path = tmp_path / "toa.txt"
    path.write_text(f"0.1 NA 0.2\n0.3 {cell} 0.4\n")
    with pytest.raises(ModelError) as info:
        read_toa(path)
    message = str(info.value)
    assert "\n" not in message and word in message and "line 2" in message and "[0, 1e+10]" in message


def test_large_and_device_files_refused(tmp_path, monkeypatch):
    big = tmp_path / "big.txt"
    big.write_bytes(b"0.1 0.2\n" * 2_000)
    monkeypatch.setattr("sblsim.orchestrator.readers.toa_matrix.MAX_MATRIX_PINGS", 1_000)  # (read in pieces: 4 M)
    with pytest.raises(ModelError, match="holds more than 1,000 pings; allowed at most 1,000"):
        read_toa(big)
    link = tmp_path / "zero.txt"
    os.symlink("/dev/zero", link)
    with pytest.raises(ModelError, match="not a regular file"):
        read_toa(link)
    toml = tmp_path / "receivers.toml"
    toml.write_text('include = "/etc/passwd"\n[[receiver]]\nname = "a"\nx_m = 0\ny_m = 0\n')
    with pytest.raises(ModelError, match="expected \\[\\[receiver\\]\\] tables only"):
        read_receivers(toml)


def test_command_refuses_bad_input_and_writes_nothing(tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    bad = tmp_path / "toa.txt"
    bad.write_text("0.1 NA\n0.2 nan\n")
    out = tmp_path / "out"
    status = main(["replay", str(bad), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv"), "--out",
                   str(out)])
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "toa" in err[0] and not out.exists()


def test_toa_model_against_numpy():
    rng = np.random.default_rng(3)
    receivers = rng.uniform(-100, 100, (7, 2))
    p, te, c = np.array([12.0, -30.0]), 5.25, 1437.0
    toa, J = tt.toa_model(p, te, receivers, c)
    d = np.sqrt(((p - receivers) ** 2).sum(axis=1))
    assert np.allclose(toa, te + d / c, rtol=0, atol=1e-12)
    assert np.allclose(J[:, :2], (p - receivers) / d[:, None] / c, atol=1e-15) and np.all(J[:, 2] == 1)


def test_rts_against_filterpy():
    from filterpy.kalman import rts_smoother

    rng = np.random.default_rng(1)
    m, s = 40, 6
    F = np.eye(s) + 0.1 * rng.normal(size=(s, s))
    Q = np.diag(rng.uniform(0.01, 0.1, s))
    xf = rng.normal(size=(m, s))
    A = rng.normal(size=(m, s, s))
    Pf = A @ A.transpose(0, 2, 1) + np.eye(s)
    Fs, Qs = np.tile(F, (m, 1, 1)), np.tile(Q, (m, 1, 1))
    xp = np.einsum("ij,mj->mi", F, np.roll(xf, 1, axis=0))
    Pp = F @ np.roll(Pf, 1, axis=0) @ F.T + Q
    xs, Ps = tt.rts_smooth(xf, Pf, xp, Pp, Fs)
    x_ref, P_ref, _, _ = rts_smoother(xf, Pf, Fs, Qs)
    assert np.abs(xs - x_ref).max() <= 1e-9 and np.abs(Ps - P_ref).max() <= 1e-9


def one_ping(seed: int):
    """A ping heard by five receivers around a predicted state (x, P) of realistic spread, no gate: receivers,
    settings, x, P and the times of arrival drawn from a truth inside P."""
    rng = np.random.default_rng(seed)
    receivers = rng.uniform(-150, 150, (5, 2))
    s = tt.TrackerSettings(sound_speed=1430.0, sigma_toa=2e-4, gate=1e9, gate_probability=1.0 - 1e-15)
    x = np.array([20.0, -35.0, 0.4, -0.2, 812.5, 2.0])
    A = np.array([3.0, 3.0, 0.3, 0.3, 1e-3, 1e-3])[:, None] * rng.normal(size=(6, 6))
    P = A @ A.T + np.diag([1.0, 1.0, 0.1, 0.1, 1e-6, 1e-6])
    truth = x + rng.multivariate_normal(np.zeros(6), P)
    toa = truth[4] + np.hypot(*(truth[:2] - receivers).T) / s.sound_speed + rng.normal(0, s.sigma_toa, 5)
    return receivers, s, x, P, toa


def test_ukf_update_against_filterpy():
    """One unscented update of a ping heard by five receivers (no gate), linearised once, equals FilterPy's
    UnscentedKalmanFilter with the same scaled sigma points (its prediction through the identity without process
    noise gives back the state and covariance), to 1e-9; iterated, it equals the posterior linearisation filter
    written again with FilterPy's sigma points and unscented transform (García-Fernández et al. 2015), to 1e-9, and
    lies nearer the truth's emission-and-position solution than the plain update."""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter, unscented_transform

    receivers, s, x, P, toa = one_ping(3)
    got_x, got_P, used = tt.ToaUkfTracker(receivers, s, iterations=1).update(x, P, toa)
    assert used.all()

    def h(z):
        return z[4] + np.hypot(*(z[:2] - receivers).T) / s.sound_speed

    points = MerweScaledSigmaPoints(6, alpha=tt.UKF_ALPHA, beta=tt.UKF_BETA, kappa=tt.UKF_KAPPA)
    ukf = UnscentedKalmanFilter(6, 5, 1.0, h, lambda z, dt: z, points)
    ukf.x, ukf.P, ukf.Q, ukf.R = x.copy(), P.copy(), np.zeros((6, 6)), s.sigma_toa**2 * np.eye(5)
    ukf.predict()
    ukf.update(toa)
    assert np.abs(got_x - ukf.x).max() <= 1e-9 * np.abs(ukf.x).max()
    assert np.abs(got_P - ukf.P).max() <= 1e-9 * np.abs(ukf.P).max()

    R = s.sigma_toa**2 * np.eye(5)
    at, spread = x.copy(), P.copy()
    for _ in range(tt.UKF_ITERATIONS):
        sigmas = points.sigma_points(at, spread)
        Z = np.array([h(p) for p in sigmas])
        mean, Pzz = unscented_transform(Z, points.Wm, points.Wc)
        Pxz = sum(w * np.outer(p - at, z - mean) for w, p, z in zip(points.Wc, sigmas, Z))
        H = np.linalg.solve(spread, Pxz).T
        b, omega = mean - H @ at, Pzz - H @ spread @ H.T
        S = H @ P @ H.T + omega + R
        K = P @ H.T @ np.linalg.inv(S)
        moved = x + K @ (toa - H @ x - b)
        at, spread, done = moved, P - K @ S @ K.T, np.abs(moved[:2] - at[:2]).max() < tt.UKF_TOLERANCE
        if done:
            break
    iterated_x, iterated_P, used = tt.ToaUkfTracker(receivers, s).update(x, P, toa)
    assert used.all()
    assert np.abs(iterated_x - at).max() <= 1e-9 * np.abs(at).max()
    assert np.abs(iterated_P - spread).max() <= 1e-9 * np.abs(spread).max()
    assert not np.allclose(iterated_x, got_x, rtol=0, atol=1e-6)  # the iterations did something


def test_sequential_update_against_filterpy():
    """One ping's five arrivals, one at a time (no gate), equal FilterPy's ExtendedKalmanFilter updated with each
    arrival in turn, the model linearised at the prediction (sequential processing), to 1e-9."""
    from filterpy.kalman import ExtendedKalmanFilter

    receivers, s, x, P, toa = one_ping(4)
    got_x, got_P, used = tt.ToaSeqTracker(receivers, s).update(x, P, toa)
    assert used.all()

    ekf = ExtendedKalmanFilter(6, 1)
    ekf.x, ekf.P = x.copy(), P.copy()
    for r, z in zip(receivers, toa):
        d = x[:2] - r  # the model and its Jacobian at the prediction
        h = np.array([[*(d / np.hypot(*d) / s.sound_speed), 0.0, 0.0, 1.0, 0.0]])
        predicted = x[4] + np.hypot(*d) / s.sound_speed
        ekf.update(np.array([z]), lambda state, h=h: h, lambda state, h=h, p=predicted: p + h @ (state - x),
                   R=np.array([[s.sigma_toa**2]]))
    assert np.abs(got_x - ekf.x).max() <= 1e-9 * np.abs(ekf.x).max()
    assert np.abs(got_P - ekf.P).max() <= 1e-9 * np.abs(ekf.P).max()


@pytest.mark.parametrize("kind", [pytest.param("ukf", marks=pytest.mark.slow), "ekf-seq"])
def test_ukf_and_ekf_seq_are_consistent_on_simulated_pings(kind):
    """The UKF and the sequential EKF over 20 seeds of simulated pings (Lake Hald's array, 30 % of the arrivals
    heard): the 2-D NEES against the exact truth in [1, 3] (2 if consistent), and the RMS error within 10 % of the
    EKF's."""
    receivers = np.genfromtxt(DATA / "hydrophones.csv", delimiter=",", skip_header=1, usecols=(1, 2))
    receivers = receivers[np.isfinite(receivers).all(axis=1)]
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4)
    nees, other_sq, ekf_sq = [], [], []
    for seed in range(20):
        rng = np.random.default_rng(200 + seed)
        toa, truth, _ = tt.simulate_pings(receivers, 60, s, rng, speed=0.3, detection=0.3)
        other = tt.CAUSAL_TRACKERS[kind](receivers, s).run(toa)
        ekf = tt.ToaTracker(receivers, s).run(toa)
        k = np.arange(max(other.start, ekf.start), len(toa))
        e = other.x_filtered[k, :2] - truth[k]
        nees.append(np.mean(np.einsum("mi,mi->m", e, np.linalg.solve(other.P_filtered[k][:, :2, :2],
                                                                        e[..., None])[..., 0])))
        other_sq.append(np.mean((e**2).sum(axis=1)))
        ekf_sq.append(np.mean(((ekf.x_filtered[k, :2] - truth[k]) ** 2).sum(axis=1)))
    assert 1.0 <= np.mean(nees) <= 3.0, np.mean(nees)
    assert abs(np.sqrt(np.mean(other_sq) / np.mean(ekf_sq)) - 1.0) < 0.1


THINNED = ["H2", "H4", "H6", "H7", "H11", "H12", "H17", "H23"]  # the authors' 8 of the 28 (docs/tracking.md)


def gps_errors(t: np.ndarray, x: np.ndarray, y: np.ndarray, gps: np.ndarray, lag: float = 0.0) -> np.ndarray:
    """An independent scoring: the GPS (rows x, y, t) interpolated at t + lag; 2-D errors inside its span."""
    inside = (t >= gps[0, 2]) & (t <= gps[-1, 2])
    return np.hypot(x - np.interp(t + lag, gps[:, 2], gps[:, 0]), y - np.interp(t + lag, gps[:, 2], gps[:, 1]))[inside]


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    out = tmp_path_factory.mktemp("lake") / "full"
    # the default: the sound speed calibrated (the joint soft-L1 fit)
    return sblsim.replay_toa(DATA / "toa.txt", receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                             reference=DATA / "umap.txt", out=out)


@pytest.mark.slow
def test_lake_hald_beats_umap(full):
    r = full
    umap = np.genfromtxt(DATA / "umap.txt", skip_header=1)
    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    median_umap, rms_umap = stats(gps_errors(umap[:, 2], umap[:, 0], umap[:, 1], gps))
    e = gps_errors(r.track["time"].to_numpy(), r.track["x"].to_numpy(), r.track["y"].to_numpy(), gps)
    median, rms = stats(e)
    assert median < median_umap and rms < rms_umap and len(r.track) >= len(umap)
    assert r.summary["sound_speed"]["source"] == "calibrated"
    fix = r.estimates[r.estimates["estimator"] == "fix"]
    assert np.median(gps_errors(fix["time"].to_numpy(), fix["x"].to_numpy(), fix["y"].to_numpy(), gps)) <= 0.5
    # score.json: the issue's keys, the track's (the smoother's) figures, the reference's under "others"
    assert list(r.score)[:9] == ["n_pings", "n_fixed", "mean_m", "median_m", "rms_m", "p90_m", "p95_m", "nees",
                                 "lag_s"]
    assert r.score["n_pings"] == 3244 and r.score["n_fixed"] == len(r.track)
    assert np.isclose(r.score["median_m"], median, rtol=1e-12) and np.isclose(r.score["rms_m"], rms, rtol=1e-12)
    assert np.isclose(r.score["p95_m"], np.percentile(e, 95), rtol=1e-12)
    assert np.isclose(r.score["others"]["reference"]["rms_m"], rms_umap, rtol=1e-12)


@pytest.mark.slow
def test_written_files_keep_the_issue_names(full):
    import json

    import pandas as pd

    track = pd.read_csv(full.out / "track.csv")
    assert list(track.columns) == ["time", "x", "y", "sigma_x", "sigma_y", "receivers_heard", "quality",
                                   "quality_reason"]
    assert set(track["quality"]) <= {"ok", "restart", "flagged"}
    # a flagged row names its reasons, of the documented ones; a row not flagged none
    why = track["quality_reason"].fillna("")
    flagged = track["quality"] == "flagged"
    assert (why[flagged] != "").all() and (why[~flagged] == "").all() and flagged.any()
    assert set(";".join(why[flagged]).split(";")) <= {name for _, name in REASONS}
    robust = full.estimates[full.estimates["estimator"] == "robust"]
    assert np.allclose(track["x"], robust["x"], rtol=0, atol=1e-9) and len(track) == len(robust)
    score = json.loads((full.out / "score.json").read_text())
    assert list(score)[:9] == list(full.score)[:9] and score["estimator"] == "robust"
    errors = pd.read_csv(full.out / "errors.csv")
    assert set(errors["estimator"]) == {"robust", "rts", "ekf", "ekf-seq", "ukf", "fix", "reference"}
    assert not (full.out / "tracks.csv").exists()


@pytest.mark.slow
def test_a_fix_the_checks_do_not_trust_is_flagged(full):
    """The single-ping fixes' rows: one with no arrival to spare (three in 2-D) can fit a reflection exactly and is
    never trusted, so never ``ok``; among the rows left ``ok`` a share more than 10 m from the GPS well below the
    flagged rows' (numpy, the GPS interpolated as the score does)."""
    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    fix = full.estimates[full.estimates["estimator"] == "fix"]
    assert (fix.loc[fix["receivers_heard"] <= 3, "quality"] == "flagged").all()
    assert (fix["receivers_heard"] <= 3).sum() >= 50
    fix = fix[(fix["time"] >= gps[0, 2]) & (fix["time"] <= gps[-1, 2])]  # the GPS's span, as gps_errors keeps
    e = gps_errors(fix["time"].to_numpy(), fix["x"].to_numpy(), fix["y"].to_numpy(), gps)
    ok = (fix["quality"] == "ok").to_numpy()
    assert np.mean(e[ok] > 10) < 0.2 * np.mean(e[~ok] > 10), (np.mean(e[ok] > 10), np.mean(e[~ok] > 10))


@pytest.mark.slow
def test_thinned_array_gives_larger_errors(full):
    """The authors' 8-hydrophone array against the full one, each scored here against the GPS."""
    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    thin = sblsim.replay_toa(DATA / "toa.txt", receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                             sound_speed=full.summary["sound_speed"]["sound_speed_m_s"], receivers_kept=THINNED)
    assert thin.summary["receivers"] == THINNED
    rows = [r.track for r in (full, thin)]
    (m_full, rms_full), (m_thin, rms_thin) = (stats(gps_errors(t["time"].to_numpy(), t["x"].to_numpy(),
                                                               t["y"].to_numpy(), gps)) for t in rows)
    assert m_thin > m_full and rms_thin > rms_full and len(thin.track) < len(full.track)


def test_lag_is_estimated_and_not_applied():
    from sblsim.orchestrator.tracks.scoring import score

    rng = np.random.default_rng(5)
    tt_ = np.arange(0.0, 600.0, 1.0)
    truth = np.column_stack([tt_, 50 * np.cos(tt_ / 60), 50 * np.sin(tt_ / 60)])  # 0.83 m/s on a circle
    t = np.arange(40.0, 560.0, 2.0)
    lag = 2.3
    xy = np.column_stack([np.interp(t + lag, tt_, truth[:, 1]), np.interp(t + lag, tt_, truth[:, 2])])
    xy += 0.05 * rng.normal(size=xy.shape)
    stats_, err, _ = score(t, xy, truth)
    assert abs(stats_["lag_s"] - lag) < 0.05
    e = gps_errors(t, xy[:, 0], xy[:, 1], truth[:, [1, 2, 0]])
    assert np.isclose(stats_["median_m"], np.median(e), rtol=1e-12) and np.median(e) > 1.5  # not applied
    assert np.isclose(stats_["along_track_m"], 0.83 * lag, rtol=0.1)  # a lag seen as an along-track offset


def test_no_lag_is_searched_against_a_truth_that_does_not_move():
    """A surveyed position (the same point at every time): no lag (None), the errors scored; the same estimates
    against a truth that moves 2 m over the span: a lag found."""
    from sblsim.orchestrator.tracks.scoring import score

    rng = np.random.default_rng(6)
    t = np.arange(40.0, 560.0, 2.0)
    still = np.array([[0.0, 10.0, -5.0], [600.0, 10.0, -5.0]])
    xy = np.array([10.0, -5.0]) + 0.3 * rng.normal(size=(len(t), 2))
    stats_, err, _ = score(t, xy, still)
    assert stats_["lag_s"] is None and stats_["rms_at_lag_m"] is None
    assert np.isclose(stats_["median_m"], np.median(np.hypot(xy[:, 0] - 10.0, xy[:, 1] + 5.0)), rtol=1e-12)
    moving = still.copy()
    moving[1, 1] += 2.0
    assert score(t, xy, moving)[0]["lag_s"] is not None


def test_drop_detections_is_seeded_and_takes_its_share():
    from sblsim.orchestrator.tracks.thinning import drop_detections

    toa = read_toa(DATA / "toa.txt").toa
    heard = np.isfinite(toa)
    a, n = drop_detections(toa, 0.25, 1)
    b, _ = drop_detections(toa, 0.25, 1)
    c, _ = drop_detections(toa, 0.25, 2)
    kept = np.isfinite(a)
    assert np.array_equal(kept, np.isfinite(b)) and not np.array_equal(kept, np.isfinite(c))
    assert not (kept & ~heard).any() and np.array_equal(a[kept], toa[kept]) and n == int((heard & ~kept).sum())
    assert abs(n / heard.sum() - 0.25) < 4 * np.sqrt(0.25 * 0.75 / heard.sum())


@pytest.mark.parametrize("option, word", [(["--drop-detections", "1.5"], "--drop-detections"),
                                          (["--receivers-kept", "H2,H99"], "H99"),
                                          (["--seed", "3"], "--seed")])
def test_thinning_options_refused_in_one_line(tmp_path, capsys, option, word):
    from sblsim.orchestrator.cli import main

    out = tmp_path / "out"
    status = main(["replay", str(DATA / "toa.txt"), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv"),
                   "--sound-speed", "1420", "--out", str(out), *option])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and word in err[0] and not out.exists()


def test_simulated_sound_speed_and_nees():
    receivers = np.genfromtxt(DATA / "hydrophones.csv", delimiter=",", skip_header=1, usecols=(1, 2))
    receivers = receivers[np.isfinite(receivers).all(axis=1)]
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4)
    nees, speeds = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        toa, truth, _ = tt.simulate_pings(receivers, 60, s, rng, speed=0.3, detection=0.3)
        if seed < 4:
            speeds.append(tt.calibrate_sound_speed_robust(toa, receivers, s.sigma_toa, max_pings=60))
        tracker = tt.ToaTracker(receivers, s)
        record = tracker.run(toa)
        xs, Ps = tracker.smooth(record)
        k = np.arange(record.start, len(toa))
        e = xs[k, :2] - truth[k]
        nees.append(np.mean(np.einsum("mi,mi->m", e, np.linalg.solve(Ps[k][:, :2, :2], e[..., None])[..., 0])))
    # 3 m/s: a relative error of 0.2 %, i.e. 0.2 m at 100 m, about the timing noise's own 0.21 m
    assert all(abs(c - 1420.0) <= 3.0 for c, _, _ in speeds)
    assert 1.0 <= np.mean(nees) <= 3.0


def late_arrivals(toa: np.ndarray, rng: np.random.Generator, share: float = 0.05) -> np.ndarray:
    """A share of the arrivals made 1 to 3 ms late (multipath)."""
    late = np.isfinite(toa) & (rng.random(toa.shape) < share)
    return np.where(late, toa + rng.uniform(1e-3, 3e-3, toa.shape), toa)


def test_robust_calibration_finds_the_simulated_sound_speed():
    """Simulated pings in the Lake Hald array at 1,420 m/s, 5 % of the arrivals 1 to 3 ms late: the joint soft-L1
    calibration within 1.5 m/s of the truth on every seed (about 3 of its standard errors)."""
    receivers = np.genfromtxt(DATA / "hydrophones.csv", delimiter=",", skip_header=1, usecols=(1, 2))
    receivers = receivers[np.isfinite(receivers).all(axis=1)]
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4)
    for seed in range(4):
        rng = np.random.default_rng(seed)
        toa, _, _ = tt.simulate_pings(receivers, 80, s, rng, speed=0.3, detection=0.3)
        c, sigma_c, _ = tt.calibrate_sound_speed_robust(late_arrivals(toa, rng), receivers, s.sigma_toa)
        assert abs(c - 1420.0) <= 1.5 and 0 < sigma_c < 1.0


def test_robust_calibration_against_scipy_least_squares():
    """The same objective minimised by scipy's least_squares(loss="soft_l1") over c and every ping's position and
    emission time, started near the truth: the same sound speed."""
    from scipy.optimize import least_squares

    receivers = np.genfromtxt(DATA / "hydrophones.csv", delimiter=",", skip_header=1, usecols=(1, 2))
    receivers = receivers[np.isfinite(receivers).all(axis=1)]
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4)
    rng = np.random.default_rng(7)
    toa, truth, emissions = tt.simulate_pings(receivers, 15, s, rng, speed=0.3, detection=0.4)
    toa = late_arrivals(toa, rng)
    c, _, pings = tt.calibrate_sound_speed_robust(toa, receivers, s.sigma_toa)
    rows = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= 5)
    assert pings == len(rows)
    i, j = np.nonzero(np.isfinite(toa[rows]))
    y, k = toa[rows][i, j], len(rows)

    def residuals(z):
        p, te = z[1:1 + 2 * k].reshape(k, 2), z[1 + 2 * k:]
        return (y - te[i] - np.linalg.norm(p[i] - receivers[j], axis=1) / z[0]) / s.sigma_toa

    z0 = np.concatenate([[1425.0], truth[rows].ravel() + 0.5, emissions[rows]])
    ref = least_squares(residuals, z0, loss="soft_l1", f_scale=tt.ROBUST_SCALE,
                        x_scale=np.r_[1.0, np.full(2 * k, 0.1), np.full(k, 1e-4)], xtol=1e-10, ftol=1e-10, gtol=1e-10)
    assert abs(c - ref.x[0]) <= 0.01


def test_robust_calibration_with_the_tag_s_depth_against_scipy_least_squares():
    """Receivers 1-5 m deep, a tag whose depth sensor reads its depth to 0.3 m: the calibration's objective with
    each ping's depth term, ``Σ 2 (√(1 + (r/f)²) − 1) + Σ ((z + depth) / σ_depth)²``, minimised by scipy's
    least_squares (a callable loss: soft-L1 on the arrivals, none on the depths), gives the same sound speed; the
    depth makes the speed better determined; a depth at receivers in 2-D, or not one per ping, is refused."""
    from scipy.optimize import least_squares

    plan = np.genfromtxt(DATA / "hydrophones.csv", delimiter=",", skip_header=1, usecols=(1, 2))
    plan = plan[np.isfinite(plan).all(axis=1)]
    rng = np.random.default_rng(8)
    receivers = np.column_stack([plan, -rng.uniform(1.0, 5.0, len(plan))])
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4)
    toa, truth, emissions = tt.simulate_pings(receivers, 15, s, rng, speed=0.3, detection=0.4)
    toa = late_arrivals(toa, rng)
    depth = -truth[:, 2] + rng.normal(scale=0.3, size=len(truth))
    c, sigma, pings = tt.calibrate_sound_speed_robust(toa, receivers, s.sigma_toa, depth=depth, depth_sigma=0.3)
    rows = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= 6)
    assert pings == len(rows)
    i, j = np.nonzero(np.isfinite(toa[rows]))
    y, k, scale = toa[rows][i, j], len(rows), tt.ROBUST_SCALE

    def residuals(z):
        p, te = z[1:1 + 3 * k].reshape(k, 3), z[1 + 3 * k:]
        arrivals = (y - te[i] - np.linalg.norm(p[i] - receivers[j], axis=1) / z[0]) / s.sigma_toa
        return np.concatenate([arrivals, scale * (p[:, 2] + depth[rows]) / 0.3])

    def loss(z):  # soft-L1 on the arrivals' residuals, the depths' squared as they are
        out = np.vstack([2 * (np.sqrt(1 + z) - 1), 1 / np.sqrt(1 + z), -0.5 * (1 + z) ** -1.5])
        out[:, len(i):] = [z[len(i):], np.ones(k), np.zeros(k)]
        return out

    z0 = np.concatenate([[1425.0], truth[rows].ravel() + 0.5, emissions[rows]])
    ref = least_squares(residuals, z0, loss=loss, f_scale=scale,
                        x_scale=np.r_[1.0, np.full(3 * k, 0.1), np.full(k, 1e-4)], xtol=1e-10, ftol=1e-10, gtol=1e-10)
    assert abs(c - ref.x[0]) <= 0.01, (c, ref.x[0])
    assert sigma < tt.calibrate_sound_speed_robust(toa, receivers, s.sigma_toa)[1]
    for bad, where in ((depth[:-1], receivers), (depth, plan)):
        for calibrate in (tt.calibrate_sound_speed_robust, tt.calibrate_sound_speed):
            with pytest.raises(ModelError, match="^depth_m: .* readings for 15 pings at receivers in"):
                calibrate(toa, where, s.sigma_toa, depth=bad)


def test_score_in_3d_against_numpy():
    from sblsim.orchestrator.tracks.scoring import score

    rng = np.random.default_rng(2)
    tt_ = np.arange(0.0, 100.0, 1.0)
    truth = np.column_stack([tt_, np.cos(tt_ / 10), np.sin(tt_ / 10), -5 - 0.01 * tt_])
    t = rng.uniform(1, 99, 40)
    g = np.column_stack([np.interp(t, tt_, truth[:, k]) for k in (1, 2, 3)])
    p = g + rng.normal(scale=0.3, size=g.shape)
    stats_, err, err3 = score(t, p, truth)
    e3 = np.sqrt(((p - g) ** 2).sum(axis=1))
    assert np.allclose(err3, e3, atol=1e-12) and np.allclose(err, np.hypot(*(p - g)[:, :2].T), atol=1e-12)
    assert np.isclose(stats_["p90_3d_m"], np.percentile(e3, 90)) and np.isclose(stats_["rms_3d_m"],
                                                                               np.sqrt(np.mean(e3**2)))


def test_the_nees_holds_the_truth_s_own_error_against_numpy():
    """score's 2-D NEES with the truth's error σ per axis in the budget: each estimate's eᵀ(P + σ² I)⁻¹e by numpy,
    their mean and median; a consistent estimator against a truth of that error gives a mean near 2 and a median
    near 2 ln 2, and without σ in the budget more."""
    from sblsim.orchestrator.tracks.scoring import score

    rng = np.random.default_rng(4)
    tt_ = np.arange(0.0, 2000.0, 1.0)
    truth = np.column_stack([tt_, 0.3 * tt_, np.zeros_like(tt_)])
    t = np.arange(1.0, 1999.0, 2.0)
    g = np.column_stack([np.interp(t, tt_, truth[:, k]) for k in (1, 2)])
    a = rng.normal(size=(len(t), 2, 2)) * 0.2
    cov = a @ a.transpose(0, 2, 1) + 0.01 * np.eye(2)
    sigma = 0.3
    p = g + np.einsum("mij,mj->mi", np.linalg.cholesky(cov + sigma**2 * np.eye(2)), rng.normal(size=(len(t), 2)))
    stats_, _, _ = score(t, p, truth, cov, truth_sigma=sigma)
    e = p - g
    nees = np.einsum("mi,mi->m", e, np.linalg.solve(cov + sigma**2 * np.eye(2), e[..., None])[..., 0])
    assert np.isclose(stats_["nees"], nees.mean(), rtol=1e-10) and np.isclose(stats_["nees_median"],
                                                                             np.median(nees), rtol=1e-10)
    assert abs(stats_["nees"] - 2.0) < 0.25 and abs(stats_["nees_median"] - 2 * np.log(2)) < 0.2
    exact, _, _ = score(t, p, truth, cov)
    assert exact["nees"] > 1.5 * stats_["nees"]


@pytest.mark.slow
def test_lake_hald_with_a_gps_error_in_the_budget(tmp_path, capsys, full):
    """The robust smoother against the GPS with 0.1 m per axis of the truth's own error in the budget: the median
    NEES is near a consistent estimator's (2 ln 2), the mean above 2 (a tail of gross errors) but under half the RTS
    smoother's (its tail is heavier); the number is in score.json and on the console; a bad --truth-sigma, or one
    without --truth, refused in one line."""
    from sblsim.orchestrator.cli import main

    args = ["replay", str(DATA / "toa.txt"), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv"),
            "--smooth"]
    out = tmp_path / "out"
    assert main([*args, "--truth", str(DATA / "gps.txt"), "--truth-sigma", "0.1", "--out", str(out)]) == 0
    import json

    score = json.loads((out / "score.json").read_text())
    assert score["truth_sigma_m"] == 0.1 and full.score["truth_sigma_m"] == 0.0
    assert 1.0 <= score["nees_median"] <= 2.0 and 2.0 < score["nees"] < score["others"]["rts"]["nees"] / 2
    assert score["nees"] < full.score["nees"] and score["median_m"] == full.score["median_m"]
    assert f"median {score['nees_median']:.3g} (2 and 1.39 when consistent)" in capsys.readouterr().out
    for option, word in ((["--truth", str(DATA / "gps.txt"), "--truth-sigma", "-1"], "--truth-sigma"),
                         (["--truth-sigma", "0.1"], "only with --truth")):
        status = main([*args, *option, "--out", str(tmp_path / "bad")])
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(err) == 1 and word in err[0] and not (tmp_path / "bad").exists()


def test_fixes_restart_a_lost_filter_and_only_then():
    """Simulated pings, the refusal rule switched off: a filter started 40 m off is restarted from a fix by
    disagree_after pings whose fixes disagree, only when given the fixes; a filter started right never is."""
    import dataclasses

    receivers = np.genfromtxt(DATA / "hydrophones.csv", delimiter=",", skip_header=1, usecols=(1, 2))
    receivers = receivers[np.isfinite(receivers).all(axis=1)]
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4,
                           reinit_after=10**6)
    rng = np.random.default_rng(4)
    toa, truth, _ = tt.simulate_pings(receivers, 120, s, rng, speed=0.3, detection=0.5)
    fx, _, fc, fused, _ = tt.fix_pings(toa, receivers, s.sound_speed, s.sigma_toa)
    fixes = (fx, fc, fused.sum(axis=1))
    assert tt.ToaTracker(receivers, dataclasses.replace(s, reinit_after=3)).run(toa, fixes).restarts == []

    class Lost(tt.ToaTracker):
        def initial(self, fix):
            x, P = super().initial(fix)
            self.calls = getattr(self, "calls", 0) + 1
            if self.calls <= 2:  # the first start (its prediction and its state) 40 m off, as a lost filter
                x[:2] += 40.0
            return x, P

    assert Lost(receivers, s).run(toa).restarts == []
    record = Lost(receivers, s).run(toa, fixes)
    overdetermined = np.flatnonzero(np.isfinite(fx).all(axis=1) & (fixes[2] >= 5))
    fifth = overdetermined[overdetermined > record.start][s.disagree_after - 1]
    assert record.restarts[0] == fifth
    k = np.arange(fifth, len(toa))
    assert np.median(np.hypot(*(record.x_filtered[k, :2] - truth[k]).T)) < 1.0


@pytest.mark.slow
def test_bound_predicts_the_observed_errors_on_lake_hald(full):
    """The accuracy limit per third of the track (score.json's bound, bound.csv) against the errors observed here
    against the GPS: the robust RMS (median / sqrt(ln 2)) of the single-ping fix and of the EKF within a factor 1.5
    of the median predicted DRMS; the smoothers' (RTS and robust) too once the floor the fix shows (its observed
    robust RMS beyond its bound, in quadrature: GPS and lever arm) is added to their bound. The thinned array: a
    larger predicted DRMS, the fix's robust RMS within a factor 2 of it (docs/tracking.md)."""
    import pandas as pd

    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    bound = pd.read_csv(full.out / "bound.csv")
    assert list(bound.columns) == ["ping", "time", "heard", "fix_drms_m", "pcrb_m", "pcrb_smoothed_m"]
    thirds = full.score["bound"]["thirds"]
    assert len(thirds) == 3 and thirds[0]["first_ping"] == 0 and thirds[-1]["last_ping"] == 3243
    for third in thirds:
        part = np.arange(third["first_ping"], third["last_ping"] + 1)
        robust = {}
        for estimator, column in (("fix", "fix_drms_m"), ("ekf", "pcrb_m"), ("rts", "pcrb_smoothed_m"),
                                  ("robust", "pcrb_smoothed_m")):
            rows = full.estimates[(full.estimates["estimator"] == estimator) & full.estimates["ping"].isin(part)]
            e = gps_errors(rows["time"].to_numpy(), rows["x"].to_numpy(), rows["y"].to_numpy(), gps)
            inside = (rows["time"] >= gps[0, 2]) & (rows["time"] <= gps[-1, 2])
            predicted = np.median(bound[column].to_numpy()[rows["ping"].to_numpy()[inside.to_numpy()]])
            robust[estimator] = (np.median(e) / np.sqrt(np.log(2)), predicted)
            assert np.isclose(third[estimator]["predicted_median_m"], predicted, rtol=1e-12)
        floor2 = max(robust["fix"][0] ** 2 - robust["fix"][1] ** 2, 0.0)
        for estimator, (observed, predicted) in robust.items():
            with_floor = np.sqrt(predicted**2 + floor2) if estimator in ("rts", "robust") else predicted
            assert 1 / 1.5 <= observed / with_floor <= 1.5, (third, estimator, observed, predicted)
    thin = sblsim.replay_toa(DATA / "toa.txt", receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                             sound_speed=full.summary["sound_speed"]["sound_speed_m_s"], receivers_kept=THINNED)
    for a, b in zip(thirds, thin.score["bound"]["thirds"]):
        assert b["fix"]["predicted_median_m"] > a["fix"]["predicted_median_m"]
        assert 1 / 2 <= b["fix"]["observed_robust_rms_m"] / b["fix"]["predicted_median_m"] <= 2


#: The thinned array's smoother: its 95 % and RMS 2-D errors against the GPS below these [m] (docs/tracking.md: about
#: 31 and 18 m with the consistent-fixes restart, 112 and 46 m without it; the issue's 5 m is not reached).
THIN_P95_M, THIN_RMS_M = 40.0, 20.0


@pytest.mark.slow
def test_consistent_fixes_restart_holds_the_thinned_track(full):
    """The authors' 8 hydrophones: the smoother with the restart on agree_after consecutive consistent fixes of 4
    receivers keeps its 95 % and RMS errors against the GPS (scored here) below the thresholds above and below those
    of the same tracker without that rule (the disagreement rule of 5 receivers alone)."""
    import dataclasses

    from sblsim.models.tracking.timing import SIGMA_TOA
    from sblsim.orchestrator.tracks.thinning import _usable
    from sblsim.orchestrator.tracks.tracker import AGREE_AFTER, tracker_settings

    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    toa, positions, _ = _usable(read_toa(DATA / "toa.txt"), read_receivers(DATA / "hydrophones.csv"), THINNED)
    c = full.summary["sound_speed"]["sound_speed_m_s"]
    fx, fe, fc, fused, _ = tt.fix_pings(toa, positions, c, SIGMA_TOA)
    s = tracker_settings(c, fe)
    figures = {}
    for agree in (AGREE_AFTER, None):
        tracker = tt.ToaTracker(positions, dataclasses.replace(s, agree_after=agree))
        record = tracker.run(toa, (fx, fc, fused.sum(axis=1)))
        xs, _ = tracker.smooth(record)
        k = np.flatnonzero(record.used.any(axis=1) & np.isfinite(record.x_filtered[:, 0]))
        e = gps_errors(xs[k, -2], xs[k, 0], xs[k, 1], gps)
        figures[agree] = (np.percentile(e, 95), np.sqrt(np.mean(e**2)), len(record.restarts))
    (p95, rms, restarts), (p95_off, rms_off, restarts_off) = figures[AGREE_AFTER], figures[None]
    assert p95 < THIN_P95_M and rms < THIN_RMS_M, figures
    assert p95 < p95_off / 2 and rms < rms_off / 2 and restarts > restarts_off, figures


@pytest.mark.slow
def test_the_robust_smoother_holds_the_thinned_track(full):
    """The authors' 8 hydrophones: the robust smoother's RMS and 95 % errors against the GPS (scored here) below 3
    and 5 m (the issue's 5 m; measured 1.9 and 4.1 m with the motion noise estimated; U-MAP's on the full array 15
    and 15 m) and below the RTS smoother's of the same run (5.5 and 13 m; 18 and 31 m at the default motion noise);
    below those of the robust smoother without its graduated start at the same motion noise; on the pings the RTS
    smoother positions, below its RMS on both arrays and its 95 % on the thin one (within 5 % on the full one); more
    pings positioned (every one from the tracker's start)."""
    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    thin = sblsim.replay_toa(DATA / "toa.txt", receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                             sound_speed=full.summary["sound_speed"]["sound_speed_m_s"], receivers_kept=THINNED)
    for case, result in (("thin", thin), ("full", full)):
        rts = result.estimates[result.estimates["estimator"] == "rts"]
        robust = result.estimates[result.estimates["estimator"] == "robust"]
        figures = {}
        for name, rows in (("robust", robust), ("rts", rts), ("common", robust[robust["ping"].isin(rts["ping"])])):
            e = gps_errors(rows["time"].to_numpy(), rows["x"].to_numpy(), rows["y"].to_numpy(), gps)
            figures[name] = (np.sqrt(np.mean(e**2)), np.percentile(e, 95), len(rows))
        (rms, p95, n), (rms_rts, p95_rts, n_rts), (rms_common, p95_common, _) = figures.values()
        # (on the full array, at the motion noise EM finds, the robust smoother's 95 % on these pings is 2.8 % above
        # the RTS smoother's: 0.774 against 0.754 m, its RMS 30 % below)
        assert rms_common < rms_rts and p95_common < 1.05 * p95_rts and n > n_rts, (case, figures)
        if case == "thin":
            thin_rms = rms
            assert rms < 3.0 and p95 < 5.0 and rms < rms_rts / 2 and p95 < p95_rts / 2, figures
            assert result.score["estimator"] == "robust" and np.isclose(result.score["rms_m"], rms, rtol=1e-12)
    # without the graduated start: from the fixes' own track and the RTS smoother's alone
    from sblsim.models.tracking.timing import SIGMA_TOA
    from sblsim.orchestrator.tracks.thinning import _usable
    from sblsim.orchestrator.tracks.tracker import tracker_settings

    toa, positions, _ = _usable(read_toa(DATA / "toa.txt"), read_receivers(DATA / "hydrophones.csv"), THINNED)
    c = full.summary["sound_speed"]["sound_speed_m_s"]
    fx, fe, fc, fused, _ = tt.fix_pings(toa, positions, c, SIGMA_TOA)
    s = replace(tracker_settings(c, fe), acceleration_psd=thin.summary["motion"]["acceleration_psd_m2_s3"])
    tracker = tt.ToaTracker(positions, s)
    record = tracker.run(toa, (fx, fc, fused.sum(axis=1)))
    xs, _ = tracker.smooth(record)
    k0 = record.start
    anchored = tt.anchored_start((fx, fe, fused), np.isfinite(toa).sum(axis=1), s, 2)[k0:]
    plain = tt.robust_smooth(toa[k0:], positions, s, [anchored, xs[k0:]])
    e_plain = gps_errors(plain.x[:, 4], plain.x[:, 0], plain.x[:, 1], gps)
    used = thin.summary["robust_smoother"]
    assert used["start"] == "graduated" and used["cost"] < plain.cost
    assert np.sqrt(np.mean(e_plain**2)) > thin_rms and np.percentile(e_plain, 95) > 5.0


@pytest.mark.slow
def test_another_estimator_s_rows_off_the_robust_track_are_flagged(full):
    """A filter's, the RTS smoother's or a fix's row off the robust smoother's track where that row is ``ok``
    (models/tracking/quality.off_the_track) is flagged ``off_the_track``, never a row of the track itself; on the
    full array those rows are far from the GPS, the ones left ``ok`` near it (an independent scoring)."""
    gps = np.genfromtxt(DATA / "gps.txt", skip_header=1)
    est = full.estimates
    why = est["quality_reason"].fillna("").str.split(";")
    off = why.map(lambda reasons: "off_the_track" in reasons)
    assert off.any() and not off[est["estimator"] == "robust"].any()
    assert (est.loc[off, "quality"] == "flagged").all()
    robust = est[est["estimator"] == "robust"].set_index("ping")["quality"]
    assert (robust.reindex(est.loc[off, "ping"]).to_numpy() == "ok").all()
    others = est[est["estimator"].isin(["rts", "ekf", "ekf-seq", "ukf"])]
    flagged_off = others[off[others.index]]
    kept = others[others["quality"] == "ok"]
    e_off = gps_errors(flagged_off["time"].to_numpy(), flagged_off["x"].to_numpy(), flagged_off["y"].to_numpy(), gps)
    e_ok = gps_errors(kept["time"].to_numpy(), kept["x"].to_numpy(), kept["y"].to_numpy(), gps)
    assert np.median(e_off) > 3 * np.median(e_ok)
