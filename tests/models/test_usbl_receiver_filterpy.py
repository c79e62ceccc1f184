"""The USBL receiver (``ekf`` of a USBL interface) replayed independently with FilterPy on a recorded run.

A short co-simulation (``square`` around the transceiver, so that the azimuth
crosses ±π due South; 20 % packet loss; the receiver at one and at three
steps per sampling time) records the receiver's inputs: the packet's range,
azimuth, elevation and transceiver position, the depth reading, the slot
counter and validity. The replay feeds them to
``filterpy.kalman.ExtendedKalmanFilter``: ``F`` and ``Q`` of the
constant-velocity, white-noise-acceleration model (``test_receiver_filterpy.py``),
one ``predict()`` per receiver step and, at each new slot (the slot rule
re-implemented there), one scalar ``update()`` with the depth and then, for a
received packet, one ``update()`` with ``[r, α, ε]``: h and its Jacobian
written out in numpy (``test_measurement_models.py``), the angle residuals
wrapped to (−π, π], and R = diag(σ_r² + σ_b², σ_a² + σ_b² / ρ², σ_a² + σ_b² / r²)
with ``σ_a² = (σ_θ / max(cos φ, 0.1))² + σ_att²`` and the transceiver position's
error ``σ_b² = σ_GPS² + (σ_att a)²`` at the position after the depth update
(numpy; checked here against :func:`sblsim.models.systems.usbl.variances` as
numbers; the ``ekf`` declares no GPS, attitude or lever arm: σ_att = σ_b = 0).
The ``ekf`` receiver has no gate (gate probability 1).

Tolerance. FilterPy inverts the 3 × 3 S where the receiver adds the rows one
at a time (the same update in exact arithmetic); both are backward stable and
the filter contracts, so the estimates agree to round-off: ≤ 1e-6 m asked,
≤ 1e-14 m seen.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from sblsim.models.systems import usbl
from sblsim.orchestrator.config import load_config
from sblsim.orchestrator.run import run
from tests.models.test_measurement_models import np_jacobian, np_range_bearing, np_wrap
from tests.models.test_receiver_filterpy import SLACK, phi, white_noise_q

STATE = ("x", "vx", "y", "vy", "z", "vz")
DEPTH_ROW = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])


def usbl_variances(position, transceiver, rc):
    """The receiver's R (numpy): ``[σ_r² + σ_b², σ_a² + σ_b² / ρ², σ_a² + σ_b² / r²]`` with the channel's angle noise
    ``σ_a² = (σ_θ / max(cos φ, 0.1))² + σ_att²`` and the transceiver position's error ``σ_b² = σ_GPS² + (σ_att a)²``
    seen along the range and across the two angles (ρ at least 1 mm, r its slant range); the GPS, attitude and lever
    arm 0 where the receiver has none."""
    d = position - transceiver
    off_axis = max(d[2] / max(np.linalg.norm(d), 1e-9), 0.1)
    attitude = math.radians(rc.get("beacon_attitude_sigma_deg", 0.0))
    angle = (math.radians(rc["sigma_angle_deg"]) / off_axis) ** 2 + attitude ** 2
    b2 = rc.get("beacon_gps_sigma", 0.0) ** 2 + (attitude * rc.get("beacon_arm", 0.0)) ** 2
    rho = max(math.hypot(d[0], d[1]), 1e-3)
    return np.array([rc["sigma_range"] ** 2 + b2, angle + b2 / rho ** 2, angle + b2 / (rho ** 2 + d[2] ** 2)])


def wrapped(a, b):
    y = np.asarray(a, float) - b
    y[1:] = np_wrap(y[1:])
    return y


def replay(ts, cfg, ratio):
    """FilterPy replay of one replicate's recorded inputs; state at each macro step's end and the count of angle
    residuals that needed the wrap."""
    rc = cfg["receiver"]
    T = cfg["simulation"]["sampling_time"]
    dt = T / ratio
    ekf = ExtendedKalmanFilter(dim_x=6, dim_z=3)
    ekf.x = np.array([[rc[f"x0_{n}"]] for n in STATE], dtype=float)
    ekf.P = np.diag([rc["p0_position"] ** 2, rc["p0_velocity"] ** 2] * 3)
    ekf.F, ekf.Q = phi(dt), white_noise_q(dt, rc["q_horizontal"], rc["q_vertical"])
    out = {n: [] for n in STATE}
    last, updates, wraps = 0, 0, 0
    for k, row in enumerate(ts.itertuples()):
        for j in range(ratio):
            t = k * T + j * dt
            ekf.predict()
            if row.packet_seq != last and t + dt >= row.rx_time - SLACK:
                last = row.packet_seq
                ekf.update(np.array([[row.depth]]), lambda x: DEPTH_ROW, lambda x: x[4:5],
                           R=np.array([[rc["sigma_depth"] ** 2]]))
                if row.packet_valid and row.beacon_id == 1:
                    b = np.array([row.beacon_x, row.beacon_y, row.beacon_z])
                    z = np.array([[row.range], [row.azimuth], [row.elevation]])
                    R = np.diag(usbl_variances(ekf.x[[0, 2, 4], 0], b, rc))
                    wraps += abs(z[1, 0] - np_range_bearing(ekf.x, b)[1]) > np.pi
                    ekf.update(z, lambda x, b=b: np_jacobian(x, b),
                               lambda x, b=b: np_range_bearing(x, b).reshape(-1, 1), R=R, residual=wrapped)
                    updates += 1
        for i, n in enumerate(STATE):
            out[n].append(ekf.x[i, 0])
    return {n: np.array(v) for n, v in out.items()}, updates, wraps


def test_the_numpy_variances_are_the_receivers():
    p_sym, b_sym = ca.SX.sym("p", 3), ca.SX.sym("b", 3)
    rc = {"sigma_range": 0.1, "sigma_angle_deg": 0.7, "beacon_gps_sigma": 0.2, "beacon_attitude_sigma_deg": 1.5,
          "beacon_arm": 2.0}
    f = ca.Function("v", [p_sym, b_sym], [usbl.variances(p_sym, b_sym, rc)])
    rng = np.random.default_rng(3)
    for p in rng.normal(scale=[20, 20, 4], size=(20, 3)) + [0, 0, 3]:  # some above the transceiver: the floor
        b = np.array([0.1, -0.2, 1.0])
        np.testing.assert_allclose(np.array(f(p, b)).ravel(), usbl_variances(p, b, rc), rtol=1e-13)
    for p in ([0.1, -0.2, 5.0], [0.1 + 2e-4, -0.2, 5.0]):  # straight below it, and within the 1 mm floor
        np.testing.assert_allclose(np.array(f(p, b)).ravel(), usbl_variances(np.array(p), b, rc), rtol=1e-13)
    without = {k: v for k, v in rc.items() if not k.startswith("beacon_")}  # the ekf: no transceiver error
    f = ca.Function("v", [p_sym, b_sym], [usbl.variances(p_sym, b_sym, without)])
    np.testing.assert_allclose(np.array(f([3.0, 4.0, 5.0], b)).ravel(),
                               usbl_variances(np.array([3.0, 4.0, 5.0]), b, without), rtol=1e-14)


@pytest.fixture(scope="module", params=[1, 3], ids=["ratio1", "ratio3"])
def recorded(request):
    ratio = request.param
    cfg = load_config("square", ["platform.system=usbl", "simulation.duration=80", "acoustics.loss_pct=20",
                                 f"simulation.ekf_rate_ratio={ratio}"], seed=6)
    return run(cfg, "local", replicates=[0, 1]), ratio


def test_usbl_ekf_receiver_equals_a_filterpy_replay_of_a_recorded_run(recorded):
    result, ratio = recorded
    cfg = result.config
    assert cfg["simulation"]["receiver"] == "ekf" and cfg["receiver"]["gate_probability"] == 1.0
    for rep, ts in result.timeseries.groupby("replicate"):
        ts = ts.sort_values("time")
        ref, updates, wraps = replay(ts, cfg, ratio)
        # what the recording exercises: lost packets, updates, the azimuth's branch at ±π
        assert (~ts["packet_valid"].astype(bool)).sum() > 100 and updates > 400
        assert wraps >= 1, "the azimuth never crossed ±π"
        for n in STATE:
            np.testing.assert_allclose(ts[f"est_{n}"].to_numpy(), ref[n], rtol=0, atol=1e-6,
                                       err_msg=f"est_{n}, replicate {rep}")
        # and the receiver tracks the diver
        err = np.hypot(ts["est_x"] - ts["true_x"], ts["est_y"] - ts["true_y"]).to_numpy()
        assert np.median(err) < 1.0
