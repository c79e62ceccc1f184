"""The tag's depth from its sensor and the receivers' survey error in the covariance (models/tracking/fix.py,
models/tracking/smoother.py), against simulated truths: a depth reading makes a ping of dim receivers fixable and the
track's depth right; a consider covariance makes the fixes and the track consistent with receivers surveyed to 1 m,
where the same estimates without it are overconfident; a fix whose start falls on a receiver."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking.fix import fix_pings

R2 = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0], [140.0, 20.0],
               [30.0, 80.0]])
R3 = np.column_stack([R2, -np.array([2.0, 15.0, 4.0, 20.0, 8.0, 3.0, 12.0, 6.0])])
SETTINGS = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)


def _nees(e: np.ndarray, C: np.ndarray) -> np.ndarray:
    return np.einsum("ki,kij,kj->k", e, np.linalg.inv(C), e)


def _smoothed(toa, receivers, settings, depth=None):
    """The robust smoother from the fixes and the RTS smoother, as the replay runs it: its states and covariances
    from the EKF's start, and that start."""
    fx, fe, fc, fu, _ = fix_pings(toa, receivers, settings.sound_speed, settings.sigma_toa, depth=depth,
                                  depth_sigma=settings.depth_sigma, survey_sigma=settings.survey_sigma)
    tracker = tt.ToaTracker(receivers, settings)
    record = tracker.run(toa, (fx, fc, fu.sum(axis=1)), fu)
    xs, _ = tracker.smooth(record)
    k0 = record.start
    track = tt.robust_track(toa[k0:], receivers, settings, (fx[k0:], fe[k0:], fu[k0:]), xs[k0:],
                            depth=None if depth is None else depth[k0:])
    return track, k0


def _pings_heard_by(count: int, rng: np.random.Generator, n: int = 200):
    """``n`` pings of tags spread over the array in 3-D, each heard by ``count`` receivers chosen at random, and
    the tags' positions."""
    truth = np.column_stack([rng.uniform(20, 180, n), rng.uniform(20, 130, n), -rng.uniform(1, 20, n)])
    toa = np.full((n, len(R3)), np.nan)
    for k, p in enumerate(truth):
        heard = rng.choice(len(R3), count, replace=False)
        toa[k, heard] = 100.0 + k + np.linalg.norm(p - R3[heard], axis=1) / 1480.0 + 1e-4 * rng.normal(size=count)
    return toa, truth


@pytest.mark.parametrize("count", [3, 4])
def test_a_depth_reading_fixes_a_ping_of_dim_receivers_and_its_depth(count):
    """Pings heard by 3 receivers in 3-D: no fix without the reading (dim + 1 = 4 needed), with it every one, the
    median height error within σ_depth and the median 3-D NEES that of χ²(3) (2.37) within 70 %; by 4 receivers:
    beyond χ²(3)'s 0.999 quantile at most 3 % of the fixes with the reading, more than 15 % without (the height
    and the emission time trade against each other there), the height's median error under 0.3 m against metres."""
    rng = np.random.default_rng(4)
    toa, truth = _pings_heard_by(count, rng)
    depth = -truth[:, 2] + 0.3 * rng.normal(size=len(truth))
    figures = {}
    for given in (False, True):
        fx, fe, fc, _, _ = fix_pings(toa, R3, 1480.0, 1e-4, depth=depth if given else None, depth_sigma=0.3)
        ok = np.isfinite(fe)
        if not ok.any():
            figures[given] = None
            continue
        nees = _nees(fx[ok] - truth[ok], fc[ok][:, :3, :3])
        figures[given] = (ok.mean(), float(np.median(nees)), float((nees > 16.27).mean()),
                          float(np.median(np.abs(fx[ok, 2] - truth[ok, 2]))))
    if count == 3:
        assert figures[False] is None and figures[True][0] == 1.0, figures
        assert figures[True][3] <= 0.3 and figures[True][1] <= 1.7 * 2.37, figures
    else:
        assert figures[True][2] <= 0.03 and figures[False][2] > 0.15, figures
        assert figures[True][3] <= 0.3 and figures[False][3] >= 1.0, figures


@pytest.mark.slow
def test_a_track_with_depth_readings_has_the_depth_right_and_stays_consistent():
    """10 seeds of a tag in 3-D heard by half the receivers: with noisy readings (0.3 m) the smoother's height RMS
    is at most 0.6 of the one it estimates without them, its horizontal error no worse, its 3-D NEES in [1.5, 4.5]."""
    out = {}
    for use in (False, True):
        ez, eh, nees = [], [], []
        for seed in range(10):
            rng = np.random.default_rng(seed)
            toa, truth, _ = tt.simulate_pings(R3, 80, SETTINGS, rng, start=np.array([100.0, 75.0, -10.0]), speed=0.2,
                                              detection=0.5)
            depth = -truth[:, 2] + 0.3 * rng.normal(size=len(truth))
            track, k0 = _smoothed(toa, R3, SETTINGS, depth if use else None)
            e = track.x[:, :3] - truth[k0:]
            ez.extend(e[:, 2])
            eh.extend(np.hypot(e[:, 0], e[:, 1]))
            nees.extend(_nees(e, track.P[:, :3, :3]))
        out[use] = (np.sqrt(np.mean(np.square(ez))), np.sqrt(np.mean(np.square(eh))), np.mean(nees))
    assert out[True][0] <= 0.6 * out[False][0] and out[True][1] <= 1.1 * out[False][1], out
    assert 1.5 <= out[True][2] <= 4.5, out


def test_a_depth_needs_receivers_in_3d():
    with pytest.raises(ModelError, match="depth_m"):
        fix_pings(np.full((2, len(R2)), 1.0), R2, 1480.0, 1e-4, depth=np.array([1.0, 2.0]))


def test_the_fixes_hold_the_receivers_survey_error():
    """30 arrays whose surveyed positions are 1 m off (per axis) from where the receivers stand: the fixes' 2-D NEES
    over them near 2 with the survey error in their covariance, above 20 without."""
    means = {}
    for survey in (None, 1.0):
        nees = []
        for seed in range(30):
            rng = np.random.default_rng(seed)
            toa, truth, _ = tt.simulate_pings(R2, 50, SETTINGS, rng, speed=0.2, detection=0.9)
            surveyed = R2 + rng.normal(0.0, 1.0, R2.shape)
            fx, fe, fc, _, _ = fix_pings(toa, surveyed, 1480.0, 1e-4,
                                         survey_sigma=None if survey is None else np.full(len(R2), survey))
            ok = np.isfinite(fe)
            nees.extend(_nees(fx[ok] - truth[ok], fc[ok][:, :2, :2]))
        means[survey] = float(np.mean(nees))
    assert 1.5 <= means[1.0] <= 4.5 and means[None] >= 20.0, means


@pytest.mark.slow
def test_the_track_holds_the_receivers_survey_error():
    """12 arrays surveyed to 1 m: the robust smoother's 2-D NEES in [1.5, 3] with the survey error (a consider
    covariance: the same bias at every ping, which the smoother cannot average away), above 20 without."""
    means = {}
    for survey in (None, 1.0):
        nees = []
        for seed in range(12):
            rng = np.random.default_rng(seed)
            toa, truth, _ = tt.simulate_pings(R2, 80, SETTINGS, rng, speed=0.2, detection=0.9)
            surveyed = R2 + rng.normal(0.0, 1.0, R2.shape)
            settings = replace(SETTINGS, survey_sigma=None if survey is None else np.full(len(R2), survey))
            track, k0 = _smoothed(toa, surveyed, settings)
            nees.extend(_nees(track.x[:, :2] - truth[k0:], track.P[:, :2, :2]))
        means[survey] = float(np.mean(nees))
    assert 1.5 <= means[1.0] <= 3.0 and means[None] >= 20.0, means


def test_a_fix_whose_start_falls_on_a_receiver_is_the_least_squares_solution():
    """A square with a receiver at its middle: a ping that receiver hears first starts Gauss-Newton at the middle
    (half way from that receiver to the centroid of those heard, which is it), where its range has no gradient. The
    fixes are scipy's least_squares solutions from the truth, with finite covariances (they were the start itself,
    covariance NaN, and a filter started from one failed)."""
    from scipy.optimize import least_squares

    square = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 200.0], [0.0, 200.0], [100.0, 100.0]])
    rng = np.random.default_rng(5)
    truth = 100.0 + rng.uniform(-30.0, 30.0, (20, 2))
    toa = 50.0 + np.linalg.norm(truth[:, None] - square[None], axis=-1) / 1480.0 + 1e-4 * rng.normal(size=(20, 5))
    assert (np.argmin(toa, axis=1) == 4).all()  # the middle receiver heard first: the start on it
    fx, fe, fc, fu, _ = fix_pings(toa, square, 1480.0, 1e-4, gate=np.inf)
    for k in range(len(truth)):
        ref = least_squares(lambda v, t=toa[k]: (t - v[2] - np.linalg.norm(v[:2] - square, axis=1) / 1480.0) / 1e-4,
                            np.r_[truth[k], 50.0], xtol=1e-14, ftol=1e-14, gtol=1e-14).x
        assert np.linalg.norm(fx[k] - ref[:2]) < 1e-3, (k, fx[k], ref)
        assert np.isfinite(fc[k]).all() and fu[k].all()


def test_the_speed_terms_are_the_estimates_sensitivity_to_the_speed():
    """The sound speed's consider terms (fix.speed_fix_covariance, smoother_covariance.speed_covariance) against the
    estimates' own change with the speed, by central differences of the fixes and of the robust smoother solved again
    at c ± 0.5 m/s: σ_c² S Sᵀ with S that derivative, to 2 % of each fix's; each track ping's spread within 0.8 to
    1.25 times the re-solves' and 10 % over the track (the consider term is the first order of a smoother whose
    weights move with the speed)."""
    from sblsim.models.tracking.fix import speed_fix_covariance
    from sblsim.models.tracking.smoother import robust_smooth
    from sblsim.models.tracking.smoother_covariance import speed_covariance

    rng = np.random.default_rng(8)
    toa, _, _ = tt.simulate_pings(R2, 60, SETTINGS, rng, speed=0.2, detection=0.9)
    c, h, sigma_c = 1480.0, 0.5, 3.0
    fixes = {d: fix_pings(toa, R2, c + d, 1e-4, gate=np.inf) for d in (-h, 0.0, h)}
    fx, fe, fc, fu, _ = fixes[0.0]
    ok = np.isfinite(fe)
    S = (fixes[h][0] - fixes[-h][0])[ok] / (2 * h)
    term = speed_fix_covariance(R2, c, 1e-4, fx, fe, fc, fu, sigma_c)[ok][:, :2, :2]
    expected = sigma_c**2 * S[:, :, None] * S[:, None, :]
    per_ping = np.trace(expected, axis1=1, axis2=2)[:, None, None]
    assert (np.abs(term - expected) <= 0.02 * per_ping).all(), (term[:2], expected[:2])
    track, k0 = _smoothed(toa, R2, SETTINGS)
    at = {d: robust_smooth(toa[k0:], R2, replace(SETTINGS, sound_speed=c + d), [track.x], covariance=False,
                           student_start=False, iterations=200).x for d in (-h, h)}
    S = (at[h] - at[-h])[:, :2] / (2 * h)
    term = speed_covariance(toa[k0:], R2, SETTINGS, track.x, sigma_c)[:, :2, :2]
    ours, theirs = np.trace(term, axis1=1, axis2=2), sigma_c**2 * (S**2).sum(axis=1)
    ratio = np.sqrt(ours / theirs)  # each ping's spread against the re-solves' (measured: 0.86 to 1.17)
    assert theirs.max() > 1e-4 and 0.8 <= ratio.min() and ratio.max() <= 1.25, ratio
    assert abs(np.sqrt(ours.sum() / theirs.sum()) - 1.0) <= 0.1, np.sqrt(ours.sum() / theirs.sum())


@pytest.mark.slow
def test_the_fixes_and_the_track_hold_the_sound_speed_error():
    """A speed 10 m/s uncertain (each run solved at 1,480 + 10 N(0, 1) m/s, the pings simulated at 1,480 m/s, among
    receivers 200 m apart): the fixes' 2-D NEES (30 runs) and the robust smoother's (12) in [1.5, 4.5] with the speed's
    consider term, well above without."""
    from sblsim.models.tracking.fix import speed_fix_covariance
    from sblsim.models.tracking.smoother_covariance import speed_covariance

    fixes, tracks = {False: [], True: []}, {False: [], True: []}
    for seed in range(30):
        rng = np.random.default_rng(100 + seed)
        toa, truth, _ = tt.simulate_pings(R2, 60, SETTINGS, rng, speed=0.2, detection=0.9)
        c = 1480.0 + 10.0 * rng.normal()
        fx, fe, fc, fu, _ = fix_pings(toa, R2, c, 1e-4)
        ok = np.isfinite(fe)
        extra = speed_fix_covariance(R2, c, 1e-4, fx, fe, fc, fu, 10.0)
        for told in (False, True):
            C = fc + extra if told else fc
            fixes[told].extend(_nees(fx[ok] - truth[ok], C[ok][:, :2, :2]))
        if seed < 12:
            settings = replace(SETTINGS, sound_speed=c)
            track, k0 = _smoothed(toa, R2, settings)
            extra = speed_covariance(toa[k0:], R2, settings, track.x, 10.0)
            for told in (False, True):
                P = track.P + extra if told else track.P
                tracks[told].extend(_nees(track.x[:, :2] - truth[k0:], P[:, :2, :2]))
    means = {f"{name} {told}": float(np.mean(v[told])) for name, v in (("fix", fixes), ("track", tracks))
             for told in (False, True)}
    assert 1.5 <= means["fix True"] <= 4.5 and 1.5 <= means["track True"] <= 4.5, means
    assert means["fix False"] >= 2 * means["fix True"] and means["track False"] >= 2 * means["track True"], means
