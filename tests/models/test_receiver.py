"""Tests of the receiver: casadi range Jacobian, EKF, multilateration and the core's timing.

Every reference value is computed independently in plain numpy in this file
(finite differences, the textbook Kalman equations, hand-built geometry).
"""

from __future__ import annotations

import numpy as np
import pytest

from models.receiver.core import ReceiverCore
from models.receiver.ekf import ExtendedKalmanFilter
from models.receiver.jacobian import range_and_jacobian
from models.receiver.multilateration import multilaterate

POS = [0, 2, 4]  # position columns of the state [x, vx, y, vy, z, vz]


# ----------------------------------------------------------------------------
# Independent reference implementations
# ----------------------------------------------------------------------------

def np_range(state: np.ndarray, beacon: np.ndarray) -> float:
    """Range from one 6-state to one beacon, in plain numpy."""
    p = np.array([state[0], state[2], state[4]])
    return float(np.sqrt(np.sum((p - beacon) ** 2)))


def ref_phi(dt: float) -> np.ndarray:
    block = np.array([[1.0, dt], [0.0, 1.0]])
    phi = np.zeros((6, 6))
    for a in range(3):
        phi[2 * a:2 * a + 2, 2 * a:2 * a + 2] = block
    return phi


def ref_q(dt: float, qh: float, qv: float) -> np.ndarray:
    q = np.zeros((6, 6))
    for a, dens in enumerate((qh, qh, qv)):
        q[2 * a:2 * a + 2, 2 * a:2 * a + 2] = dens * np.array(
            [[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return q


def ref_update(x, P, ranges, beacons, depth, sr, sd):
    """Plain EKF update of one replicate using only the available measurements.

    ``ranges`` (n,) with NaN = missing (the row is removed entirely), ``depth``
    a float (NaN = missing). Returns x, P (Joseph form) and NIS.
    """
    p = x[POS]
    rows, z, hx, rvar = [], [], [], []
    for r, b in zip(ranges, beacons):
        if not np.isfinite(r):
            continue
        d = p - b
        rho = np.linalg.norm(d)
        row = np.zeros(6)
        row[POS] = d / rho
        rows.append(row)
        z.append(r)
        hx.append(rho)
        rvar.append(sr**2)
    if np.isfinite(depth):
        rows.append(np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0]))
        z.append(depth)
        hx.append(x[4])
        rvar.append(sd**2)
    H = np.array(rows)
    R = np.diag(rvar)
    y = np.array(z) - np.array(hx)
    S = H @ P @ H.T + R
    Sinv = np.linalg.inv(S)
    K = P @ H.T @ Sinv
    x_new = x + K @ y
    A = np.eye(6) - K @ H
    P_new = A @ P @ A.T + K @ R @ K.T
    return x_new, P_new, float(y @ Sinv @ y)


def cross(L=1.0, h=1.0):
    """The 4 cross beacons L(cos θ, sin θ, 0) + (0, 0, h), θ = 0, 90, 180, 270 deg."""
    return np.array([[L, 0.0, h], [0.0, L, h], [-L, 0.0, h], [0.0, -L, h]])


def random_spd(rng, n=6, scale=1.0):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T / n + 0.5 * np.eye(n))


# ----------------------------------------------------------------------------
# casadi range Jacobian
# ----------------------------------------------------------------------------

def test_range_and_jacobian_match_numpy_and_central_differences():
    rng = np.random.default_rng(12345)
    B, n = 7, 4
    states = rng.normal(scale=10.0, size=(B, 6))
    beacons = rng.normal(scale=3.0, size=(B, n, 3))
    h, H = range_and_jacobian(states, beacons)
    assert h.shape == (B, n) and H.shape == (B, n, 6)

    eps = 1e-6
    for b in range(B):
        for i in range(n):
            assert h[b, i] == pytest.approx(np.linalg.norm(states[b, POS] - beacons[b, i]), rel=1e-12)
            fd = np.empty(6)
            for k in range(6):
                e = np.zeros(6)
                e[k] = eps
                fd[k] = (np_range(states[b] + e, beacons[b, i]) - np_range(states[b] - e, beacons[b, i])) / (2 * eps)
            np.testing.assert_allclose(H[b, i], fd, atol=1e-6, rtol=0)
            # velocity columns are exactly zero, the position part is a unit vector
            assert np.all(H[b, i, [1, 3, 5]] == 0.0)
            assert np.linalg.norm(H[b, i, POS]) == pytest.approx(1.0, abs=1e-12)


def test_range_and_jacobian_single_beacon_batch_ordering():
    """Different beacons per replicate are not mixed up by the flattening."""
    states = np.array([[3.0, 9.0, 4.0, 9.0, 0.0, 9.0], [0.0, 0.0, 0.0, 0.0, 12.0, 0.0]])
    beacons = np.array([[[0.0, 0.0, 0.0]], [[0.0, 0.0, 7.0]]])
    h, H = range_and_jacobian(states, beacons)
    np.testing.assert_allclose(h, [[5.0], [5.0]], rtol=1e-14)
    np.testing.assert_allclose(H[0, 0], [0.6, 0, 0.8, 0, 0, 0], atol=1e-14)
    np.testing.assert_allclose(H[1, 0], [0, 0, 0, 0, 1.0, 0], atol=1e-14)


# ----------------------------------------------------------------------------
# EKF
# ----------------------------------------------------------------------------

EKF_PARAMS = dict(q_horizontal=0.03, q_vertical=0.004, sigma_range=0.15, sigma_depth=0.02)


def _ekf_case(seed=7, B=3):
    rng = np.random.default_rng(seed)
    x0 = np.column_stack([
        rng.uniform(5, 15, B), rng.normal(0, 0.5, B),
        rng.uniform(-10, 10, B), rng.normal(0, 0.5, B),
        rng.uniform(3, 8, B), rng.normal(0, 0.1, B)])
    P0 = random_spd(rng, scale=0.5)
    beacons = cross(1.0, 1.0)[None] + rng.normal(scale=0.05, size=(B, 4, 3))
    truth = x0[:, POS] + rng.normal(scale=0.7, size=(B, 3))
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1) + rng.normal(scale=0.15, size=(B, 4))
    depth = truth[:, 2] + rng.normal(scale=0.02, size=B)
    return x0, P0, beacons, ranges, depth


def test_ekf_predict_matches_numpy():
    x0, P0, *_ = _ekf_case()
    ekf = ExtendedKalmanFilter(x0, P0, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"],
                               EKF_PARAMS["sigma_range"], EKF_PARAMS["sigma_depth"])
    dt = 0.7
    ekf.predict(dt)
    phi, Q = ref_phi(dt), ref_q(dt, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"])
    for b in range(x0.shape[0]):
        np.testing.assert_allclose(ekf.x[b], phi @ x0[b], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(ekf.P[b], phi @ P0 @ phi.T + Q, rtol=1e-12, atol=1e-14)
    # hand check of one element: position x moves by v dt
    assert ekf.x[0, 0] == pytest.approx(x0[0, 0] + dt * x0[0, 1], rel=1e-14)


def test_ekf_predict_update_matches_numpy():
    x0, P0, beacons, ranges, depth = _ekf_case()
    sr, sd = EKF_PARAMS["sigma_range"], EKF_PARAMS["sigma_depth"]
    ekf = ExtendedKalmanFilter(x0, P0, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"], sr, sd)
    dt = 1.0
    ekf.predict(dt)
    ekf.update(ranges, beacons, depth)

    phi, Q = ref_phi(dt), ref_q(dt, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"])
    for b in range(x0.shape[0]):
        xp, Pp = phi @ x0[b], phi @ P0 @ phi.T + Q
        x_ref, P_ref, nis_ref = ref_update(xp, Pp, ranges[b], beacons[b], depth[b], sr, sd)
        np.testing.assert_allclose(ekf.x[b], x_ref, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(ekf.P[b], P_ref, rtol=1e-8, atol=1e-12)
        assert ekf.nis[b] == pytest.approx(nis_ref, rel=1e-9)
        # the update actually moved the state (the test would catch a no-op)
        assert np.linalg.norm(ekf.x[b] - xp) > 1e-3
    # the updated covariance is symmetric positive definite
    assert np.allclose(ekf.P, np.swapaxes(ekf.P, 1, 2), atol=1e-14)
    assert np.all(np.linalg.eigvalsh(ekf.P) > 0)


@pytest.mark.parametrize("missing", [0, 1, 2, 3, "depth"])
def test_ekf_missing_measurement_equals_update_without_that_row(missing):
    x0, P0, beacons, ranges, depth = _ekf_case(seed=21, B=2)
    ranges = ranges.copy()
    depth = depth.copy()
    if missing == "depth":
        depth[0] = np.nan
    else:
        ranges[0, missing] = np.nan
        beacons = beacons.copy()
        beacons[0, missing] = np.nan  # a beacon never heard has no position either
    sr, sd = EKF_PARAMS["sigma_range"], EKF_PARAMS["sigma_depth"]
    ekf = ExtendedKalmanFilter(x0, P0, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"], sr, sd)
    ekf.predict(0.5)
    ekf.update(ranges, beacons, depth)
    phi, Q = ref_phi(0.5), ref_q(0.5, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"])
    for b in range(2):
        xp, Pp = phi @ x0[b], phi @ P0 @ phi.T + Q
        x_ref, P_ref, nis_ref = ref_update(xp, Pp, ranges[b], beacons[b], depth[b], sr, sd)
        np.testing.assert_allclose(ekf.x[b], x_ref, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(ekf.P[b], P_ref, rtol=1e-8, atol=1e-12)
        assert ekf.nis[b] == pytest.approx(nis_ref, rel=1e-9)
    assert np.all(np.isfinite(ekf.x)) and np.all(np.isfinite(ekf.P))


# ----------------------------------------------------------------------------
# Multilateration
# ----------------------------------------------------------------------------

def test_multilaterate_recovers_true_position_from_noiseless_ranges():
    truth = np.array([[8.0, -3.0, 5.0], [-12.0, 6.5, 9.0], [0.5, 15.0, 3.0]])
    B = truth.shape[0]
    beacons = np.broadcast_to(cross(1.0, 1.0), (B, 4, 3)).copy()
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1)
    depth = truth[:, 2].copy()
    guess = truth + np.array([[1.5, -1.0, 1.0], [-2.0, 2.0, -1.0], [1.0, 1.0, 1.0]])
    fix, valid = multilaterate(ranges, beacons, depth, guess, 0.1, 0.01)
    assert valid.tolist() == [True] * B
    np.testing.assert_allclose(fix, truth, atol=1e-6)


def test_multilaterate_three_ranges_enough_two_not():
    truth = np.array([[6.0, 4.0, 7.0], [6.0, 4.0, 7.0], [6.0, 4.0, 7.0]])
    beacons = np.broadcast_to(cross(2.0, 1.0), (3, 4, 3)).copy()
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1)
    ranges[0, 3] = np.nan                 # 3 ranges: valid
    ranges[1, [1, 3]] = np.nan            # 2 ranges: invalid
    ranges[2, :] = np.nan                 # none: invalid
    fix, valid = multilaterate(ranges, beacons, truth[:, 2].copy(), truth + 1.0, 0.1, 0.01)
    assert valid.tolist() == [True, False, False]
    np.testing.assert_allclose(fix[0], truth[0], atol=1e-6)
    assert np.all(np.isnan(fix[1])) and np.all(np.isnan(fix[2]))


def test_multilaterate_nan_depth_is_invalid():
    truth = np.array([[6.0, 4.0, 7.0]])
    beacons = cross()[None]
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1)
    fix, valid = multilaterate(ranges, beacons, np.array([np.nan]), truth, 0.1, 0.01)
    assert not valid[0] and np.all(np.isnan(fix))


# ----------------------------------------------------------------------------
# ReceiverCore timing
# ----------------------------------------------------------------------------

RX = dict(sigma_range=0.2, sigma_depth=0.05, q_horizontal=0.02, q_vertical=0.002,
          p0_position=2.0, p0_velocity=0.4,
          x0_x=10.0, x0_y=-4.0, x0_z=6.0, x0_vx=0.3, x0_vy=-0.2, x0_vz=0.05)


def _x0_P0():
    x = np.array([RX["x0_x"], RX["x0_vx"], RX["x0_y"], RX["x0_vy"], RX["x0_z"], RX["x0_vz"]])
    P = np.diag([RX["p0_position"] ** 2, RX["p0_velocity"] ** 2] * 3)
    return x, P


def _packet(seq, beacon_id, tx_time, rng_value, beacon, depth, valid=True):
    return dict(packet_seq=seq, beacon_id=beacon_id, packet_valid=valid, tx_time=tx_time,
                range=rng_value, beacon_x=beacon[0], beacon_y=beacon[1], beacon_z=beacon[2], depth=depth)


def test_receiver_core_uses_packet_only_when_step_end_reaches_tx_time():
    T, r = 1.0, 4
    dt = T / r
    core = ReceiverCore(RX, replicates=[0])
    core.initialize(0.0)
    x_ref, P_ref = _x0_P0()
    phi, Q = ref_phi(dt), ref_q(dt, RX["q_horizontal"], RX["q_vertical"])
    held = np.full(4, np.nan)
    held_b = np.full((4, 3), np.nan)
    beacons = cross(1.0, 1.0)

    def check_no_update():
        np.testing.assert_allclose([core.outputs[f"est_{n}"][0] for n in ("x", "vx", "y", "vy", "z", "vz")],
                                   x_ref, rtol=1e-12, atol=1e-12)
        assert core.outputs["pos_std"][0] == pytest.approx(np.sqrt(P_ref[0, 0] + P_ref[2, 2] + P_ref[4, 4]),
                                                           rel=1e-12)

    # initial outputs: no update yet
    check_no_update()
    assert np.isnan(core.outputs["nis"][0]) and not core.outputs["instr_valid"][0]

    packets = [  # (seq, beacon_id, range, depth); each sent at the start of a slot of length T
        (1, 2, 12.3, 6.4),
        (2, 3, 13.1, 6.5),
    ]
    t = 0.0
    for seq, bid, rng_value, depth in packets:
        tx = t + T
        core.set_inputs(_packet(seq, bid, tx, rng_value, beacons[bid - 1], depth))
        for j in range(r):
            core.step(t, dt)
            t += dt
            x_ref, P_ref = phi @ x_ref, phi @ P_ref @ phi.T + Q
            if j < r - 1:
                assert t < tx - 1e-9
                check_no_update()   # packet not reached yet: a pure prediction
                continue
            assert t == pytest.approx(tx)
            held[bid - 1] = rng_value
            held_b[bid - 1] = beacons[bid - 1]
            x_ref, P_ref, nis = ref_update(x_ref, P_ref, held, held_b, depth, RX["sigma_range"],
                                           RX["sigma_depth"])
            np.testing.assert_allclose([core.outputs[f"est_{n}"][0] for n in ("x", "vx", "y", "vy", "z", "vz")],
                                       x_ref, rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(core.ekf.P[0], P_ref, rtol=1e-8, atol=1e-12)
            assert core.outputs["nis"][0] == pytest.approx(nis, rel=1e-9)
        # a whole further slot with the same packet still on the inputs: no second update
        nis_before = core.outputs["nis"][0]
        for _ in range(r):
            core.step(t, dt)
            t += dt
            x_ref, P_ref = phi @ x_ref, phi @ P_ref @ phi.T + Q
            check_no_update()
            assert core.outputs["nis"][0] == nis_before
    # two beacons heard only: no instrumentation fix
    assert not core.outputs["instr_valid"][0]


def test_receiver_core_lost_packet_keeps_held_range_and_fix():
    """A lost packet (valid False) stores nothing; the update re-uses the held ranges."""
    truth = np.array([7.0, -5.0, 6.0])
    beacons = cross(1.0, 1.0)
    true_ranges = np.linalg.norm(truth - beacons, axis=1)
    params = dict(RX, x0_x=6.5, x0_y=-4.5, x0_z=6.2, x0_vx=0.0, x0_vy=0.0, x0_vz=0.0)
    core = ReceiverCore(params, replicates=[0, 1])
    core.initialize(0.0)
    t = 0.0
    for k in range(4):
        core.set_inputs(_packet(k + 1, k + 1, t + 1.0, true_ranges[k], beacons[k], truth[2]))
        core.step(t, 1.0)
        t += 1.0
    assert core.outputs["instr_valid"].tolist() == [True, True]
    np.testing.assert_allclose(np.column_stack([core.outputs[f"instr_{a}"] for a in "xyz"]),
                               np.tile(truth, (2, 1)), atol=1e-6)
    np.testing.assert_allclose(core.ranges, np.tile(true_ranges, (2, 1)))
    # replicate 0 loses the next packet of beacon 1 (range NaN); replicate 1 hears 99 m
    core.set_inputs(dict(_packet(5, 1, t + 1.0, np.array([np.nan, 99.0]), beacons[0], truth[2]),
                         packet_valid=np.array([False, True])))
    core.step(t, 1.0)
    assert core.ranges[0, 0] == pytest.approx(true_ranges[0])
    assert core.ranges[1, 0] == 99.0
    assert np.isfinite(core.outputs["nis"][0])
