"""The fixes' splice rounds over their own windows (models/tracking/starts.py, models/tracking/smoother_windows.py):
a window re-solved with the rest of the track held is the track's own minimum there and its gain the whole cost's
fall (the cost written again with numpy); the windowed rounds give the whole record's re-solve, written here by hand
as the rounds were before (a re-solve of the whole record from the track and from its splice)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking import starts
from sblsim.models.tracking.modes import MODE_BETTER
from sblsim.models.tracking.smoother_windows import resolved_windows
from tests.models.test_toa_smoother import cost_residuals

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

#: Eight receivers on a 300 m × 250 m site, invented.
RECEIVERS = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 250.0], [0.0, 250.0], [150.0, 125.0], [60.0, 240.0],
                      [240.0, 20.0], [30.0, 130.0]])


def _record(seed: int, pings: int, detection: float, late: float = 0.0):
    """A simulated random-interval tag (U(20, 40) s) among :data:`RECEIVERS`, ``late`` of its arrivals 5-30 ms late:
    times of arrival, settings, schedule, the single-ping fixes, the truth's states as a start."""
    s = tt.TrackerSettings(sound_speed=1450.0, sigma_toa=1.5e-4, interval=30.0, acceleration_psd=1e-5)
    rng = np.random.default_rng(seed)
    toa, truth, emissions = tt.simulate_pings(RECEIVERS, pings, s, rng, speed=0.4, detection=detection,
                                              ping_type="rbi", burst_interval=(20.0, 40.0))
    delayed = np.isfinite(toa) & (rng.random(toa.shape) < late)
    toa = np.where(delayed, toa + rng.uniform(5e-3, 3e-2, toa.shape), toa)
    schedule = ps.build_schedule(toa, "rbi", s.interval, s.jitter, s.interval_drift,
                                 ps.crossing_time(RECEIVERS, s.sound_speed), (20.0, 40.0))
    fx, fe, _, fused, _ = tt.fix_pings(toa, RECEIVERS, s.sound_speed, s.sigma_toa)
    X = np.zeros((pings, 6))
    X[:, :2], X[:, 2:4] = truth, np.gradient(truth, emissions, axis=0)
    X[:, 4], X[:, 5] = emissions, s.interval
    return toa, s, schedule, (fx, fe, fused), X


def _cost(X: np.ndarray, toa: np.ndarray, s: tt.TrackerSettings, schedule) -> float:
    """The smoother's cost at the states X, from its definition written with numpy (Σ r²)."""
    return float(np.sum(cost_residuals(X.ravel(), toa, RECEIVERS, s, 3.0, schedule) ** 2))


def _whole_rounds(track, toa, s, fixes, schedule):
    """The rounds as they were: each a re-solve of the whole record from the track and from its splice, kept where
    the cost is lower by more than MODE_BETTER, up to SPLICE_ROUNDS."""
    for _ in range(starts.SPLICE_ROUNDS):
        pings = starts.splice_pings(track.x, toa, RECEIVERS, s, fixes)
        if not len(pings):
            break
        again = tt.robust_smooth(toa, RECEIVERS, s, [track.x, starts.spliced(track.x, fixes, pings)],
                                 schedule=schedule, covariance=False, student_start=False)
        if not again.cost < track.cost - MODE_BETTER:
            break
        track = again
    return track


def test_a_window_re_solved_with_the_rest_held_is_the_minimum_there_and_its_gain_the_whole_cost_s_fall():
    """The track at its minimum, two stretches moved 20 m off and re-solved in their windows (the rows about them
    held): the windows come back to the minimum's states, the held rows are not in them, and each window's gain is
    the whole cost's fall (the cost written again) when its states alone are put in; after the screening's steps
    the gain is no larger."""
    toa, s, schedule, _, truth = _record(seed=4, pings=120, detection=0.8)
    right = tt.robust_smooth(toa, RECEIVERS, s, [truth], schedule=schedule, covariance=False)
    X = right.x.copy()
    X[30:34, 0] += 20.0
    X[80:83, 1] -= 20.0
    lo, hi = np.array([22, 72]), np.array([42, 92])
    found = resolved_windows(X, X, lo, hi, toa, RECEIVERS, s, schedule)
    assert [len(x) for x in found.x] == [20, 20] and [len(w) for w in found.weights] == [20, 20]
    for b in range(2):
        rows = slice(lo[b], hi[b])
        assert np.abs(found.x[b][:, :2] - right.x[rows, :2]).max() < 1e-3  # the minimum's own stop: 0.1 mm
        put = X.copy()
        put[rows] = found.x[b]
        fall = _cost(X, toa, s, schedule) - _cost(put, toa, s, schedule)
        assert found.gain[b] == pytest.approx(fall, rel=1e-9) and fall > 100.0
        assert found.screened[b] <= found.gain[b] + 1e-9
    assert found.edge.max() < 1e-3


def test_windows_that_overlap_or_touch_are_joined():
    """Windows of 16 pings each side: those whose rows meet (one's held row another's row) are one window; those
    one held row apart stay two; each splice's window named."""
    lo, hi, owner = starts._joined(np.array([10, 40, 80, 113, 130]), np.full(5, 16), 150)
    # by hand: [0, 27) and [24, 57) overlap; [64, 97) and [97, 130) touch (97 a row of the second); [114, 147)
    # begins after [97, 130) ends: joined too
    assert lo.tolist() == [0, 64] and hi.tolist() == [57, 147] and owner.tolist() == [0, 0, 1, 1, 1]
    lo, hi, owner = starts._joined(np.array([20, 54]), np.full(2, 16), 100)
    # [4, 37) and [38, 71): row 37 held by both, no row of one among the other's
    assert lo.tolist() == [4, 38] and hi.tolist() == [37, 71] and owner.tolist() == [0, 1]


def test_the_benchmark_s_splices_are_screened_in_windows_of_their_own_and_the_track_kept_as_a_whole_re_solve():
    """The benchmark's record (a stable 2.5 s tag inside 8 receivers, 1 % of the arrivals late), 2,000 pings: the
    fixes the track disagrees with are screened in windows of their own (33 pings) whose splice comes back to the
    track (their gain nothing: not widened, their edges not measured); the track is kept as it is, as the whole
    record's re-solve keeps it (its cost not lower by MODE_BETTER)."""
    import bench_tracking_scale as bench

    from sblsim.models.tracking.timing import SIGMA_TOA

    toa, receivers, _, _, s = bench.simulate(2000, seed=0)
    fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, bench.SOUND_SPEED, SIGMA_TOA)
    fixes = (fx, fe, fused)
    schedule = ps.PingSchedule.stable(len(toa), s.interval, s.jitter, s.interval_drift)
    track = tt.robust_smooth(toa, receivers, s, [tt.anchored_start(fixes, np.isfinite(toa).sum(axis=1), s, 2)],
                             schedule=schedule, covariance=False)
    assert track.converged
    pings = starts.splice_pings(track.x, toa, receivers, s, fixes)
    assert len(pings) >= 1
    found = starts.splice_windows(track.x, starts.spliced(track.x, fixes, pings), pings, toa, receivers, s, schedule)
    assert np.array_equal(found.lo, pings - starts.SPLICE_MARGIN) and np.array_equal(found.hi - found.lo,
                                                                                     np.full(len(pings), 33))
    assert np.abs(found.gain).max() < MODE_BETTER and np.isnan(found.edge).all()
    assert starts.with_fixes_spliced(track, toa, receivers, s, fixes, schedule) is track
    again = tt.robust_smooth(toa, receivers, s, [track.x, starts.spliced(track.x, fixes, pings)], schedule=schedule,
                             covariance=False, student_start=False)
    assert not again.cost < track.cost - MODE_BETTER


def test_a_weakly_determined_record_s_windows_grow_to_the_whole_record_s_answer():
    """Few arrivals a ping (detection 0.4, 5 % of them late): the pipeline's track (no rounds) sits in a local
    minimum whose splice moves the whole track by decimetres; the windows widen until their edges hold and the
    answer is the whole record's re-solve's; with the covariance asked, it is made for the track kept."""
    toa, s, schedule, fixes, _ = _record(seed=7, pings=200, detection=0.4, late=0.05)
    rounds = starts.SPLICE_ROUNDS
    try:
        starts.SPLICE_ROUNDS = 0
        first = tt.robust_track(toa, RECEIVERS, s, fixes, None, schedule, modes=False)
    finally:
        starts.SPLICE_ROUNDS = rounds
    assert first.converged and first.P is not None
    new = starts.with_fixes_spliced(first, toa, RECEIVERS, s, fixes, schedule)
    whole = _whole_rounds(first, toa, s, fixes, schedule)
    assert whole.cost < first.cost - 10.0
    assert np.hypot(*(new.x[:, :2] - whole.x[:, :2]).T).max() < 1e-6
    assert new.cost == pytest.approx(whole.cost, rel=1e-9)
    with_p = tt.robust_smooth(toa, RECEIVERS, s, [new.x], schedule=schedule, iterations=0)
    assert np.allclose(new.P, with_p.P, rtol=1e-9, atol=1e-15)


def test_an_unconverged_track_s_rounds_re_solve_the_whole_record():
    """A track its solve stopped at its iterations allowed (none: held where it was put, 60 m off over six pings):
    the rounds are the whole record's re-solve, bit for bit."""
    toa, s, schedule, fixes, truth = _record(seed=4, pings=160, detection=0.8)
    right = tt.robust_smooth(toa, RECEIVERS, s, [truth], schedule=schedule, covariance=False)
    off = right.x.copy()
    off[60:66, 0] += 60.0
    early = tt.robust_smooth(toa, RECEIVERS, s, [off], schedule=schedule, covariance=False, iterations=0)
    assert not early.converged
    new = starts.with_fixes_spliced(early, toa, RECEIVERS, s, fixes, schedule)
    whole = _whole_rounds(early, toa, s, fixes, schedule)
    assert new.cost < early.cost - 100.0 and np.array_equal(new.x, whole.x) and new.cost == whole.cost
    assert new.iterations == whole.iterations and new.converged == whole.converged
