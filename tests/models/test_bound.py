"""The accuracy limit (models/bound.py, error_bound.py, fisher.py) against independent computations.

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
* The bound with error states (a Gauss-Markov GPS error, the clock, a
  constant attitude error) against an augmented FilterPy Kalman filter, and
  equal to the plain bound without them.
* The same generic Fisher information for the range + direction (USBL)
  model against analytic gradients, with the closed form of its cross-range
  accuracy; the USBL bound against an augmented FilterPy Kalman filter with
  the full R; the compiled bounds equal the casadi evaluations.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from sblsim.models.bound import effective_range_variance, pcrb, pcrb_inputs
from sblsim.models.fisher import fix_information, horizontal_std
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
                 depth_variance=np.array([1e-4, 1e-2, 1e-6]), sigma_range=0.0, range_k=0.0)  # no range law
    return truth, slot, received, beacons, arms, fixed


def range_variance(position, beacon, arm, noise, attitude):
    return noise + fd_attitude_variance(position, beacon, arm, attitude)


@pytest.mark.parametrize("law", [None, (0.1, 0.01)], ids=["constant", "range-law"])
def test_pcrb_equals_a_kalman_filter_covariance_and_tichavsky_information_recursion(law):
    """With the range law (σ₀ 0.1 m, k 0.01), each range's variance in the filter is the noise variance with σ₀²
    replaced by (σ₀ + k d)², d the true range (numpy)."""
    truth, slot, received, beacons, arms, fixed = case()
    if law is not None:
        fixed = {**fixed, "sigma_range": law[0], "range_k": law[1]}
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
                    noise = f["noise_variance"]
                    if law is not None:
                        d = np.linalg.norm(truth[k, r] - beacons[k, r])
                        noise = noise - law[0] ** 2 + (law[0] + law[1] * d) ** 2
                    var = range_variance(truth[k, r], beacons[k, r], arms[k, r], noise, f["attitude_variance"])
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


def augmented_filter(f, n_states=14):
    """FilterPy's KalmanFilter of the receivers' state with error states (numpy): the constant velocity, the GPS
    error a Gauss-Markov process, the clock's offset and drift, a constant attitude error, with their priors."""
    kf = KalmanFilter(dim_x=n_states, dim_z=1)
    dt = f["dt"]
    decay = np.exp(-dt / max(f["gps_tau"], 1e-9))
    F = np.eye(n_states)
    F[:6, :6] = phi(dt)
    F[6:9, 6:9] = decay * np.eye(3)
    F[9, 10] = dt
    Q = np.zeros((n_states, n_states))
    Q[:6, :6] = white_noise_q(dt, f["q_horizontal"], f["q_vertical"])
    Q[6:9, 6:9] = f["gps_sigma"] ** 2 * (1 - decay ** 2) * np.eye(3)
    kf.x, kf.F, kf.Q = np.zeros((n_states, 1)), F, Q
    kf.P = np.diag([f["p0_position"] ** 2, f["p0_velocity"] ** 2] * 3 + [f["gps_sigma"] ** 2] * 3
                   + [0.0, f["clock_drift_sigma"] ** 2] + [f["attitude_sigma"] ** 2] * 3)
    return kf


def np_error_range(position, beacon, arm, errors, clock):
    """A range from the broadcast beacon less the GPS error and the attitude error turned through the arm (numpy)."""
    gps, offset, attitude = errors[0:3], errors[3], errors[5:8]
    return np.linalg.norm(position - (beacon - gps - np.cross(attitude, arm))) + clock * offset


@pytest.mark.slow
def test_the_bound_with_error_states_equals_an_augmented_kalman_filter_and_the_plain_bound_without_them():
    """The ranging bound with error states (models/error_bound.py error_pcrb) against FilterPy's KalmanFilter with the
    augmented state (a Gauss-Markov GPS error, the clock's offset and drift, a constant attitude error, the offset's
    random step of an inverted LBL's ping jitter at each new ping), its range row by central differences of the
    numpy range; with every error prior 0 it is the plain bound bit for bit."""
    from sblsim.models.error_bound import ERROR_FIXED, error_pcrb

    truth, slot, received, beacons, arms, fixed = case()
    n, b = slot.shape
    errors = dict(gps_sigma=np.array([0.0, 1.0, 0.3]), gps_tau=np.array([0.0, 60.0, 5.0]),
                  clock_drift_sigma=np.array([5e-6, 0.0, 2e-5]), attitude_sigma=np.radians([0.0, 1.0, 2.0]),
                  clock=np.array([1500.0, 0.0, 1480.0]), ping_jitter=np.array([0.0, 0.0, 0.03]))
    new_ping = np.random.default_rng(3).random(slot.shape) < 0.3  # the first packet of a ping, at some slots
    columns = np.stack([np.broadcast_to({**fixed, **errors}[k], (b,)) for k in ERROR_FIXED], axis=1)
    steps = np.concatenate([truth, beacons, arms, slot[..., None], received[..., None], new_ping[..., None]], axis=-1)
    bound = error_pcrb(columns, steps)
    for r in range(b):
        f = {k: float(np.broadcast_to(v, (b,))[r]) for k, v in {**fixed, **errors}.items()}
        kf = augmented_filter(f)
        for k in range(n):
            kf.predict()
            if slot[k, r]:
                if new_ping[k, r]:  # the emission offset's random step, before the ping's rows
                    kf.P[9, 9] += f["ping_jitter"] ** 2
                depth = np.zeros((1, 14))
                depth[0, 4] = 1.0
                kf.update(np.zeros((1, 1)), R=f["depth_variance"], H=depth)
                if received[k, r]:
                    state = np.zeros(14)
                    state[[0, 2, 4]] = truth[k, r]

                    def h(x, beacon=beacons[k, r], arm=arms[k, r], clock=f["clock"]):
                        return np_error_range(x[[0, 2, 4]], beacon, arm, np.r_[x[6:9], x[9], x[10], x[11:14]], clock)

                    H = np.zeros((1, 14))
                    for i in range(14):
                        e = np.zeros(14)
                        e[i] = EPS
                        H[0, i] = (h(state + e) - h(state - e)) / (2 * EPS)
                    variance = range_variance(truth[k, r], beacons[k, r], arms[k, r], f["noise_variance"],
                                              f["attitude_variance"])
                    kf.update(np.zeros((1, 1)), R=variance, H=H)
            assert bound[k, r] == pytest.approx(np.sqrt(kf.P[0, 0] + kf.P[2, 2] + kf.P[4, 4]), rel=1e-6), (k, r)
    # the error states only add uncertainty: each run's bound is at least the plain one
    plain = pcrb(*pcrb_inputs(truth, slot, received, beacons, arms, **fixed))
    assert np.all(bound >= plain * (1 - 1e-12)) and np.all(bound[-1, 1:] > 1.05 * plain[-1, 1:])
    zero = np.stack([np.broadcast_to({**fixed, **{k: 0.0 for k in errors}}[k], (b,)) for k in ERROR_FIXED], axis=1)
    np.testing.assert_array_equal(error_pcrb(zero, steps), plain)


def test_the_compiled_bound_with_error_states_is_the_reference_one():
    """The ranging interface's library steps the bound with error states in C (the runs with such errors);
    casadi's virtual machine is the reference."""
    from sblsim.fmus import compiled_metrics
    from sblsim.models.error_bound import ERROR_FIXED, error_pcrb

    truth, slot, received, beacons, arms, fixed = case(seed=8, n=200)
    b = slot.shape[1]
    errors = dict(gps_sigma=1.0, gps_tau=60.0, clock_drift_sigma=5e-6, attitude_sigma=np.radians(1.0), clock=1500.0,
                  ping_jitter=0.02, sigma_range=0.1, range_k=0.005)  # with the range law
    new_ping = np.random.default_rng(9).random(slot.shape) < 0.3
    columns = np.stack([np.broadcast_to({**fixed, **errors}[k], (b,)) for k in ERROR_FIXED], axis=1)
    steps = np.concatenate([truth, beacons, arms, slot[..., None], received[..., None], new_ping[..., None]], axis=-1)
    np.testing.assert_allclose(compiled_metrics.system_pcrb(4, columns, steps), error_pcrb(columns, steps), rtol=1e-12,
                               atol=0)


def test_range_direction_fisher_information_through_the_generic_map_function():
    """The map's Fisher information of a USBL packet (the range + direction model of a level array, through the
    same generic function as the ranges-plus-depth map) against analytic gradients; its cross-range standard
    deviation is the slant range times the direction cosines' σ, exactly, at any elevation, and it is finite
    straight below the transceiver."""
    import casadi as ca

    from sblsim.models.fisher import model_horizontal_std, position_information
    from sblsim.models.receiver.range_direction import RangeDirectionModel

    model = RangeDirectionModel()
    transceiver, level = np.array([1.0, -2.0, 0.5]), np.zeros(3)
    s_r, s_u = 0.1, np.radians(0.5)
    variances = np.array([s_r**2, s_u**2, s_u**2])
    rng = np.random.default_rng(7)
    for p in rng.normal(scale=[40, 40, 10], size=(10, 3)) + [0, 0, 20]:
        J = np.array(ca.evalf(position_information(model, p, (transceiver, level), variances)))
        d = p - transceiver
        r = np.linalg.norm(d)
        s = d / r
        H = np.vstack([s, ((np.eye(3) - np.outer(s, s)) / r)[:2]])  # ∂[r, s_N, s_E]/∂p of a level array
        expected = H.T @ np.diag(1 / variances) @ H
        np.testing.assert_allclose(J, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
        across = np.array([-s[1], s[0], 0.0]) / np.hypot(s[0], s[1])
        assert np.sqrt(across @ np.linalg.solve(J, across)) == pytest.approx(r * s_u, rel=1e-9)
    # straight below the transceiver: finite, √2 r σ_u horizontally (both direction cosines measure it)
    below = transceiver + [[0.0, 0.0, 100.0]]
    drms = model_horizontal_std(model, below, (transceiver, level), variances)
    assert drms[0] == pytest.approx(np.sqrt(2) * 100.0 * s_u, rel=1e-9)


def usbl_case(seed=4, n=200, b=3):
    """Three runs: a diver circling 8-20 m from a transceiver that heaves and rolls, one run passing almost under
    it; the attitude the packets carry varies, and the third run has a Gauss-Markov GPS error and an attitude
    error as states."""
    rng = np.random.default_rng(seed)
    t = 0.5 * np.arange(1, n + 1)
    radius = np.array([8.0, 20.0, 0.3])
    depth = np.array([6.0, 2.5, 40.0])
    truth = np.stack([np.stack([radius[j] * np.cos(0.03 * t + j), radius[j] * np.sin(0.03 * t + j),
                                depth[j] + 0.01 * t], -1) for j in range(b)], axis=1)
    transceivers = rng.normal(scale=0.2, size=(n, b, 3)) + [0, 0, 1.0]
    attitudes = rng.normal(scale=0.05, size=(n, b, 3)) + [0.0, 0.0, 0.4]
    slot = rng.uniform(size=(n, b)) < 0.8
    received = slot & (rng.uniform(size=(n, b)) < 0.8)
    fixed = dict(dt=0.5, q_horizontal=np.array([0.01, 0.002, 0.05]), q_vertical=np.array([1e-3, 1e-4, 1e-2]),
                 p0_position=np.array([1.0, 2.0, 0.5]), p0_velocity=np.array([0.5, 0.2, 0.3]),
                 range_variance=np.array([0.01, 0.49, 0.01]), position_variance=np.array([0.01, 1.0, 0.0]),
                 angle_sigma_deg=np.array([0.5, 1.0, 0.2]),
                 attitude_variance=np.radians([1.0, 0.0, 0.5]) ** 2, depth_variance=np.array([1e-4, 1e-2, 1e-6]),
                 gps_sigma=np.array([0.0, 0.0, 0.5]), gps_tau=np.array([0.0, 0.0, 30.0]),
                 attitude_sigma=np.radians([0.0, 0.0, 1.0]), sigma_range=0.0, range_k=0.0)  # no range law
    return truth, slot, received, transceivers, attitudes, fixed


@pytest.mark.slow
def test_usbl_pcrb_equals_a_kalman_filter_covariance_with_range_and_direction_cosines():
    """The USBL bound (models/systems/usbl_bound.py pcrb) against FilterPy's KalmanFilter covariance of the augmented
    state (the third run's GPS error and attitude error as states) with the linearized range and direction-cosine rows
    at the true position (central differences of the numpy h, scipy's rotations) and their full R written out
    here: ``diag(σ_r², σ_u², σ_u²) + σ_b² H_b H_bᵀ + σ_att² H_θ H_θᵀ`` (σ_b² the transceiver position's variance
    per axis, σ_att² the attitude's per Euler angle)."""
    from sblsim.models.systems.usbl_bound import pcrb as usbl_pcrb
    from sblsim.models.systems.usbl_bound import pcrb_inputs as usbl_pcrb_inputs
    from tests.models.test_measurement_models import central, np_range_direction

    truth, slot, received, transceivers, attitudes, fixed = usbl_case()
    n, b = slot.shape
    bound = usbl_pcrb(*usbl_pcrb_inputs(truth, slot, received, transceivers, attitudes, **fixed))
    for r in range(b):
        f = {k: float(np.broadcast_to(v, (b,))[r]) for k, v in fixed.items()}
        kf = augmented_filter({**f, "clock_drift_sigma": 0.0})
        for k in range(n):
            kf.predict()
            if slot[k, r]:
                depth = np.zeros((1, 14))
                depth[0, 4] = 1.0
                kf.update(np.zeros((1, 1)), R=f["depth_variance"], H=depth)
                if received[k, r]:
                    c, a, p = transceivers[k, r], attitudes[k, r], truth[k, r]
                    state = np.zeros(14)
                    state[[0, 2, 4]] = p

                    def h(x, c=c, a=a):  # the broadcast transceiver less the GPS error, the attitude less its error
                        return np_range_direction(x[:6], c - x[6:9], a - x[11:14])

                    H = central(h, state)
                    H_b = central(lambda q, x=state[:6], a=a: np_range_direction(x, q, a), c)
                    H_a = central(lambda q, x=state[:6], c=c: np_range_direction(x, c, q), a)
                    R = (np.diag([f["range_variance"]] + [np.radians(f["angle_sigma_deg"]) ** 2] * 2)
                         + f["position_variance"] * H_b @ H_b.T + f["attitude_variance"] * H_a @ H_a.T)
                    kf.update(np.zeros((3, 1)), R=R, H=H)
            assert bound[k, r] == pytest.approx(np.sqrt(kf.P[0, 0] + kf.P[2, 2] + kf.P[4, 4]), rel=1e-6), (k, r)
    assert received.sum() > 300
    # the direction carries the horizontal position: far below the range-only bound of the same packets
    zeros = np.zeros_like(transceivers)
    ranges = {k: v for k, v in fixed.items()
              if k in ("dt", "q_horizontal", "q_vertical", "p0_position", "p0_velocity", "attitude_variance",
                       "depth_variance")}
    range_only = pcrb(*pcrb_inputs(truth, slot, received, transceivers, zeros,
                                   noise_variance=fixed["range_variance"] + fixed["position_variance"], **ranges))
    assert np.all(bound[-1, :2] < 0.5 * range_only[-1, :2])


def test_the_compiled_usbl_bound_is_the_reference_one():
    """The USBL interface's library steps the USBL bound in C (what runs use); casadi's virtual machine is the
    reference: equal to round-off on random tracks, packets, losses, attitudes and transceiver motion."""
    from sblsim.fmus import compiled_metrics
    from sblsim.models.systems.usbl_bound import pcrb as usbl_pcrb
    from sblsim.models.systems.usbl_bound import pcrb_inputs as usbl_pcrb_inputs

    truth, slot, received, transceivers, attitudes, fixed = usbl_case(seed=11)
    fixed = {**fixed, "sigma_range": np.array([0.1, 0.2, 0.05]), "range_k": np.array([0.0, 0.01, 0.002])}
    fixed, steps = usbl_pcrb_inputs(truth, slot, received, transceivers, attitudes, **fixed)
    reference = usbl_pcrb(fixed, steps)
    np.testing.assert_allclose(compiled_metrics.system_pcrb(1, fixed, steps), reference, rtol=1e-12, atol=0)
    assert np.ptp(reference[-1]) > 0  # the runs differ: each is stepped with its own inputs
