"""The accuracy limit of an inverted LBL (:mod:`sblsim.models.receiver.toa_bound`): the single-ping Fisher
information against a finite-difference one built with numpy, the PCRB recursion against the covariance form, the
filtered and smoothed bounds against the whole track's information inverted as one matrix, and
both bounds reached by the estimators on simulated pings (the single-ping fix by Monte Carlo at a fixed point, the
EKF over 20 seeds)."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.receiver import toa_bound as tb
from sblsim.models.receiver import toa_tracking as tt

# a 2-D array of 8 receivers about 100 m across (the scale of the Lake Hald array)
RECEIVERS = np.array([[0.0, 0.0], [110.0, 10.0], [95.0, 120.0], [-10.0, 105.0], [50.0, -20.0], [130.0, 60.0],
                      [45.0, 130.0], [-25.0, 50.0]])
C, SIGMA = 1420.0, 1.5e-4


def toa_numpy(theta: np.ndarray, receivers: np.ndarray, c: float) -> np.ndarray:
    """One-way times of arrival of (p, t_e)."""
    return theta[-1] + np.linalg.norm(theta[None, :-1] - receivers, axis=1) / c


def test_ping_information_against_finite_differences():
    rng = np.random.default_rng(0)
    for p in ([40.0, 50.0], [140.0, -30.0], [60.0, 90.0]):
        heard = rng.random(len(RECEIVERS)) < 0.8
        heard[:3] = True
        theta = np.array([*p, 12.3])
        steps = np.array([1e-3, 1e-3, 1e-6])
        J = np.column_stack([(toa_numpy(theta + s * e, RECEIVERS, C) - toa_numpy(theta - s * e, RECEIVERS, C))
                             / (2 * s) for s, e in zip(steps, np.eye(3))])[heard]
        info = J.T @ J / SIGMA**2
        got = tb.ping_information(np.array([p]), heard[None], RECEIVERS, C, SIGMA)[0]
        assert np.all(np.abs(got - info) <= 1e-6 * np.abs(info) + 1e-12 * np.abs(info).max())
        # the position's information with t_e unknown: the inverse of the position block of the inverse
        schur = np.linalg.inv(np.linalg.inv(info)[:2, :2])
        pos = tb.position_information(np.array([p]), heard[None], RECEIVERS, C, SIGMA)[0]
        assert np.allclose(pos, schur, rtol=1e-6, atol=0)
        drms = tb.fix_drms(np.array([p]), heard[None], RECEIVERS, C, SIGMA)[0]
        assert np.isclose(drms, np.sqrt(np.trace(np.linalg.inv(info)[:2, :2])), rtol=1e-6)
    # fewer than dim + 1 receivers: unbounded
    assert np.isinf(tb.fix_drms(np.array([[40.0, 50.0]]), np.array([[True, True] + [False] * 6]), RECEIVERS, C,
                                SIGMA)[0])


def test_single_ping_fix_reaches_its_drms():
    """Monte Carlo over 1,000 noise draws at a fixed point, two receiver sets: RMS error within 15 % of the DRMS."""
    rng = np.random.default_rng(1)
    for p, heard in (([40.0, 50.0], np.ones(8, bool)), ([150.0, 20.0], np.array([1, 1, 1, 0, 1, 1, 0, 0], bool))):
        p = np.array(p)
        draws = 1000
        toa = np.tile(7.0 + np.linalg.norm(p - RECEIVERS, axis=1) / C, (draws, 1))
        toa += SIGMA * rng.normal(size=toa.shape)
        toa[:, ~heard] = np.nan
        positions = tt.fix_pings(toa, RECEIVERS, C, SIGMA, gate=np.inf)[0]
        rms = np.sqrt(np.mean(np.sum((positions - p) ** 2, axis=1)))
        predicted = tb.fix_drms(p[None], heard[None], RECEIVERS, C, SIGMA)[0]
        print(f"fix RMS {rms:.4f} m, DRMS {predicted:.4f} m")
        assert abs(rms / predicted - 1) <= 0.15, (rms, predicted)


@pytest.mark.slow
def test_ekf_reaches_its_pcrb_over_20_seeds():
    s = tt.TrackerSettings(sound_speed=C, sigma_toa=SIGMA, interval=2.0, acceleration_psd=1e-3, jitter=1e-3)
    motion = tb.MotionModel.of(s)
    squared_errors, squared_bounds = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        toa, truth, emissions = tt.simulate_pings(RECEIVERS, 80, s, rng, speed=0.5, detection=0.6)
        record = tt.ToaTracker(RECEIVERS, s).run(toa)
        k0 = record.start
        velocity = np.gradient(truth, emissions, axis=0)
        bound = tb.pcrb(truth[k0:], velocity[k0:], emissions[k0:], np.isfinite(toa[k0:]), RECEIVERS, C, SIGMA, motion)
        squared_errors.append(np.sum((record.x_filtered[k0:, :2] - truth[k0:]) ** 2, axis=1))
        squared_bounds.append(bound.filtered**2)
        if seed == 0:  # the information form against the covariance form of the same recursion
            B = bound.B_filtered
            for k in range(1, 6):
                F, Q = tb.transition(velocity[k0 + k - 1], emissions[k0 + k] - emissions[k0 + k - 1], motion)
                info = tb.ping_information(truth[k0 + k][None], np.isfinite(toa[k0 + k])[None], RECEIVERS, C, SIGMA)
                Jz = np.zeros((6, 6))
                Jz[np.ix_([0, 1, 4], [0, 1, 4])] = info[0]
                expected = np.linalg.inv(np.linalg.inv(F @ B[k - 1] @ F.T + Q) + Jz)
                assert np.allclose(B[k], expected, rtol=1e-6, atol=1e-12), k
            # the smoothing bound is below the filtering one
            assert np.all(bound.smoothed <= bound.filtered * (1 + 1e-9))
    ratio = np.sqrt(np.mean(np.concatenate(squared_errors)) / np.mean(np.concatenate(squared_bounds)))
    print(f"EKF RMS / PCRB over 20 seeds: {ratio:.3f}")
    assert 1 / 1.3 <= ratio <= 1.3, ratio


def test_the_pcrb_and_smoothing_bound_are_the_whole_tracks_information_inverted():
    """The recursions of :func:`tb.pcrb` (filtered: Tichavský's; smoothed: RTS) against the whole track's Fisher
    information built as one dense matrix here (the start's prior, each step's ``[Fᵀ Q⁻¹ F, −Fᵀ Q⁻¹; −Q⁻¹ F, Q⁻¹]``,
    each ping's information) and inverted: the filtered bound of ping k is the last block of the inverse of the
    pings 0..k's information, the smoothed one the k-th block of the whole's. Steps of burst type (no stable
    interval: count 0) and stable ones mixed, the receivers heard varying."""
    from types import SimpleNamespace

    rng = np.random.default_rng(5)
    m, d = 7, 2
    s = 2 * d + 2
    positions = rng.uniform(0.0, 100.0, (m, d))
    velocities = rng.normal(0.0, 0.3, (m, d))
    emissions = np.cumsum(rng.uniform(2.0, 4.0, m))
    heard = rng.random((m, len(RECEIVERS))) < 0.7
    heard[0] = True
    motion = tb.MotionModel(1e-3, 2e-4, 1e-5, 1.0, 0.05)
    schedule = SimpleNamespace(count=np.array([1.0, 0.0, 2.0, 1.0, 0.0, 1.0]), te_sigma=rng.uniform(1e-4, 5e-4, m - 1),
                               drift_sigma=rng.uniform(1e-6, 1e-5, m - 1))
    bound = tb.pcrb(positions, velocities, emissions, heard, RECEIVERS, C, SIGMA, motion, schedule)

    idx = np.r_[0:d, 2 * d]
    info = tb.ping_information(positions, heard, RECEIVERS, C, SIGMA)
    whole = np.zeros((m * s, m * s))
    for k in range(m):
        block = whole[k * s:(k + 1) * s, k * s:(k + 1) * s]
        block[np.ix_(idx, idx)] += info[k]
    whole[d:2 * d, d:2 * d] += np.eye(d) / motion.sigma_speed**2
    whole[s - 1, s - 1] += 1.0 / motion.sigma_interval**2
    ahead = []  # each step's term on the block it leaves (Fᵀ Q⁻¹ F), which the filter there has not yet seen
    for k in range(m - 1):
        F, Q = tb.transition(velocities[k], emissions[k + 1] - emissions[k], motion, schedule.count[k],
                             schedule.te_sigma[k], schedule.drift_sigma[k])
        Qi = np.linalg.inv(Q)
        a, b = slice(k * s, (k + 1) * s), slice((k + 1) * s, (k + 2) * s)
        ahead.append(F.T @ Qi @ F)
        whole[a, a] += ahead[-1]
        whole[a, b] -= F.T @ Qi
        whole[b, a] -= Qi @ F
        whole[b, b] += Qi
    smoothed = np.linalg.inv(whole)
    for k in range(m):
        # the filter's information on ping k is the first k + 1 pings' alone: the next step's term on block k is not
        # in it
        filtered_info = whole[:(k + 1) * s, :(k + 1) * s].copy()
        if k < m - 1:
            filtered_info[k * s:, k * s:] -= ahead[k]
        filtered = np.linalg.inv(filtered_info)[k * s:, k * s:]
        np.testing.assert_allclose(bound.B_filtered[k], filtered, rtol=1e-6, atol=1e-15, err_msg=f"filtered {k}")
        np.testing.assert_allclose(bound.B_smoothed[k], smoothed[k * s:(k + 1) * s, k * s:(k + 1) * s], rtol=1e-6,
                                   atol=1e-15, err_msg=f"smoothed {k}")
    np.testing.assert_allclose(bound.filtered, np.sqrt(np.trace(bound.B_filtered[:, :d, :d], axis1=1, axis2=2)))


@pytest.mark.parametrize("dim", [2, 3])
def test_the_ekf_s_transition_is_the_motion_model_s_predict_and_process_noise_to_the_bit(dim):
    """The EKF's one-step transition (made on one state's numbers, every ping) against the motion model's vectorised
    functions of the same state (toa_bound's predict and process_noise, which the bound and the smoother use): the
    same bytes, signed zeros included, over stable steps of 1 and 3 intervals, a burst's step of its own (count 0,
    an offset), intervals and velocities of either sign, and the default schedule."""
    from dataclasses import replace

    from sblsim.models.tracking.schedule import PingSchedule

    rng = np.random.default_rng(5)
    receivers = rng.uniform(-100.0, 100.0, (2, dim))  # fewer receivers than axes in 3-D: the transition needs none
    settings = replace(tt.TrackerSettings(sound_speed=C, sigma_toa=SIGMA, interval=2.5), acceleration_psd=3e-4)
    tracker = tt.ToaTracker(receivers, settings)
    steps = 6
    schedule = replace(PingSchedule.stable(steps + 1, 2.5, settings.jitter, settings.interval_drift),
                       count=np.array([1.0, 3.0, 0.0, 1.0, 0.0, 2.0]),
                       offset=np.array([0.0, 0.0, 7.25, 0.0, 31.0, 0.0]),
                       te_sigma=rng.uniform(1e-4, 1e-2, steps), drift_sigma=rng.uniform(1e-6, 1e-3, steps))
    for trial in range(40):
        x = rng.normal(0.0, 50.0, 2 * dim + 2)
        x[-1] = rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 10.0) if trial % 4 == 0 else rng.uniform(0.5, 10.0)
        for step in [None, *range(steps)]:
            if step is None:
                count, offset, te, drift = 1.0, 0.0, settings.jitter, settings.interval_drift
                xp, F, Q = tracker.transition(x)
            else:
                count, offset = schedule.count[step], schedule.offset[step]
                te, drift = schedule.te_sigma[step], schedule.drift_sigma[step]
                xp, F, Q = tracker.transition(x, step, schedule)
            want_x, want_F = tb.predict(x[None], dim, np.array([count]), np.array([offset]))
            want_Q = tb.process_noise(np.array([count * float(x[-1]) + offset]), settings.acceleration_psd,
                                      np.array([te]), np.array([drift]), dim)
            for got, want in ((xp, want_x[0]), (F, want_F[0]), (Q, want_Q[0])):
                assert got.shape == want.shape and got.tobytes() == want.tobytes(), (trial, step)
