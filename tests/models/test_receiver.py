"""Tests of the EKF receiver: casadi range model, EKF expressions, multilateration, compiled receiver.

The casadi expressions (:mod:`sblsim.models.receiver.measurement`, ``ekf``,
``multilateration``) are evaluated directly through casadi Functions; the
compiled receiver is stepped through :class:`tests.helpers.Core`. Every
reference is computed independently in this file: central finite
differences, a textbook numpy EKF (explicit inverse of S, only the available
rows), numpy's Cholesky and solvers, a numpy Levenberg-Marquardt,
``scipy.optimize.least_squares`` and hand-worked geometry.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import least_squares

from sblsim.models.receiver import PaperEKF, ekf, kalman, position_range_function, range_function
from sblsim.models.receiver import multilateration as ml
from sblsim.models.receiver.motion import CONSTANT_VELOCITY
from tests.helpers import Core

POS = [0, 2, 4]  # position entries of the state [x, vx, y, vy, z, vz]
STATE = ("x", "vx", "y", "vy", "z", "vz")


# ----------------------------------------------------------------------------
# Independent references and helpers
# ----------------------------------------------------------------------------

def casadi_function(builder, *shapes):
    """A casadi Function of ``builder(*SX symbols)`` (a tuple of outputs or one output)."""
    syms = [ca.SX.sym(f"a{k}", *shape) for k, shape in enumerate(shapes)]
    out = builder(*syms)
    out = list(out) if isinstance(out, (tuple, list)) else [out]
    return ca.Function("under_test", syms, [ca.densify(ca.SX(o)) for o in out])


def evaluate(f, *args):
    return [np.array(v) for v in f.call([ca.DM(np.asarray(a, float)) for a in args])]


def np_range(state, beacon):
    return float(np.linalg.norm(np.asarray(state)[POS] - beacon))


def ref_phi(dt):
    phi = np.eye(6)
    for a in range(3):
        phi[2 * a, 2 * a + 1] = dt
    return phi


def ref_q(dt, qh, qv):
    q = np.zeros((6, 6))
    for a, dens in enumerate((qh, qh, qv)):
        q[2 * a:2 * a + 2, 2 * a:2 * a + 2] = dens * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return q


def ref_update(x, P, ranges, beacons, depth, sr, sd):
    """Textbook EKF update with only the available ranges (NaN: no row at all) and the depth.

    Returns x, P (Joseph form) and the NIS ``yᵀ S⁻¹ y`` (explicit inverse).
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
    rows.append(np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0]))
    z.append(depth)
    hx.append(x[4])
    rvar.append(sd**2)
    H, R = np.array(rows), np.diag(rvar)
    y = np.array(z) - np.array(hx)
    S = H @ P @ H.T + R
    Sinv = np.linalg.inv(S)
    K = P @ H.T @ Sinv
    A = np.eye(6) - K @ H
    return x + K @ y, A @ P @ A.T + K @ R @ K.T, float(y @ Sinv @ y)


def cross(L=1.0, h=1.0):
    """The 4 cross beacons L(cos θ, sin θ, 0) + (0, 0, h), θ = 0, 90, 180, 270 deg."""
    return np.array([[L, 0.0, h], [0.0, L, h], [-L, 0.0, h], [0.0, -L, h]])


def random_spd(rng, n=6, scale=1.0):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T / n + 0.5 * np.eye(n))


def np_cost(p, ranges, beacons, heard, depth, wr, wd):
    """F(p) = Σ_heard w_r (r_i − ‖p − b_i‖)² + w_d (d − p_z)², written out in numpy."""
    total = 0.0
    for r, b, k in zip(ranges, beacons, heard):
        if k:
            total += wr * (r - np.linalg.norm(p - b)) ** 2
    return total + wd * (depth - p[2]) ** 2


def fd_residual_jacobian(p, ranges, beacons, heard, depth, wr, wd, eps=1e-6):
    """Jacobian of the weighted residuals sqrt(w)(‖p − b_i‖, p_z) by central differences, (m, 3)."""
    def model(q):
        return np.append([np.sqrt(wr) * np.linalg.norm(q - b) for b, k in zip(beacons, heard) if k], np.sqrt(wd) * q[2])
    J = np.empty((int(np.sum(heard)) + 1, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = eps
        J[:, k] = (model(p + e) - model(p - e)) / (2 * eps)
    return J


def weighted_residuals(p, ranges, beacons, depth, sr, sd):
    """(r_i − ‖p − b_i‖)/σ_r for the finite ranges, then (d − p_z)/σ_d."""
    have = np.isfinite(ranges)
    rho = np.linalg.norm(p[None, :] - beacons[have], axis=1)
    return np.append((ranges[have] - rho) / sr, (depth - p[2]) / sd)


def scipy_fix(ranges, beacons, depth, sr, sd, start):
    return least_squares(weighted_residuals, start, args=(ranges, beacons, depth, sr, sd), method="lm",
                         xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=10000).x


def packet(seq, beacon_id, tx_time, range_value, beacon, depth, valid=True, rx_time=None):
    """Receiver inputs of one packet (arriving at ``rx_time``, default its ``tx_time``); values are scalars or
    arrays of shape (B,)."""
    beacon = np.asarray(beacon, dtype=float)
    return dict(packet_seq=seq, beacon_id=beacon_id, packet_valid=valid, tx_time=tx_time, range=range_value,
                beacon_x=beacon[..., 0], beacon_y=beacon[..., 1], beacon_z=beacon[..., 2], depth=depth,
                rx_time=tx_time if rx_time is None else rx_time)


def est(out):
    """The (B, 6) estimated state from the outputs, in state order."""
    return np.column_stack([out[f"est_{n}"] for n in STATE])


def instr(out):
    return np.column_stack([out[f"instr_{a}"] for a in "xyz"])


def check_estimate(core, b, x_ref, updated, rtol=1e-9, atol=1e-9, err_msg=""):
    """Replicate b: the filter's state is the reference ``x_ref``; its estimate output is that state from the
    receiver's first update on (``updated``: a received packet of the array, taken), and NaN before it (no
    estimate: the prior x0 is not one)."""
    np.testing.assert_allclose(core.state["x"][b], x_ref, rtol=rtol, atol=atol, err_msg=err_msg)
    if updated:
        np.testing.assert_allclose(est(core.outputs)[b], x_ref, rtol=rtol, atol=atol, err_msg=err_msg)
    else:
        assert np.isnan(est(core.outputs)[b]).all(), err_msg


def covariance(core, b=0):
    """The receiver's 6 × 6 covariance of replicate b (the state block is column-major)."""
    return core.state["P"][b].reshape(6, 6, order="F")


# ----------------------------------------------------------------------------
# casadi range model
# ----------------------------------------------------------------------------

def test_range_function_matches_numpy_and_central_differences():
    rng = np.random.default_rng(12345)
    f, fp = range_function(), position_range_function()
    eps = 1e-6
    for _ in range(20):
        state = rng.normal(scale=10.0, size=6)
        beacon = rng.normal(scale=3.0, size=3)
        h, H = (np.array(v).ravel() for v in f(state, beacon))
        assert h[0] == pytest.approx(np.linalg.norm(state[POS] - beacon), rel=1e-14)
        fd = np.array([(np_range(state + e, beacon) - np_range(state - e, beacon)) / (2 * eps)
                       for e in np.eye(6) * eps])
        np.testing.assert_allclose(H, fd, atol=1e-8, rtol=0)
        assert np.all(H[[1, 3, 5]] == 0.0)  # velocities do not enter a range
        assert np.linalg.norm(H[POS]) == pytest.approx(1.0, abs=1e-14)
        # the position form is the same model in position coordinates
        hp, Hp = (np.array(v).ravel() for v in fp(state[POS], beacon))
        assert hp[0] == h[0]
        np.testing.assert_array_equal(Hp, H[POS])


def test_range_function_hand_worked_and_batched_without_mixing():
    """A 3-4-5 triangle and a vertical range; two replicates through casadi's map keep their beacons."""
    states = np.array([[3.0, 9.0, 4.0, 9.0, 0.0, 9.0], [0.0, 0.0, 0.0, 0.0, 12.0, 0.0]]).T
    beacons = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 7.0]]).T
    h, H = (np.array(v) for v in range_function().map(2)(states, beacons))
    np.testing.assert_allclose(h, [[5.0, 5.0]], rtol=1e-15)
    np.testing.assert_allclose(H[:, 0], [0.6, 0, 0.8, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(H[:, 1], [0, 0, 0, 0, 1.0, 0], atol=1e-15)


# ----------------------------------------------------------------------------
# EKF expressions
# ----------------------------------------------------------------------------

EKF_PARAMS = dict(q_horizontal=0.03, q_vertical=0.004, sigma_range=0.15, sigma_depth=0.02)


def _ekf_case(seed=7):
    rng = np.random.default_rng(seed)
    x0 = np.array([rng.uniform(5, 15), rng.normal(0, 0.5), rng.uniform(-10, 10), rng.normal(0, 0.5),
                   rng.uniform(3, 8), rng.normal(0, 0.1)])
    P0 = random_spd(rng, scale=0.5)
    beacons = cross(1.0, 1.0) + rng.normal(scale=0.05, size=(4, 3))
    truth = x0[POS] + rng.normal(scale=0.7, size=3)
    ranges = np.linalg.norm(truth - beacons, axis=-1) + rng.normal(scale=0.15, size=4)
    depth = truth[2] + rng.normal(scale=0.02)
    return x0, P0, beacons, ranges, depth


def _predict_function():
    return casadi_function(CONSTANT_VELOCITY.predict, (6, 1), (6, 6), (1, 1), (1, 1),
                           (1, 1))


def _update_function(n):
    return casadi_function(lambda x, P, r, b, heard, d, sr, sd: ekf.update(x, P, r, b, heard, d, sr, sd),
                           (6, 1), (6, 6), (n, 1), (3 * n, 1), (n, 1), (1, 1), (1, 1), (1, 1))


def test_predict_matches_numpy():
    x0, P0, *_ = _ekf_case()
    qh, qv = EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"]
    dt = 0.7
    x, P = evaluate(_predict_function(), x0, P0, dt, qh, qv)
    np.testing.assert_allclose(x.ravel(), ref_phi(dt) @ x0, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(P, ref_phi(dt) @ P0 @ ref_phi(dt).T + ref_q(dt, qh, qv), rtol=1e-14, atol=1e-15)
    # hand checks: position x moves by v dt; Q of the Down axis for dt = 2 s is q_v [[8/3, 2], [2, 2]]
    assert x[0, 0] == pytest.approx(x0[0] + dt * x0[1], rel=1e-15)
    Q = np.array(ca.DM(CONSTANT_VELOCITY.process_noise(2.0, qh, qv)))
    np.testing.assert_allclose(Q[4:, 4:], qv * np.array([[8 / 3, 2.0], [2.0, 2.0]]), rtol=1e-15)
    np.testing.assert_allclose(Q[:2, :2], qh * np.array([[8 / 3, 2.0], [2.0, 2.0]]), rtol=1e-15)
    assert np.all(Q[:2, 2:] == 0.0) and np.all(Q[2:4, 4:] == 0.0)
    np.testing.assert_array_equal(np.array(ca.DM(CONSTANT_VELOCITY.transition(2.0))), ref_phi(2.0))


def test_cholesky_and_solve_spd_match_numpy():
    rng = np.random.default_rng(4)
    S = random_spd(rng, n=5, scale=3.0)
    B = rng.normal(size=(5, 3))
    (L,) = evaluate(casadi_function(kalman.cholesky, (5, 5)), S)
    np.testing.assert_allclose(L, np.linalg.cholesky(S), rtol=1e-13, atol=1e-15)
    (X,) = evaluate(casadi_function(kalman.solve_spd, (5, 5), (5, 3)), S, B)
    np.testing.assert_allclose(X, np.linalg.solve(S, B), rtol=1e-12, atol=1e-14)


def test_scalar_update_is_the_joseph_form_of_the_textbook_gain():
    """The rank-one evaluation on the upper triangle equals ``(I − k h) P (I − k h)ᵀ + k r kᵀ`` with
    ``k = P hᵀ / (h P hᵀ + r)`` in numpy, is exactly symmetric, and ``use = 0`` changes nothing."""
    rng = np.random.default_rng(11)
    P, x, h = random_spd(rng, scale=2.0), rng.normal(size=6), rng.normal(size=(1, 6))
    y, r = 0.7, 0.04
    f = casadi_function(lambda x, P, y, h, r, use: kalman.scalar_update(x, P, y, h, r, use),
                        (6, 1), (6, 6), (1, 1), (1, 6), (1, 1), (1, 1))
    x_new, P_new, nis = evaluate(f, x, P, y, h, r, 1.0)
    s = (h @ P @ h.T).item() + r
    k = P @ h.T / s
    I_kh = np.eye(6) - k @ h
    np.testing.assert_allclose(P_new, I_kh @ P @ I_kh.T + r * k @ k.T, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(x_new.ravel(), x + k.ravel() * y, rtol=1e-14)
    assert nis.item() == pytest.approx(y * y / s, rel=1e-14)
    np.testing.assert_array_equal(P_new, P_new.T)
    x_kept, P_kept, _ = evaluate(f, x, P, y, h, r, 0.0)
    np.testing.assert_array_equal(x_kept.ravel(), x)
    np.testing.assert_array_equal(P_kept, P)


def test_predict_update_matches_textbook_numpy_ekf():
    x0, P0, beacons, ranges, depth = _ekf_case()
    sr, sd = EKF_PARAMS["sigma_range"], EKF_PARAMS["sigma_depth"]
    dt = 1.0
    xp, Pp = (v.ravel() if v.shape[1] == 1 else v for v in evaluate(
        _predict_function(), x0, P0, dt, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"]))
    x, P, nis = evaluate(_update_function(4), xp, Pp, ranges, beacons.ravel(), np.ones(4), depth, sr, sd)
    x = x.ravel()
    x_pred = ref_phi(dt) @ x0
    P_pred = ref_phi(dt) @ P0 @ ref_phi(dt).T + ref_q(dt, EKF_PARAMS["q_horizontal"], EKF_PARAMS["q_vertical"])
    x_ref, P_ref, nis_ref = ref_update(x_pred, P_pred, ranges, beacons, depth, sr, sd)
    np.testing.assert_allclose(x, x_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P, P_ref, rtol=1e-10, atol=1e-14)
    assert nis[0, 0] == pytest.approx(nis_ref, rel=1e-10)
    assert np.linalg.norm(x - x_pred) > 1e-3  # the update moved the state
    np.testing.assert_allclose(P, P.T, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(P) > 0)


@pytest.mark.parametrize("missing", [(0,), (1,), (2,), (3,), (0, 2), (0, 1, 2, 3)])
def test_unheard_beacons_are_left_out_exactly(missing):
    """An unheard beacon (placeholder range 0 at (0, 0, 0)) changes nothing: the update equals the
    textbook one without that row, and bit for bit the update built for the heard beacons only."""
    x0, P0, beacons, ranges, depth = _ekf_case(seed=21)
    sr, sd = EKF_PARAMS["sigma_range"], EKF_PARAMS["sigma_depth"]
    heard = np.ones(4)
    heard[list(missing)] = 0.0
    held_r = np.where(heard > 0, ranges, 0.0)
    held_b = np.where(heard[:, None] > 0, beacons, 0.0)
    x, P, nis = evaluate(_update_function(4), x0, P0, held_r, held_b.ravel(), heard, depth, sr, sd)
    x_ref, P_ref, nis_ref = ref_update(x0, P0, np.where(heard > 0, ranges, np.nan), beacons, depth, sr, sd)
    np.testing.assert_allclose(x.ravel(), x_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P, P_ref, rtol=1e-10, atol=1e-14)
    assert nis[0, 0] == pytest.approx(nis_ref, rel=1e-10)
    keep = heard > 0
    m = int(keep.sum())
    if m:
        x_m, P_m, nis_m = evaluate(_update_function(m), x0, P0, ranges[keep], beacons[keep].ravel(), np.ones(m),
                                   depth, sr, sd)
        np.testing.assert_array_equal(x, x_m)
        np.testing.assert_array_equal(P, P_m)
        np.testing.assert_array_equal(nis, nis_m)


def test_unheard_beacon_at_the_state_position_gives_no_nan():
    """The placeholder (0, 0, 0) of an unheard beacon coinciding with the estimate (a 0/0 Jacobian)."""
    _, P0, beacons, ranges, depth = _ekf_case(seed=3)
    x0 = np.array([0.0, 0.2, 0.0, -0.1, 0.0, 0.0])
    heard = np.array([1.0, 1.0, 0.0, 1.0])
    sr, sd = EKF_PARAMS["sigma_range"], EKF_PARAMS["sigma_depth"]
    held_b = np.where(heard[:, None] > 0, beacons, 0.0)
    x, P, nis = evaluate(_update_function(4), x0, P0, ranges * heard, held_b.ravel(), heard, depth, sr, sd)
    x_ref, P_ref, nis_ref = ref_update(x0, P0, np.where(heard > 0, ranges, np.nan), beacons, depth, sr, sd)
    np.testing.assert_allclose(x.ravel(), x_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P, P_ref, rtol=1e-10, atol=1e-14)
    assert nis[0, 0] == pytest.approx(nis_ref, rel=1e-10)


# ----------------------------------------------------------------------------
# Multilateration expressions
# ----------------------------------------------------------------------------

def _multilateration_case(seed, n=4, sr=0.3, sd=0.05):
    rng = np.random.default_rng(seed)
    truth = np.array([rng.uniform(-25, 25), rng.uniform(-25, 25), rng.uniform(4, 20)])
    beacons = cross(20.0, 1.0) + rng.normal(scale=0.5, size=(4, 3))
    ranges = np.linalg.norm(truth - beacons, axis=1) + sr * rng.normal(size=4)
    depth = truth[2] + sd * rng.normal()
    return truth, beacons[:n], ranges[:n], depth


def _normal_function(n):
    return casadi_function(lambda p, r, b, k, d, wr, wd: ml.normal_equations(p, r, b, k, d, wr, wd),
                           (3, 1), (n, 1), (3 * n, 1), (n, 1), (1, 1), (1, 1), (1, 1))


def test_weights_are_inverse_variances_with_a_one_millimetre_floor():
    f = casadi_function(lambda a, b: ml.weights(a, b), (1, 1), (1, 1))
    wr, wd = evaluate(f, 0.1, 1e-5)
    assert wr[0, 0] == pytest.approx(100.0, rel=1e-15) and wd[0, 0] == pytest.approx(1e6, rel=1e-15)


@pytest.mark.parametrize("heard", [(1, 1, 1, 1), (1, 0, 1, 1)])
def test_normal_equations_match_finite_differences(heard):
    truth, beacons, ranges, depth = _multilateration_case(2)
    heard = np.array(heard, float)
    wr, wd = 1 / 0.3**2, 1 / 0.05**2
    point = truth + np.array([1.5, -2.0, 0.7])
    held_b = np.where(heard[:, None] > 0, beacons, 0.0)
    A, g, cost = evaluate(_normal_function(4), point, ranges * heard, held_b.ravel(), heard, depth, wr, wd)
    args = (ranges, beacons, heard, depth, wr, wd)
    assert cost[0, 0] == pytest.approx(np_cost(point, *args), rel=1e-13)
    grad = np.array([(np_cost(point + e, *args) - np_cost(point - e, *args)) / 2e-6 for e in np.eye(3) * 1e-6])
    np.testing.assert_allclose(g.ravel(), -0.5 * grad, rtol=1e-6, atol=1e-6)  # g = JᵀW res = −∇F / 2
    J = fd_residual_jacobian(point, *args)
    np.testing.assert_allclose(A, J.T @ J, rtol=1e-7, atol=1e-6)


def test_solve_damped3_matches_numpy_solve():
    rng = np.random.default_rng(8)
    A = random_spd(rng, n=3, scale=50.0)
    g = rng.normal(size=3)
    f = casadi_function(ml.solve_damped3, (3, 3), (3, 1), (1, 1))
    for mu in (0.0, 1e-3, 10.0):
        (step,) = evaluate(f, A, g, mu)
        ref = np.linalg.solve(A + mu * np.diag(np.diag(A)) + ml.EPS * np.eye(3), g)
        np.testing.assert_allclose(step.ravel(), ref, rtol=1e-12)


def test_linear_fix_is_exact_for_consistent_ranges_and_the_least_squares_solution_otherwise():
    f = casadi_function(ml.linear_fix, (4, 1), (12, 1), (4, 1), (1, 1))
    rng = np.random.default_rng(5)
    beacons = cross(20.0, 1.0) + rng.normal(scale=[0.5, 0.5, 2.0], size=(4, 3))  # beacons at different depths
    truth = np.array([7.0, -11.0, 9.0])
    exact = np.linalg.norm(truth - beacons, axis=1)
    for heard in ((1, 1, 1, 1), (1, 1, 0, 1)):
        heard = np.array(heard, float)
        held_b = np.where(heard[:, None] > 0, beacons, 0.0)
        (p,) = evaluate(f, exact * heard, held_b.ravel(), heard, truth[2])
        np.testing.assert_allclose(p.ravel(), truth, rtol=0, atol=1e-9)
    # noisy ranges: the least-squares solution of ‖p − b_i‖² = r_i² (p_z = d) differenced about the mean
    noisy = exact + 0.3 * rng.normal(size=4)
    (p,) = evaluate(f, noisy, beacons.ravel(), np.ones(4), truth[2])
    rows = 2.0 * (beacons[:, :2] - beacons[:, :2].mean(axis=0))
    c = (np.sum(beacons**2, axis=1) - noisy**2 - 2.0 * beacons[:, 2] * truth[2])
    ref = np.linalg.lstsq(rows, c - c.mean(), rcond=None)[0]
    np.testing.assert_allclose(p.ravel(), [*ref, truth[2]], rtol=1e-10, atol=1e-10)
    assert np.linalg.norm(p.ravel()[:2] - truth[:2]) > 1e-3  # the noise moved it
    # collinear beacons: no horizontal solution, (0, 0, d)
    line = np.column_stack([np.linspace(-3, 3, 4), np.zeros(4), np.ones(4)])
    (p,) = evaluate(f, np.linalg.norm(truth - line, axis=1), line.ravel(), np.ones(4), truth[2])
    np.testing.assert_array_equal(p.ravel(), [0.0, 0.0, truth[2]])


def test_fit_statistics_match_numpy():
    truth, beacons, ranges, depth = _multilateration_case(6)
    wr, wd = 1 / 0.3**2, 1 / 0.05**2
    f = casadi_function(lambda p, r, b, k, d, a, c: ml.fit_statistics(p, r, b, k, d, a, c),
                        (3, 1), (4, 1), (12, 1), (4, 1), (1, 1), (1, 1), (1, 1))
    heard = np.ones(4)
    rss, spread = evaluate(f, truth, ranges, beacons.ravel(), heard, depth, wr, wd)
    assert rss[0, 0] == pytest.approx(np_cost(truth, ranges, beacons, heard, depth, wr, wd), rel=1e-13)
    J = fd_residual_jacobian(truth, ranges, beacons, heard, depth, wr, wd)
    assert spread[0, 0] == pytest.approx(np.sqrt(np.trace(np.linalg.inv(J.T @ J))), rel=1e-6)
    # nothing heard: JᵀWJ = diag(0, 0, w_d) is singular, the spread is reported as 0
    rss, spread = evaluate(f, truth, np.zeros(4), np.zeros(12), np.zeros(4), depth, wr, wd)
    assert spread[0, 0] == 0.0 and rss[0, 0] == pytest.approx(wd * (depth - truth[2]) ** 2, rel=1e-13)


def _lm_functions(n, iterations, tolerance):
    start = casadi_function(
        lambda guess, r, b, k, d, wr, wd, valid: tuple(ml.lm_start(guess, r, b, k, d, wr, wd, valid)[key] for key in
                                                       ("lm_point", "lm_cost", "lm_mu", "lm_iter", "lm_active")),
        (3, 1), (n, 1), (3 * n, 1), (n, 1), (1, 1), (1, 1), (1, 1), (1, 1))

    def iteration(point, cost, mu, it, r, b, k, d, wr, wd):
        out = ml.lm_iteration({"lm_point": point, "lm_cost": cost, "lm_mu": mu, "lm_iter": it}, r, b, k, d, wr, wd,
                              iterations, tolerance)
        return tuple(out[key] for key in ("lm_point", "lm_cost", "lm_mu", "lm_iter", "lm_active"))

    step = casadi_function(iteration, (3, 1), (1, 1), (1, 1), (1, 1), (n, 1), (3 * n, 1), (n, 1), (1, 1), (1, 1),
                           (1, 1))
    return start, step


def np_lm_iteration(point, cost, mu, ranges, beacons, heard, depth, wr, wd):
    """A textbook Levenberg-Marquardt iteration with Marquardt's diagonal scaling (numpy)."""
    A, g = np.zeros((3, 3)), np.zeros(3)
    for r, b, k in zip(ranges, beacons, heard):
        if k:
            u = (point - b) / np.linalg.norm(point - b)
            A += wr * np.outer(u, u)
            g += wr * u * (r - np.linalg.norm(point - b))
    A[2, 2] += wd
    g[2] += wd * (depth - point[2])
    step = np.linalg.solve(A + mu * np.diag(np.diag(A)) + ml.EPS * np.eye(3), g)
    trial_cost = np_cost(point + step, ranges, beacons, heard, depth, wr, wd)
    better = trial_cost < cost
    return (point + step if better else point), min(trial_cost, cost), (mu * 0.1 if better else mu * 10.0), \
        float(step @ A @ step), better, trial_cost


def _lm_run(start_f, step_f, guess, ranges, beacons, depth, wr, wd, cap, via_start=False):
    """Run the casadi iteration and a numpy LM side by side; (point, iterations, clear rejections)."""
    heard = np.ones(len(ranges))
    args = (ranges, beacons.ravel(), heard, depth, wr, wd)
    if via_start:
        point, cost, mu, it, active = evaluate(start_f, guess, *args, 1.0)
        assert active[0, 0] == 1.0 and mu[0, 0] == 1e-3 and it[0, 0] == 0.0
    else:
        cost = np.array([[np_cost(np.asarray(guess, float), ranges, beacons, heard, depth, wr, wd)]])
        point, mu, it, active = np.asarray(guess, float), np.array([[1e-3]]), np.array([[0.0]]), np.array([[1.0]])
    point = point.ravel()
    rejected = 0
    while active[0, 0]:
        ref_point, ref_cost, ref_mu, size, better, trial = np_lm_iteration(point, cost[0, 0], mu[0, 0], ranges,
                                                                           beacons, heard, depth, wr, wd)
        new_point, cost, mu, it, active = evaluate(step_f, point, cost, mu, it, *args)
        new_point = new_point.ravel()
        if abs(trial - ref_cost) > 1e-9 * ref_cost or not better:  # a clear decision, not a round-off tie
            assert mu[0, 0] == pytest.approx(ref_mu, rel=1e-12)
            rejected += trial > 1.000001 * cost[0, 0]
        np.testing.assert_allclose(new_point, ref_point, rtol=0, atol=1e-8)
        assert active[0, 0] == float(size > 1e-12 and it[0, 0] < cap)
        point = new_point
    return point, int(it[0, 0]), rejected


def test_lm_iteration_follows_a_numpy_levenberg_marquardt_and_converges_to_scipy():
    """Short baseline (the ring valley, where some Gauss-Newton steps overshoot and are rejected) and a
    20 m cross from a poor start: the casadi iteration takes the numpy LM's steps and damping decisions;
    stopped by its tolerance (1e-6 σ) it lies within 1e-6 σ (Mahalanobis) of scipy's converged fit."""
    cap = 50
    start_f, step_f = _lm_functions(4, cap, 1e-6)
    wr, wd = 1 / 0.3**2, 1 / 0.05**2
    rejected = converged = 0
    for seed in range(8):
        rng = np.random.default_rng(seed)
        truth = np.array([rng.uniform(10, 30), rng.uniform(-10, 10), rng.uniform(4, 10)])
        beacons = cross(1.5, 1.0) + rng.normal(scale=0.05, size=(4, 3))
        ranges = np.linalg.norm(truth - beacons, axis=1) + 0.3 * rng.normal(size=4)
        depth = truth[2] + 0.05 * rng.normal()
        ref = scipy_fix(ranges, beacons, depth, 0.3, 0.05, truth)
        J = -fd_residual_jacobian(ref, ranges, beacons, np.ones(4), depth, wr, wd)
        for guess in ([0.0, 25.0, depth], [5.0, 5.0, depth]):
            point, iterations, clear = _lm_run(start_f, step_f, guess, ranges, beacons, depth, wr, wd, cap)
            rejected += clear
            if iterations < cap:
                converged += 1
                d = point - ref
                assert np.sqrt(d @ J.T @ J @ d) <= 1e-6, (seed, guess)
    assert rejected > 10 and converged >= 12
    for seed in range(4):  # a 20 m cross: converged to 1e-6 m, from the start rule
        truth, beacons, ranges, depth = _multilateration_case(seed)
        point, iterations, _ = _lm_run(start_f, step_f, [0.5, -0.3, 40.0], ranges, beacons, depth, wr, wd, cap,
                                       via_start=True)
        assert iterations < cap
        np.testing.assert_allclose(point, scipy_fix(ranges, beacons, depth, 0.3, 0.05, truth), rtol=0, atol=1e-6)


def test_lm_start_takes_the_guess_or_the_linear_fix_whichever_costs_less():
    truth, beacons, ranges, depth = _multilateration_case(9, sr=0.0, sd=0.0)
    wr, wd = 1 / 0.3**2, 1 / 0.05**2
    start_f, _ = _lm_functions(4, 8, 1e-3)
    args = (ranges, beacons.ravel(), np.ones(4), depth, wr, wd)
    point, cost, *_ , active = evaluate(start_f, truth, *args, 1.0)  # the exact position: cost 0, kept
    np.testing.assert_array_equal(point.ravel(), truth)
    assert cost[0, 0] < 1e-20 and active[0, 0] == 1.0
    far = np.array([200.0, -150.0, 3.0])
    point, cost, *_, active = evaluate(start_f, far, *args, 0.0)  # far away: the linear fix (the truth here)
    np.testing.assert_allclose(point.ravel(), truth, rtol=0, atol=1e-9)
    assert cost[0, 0] == pytest.approx(np_cost(point.ravel(), ranges, beacons, np.ones(4), depth, wr, wd), abs=1e-12)
    assert active[0, 0] == 0.0  # not enough ranges: no iterations follow


# ----------------------------------------------------------------------------
# The compiled receiver
# ----------------------------------------------------------------------------

RX = dict(sigma_range=0.2, sigma_depth=0.05, q_horizontal=0.02, q_vertical=0.002, p0_position=2.0, p0_velocity=0.4,
          x0_x=10.0, x0_y=-4.0, x0_z=6.0, x0_vx=0.3, x0_vy=-0.2, x0_vz=0.05)


def _x0_P0(params=RX):
    x = np.array([params[f"x0_{n}"] for n in STATE], dtype=float)
    P = np.diag([params["p0_position"] ** 2, params["p0_velocity"] ** 2] * 3).astype(float)
    return x, P


def test_initial_outputs_have_no_estimate_and_the_prior_covariance():
    """Before the first update the filter holds its prior (x0, P0), but reports no estimate: est_* are NaN (x0 is
    tied to the diver's true start, never an estimate); its covariance outputs are the prior's, finite."""
    core = Core(PaperEKF, RX, replicates=[0, 1])
    core.initialize(0.0)
    out = core.outputs
    x0, P0 = _x0_P0()
    assert np.isnan(est(out)).all()
    np.testing.assert_array_equal(core.state["x"], np.tile(x0, (2, 1)))
    np.testing.assert_array_equal(covariance(core), P0)
    assert out["pos_std"][0] == pytest.approx(np.sqrt(3.0) * RX["p0_position"], rel=1e-15)
    assert out["nis"].tolist() == [0.0, 0.0] and out["instr_valid"].tolist() == [False, False]
    np.testing.assert_array_equal(instr(out), 0.0)


def test_receiver_uses_a_packet_only_when_the_step_end_reaches_its_rx_time():
    """A packet transmitted a quarter slot in and arriving at the slot's end is used at the step that reaches its
    arrival, not its transmit epoch."""
    T, r = 1.0, 4
    dt = T / r
    core = Core(PaperEKF, RX, replicates=[0])
    core.initialize(0.0)
    x_ref, P_ref = _x0_P0()
    phi, Q = ref_phi(dt), ref_q(dt, RX["q_horizontal"], RX["q_vertical"])
    held = np.full(4, np.nan)
    beacons = cross(1.0, 1.0)
    updates = []  # the packets the receiver updated with

    def check_no_update():
        check_estimate(core, 0, x_ref, updated=bool(updates), rtol=1e-12, atol=1e-12)  # none before the first
        np.testing.assert_allclose(covariance(core), P_ref, rtol=1e-12, atol=1e-15)
        assert core.outputs["pos_std"][0] == pytest.approx(np.sqrt(P_ref[0, 0] + P_ref[2, 2] + P_ref[4, 4]),
                                                           rel=1e-12)

    packets = [(1, 2, 12.3, 6.4), (2, 3, 13.1, 6.5)]  # (seq, beacon_id, range, depth), one slot of length T each
    t, nis_before = 0.0, 0.0
    for seq, bid, rng_value, depth in packets:
        tx, rx = t + dt, t + T
        core.set_inputs(packet(seq, bid, tx, rng_value, beacons[bid - 1], depth, rx_time=rx))
        for j in range(r):
            core.step(t, dt)
            t += dt
            x_ref, P_ref = phi @ x_ref, phi @ P_ref @ phi.T + Q
            if j < r - 1:
                assert t < rx - 1e-9
                check_no_update()  # the packet's epoch not reached yet: a pure prediction
                assert core.outputs["nis"][0] == (0.0 if seq == 1 else nis_before)
                continue
            assert t == pytest.approx(rx)
            held[bid - 1] = rng_value
            x_ref, P_ref, nis = ref_update(x_ref, P_ref, held, beacons, depth, RX["sigma_range"], RX["sigma_depth"])
            updates.append(seq)
            check_estimate(core, 0, x_ref, updated=True, rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(covariance(core), P_ref, rtol=1e-8, atol=1e-12)
            assert core.outputs["nis"][0] == pytest.approx(nis, rel=1e-9)
            assert core.state["slot_time"][0, 0] == tx and core.state["last_seq"][0, 0] == seq
        # a whole further slot with the same packet still on the inputs: no second update
        nis_before = core.outputs["nis"][0]
        for _ in range(r):
            core.step(t, dt)
            t += dt
            x_ref, P_ref = phi @ x_ref, phi @ P_ref @ phi.T + Q
            check_no_update()
            assert core.outputs["nis"][0] == nis_before
    # two beacons heard only: no instrumentation fix, and its outputs are 0, not NaN
    assert not core.outputs["instr_valid"][0]
    np.testing.assert_array_equal(instr(core.outputs), 0.0)


def test_lost_packet_and_unknown_beacon_keep_the_held_ranges():
    """A lost packet (valid false, range 0) or an id outside 1…4 stores nothing, but its slot still
    updates the filter with the held ranges and the depth (numpy reference), and the fix stays valid."""
    truth = np.array([7.0, -5.0, 6.0])
    beacons = cross(1.0, 1.0)
    true_ranges = np.linalg.norm(truth - beacons, axis=1)
    params = dict(RX, x0_x=6.5, x0_y=-4.5, x0_z=6.2, x0_vx=0.0, x0_vy=0.0, x0_vz=0.0)
    core = Core(PaperEKF, params, replicates=[0, 1])
    core.initialize(0.0)
    x_ref, P_ref = _x0_P0(params)
    phi, Q = ref_phi(1.0), ref_q(1.0, RX["q_horizontal"], RX["q_vertical"])
    held = np.full(4, np.nan)
    t = 0.0
    for k in range(4):
        core.set_inputs(packet(k + 1, k + 1, t + 1.0, true_ranges[k], beacons[k], truth[2]))
        core.step(t, 1.0)
        t += 1.0
        held[k] = true_ranges[k]
        x_ref, P_ref, _ = ref_update(phi @ x_ref, phi @ P_ref @ phi.T + Q, held, beacons, truth[2],
                                     RX["sigma_range"], RX["sigma_depth"])
    assert core.outputs["instr_valid"].tolist() == [True, True]
    np.testing.assert_allclose(instr(core.outputs), np.tile(truth, (2, 1)), atol=1e-6)
    np.testing.assert_allclose(core.state["ranges"], np.tile(true_ranges, (2, 1)))
    # replicate 0 loses the next packet of beacon 1 (range 0, position 0); replicate 1 hears 99 m
    core.set_inputs(dict(packet(5, 1, t + 1.0, np.array([0.0, 99.0]), np.array([[0.0] * 3, beacons[0]]), truth[2]),
                         packet_valid=np.array([False, True])))
    core.step(t, 1.0)
    t += 1.0
    x_ref, P_ref, nis_ref = ref_update(phi @ x_ref, phi @ P_ref @ phi.T + Q, held, beacons, truth[2],
                                       RX["sigma_range"], RX["sigma_depth"])
    assert core.state["ranges"][0, 0] == true_ranges[0]
    np.testing.assert_array_equal(core.state["beacons"][0, :3], beacons[0])
    assert core.state["ranges"][1, 0] == 99.0
    np.testing.assert_allclose(est(core.outputs)[0], x_ref, rtol=1e-10, atol=1e-10)
    assert core.outputs["nis"][0] == pytest.approx(nis_ref, rel=1e-9)
    assert core.outputs["instr_valid"].tolist() == [True, True]
    np.testing.assert_allclose(instr(core.outputs)[0], truth, atol=1e-6)
    assert np.linalg.norm(instr(core.outputs)[1] - truth) > 1.0  # the 99 m range moved replicate 1's fix
    # ids 9 and 0: a slot each (the sequence advances, the filter updates), nothing stored
    for seq, bid in ((6, 9), (7, 0)):
        before = core.state
        core.set_inputs(packet(seq, bid, t + 1.0, 3.0, beacons[1], truth[2]))
        core.step(t, 1.0)
        t += 1.0
        x_ref, P_ref, nis_ref = ref_update(phi @ x_ref, phi @ P_ref @ phi.T + Q, held, beacons, truth[2],
                                           RX["sigma_range"], RX["sigma_depth"])
        for name in ("ranges", "beacons", "heard"):
            np.testing.assert_array_equal(core.state[name], before[name], err_msg=name)
        assert core.state["last_seq"][:, 0].tolist() == [seq, seq]
        np.testing.assert_allclose(est(core.outputs)[0], x_ref, rtol=1e-10, atol=1e-10)
        assert core.outputs["nis"][0] == pytest.approx(nis_ref, rel=1e-9)


def test_instrumentation_fix_needs_three_ranges():
    truth = np.array([6.0, 4.0, 7.0])
    beacons = cross(20.0, 1.0)
    ranges = np.linalg.norm(truth - beacons, axis=1)
    core = Core(PaperEKF, dict(RX, x0_x=0.0, x0_y=0.0, x0_z=0.0, x0_vx=0.0, x0_vy=0.0, x0_vz=0.0),
                replicates=[0])  # the estimate sits at the unheard beacons' placeholder (0, 0, 0)
    core.initialize(0.0)
    for k in range(4):
        core.set_inputs(packet(k + 1, k + 1, k + 1.0, ranges[k], beacons[k], truth[2]))
        core.step(float(k), 1.0)
        out = core.outputs
        assert all(np.all(np.isfinite(v)) for v in out.values())
        if k < 2:
            assert not out["instr_valid"][0]
            np.testing.assert_array_equal(instr(out), 0.0)
        else:
            assert out["instr_valid"][0]
            np.testing.assert_allclose(instr(out)[0], truth, rtol=0, atol=1e-6)


def test_instrumentation_fix_matches_scipy_within_its_stopping_tolerance():
    """The fix stops once a step is below 1e-3 standard deviations (δᵀ JᵀWJ δ ≤ 1e-6) or after 8
    iterations: it lies within 1e-3 σ (Mahalanobis, JᵀWJ at scipy's solution) of the converged fit."""
    B = 24
    rng = np.random.default_rng(17)
    sr, sd = RX["sigma_range"], RX["sigma_depth"]
    truth = np.column_stack([rng.uniform(-25, 25, B), rng.uniform(-25, 25, B), rng.uniform(4, 20, B)])
    beacons = cross(20.0, 1.0)[None] + rng.normal(scale=0.5, size=(B, 4, 3))
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1) + sr * rng.normal(size=(B, 4))
    depth = truth[:, 2] + sd * rng.normal(size=B)
    start = truth + rng.normal(scale=2.0, size=(B, 3))
    core = Core(PaperEKF, RX, replicates=range(B))
    core.values.update(x0_x=start[:, 0], x0_y=start[:, 1], x0_z=start[:, 2])  # per-replicate FMU values
    core.initialize(0.0)
    lost = rng.uniform(size=B) < 0.3  # some replicates lose beacon 4: the fix uses three ranges
    for k in range(4):
        valid = ~lost if k == 3 else np.ones(B, bool)
        core.set_inputs(packet(k + 1, k + 1, k + 1.0, np.where(valid, ranges[:, k], 0.0), beacons[:, k], depth, valid))
        core.step(float(k), 1.0)
    out = core.outputs
    assert out["instr_valid"].all() and lost.any() and not lost.all()
    np.testing.assert_array_equal(instr(out), core.state["fix"])
    iterations = core.state["lm_iter"][:, 0]
    assert np.all(iterations < 8)  # stopped by the tolerance in this geometry
    for b in range(B):
        held = np.where([True, True, True, not lost[b]], ranges[b], np.nan)
        ref = scipy_fix(held, beacons[b], depth[b], sr, sd, truth[b])
        J = -fd_residual_jacobian(ref, held, beacons[b], np.isfinite(held), depth[b], 1 / sr**2, 1 / sd**2)
        d = instr(out)[b] - ref
        assert np.sqrt(d @ (J.T @ J) @ d) <= 1e-3, b
        assert np.linalg.norm(ref - truth[b]) > 1e-3  # the noise matters


def test_receiver_run_matches_a_numpy_ekf_with_substeps_and_per_replicate_parameters():
    """A packet stream at T = 1 s stepped at T/4 with arrivals between step ends, losses, repeats and a
    bad id; three replicates with their own parameters, each against a numpy EKF of its own."""
    B, T, r = 3, 1.0, 4
    dt = T / r
    rng = np.random.default_rng(29)
    per = dict(sigma_range=np.array([0.1, 0.4, 1.0]), sigma_depth=np.array([0.01, 0.05, 0.2]),
               q_horizontal=np.array([0.01, 0.1, 0.0]), q_vertical=np.array([0.001, 0.02, 0.0]),
               p0_position=np.array([1.0, 3.0, 0.5]), p0_velocity=np.array([0.5, 0.1, 1.0]),
               x0_x=np.array([2.0, -5.0, 9.0]), x0_y=np.array([-14.0, 3.0, 1.0]), x0_z=np.array([5.0, 8.0, 2.0]),
               x0_vx=np.array([0.4, 0.0, -0.2]), x0_vy=np.array([0.0, 0.1, 0.3]), x0_vz=np.array([0.0, 0.0, 0.05]))
    core = Core(PaperEKF, RX, replicates=range(B))
    core.values.update(per)  # per-replicate FMU values
    core.initialize(0.0)
    ref = []
    for b in range(B):
        p = {k: v[b] for k, v in per.items()}
        x, P = _x0_P0(p)
        ref.append(dict(p=p, x=x, P=P, held=np.full(4, np.nan), beacons=np.zeros((4, 3)), seq=0, nis=0.0,
                        updated=False))
    beacons = cross(3.0, 1.0)
    t, seq, tx = 0.0, 0, 0.0
    updates = 0
    for k in range(40):
        if k % 5 != 3:  # every fifth slot repeats the previous packet (no new slot)
            seq += 1
            tx = (seq + rng.uniform(-0.9, 0.0)) * T  # an epoch anywhere in the slot's last step or before
        bid = 9 if seq == 17 else (seq - 1) % 4 + 1
        target = np.column_stack([0.3 * tx + np.arange(B), -14.0 + 0.1 * tx * np.ones(B), 5.0 + np.arange(B)])
        b_pos = beacons[min(bid, 4) - 1] + rng.normal(scale=0.05, size=(B, 3))
        rng_value = np.linalg.norm(target - b_pos, axis=1) + per["sigma_range"] * rng.normal(size=B)
        valid = rng.uniform(size=B) > 0.25
        depth = target[:, 2] + per["sigma_depth"] * rng.normal(size=B)
        rx = tx + 0.1  # it arrives a tenth of a second after it was sent: used then
        core.set_inputs(packet(seq, bid, tx, np.where(valid, rng_value, 0.0), np.where(valid[:, None], b_pos, 0.0),
                               depth, valid, rx_time=rx))
        for _ in range(r):
            core.step(t, dt)
            for b, s in enumerate(ref):
                p = s["p"]
                s["x"], s["P"] = ref_phi(dt) @ s["x"], ref_phi(dt) @ s["P"] @ ref_phi(dt).T + ref_q(
                    dt, p["q_horizontal"], p["q_vertical"])
                if seq != s["seq"] and t + dt >= rx - 1e-9:
                    s["seq"] = seq
                    if valid[b] and 1 <= bid <= 4:
                        s["held"][bid - 1], s["beacons"][bid - 1] = rng_value[b], b_pos[b]
                        s["updated"] = True  # a received packet of the array: an estimate from here on
                    s["x"], s["P"], s["nis"] = ref_update(s["x"], s["P"], s["held"], s["beacons"], depth[b],
                                                          p["sigma_range"], p["sigma_depth"])
                    updates += 1
            t += dt
            out = core.outputs
            for b, s in enumerate(ref):
                check_estimate(core, b, s["x"], s["updated"], err_msg=f"t={t}, b={b}")
                np.testing.assert_allclose(covariance(core, b), s["P"], rtol=1e-8, atol=1e-12)
                assert out["nis"][b] == pytest.approx(s["nis"], rel=1e-8, abs=1e-12)
                assert out["pos_std"][b] == pytest.approx(np.sqrt(s["P"][0, 0] + s["P"][2, 2] + s["P"][4, 4]),
                                                          rel=1e-12)
    assert updates > 60 and all(s["nis"] > 0 for s in ref)
