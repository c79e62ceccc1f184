"""The accuracy limit (models/bound.py) against independent computations.

* Linear-Gaussian case: with the measurement Jacobians fixed along a given
  path, the system is linear and Gaussian, and the PCRB recursion must equal
  the Kalman filter's covariance exactly; checked against FilterPy's
  ``KalmanFilter`` (covariance form) and against Tichavský's information
  recursion ``J_k+1 = D22 − D21 (J_k + D11)⁻¹ D12`` written here in numpy,
  with the Jacobians by central differences.
* The effective range variance against finite differences of the range under
  small rotations of the beacon's lever arm.
* The Fisher information of one round of ranges: a hand-worked case and a
  numpy build with finite-difference gradients.
* The compiled bound equals the casadi evaluation.
* The same generic Fisher information for the range + bearing (USBL) model:
  against analytic gradients and finite differences, and the closed form of
  its horizontal DRMS along a line at fixed depth.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from sblsim.models.bound import effective_range_variance, fix_information, horizontal_std, pcrb, pcrb_inputs
from tests.models.test_receiver_filterpy import phi, white_noise_q

EPS = 1e-6


def fd_range_row(position, beacon):
    """∂‖p − b‖/∂x of the 6-state by central differences."""
    H = np.zeros((1, 6))
    for k, i in enumerate((0, 2, 4)):
        d = np.zeros(3)
        d[k] = EPS
        H[0, i] = (np.linalg.norm(position + d - beacon) - np.linalg.norm(position - d - beacon)) / (2 * EPS)
    return H


def fd_attitude_variance(position, beacon, arm, variance):
    """σ² Σ_k (∂r/∂θ_k)², the range's sensitivities to small rotations δθ × arm by central differences."""
    total = 0.0
    for k in range(3):
        d = np.zeros(3)
        d[k] = EPS
        plus = np.linalg.norm(position - (beacon + np.cross(d, arm)))
        minus = np.linalg.norm(position - (beacon - np.cross(d, arm)))
        total += ((plus - minus) / (2 * EPS)) ** 2
    return variance * total


def case(seed=3, n=300, b=3):
    rng = np.random.default_rng(seed)
    t = 0.2 * np.arange(1, n + 1)
    truth = np.stack([np.stack([12 * np.cos(0.05 * t + j), 12 * np.sin(0.05 * t + j), 5 + 0.01 * t], -1)
                      for j in range(b)], axis=1)  # (N, B, 3)
    beacons = rng.normal(scale=3.0, size=(n, b, 3)) * [1, 1, 0.2] + [0, 0, 1]
    arms = rng.normal(scale=2.0, size=(n, b, 3))
    slot = rng.uniform(size=(n, b)) < 0.7
    received = slot & (rng.uniform(size=(n, b)) < 0.8)
    fixed = dict(dt=0.2, q_horizontal=np.array([0.01, 0.1, 0.002]), q_vertical=np.array([1e-3, 1e-2, 1e-4]),
                 p0_position=np.array([1.0, 2.0, 0.5]), p0_velocity=np.array([0.5, 0.2, 0.3]),
                 noise_variance=np.array([0.02, 0.5, 0.01]), attitude_variance=np.radians([1.0, 5.0, 0.5]) ** 2,
                 depth_variance=np.array([1e-4, 1e-2, 1e-6]))
    return truth, slot, received, beacons, arms, fixed


def range_variance(position, beacon, arm, noise, attitude):
    return noise + fd_attitude_variance(position, beacon, arm, attitude)


def test_pcrb_equals_a_kalman_filter_covariance_and_tichavsky_information_recursion():
    truth, slot, received, beacons, arms, fixed = case()
    n, b = slot.shape
    bound = pcrb(*pcrb_inputs(truth, slot, received, beacons, arms, **fixed))
    assert slot.sum() > 300 and (slot & ~received).sum() > 50  # depth-only slots and range slots
    for r in range(b):
        f = {k: (v[r] if isinstance(v, np.ndarray) else v) for k, v in fixed.items()}
        F, Q = phi(f["dt"]), white_noise_q(f["dt"], f["q_horizontal"], f["q_vertical"])
        kf = KalmanFilter(dim_x=6, dim_z=1)
        kf.x, kf.F, kf.Q = np.zeros((6, 1)), F, Q
        kf.P = np.diag([f["p0_position"] ** 2, f["p0_velocity"] ** 2] * 3)
        J = np.linalg.inv(kf.P)
        Qi = np.linalg.inv(Q)
        D11, D12 = F.T @ Qi @ F, -F.T @ Qi
        for k in range(n):
            kf.predict()
            info = np.zeros((6, 6))
            if slot[k, r]:
                H = np.array([[0, 0, 0, 0, 1.0, 0]])
                kf.update(np.zeros((1, 1)), R=f["depth_variance"], H=H)
                info += H.T @ H / f["depth_variance"]
                if received[k, r]:
                    H = fd_range_row(truth[k, r], beacons[k, r])
                    var = range_variance(truth[k, r], beacons[k, r], arms[k, r], f["noise_variance"],
                                         f["attitude_variance"])
                    kf.update(np.zeros((1, 1)), R=var, H=H)
                    info += H.T @ H / var
            J = Qi + info - D12.T @ np.linalg.solve(J + D11, D12)
            expected = np.sqrt(kf.P[0, 0] + kf.P[2, 2] + kf.P[4, 4])
            from_information = np.linalg.inv(J)
            assert bound[k, r] == pytest.approx(expected, rel=1e-6), (k, r)
            assert bound[k, r] == pytest.approx(np.sqrt(np.trace(from_information[np.ix_([0, 2, 4], [0, 2, 4])])),
                                                rel=1e-6), (k, r)
    # the bound settles where measurements keep coming, and grows without them
    assert np.all(bound[-1] < bound[0])


def test_bound_without_measurements_is_the_prediction_of_the_prior():
    """No slot at all: the bound is ΦᵏP0Φᵏᵀ + Σ Q, the open-loop covariance (hand-worked for one axis)."""
    n, dt, q, s0, v0 = 50, 0.5, 0.01, 1.0, 0.5
    zeros = np.zeros((n, 1, 3))
    bound = pcrb(*pcrb_inputs(zeros + [10, 0, 5], np.zeros((n, 1), bool), np.zeros((n, 1), bool), zeros, zeros,
                              dt=dt, q_horizontal=q, q_vertical=q, p0_position=s0, p0_velocity=v0,
                              noise_variance=0.01, attitude_variance=0.0, depth_variance=1e-4))
    t = dt * np.arange(1, n + 1)
    per_axis = s0**2 + (v0 * t) ** 2 + q * t**3 / 3.0  # position variance of a constant-velocity walk
    np.testing.assert_allclose(bound[:, 0], np.sqrt(3 * per_axis), rtol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_effective_range_variance_matches_finite_differences_of_a_rotated_arm(seed):
    rng = np.random.default_rng(seed)
    position, beacon, arm = rng.normal(scale=10, size=3), rng.normal(scale=2, size=3), rng.normal(scale=3, size=3)
    value = float(effective_range_variance(position, beacon, arm, 0.03, 2e-4))
    assert value == pytest.approx(0.03 + fd_attitude_variance(position, beacon, arm, 2e-4), rel=1e-7)
    # an arm along the line of sight does not move the range
    along = (position - beacon) / np.linalg.norm(position - beacon)
    assert float(effective_range_variance(position, beacon, 2.0 * along, 0.03, 2e-4)) == pytest.approx(0.03, rel=1e-12)


def test_horizontal_std_hand_worked_and_against_a_numpy_fisher_matrix():
    # the diver at the centre of a level cross at its own depth: J = diag(2/σ², 2/σ², 1/σ_d²), DRMS = σ
    L, sigma2 = 3.0, 0.04
    beacons = np.array([[L, 0, 5.0], [0, L, 5.0], [-L, 0, 5.0], [0, -L, 5.0]])
    drms = horizontal_std(np.array([[0.0, 0.0, 5.0]]), beacons, np.zeros((4, 3)), sigma2, 0.0, 1e-4)
    assert drms[0] == pytest.approx(np.sqrt(sigma2), rel=1e-12)
    # anywhere else, against finite-difference gradients and numpy's inverse
    rng = np.random.default_rng(4)
    beacons = np.array([[L, 0, 1.0], [0, L, 1.0], [-L, 0, 1.0], [0, -L, 1.0]])
    arms = beacons.copy()
    points = np.column_stack([rng.uniform(-30, 30, size=(20, 2)), np.full(20, 5.0)])
    got = horizontal_std(points, beacons, arms, 0.02, np.radians(1.0) ** 2, 1e-4)
    for p, value in zip(points, got):
        J = np.zeros((3, 3))
        for b, a in zip(beacons, arms):
            g = fd_range_row(p, b)[0, [0, 2, 4]]
            J += np.outer(g, g) / range_variance(p, b, a, 0.02, np.radians(1.0) ** 2)
        J[2, 2] += 1e4
        inverse = np.linalg.inv(J)
        assert value == pytest.approx(np.sqrt(inverse[0, 0] + inverse[1, 1]), rel=1e-6)
    # and the Function reports the information matrix itself
    J = np.asarray(fix_information(4)(points[0], beacons.reshape(-1), arms.reshape(-1), 0.02,
                                      np.radians(1.0) ** 2, 1e-4)[0])
    assert np.allclose(J, J.T) and np.all(np.linalg.eigvalsh(J) > 0)


def usbl_h(p, transceiver):
    """Range, azimuth, elevation (numpy): NED, the elevation below the horizontal."""
    d = p - transceiver
    return np.array([np.linalg.norm(d), np.arctan2(d[1], d[0]), np.arctan2(d[2], np.hypot(d[0], d[1]))])


def usbl_information(p, transceiver, variances):
    """Fisher information of range, azimuth, elevation about the position, from the analytic gradients (numpy)."""
    dn, de, dd = p - transceiver
    rho2 = dn**2 + de**2
    rho, r2 = np.sqrt(rho2), rho2 + dd**2
    gradients = (np.array([dn, de, dd]) / np.sqrt(r2),  # ∂r/∂p
                 np.array([-de, dn, 0.0]) / rho2,  # ∂α/∂p, α = atan2(d_E, d_N)
                 np.array([-dd * dn / rho, -dd * de / rho, rho]) / r2)  # ∂ε/∂p, ε = atan2(d_D, ρ)
    return sum(np.outer(g, g) / v for g, v in zip(gradients, variances))


def test_range_bearing_fisher_information_through_the_generic_map_function():
    """The map's Fisher information for a USBL transceiver (range + bearing model) through the same generic function
    as the ranges-plus-depth map, against analytic gradients; its horizontal DRMS grows linearly with the horizontal
    distance at fixed depth (cross-range σ = ρ σ_α exactly; DRMS² = ρ²σ_α² + σ_r² cos²ε + D²σ_ε²)."""
    import casadi as ca

    from sblsim.models.bound import horizontal_drms, model_horizontal_std, position_information
    from sblsim.models.receiver.range_bearing import RangeBearingModel

    model = RangeBearingModel()
    transceiver = np.array([1.0, -2.0, 0.5])
    s_r, s_a, s_e = 0.1, np.radians(0.5), np.radians(0.7)
    variances = np.array([s_r**2, s_a**2, s_e**2])
    rng = np.random.default_rng(7)
    for p in rng.normal(scale=[40, 40, 10], size=(10, 3)) + [0, 0, 20]:
        J = np.array(ca.evalf(position_information(model, p, transceiver, variances)))
        expected = usbl_information(p, transceiver, variances)
        np.testing.assert_allclose(J, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
        # and the finite-difference Jacobian of the numpy measurement
        H = np.zeros((3, 3))
        for k in range(3):
            d = np.zeros(3)
            d[k] = EPS
            H[:, k] = (usbl_h(p + d, transceiver) - usbl_h(p - d, transceiver)) / (2 * EPS)
        np.testing.assert_allclose(J, H.T @ np.diag(1 / variances) @ H, rtol=1e-6)
        inverse = np.linalg.inv(expected)
        assert float(ca.evalf(horizontal_drms(ca.DM(J)))) == pytest.approx(np.sqrt(inverse[0, 0] + inverse[1, 1]),
                                                                           rel=1e-10)
    # along a horizontal line at fixed depth D below the transceiver
    depth = 20.0
    rho = np.linspace(50.0, 2000.0, 40)
    bearing = np.radians(130.0)
    points = transceiver + np.column_stack([rho * np.cos(bearing), rho * np.sin(bearing), np.full(rho.size, depth)])
    drms = model_horizontal_std(model, points, transceiver, variances)
    cos2 = rho**2 / (rho**2 + depth**2)
    np.testing.assert_allclose(drms, np.sqrt((rho * s_a) ** 2 + s_r**2 * cos2 + (depth * s_e) ** 2), rtol=1e-10)
    for p, r in zip(points, rho):  # the cross-range (azimuth) component alone: ρ σ_α
        across = np.array([-np.sin(bearing), np.cos(bearing), 0.0])
        J = np.array(ca.evalf(position_information(model, p, transceiver, variances)))
        assert np.sqrt(across @ np.linalg.solve(J, across)) == pytest.approx(r * s_a, rel=1e-10)
    slope = np.diff(drms) / np.diff(rho)
    np.testing.assert_allclose(slope[rho[1:] > 500], s_a, rtol=1e-2)  # linear: about range · σ_angle
    # straight below the transceiver the azimuth is undefined: no finite fix
    assert np.isinf(model_horizontal_std(model, transceiver + [[0, 0, 10.0]], transceiver, variances)).all()


def usbl_gradients(p, transceiver):
    """∂[r, α, ε]/∂p (3, 3), analytic (numpy)."""
    dn, de, dd = p - transceiver
    rho2 = dn**2 + de**2
    rho, r2 = np.sqrt(rho2), rho2 + dd**2
    return np.array([np.array([dn, de, dd]) / np.sqrt(r2), np.array([-de, dn, 0.0]) / rho2,
                     np.array([-dd * dn / rho, -dd * de / rho, rho]) / r2])


def usbl_case(seed=4, n=200, b=3):
    """Three runs: a diver circling 8-20 m from a transceiver that heaves, one run passing almost under it (the
    angle noise at its floor, cos φ ≥ 0.1 off the vertical, and far off it)."""
    rng = np.random.default_rng(seed)
    t = 0.5 * np.arange(1, n + 1)
    radius = np.array([8.0, 20.0, 3.0])
    depth = np.array([6.0, 2.5, 40.0])  # cos φ ≈ 0.6, ≈ 0.07 (floored at 0.1) and ≈ 1
    truth = np.stack([np.stack([radius[j] * np.cos(0.03 * t + j), radius[j] * np.sin(0.03 * t + j),
                                depth[j] + 0.01 * t], -1) for j in range(b)], axis=1)
    transceivers = rng.normal(scale=0.2, size=(n, b, 3)) + [0, 0, 1.0]
    slot = rng.uniform(size=(n, b)) < 0.8
    received = slot & (rng.uniform(size=(n, b)) < 0.8)
    fixed = dict(dt=0.5, q_horizontal=np.array([0.01, 0.002, 0.05]), q_vertical=np.array([1e-3, 1e-4, 1e-2]),
                 p0_position=np.array([1.0, 2.0, 0.5]), p0_velocity=np.array([0.5, 0.2, 0.3]),
                 range_variance=np.array([0.01, 0.49, 0.01]), position_variance=np.array([0.01, 1.0, 0.0]),
                 angle_sigma_deg=np.array([0.5, 1.0, 0.2]),
                 attitude_variance=np.radians([1.0, 0.0, 0.5]) ** 2, depth_variance=np.array([1e-4, 1e-2, 1e-6]))
    return truth, slot, received, transceivers, fixed


def test_usbl_pcrb_equals_a_kalman_filter_covariance_with_range_azimuth_and_elevation():
    """The USBL bound (models/systems/usbl.py pcrb) against FilterPy's KalmanFilter covariance with the linearized
    range, azimuth and elevation rows at the true position (analytic gradients, numpy) and the variances written
    out here: ``σ_r² + σ_b²``, ``σ_a² + σ_b² / ρ²`` and ``σ_a² + σ_b² / r²``,
    ``σ_a² = (σ_θ / max(cos φ, 0.1))² + σ_att²`` (φ off the vertical) and σ_b² the transceiver position's variance
    per axis (its error seen along the range and across the angles)."""
    from sblsim.models.systems.usbl import pcrb as usbl_pcrb
    from sblsim.models.systems.usbl import pcrb_inputs as usbl_pcrb_inputs

    truth, slot, received, transceivers, fixed = usbl_case()
    n, b = slot.shape
    bound = usbl_pcrb(*usbl_pcrb_inputs(truth, slot, received, transceivers, **fixed))
    floored = 0
    for r in range(b):
        f = {k: v[r] if isinstance(v, np.ndarray) else v for k, v in fixed.items()}
        kf = KalmanFilter(dim_x=6, dim_z=1)
        kf.x, kf.F, kf.Q = np.zeros((6, 1)), phi(f["dt"]), white_noise_q(f["dt"], f["q_horizontal"], f["q_vertical"])
        kf.P = np.diag([f["p0_position"] ** 2, f["p0_velocity"] ** 2] * 3)
        for k in range(n):
            kf.predict()
            if slot[k, r]:
                kf.update(np.zeros((1, 1)), R=f["depth_variance"], H=np.array([[0, 0, 0, 0, 1.0, 0]]))
                if received[k, r]:
                    d = truth[k, r] - transceivers[k, r]
                    cos_phi = d[2] / np.linalg.norm(d)
                    floored += cos_phi < 0.1
                    angle = (np.radians(f["angle_sigma_deg"]) / max(cos_phi, 0.1)) ** 2 + f["attitude_variance"]
                    b2, rho2 = f["position_variance"], d[0] ** 2 + d[1] ** 2
                    H = np.zeros((3, 6))
                    H[:, [0, 2, 4]] = usbl_gradients(truth[k, r], transceivers[k, r])
                    R = np.diag([f["range_variance"] + b2, angle + b2 / rho2, angle + b2 / (rho2 + d[2] ** 2)])
                    kf.update(np.zeros((3, 1)), R=R, H=H)
            assert bound[k, r] == pytest.approx(np.sqrt(kf.P[0, 0] + kf.P[2, 2] + kf.P[4, 4]), rel=1e-7), (k, r)
    assert floored > 50 and received.sum() > 300  # the floor of the angle noise is exercised
    # the angles carry the horizontal position: far below the range-only bound of the same packets
    zeros = np.zeros_like(transceivers)
    ranges = {k: v for k, v in fixed.items() if k not in ("angle_sigma_deg", "range_variance", "position_variance")}
    range_only = pcrb(*pcrb_inputs(truth, slot, received, transceivers, zeros,
                                   noise_variance=fixed["range_variance"] + fixed["position_variance"], **ranges))
    assert np.all(bound[-1] < 0.5 * range_only[-1])


def test_the_compiled_usbl_bound_is_the_reference_one():
    """The USBL interface's library steps the USBL bound in C (what runs use); casadi's virtual machine is the
    reference: equal to round-off on random tracks, packets, losses and transceiver motion."""
    from sblsim.fmus import native
    from sblsim.models.systems.usbl import pcrb as usbl_pcrb
    from sblsim.models.systems.usbl import pcrb_inputs as usbl_pcrb_inputs

    rng = np.random.default_rng(11)
    n, b = 300, 5
    truth = rng.normal(size=(n, b, 3)) * 10.0 + np.array([0.0, 0.0, 5.0])
    transceiver = rng.normal(size=(n, b, 3)) * 0.1 + np.array([0.0, 0.0, 1.0])
    slot = rng.random((n, b)) < 0.5
    received = slot & (rng.random((n, b)) < 0.8)
    fixed, steps = usbl_pcrb_inputs(truth, slot, received, transceiver, dt=0.1, q_horizontal=0.01,
                                    q_vertical=0.001, p0_position=1.0, p0_velocity=np.linspace(0.2, 1.0, b),
                                    range_variance=0.01, position_variance=np.linspace(0.0, 1.0, b),
                                    angle_sigma_deg=0.5, attitude_variance=1e-4,
                                    depth_variance=1e-4)
    reference = usbl_pcrb(fixed, steps)
    np.testing.assert_allclose(native.system_pcrb(1, fixed, steps), reference, rtol=1e-12, atol=0)
    assert np.ptp(reference[-1]) > 0  # the runs differ: each is stepped with its own inputs
