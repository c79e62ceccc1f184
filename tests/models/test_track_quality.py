"""A track checked against its own data (models/tracking/quality.py): a lost track is flagged, never ``ok``; a
multipath fix does not flag a right track; the arrivals that agree with a position counted independently."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import quality as qa

RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0]])
C, SIGMA = 1480.0, 1e-4


def simulated(seed: int = 0, n: int = 60):
    s = tt.TrackerSettings(sound_speed=C, sigma_toa=SIGMA, interval=2.0, acceleration_psd=1e-4)
    toa, truth, emissions = tt.simulate_pings(RECEIVERS, n, s, np.random.default_rng(seed), speed=0.3, detection=1.0)
    fx, fe, fc, fu, chi2 = tt.fix_pings(toa, RECEIVERS, C, SIGMA)
    trusted = qa.trusted_fixes(fx, fc, fu.sum(axis=1), np.isfinite(toa).sum(axis=1), chi2, 2)
    return toa, truth, emissions, fx, fc, fu, trusted


def check(toa, track, emissions, fx, fc, trusted, cov):
    return qa.check_track(emissions, track, cov, fx, fc, trusted,
                          explained=qa.explained(toa, RECEIVERS, track, C, SIGMA),
                          fix_used=qa.explained(toa, RECEIVERS, fx, C, SIGMA))


def test_explained_counts_the_arrivals_within_their_sigmas_of_the_best_emission():
    toa, truth, emissions, *_ = simulated()
    # independently: at the truth every arrival is within 6.1 sigma of the true emission time
    assert (qa.explained(toa, RECEIVERS, truth, C, SIGMA) == 6).all()
    late = toa.copy()
    late[:, 2] += 5e-3  # one receiver's arrivals 7 m late: no longer explained by the true positions
    assert (qa.explained(late, RECEIVERS, truth, C, SIGMA) == 5).all()
    # 1 km away a position explains at most the few arrivals that happen to line up
    assert (qa.explained(toa, RECEIVERS, truth + [1000.0, 0.0], C, SIGMA) <= 2).all()


def test_a_track_on_its_fixes_is_ok_and_one_multipath_fix_does_not_flag_it():
    toa, truth, emissions, fx, fc, fu, trusted = simulated()
    assert trusted.mean() > 0.9
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    assert set(check(toa, truth, emissions, fx, fc, trusted, cov).quality) == {"ok"}
    bad = fx.copy()
    bad[30] += [12.0, 0.0]  # a fix 12 m off (a multipath arrival it kept): the track explains more than it does
    toa_bad = toa.copy()
    assert check(toa_bad, truth, emissions, bad, fc, trusted, cov).flagged == 0


@pytest.mark.parametrize("offset", [50.0, 1000.0])
def test_a_track_off_its_fixes_is_flagged_whatever_its_covariance(offset):
    toa, truth, emissions, fx, fc, fu, trusted = simulated()
    lost = truth + [offset, 0.0]
    for sigma in (0.1, 5000.0):  # tight and wrong, or loose and wrong: never ok
        cov = np.tile(sigma**2 * np.eye(2), (len(truth), 1, 1))
        q = check(toa, lost, emissions, fx, fc, trusted, cov)
        assert q.flagged == len(truth), (offset, sigma, q.quality)
    # lost over a stretch in the middle only: those rows flagged, the rest ok
    stretch = truth.copy()
    stretch[20:35] += [offset, 0.0]
    q = check(toa, stretch, emissions, fx, fc, trusted, np.tile(0.01 * np.eye(2), (len(truth), 1, 1)))
    assert q.quality[20:35].tolist() == ["flagged"] * 15
    assert "flagged" not in q.quality[:19].tolist() + q.quality[36:].tolist()


def test_a_jump_faster_than_a_tag_moves_is_flagged_and_restarts_are_marked():
    toa, truth, emissions, fx, fc, fu, _ = simulated()
    jump = truth.copy()
    jump[40] += [60.0, 0.0]  # 60 m in 2 s and back
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    q = qa.check_track(emissions, jump, cov, fx, fc, np.zeros(len(truth), bool), restarts=np.arange(60) == 10)
    assert q.speed[39:42].all() and q.quality[40] == "flagged" and q.quality[10] == "restart"
    assert (q.quality == "flagged").sum() == 3


def test_each_flagged_row_names_its_reasons_and_no_other_row_any():
    """A 60 m jump at ping 40 (too fast on both sides: 39, 40, 41), a NaN covariance at 12 (placed less well than a
    fix) and a NaN position at 20 (no position): each row's ``quality_reason`` is exactly the
    reasons set for it, in :data:`~sblsim.models.tracking.quality.REASONS`' order; every other row ``""``."""
    toa, truth, emissions, fx, fc, fu, _ = simulated()
    track = truth.copy()
    track[40] += [60.0, 0.0]
    track[20] = np.nan
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    cov[12] = np.nan
    q = qa.check_track(emissions, track, cov, fx, fc, np.zeros(len(truth), bool))
    # a step to or from no position is not within the speed limit: its neighbours too fast as well
    expected = {12: "placed_less_well_than_a_fix", 39: "too_fast", 40: "too_fast", 41: "too_fast",
                19: "too_fast", 20: "too_fast;no_position", 21: "too_fast"}
    reason = q.reason
    assert {int(k): str(reason[k]) for k in np.flatnonzero(reason != "")} == expected
    assert set(np.flatnonzero(q.quality == "flagged")) == set(expected)
    assert qa.reasons(np.array([True, True, False]), {"a": np.array([1, 0, 1]), "b": np.array([1, 1, 1])}).tolist(
        ) == ["a;b", "b", ""]


def test_a_receiver_heard_by_a_reflection_is_named_and_the_others_are_not():
    """One receiver's arrivals all 3 ms late (4.4 m of extra path; a reflection around a corner): its median residual
    against the robust smoother's track far beyond 3 σ, named; every other receiver's within a few tenths, not named;
    on the truth itself the same (the residuals counted independently with numpy)."""
    from sblsim.models.tracking.receivers import receiver_residuals

    s = tt.TrackerSettings(sound_speed=C, sigma_toa=SIGMA, interval=2.0, acceleration_psd=1e-4)
    toa, truth, emissions = tt.simulate_pings(RECEIVERS, 120, s, np.random.default_rng(2), speed=0.3, detection=0.9)
    toa[:, 3] += 3e-3
    judged = receiver_residuals(toa, RECEIVERS, truth, emissions, C, SIGMA)
    assert judged.late.tolist() == [False, False, False, True, False, False]
    z = (toa[:, 3] - emissions - np.hypot(*(truth - RECEIVERS[3]).T) / C) / SIGMA
    assert judged.median_z[3] == np.nanmedian(z) and judged.median_z[3] > 25
    fx, fe, fc, fu, _ = tt.fix_pings(toa, RECEIVERS, C, SIGMA)
    tracker = tt.ToaTracker(RECEIVERS, s)
    record = tracker.run(toa, (fx, fc, fu.sum(axis=1)), fu)
    xs, _ = tracker.smooth(record)
    k0 = record.start
    robust = tt.robust_track(toa[k0:], RECEIVERS, s, (fx[k0:], fe[k0:], fu[k0:]), xs[k0:])
    on_track = receiver_residuals(toa[k0:], RECEIVERS, robust.x[:, :2], robust.x[:, 4], C, SIGMA)
    assert on_track.late.tolist() == [False, False, False, True, False, False]
    assert np.abs(np.delete(on_track.median_z, 3)).max() < 1.0 and on_track.kept[3] < 0.2


def test_a_track_whose_covariance_grows_over_a_silent_stretch_is_flagged_from_10_m_drms():
    """Pings 20-49 not heard: the track's covariance there is the motion model's prediction alone (the tracker's own
    transition, nearly constant velocity, from a position and velocity known exactly at ping 19), and the rows are
    flagged ``uncertain`` exactly from the ping where the closed form of white-noise acceleration, a position variance
    of q t³ / 3 per axis (Bar-Shalom, Li & Kirubarajan 2001, § 6.2.2), puts the DRMS √(2 q t³ / 3) above 10 m."""
    toa, truth, emissions, fx, fc, fu, trusted = simulated()
    q, interval = 0.05, 2.0
    silent = np.arange(20, 50)
    toa, fx, trusted = toa.copy(), fx.copy(), trusted.copy()
    toa[silent], fx[silent], trusted[silent] = np.nan, np.nan, False
    s = tt.TrackerSettings(sound_speed=C, sigma_toa=SIGMA, interval=interval, acceleration_psd=q)
    tracker = tt.ToaTracker(RECEIVERS, s)
    x = np.concatenate([truth[19], [0.0, 0.0], [emissions[19], interval]])
    P = np.zeros((6, 6))
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    for k in silent:
        x, F, Q = tracker.transition(x)
        P = F @ P @ F.T + Q
        cov[k] = P[:2, :2]
    elapsed = (silent - 19) * interval
    closed = np.sqrt(2 * q * elapsed**3 / 3)
    assert np.allclose(np.sqrt(np.trace(cov[silent], axis1=1, axis2=2)), closed, rtol=1e-9)
    crossing = silent[np.argmax(closed > 10.0)]
    assert 20 < crossing < 49  # the threshold is crossed inside the stretch, with rows ok before it
    quality = check(toa, truth, emissions, fx, fc, trusted, cov)
    expected = np.zeros(len(truth), bool)
    expected[crossing:50] = True
    assert quality.uncertain.tolist() == expected.tolist()
    assert quality.quality.tolist() == np.where(expected, "flagged", "ok").tolist()


def test_a_row_of_9_9_m_drms_stays_ok_and_one_of_10_1_m_is_flagged():
    """The limit is the DRMS, √ of the covariance's trace (not its largest axis): 9 m along x and 4.12 m along y is
    9.9 m, ok; the same ellipse turned 30° with 10.1 m, flagged; the other rows' marks unchanged."""
    toa, truth, emissions, fx, fc, fu, trusted = simulated()
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    cov[30] = np.diag([9.0**2, 9.9**2 - 9.0**2])
    turn = np.array([[np.cos(0.5236), -np.sin(0.5236)], [np.sin(0.5236), np.cos(0.5236)]])
    cov[40] = turn @ np.diag([9.0**2, 10.1**2 - 9.0**2]) @ turn.T
    quality = check(toa, truth, emissions, fx, fc, trusted, cov)
    assert quality.quality[30] == "ok" and not quality.uncertain[30]
    assert quality.quality[40] == "flagged" and quality.uncertain[40]
    assert quality.flagged == 1 and quality.uncertain.sum() == 1


def test_a_covariance_that_is_not_finite_is_flagged_without_a_crash():
    """A NaN covariance (a filter's broken by round-off) says nothing of where the row is: flagged ``uncertain``, on a
    ping with a trusted fix as well as without; every other row ok."""
    toa, truth, emissions, fx, fc, fu, trusted = simulated()
    assert trusted[12]
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    cov[12] = np.nan
    cov[13, 0, 1] = cov[13, 1, 0] = np.nan
    quality = check(toa, truth, emissions, fx, fc, trusted, cov)
    assert np.flatnonzero(quality.uncertain).tolist() == [12, 13]
    assert np.flatnonzero(quality.quality == "flagged").tolist() == [12, 13]


def test_the_reported_covariance_decides_the_own_uncertainty_and_the_own_one_the_fixes_gates():
    """A consider term (an error common to the track and its fixes: the sound speed's, the survey's) reported with the
    rows: a row whose reported DRMS is above the limit is flagged ``uncertain`` though its own covariance is small; a
    row 8 m off its trusted fix disagrees with it under its own covariance, not under one widened by the term."""
    toa, truth, emissions, fx, fc, fu, trusted = simulated()
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    reported = cov.copy()
    reported[20] += np.diag([8.0**2, 7.0**2])  # DRMS 10.6 m with the term
    k = int(np.flatnonzero(trusted)[5])
    moved = truth.copy()
    moved[k] += [8.0, 0.0]
    reported[k] += 25.0 * np.eye(2)  # DRMS 7.1 m: within the limit, wide enough to take the fix in
    plain = qa.check_track(emissions, moved, cov, fx, fc, trusted, explained=qa.explained(toa, RECEIVERS, moved, C,
                                                                                       SIGMA),
                           fix_used=qa.explained(toa, RECEIVERS, fx, C, SIGMA))
    said = qa.check_track(emissions, moved, cov, fx, fc, trusted, explained=qa.explained(toa, RECEIVERS, moved, C,
                                                                                      SIGMA),
                          fix_used=qa.explained(toa, RECEIVERS, fx, C, SIGMA), reported=reported)
    assert not plain.uncertain[20] and said.uncertain[20] and said.quality[20] == "flagged"
    assert plain.fix[k] and said.fix[k]  # the gate of the fix the same
    assert np.flatnonzero(said.uncertain).tolist() == [20]


def test_rows_no_arrivals_place_are_unverified_beyond_the_motion_models_reach_of_a_trusted_fix():
    """Pings 30-89 heard by receivers 0 and 1 only (a thin array's): a track mirrored across the line through them
    explains both arrivals of each ping exactly, with a tight covariance, far from the truth. The reach of the
    fastest tag leaves its middle ``ok``; with the motion model's q, each row more than the time at which
    √(DRMS_fix² + 2 q τ³ / 3) passes 10 m from its nearest trusted fix is ``unverified`` (written again here as a
    loop over the rows), the right track's rows there too (nothing in the data checks either), and a row its own
    arrivals place is not."""
    toa, truth, emissions, fx, fc, fu, trusted = simulated(n=120)
    stretch = np.arange(30, 90)
    toa, fx, trusted = toa.copy(), fx.copy(), trusted.copy()
    toa[stretch, 2:] = np.nan
    fx[stretch], trusted[stretch] = np.nan, False
    mirrored = truth.copy()
    mirrored[stretch, 1] *= -1.0
    assert (np.abs(mirrored - truth)[stretch, 1] > 10.0).all()
    cov = np.tile(0.01 * np.eye(2), (len(truth), 1, 1))
    q = 0.01
    expected = np.zeros(len(truth), bool)
    for i in stretch:
        tau = np.abs(emissions[trusted] - emissions[i])
        j = np.flatnonzero(trusted)[np.argmin(tau)]
        expected[i] = np.trace(fc[j]) + 2.0 * q * tau.min() ** 3 / 3.0 > 10.0**2
    assert 20 < expected.sum() < len(stretch)  # rows near the fixes stay within reach
    for track in (mirrored, truth):
        plain = check(toa, track, emissions, fx, fc, trusted, cov)
        said = qa.check_track(emissions, track, cov, fx, fc, trusted,
                              explained=qa.explained(toa, RECEIVERS, track, C, SIGMA),
                              fix_used=qa.explained(toa, RECEIVERS, fx, C, SIGMA), acceleration_psd=q)
        assert not plain.unverified.any()
        assert said.unverified.tolist() == expected.tolist()
        assert (said.quality[expected] == "flagged").all()
        assert (said.quality[~expected] == plain.quality[~expected]).all()
    assert (plain.quality[expected] == "ok").all()  # the right track: ok without the rule
    wrong_ok = check(toa, mirrored, emissions, fx, fc, trusted, cov).quality[stretch] == "ok"
    assert wrong_ok.sum() >= expected.sum()  # the mirrored middle: ok without it
    # four receivers heard, no fix trusted: the rows place themselves and are not unverified
    heard = simulated(n=120)[0]
    placed = qa.check_track(emissions, truth, cov, fx, fc, trusted,
                            explained=qa.explained(heard, RECEIVERS, truth, C, SIGMA),
                            fix_used=qa.explained(heard, RECEIVERS, fx, C, SIGMA), acceleration_psd=q)
    assert not placed.unverified.any()


def test_a_depth_the_fix_was_given_counts_as_one_more_measurement_of_a_trusted_fix():
    """Receivers in 3-D (moored at 1-9 m), a tag at 4 m heard by four of them: with no depth a fix has no arrival to
    spare (dim + 1 = 4) and is never trusted; with the tag's depth-sensor reading it has one (the fix counts the
    reading as a measurement), so the ones that pass χ²(1) at 0.999 are trusted; a ping heard by three with the
    reading still is not (nothing to spare)."""
    rng = np.random.default_rng(3)
    receivers = np.column_stack([RECEIVERS[:4], -np.array([1.0, 9.0, 3.0, 6.0])])
    tags = np.column_stack([rng.uniform(20, 180, 200), rng.uniform(20, 130, 200), np.full(200, -4.0)])
    emissions = np.arange(200) * 2.0
    toa = emissions[:, None] + np.linalg.norm(tags[:, None] - receivers[None], axis=2) / C
    toa += SIGMA * rng.standard_normal(toa.shape)
    depth = np.full(200, 4.0)
    heard = np.isfinite(toa).sum(axis=1)
    fx, fe, fc, fu, chi2 = tt.fix_pings(toa, receivers, C, SIGMA, depth=depth, depth_sigma=0.05)
    known = np.isfinite(depth)
    assert not qa.trusted_fixes(fx, fc, fu.sum(axis=1), heard, chi2, 3).any()
    trusted = qa.trusted_fixes(fx, fc, fu.sum(axis=1), heard, chi2, 3, known)
    from scipy.stats import chi2 as chi2_dist
    assert trusted.tolist() == (chi2 <= chi2_dist.ppf(0.999, 1)).tolist()
    assert trusted.mean() > 0.95
    three = toa.copy()
    three[:, 3] = np.nan
    fx3, fe3, fc3, fu3, chi23 = tt.fix_pings(three, receivers, C, SIGMA, depth=depth, depth_sigma=0.05)
    assert np.isfinite(fx3).all()  # fixed from three arrivals and the reading, none to spare
    assert not qa.trusted_fixes(fx3, fc3, fu3.sum(axis=1), np.isfinite(three).sum(axis=1), chi23, 3, known).any()


def test_an_estimates_own_measurements_check_it_with_one_to_spare_its_depth_counted_as_one():
    """Receivers in 3-D (moored at 1-9 m), a tag at 4 m, pings 60-139 heard by four of the five and no fix there:
    an estimate in 3-D is fitted exactly by four measurements (x, y, z and its emission time), so its own
    measurements check it with five; four arrivals and no depth leave it to the motion model, ``unverified``
    beyond its reach of the nearest trusted fix; four and the tag's depth check it. In 2-D (the same receivers'
    x and y) four arrivals check an estimate, and three do not. Written again here as a loop over the rows."""
    rng = np.random.default_rng(5)
    receivers = np.column_stack([RECEIVERS[:5], -np.array([1.0, 9.0, 3.0, 6.0, 2.0])])
    n = 200
    tags = np.column_stack([100 + 40 * np.cos(np.arange(n) / 40), 75 + 30 * np.sin(np.arange(n) / 40),
                            np.full(n, -4.0)])
    emissions = np.arange(n) * 2.0
    toa = emissions[:, None] + np.linalg.norm(tags[:, None] - receivers[None], axis=2) / C
    toa += SIGMA * rng.standard_normal(toa.shape)
    stretch = np.arange(60, 140)
    toa[stretch, 4] = np.nan
    depth = np.full(n, 4.0)
    fx, fe, fc, fu, chi2 = tt.fix_pings(toa, receivers, C, SIGMA, depth=depth, depth_sigma=0.05)
    fx[stretch] = np.nan  # no fix there (as where one is refused)
    trusted = qa.trusted_fixes(fx, fc, fu.sum(axis=1), np.isfinite(toa).sum(axis=1), chi2, 3, np.isfinite(depth))
    assert trusted[:60].mean() > 0.9 and not trusted[stretch].any()
    cov = np.tile(0.01 * np.eye(3), (n, 1, 1))
    agree = qa.explained(toa, receivers, tags, C, SIGMA)
    assert (agree[stretch] == 4).all()
    q = 0.01
    k = np.flatnonzero(trusted)

    def expected_rows(measured, dim):
        expected = np.zeros(n, bool)
        for i in range(n):
            if measured[i] >= dim + 2 or trusted[i]:
                continue
            tau = np.abs(emissions[k] - emissions[i])
            j = k[np.argmin(tau)]
            expected[i] = np.trace(fc[j][:2, :2]) + 2.0 * q * tau.min() ** 3 / 3.0 > 10.0**2
        return expected

    fix_used = qa.explained(toa, receivers, fx, C, SIGMA)
    for known in (np.zeros(n, bool), np.ones(n, bool)):
        expected = expected_rows(agree + known, 3)
        said = qa.check_track(emissions, tags, cov, fx, fc, trusted, explained=agree, fix_used=fix_used,
                              acceleration_psd=q, known_depth=known)
        assert said.unverified.tolist() == expected.tolist()
        if known.any():
            assert not expected.any()
        else:  # the stretch's middle, beyond the reach of the fixes either side
            assert 20 < expected.sum() < len(stretch) and expected[stretch].sum() == expected.sum()
            assert (said.quality[expected] == "flagged").all()
    flat_agree = qa.explained(toa, receivers[:, :2], tags[:, :2], C, SIGMA)
    assert (flat_agree[stretch] == 4).all()
    for heard, checked in ((flat_agree, True), (np.minimum(flat_agree, 3), False)):
        flat = qa.check_track(emissions, tags[:, :2], cov[:, :2, :2], fx[:, :2], fc[:, :2, :2], trusted,
                              explained=heard, fix_used=fix_used, acceleration_psd=q)
        assert flat.unverified.tolist() == expected_rows(heard, 2).tolist()
        assert flat.unverified[stretch].any() != checked


def test_a_filter_row_off_the_track_is_flagged_where_the_track_explains_as_much():
    """Another estimator's rows against the robust track (qa.off_the_track): a filter that kept a reflection at ten
    pings sits 4 m off with a covariance of decimetres; its rows there are flagged ``off_the_track`` where the track
    explains as many arrivals or more (counted by qa.explained, independently of the gate), and nowhere else; the
    gate against a direct solve of the summed covariances."""
    toa, truth, emissions, fx, fc, _, trusted = simulated(seed=3)
    cov = np.repeat((0.05 ** 2 * np.eye(2))[None], len(truth), axis=0)
    filtered = truth.copy()
    off = np.arange(20, 30)
    filtered[off, 0] += 4.0
    ours = qa.explained(toa, RECEIVERS, filtered, C, SIGMA)
    theirs = qa.explained(toa, RECEIVERS, truth, C, SIGMA)
    assert (theirs[off] > ours[off]).all()  # the reflection's rows explain fewer arrivals
    track_ok = np.ones(len(truth), bool)
    found = qa.off_the_track(filtered, cov, ours, truth, cov, theirs, track_ok)
    d2 = np.array([e @ np.linalg.solve(2 * c, e) for e, c in zip(filtered[:, :2] - truth[:, :2], cov)])
    assert np.array_equal(found, d2 > qa.FIX_GATE)
    assert np.array_equal(np.flatnonzero(found), off)
    # the track not ok there, or the filter explaining more: not flagged; a tie keeps the track
    assert not qa.off_the_track(filtered, cov, ours, truth, cov, theirs, ~track_ok).any()
    assert not qa.off_the_track(filtered, cov, theirs + 1, truth, cov, theirs, track_ok).any()
    assert np.array_equal(qa.off_the_track(filtered, cov, theirs, truth, cov, theirs, track_ok), found)
    # within the gate of large covariances: not off
    assert not qa.off_the_track(filtered, 1e4 * cov, ours, truth, cov, theirs, track_ok).any()
    checked = qa.with_track(check(toa, filtered, emissions, fx, fc, trusted, cov), found)
    assert (checked.quality[off] == "flagged").all()
    assert all("off_the_track" in why.split(";") for why in checked.reason[off])
    assert not any("off_the_track" in why for why in np.delete(checked.reason, off))
