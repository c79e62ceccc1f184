"""Measurement models, motion model, sigma points and gate against independent computations.

* The range + bearing model (``models/receiver/range_bearing.py``): h against
  numpy and a hand-worked case, its casadi Jacobian against central finite
  differences of the numpy h, the residual's wrap at ±π, and an EKF built
  from the receivers' own code (``kalman.ekf_update`` with this model and the
  constant-velocity prediction) against FilterPy's ``ExtendedKalmanFilter``
  (``HJacobian``, ``Hx``, ``residual=``) on the same measurements, on a path
  that crosses the azimuth's ±π branch.
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
from scipy.stats import chi2

from sblsim.models.receiver import kalman, sigma_points
from sblsim.models.receiver.gate import gate_threshold
from sblsim.models.receiver.measurement import MeasurementModel, RangeDepthModel, wrap_angle
from sblsim.models.receiver.motion import CONSTANT_VELOCITY
from sblsim.models.receiver.range_bearing import RangeBearingModel
from tests.models.test_receiver_filterpy import phi, white_noise_q

POS = [0, 2, 4]
MODEL = RangeBearingModel()


def np_range_bearing(state, b):
    """Range, azimuth atan2(E, N), elevation below the horizontal, written out in numpy."""
    d = np.asarray(state, float).reshape(-1)[POS] - b
    return np.array([np.linalg.norm(d), np.arctan2(d[1], d[0]), np.arctan2(d[2], np.hypot(d[0], d[1]))])


def np_wrap(a):
    """To (−π, π], by a route of its own (numpy remainder, then the −π end moved to π)."""
    w = np.remainder(np.asarray(a, float) + np.pi, 2 * np.pi) - np.pi
    return np.where(w <= -np.pi, w + 2 * np.pi, w)


def np_jacobian(state, b):
    """Analytic ∂h/∂x of range, azimuth, elevation (3, 6), derived by hand."""
    d = np.asarray(state, float).reshape(-1)[POS] - b
    n, e, z = d
    rho2 = n * n + e * e
    rho, r = np.sqrt(rho2), np.linalg.norm(d)
    H = np.zeros((3, 6))
    H[0, POS] = d / r
    H[1, POS] = [-e / rho2, n / rho2, 0.0]
    H[2, POS] = [-n * z / (rho * r * r), -e * z / (rho * r * r), rho / (r * r)]
    return H


def evaluate(f, *args):
    return [np.array(v) for v in f.call([ca.DM(np.asarray(a, float)) for a in args])]


def model_function(model, method):
    x, b = ca.SX.sym("x", 6), ca.SX.sym("b", 3)
    out = getattr(model, method)(x, b)
    out = list(out) if isinstance(out, tuple) else [out]
    return ca.Function("f", [x, b], out)


# ----------------------------------------------------------------------------
# range + bearing
# ----------------------------------------------------------------------------

def test_range_bearing_hand_worked_and_against_numpy():
    b = np.array([1.0, -2.0, 3.0])
    # 10 m East and 10 m deeper: r = 10√2, azimuth π/2 (East), elevation π/4 below the horizontal
    (h,) = evaluate(model_function(MODEL, "h"), [1.0, 0, 8.0, 0, 13.0, 0], b)
    np.testing.assert_allclose(h.ravel(), [10 * math.sqrt(2), math.pi / 2, math.pi / 4], rtol=1e-15)
    # due South and shallower: azimuth π, elevation negative
    (h,) = evaluate(model_function(MODEL, "h"), [-3.0, 0, -2.0, 0, 0.0, 0], b)
    np.testing.assert_allclose(h.ravel(), [5.0, math.pi, -math.atan2(3, 4)], rtol=1e-15)
    rng = np.random.default_rng(1)
    f = model_function(MODEL, "h")
    for _ in range(20):
        state, b = rng.normal(scale=10, size=6), rng.normal(scale=3, size=3)
        np.testing.assert_allclose(evaluate(f, state, b)[0].ravel(), np_range_bearing(state, b), rtol=1e-14)
    assert MODEL.dimension(b) == 3 and MODEL.state_size == 6


@pytest.mark.parametrize("seed", range(5))
def test_range_bearing_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    state, b = rng.normal(scale=10, size=6), rng.normal(scale=3, size=3)
    f = model_function(MODEL, "linearize")
    h, H = evaluate(f, state, b)
    eps = 1e-6
    fd = np.zeros((3, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = eps
        fd[:, i] = np_wrap(np_range_bearing(state + e, b) - np_range_bearing(state - e, b)) / (2 * eps)
    np.testing.assert_allclose(H, fd, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(H, np_jacobian(state, b), rtol=1e-12, atol=1e-15)
    assert np.all(H[:, [1, 3, 5]] == 0.0)  # velocities do not enter
    # the base class's generic linearization (casadi's derivative of h) gives the same
    generic = model_function(MODEL, "h")
    s, c = ca.SX.sym("x", 6), ca.SX.sym("b", 3)
    g_h, g_H = MeasurementModel.linearize(MODEL, s, c)
    got = evaluate(ca.Function("g", [s, c], [g_h, g_H]), state, b)
    np.testing.assert_allclose(got[0], evaluate(generic, state, b)[0], rtol=1e-15)
    np.testing.assert_allclose(got[1], H, rtol=1e-14, atol=1e-16)


def test_residual_wraps_angles_at_pi_and_leaves_the_range():
    z, h = ca.SX.sym("z", 3), ca.SX.sym("h", 3)
    f = ca.Function("r", [z, h], [MODEL.residual(z, h)])
    (y,) = evaluate(f, [5.0, math.pi - 0.01, 0.1], [4.0, -math.pi + 0.01, 0.2])
    np.testing.assert_allclose(y.ravel(), [1.0, -0.02, -0.1], atol=1e-14)
    (y,) = evaluate(f, [5.0, -math.pi + 0.01, 0.0], [4.0, math.pi - 0.01, 0.0])
    np.testing.assert_allclose(y.ravel(), [1.0, 0.02, 0.0], atol=1e-14)
    # a range difference of 7 m is not an angle: never wrapped
    (y,) = evaluate(f, [10.0, 0.0, 0.0], [3.0, 0.0, 0.0])
    assert y[0, 0] == 7.0
    # the interval is (−π, π]: π stays, −π becomes π, 3π is π, −3π/2 is π/2
    a = ca.SX.sym("a")
    w = ca.Function("w", [a], [wrap_angle(a)])
    for value, expected in [(math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi, math.pi),
                            (-1.5 * math.pi, 0.5 * math.pi), (0.3, 0.3), (-0.3, -0.3)]:
        assert float(w(value)) == pytest.approx(expected, abs=1e-14)
        assert float(np_wrap(value)) == pytest.approx(expected, abs=1e-14)
    # the range + depth model has no angles: its residual is z − h as is
    r = RangeDepthModel()
    assert r.angles == () and float(ca.Function("d", [z, h], [r.residual(z, h)])([10, 0, 0], [3, 0, 0])[0]) == 7.0


def path_case(n=80, dt=1.0, seed=2):
    """The diver sways East and West 12 m South of a transceiver, 6 m deeper: its azimuth crosses ±π (due South)
    again and again."""
    rng = np.random.default_rng(seed)
    b = np.array([0.5, -0.3, 1.0])
    t = dt * np.arange(1, n + 1)
    truth = np.stack([-12.0 + 0.1 * np.sin(0.2 * t), -0.3 + 1.5 * np.sin(0.2 * t), 7.0 + 0.02 * t], axis=1)
    sigma = np.array([0.1, np.radians(1.0), np.radians(1.5)])
    z = np.array([np_range_bearing(np.array([p[0], 0, p[1], 0, p[2], 0]), b) for p in truth])
    z = z + rng.normal(size=z.shape) * sigma
    z[:, 1:] = np_wrap(z[:, 1:])
    return b, truth, z, sigma, dt


def ekf_step_function():
    """One prediction and one range-bearing update, from the receivers' code, as a casadi Function."""
    x, P, z, b = ca.SX.sym("x", 6), ca.SX.sym("P", 6, 6), ca.SX.sym("z", 3), ca.SX.sym("b", 3)
    dt, qh, qv, sr, sa, se = (ca.SX.sym(n) for n in ("dt", "qh", "qv", "sr", "sa", "se"))
    x1, P1 = CONSTANT_VELOCITY.predict(x, P, dt, qh, qv)
    p = {"sigma_range": sr, "sigma_azimuth": sa, "sigma_elevation": se}
    x2, P2, nis = kalman.ekf_update(x1, P1, z, MODEL, b, MODEL.variances(x1, b, p))
    return ca.Function("ekf_step", [x, P, z, b, dt, qh, qv, sr, sa, se], [x2, P2, nis])


def filterpy_ekf(b, z, sigma, dt, qh, qv, x0, P0, residual):
    ekf = ExtendedKalmanFilter(dim_x=6, dim_z=3)
    ekf.x, ekf.P = x0.reshape(-1, 1).copy(), P0.copy()
    ekf.F, ekf.Q = phi(dt), white_noise_q(dt, qh, qv)
    out = []
    for zk in z:
        ekf.predict()
        ekf.update(zk.reshape(-1, 1), lambda x: np_jacobian(x, b), lambda x: np_range_bearing(x, b).reshape(-1, 1),
                   R=np.diag(sigma**2), residual=residual)
        out.append((ekf.x.ravel().copy(), ekf.P.copy(), (ekf.y.T @ ekf.SI @ ekf.y).item()))
    return out


def test_ekf_over_range_bearing_equals_filterpy_across_the_azimuth_branch():
    b, truth, z, sigma, dt = path_case()
    qh, qv = 0.05, 0.005
    x0 = np.array([truth[0, 0], 0.0, truth[0, 1] + 0.5, 0.3, truth[0, 2], 0.0])
    P0 = np.diag([1.0, 0.25] * 3)

    def wrapped(a, c):
        y = a - c
        y[1:] = np_wrap(y[1:])
        return y

    reference = filterpy_ekf(b, z, sigma, dt, qh, qv, x0, P0, wrapped)
    step = ekf_step_function()
    x, P = x0, P0
    raw_jumps = 0
    for k, (zk, (x_ref, P_ref, nis_ref)) in enumerate(zip(z, reference)):
        predicted = phi(dt) @ x
        raw_jumps += abs(zk[1] - np_range_bearing(predicted, b)[1]) > np.pi
        x, P, nis = (np.array(v) for v in step(x, P, zk, b, dt, qh, qv, *sigma))
        x = x.ravel()
        np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-9, err_msg=f"step {k}")
        np.testing.assert_allclose(P, P_ref, rtol=1e-9, atol=1e-12, err_msg=f"step {k}")
        assert nis.item() == pytest.approx(nis_ref, rel=1e-8, abs=1e-12), k
    # the path crosses the branch (raw azimuth residuals near 2π), and the filter tracks the diver
    assert raw_jumps >= 3
    assert np.linalg.norm(x[POS] - truth[-1]) < 1.0
    # without the wrap the same filter goes wrong: the residual matters
    unwrapped = filterpy_ekf(b, z, sigma, dt, qh, qv, x0, P0, np.subtract)
    assert max(np.linalg.norm(u[0][POS] - p) for u, p in zip(unwrapped, truth)) > 10.0


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

    class Planar:
        state_names, state_size, position_index = ("x", "y"), 2, (0, 1)

    with pytest.raises(ValueError, match="RangeDepthModel"):
        RangeDepthModel(PositionOnly())
    with pytest.raises(ValueError, match="3 entries"):
        RangeBearingModel(Planar())
    # the range + bearing model reads any layout with a 3-D position
    m = RangeBearingModel(PositionOnly())
    s, b = ca.SX.sym("x", 3), ca.SX.sym("b", 3)
    h, H = (np.array(v) for v in ca.Function("f", [s, b], list(m.linearize(s, b)))([3.0, 4.0, 0.0], [0.0, 0.0, 0.0]))
    np.testing.assert_allclose(h.ravel(), [5.0, math.atan2(4, 3), 0.0], rtol=1e-15)
    assert H.shape == (3, 3) and m.state_size == 3
