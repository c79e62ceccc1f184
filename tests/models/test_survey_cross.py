"""A still tag scored against its own receiver's surveyed position (models/tracking/still_tag.py ``survey_gains``,
``survey_cross``, ``place_score``): the place's sensitivity to each receiver's position against the pooled fix solved
again with that receiver moved, and the score's covariance against Monte Carlo draws of the survey's error, where
the place and the position scored against share one receiver's error."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking.stationary import stationary_fix
from sblsim.models.tracking.still_tag import place_score, survey_cross, survey_gains

RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0],
                      [150.0, 40.0], [40.0, 90.0]])
C = 1480.0


def _pings(rng, p, m: int, sigma: float) -> np.ndarray:
    emissions = np.cumsum(rng.uniform(20.0, 40.0, m))
    toa = emissions[:, None] + np.linalg.norm(p - RECEIVERS, axis=1)[None] / C
    return toa + sigma * rng.normal(size=toa.shape)


def _fix(toa, table, sigma):
    return stationary_fix(toa, table, C, sigma, np.nanmedian(tt.fix_pings(toa, table, C, sigma)[0], axis=0))


@pytest.mark.parametrize("where", [np.array([120.0, 60.0]), np.array([3.0, 4.0])])
def test_the_gains_are_the_pooled_fix_moved_with_a_receiver(where):
    """``G_k`` against central differences of the pooled fix with receiver k's position moved ±1 mm along each axis,
    in the array and 5 m from a receiver; their sum the identity (a translation of the array translates the place)."""
    rng = np.random.default_rng(1)
    toa = _pings(rng, where, 60, 1e-4)
    fix = _fix(toa, RECEIVERS, 1e-4)
    gains = survey_gains(toa, RECEIVERS, C, fix, 1e-4)
    for k in range(len(RECEIVERS)):
        numeric = np.empty((2, 2))
        for axis in range(2):
            moved = [RECEIVERS.copy(), RECEIVERS.copy()]
            moved[0][k, axis] += 1e-3
            moved[1][k, axis] -= 1e-3
            ends = [stationary_fix(toa, r, C, 1e-4, fix.position).position for r in moved]
            numeric[:, axis] = (ends[0] - ends[1]) / 2e-3
        np.testing.assert_allclose(gains[k], numeric, atol=0.01)
    # the whole array moved moves the place with it: the gains sum to the identity
    np.testing.assert_allclose(gains.sum(axis=0), np.eye(2), atol=1e-6)


@pytest.mark.slow
def test_scored_against_its_own_receiver_the_shared_error_is_counted_once():
    """A tag 5 m from receiver 0, 30 pings of 0.1 ms noise, scored against receiver 0's position as surveyed (its
    offset from it known), every position off by N(0, 5 cm) per axis, 300 draws: with the cross term the 2-D NEES
    averages 2 within three of its standard deviations; counting the receiver's error in the place and in the position
    apart (no cross term) makes it smaller than that."""
    survey, noise = 0.05, 1e-4
    where = RECEIVERS[0] + np.array([3.0, 4.0])
    with_cross, without = [], []
    for seed in range(300):
        rng = np.random.default_rng(seed)
        toa = _pings(rng, where, 30, noise)
        table = RECEIVERS + survey * rng.normal(size=RECEIVERS.shape)
        fix = stationary_fix(toa, table, C, noise, where)
        gains = survey_gains(toa, table, C, fix, noise)
        still = {"place": fix.position.tolist(), "survey_gains": gains.tolist(),
                 "covariance": fix.covariance + survey**2 * np.einsum("kij,klj->il", gains, gains)}
        truth = table[0] + (where - RECEIVERS[0])
        known = survey**2 * np.eye(2)
        with_cross.append(place_score(still, truth, known, survey_cross(still, 0, known))[3])
        without.append(place_score(still, truth, known)[3])
    spread = 2.0 / np.sqrt(len(with_cross))  # a χ²(2) mean's standard deviation over the draws
    assert abs(np.mean(with_cross) - 2.0) < 3 * spread, np.mean(with_cross)
    assert np.mean(without) < 2.0 - 3 * spread, np.mean(without)


def test_without_gains_there_is_no_cross_term():
    assert survey_cross({"place": [0.0, 0.0], "covariance": np.eye(2)}, 0, np.eye(2)) is None
