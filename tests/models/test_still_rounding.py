"""A still tag's verdict on times rounded to a coarse grid (models/tracking/still_tag.py ``rounding``, the verdict's
``white_floor``): the arrivals simulated here on drifting receivers' clocks, floored to hundredths of a second as a
receiver logs them, and the clocks then taken out exactly, so that the rounding is the only error but for 0.1 ms of
noise. While the receivers' arrivals round alike the fixes scatter far less than the rounding's σ, and more later:
taken as the fixes' own scatter, that change is called a move."""

from __future__ import annotations

import numpy as np

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.sync.resolution import rounding_sigma, time_quantum
from sblsim.models.tracking import quality as qa
from sblsim.models.tracking.still_tag import still_tag

RECEIVERS = np.array([[0.0, 0.0], [600.0, 0.0], [600.0, 450.0], [0.0, 450.0], [300.0, 225.0], [180.0, 420.0]])
C, NOISE, QUANTUM = 1480.0, 1e-4, 0.01
TAG = np.array([350.0, 160.0])
#: The clocks' drift [1]: ±0.05 ppm, so that two receivers' arrivals drift across a quantum of each other in a day
#: or more (a clock's own drift, before it is synchronised, is a few ppm; what matters here is how the receivers'
#: times move against each other on the grid while their rounding stays alike).
DRIFT = 0.05e-6


def _toa(seed: int, moved: float = 0.0, quantum: float = QUANTUM) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two days of pings 540-660 s apart at :data:`TAG` (``moved`` [m] along x from half way): their times of
    arrival on the true time base (m, 6) [s], each read on its receiver's clock (an offset of seconds, a drift of
    :data:`DRIFT`), floored to ``quantum`` [s] and the clock taken out again; the pings' places (m, 2) [m]; and the
    times as logged (m, 6) [s]."""
    rng = np.random.default_rng(seed)
    emitted = np.cumsum(rng.uniform(540.0, 660.0, 288))
    places = np.repeat(TAG[None], len(emitted), axis=0)
    places[len(emitted) // 2:, 0] += moved
    true = emitted[:, None] + np.linalg.norm(places[:, None] - RECEIVERS[None], axis=2) / C \
        + NOISE * rng.normal(size=(len(emitted), len(RECEIVERS)))
    offset, drift = rng.uniform(-2.0, 2.0, len(RECEIVERS)), rng.uniform(-DRIFT, DRIFT, len(RECEIVERS))
    logged = np.floor((true + offset + drift * true) / quantum) * quantum
    return (logged - offset) / (1.0 + drift), places, logged


def _verdict(toa: np.ndarray, rounding: float | None, quantum: float = QUANTUM):
    sigma = np.full(len(RECEIVERS), np.hypot(NOISE, rounding_sigma(quantum)))
    fx, fe, fc, used, chi2 = tt.fix_pings(toa, RECEIVERS, C, sigma)
    trusted = qa.trusted_fixes(fx, fc, used.sum(axis=1), np.isfinite(toa).sum(axis=1), chi2, 2, None)
    return still_tag(toa, RECEIVERS, C, (fx, fe, fc, used), trusted, sigma, None, {}, None, rounding=rounding)


def test_a_still_tag_on_rounded_times_is_still_and_its_fixes_show_why():
    """Over 12 simulated records: the fixes' own dispersion against their covariances (the rounding's σ) is below
    1 on most (the rounding's error is not the independent noise of that σ); with the rounding given no row of the
    still tag is flagged and each says ``still``, where without it at least one record is called moved (its rows
    flagged)."""
    dispersions, before, after = [], [], []
    for seed in range(12):
        toa, _, _ = _toa(seed)
        alone, given = _verdict(toa, None), _verdict(toa, rounding_sigma(QUANTUM))
        dispersions.append(alone.summary["still"]["dispersion"])
        before.append(int(alone.moved.sum()))
        after.append(int(given.moved.sum()))
        assert given.summary["still"]["verdict"] == "still", (seed, given.summary["still"])
        assert given.summary["still"]["dispersion"] >= 0.99
    assert np.median(dispersions) < 1.0, dispersions
    assert sum(after) == 0 and max(before) > 0, (before, after)


def test_a_tag_moved_on_rounded_times_is_still_flagged_from_the_move():
    """A move of 30 m half way (1.8 to 2.4 times the smallest step a single fix could see here, with the
    rounding's σ a slow error too): called moved with the rounding given, its rows flagged from within 3 pings of
    the move and none before it."""
    toa, places, _ = _toa(11, moved=30.0)
    still = _verdict(toa, rounding_sigma(QUANTUM))
    assert still.summary["still"]["verdict"] == "moved", still.summary["still"]
    half = len(places) // 2
    flagged = np.flatnonzero(still.moved)
    pings = still.pings[flagged]
    assert pings.min() >= half - 3 and pings.min() <= half + 3, pings.min()
    assert not still.moved[still.pings < half - 3].any()


def test_a_grid_of_twentieths_is_found_and_calls_no_still_tag_moved():
    """Times floored to 0.05 s (a grid no decimal step is: the boats' times so floored were taken as hundredths,
    their rounding σ 2.9 ms where it is 14.4 ms, and a quarter of their sync tags' emissions flagged). The grid is
    found from the times as logged (their epoch seconds in 2024), and over 12 records its rounding σ calls no row
    moved; the hundredths' σ (the timing noise and the verdict's both) calls all of one record's rows moved or more."""
    found, before, after = [], [], []
    for seed in range(12):
        toa, _, logged = _toa(seed, quantum=0.05)
        q = time_quantum(1.7e9 + logged.ravel())
        found.append(q)
        before.append(int(_verdict(toa, rounding_sigma(0.01), 0.01).moved.sum()))
        after.append(int(_verdict(toa, rounding_sigma(q), q).moved.sum()))
    assert found == [0.05] * 12, found
    assert sum(after) == 0 and max(before) == len(toa), (before, after)
