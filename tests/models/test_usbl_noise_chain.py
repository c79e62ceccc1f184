"""The USBL packet's R, its least-squares fix and its map against independent computations.

* R (:func:`sblsim.models.systems.usbl_packet.covariance`) against a Monte Carlo of the channel's own noise chain,
  written here in numpy and scipy (not with the model's casadi): the array tilted by the waves and turned to its
  heading measures the direction cosines of the line of sight across its two axes with their noise, its
  mounting misalignment drawn per sample; the IMU measures the attitude with its noise, the surface broadcasts
  the transceiver at the GPS position (with its error) plus the lever arm turned by the IMU's attitude; the
  receiver predicts the packet from what was broadcast. The covariance of the residual ``z − h`` straight below
  the transceiver, 45° and 85° off the vertical is within 10 % of R there.
* The packet's least-squares fix with the depth (:func:`sblsim.models.systems.usbl_fix.packet_fix`) equals
  scipy's ``least_squares`` on the same weighted residuals.
* The map's covariance of one packet plus the depth (:func:`sblsim.models.systems.usbl_map.fix_information`) is the
  inverse of the bound's information of the same packet (the bound's step from a wide prior, whose information
  is taken off): the map and the bound use one R; straight below the transceiver the map is finite and keeps the
  GPS error (DRMS ≥ √2 σ_GPS).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import least_squares

from sblsim.models.systems import usbl_bound, usbl_fix, usbl_map, usbl_packet
from tests.models.test_measurement_models import np_range_direction, np_rotation

#: The platform's attitude (roll and pitch of the waves, the heading) [rad] and the transceiver's lever arm [m].
PLATFORM = np.array([0.06, -0.04, 0.5])
ARM = np.array([0.0, 0.0, 5.0])
#: The receivers' parameters: σ_r, σ_u [deg], GPS, the IMU's white error [deg], the lever arm, the misalignment.
P = {"sigma_range": 0.2, "sigma_angle_deg": 0.5, "beacon_gps_sigma": 0.5, "beacon_attitude_sigma_deg": 1.0,
     "beacon_arm": 5.0, "attitude_bias_sigma_deg": 0.5, "sigma_depth": 0.05}


def chain(p, n, seed=0):
    """``z − h`` (n, 3) of n packets from a diver at ``p``: the channel's noise chain, then the receiver's
    prediction from the broadcast transceiver and the IMU's attitude."""
    rng = np.random.default_rng(seed)
    rad = math.radians
    b_true = np_rotation(PLATFORM) @ ARM
    out = np.empty((n, 3))
    for k in range(n):
        misalignment = rng.normal(scale=rad(P["attitude_bias_sigma_deg"]), size=3)
        imu = PLATFORM + rng.normal(scale=rad(P["beacon_attitude_sigma_deg"]), size=3)
        broadcast = rng.normal(scale=P["beacon_gps_sigma"], size=3) + np_rotation(imu) @ ARM
        d = p - b_true
        seen = np_rotation(PLATFORM + misalignment).T @ d / np.linalg.norm(d)
        z = np.array([np.linalg.norm(d), seen[0], seen[1]])
        z += rng.normal(size=3) * [P["sigma_range"], rad(P["sigma_angle_deg"]), rad(P["sigma_angle_deg"])]
        out[k] = z - np_range_direction(np.array([p[0], 0, p[1], 0, p[2], 0]), broadcast, imu)
    return out


def receivers_covariance(p):
    """The receivers' R (one packet's fix: the misalignment's prior in it) at ``p`` with the nominal context."""
    x, b, att = ca.SX.sym("x", 3), ca.SX.sym("b", 3), ca.SX.sym("att", 3)
    R = usbl_packet.covariance(x, (b, att), P, usbl_packet.POSITION_MODEL, states=False)
    return np.array(ca.Function("R", [x, b, att], [R])(p, np_rotation(PLATFORM) @ ARM, PLATFORM))


@pytest.mark.slow
@pytest.mark.parametrize("off_vertical", [0.0, 45.0, 85.0])
def test_r_is_the_covariance_of_the_channels_noise_chain(off_vertical):
    slant, bearing = 1000.0, math.radians(30.0)
    phi = math.radians(off_vertical)
    p = np_rotation(PLATFORM) @ ARM + slant * np.array([math.sin(phi) * math.cos(bearing),
                                                        math.sin(phi) * math.sin(bearing), math.cos(phi)])
    residual = chain(p, 40_000, seed=int(off_vertical))
    sample, R = np.cov(residual.T), receivers_covariance(p)
    scale = np.sqrt(np.outer(np.diag(R), np.diag(R)))
    assert np.all(np.abs(sample - R) <= 0.1 * scale), (sample, R)
    assert np.abs(residual.mean(axis=0)).max() < 0.05 * np.sqrt(np.diag(R)).max()  # no bias


def test_the_packet_fix_is_scipys_least_squares():
    b, att = np.array([0.3, -0.2, 5.0]), PLATFORM
    rng = np.random.default_rng(3)
    for truth in ([400.0, -300.0, 800.0], [0.5, 0.0, 900.0], [2000.0, 500.0, 150.0]):
        truth = np.asarray(truth)
        z = np_range_direction(np.array([truth[0], 0, truth[1], 0, truth[2], 0]), b, att) + rng.normal(size=3) * [
            0.2, 0.005, 0.005]
        depth = truth[2] + rng.normal() * P["sigma_depth"]
        n = np_rotation(att) @ np.array([z[1], z[2], math.sqrt(max(1 - z[1] ** 2 - z[2] ** 2, 0.0))])
        u = {"range": z[0], "doa_x": z[1], "doa_y": z[2], "beacon_x": b[0], "beacon_y": b[1], "beacon_z": b[2],
             "azimuth": math.atan2(n[1], n[0]), "elevation": math.atan2(n[2], math.hypot(n[0], n[1])),
             **{f"doa_{a}": v for a, v in zip(("roll", "pitch", "yaw"), att)}}
        point, covariance, rss = (np.array(v) for v in ca.Function("fix", [], list(usbl_fix.packet_fix(
            {k: ca.SX(v) for k, v in u.items()}, P, ca.SX(depth)))).call([]))
        polar = b + z[0] * n  # the documented start, where the weights are taken

        def weighted(q, at, z=z, depth=depth):
            L = np.linalg.cholesky(np.linalg.inv(receivers_covariance_at(at, b, att)))
            return np.append(L.T @ (z - np_range_direction(np.array([q[0], 0, q[1], 0, q[2], 0]), b, att)),
                             (depth - q[2]) / P["sigma_depth"])

        ref = least_squares(weighted, truth + [3.0, -2.0, 0.5], args=(polar,), xtol=1e-15, ftol=1e-15, gtol=1e-15)
        # Gauss-Newton converges linearly below the vertical: within 0.1 mm after its iterations
        np.testing.assert_allclose(point.ravel(), ref.x, atol=1e-4)
        assert rss.item() == pytest.approx(np.sum(ref.fun ** 2), rel=1e-5, abs=1e-9)
        J = least_squares(weighted, ref.x, args=(ref.x,), max_nfev=1, jac="3-point").jac  # R at the fix
        expected = np.linalg.inv(J.T @ J)
        scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
        assert np.all(np.abs(covariance - expected) <= 1e-4 * scale), (covariance, expected)


def receivers_covariance_at(p, b, att):
    x, bs, a = ca.SX.sym("x", 3), ca.SX.sym("b", 3), ca.SX.sym("att", 3)
    R = usbl_packet.covariance(x, (bs, a), P, usbl_packet.POSITION_MODEL, states=False)
    return np.array(ca.Function("R", [x, bs, a], [R])(p, b, att))


#: The prior's variance of the one-packet bound [m², m²/s²]: wide, and its information (1 / PRIOR) taken off.
PRIOR = 1e4


def one_packet_bound(position, transceiver, attitude, fixed):
    """The bound's step (the receivers' H and R of one USBL packet plus the depth) from a wide prior with no
    process noise and no error states: the information about the position it adds, ``B_pos⁻¹ − I / PRIOR``."""
    step = usbl_bound.bound_step()
    n = usbl_bound.BOUND_MODEL.motion.state_size
    prior = np.diag([PRIOR] * 6 + [0.0] * (n - 6)).reshape(-1)
    B = np.array(step(prior, 1e-12, 0.0, 0.0, position, transceiver, attitude, fixed["range_variance"],
                      fixed["position_variance"], fixed["angle_sigma_deg"], fixed["attitude_variance"],
                      fixed["depth_variance"], 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0)).reshape(n, n, order="F")
    return np.linalg.inv(B[np.ix_([0, 2, 4], [0, 2, 4])]) - np.eye(3) / PRIOR


@pytest.mark.parametrize("gps", [0.1, 1.0])
def test_the_map_is_the_bounds_information_of_one_packet_and_finite_below_the_transceiver(gps):
    fixed = {"range_variance": 0.01, "position_variance": gps ** 2 + (math.radians(1.0) * 1.0) ** 2,
             "angle_sigma_deg": 0.5, "attitude_variance": math.radians(1.0) ** 2, "depth_variance": 1e-4}
    f = usbl_map.fix_information()
    transceiver, level = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.3])
    for d in ([15.0, 0.0, 4.0], [-3.0, 2.0, 20.0], [40.0, -30.0, 2.0], [0.0, 0.0, 6.0], [1.0, 1.0, 400.0]):
        position = transceiver + np.asarray(d)
        C, drms = (np.array(v) for v in f(position, transceiver, level, *fixed.values()))
        information = one_packet_bound(position, transceiver, level, fixed)
        np.testing.assert_allclose(np.linalg.inv(C), information, rtol=1e-6, atol=1e-9 * np.abs(information).max())
        bound = np.linalg.inv(information)
        assert drms.item() == pytest.approx(math.sqrt(bound[0, 0] + bound[1, 1]), rel=1e-6)
    # straight below the transceiver and near it: finite, continuous, the transceiver's error kept
    below = [usbl_map.horizontal_std(transceiver + [[dn, 0.0, 4.0]], transceiver, *fixed.values())[0]
             for dn in (0.0, 1e-6, 0.5)]
    assert np.isfinite(below).all() and min(below) >= math.sqrt(2 * fixed["position_variance"]) * (1 - 1e-12)
    assert below[0] == pytest.approx(below[1], rel=1e-9)
    # and a perfect array (σ_r, σ_u at their minimums, no attitude error): the GPS floor √2 σ everywhere, reached
    perfect = {**fixed, "range_variance": 1e-12, "position_variance": gps ** 2, "angle_sigma_deg": 1e-3,
               "attitude_variance": 0.0}
    points = np.array([[n, e, 5.0] for n in (-30.0, -0.5, 0.0, 1e-7, 3.0, 30.0) for e in (-20.0, 0.0, 0.5, 25.0)])
    drms = usbl_map.horizontal_std(points, transceiver, *perfect.values())
    # (to 1e-4 near the vertical, where the map is the fix's own error over its errors' draws: nadir_fix_rms)
    assert np.isfinite(drms).all() and np.all(drms >= math.sqrt(2.0) * gps * (1 - 1e-4))
    assert drms.min() == pytest.approx(math.sqrt(2.0) * gps, rel=1e-3)
