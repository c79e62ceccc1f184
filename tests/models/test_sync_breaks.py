"""Clock breaks (:mod:`sblsim.models.sync.breaks`) on small simulations
(:func:`sblsim.models.sync.simulate.simulate_sync` with one receiver's clock jumping): the break found at its time
within the arrivals' spacing and its size within its sigma, the arrivals put in their segments, the offsets after
the split as close to the truth as without the jump; no break without one; the jump scan's algebra against an
explicit least squares."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from sblsim.models.sync.breaks import THRESHOLD, _bounds
from sblsim.models.sync.change_points import scan
from sblsim.models.sync.clocks import fit_clocks
from sblsim.models.sync.emissions import connected, sync_emissions
from tests.helpers import simulated_clocks

N, HOURS = 8, 6.0


@lru_cache(maxsize=None)
def _fit(seed: int, jump: tuple[int, float, float] | None = None, threshold: float = THRESHOLD):
    """A simulated array of :data:`N` receivers over :data:`HOURS` h (:func:`tests.helpers.simulated_clocks`), the
    clocks fitted with their breaks against receiver 0."""
    sim, origin, t, used, *_, fit = simulated_clocks(N, HOURS, seed, jump, threshold=threshold)
    return sim, origin, t, used, fit


def _error(sim, t: np.ndarray, fit, used: np.ndarray, receiver: int | None = None) -> np.ndarray:
    """[s] each used arrival's fitted offset less the truth (against receiver 0's clock before any jump of it)."""
    rows = sim.receiver if fit.clock is None else fit.clock
    tau = sim.true_time(sim.receiver, sim.time, sim.after)
    truth = sim.time - (tau + sim.offset0[0] + sim.drift[0] * tau)
    pick = used & (rows >= 0) & (sim.receiver != 0) & (True if receiver is None else sim.receiver == receiver)
    return fit.offset(rows[pick], t[pick]) - truth[pick]


def _on_reference(sim, origin: float, tau: float) -> float:
    """[s] the true instant ``tau`` on receiver 0's clock before any jump of it, on the fit's time base."""
    return float(tau + sim.offset0[0] + sim.drift[0] * tau - origin)


@pytest.mark.parametrize("size", [0.5, -20.0, 5e-3])
def test_a_jump_found_at_its_time_with_its_size_and_the_offsets_as_without_it(size):
    """+0.5 s, −20 s (the time goes back) and +5 ms at receiver 4 at 2 h 40 min: one break, at receiver 4, its
    instant within its stated interval (the two arrivals either side), its size within 3 of its sigmas and 0.3 ms,
    the arrivals on its segments as the simulation logged them before and after, and the offsets' RMS error within
    1.2 times the same array's without the jump (its two segments no longer share their data: 1.14 here, the most
    of ten such small arrays; 1.00 to 1.01 on arrays of 20 receivers over a day) and under 0.5 ms at receiver 4."""
    tau = 2 * 3600.0 + 2400.0
    sim, origin, t, used, fit = _fit(11, (4, tau, size))
    assert fit.breaks is not None and len(fit.breaks) == 1
    b = fit.breaks[0]
    assert b.receiver == 4 and fit.site[b.before] == fit.site[b.after] == 4
    assert abs(b.time - _on_reference(sim, origin, tau)) <= b.time_within + 1e-6
    assert b.time_within < 300.0  # the arrivals of 8 sync tags at one receiver: minutes apart at most
    assert abs(b.size - size) <= min(3 * b.size_sigma, 0.3e-3)
    mine = used & (sim.receiver == 4) & (fit.clock >= 0)
    assert np.array_equal(fit.clock[mine] == b.after, sim.after[mine])
    assert (used & (sim.receiver == 4) & (fit.clock < 0)).sum() <= 2  # set aside at the break
    clean = _fit(11)
    ratio = np.sqrt(np.mean(_error(sim, t, fit, used) ** 2) / np.mean(_error(clean[0], clean[2], clean[4],
                                                                             clean[3]) ** 2))
    assert ratio <= 1.2
    assert np.abs(_error(sim, t, fit, used, 4)).max() < 0.5e-3


def test_no_break_without_a_jump_and_the_fit_is_the_plain_one():
    """Three seeds without a jump: no break, and the fit is :func:`fit_clocks`'s (one row per receiver)."""
    for seed in (1, 2, 3):
        sim, _, t, used, fit = _fit(seed)
        assert fit.breaks is None and fit.site is None and fit.clock is None
    emission, duplicate, single = sync_emissions(sim.tag, sim.receiver, t, np.full(N, 180.0))
    distance = np.linalg.norm(sim.positions[sim.tag] - sim.positions[sim.receiver], axis=1)
    plain = fit_clocks(sim.receiver, emission, t, distance, np.full(len(t), 1 / sim.sound_speed), used,
                       connected(sim.receiver[used], emission[used], N, 0), 0, 3600.0)
    np.testing.assert_array_equal(plain.knots, fit.knots)


def test_a_break_of_the_reference_receiver_is_its_own():
    """Receiver 0 (the reference) jumps by +0.5 s: the break is found at it (not at every other receiver), and the
    clocks of the others stay right between themselves (each offset less receiver 1's at the same instant)."""
    sim, origin, t, used, fit = _fit(12, (0, 3 * 3600.0, 0.5))
    assert [b.receiver for b in fit.breaks] == [0]
    assert abs(fit.breaks[0].size - 0.5) <= 3 * fit.breaks[0].size_sigma
    later = used & (sim.after is not None) & (sim.receiver > 1) & (fit.clock >= 0)
    tau = sim.true_time(sim.receiver, sim.time, sim.after)[later]
    one = sim.reading(np.ones(later.sum(), np.int64), tau)  # receiver 1's clock at the same instants
    fitted = (t[later] - fit.offset(fit.clock[later], t[later])) - (one - origin - fit.offset(
        np.ones(later.sum(), np.int64), one - origin))
    assert np.sqrt(np.mean(fitted ** 2)) < 0.1e-3  # both corrected to one instant: the same reference time


def test_the_jump_scan_is_the_explicit_least_squares():
    """:func:`scan` on a small series (3 pairs, a constant each, 4 bins, a step of 2 ms after sample 37) against
    the least squares written out for every gap (the clock's knots, the pairs' constants, the drift prior's rows,
    a jump column): the same best gap, jump and statistic."""
    rng = np.random.default_rng(5)
    n = 70
    t = np.sort(rng.uniform(0, 4 * 3600.0, n))
    pair = rng.integers(0, 3, n)
    sigma = np.array([1e-4, 2e-4, 1.5e-4])[pair]
    z = 1e-6 * t / 3600 + np.array([0.0, 3e-3, -2e-3])[pair] + 2e-3 * (np.arange(n) >= 37) + rng.normal(0, sigma)
    w = 1 / sigma ** 2
    edges = np.arange(5) * 3600.0
    prior = 3.6e-3
    found = scan(t, z, pair, w, edges, prior, min_side=10)
    # the explicit system: knots (5), constants of pairs 1 and 2 (pair 0, the most weighted, is the knots' level)
    k = np.clip((t // 3600).astype(int), 0, 3)
    f = t / 3600 - k
    main = int(np.argmax(np.bincount(pair, w)))
    others = [p for p in range(3) if p != main]
    A = np.zeros((n, 5 + 2))
    A[np.arange(n), k] = 1 - f
    A[np.arange(n), k + 1] = f
    for c, p in enumerate(others):
        A[pair == p, 5 + c] = 1.0
    L = np.zeros((3, 7))
    for r in range(3):
        L[r, r:r + 3] = [1.0, -2.0, 1.0]
    L /= prior

    def chi2(design: np.ndarray) -> tuple[float, np.ndarray]:
        M = np.vstack([design * np.sqrt(w)[:, None], np.c_[L, np.zeros((3, design.shape[1] - 7))]])
        y = np.r_[z * np.sqrt(w), np.zeros(3)]
        x = np.linalg.lstsq(M, y, rcond=None)[0]
        return float(np.sum(w * (z - design @ x) ** 2) + np.sum((L @ x[:7]) ** 2)), x

    base, _ = chi2(A)
    drops = {}
    for g in range(10, n - 9):
        c, x = chi2(np.c_[A, (np.arange(n) >= g).astype(float)])
        drops[g] = (base - c, x[-1], c)
    g = max(drops, key=lambda key: drops[key][0])
    assert found["gap"] == g == 37
    drop, size, rest = drops[g]
    assert found["size"] == pytest.approx(size, rel=1e-6)
    assert found["statistic"] == pytest.approx(np.sqrt(drop / (rest / (n - 7 - 1))), rel=1e-5)
    assert abs(size - 2e-3) < 0.2e-3


@pytest.mark.parametrize("before, after, size, stretch", [
    ((10.0, 20.0, 300.0), (310.0, 350.0, 400.0), 0.5, (300.0, 310.0)),  # ahead: from the last before to the first after
    ((10.0, 20.0, 300.0), (281.0, 350.0, 400.0), -20.0, (280.0, 301.0)),  # back 20 s: the readings both clocks make
    ((10.0, 20.0, 300.0), (100.0, 150.0, 400.0), -1e-3, (100.0, 300.0)),  # interleaved beyond the jump (the boats')
])
def test_the_stretch_set_aside_at_a_break_is_never_inverted(before, after, size, stretch):
    """A break's stretch set aside (its two segments' spans) against the readings either segment may make: after
    a jump ahead, from the last arrival put before it to the first after; after the time went back 20 s, widened by
    the jump on both sides; where the arrivals the fit put in the two segments interleave in time far beyond a jump
    of 1 ms (the last before at 300 s, the first after at 100 s: the boats' spurious split printed its stretch "from
    21:15:09 to 21:11:33"), the whole interleave, in order; the receiver's other arrivals by their times (-1 in it)."""
    rest = (5.0, 200.0, 500.0)
    time = np.array(before + after + rest)
    rows = np.array([0, 0, 0, 1, 1, 1, 0, 0, 0])
    classified = np.arange(9) < 6
    span = [[-np.inf, np.inf], [np.nan, np.inf]]
    entry = {"receiver": 0, "before": 0, "after": 1}
    _bounds(entry, rows, np.zeros(9, np.int64), time, classified, size, span, np.ones(9, bool))
    assert (entry["last"], entry["first"]) == (max(before), min(after))
    assert span[0][1] == pytest.approx(stretch[0]) and span[1][0] == pytest.approx(stretch[1])
    assert span[0][1] <= span[1][0]
    expected = [0 if t <= stretch[0] else 1 if t >= stretch[1] else -1 for t in rest]
    assert rows[6:].tolist() == expected and rows[:6].tolist() == [0, 0, 0, 1, 1, 1]
