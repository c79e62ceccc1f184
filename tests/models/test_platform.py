"""Tests of the platform: rotations, beacon geometry, GPS/IMU error models, reproducibility.

References are independent: scipy's Rotation, hand-worked rotations by 90°,
chi-square / Fisher-z confidence intervals for the noise statistics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from models.platform import PlatformCore, beacon_names, beacon_positions, cross_offsets, rotation_ned

CONF = 0.999  # confidence level of the statistical checks


def std_ci_contains(samples: np.ndarray, sigma: float, conf: float = CONF) -> tuple[bool, float]:
    """Whether ``sigma`` lies in the chi-square CI of the std of zero-mean samples."""
    x = np.asarray(samples, float).ravel()
    n = x.size
    ss = float(np.sum(x * x))
    lo = math.sqrt(ss / stats.chi2.ppf(0.5 + conf / 2, n))
    hi = math.sqrt(ss / stats.chi2.ppf(0.5 - conf / 2, n))
    return lo <= sigma <= hi, math.sqrt(ss / n)


def corr_ci_contains(a: np.ndarray, b: np.ndarray, rho: float, conf: float = CONF) -> tuple[bool, float]:
    """Whether ``rho`` lies in the Fisher-z CI of the sample correlation of a and b."""
    a, b = np.ravel(a), np.ravel(b)
    r = float(np.corrcoef(a, b)[0, 1])
    half = stats.norm.ppf(0.5 + conf / 2) / math.sqrt(a.size - 3)
    return abs(math.atanh(r) - math.atanh(rho)) <= half, r


def beacons_of(core: PlatformCore, kind: str) -> np.ndarray:
    names = beacon_names(core.n_beacons, kind)
    return np.stack([core.outputs[n] for n in names], axis=-1).reshape(core.batch, core.n_beacons, 3)


# ----------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------

def test_rotation_ned_matches_scipy_zyx():
    rng = np.random.default_rng(3)
    roll = rng.uniform(-np.pi, np.pi, 20)
    pitch = rng.uniform(-np.pi / 2, np.pi / 2, 20)
    yaw = rng.uniform(-np.pi, np.pi, 20)
    R = rotation_ned(roll, pitch, yaw)
    assert R.shape == (20, 3, 3)
    for k in range(20):
        ref = Rotation.from_euler("ZYX", [yaw[k], pitch[k], roll[k]]).as_matrix()
        np.testing.assert_allclose(R[k], ref, atol=1e-14)


@pytest.mark.parametrize("roll,pitch,yaw,ref", [
    (0.0, 0.0, 0.0, np.eye(3)),
    # yaw 90°: North -> East, East -> South
    (0.0, 0.0, 90.0, np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])),
    # pitch 90° (nose up in NED): forward -> up (-Down), down -> forward
    (0.0, 90.0, 0.0, np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]])),
    # roll 90° (right wing down): right -> down, down -> left
    (90.0, 0.0, 0.0, np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])),
])
def test_rotation_ned_hand_worked(roll, pitch, yaw, ref):
    R = rotation_ned(np.radians([roll]), np.radians([pitch]), np.radians([yaw]))[0]
    np.testing.assert_allclose(R, ref, atol=1e-15)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_cross_offsets_formula():
    L, h = 2.5, 0.8
    off = cross_offsets(L, h, 4)
    ref = np.array([[L, 0, h], [0, L, h], [-L, 0, h], [0, -L, h]])
    np.testing.assert_allclose(off, ref, atol=1e-15)
    # general n: a_i = L (cos θ_i, sin θ_i, 0) + (0, 0, h), θ_i = 2π i / n
    off6 = cross_offsets(L, h, 6)
    th = np.radians([0, 60, 120, 180, 240, 300])
    np.testing.assert_allclose(off6, np.column_stack([L * np.cos(th), L * np.sin(th), np.full(6, h)]),
                               atol=1e-14)


def test_beacon_positions_hand_worked():
    L, h = 2.0, 1.5
    off = cross_offsets(L, h, 4)
    p = np.array([[1.0, 2.0, 0.3], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    R = rotation_ned(np.radians([0.0, 0.0, 90.0, 0.0]), np.radians([0.0, 90.0, 0.0, 0.0]),
                     np.radians([90.0, 0.0, 0.0, 180.0]))
    b = beacon_positions(p, R, off)
    assert b.shape == (4, 4, 3)
    # yaw 90° + translation: (L,0,h) -> (0,L,h), (0,L,h) -> (-L,0,h)
    np.testing.assert_allclose(b[0], p[0] + np.array([[0, L, h], [-L, 0, h], [0, -L, h], [L, 0, h]]), atol=1e-14)
    # pitch 90°: (x, y, z) -> (z, y, -x)
    np.testing.assert_allclose(b[1], np.array([[h, 0, -L], [h, L, 0], [h, 0, L], [h, -L, 0]]), atol=1e-14)
    # roll 90°: (x, y, z) -> (x, -z, y)
    np.testing.assert_allclose(b[2], np.array([[L, -h, 0], [0, -h, L], [-L, -h, 0], [0, -h, -L]]), atol=1e-14)
    # yaw 180° + translation: (x, y, z) -> (-x, -y, z) + p
    np.testing.assert_allclose(b[3], p[3] + np.array([[-L, 0, h], [0, -L, h], [L, 0, h], [0, L, h]]), atol=1e-14)


# ----------------------------------------------------------------------------
# PlatformCore
# ----------------------------------------------------------------------------

def test_calm_sea_true_beacons_are_the_offsets_rotated_by_heading():
    L, h, heading = 1.7, 0.9, 30.0
    core = PlatformCore(dict(beaufort=0, baseline=L, transducer_depth=h, heading_deg=heading,
                             gps_sigma=0.0, imu_sigma_deg=0.0), replicates=[0, 1])
    core.initialize(0.0)
    c, s = math.cos(math.radians(heading)), math.sin(math.radians(heading))
    ref = np.array([[L * c, L * s, h], [-L * s, L * c, h], [-L * c, -L * s, h], [L * s, -L * c, h]])
    for k in range(3):
        np.testing.assert_allclose(beacons_of(core, "true"), np.broadcast_to(ref, (2, 4, 3)), atol=1e-14)
        core.step(0.5 * k, 0.5)


@pytest.mark.parametrize("beaufort", [0, 4])
def test_zero_sensor_noise_broadcast_equals_true(beaufort):
    core = PlatformCore(dict(beaufort=beaufort, gps_sigma=0.0, imu_sigma_deg=0.0, imu_bias_deg=0.0,
                             imu_gyro_bias=0.0, baseline=2.0), replicates=range(3))
    core.initialize(0.0)
    history = []
    for k in range(6):
        true, sent = beacons_of(core, "true"), beacons_of(core, "broadcast")
        np.testing.assert_array_equal(sent, true)
        history.append(true)
        core.step(0.4 * k, 0.4)
    spread = np.ptp(np.stack(history), axis=0).max()
    if beaufort == 0:
        assert spread == 0.0           # calm: nothing moves
    else:
        assert spread > 1e-2           # the sea moves the beacons: the equality is not trivial


def _gps_errors(core):
    """Broadcast minus true, checked to be the same vector for every beacon; shape (B, 3)."""
    diff = beacons_of(core, "broadcast") - beacons_of(core, "true")
    np.testing.assert_allclose(diff, np.broadcast_to(diff[:, :1, :], diff.shape), atol=1e-12)
    gps = np.column_stack([core.outputs[f"gps_{a}"] for a in "xyz"])
    np.testing.assert_allclose(diff[:, 0, :], gps, atol=1e-12)  # the platform sits at the origin
    return diff[:, 0, :]


def test_gps_white_noise_std_and_independence():
    sigma = 0.3
    core = PlatformCore(dict(beaufort=0, gps_sigma=sigma, imu_sigma_deg=0.0, seed=11),
                        replicates=range(2000))
    core.initialize(0.0)
    errors = [_gps_errors(core)]
    for k in range(3):
        core.step(float(k), 1.0)
        errors.append(_gps_errors(core))
    for e in errors:
        ok, est = std_ci_contains(e, sigma)
        assert ok, f"sample std {est} vs {sigma}"
        # zero mean: |mean| within the normal CI
        assert abs(e.mean()) <= stats.norm.ppf(0.5 + CONF / 2) * sigma / math.sqrt(e.size)
    # white: successive errors uncorrelated
    ok, r = corr_ci_contains(errors[1], errors[2], 0.0)
    assert ok, f"lag-1 correlation {r} of white GPS noise"


def test_gps_gauss_markov_autocorrelation_and_stationary_std():
    sigma, tau, dt = 0.5, 2.0, 1.0
    core = PlatformCore(dict(beaufort=0, gps_sigma=sigma, gps_model="gauss-markov", gps_tau=tau,
                             imu_sigma_deg=0.0, seed=5), replicates=range(2000))
    core.initialize(0.0)
    errors = [_gps_errors(core)]
    for k in range(4):
        core.step(k * dt, dt)
        errors.append(_gps_errors(core))
    phi = math.exp(-dt / tau)
    for a, b in ((0, 1), (3, 4)):
        ok, r = corr_ci_contains(errors[a], errors[b], phi)
        assert ok, f"lag-1 correlation {r} vs exp(-dt/tau) = {phi}"
    ok, r = corr_ci_contains(errors[0], errors[2], phi**2)
    assert ok, f"lag-2 correlation {r} vs {phi ** 2}"
    for e in errors:  # stationary start: the std is sigma at every step
        ok, est = std_ci_contains(e, sigma)
        assert ok, f"sample std {est} vs {sigma}"


def test_imu_noise_rotates_broadcast_beacons():
    """With GPS exact and only IMU noise, |broadcast - gps| = |a_i| and the angle error has std σ_IMU."""
    sig_deg = 2.0
    L, h = 3.0, 0.0
    core = PlatformCore(dict(beaufort=0, gps_sigma=0.0, imu_sigma_deg=sig_deg, baseline=L, transducer_depth=h,
                             seed=2), replicates=range(2000))
    core.initialize(0.0)
    sent = beacons_of(core, "broadcast")
    np.testing.assert_allclose(np.linalg.norm(sent, axis=-1), L, rtol=1e-12)
    # beacon 1 at (L, 0, 0): with small angles, its East coordinate is L * yaw error
    yaw_err = np.arcsin(np.clip(sent[:, 0, 1] / (L * np.cos(np.arcsin(np.clip(-sent[:, 0, 2] / L, -1, 1)))), -1, 1))
    ok, est = std_ci_contains(yaw_err, math.radians(sig_deg))
    assert ok, f"yaw error std {math.degrees(est)} deg vs {sig_deg}"
    # and its Down coordinate is -L sin(pitch error)
    pitch_err = np.arcsin(np.clip(-sent[:, 0, 2] / L, -1, 1))
    ok, est = std_ci_contains(pitch_err, math.radians(sig_deg))
    assert ok, f"pitch error std {math.degrees(est)} deg vs {sig_deg}"


def test_imu_bias_and_gyro_drift():
    """A constant bias b and drift ω t rotate the calm-sea broadcast cross by b + ω t about every axis."""
    bias_deg, drift = 3.0, 0.01
    L, h = 2.0, 1.0
    core = PlatformCore(dict(beaufort=0, gps_sigma=0.0, imu_sigma_deg=0.0, imu_bias_deg=bias_deg,
                             imu_gyro_bias=drift, baseline=L, transducer_depth=h), replicates=[0])
    core.initialize(0.0)
    for k in range(3):
        t = 2.0 * k
        ang = math.radians(bias_deg) + drift * t
        ref = Rotation.from_euler("ZYX", [ang, ang, ang]).apply(cross_offsets(L, h))
        np.testing.assert_allclose(beacons_of(core, "broadcast")[0], ref, atol=1e-12)
        core.step(t, 2.0)


def test_replicate_alone_equals_replicate_in_batch():
    params = dict(beaufort=4, gps_sigma=0.2, gps_model="gauss-markov", gps_tau=5.0, imu_sigma_deg=1.5,
                  seed=99, scenario_key=2, cell=3)
    batch = PlatformCore(params, replicates=range(5))
    alone = PlatformCore(params, replicates=[3])
    other = PlatformCore(dict(params, seed=100), replicates=[3])
    batch.initialize(0.0)
    alone.initialize(0.0)
    other.initialize(0.0)
    for k in range(300):  # crosses a RandomStreams block boundary (256 steps)
        for name in batch.outputs:
            np.testing.assert_array_equal(alone.outputs[name], batch.outputs[name][3:4], err_msg=name)
        batch.step(0.1 * k, 0.1)
        alone.step(0.1 * k, 0.1)
        other.step(0.1 * k, 0.1)
    # replicates of a batch differ from each other, and another seed gives other numbers
    assert np.unique(batch.outputs["gps_x"]).size == 5
    assert other.outputs["gps_x"][0] != alone.outputs["gps_x"][0]
