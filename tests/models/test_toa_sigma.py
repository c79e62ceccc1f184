"""Each receiver's own timing noise in the tracker's measurement covariance (issue 87): a receiver given ten times the
sigma weighs as a weighted least squares says (the single-ping fix against scipy's ``least_squares`` on the arrivals
over their own sigmas; the EKF's and the sequential EKF's update against a Kalman update written here with
``R = diag(σ_i²)``; the robust smoother a minimum of its cost written again with numpy); one value for every receiver
is the scalar path; and the synchronisation's robust scale of each receiver's residuals
(:mod:`sblsim.models.sync.noise`) against the noise drawn."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import least_squares

from sblsim.models.errors import ModelError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.sync.noise import MIN_ARRIVALS, receiver_noise
from sblsim.models.tracking.toa import checked_sigma

C = 1480.0
RECEIVERS = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 300.0], [0.0, 300.0], [150.0, -60.0], [-60.0, 150.0]])
SIGMA = 1e-4
NOISY = 3  # the receiver given ten times the sigma


def _sigmas() -> np.ndarray:
    sigma = np.full(len(RECEIVERS), SIGMA)
    sigma[NOISY] = 10 * SIGMA
    return sigma


def _ping(rng: np.random.Generator, position=(120.0, 170.0), late: float = 0.0) -> np.ndarray:
    """One ping's times of arrival at :data:`RECEIVERS` from ``position`` emitted at 10 s, each with its receiver's
    noise, the noisy receiver's ``late`` [s] late."""
    sigma = _sigmas()
    d = np.linalg.norm(np.asarray(position) - RECEIVERS, axis=1)
    toa = 10.0 + d / C + sigma * rng.normal(size=len(RECEIVERS))
    toa[NOISY] += late
    return toa


def _weighted(toa: np.ndarray, sigma: np.ndarray, start: np.ndarray):
    """The weighted least squares of (x, y, t_e) by scipy: residuals over each arrival's own sigma."""

    def residuals(theta):
        return (toa - theta[2] - np.linalg.norm(theta[:2] - RECEIVERS, axis=1) / C) / sigma

    found = least_squares(residuals, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                          x_scale=np.array([1.0, 1.0, 1e-3]))
    return found.x, np.linalg.inv(found.jac.T @ found.jac)


def test_a_receiver_given_ten_times_the_sigma_weighs_as_weighted_least_squares():
    """The single-ping fix with one receiver's sigma ten times the others' is scipy's weighted least squares of the
    same arrivals (position to 1 µm, emission time to 0.1 ns, covariance to 1e-6), and a late arrival at that
    receiver moves it far less than with one sigma for all (its weight a hundredth)."""
    rng = np.random.default_rng(5)
    toa = _ping(rng, late=5 * SIGMA * 10)  # 5 of its own sigmas late: kept by the gate, weighed down
    sigma = _sigmas()
    fix = tt.single_ping_fix(toa, RECEIVERS, C, sigma, gate=1e9)
    x, cov = _weighted(toa, sigma, np.r_[fix.position + 3.0, fix.emission])
    assert fix.used.all()
    assert np.abs(fix.position - x[:2]).max() < 1e-6 and abs(fix.emission - x[2]) < 1e-10
    assert np.allclose(fix.covariance, cov, rtol=1e-6, atol=0)
    equal = tt.single_ping_fix(toa, RECEIVERS, C, SIGMA, gate=1e9)
    x_equal, _ = _weighted(toa, np.full(len(RECEIVERS), SIGMA), x)
    assert np.abs(equal.position - x_equal[:2]).max() < 1e-6
    truth = np.array([120.0, 170.0])
    assert np.linalg.norm(equal.position - truth) > 5 * np.linalg.norm(fix.position - truth)


def _kalman(x: np.ndarray, P: np.ndarray, toa: np.ndarray, R: np.ndarray):
    """One EKF update written here: H by central differences of the arrivals' model at x, the gain of
    ``H P Hᵀ + R``."""
    def model(state):
        return state[4] + np.linalg.norm(state[:2] - RECEIVERS, axis=1) / C

    H = np.zeros((len(RECEIVERS), len(x)))
    for a in (0, 1, 4):
        step = np.zeros(len(x))
        step[a] = 1e-3 if a < 2 else 1e-6
        H[:, a] = (model(x + step) - model(x - step)) / (2 * step[a])
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    return x + K @ (toa - model(x)), (np.eye(len(x)) - K @ H) @ P


@pytest.mark.parametrize("kind", ["ekf", "ekf-seq"])
def test_the_filters_update_with_each_receivers_own_noise(kind):
    """The EKF's and the sequential EKF's update with a sigma per receiver is the Kalman update with
    ``R = diag(σ_i²)`` written here (state to 1e-6 m and 1e-10 s, covariance to 1e-6), not the one with one
    sigma for all."""
    rng = np.random.default_rng(2)
    s = tt.TrackerSettings(sound_speed=C, sigma_toa=_sigmas(), gate=1e9, gate_probability=1 - 1e-15)
    x = np.array([118.0, 173.0, 0.2, -0.1, 10.0 + 2e-4, 2.0])
    P = np.diag([9.0, 9.0, 0.25, 0.25, 1e-6, 1e-4])
    toa = _ping(rng, late=3e-3)
    tracker = tt.CAUSAL_TRACKERS[kind](RECEIVERS, s)
    xu, Pu, used = tracker.update(x, P, toa)
    xk, Pk = _kalman(x, P, toa, np.diag(_sigmas() ** 2))
    assert used.all()
    assert np.abs(xu[:2] - xk[:2]).max() < 1e-6 and abs(xu[4] - xk[4]) < 1e-10
    assert np.allclose(Pu, Pk, rtol=1e-6, atol=1e-14)
    xs, _ = _kalman(x, P, toa, np.eye(len(RECEIVERS)) * SIGMA**2)
    assert np.abs(xu[:2] - xs[:2]).max() > 100 * np.abs(xu[:2] - xk[:2]).max()


def _cost(X: np.ndarray, toa: np.ndarray, s: tt.TrackerSettings, sigma: np.ndarray, dof: float) -> float:
    """The robust smoother's cost written again with numpy: the arrivals' Student-t terms over each receiver's own
    sigma, the steps' whitened process innovations (one nominal interval each) and the first interval's prior."""
    m = len(toa)
    k, i = np.nonzero(np.isfinite(toa))
    p, v, te, interval = X[:, :2], X[:, 2:4], X[:, 4], X[:, 5]
    z = (toa[k, i] - te[k] - np.linalg.norm(p[k] - RECEIVERS[i], axis=1) / C) / sigma[i]
    total = (dof + 1) * np.log1p(z**2 / dof).sum()
    T, q = s.interval, s.acceleration_psd
    Q = np.zeros((6, 6))
    for a in range(2):
        Q[np.ix_([a, 2 + a], [a, 2 + a])] = q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
    Q[4, 4], Q[5, 5] = s.jitter**2, s.interval_drift**2
    W = np.linalg.inv(np.linalg.cholesky(Q))
    for j in range(m - 1):
        predicted = np.r_[p[j] + interval[j] * v[j], v[j], te[j] + interval[j], interval[j]]
        total += float(np.sum((W @ (X[j + 1] - predicted)) ** 2))
    return total + ((interval[0] - s.interval) / s.sigma_interval) ** 2


def test_the_robust_smoother_minimises_its_cost_with_each_receivers_noise():
    """The robust smoother's answer with a sigma per receiver is a minimum of its cost written again here (the cost
    it reports that one to 1e-9; each position moved 2 cm either way and each emission time 2 µs raises it), and
    another track than with one sigma for all."""
    rng = np.random.default_rng(7)
    sigma = _sigmas()
    s = tt.TrackerSettings(sound_speed=C, sigma_toa=sigma, interval=5.0, acceleration_psd=1e-4)
    toa, _, _ = tt.simulate_pings(RECEIVERS, 20, s, rng, speed=0.3, detection=0.8,
                                  path=lambda t: np.c_[120 + 0.3 * t, 170 - 0.2 * t])
    tracker = tt.ToaTracker(RECEIVERS, s)
    record = tracker.run(toa)
    xs, _ = tracker.smooth(record)
    k0 = record.start
    robust = tt.robust_smooth(toa[k0:], RECEIVERS, s, [xs[k0:]])
    X = robust.x
    ours = _cost(X, toa[k0:], s, sigma, tt.ROBUST_DOF)
    assert abs(ours - robust.cost) <= 1e-9 * ours
    for k in range(len(X)):
        for a, h in ((0, 0.02), (1, 0.02), (4, 2e-6)):
            for sign in (-1, 1):
                moved = X.copy()
                moved[k, a] += sign * h
                assert _cost(moved, toa[k0:], s, sigma, tt.ROBUST_DOF) > ours, (k, a, sign)
    one = tt.robust_smooth(toa[k0:], RECEIVERS, replace(s, sigma_toa=float(np.median(sigma))), [xs[k0:]])
    assert np.abs(one.x[:, :2] - X[:, :2]).max() > 1e-3


def test_one_noise_for_every_receiver_is_the_scalar_path():
    """A sigma per receiver that is the same for all gives the fixes and the EKF of one sigma (to rounding), and a
    sigma per receiver of the wrong length or not positive is refused in one line."""
    rng = np.random.default_rng(3)
    s = tt.TrackerSettings(sound_speed=C, sigma_toa=SIGMA, interval=5.0, acceleration_psd=1e-4)
    toa, _, _ = tt.simulate_pings(RECEIVERS, 25, s, rng, speed=0.3, detection=0.8)
    same = np.full(len(RECEIVERS), SIGMA)
    a, b = tt.fix_pings(toa, RECEIVERS, C, SIGMA), tt.fix_pings(toa, RECEIVERS, C, same)
    for x, y in zip(a, b):
        assert np.allclose(x, y, rtol=1e-9, atol=1e-15, equal_nan=True)
    ra = tt.ToaTracker(RECEIVERS, s).run(toa)
    rb = tt.ToaTracker(RECEIVERS, replace(s, sigma_toa=same)).run(toa)
    assert np.allclose(ra.x_filtered, rb.x_filtered, rtol=1e-9, atol=1e-12, equal_nan=True)
    for bad in (np.full(4, SIGMA), np.r_[same[:-1], 0.0], np.r_[same[:-1], np.nan]):
        with pytest.raises(ModelError) as error:
            checked_sigma(bad, len(RECEIVERS))
        assert "sigma_toa" in str(error.value) and "\n" not in str(error.value)


def test_the_residuals_robust_scale_is_each_receivers_noise():
    """The robust scale of each receiver's residuals (5 % of them gross, 20 to 50 ms late) is the noise drawn within
    12 % over 1,500 arrivals (the gross share moves the median absolute residual by about 6 %, its sampling error
    about 3 %), the clock's sigma added in quadrature (the reference receiver's 0); a receiver with too
    few residuals takes the others' median (not measured) and one not synchronised has none."""
    rng = np.random.default_rng(11)
    noise = np.array([1e-4, 5e-4, 2e-3, 1e-4, 3e-4])
    count = np.array([1500, 1500, 1500, 1500, MIN_ARRIVALS - 1])
    receiver = np.repeat(np.arange(5), count)
    corrected = noise[receiver] * rng.normal(size=len(receiver))
    gross = rng.random(len(receiver)) < 0.05
    corrected[gross] += rng.uniform(0.02, 0.05, gross.sum())
    corrected = np.r_[corrected, np.nan, 0.0]  # an echo (not fitted), an arrival of leverage one: both left out
    receiver = np.r_[receiver, 0, 0]
    knots = np.array([[0.0, 0.0, 0.0], [2e-4, 2e-4, 2e-4], [1e-4, 3e-4, np.nan], [5e-5, 5e-5, 5e-5], [0, 0, 0]])
    synchronised = np.array([True, True, True, True, True, False])
    result = receiver_noise(receiver, corrected, np.r_[knots, [[np.nan] * 3]], synchronised)
    assert np.all(np.abs(result.noise[:4] / noise[:4] - 1) < 0.12)
    clock = np.sqrt(np.nanmean(knots**2, axis=1))
    assert np.allclose(result.clock[:5], clock) and result.clock[0] == 0.0
    assert np.allclose(result.sigma[:4], np.hypot(result.noise[:4], clock[:4]))
    assert not result.measured[4] and result.noise[4] == np.median(result.noise[:4])
    assert np.isnan(result.sigma[5]) and result.arrivals[0] == 1500
