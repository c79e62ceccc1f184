"""Measurement models, motion model, sigma points and gate against independent computations.

* The range + direction model of a USBL (``models/receiver/range_direction.py``): h against numpy and
  hand-worked cases (straight below the transceiver included, and a turned array), its casadi Jacobians
  (state, transceiver, attitude) against central finite differences of the numpy h, finite everywhere, and an
  EKF built from the receivers' own code (the constant-velocity prediction and the whitened sequential
  update with the full R) against FilterPy's ``ExtendedKalmanFilter`` with the same R, on a path that passes
  straight below the transceiver.
* The range + depth model's linearization and its one range-variance formula.
* The sigma points against FilterPy's ``MerweScaledSigmaPoints`` and
  ``JulierSigmaPoints``; the gate threshold against scipy's χ² quantile.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, JulierSigmaPoints, MerweScaledSigmaPoints
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from sblsim.models.receiver import kalman, sigma_points
from sblsim.models.receiver.gate import gate_threshold
from sblsim.models.receiver.measurement import MeasurementModel, RangeDepthModel, wrap_angle
from sblsim.models.receiver.motion import CONSTANT_VELOCITY
from sblsim.models.receiver.range_direction import RangeDirectionModel
from tests.models.test_receiver_filterpy import phi, white_noise_q

POS = [0, 2, 4]
MODEL = RangeDirectionModel()


def np_rotation(attitude):
    """Body to NED of roll, pitch, yaw (ZYX), by scipy's rotations (not our rotation_ned)."""
    roll, pitch, yaw = attitude
    return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()


def np_range_direction(state, b, attitude):
    """Range and the first two direction cosines of the line of sight in the array's frame, in numpy."""
    d = np.asarray(state, float).reshape(-1)[POS] - b
    a = np_rotation(attitude).T @ d / np.linalg.norm(d)
    return np.array([np.linalg.norm(d), a[0], a[1]])


def evaluate(f, *args):
    return [np.array(v) for v in f.call([ca.DM(np.asarray(a, float)) for a in args])]


def model_function(model, method):
    x, b, att = ca.SX.sym("x", 6), ca.SX.sym("b", 3), ca.SX.sym("att", 3)
    out = getattr(model, method)(x, (b, att))
    out = list(out) if isinstance(out, tuple) else [out]
    return ca.Function("f", [x, b, att], out)


def central(f, point, eps=1e-6):
    """Central finite differences of a numpy function at ``point`` (columns per entry)."""
    point = np.asarray(point, float)
    columns = []
    for i in range(point.size):
        e = np.zeros(point.size)
        e[i] = eps
        columns.append((f(point + e) - f(point - e)) / (2 * eps))
    return np.stack(columns, axis=1)


# ----------------------------------------------------------------------------
# range + direction (USBL)
# ----------------------------------------------------------------------------

def test_range_direction_hand_worked_and_against_numpy():
    b, level = np.array([1.0, -2.0, 3.0]), np.zeros(3)
    f = model_function(MODEL, "h")
    # straight below: 10 m, the direction cosines across the array 0 (no azimuth needed, none undefined)
    (h,) = evaluate(f, [1.0, 0, -2.0, 0, 13.0, 0], b, level)
    np.testing.assert_allclose(h.ravel(), [10.0, 0.0, 0.0], atol=1e-15)
    # 10 m East and 10 m deeper, a level array: a = (0, 1/√2); the array turned to heading East (yaw π/2):
    # its x axis points East, so a = (1/√2, 0)
    (h,) = evaluate(f, [1.0, 0, 8.0, 0, 13.0, 0], b, level)
    np.testing.assert_allclose(h.ravel(), [10 * math.sqrt(2), 0.0, 1 / math.sqrt(2)], atol=1e-15)
    (h,) = evaluate(f, [1.0, 0, 8.0, 0, 13.0, 0], b, [0.0, 0.0, math.pi / 2])
    np.testing.assert_allclose(h.ravel(), [10 * math.sqrt(2), 1 / math.sqrt(2), 0.0], atol=1e-15)
    rng = np.random.default_rng(1)
    for _ in range(20):
        state, b, att = rng.normal(scale=10, size=6), rng.normal(scale=3, size=3), rng.normal(scale=0.3, size=3)
        np.testing.assert_allclose(evaluate(f, state, b, att)[0].ravel(), np_range_direction(state, b, att),
                                   rtol=1e-13, atol=1e-15)
    assert MODEL.dimension((b, level)) == 3 and MODEL.state_size == 6 and MODEL.angles == ()


@pytest.mark.parametrize("seed", range(5))
def test_range_direction_jacobians_match_finite_differences_straight_below_too(seed):
    rng = np.random.default_rng(seed)
    state, b, att = rng.normal(scale=10, size=6), rng.normal(scale=3, size=3), rng.normal(scale=0.2, size=3)
    if seed == 0:  # straight below the transceiver, where an azimuth has no derivative
        state[POS] = b + [0.0, 0.0, 500.0]
    x, bs, a = ca.SX.sym("x", 6), ca.SX.sym("b", 3), ca.SX.sym("att", 3)
    ctx = (bs, a)
    f = ca.Function("f", [x, bs, a], [*MODEL.linearize(x, ctx), MODEL.transceiver_jacobian(x, ctx),
                                      MODEL.attitude_jacobian(x, ctx)])
    h, H, H_b, H_a = evaluate(f, state, b, att)
    assert np.all(np.isfinite(H)) and np.all(np.isfinite(H_b)) and np.all(np.isfinite(H_a))
    np.testing.assert_allclose(H, central(lambda s: np_range_direction(s, b, att), state), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(H_b, central(lambda c: np_range_direction(state, c, att), b), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(H_a, central(lambda c: np_range_direction(state, b, c), att), rtol=1e-6, atol=1e-9)
    assert np.all(H[:, [1, 3, 5]] == 0.0) and np.all(H_a[0] == 0.0)  # velocities do not enter; nor the attitude
    # the base class's generic linearization (casadi's derivative of h) gives the same
    g_h, g_H = MeasurementModel.linearize(MODEL, x, ctx)
    got = evaluate(ca.Function("g", [x, bs, a], [g_h, g_H]), state, b, att)
    np.testing.assert_allclose(got[0], h, rtol=1e-15)
    np.testing.assert_allclose(got[1], H, rtol=1e-13, atol=1e-16)


def test_range_direction_covariance_is_the_noise_chain_through_its_jacobians():
    """R = diag(σ_r², σ_u², σ_u²) + σ_b² H_b H_bᵀ + σ_θ² H_θ H_θᵀ, with the Jacobians by finite differences."""
    rng = np.random.default_rng(4)
    state, b, att = rng.normal(scale=20, size=6), rng.normal(size=3), rng.normal(scale=0.1, size=3)
    x, bs, a = ca.SX.sym("x", 6), ca.SX.sym("b", 3), ca.SX.sym("att", 3)
    f = ca.Function("R", [x, bs, a], [MODEL.covariance(x, (bs, a), 0.04, 1e-4, 0.09, 3e-4)])
    (R,) = evaluate(f, state, b, att)
    H_b = central(lambda c: np_range_direction(state, c, att), b)
    H_a = central(lambda c: np_range_direction(state, b, c), att)
    expected = np.diag([0.04, 1e-4, 1e-4]) + 0.09 * H_b @ H_b.T + 3e-4 * H_a @ H_a.T
    np.testing.assert_allclose(R, expected, rtol=1e-7, atol=1e-10)
    assert np.all(np.linalg.eigvalsh(R) > 0)


def path_case(n=80, dt=1.0, seed=2):
    """The diver crosses below a transceiver 40 m deep, from 8 m North to 8 m South, under a gently rolling array
    (its attitude known), measured with the array's noise on each direction cosine and a range noise."""
    rng = np.random.default_rng(seed)
    b = np.array([0.5, -0.3, 1.0])
    t = dt * np.arange(1, n + 1)
    truth = np.stack([8.0 - 0.2 * t, -0.3 + 0.5 * np.sin(0.1 * t), 41.0 + 0.01 * t], axis=1)
    attitude = np.stack([0.05 * np.sin(0.7 * t), 0.04 * np.cos(0.5 * t), 0.3 + 0.01 * t], axis=1)
    sigma = np.array([0.1, 0.01, 0.01])
    z = np.array([np_range_direction(np.array([p[0], 0, p[1], 0, p[2], 0]), b, a) for p, a in zip(truth, attitude)])
    return b, truth, attitude, z + rng.normal(size=z.shape) * sigma, sigma, dt


def ekf_step_function():
    """One prediction and one range-direction update with a full R, from the receivers' code, as a Function."""
    x, P, z, b, att = ca.SX.sym("x", 6), ca.SX.sym("P", 6, 6), ca.SX.sym("z", 3), ca.SX.sym("b", 3), ca.SX.sym("a", 3)
    dt, qh, qv, sr, su, sb = (ca.SX.sym(n) for n in ("dt", "qh", "qv", "sr", "su", "sb"))
    x1, P1 = CONSTANT_VELOCITY.predict(x, P, dt, qh, qv)
    R = MODEL.covariance(x1, (b, att), sr ** 2, su ** 2, sb ** 2, 0.0)
    h, H = MODEL.linearize(x1, (b, att))
    y, Hw = kalman.whiten(z - h, H, R)
    x2, P2, nis = kalman.update(x1, P1, y, Hw, ca.SX.ones(3))
    return ca.Function("ekf_step", [x, P, z, b, att, dt, qh, qv, sr, su, sb], [x2, P2, nis, R])


def test_ekf_over_range_direction_equals_filterpy_straight_below_the_transceiver():
    b, truth, attitude, z, sigma, dt = path_case()
    qh, qv, sb = 0.05, 0.005, 0.2
    x0 = np.array([truth[0, 0], 0.0, truth[0, 1] + 0.5, 0.0, truth[0, 2], 0.0])
    P0 = np.diag([1.0, 0.25] * 3)
    step = ekf_step_function()
    ekf = ExtendedKalmanFilter(dim_x=6, dim_z=3)
    ekf.x, ekf.P = x0.reshape(-1, 1).copy(), P0.copy()
    ekf.F, ekf.Q = phi(dt), white_noise_q(dt, qh, qv)
    x, P = x0, P0
    for k, (zk, att) in enumerate(zip(z, attitude)):
        x, P, nis, R = (np.array(v) for v in step(x, P, zk, b, att, dt, qh, qv, *sigma[:2], sb))
        x = x.ravel()
        ekf.predict()
        ekf.update(zk.reshape(-1, 1), lambda s, a=att: central(lambda c: np_range_direction(c, b, a), s.ravel()),
                   lambda s, a=att: np_range_direction(s, b, a).reshape(-1, 1), R=R)
        np.testing.assert_allclose(x, ekf.x.ravel(), rtol=0, atol=1e-6, err_msg=f"step {k}")
        np.testing.assert_allclose(P, ekf.P, rtol=1e-5, atol=1e-9, err_msg=f"step {k}")
        assert nis.item() == pytest.approx((ekf.y.T @ ekf.SI @ ekf.y).item(), rel=1e-5, abs=1e-9), k
    # the path passes within a metre of the vertical, and the filter tracks the diver there and after
    horizontal = np.hypot(truth[:, 0] - b[0], truth[:, 1] - b[1])
    assert horizontal.min() < 1.0
    assert np.linalg.norm(x[POS] - truth[-1]) < 1.0


def test_residual_wraps_the_rows_that_are_angles():
    """A model with angle rows (``angles``) wraps them to (−π, π]; the range + direction model has none."""
    class Bearing(MeasurementModel):
        angles = (1,)

    z, h = ca.SX.sym("z", 2), ca.SX.sym("h", 2)
    f = ca.Function("r", [z, h], [Bearing().residual(z, h)])
    (y,) = evaluate(f, [5.0, math.pi - 0.01], [4.0, -math.pi + 0.01])
    np.testing.assert_allclose(y.ravel(), [1.0, -0.02], atol=1e-14)
    (y,) = evaluate(f, [10.0, 0.0], [3.0, 0.0])
    assert y[0, 0] == 7.0  # a range difference is not an angle: never wrapped
    # the interval is (−π, π]: π stays, −π becomes π, 3π is π, −3π/2 is π/2
    a = ca.SX.sym("a")
    w = ca.Function("w", [a], [wrap_angle(a)])
    for value, expected in [(math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi, math.pi),
                            (-1.5 * math.pi, 0.5 * math.pi), (0.3, 0.3), (-0.3, -0.3)]:
        assert float(w(value)) == pytest.approx(expected, abs=1e-14)
    # the range + depth and range + direction models have no angles: their residual is z − h as is
    for m in (RangeDepthModel(), MODEL):
        z3, h3 = ca.SX.sym("z", 3), ca.SX.sym("h", 3)
        assert float(ca.Function("d", [z3, h3], [m.residual(z3, h3)])([10, 0, 0], [3, 0, 0])[0]) == 7.0


# ----------------------------------------------------------------------------
# range + depth: linearization and the range variance
# ----------------------------------------------------------------------------

def test_range_depth_linearize_equals_h_and_jacobian_and_the_generic_derivative():
    m = RangeDepthModel()
    rng = np.random.default_rng(5)
    state, beacons = rng.normal(scale=10, size=6), rng.normal(scale=3, size=(3, 3))
    x = ca.SX.sym("x", 6)
    bs = [ca.SX.sym(f"b{i}", 3) for i in range(3)]
    h, H = m.linearize(x, bs)
    g_h, g_H = MeasurementModel.linearize(m, x, bs)
    f = ca.Function("f", [x, *bs], [h, H, m.h(x, bs), m.jacobian(x, bs), g_h, g_H])
    out = [np.array(v) for v in f(state, *beacons)]
    expected_h = np.append(np.linalg.norm(state[POS] - beacons, axis=1), state[4])
    np.testing.assert_allclose(out[0].ravel(), expected_h, rtol=1e-15)
    d = state[POS] - beacons
    expected_H = np.zeros((4, 6))
    expected_H[:3][:, POS] = d / np.linalg.norm(d, axis=1)[:, None]
    expected_H[3, 4] = 1.0
    for got in (out[1], out[3], out[5]):
        np.testing.assert_allclose(got, expected_H, rtol=1e-14, atol=1e-16)
    np.testing.assert_array_equal(out[2], out[0])
    assert m.dimension(bs) == 4


def test_range_variance_isotropic_and_attitude_terms():
    """The one formula: σ² + σ_b² ‖g‖² + σ_θ² ‖a × g‖², g the unit line of sight, against numpy."""
    rng = np.random.default_rng(7)
    position, beacon, arm = rng.normal(scale=10, size=3), rng.normal(scale=2, size=3), rng.normal(scale=3, size=3)
    g = (beacon - position) / np.linalg.norm(beacon - position)  # ∂‖p − b‖/∂b
    m = RangeDepthModel
    assert float(m.range_variance(position, beacon, 0.01)) == 0.01
    assert float(m.range_variance(position, beacon, 0.01, 0.04)) == pytest.approx(0.05, rel=1e-14)
    both = float(m.range_variance(position, beacon, 0.01, 0.04, 3e-4, arm))
    assert both == pytest.approx(0.05 + 3e-4 * np.sum(np.cross(arm, g) ** 2), rel=1e-13)
    with pytest.raises(ValueError, match="lever arm"):
        m.range_variance(position, beacon, 0.01, attitude_variance=1e-4)
    # the receivers' parameters: σ_GPS² + (σ_att arm)² per axis, σ_att in degrees
    p = {"sigma_range": 0.1, "beacon_gps_sigma": 0.2, "beacon_attitude_sigma_deg": 2.0, "beacon_arm": 1.5}
    state = np.array([position[0], 0, position[1], 0, position[2], 0])
    value = float(RangeDepthModel().fresh_range_variance(state, beacon, p))
    assert value == pytest.approx(0.01 + 0.04 + (np.radians(2.0) * 1.5) ** 2, rel=1e-13)


# ----------------------------------------------------------------------------
# sigma points and gate threshold
# ----------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["merwe", "julier"])
def test_sigma_points_and_weights_equal_filterpy(kind):
    rng = np.random.default_rng(9)
    n = 6
    A = rng.normal(size=(n, n))
    P, x = A @ A.T / n + 0.5 * np.eye(n), rng.normal(size=n)
    if kind == "merwe":
        ours, ref = sigma_points.MerweScaledSigmaPoints(n, 0.5, 2.0, 1.0), MerweScaledSigmaPoints(n, 0.5, 2.0, 1.0)
    else:
        ours, ref = sigma_points.JulierSigmaPoints(n, 3.0 - n), JulierSigmaPoints(n, 3.0 - n)
    wm, wc = (np.array(ca.DM(w)).ravel() for w in ours.weights())
    np.testing.assert_allclose(wm, ref.Wm, rtol=1e-14)
    np.testing.assert_allclose(wc, ref.Wc, rtol=1e-14)
    s = ca.SX.sym("x", n)
    S = ca.SX.sym("P", n, n)
    pts = np.array(ca.Function("s", [s, S], [ca.horzcat(*ours.points(s, S))])(x, P)).T
    np.testing.assert_allclose(pts, ref.sigma_points(x, P), rtol=1e-12, atol=1e-14)
    assert ours.count == pts.shape[0] == 2 * n + 1
    with pytest.raises(ValueError, match="6 states"):
        ours.points(ca.SX.sym("y", 3), ca.SX.sym("Q", 3, 3))


@pytest.mark.parametrize("probability", [0.9, 0.99, 0.999])
def test_gate_threshold_is_the_chi_square_quantile(probability):
    assert float(gate_threshold(probability)) == pytest.approx(chi2.ppf(probability, 1), rel=1e-12)
    assert math.isinf(float(gate_threshold(1.0)))


def test_models_refuse_a_state_layout_they_cannot_read():
    class PositionOnly:  # a motion model of three positions, no velocities
        state_names, state_size, position_index = ("x", "y", "z"), 3, (0, 1, 2)

        @staticmethod
        def position(x):
            return x

    class Planar:
        state_names, state_size, position_index = ("x", "y"), 2, (0, 1)

    with pytest.raises(ValueError, match="RangeDepthModel"):
        RangeDepthModel(PositionOnly())
    with pytest.raises(ValueError, match="3 entries"):
        RangeDirectionModel(Planar())
    # the range + direction model reads any layout with a 3-D position
    m = RangeDirectionModel(PositionOnly())
    s, b, a = ca.SX.sym("x", 3), ca.SX.sym("b", 3), ca.SX.sym("a", 3)
    h, H = (np.array(v) for v in ca.Function("f", [s, b, a], list(m.linearize(s, (b, a))))(
        [3.0, 4.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]))
    np.testing.assert_allclose(h.ravel(), [5.0, 0.6, 0.8], rtol=1e-15)
    assert H.shape == (3, 3) and m.state_size == 3
