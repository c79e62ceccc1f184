"""The USBL receiver (``ekf`` of a USBL interface) replayed independently with FilterPy on a recorded run.

A short co-simulation (``square`` with a diver crossing straight below the transceiver twice; 20 % packet
loss; the receiver at one and at three steps per sampling time) records the receiver's inputs: the packet's
range, azimuth, elevation, the attitude it was turned with (``doa_*``) and the transceiver position, the
depth reading, the slot counter and validity. The replay feeds them to
``filterpy.kalman.ExtendedKalmanFilter``: ``F`` and ``Q`` of the constant-velocity, white-noise-acceleration
model (``test_receiver_filterpy.py``), one ``predict()`` per receiver step and, at each new slot (the slot
rule re-implemented there), one scalar ``update()`` with the depth and then, for a received packet, one
``update()`` with ``z = [r, a_x, a_y]``: the array's direction cosines as recorded (``doa_x``, ``doa_y``; where
the noisy pair lies inside the unit circle they equal the ones recovered in numpy from the NED azimuth and
elevation and the attitude, scipy's rotations, ``test_measurement_models.py``; beyond it the NED direction is
the pair shrunk to the circle, while the receiver weighs the pair as measured), h in numpy and
its Jacobian by central differences, and R = diag(σ_r², σ_u², σ_u²) (the ``ekf`` declares no GPS, attitude
or lever arm: the transceiver's and the attitude's terms are 0). The ``ekf`` receiver has no gate (gate
probability 1).

Tolerance. FilterPy inverts the 3 × 3 S where the receiver adds decorrelated rows one at a time (the same
update in exact arithmetic), and its Jacobian is a finite difference: the estimates agree to ≤ 1e-5 m.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
from tests.models.test_measurement_models import central, np_range_direction, np_rotation
from tests.models.test_receiver_filterpy import SLACK, phi, white_noise_q

STATE = ("x", "vx", "y", "vy", "z", "vz")
#: The diver crosses straight below the transceiver (at the origin) twice, 5 m deep.
THROUGH = ("target.trajectory=file", "target.waypoints=0 -12 -12 5; 30 12 12 5; 50 12 -12 5; 80 -12 12 5")
DEPTH_ROW = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])


def array_direction(row) -> np.ndarray:
    """``[r, a_x, a_y]`` of a recorded packet: the NED direction of its azimuth and elevation turned back into the
    array's frame by the attitude it carries (the measured pair, or that pair shrunk to the unit circle)."""
    n = np.array([math.cos(row.elevation) * math.cos(row.azimuth), math.cos(row.elevation) * math.sin(row.azimuth),
                  math.sin(row.elevation)])
    a = np_rotation([row.doa_roll, row.doa_pitch, row.doa_yaw]).T @ n
    return np.array([row.range, a[0], a[1]])


def measured(row) -> np.ndarray:
    """``[r, a_x, a_y]`` as the packet carries it, checked against :func:`array_direction`."""
    z = np.array([row.range, row.doa_x, row.doa_y])
    recovered = array_direction(row)
    inside = math.hypot(row.doa_x, row.doa_y) <= 1.0
    np.testing.assert_allclose(recovered[1:], z[1:] if inside else z[1:] / math.hypot(*z[1:]), rtol=0, atol=1e-9)
    return z


def replay(ts, cfg, ratio):
    """FilterPy replay of one replicate's recorded inputs; the state at each macro step's end (NaN before the first
    update with a received packet: no estimate before the receiver's first fix, never its prior x0), the count of
    updates and the smallest horizontal distance of an update's diver from the transceiver."""
    rc = cfg["receiver"]
    T = cfg["simulation"]["sampling_time"]
    dt = T / ratio
    ekf = ExtendedKalmanFilter(dim_x=6, dim_z=3)
    ekf.x = np.array([[rc[f"x0_{n}"]] for n in STATE], dtype=float)
    ekf.P = np.diag([rc["p0_position"] ** 2, rc["p0_velocity"] ** 2] * 3)
    ekf.F, ekf.Q = phi(dt), white_noise_q(dt, rc["q_horizontal"], rc["q_vertical"])
    R = np.diag([rc["sigma_range"] ** 2] + [math.radians(rc["sigma_angle_deg"]) ** 2] * 2)
    out = {n: [] for n in STATE}
    last, updates, closest = 0, 0, np.inf
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
                    att = [row.doa_roll, row.doa_pitch, row.doa_yaw]
                    ekf.update(measured(row).reshape(-1, 1),
                               lambda x, b=b, a=att: central(lambda c: np_range_direction(c, b, a), x.ravel()),
                               lambda x, b=b, a=att: np_range_direction(x, b, a).reshape(-1, 1), R=R)
                    updates += 1  # an estimate from the first on
                    closest = min(closest, math.hypot(row.true_x - b[0], row.true_y - b[1]))
        for i, n in enumerate(STATE):
            out[n].append(ekf.x[i, 0] if updates else np.nan)
    return {n: np.array(v) for n, v in out.items()}, updates, closest


@pytest.fixture(scope="module", params=[1, pytest.param(3, marks=pytest.mark.slow)], ids=["ratio1", "ratio3"])
def recorded(request):
    ratio = request.param
    cfg = load_config("square", ["platform.system=usbl", "simulation.duration=80", "acoustics.loss_pct=20",
                                 f"simulation.ekf_rate_ratio={ratio}", *THROUGH], seed=6)
    return run(cfg, "local", replicates=[0, 1]), ratio


def test_usbl_ekf_receiver_equals_a_filterpy_replay_of_a_recorded_run(recorded):
    result, ratio = recorded
    cfg = result.config
    assert cfg["simulation"]["receiver"] == "ekf" and cfg["receiver"]["gate_probability"] == 1.0
    for rep, ts in result.timeseries.groupby("replicate"):
        ts = ts.sort_values("time")
        ref, updates, closest = replay(ts, cfg, ratio)
        # what the recording exercises: lost packets, updates, a diver close to straight below the transceiver
        assert (~ts["packet_valid"].astype(bool)).sum() > 100 and updates > 400
        assert closest < 2.0, closest
        first = int(np.argmax(np.isfinite(ref["x"])))  # the first packet received: an estimate from there on
        assert 0 < first < 10 and np.isfinite(ref["x"][first:]).all()
        for n in STATE:  # NaN where the replay has no estimate yet, equal where it has
            np.testing.assert_allclose(ts[f"est_{n}"].to_numpy(), ref[n], rtol=0, atol=1e-5,
                                       err_msg=f"est_{n}, replicate {rep}")
        # and the receiver tracks the diver
        err = np.hypot(ts["est_x"] - ts["true_x"], ts["est_y"] - ts["true_y"]).to_numpy()
        assert np.median(err[first:]) < 1.0
