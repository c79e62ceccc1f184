"""One id heard from two places at once (issue 98 item 6): :func:`sblsim.models.tracking.two_places.places_at_once`
on single-ping fixes of simulated pings. Two emitters 400 m apart under one id, the second heard a fraction of the
time, are found whatever the first does (a slow circle or a fast one), and the rows it calls the second place's are
exactly the second emitter's trusted fixes (the truth's labels, not the code's); one tag is never split in two,
whether it moves, goes back and forth between two places 400 m apart (not at once), moves fast, or its arrivals are
late by reflections; a second place a reflection could explain (protection levels without bound) is not one.

The pings are made here, independently of the code: receivers on a 5 x 5 grid 150 m apart, each emitter's times at a
random burst interval, the arrival at a receiver its distance over the sound speed with a Gaussian timing noise,
heard with a logistic detection range curve (50 % at 220 m)."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import quality as qa
from sblsim.models.tracking.integrity import protection_levels
from sblsim.models.tracking.two_places import chains, places_at_once

SPEED = 1480.0
SIGMA = 1.5e-4
SPAN = 6 * 3600.0


def _grid(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    g = np.array([(i, j) for j in range(5) for i in range(5)], float) * 150.0
    return g - g.mean(axis=0) + rng.normal(0, 15.0, g.shape)


def _times(rng, start: float, end: float, bounds=(100.0, 200.0)) -> np.ndarray:
    tau = rng.uniform(0, bounds[1]) + np.r_[0, np.cumsum(rng.uniform(*bounds, int(SPAN / bounds[0]) + 2))]
    return tau[(tau >= start) & (tau < end)]


def _pings(rng, receivers, emitters, late: float = 0.0):
    """One times-of-arrival matrix of every emitter's pings (``(times, positions)`` each), rows in order of first
    arrival, rows nobody heard dropped; each row's emitter. ``late``: the share of arrivals a reflection delays by
    up to 40 m of path."""
    rows, source = [], []
    for k, (tau, where) in enumerate(emitters):
        d = np.linalg.norm(where[:, None] - receivers[None], axis=2)
        toa = tau[:, None] + d / SPEED + rng.normal(0, SIGMA, d.shape)
        toa += (rng.random(d.shape) < late) * rng.uniform(0, 40.0, d.shape) / SPEED
        toa[rng.random(d.shape) >= 1 / (1 + np.exp((d - 220.0) / (220.0 / 6)))] = np.nan
        rows.append(toa)
        source.append(np.full(len(tau), k))
    toa, source = np.vstack(rows), np.concatenate(source)
    heard = np.isfinite(toa).any(axis=1)
    first = np.where(heard, np.nanmin(np.where(np.isfinite(toa), toa, np.inf), axis=1), np.inf)
    order = np.argsort(first, kind="stable")[:heard.sum()]
    return toa[order], source[order]


def _circle(tau, centre, radius, period, phase=0.0):
    a = 2 * np.pi * tau / period + phase
    return np.asarray(centre) + np.c_[radius * np.cos(a), radius * np.sin(a)]


def _fixes(toa, receivers, bounded: bool = True):
    fx, fe, fc, used, chi2 = tt.fix_pings(toa, receivers, SPEED, SIGMA)
    trusted = qa.trusted_fixes(fx, fc, used.sum(axis=1), np.isfinite(toa).sum(axis=1), chi2, 2, None)
    level = protection_levels(receivers, fx, used, SPEED, SIGMA) if bounded else np.full(len(fx), np.inf)
    return fx, fe, fc, trusted, level


def _twins(seed: int, radius_first: float):
    """The first emitter on a circle of ``radius_first`` round (-200, 0) m the whole 6 hours, the second 400 m away
    on a 30 m circle round (200, 0) m for the middle 30 % of them."""
    rng = np.random.default_rng(seed)
    receivers = _grid(seed)
    a, b = _times(rng, 0.0, SPAN), _times(rng, 0.35 * SPAN, 0.65 * SPAN)
    toa, source = _pings(rng, receivers, [(a, _circle(a, (-200.0, 0.0), radius_first, 5400.0)),
                                          (b, _circle(b, (200.0, 0.0), 30.0, 7200.0, 1.0))])
    return receivers, toa, source


@pytest.mark.parametrize("seed, radius", [(0, 30.0), (1, 30.0), (2, 120.0), (3, 120.0)])
def test_a_second_emitter_on_one_id_is_found_and_only_its_rows(seed, radius):
    receivers, toa, source = _twins(seed, radius)
    fx, fe, fc, trusted, level = _fixes(toa, receivers)
    found = places_at_once(fx, fe, fc, trusted, level)
    assert found is not None
    second = source == 1
    # its trusted fixes are the second emitter's, all of them, counted from the truth's labels
    assert (found.second[trusted] == second[trusted]).all()
    assert found.fixes == (int((trusted & ~second).sum()), int((trusted & second).sum()))
    assert found.shares[1] == pytest.approx((trusted & second).mean() / trusted.mean())
    # every row it adds (untrusted fixes) is the second emitter's too
    assert not (found.second & ~second).any()
    # the places: the second within its circle of (200, 0), the first within its circle of (-200, 0)
    assert np.hypot(*(found.places[1] - (200.0, 0.0))) < 30.0 + 5.0
    assert np.hypot(*(found.places[0] - (-200.0, 0.0))) < radius + 5.0
    assert 400.0 - radius - 60.0 < found.separation < 400.0 + radius + 60.0
    assert 10 <= found.out_of_reach <= found.fixes[1]


def _one(seed: int, kind: str, late: float = 0.05, bounds=(100.0, 200.0)):
    rng = np.random.default_rng(seed)
    receivers = _grid(seed)
    tau = _times(rng, 0.0, SPAN, bounds)
    if kind == "circle":  # 200 m round the array's middle, 0.23 m/s
        where = _circle(tau, (0.0, 0.0), 200.0, 5400.0)
    elif kind == "fast":  # 4.2 m/s
        where = _circle(tau, (0.0, 0.0), 200.0, 300.0)
    else:  # an hour at (-200, 0), ten minutes across to (200, 0), an hour there, back: two places, not at once
        phase = (tau % 8400.0) / 8400.0
        where = np.c_[np.interp(phase, [0, 0.43, 0.5, 0.93, 1.0], [-200, -200, 200, 200, -200]), np.zeros(len(tau))]
    return receivers, _pings(rng, receivers, [(tau, where)], late)[0]


@pytest.mark.parametrize("seed, kind, late, bounds", [
    (0, "circle", 0.05, (100.0, 200.0)), (1, "circle", 0.15, (100.0, 200.0)),
    (2, "shuttle", 0.1, (100.0, 200.0)), (3, "shuttle", 0.1, (100.0, 200.0)),
    (4, "fast", 0.05, (20.0, 40.0)), (5, "fast", 0.05, (20.0, 40.0)),
])
def test_one_tag_is_never_two_places(seed, kind, late, bounds):
    receivers, toa = _one(seed, kind, late, bounds)
    fx, fe, fc, trusted, level = _fixes(toa, receivers)
    assert trusted.sum() > 100
    assert places_at_once(fx, fe, fc, trusted, level) is None


def test_a_jump_one_reflection_could_make_is_no_second_place():
    receivers, toa, _ = _twins(0, 30.0)
    fx, fe, fc, trusted, level = _fixes(toa, receivers)
    assert places_at_once(fx, fe, fc, trusted, level) is not None
    assert places_at_once(fx, fe, fc, trusted, np.full(len(fx), np.inf)) is None  # protection levels unbounded
    assert places_at_once(fx, fe, fc, np.zeros(len(fx), bool), level) is None  # no trusted fix


def test_chains_follow_each_emitter():
    """Two still emitters 400 m apart, interleaved every 10 s, each fix within a metre: two chains, each one
    emitter's; one emitter on a straight line at 1 m/s: one chain."""
    rng = np.random.default_rng(0)
    t = np.arange(60) * 10.0
    which = rng.random(60) < 0.5
    p = np.where(which[:, None], (400.0, 0.0), (0.0, 0.0)) + rng.normal(0, 0.3, (60, 2))
    label = chains(p, t, np.full(60, 0.2))
    assert len(np.unique(label)) == 2 and all(len(np.unique(which[label == c])) == 1 for c in np.unique(label))
    line = np.c_[t, np.zeros(60)] + rng.normal(0, 0.3, (60, 2))
    assert (chains(line, t, np.full(60, 0.2)) == 0).all()
