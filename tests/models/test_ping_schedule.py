"""The ping types as the steps between the rows of a TOA matrix (models/tracking/schedule.py, ping_type.py,
burst_sequence.py), against the pings a simulation emitted: the type seen, each step's duration, the gaps, a
pseudo-random sequence aligned."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.burst_sequence import PBI_PHASE_STEPS, align_sequence
from sblsim.models.tracking.ping_type import infer_ping_type

RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0]])
SETTINGS = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-4)
SEQUENCE = np.array([22.0, 37.0, 29.0, 31.0, 25.0, 39.0, 21.0, 33.0])


def pings(kind: str, n: int = 120, seed: int = 0, detection: float = 0.9):
    rng = np.random.default_rng(seed)
    return tt.simulate_pings(RECEIVERS, n, SETTINGS, rng, speed=0.2, detection=detection, ping_type=kind,
                             burst_interval=(20.0, 40.0), burst_sequence=SEQUENCE)


def crossing() -> float:
    return ps.crossing_time(RECEIVERS, SETTINGS.sound_speed)


def test_the_crossing_time_is_the_array_s_largest_distance_over_the_speed():
    span = max(np.hypot(*(a - b)) for a in RECEIVERS for b in RECEIVERS)
    assert crossing() == pytest.approx(span / 1480.0, rel=1e-12)
    assert ps.crossing_time(RECEIVERS[:1], 1480.0) == ps.MIN_STEP_SIGMA


@pytest.mark.parametrize("kind", ["sbi", "rbi", "pbi"])
def test_the_type_seen_in_the_first_arrivals(kind):
    toa, _, emissions = pings(kind)
    seen = infer_ping_type(toa, crossing())
    assert seen.kind == ("sbi" if kind == "sbi" else "rbi")  # a sequence looks random without its table
    steps = np.diff(emissions)
    assert seen.interval == pytest.approx(np.median(steps), abs=crossing())
    if kind == "rbi":
        assert 20.0 - crossing() <= seen.bounds[0] < 22.0 and 38.0 < seen.bounds[1] <= 40.0 + crossing()


def test_a_stable_interval_counts_the_pings_a_gap_skipped():
    toa, _, emissions = pings("sbi", n=400)
    kept = np.r_[0:150, 300:400]  # 150 pings (300 s) cut out
    schedule = ps.build_schedule(toa[kept], "sbi", 2.0, SETTINGS.jitter, SETTINGS.interval_drift, crossing())
    expected = np.round(np.diff(emissions[kept]) / 2.0)
    assert np.array_equal(schedule.count, expected) and schedule.count[149] == 151
    assert np.allclose(schedule.steps(), np.diff(emissions[kept]), rtol=0.01)  # the nominal interval; it drifts
    # the 302 s step is a gap: a new segment there
    assert schedule.gaps == (149,) and schedule.segments() == [(0, 150), (150, 250)]
    assert np.allclose(schedule.te_sigma, SETTINGS.jitter * np.sqrt(expected))


def test_a_random_interval_s_steps_are_the_emissions_within_the_crossing_time():
    toa, _, emissions = pings("rbi")
    schedule = ps.build_schedule(toa, "rbi", 30.0, SETTINGS.jitter, SETTINGS.interval_drift, crossing(),
                                 bounds=(20.0, 40.0))
    assert (schedule.count == 0).all() and np.allclose(schedule.te_sigma, crossing())
    assert np.abs(schedule.steps() - np.diff(emissions)).max() <= crossing()
    # a step shorter than the interval's min by more than the crossing time is refused
    with pytest.raises(ModelError, match="below the random interval's min 25"):
        ps.build_schedule(toa, "rbi", 30.0, SETTINGS.jitter, SETTINGS.interval_drift, crossing(), bounds=(25.0, 40.0))


def test_a_pseudo_random_sequence_is_aligned_through_missing_pings():
    toa, _, emissions = pings("pbi", n=150)
    kept = np.sort(np.random.default_rng(3).choice(150, 110, replace=False))  # 40 pings nobody heard
    schedule = ps.build_schedule(toa[kept], "pbi", 30.0, SETTINGS.jitter, SETTINGS.interval_drift, crossing(),
                                 sequence=SEQUENCE)
    true = np.diff(emissions[kept])
    matched = schedule.te_sigma < crossing()
    assert matched.mean() > 0.95
    # where matched, the step is the sequence's sum: the emissions' step to the jitter
    assert np.abs(schedule.steps()[matched] - true[matched]).max() < 10 * SETTINGS.jitter * np.sqrt(5)
    with pytest.raises(ModelError, match="match the sequence"):
        ps.build_schedule(toa[kept], "pbi", 30.0, SETTINGS.jitter, SETTINGS.interval_drift, crossing(),
                          sequence=np.array([5.0, 7.0, 11.0]))


def test_rows_out_of_time_order_or_too_few_are_refused_in_one_line():
    toa, _, _ = pings("sbi", n=20)
    with pytest.raises(ModelError, match=r"row 6's first arrival .* is not after row 5's"):
        ps.first_arrival_steps(toa[[0, 1, 2, 3, 5, 4, 6]])
    with pytest.raises(ModelError, match="1 pings heard; allowed: at least 2"):
        ps.first_arrival_steps(toa[:1])
    with pytest.raises(ModelError, match="ping type: 'xyz'"):
        ps.build_schedule(toa, "xyz", 2.0, 1e-3, 1e-4, crossing())


def test_a_stable_schedule_is_today_s_model_and_slices_keep_their_gaps():
    stable = ps.PingSchedule.stable(5, 2.0, 1e-3, 1e-4)
    assert np.array_equal(stable.times(), [0.0, 2.0, 4.0, 6.0, 8.0])
    toa, _, _ = pings("sbi", n=400)
    schedule = ps.build_schedule(toa[np.r_[0:150, 300:400]], "sbi", 2.0, 1e-3, 1e-4, crossing())
    tail = schedule.sliced(100)
    assert tail.gaps == (49,) and len(tail.count) == len(schedule.count) - 100


@pytest.mark.parametrize("seed", range(5))
def test_a_long_pseudo_random_record_is_aligned_from_its_first_steps_phase(seed):
    """2,000 emissions of a 64-interval sequence started at a random phase, 20 % of the pings unheard (runs of them
    at the start too), the steps seen with 10 ms of travel-time change: every step matched, each duration the true
    emission step (the sum of the intervals it spans) to 1e-9 s, though only the first steps tried every phase."""
    rng = np.random.default_rng(seed)
    sequence = rng.uniform(20.0, 40.0, 64)
    start = int(rng.integers(64))
    emissions = np.cumsum(np.r_[0.0, sequence[(start + np.arange(1999)) % 64]])
    heard = rng.random(2000) > 0.2
    heard[1:6] = False
    steps = np.diff(emissions[heard])
    durations, matched = align_sequence(steps + rng.normal(0.0, 0.01, len(steps)), sequence, 0.17)
    assert matched.all() and len(steps) > PBI_PHASE_STEPS
    assert np.allclose(durations, steps, rtol=0, atol=1e-9)


def test_rows_nobody_heard_at_the_ends_take_the_median_step_per_row():
    """Blank rows before the first heard row and after the last: each step the median over the heard rows of their
    first arrivals' step per row (a step of no duration had no process noise, and a random interval's bounds refused
    it); the steps between heard rows as before, a blank row inside sharing the step across it."""
    toa, _, _ = pings("rbi", n=40, detection=1.0)
    blank = toa.copy()
    blank[[0, 1, 20, 38, 39]] = np.nan
    first = np.nanmin(toa, axis=1)
    heard = np.setdiff1d(np.arange(40), [0, 1, 20, 38, 39])
    per_row = np.median(np.diff(first[heard]) / np.diff(heard))
    steps = ps.first_arrival_steps(blank)
    assert np.allclose(steps[[0, 1, 37, 38]], per_row, rtol=1e-12)
    assert np.allclose(steps[[19, 20]], (first[21] - first[19]) / 2, rtol=1e-12)
    inside = np.setdiff1d(np.arange(2, 37), [19, 20])
    assert np.allclose(steps[inside], np.diff(first)[inside], rtol=1e-12)
    schedule = ps.build_schedule(blank, "rbi", 30.0, SETTINGS.jitter, SETTINGS.interval_drift, crossing(),
                                 bounds=(20.0, 40.0))
    assert (schedule.steps() > 0).all() and 20.0 <= per_row <= 40.0
