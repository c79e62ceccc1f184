"""A still tag's verdict (models/tracking/still.py) and the receivers' jackknife of its pooled place
(models/tracking/stationary.py): the step statistic against the dense generalised least squares it stands for, the
slow errors' expansion against their kernel, the fixes' sensitivity against refitted single-ping fixes, and the
verdict on simulated fixes of a still tag in water whose sound speed changes by ±5 m/s over a day, of one moved
20 m half way and of an animal."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.tracking import still as sv
from sblsim.models.tracking.stationary import moved, receiver_jackknife, stationary_fix

C = 1480.0
SIGMA = 1e-4
RECEIVERS = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 800.0], [0.0, 800.0], [500.0, 400.0], [250.0, 700.0],
                      [800.0, 150.0], [650.0, 750.0]])
TAG = np.array([780.0, 560.0])
DAY = 86400.0


def _fixes(seed: int, n: int = 720, move: np.ndarray | None = None, walk: float | None = None,
           drift: np.ndarray | None = None, drift_pings: int | None = None):
    """Simulated single-ping fixes of a tag at TAG (ping every 120 ± 24 s over a day): each fix's own error (its
    covariance of 0.2 m per axis, 0.1 m correlated) and the sound speed's change, 1,480 ± 5 m/s over the day in a
    sine of random phase, which scales every range about the tag's receivers and so moves the fix along
    ``∂p/∂c`` (found here by refitting exact ranges at two speeds); a step of ``move`` at the middle ping, a
    random walk of ``walk`` [m] per ping, or a drift of ``drift`` [m] per ping from the middle ping on (the middle
    ping the first moved) for ``drift_pings`` pings (None: to the end), then still."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(96.0, 144.0, n))
    speed = 5.0 * np.sin(2 * np.pi * t / DAY + rng.uniform(0, 2 * np.pi))
    along = _scale_direction(TAG)
    R = np.tile(np.array([[0.04, 0.01], [0.01, 0.04]]), (n, 1, 1))
    x = TAG + speed[:, None] * along + np.einsum("kab,kb->ka", np.linalg.cholesky(R), rng.standard_normal((n, 2)))
    truth = np.repeat(TAG[None], n, axis=0)
    if move is not None:
        truth[n // 2:] += move
    if walk is not None:
        truth += np.cumsum(rng.normal(scale=walk, size=(n, 2)), axis=0)
    if drift is not None:
        pings = np.arange(1, n - n // 2 + 1)
        truth[n // 2:] += np.minimum(pings, drift_pings or n)[:, None] * drift
    return x + truth - TAG, R, t


def _scale_direction(p: np.ndarray) -> np.ndarray:
    """How a fix at p moves per m/s of sound speed [m/(m/s)]: the least-squares position (emission time free) of
    ranges taken at C + 1 m/s and read at C, by Gauss-Newton."""
    rho = np.linalg.norm(p - RECEIVERS, axis=1) * C / (C + 1.0)  # the travel times at C + 1, read as ranges at C
    q, b = p.copy(), 0.0
    for _ in range(20):
        d = np.linalg.norm(q - RECEIVERS, axis=1)
        J = np.column_stack([(q - RECEIVERS) / d[:, None], np.ones(len(d))])
        step = np.linalg.lstsq(J, rho - d - b, rcond=None)[0]
        q, b = q + step[:2], b + step[2]
    return q - p


def _slow(p: np.ndarray = TAG) -> np.ndarray:
    """The slow errors' covariance of the simulation's fixes as the verdict takes it: the sound speed's change
    (:data:`~sblsim.models.tracking.still.SPEED_WANDER`) through ``∂p/∂c``."""
    along = _scale_direction(p)
    return sv.SPEED_WANDER**2 * np.outer(along, along)


@pytest.mark.parametrize("change", ["step", "drift", "drift_stopping"])
def test_the_step_statistic_is_the_dense_generalised_least_squares_one(change):
    """Λ(τ) of every τ equals the Wald statistic of the change in the regression ``x = 1 μ + h_τ δ + ε``, ε ~ N(0,
    diag(R_k) + G Gᵀ), solved here with the dense 2N × 2N covariance; the change is its δ. ``h_τ``: 1 from fix τ on
    (a step), or a ramp ``r_k − r_τ−1`` from fix τ on with ``r`` the times scaled to a day (a drift to the end) or
    those clipped at fix 30's (a drift that stops there; τ up to 30)."""
    rng = np.random.default_rng(1)
    n = 40
    t = np.sort(rng.uniform(0, DAY, n))
    R = np.array([np.diag(rng.uniform(0.5, 2.0, 2)) for _ in range(n)])
    x = rng.normal(size=(n, 2)) * np.sqrt(R[:, [0, 1], [0, 1]])
    x[25:] += [1.5, -0.5]
    G = sv.slow_columns(t, np.array([[1.0, 0.3], [0.3, 0.5]]))
    ramp = {"step": None, "drift": t / DAY, "drift_stopping": np.minimum(t, t[30]) / DAY}[change]
    stats, steps = sv.step_statistics(x, R, G, ramp)
    covariance = np.zeros((2 * n, 2 * n))
    for k in range(n):
        covariance[2 * k:2 * k + 2, 2 * k:2 * k + 2] = R[k]
    dense = G.transpose(2, 1, 0).reshape(2 * n, -1)
    W = np.linalg.inv(covariance + dense @ dense.T)
    one = np.tile(np.eye(2), (n, 1))
    for tau in range(1, 31 if change == "drift_stopping" else n):
        h = np.where(np.arange(n) >= tau, 1.0 if ramp is None else ramp - ramp[tau - 1], 0.0)
        X = np.hstack([one, np.kron(h[:, None], np.eye(2))])
        cov = np.linalg.inv(X.T @ W @ X)
        beta = cov @ X.T @ W @ x.reshape(-1)
        assert stats[tau] == pytest.approx(beta[2:] @ np.linalg.solve(cov[2:, 2:], beta[2:]), rel=1e-8)
        np.testing.assert_allclose(steps[tau], beta[2:], rtol=1e-8, atol=1e-10 * np.abs(beta[2:]).max())
    assert np.isnan(stats[0]) and (int(np.nanargmax(stats)) == 25 or ramp is not None)


def test_the_slow_columns_hold_the_squared_exponential_kernel():
    """G Gᵀ is ``C exp(−(t − t')² / 2T²)`` up to a constant (the position takes it): both centred over the times,
    within 10⁻³ of the kernel's variance over a day of 300 times."""
    t = np.linspace(0.0, DAY, 300)
    slow = np.array([[2.0, 0.5], [0.5, 1.0]])
    G = sv.slow_columns(t, slow, 3600.0)
    kernel = np.exp(-0.5 * ((t[:, None] - t[None]) / 3600.0) ** 2)

    def centred(a):
        return a - a.mean(axis=0) - a.mean(axis=1)[:, None] + a.mean()

    for a in range(2):
        for b in range(2):
            got = np.einsum("qk,ql->kl", G[:, a], G[:, b])
            assert np.abs(centred(got) - slow[a, b] * centred(kernel)).max() < 1e-3 * slow[a, b] + 1e-9


def test_the_slow_covariance_is_the_refitted_fixes_sensitivity():
    """``slow_covariance`` for one ping heard by every receiver: ``A B Aᵀ`` with A the single-ping fix's ∂p/∂β_i,
    here by central differences of single-ping fixes (the emission time free) with receiver i's arrival shifted by
    ±1 µs."""
    from sblsim.models.tracking.fix import fix_pings

    rng = np.random.default_rng(2)
    toa = np.linalg.norm(TAG - RECEIVERS, axis=1)[None] / C
    A = np.empty((2, len(RECEIVERS)))
    for i in range(len(RECEIVERS)):
        plus, minus = toa.copy(), toa.copy()
        plus[0, i] += 1e-6
        minus[0, i] -= 1e-6
        A[:, i] = (fix_pings(plus, RECEIVERS, C, SIGMA)[0][0] - fix_pings(minus, RECEIVERS, C, SIGMA)[0][0]) / 2e-6
    B = np.diag(rng.uniform(0.5, 2.0, len(RECEIVERS)) * 1e-8)
    got = sv.slow_covariance(RECEIVERS, TAG, C, np.ones((1, len(RECEIVERS)), bool), np.full(len(RECEIVERS), SIGMA), B)
    np.testing.assert_allclose(got, A @ B @ A.T, rtol=1e-3)


@pytest.mark.slow
def test_still_tags_in_changing_water_stay_still_where_the_order_test_says_moved():
    """20 simulated still tags, their fixes moved by a sound speed 1,480 ± 5 m/s over the day: the verdict finds
    no change in any (the share of rows it flags 0, at most the issue's 5 %), where the permutation test of the
    fixes' order (:func:`~sblsim.models.tracking.stationary.moved`) calls most of them moved."""
    changes, ordered = 0, 0
    for seed in range(20):
        x, R, t = _fixes(seed)
        verdict = sv.still_verdict(x, R, t, np.ones(len(x), bool), _slow())
        changes += verdict.change is not None
        ordered += moved(x, t, np.ones(len(x), bool))[2]
        assert verdict.fixes == len(x) and 0.5 < verdict.white_scale < 2.0, verdict
    assert changes == 0 and ordered >= 15, (changes, ordered)


def test_a_tag_moved_20_m_half_way_is_found_at_its_move():
    """A still tag moved 20 m at its middle ping: the change is the first fix after the move (within 3 fixes), no
    earlier, not moved the whole time (3 seeds)."""
    for seed in range(3):
        x, R, t = _fixes(seed, move=np.array([20.0, 0.0]))
        verdict = sv.still_verdict(x, R, t, np.ones(len(x), bool), _slow())
        assert verdict.change is not None and abs(int(verdict.order[verdict.change]) - len(x) // 2) <= 3, verdict
        assert not verdict.throughout and verdict.statistic > verdict.threshold


def test_a_tag_moved_20_m_is_a_step_not_a_drift():
    """The 20 m move half way (3 seeds): no drift explains the fixes better than the step (``drifted`` False), the
    change the first fix after the move."""
    for seed in range(3):
        x, R, t = _fixes(seed, move=np.array([20.0, 0.0]))
        verdict = sv.still_verdict(x, R, t, np.ones(len(x), bool), _slow())
        assert not verdict.drifted and int(verdict.order[verdict.change]) == len(x) // 2, verdict


@pytest.mark.parametrize("speed, pings", [(1.0, None), (0.2, None), (0.05, None), (1.0, 20)])
def test_a_tag_drifting_away_is_found_from_its_onset(speed, pings):
    """A still tag that drifts from its middle ping at ``speed`` [m] a ping (a dead fish in a current; each fix 0.2 m
    of noise a side), to the end or for 20 pings then still: the first moved fix within 3 fixes of the onset (3
    seeds), called a drift, its still part not wandering. A step's change is found where the fixes' mean has moved by
    what one fix sees (about 0.9 m here): at 0.05 m a ping about 20 pings late, at 1 m a ping up to 3 late."""
    for seed in range(3):
        x, R, t = _fixes(seed, drift=np.array([0.0, speed]), drift_pings=pings)
        verdict = sv.still_verdict(x, R, t, np.ones(len(x), bool), _slow())
        assert verdict.change is not None and verdict.drifted and not verdict.throughout, verdict
        assert abs(int(verdict.order[verdict.change]) - len(x) // 2) <= 3, (seed, verdict.order[verdict.change])


def test_a_long_records_daily_wander_is_no_drift():
    """6,000 fixes a ping every 540-660 s (41 days) of a still tag whose fixes wander 0.6 m with the day (a sound
    speed's daily cycle along the array's scale direction) beside 0.3 m of white noise: over that record the slow
    errors' correlation time is lengthened to a day and more, which does not hold the daily wander (the step
    statistic 191 to 236 against a threshold of 31), and a drift fitted near the record's end had a way one fix
    sees; its fixes' own medians did not move, and no change is found (4 seeds)."""
    n, along = 6000, np.array([0.8, 0.6])
    for seed in range(4):
        rng = np.random.default_rng(seed)
        t = np.cumsum(rng.uniform(540.0, 660.0, n))
        wander = 0.6 * np.sin(2 * np.pi * t / DAY + rng.uniform(0, 2 * np.pi))[:, None] * along
        x = wander + 0.3 * rng.standard_normal((n, 2))
        verdict = sv.still_verdict(x, np.tile(0.09 * np.eye(2), (n, 1, 1)), t, np.ones(n, bool),
                                   0.36 * np.outer(along, along))
        assert verdict.change is None and not verdict.drifted, verdict
        assert verdict.statistic > 3 * verdict.threshold  # the model does not hold the wander: the fixes decide


def test_the_detectable_step_is_the_smallest_move_the_verdict_finds():
    """Fixes of 0.2 m of white noise and no slow error, 600 a minute apart: the detectable step is √(χ²(2, 0.99)) σ
    in both directions (the dispersion near 1), a move of 1.5 times it half way is found at its fix, one of half of it
    is not, though its step statistic is far above the threshold (300 fixes a side see it together; a single fix
    does not)."""
    rng = np.random.default_rng(3)
    n, sigma = 600, 0.2
    R = np.tile(sigma**2 * np.eye(2), (n, 1, 1))
    t = np.arange(n) * 60.0
    noise = sigma * rng.standard_normal((n, 2))
    base = sv.still_verdict(noise, R, t, np.ones(n, bool), 1e-12 * np.eye(2))
    expected = np.sqrt(-2.0 * np.log(1.0 - sv.STEP_LEVEL) * base.white_scale) * sigma
    np.testing.assert_allclose(base.detectable, [expected, expected], rtol=1e-6)
    assert 0.8 < base.white_scale < 1.25 and base.change is None
    for factor, found in ((1.5, True), (0.5, False)):
        x = noise.copy()
        x[n // 2:, 0] += factor * base.detectable[1]
        verdict = sv.still_verdict(x, R, t, np.ones(n, bool), 1e-12 * np.eye(2))
        assert (verdict.change is not None) == found, (factor, verdict)
        if found:
            assert verdict.order[verdict.change] == n // 2
        else:
            assert verdict.statistic > 3 * verdict.threshold


def test_an_animal_moves_the_whole_time():
    """A random walk of 2 m per ping: moved the whole time (3 seeds)."""
    for seed in range(3):
        x, R, t = _fixes(seed, walk=2.0)
        verdict = sv.still_verdict(x, R, t, np.ones(len(x), bool), _slow())
        assert verdict.change is not None and verdict.throughout, verdict


def test_gross_fixes_are_no_move():
    """Eight fixes 30 m off (reflections the fixes kept), the last fix among them: pulled to the running median,
    no change."""
    x, R, t = _fixes(4)
    x[np.r_[np.random.default_rng(4).choice(len(x) - 1, 7, replace=False), len(x) - 1]] += 30.0
    verdict = sv.still_verdict(x, R, t, np.ones(len(x), bool), _slow())
    assert verdict.change is None, verdict


def test_the_receivers_jackknife_is_the_refits_without_each_receiver():
    """Each position without receiver i is the minimum of the pooled fit's weighted least squares (its robust
    weights held) without receiver i's arrivals, found here by scipy's ``least_squares`` over the position and every
    ping's emission time (each receiver's arrivals 0 to 3 σ off, a clock's error); the covariance is
    ``(g − 1)/g Σ (p_i − p̄)(p_i − p̄)ᵀ``."""
    from scipy.optimize import least_squares

    rng = np.random.default_rng(5)
    m = 60
    toa = np.arange(m)[:, None] * 60.0 + np.linalg.norm(TAG - RECEIVERS, axis=1)[None] / C
    toa = toa + SIGMA * rng.normal(size=toa.shape) + 3 * SIGMA * rng.random(len(RECEIVERS))[None]
    toa[rng.random(toa.shape) > 0.8] = np.nan
    fix = stationary_fix(toa, RECEIVERS, C, SIGMA, TAG + 1.0)
    positions, covariance = receiver_jackknife(toa, RECEIVERS, C, SIGMA, fix)
    for i in range(len(RECEIVERS)):
        heard = np.isfinite(toa)
        heard[:, i] = False
        root = np.sqrt(fix.weights[heard]) / SIGMA

        def residuals(v, root=root, heard=heard):
            travel = np.linalg.norm(v[:2] - RECEIVERS, axis=1) / C
            return root * (toa - v[2:, None] - travel[None])[heard]

        start = np.r_[fix.position, fix.emissions]
        found = least_squares(residuals, start, x_scale=np.r_[1.0, 1.0, np.full(m, 1e-3)], xtol=1e-12, ftol=1e-12)
        np.testing.assert_allclose(positions[i], found.x[:2], atol=1e-4)
    d = positions - positions.mean(axis=0)
    g = len(RECEIVERS)
    np.testing.assert_allclose(covariance, (g - 1) / g * sum(np.outer(r, r) for r in d), rtol=1e-12)


def test_the_order_test_takes_a_fix_covariance_singular_to_rounding():
    """A fix's covariance singular to rounding (a pseudo-inverse's, one eigenvalue a hair below 0: what a newer
    numpy's pinv gave a moving tag's fixes) is drawn from by its symmetric root: the verdict made, not a
    LinAlgError; and the draws' covariance is that matrix (clipped at 0) whatever path took it."""
    rng = np.random.default_rng(2)
    n = 60
    x = np.c_[np.linspace(0, 30, n), np.zeros(n)] + rng.normal(0, 0.1, (n, 2))  # a tag moving along x
    R = np.tile(np.diag([0.01, 0.01]), (n, 1, 1))
    u = np.array([1.0, 1.0]) / np.sqrt(2)
    R[5] = 0.02 * np.outer(u, u) - 1e-18 * np.eye(2)  # rank one, its other eigenvalue -1e-18
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(R)
    G = np.zeros((1, 2, n))
    assert sv.wanders(x, R, G) is True  # moving: ordered far beyond its white errors
    w, V = np.linalg.eigh(R[5])
    root = V * np.sqrt(np.maximum(w, 0.0))
    np.testing.assert_allclose(root @ root.T, 0.02 * np.outer(u, u), atol=1e-15)


def test_the_order_test_asked_for_finds_a_slow_wander_no_step_shows():
    """A walk of 0.1 m a fix among fixes of 1 m noise (200, ten minutes apart): no step a single fix could see; asked
    for (``order_test``), the fixes' order says it moved the whole time (seed 0: no drift one fix sees either; not
    asked, ``throughout`` stays False without a change), or a drift to the end one fix sees has it move from fix 40
    (seed 1, asked or not); never on fixes of white noise alone (10 seeds: no change, not moved throughout)."""
    n, t, R = 200, np.arange(200) * 600.0, np.tile(np.eye(2), (200, 1, 1))
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        x = np.cumsum(rng.normal(scale=0.1, size=(n, 2)), axis=0) + rng.normal(size=(n, 2))
        asked = sv.still_verdict(x, R, t, np.ones(n, bool), 1e-6 * np.eye(2), order_test=True)
        plain = sv.still_verdict(x, R, t, np.ones(n, bool), 1e-6 * np.eye(2))
        if seed == 0:
            assert asked.change is None and asked.throughout and not plain.throughout, (asked, plain)
        else:
            assert asked.drifted and plain.drifted and asked.change == plain.change == 40, (asked, plain)
    for seed in range(10):
        x = np.random.default_rng(100 + seed).normal(size=(n, 2))
        verdict = sv.still_verdict(x, R, t, np.ones(n, bool), 1e-6 * np.eye(2), order_test=True)
        assert verdict.change is None and not verdict.throughout, verdict
