"""The robust smoother's other local modes with late arrivals modelled (sblsim.models.tracking.modes): the windows'
costs against the whole cost written again with scipy's densities, the windows solved together against each
solved alone, and the covariance widened only where the model has late arrivals."""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations

import numpy as np
import pytest

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import modes
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.schedule import PingSchedule
from tests.models.test_toa_smoother import late_arrivals, late_cost, small_problem, start_of
from tests.orchestrator.test_tracking_variants import RECEIVERS


def _late_track(seed: int = 2, pings: int = 24):
    toa, receivers, s, truth, _ = small_problem(seed=seed, pings=pings)
    k0, xs = start_of(toa, receivers, s)
    toa, truth = toa[k0:], truth[k0:]
    s = replace(s, delay_share=0.1, delay_mean=2e-3)
    schedule = PingSchedule.stable(len(toa), s.interval, s.jitter, s.interval_drift)
    return toa, receivers, s, schedule, tt.robust_smooth(toa, receivers, s, [xs[k0:]]), truth


def test_a_windows_cost_is_the_whole_costs_change():
    """Each window's share (:func:`modes._window_costs`: its arrivals and steps and the two steps joining it to the
    track) changes as the whole cost does, written again with scipy's Student-t and exponentially modified
    Gaussian densities (:func:`late_cost`), when the window's states are moved at random (metres, cm/s, tenths of a
    millisecond): to 1e-9 of the cost."""
    toa, receivers, s, schedule, robust, _ = _late_track()
    X = robust.x
    rng = np.random.default_rng(5)
    k = np.array([3, 8, 12, len(toa) - 1])  # windows inside the track, and one at its end
    lo, hi = np.maximum(k - modes.MODE_WINDOW, 0), np.minimum(k + modes.MODE_WINDOW + 1, len(toa))
    states = np.concatenate([X[a:b] for a, b in zip(lo, hi)])
    states = states + rng.normal(0.0, 1.0, states.shape) * np.array([1.0, 1.0, 0.01, 0.01, 1e-4, 1e-6])
    (base, moved), _ = modes._window_costs(toa, receivers, s, schedule, None, X, lo, hi, [states])
    whole = late_cost(X.ravel(), toa, receivers, s)
    first = 0
    for h, (a, b) in enumerate(zip(lo, hi)):
        Y = X.copy()
        Y[a:b] = states[first:first + b - a]
        first += b - a
        change = late_cost(Y.ravel(), toa, receivers, s) - whole
        assert abs((moved[h] - base[h]) - change) <= 1e-9 * abs(whole)
        assert abs(change) > 1.0  # a change that could be missed


@pytest.mark.slow
def test_a_windows_log_determinant_is_its_hessians():
    """The ln det that weighs a mode (:func:`modes._window_costs`' second part, Laplace's evidence) at the track's
    end (three pings, 18 states): the same as the ln det of the Hessian of the whole cost written again with scipy's
    densities (:func:`late_cost`, halved: the cost is −2 ln p) by central differences over the window's states, the
    rest of the track held, to 10⁻³ (the Gauss-Newton Hessian leaves the model's second derivatives out: small at a
    minimum); and at states moved from it, the ln det of the whole track's Hessian (the smoother's covariance's)
    restricted to the window's rows, to 10⁻⁴ (a mode's weight to 10⁻⁴ of itself: the windows solved together
    hardly couple, the velocity's variance across a step of :data:`modes.SEPARATION` about 10³ m²/s²)."""
    from functools import partial

    from sblsim.models.tracking.smoother_cost import ROBUST_DOF, _arrival_sums, _Problem
    from sblsim.models.tracking.smoother_system import _dense_blocks, _normal_blocks

    toa, receivers, s, schedule, robust, _ = _late_track()
    X, m = robust.x, len(robust.x)
    lo, hi = np.array([m - 3, 4]), np.array([m, 9])
    rng = np.random.default_rng(7)
    moved = np.concatenate([X[a:b] for a, b in zip(lo, hi)])
    moved = moved + rng.normal(0.0, 1.0, moved.shape) * np.array([1.0, 1.0, 0.01, 0.01, 1e-4, 1e-6])
    _, (at_track, at_moved) = modes._window_costs(toa, receivers, s, schedule, None, X, lo, hi, [moved])
    a, b = lo[0], hi[0]
    step = np.tile([1e-3, 1e-3, 1e-3, 1e-3, 1e-6, 1e-7], b - a)
    n = len(step)

    def cost(v):
        Y = X.copy()
        Y[a:b] += (v * step).reshape(b - a, -1)
        return late_cost(Y.ravel(), toa, receivers, s)

    E, H = np.eye(n), np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            H[i, j] = H[j, i] = (cost(E[i] + E[j]) - cost(E[i] - E[j]) - cost(E[j] - E[i]) + cost(-E[i] - E[j])) / 4
    sign, numeric = np.linalg.slogdet(H / np.outer(step, step) / 2)
    assert sign > 0 and abs(at_track[0] - numeric) < 1e-3, (at_track[0], numeric)
    first = 0
    for h, (a, b) in enumerate(zip(lo, hi)):
        Y = X.copy()
        Y[a:b] = moved[first:first + b - a]
        first += b - a
        problem = _Problem(toa, receivers, s, schedule)
        sums = _arrival_sums(problem, Y, ROBUST_DOF, information=True)
        D, B = _dense_blocks(problem, partial(_normal_blocks, problem, Y, sums, problem.count * Y[:-1, -1]
                                              + problem.offset))
        dense = np.zeros((m * 6, m * 6))
        for r in range(m):
            dense[6 * r:6 * r + 6, 6 * r:6 * r + 6] = D[r]
            if r < m - 1:
                dense[6 * r:6 * r + 6, 6 * r + 6:6 * r + 12] = B[r]
                dense[6 * r + 6:6 * r + 12, 6 * r:6 * r + 6] = B[r].T
        sign, whole = np.linalg.slogdet(dense[6 * a:6 * b, 6 * a:6 * b])
        assert sign > 0 and abs(at_moved[h] - whole) < 1e-4, (h, at_moved[h], whole)
        assert abs(at_moved[h] - at_track[h]) > 1e-3  # moved states that change it


def test_windows_solved_together_are_each_solved_alone():
    """The hypotheses' windows, solved as one problem across :data:`modes.SEPARATION` steps, give each window's
    states as the same window solved alone (the arrivals left out, then back; one hypothesis of two late
    arrivals), to 1 mm and 1 µs (each stops where a step gains less than 10⁻⁸ of its own cost, the windows together
    at a larger cost)."""
    toa, receivers, s, schedule, robust, _ = _late_track()
    X = robust.x
    k = np.array([5, 6, 14])
    j = np.array([np.flatnonzero(np.isfinite(toa[p]))[:2] for p in k])
    j[1:, 1] = -1  # the first a pair, the others one arrival each
    together, lo, hi, rows, at = modes._solve(toa, receivers, s, schedule, None, X, k, j, start_mean=True)
    edges = np.r_[0, np.cumsum(hi - lo)]
    for h in range(len(k)):
        a, b = lo[h], hi[h]
        alone_toa = toa[a:b].copy()
        alone_toa[k[h] - a, j[h][j[h] >= 0]] = np.nan
        start = X[a:b].copy()
        start[k[h] - a] = 0.5 * (X[k[h] - 1] + X[k[h] + 1])
        window = PingSchedule.stable(b - a, s.interval, s.jitter, s.interval_drift)
        alone = tt.robust_smooth(alone_toa, receivers, s, [start], iterations=modes.MODE_ITERATIONS[0],
                                 covariance=False, schedule=window, student_start=False).x
        alone = tt.robust_smooth(toa[a:b], receivers, s, [alone], iterations=modes.MODE_ITERATIONS[1],
                                 covariance=False, schedule=window, student_start=False).x
        mine = together[edges[h]:edges[h + 1]]
        assert np.array_equal(rows[edges[h]:edges[h + 1]], np.arange(a, b))
        assert np.abs(mine[:, :2] - alone[:, :2]).max() < 1e-3
        assert np.abs(mine[:, 4] - alone[:, 4]).max() < 1e-6


@pytest.mark.slow
def test_the_covariance_widens_only_with_late_arrivals_modelled():
    """Without late arrivals in the model the track is returned as it is; with them its position covariance is
    the track's plus a positive semi-definite spread, and a track re-solved from a better mode costs less."""
    toa, receivers, s, schedule, robust, _ = _late_track(seed=4)
    plain = replace(s, delay_share=0.0)
    assert modes.with_modes(robust, toa, receivers, plain, schedule) is robust
    widened = modes.with_modes(robust, toa, receivers, s, schedule)
    assert widened.cost <= robust.cost
    if widened.cost == robust.cost:
        extra = widened.P[:, :2, :2] - robust.P[:, :2, :2]
        assert np.linalg.eigvalsh(extra).min() > -1e-12
    found = modes.local_modes(robust, toa, receivers, s, schedule)
    heard = np.isfinite(toa).sum(axis=1)
    pairs = sum(len(list(combinations(range(n), 2))) for n in heard if n >= 4)
    assert pairs > 0 and found.hypotheses == int(heard[heard >= 3].sum()) + pairs


def _random_interval_track(seed: int = 5):
    """A tag at a random burst interval U(20, 40) s among 8 receivers, 10 % of its arrivals late, the robust smoother
    told (its other modes of weight: each ping placed nearly alone by its own arrivals)."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=30.0, acceleration_psd=1e-5)
    rng = np.random.default_rng(seed)
    toa, _, _ = tt.simulate_pings(RECEIVERS, 40, s, rng, speed=0.05, detection=0.5, ping_type="rbi",
                                  burst_interval=(20.0, 40.0))
    toa = late_arrivals(toa, rng, 0.1)
    schedule = ps.build_schedule(toa, "rbi", s.interval, s.jitter, s.interval_drift,
                                 ps.crossing_time(RECEIVERS, s.sound_speed), (20.0, 40.0))
    fx, fe, _, fu, _ = tt.fix_pings(toa, RECEIVERS, s.sound_speed, s.sigma_toa)
    s = replace(s, delay_share=0.1, delay_mean=2e-3)
    return toa, s, schedule, tt.robust_track(toa, RECEIVERS, s, (fx, fe, fu), None, schedule, modes=False)


@pytest.mark.slow
def test_a_search_of_some_pings_keeps_the_others_share():
    """The spread split by the hypotheses' ping: the pings searched in two halves, the second keeping the first's
    share, sum to the whole search's spread (to 1e-6 of it: the windows solved together hardly couple); after a
    re-solve only the pings within the window (and its joining row) of a state moved by more than
    :data:`MODE_MOVED` σ are searched again (counted here from the moved rows by hand)."""
    toa, s, schedule, robust = _random_interval_track()
    whole = modes.local_modes(robust, toa, RECEIVERS, s, schedule)
    assert (np.abs(whole.spread).max(axis=(1, 2)) > 1e-3).sum() >= 2 and whole.better is not None
    first = np.arange(len(toa)) < len(toa) // 2
    half = modes.local_modes(robust, toa, RECEIVERS, s, schedule, pings=first)
    both = modes.local_modes(robust, toa, RECEIVERS, s, schedule, pings=~first, base=half)
    assert np.allclose(both.spread, whole.spread, rtol=0.0, atol=1e-6 * np.abs(whole.spread).max())
    assert not half.by_ping[~first].any() and half.hypotheses + both.hypotheses == whole.hypotheses
    after = robust.x.copy()
    after[10, 4] += 0.2 * np.sqrt(robust.P[10, 4, 4])  # ping 10's emission time moved by 0.2 σ, ping 3's x by 0.05
    after[3, 0] += 0.05 * np.sqrt(robust.P[3, 0, 0])
    reach = modes.MODE_WINDOW + 1
    assert np.array_equal(np.flatnonzero(modes.moved_pings(robust.x, after, robust.P)),
                          np.arange(10 - reach, 10 + reach + 1))
