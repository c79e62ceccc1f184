"""The range-dependent noise law ``σ = σ₀ + k d`` (``acoustics.range_k``): the channel draws it, every receiver's R
weighs it at the predicted range.

References are independent: numpy distances and the law written out, the numpy Philox reference of
:mod:`sblsim.models.philox` (the channel's normal of each slot, so that each drawn error is checked exactly), a
chi-square confidence interval of the drawn errors' std, a numpy EKF update and a numpy Jacobian of the slant range.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
from scipy import stats

from sblsim.models.acoustics import Acoustics
from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.philox import normals
from sblsim.models.platform.core import beacon_names
from sblsim.models.receiver import ekf
from sblsim.models.receiver.measurement import POSITION_INDEX, RangeDepthModel
from sblsim.models.receiver.multilateration import fix_covariance, law_weight, weights
from sblsim.models.receiver.range_direction import RangeDirectionModel
from sblsim.models.systems import usbl_packet
from tests.helpers import Core

CONF = 0.999
COMPONENT = 1  # the channel's component index in the seed tree (sblsim.models.philox)
SIGMA0, K = 0.1, 0.002
#: Two beacons near the target and two far (the cross's order), the target between.
TRUE_BEACONS = np.array([[0.0, 0.0, 1.0], [600.0, 0.0, 1.0], [0.0, 30.0, 1.0], [-400.0, 0.0, 1.0]])
TARGET = np.array([50.0, 0.0, 20.0])
TARGET_NAMES = ("target_x", "target_y", "target_z", "target_vx", "target_vy", "target_vz")


def law(distance):
    return SIGMA0 + K * np.asarray(distance, float)


def channel(params, replicates):
    core = Core(Acoustics, params, replicates=list(replicates)).initialize(0.0)
    inputs = {}
    for kind in ("true", "broadcast"):
        inputs.update(zip(beacon_names(4, kind), TRUE_BEACONS.reshape(12)))
    inputs.update(zip(TARGET_NAMES, list(TARGET) + [0.0, 0.0, 0.0]))
    core.set_inputs(inputs)
    return core


def test_the_channel_draws_the_range_noise_of_the_law_at_the_true_range():
    """Slots 1 (d ≈ 54 m) and 2 (d ≈ 550 m): range − true = (σ₀ + k d) w, w the slot's Philox normal, for every
    replicate; the errors' std in the chi-square interval of σ₀ + k d at both distances (0.21 and 1.20 m)."""
    reps = range(1500)
    core = channel(dict(sigma_range=SIGMA0, range_k=K, seed=3, slot_period=1.0), reps)
    got = {}
    t = 0.0
    for _ in range(4):
        out = core.step(t, 1.0)
        t += 1.0
        seq = int(out["packet_seq"][0])
        if seq in (1, 2) and seq not in got:
            got[seq] = {name: out[name].copy() for name in ("range", "range_true", "beacon_id")}
    assert sorted(got) == [1, 2]
    for k, out in got.items():
        d = np.linalg.norm(TARGET - TRUE_BEACONS[k - 1])
        np.testing.assert_allclose(out["range_true"], d, rtol=1e-12)
        errors = out["range"] - out["range_true"]
        w = np.array([normals(3, 0, 0, r, COMPONENT, 1, k - 1, 1)[0] for r in range(40)])
        np.testing.assert_allclose(errors[:40], law(d) * w, rtol=1e-9, atol=1e-12)
        ss, n = float(np.sum(errors ** 2)), errors.size
        lo = math.sqrt(ss / stats.chi2.ppf(0.5 + CONF / 2, n))
        hi = math.sqrt(ss / stats.chi2.ppf(0.5 - CONF / 2, n))
        assert lo <= law(d) <= hi, (k, lo, hi, law(d))
        assert not lo <= SIGMA0 <= hi  # the law, not the constant σ₀, at either distance


def test_the_default_law_is_the_constant_sigma():
    """range_k = 0 (the default) draws exactly what σ₀ alone draws; a mapping without range_k gives σ₀."""
    a = channel(dict(sigma_range=SIGMA0, seed=4, slot_period=1.0), range(3))
    b = channel(dict(sigma_range=SIGMA0, range_k=0.0, seed=4, slot_period=1.0), range(3))
    for t in range(3):
        np.testing.assert_array_equal(a.step(float(t), 1.0)["range"], b.step(float(t), 1.0)["range"])
    assert range_noise_sigma({"sigma_range": 0.3}, 500.0) == 0.3
    assert range_noise_sigma({"sigma_range": 0.3, "range_k": 0.001}, 500.0) == 0.8


def _numbers(expr):
    return np.array(ca.DM(ca.evalf(expr)), float)


def test_r_of_the_range_receivers_follows_the_law_at_the_predicted_range():
    """RangeDepthModel's diagonal of R and a fresh range's variance (with the GPS and attitude terms) against
    (σ₀ + k ‖p̂ − b‖)² written out; the least-squares weights; the paper EKF's update against a numpy one."""
    p_hat = np.array([120.0, -40.0, 60.0])
    x = np.zeros(6)
    x[list(POSITION_INDEX)] = p_hat
    x[[1, 3, 5]] = (0.3, -0.1, 0.0)
    beacons = [TRUE_BEACONS[i].reshape(3, 1) for i in range(4)]
    d = np.linalg.norm(p_hat - TRUE_BEACONS, axis=1)
    p = dict(sigma_range=SIGMA0, range_k=K, sigma_depth=0.05)
    m = RangeDepthModel()
    np.testing.assert_allclose(_numbers(m.variances(ca.DM(x), [ca.DM(b) for b in beacons], p)).ravel(),
                               np.r_[law(d) ** 2, 0.05 ** 2], rtol=1e-13)
    q = dict(p, beacon_gps_sigma=0.3, beacon_attitude_sigma_deg=2.0, beacon_arm=1.5)
    extra = 0.3 ** 2 + (math.radians(2.0) * 1.5) ** 2  # ‖∂h/∂b‖ = 1
    for i, b in enumerate(beacons):
        got = _numbers(m.fresh_range_variance(ca.DM(x), ca.DM(b), q)).item()
        assert math.isclose(got, law(d[i]) ** 2 + extra, rel_tol=1e-12)
    # least squares: each range weighed by 1 / (σ₀ + k ‖p − b_i‖)²
    for i in range(4):
        assert math.isclose(_numbers(law_weight((SIGMA0, K), d[i])).item(), law(d[i]) ** -2, rel_tol=1e-13)
    ranges = ca.DM(d + np.array([0.2, -0.5, 0.1, 0.3]))
    stacked, heard = ca.DM(TRUE_BEACONS.reshape(12)), ca.DM.ones(4)
    w_r, w_d = weights(SIGMA0, 0.05)
    rss = _numbers(fix_covariance(ca.DM(p_hat), ranges, stacked, heard, 60.0, w_r, w_d, (SIGMA0, K))[0]).item()
    assert math.isclose(rss, float(np.sum((np.array([0.2, -0.5, 0.1, 0.3]) / law(d)) ** 2)), rel_tol=1e-9)
    # the paper EKF's update: R = diag((σ₀ + k d_i)², σ_d²) at the predicted state, numpy's Kalman update
    P = np.diag([4.0, 4.0, 1.0, 0.1, 0.1, 0.1])
    z = d + np.array([0.5, -1.0, 0.2, 0.7])
    depth = 60.3
    new, P_new, _ = ekf.update(ca.DM(x), ca.DM(P), ca.DM(z), stacked, heard, depth, SIGMA0, 0.05, range_k=K)
    H = np.zeros((5, 6))
    H[:4, list(POSITION_INDEX)] = (p_hat - TRUE_BEACONS) / d[:, None]
    H[4, POSITION_INDEX[2]] = 1.0
    R = np.diag(np.r_[law(d) ** 2, 0.05 ** 2])
    S = H @ P @ H.T + R
    gain = P @ H.T @ np.linalg.inv(S)
    expected = x + gain @ (np.r_[z, depth] - np.r_[d, p_hat[2]])
    np.testing.assert_allclose(_numbers(new).ravel(), expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(_numbers(P_new), (np.eye(6) - gain @ H) @ P, rtol=1e-7, atol=1e-9)


def test_r_of_the_usbl_packet_follows_the_law_at_the_predicted_slant_range():
    """The range-direction model's R[0, 0] (no transceiver or attitude error) is (σ₀ + k r̂)², r̂ = ‖p̂ − b‖."""
    transceiver, attitude = np.array([0.0, 0.0, 5.0]), np.zeros(3)
    x = np.zeros(6)
    x[list(POSITION_INDEX)] = (250.0, 120.0, 180.0)
    r_hat = np.linalg.norm(np.array([250.0, 120.0, 180.0]) - transceiver)
    p = dict(sigma_range=SIGMA0, range_k=K, sigma_angle_deg=0.2)
    R = _numbers(usbl_packet.covariance(ca.DM(x), (ca.DM(transceiver), ca.DM(attitude)), p, RangeDirectionModel()))
    assert math.isclose(R[0, 0], law(r_hat) ** 2, rel_tol=1e-12)
    assert math.isclose(R[1, 1], math.radians(0.2) ** 2, rel_tol=1e-12)
    constant = _numbers(usbl_packet.covariance(ca.DM(x), (ca.DM(transceiver), ca.DM(attitude)),
                                        dict(sigma_range=SIGMA0, sigma_angle_deg=0.2), RangeDirectionModel()))
    assert constant[0, 0] == SIGMA0 ** 2
