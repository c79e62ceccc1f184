"""A single-ping fix's protection level (RAIM: the largest horizontal error one faulty arrival leaves unseen by the
fix's own χ² test) against an independent computation: each arrival biased until scipy's nonlinear least-squares
fix of the ping just reaches the test's threshold, and the fix's move measured; a fix with no redundant arrival
unprotected; a fix one reflection could have put as far from the track as it is refutes nothing there and is itself
off the track, however many arrivals it explains."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.stats import chi2 as chi2_dist

from sblsim.models.tracking.integrity import TEST_PROBABILITY, protection_levels
from sblsim.models.tracking.quality import TRUSTED_FIX_DRMS, check_track, off_the_track

C = 1480.0
SIGMA = 2e-4
#: A timing noise small enough that a fault's move is metres at most: the linearised level and the nonlinear
#: fix's move compare within a per cent (the level scales with the noise).
SMALL = 5e-6


def _fix(receivers: np.ndarray, toa: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, float]:
    """The ping's position and its χ² by scipy's least squares on (x, y, emission time)."""
    def residual(v):
        return (toa - v[2] - np.linalg.norm(receivers - v[:2], axis=1) / C) / SMALL
    guess = np.r_[start, np.min(toa) - np.min(np.linalg.norm(receivers - start, axis=1)) / C]
    done = least_squares(residual, guess, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return done.x[:2], float(np.sum(done.fun ** 2))


def _undetected_move(receivers: np.ndarray, tag: np.ndarray) -> float:
    """The largest horizontal move of the fix by one arrival biased until the fix's χ² reaches the threshold."""
    toa = 10.0 + np.linalg.norm(receivers - tag, axis=1) / C
    threshold = chi2_dist.ppf(TEST_PROBABILITY, len(receivers) - 3)
    worst = 0.0
    for i in range(len(receivers)):
        unit = np.zeros(len(receivers))
        unit[i] = SMALL
        # the χ² grows as the square of the bias (linear model): one probe gives the bias at the threshold
        _, probe = _fix(receivers, toa + unit, tag)
        if probe <= 0:
            continue
        b = np.sqrt(threshold / probe)
        moved, _ = _fix(receivers, toa + b * unit, tag)
        worst = max(worst, float(np.linalg.norm(moved - tag)))
    return worst


@pytest.mark.parametrize("tag", [(40.0, 30.0), (120.0, -60.0), (10.0, 90.0)])
def test_the_protection_level_is_the_largest_move_one_fault_leaves_unseen(tag):
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 80.0], [0.0, 80.0], [50.0, 120.0], [-30.0, 40.0]])
    tag = np.array(tag)
    level = protection_levels(receivers, tag[None], np.ones((1, len(receivers)), bool), C, SMALL)[0]
    assert level == pytest.approx(_undetected_move(receivers, tag), rel=0.02)


def test_a_weak_geometry_is_unprotected_where_a_strong_one_is_protected():
    strong = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 80.0], [0.0, 80.0]])
    weak = np.array([[0.0, 0.0], [40.0, 0.5], [80.0, -0.5], [120.0, 0.3]])  # near one line, the tag beside it
    tags = np.array([[50.0, 40.0], [60.0, 300.0]])
    levels = [protection_levels(r, t[None], np.ones((1, 4), bool), C, SIGMA)[0] for r, t in zip((strong, weak), tags)]
    assert levels[0] < TRUSTED_FIX_DRMS < levels[1]
    small = protection_levels(weak, tags[1][None], np.ones((1, 4), bool), C, SMALL)[0]
    assert small == pytest.approx(_undetected_move(weak, tags[1]), rel=0.02)
    assert levels[1] == pytest.approx(small * SIGMA / SMALL)  # the level scales with the timing noise


def test_a_fix_one_reflection_could_have_put_that_far_refutes_nothing_and_is_off_the_track():
    """Three pings, the track 30 m from a trusted fix at the middle one that explains more of its arrivals (the
    track's three there fitted exactly, unchecked by them): off that fix unless the fix's protection level reaches
    30 m; and the fix, off the track only where it does."""
    t = np.array([0.0, 2.0, 4.0])
    track = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    fixes = track + [[0.0, 0.0], [0.0, 30.0], [0.0, 0.0]]
    small = np.repeat(np.eye(2)[None] * 0.04, 3, axis=0)
    explained, fix_used = np.array([6, 3, 6]), np.array([6, 6, 6])

    def flagged(protection):
        return check_track(t, track, small, fixes, small, np.ones(3, bool), explained=explained, fix_used=fix_used,
                           fix_protection=protection).quality.tolist()

    assert flagged(None) == ["ok", "flagged", "ok"] and flagged(np.array([1.0, 12.0, 1.0]))[1] == "flagged"
    assert flagged(np.array([1.0, 45.0, 1.0])) == ["ok", "ok", "ok"]
    off = [off_the_track(fixes, small, fix_used, track, small, explained, np.ones(3, bool), None, protection)[1]
           for protection in (None, np.array([1.0, 12.0, 1.0]), np.array([1.0, 45.0, 1.0]))]
    assert off == [False, False, True]  # the fix explains more: off only where one fault could have put it there


def test_a_fix_with_no_arrival_to_spare_or_none_at_all_is_unprotected_or_unassessed():
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 80.0], [0.0, 80.0]])
    used = np.array([[True, True, True, False], [True] * 4, [True] * 4])
    positions = np.array([[50.0, 40.0], [50.0, 40.0], [np.nan, np.nan]])
    level = protection_levels(receivers, positions, used, C, SIGMA)
    assert level[0] == np.inf and np.isfinite(level[1]) and np.isnan(level[2])
    # an arrival the fix did not keep takes no part: the same level as the fix of the arrivals it kept
    more = np.vstack([receivers, [[500.0, 500.0]]])
    kept = np.array([[True] * 4 + [False]])
    assert protection_levels(more, positions[1:2], kept, C, SIGMA)[0] == pytest.approx(level[1])
