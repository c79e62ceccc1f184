"""``ekf-seq`` and ``ukf`` replayed independently with FilterPy on recorded packet sequences.

A short co-simulation (semicircle, 20 % packet loss, 10 % multipath outliers,
the receiver at three steps per sampling time on one of the two runs)
records the receiver's inputs and outputs at every macro step. The replays
feed the same inputs to FilterPy:

* ``ekf-seq``: ``filterpy.kalman.ExtendedKalmanFilter``, one ``predict()`` per
  receiver step and, at each new slot, one scalar ``update()`` with the depth
  and then, for a received packet that passes the gate, one with the fresh
  range predicted from the state moved back to the packet's reference epoch
  (``Φ(−age) x``, the Jacobian times ``Φ(−age)``; a one-way range refers to its reception ``rx_time``), its
  variance ``σ_r² + σ_GPS² + (σ_att · arm)²`` (the beacon's isotropic position error through the unit vector
  ∂h/∂b, whose norm is 1);
* ``ukf``: ``filterpy.kalman.UnscentedKalmanFilter`` with
  ``MerweScaledSigmaPoints(14, alpha, beta, kappa + 6 - 14)`` over the receiver's 14 states (the six of position
  and velocity, and its error states: GPS, clock, attitude, here with no prior: their rows and columns of P zero, a
  square root that takes zero pivots; κ + 6 − 14 makes the 14-state set's spread and weights the six uncertain
  states', as the receiver's ``uncertain_states`` does); sigma points are redrawn from the predicted mean and
  covariance before each update, as the receiver does, and each carries its range from ``Φ(−age) x``; the joint
  update (range, depth) when the range is used, else the depth alone.

The slot rule, the one-sided NIS gate (χ²(1) quantile from scipy) and its
re-acquisition (when ``gate_max_rejections`` beacons' latest ranges failed, a failing range is used if it agrees
with its own beacon's previous failed one, both predicted from the current state, within the quantile of their
summed innovation variances) are re-implemented here in plain Python. Tolerances as in
``test_receiver_filterpy.py``: round-off of backward-stable arithmetic in a
contracting filter.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.stats import chi2

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
from tests.models.test_receiver_filterpy import N_BEACONS, SLACK, phi, white_noise_q

STATE = ("x", "vx", "y", "vy", "z", "vz")
DEPTH_ROW = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
#: The ukf's state: the six above, then its error states (GPS 3, clock 2, attitude 3).
UKF_STATES = 14


def psd_sqrt(M):
    """FilterPy's square root (``UᵀU = M``, its rows the sigma points' offsets) of a positive semi-definite M:
    Cholesky with a zero column where the pivot is zero (the states without a prior)."""
    n = M.shape[0]
    L = np.zeros_like(M)
    for j in range(n):
        pivot = M[j, j] - L[j, :j] @ L[j, :j]
        if pivot <= 0.0:
            continue
        L[j, j] = np.sqrt(pivot)
        L[j + 1:, j] = (M[j + 1:, j] - L[j + 1:, :j] @ L[j, :j]) / L[j, j]
    return L.T


def range_row(x, beacon):
    p = np.asarray(x).reshape(-1)[[0, 2, 4]]
    d = p - beacon
    H = np.zeros((1, 6))
    H[0, [0, 2, 4]] = d / np.linalg.norm(d)
    return np.linalg.norm(d), H


class Gate:
    """The one-sided NIS gate with its re-acquisition, in plain Python: each beacon remembers whether its latest
    range failed, and the last failed range, where it was broadcast from and its reference epoch."""

    def __init__(self, rc):
        self.threshold = chi2.ppf(rc["gate_probability"], 1) if rc["gate_probability"] < 1 else np.inf
        self.max_failed = min(rc["gate_max_rejections"], N_BEACONS)
        self.failed = np.zeros(N_BEACONS, bool)
        self.rejected = [None] * N_BEACONS

    def __call__(self, beacon_id, y, S, rng, beacon, epoch, earlier):
        """Whether the range is used; ``earlier(range, beacon, epoch)`` gives the innovation and its variance of
        the beacon's last failed range predicted from the current state."""
        i = beacon_id - 1
        test = y <= 0 or y * y / S <= self.threshold
        again = False
        if not test and self.failed.sum() >= self.max_failed and self.failed[i]:
            y_then, S_then = earlier(*self.rejected[i])
            again = (y - y_then) ** 2 <= self.threshold * (S + S_then)
        self.failed[i] = not test
        if not test:
            self.rejected[i] = (rng, beacon, epoch)
        return test or again


def range_variance(rc):
    return (rc["sigma_range"] ** 2 + rc["beacon_gps_sigma"] ** 2
            + (np.radians(rc["beacon_attitude_sigma_deg"]) * rc["beacon_arm"]) ** 2)


def slots(ts, cfg, ratio):
    """Yield (last sub-step of the macro step, is_slot, row, now, epoch) for every receiver step, with the slot rule
    applied: ``now`` the step's end, ``epoch`` the packet's reference epoch (a one-way range's reception, else the
    midpoint of its transmission and arrival); ``Φ(−(now − epoch))`` moves the state back to it."""
    T = cfg["simulation"]["sampling_time"]
    dt = T / ratio
    one_way = cfg["acoustics"]["ranging"] == "owtt"
    last = 0
    for k, row in enumerate(ts.itertuples()):
        for j in range(ratio):
            t = k * T + j * dt
            slot = row.packet_seq != last and t + dt >= row.rx_time - SLACK
            if slot:
                last = row.packet_seq
            epoch = row.rx_time if one_way else 0.5 * (row.tx_time + row.rx_time)
            yield j == ratio - 1, slot, row, t + dt, epoch


def back(now, epoch):
    """``Φ(−age)`` (6×6) to a reference epoch from ``now``."""
    return phi(-max(now - epoch, 0.0))


def linearized(x, P, var, now):
    """The gate's ``earlier(range, beacon, epoch)``: a beacon's last failed range predicted from the state ``x``
    (6) and covariance ``P`` (6×6) at ``now``, moved back to that range's epoch: its innovation and its
    linearized innovation variance (``var`` the range's noise)."""
    def earlier(rng, beacon, then):
        A = back(now, then)
        h, H = range_row(A @ x, beacon)
        H = H @ A
        return rng - h, (H @ P @ H.T).item() + var
    return earlier


def fresh(row):
    return bool(row.packet_valid) and 1 <= row.beacon_id <= N_BEACONS


def replay_ekf_seq(ts, cfg, ratio):
    rc = cfg["receiver"]
    dt = cfg["simulation"]["sampling_time"] / ratio
    ekf = ExtendedKalmanFilter(dim_x=6, dim_z=1)
    ekf.x = np.array([[rc[f"x0_{n}"]] for n in STATE], dtype=float)
    ekf.P = np.diag([rc["p0_position"] ** 2, rc["p0_velocity"] ** 2] * 3)
    ekf.F, ekf.Q = phi(dt), white_noise_q(dt, rc["q_horizontal"], rc["q_vertical"])
    gate, var = Gate(rc), range_variance(rc)
    out = {k: [] for k in (*STATE, "P", "nis", "gated")}
    nis, gated, fixed = 0.0, False, False
    for last_substep, slot, row, now, epoch in slots(ts, cfg, ratio):
        ekf.predict()
        if slot:
            ekf.update(np.array([[row.depth]]), lambda x: DEPTH_ROW, lambda x: x[4:5], R=rc["sigma_depth"] ** 2)
            nis = (ekf.y.T @ ekf.SI @ ekf.y).item()
            gated = False
            if fresh(row):
                b = np.array([row.beacon_x, row.beacon_y, row.beacon_z])
                A = back(now, epoch)
                h, H = range_row(A @ ekf.x, b)  # the range of the state moved back to the reference epoch
                H = H @ A
                y, S = row.range - h, (H @ ekf.P @ H.T).item() + var

                if gate(row.beacon_id, y, S, row.range, b, epoch, linearized(ekf.x, ekf.P, var, now)):
                    ekf.update(np.array([[row.range]]), lambda x, b=b, A=A: range_row(A @ x, b)[1] @ A,
                               lambda x, b=b, A=A: np.array([[range_row(A @ x, b)[0]]]), R=var)
                    nis += y * y / S
                    fixed = True
                else:
                    gated = True
        if last_substep:
            for i, n in enumerate(STATE):
                out[n].append(ekf.x[i, 0] if fixed else np.nan)  # no estimate before the first range taken
            out["P"].append(ekf.P[np.ix_([0, 2, 4], [0, 2, 4])].copy())
            out["nis"].append(nis)
            out["gated"].append(gated)
    return {k: np.array(v) for k, v in out.items()}


def replay_ukf(ts, cfg, ratio):
    rc = cfg["receiver"]
    dt = cfg["simulation"]["sampling_time"] / ratio
    size = UKF_STATES
    # the six kinematic states are the uncertain ones: the set of six's spread and weights over the 14 states
    points = MerweScaledSigmaPoints(size, alpha=rc["alpha"], beta=rc["beta"], kappa=rc["kappa"] + 6 - size,
                                    sqrt_method=psd_sqrt)

    def grow(M, eye=False):  # a 6×6 block of the kinematic states in the whole (the error states constant, no prior)
        out = np.eye(size) if eye else np.zeros((size, size))
        out[:6, :6] = M
        return out

    ukf = UnscentedKalmanFilter(dim_x=size, dim_z=2, dt=dt, fx=lambda x, dt: grow(phi(dt), True) @ x, hx=None,
                                points=points)
    ukf.x = np.zeros(size)
    ukf.x[:6] = [rc[f"x0_{s}"] for s in STATE]
    ukf.P = grow(np.diag([rc["p0_position"] ** 2, rc["p0_velocity"] ** 2] * 3))
    ukf.Q = grow(white_noise_q(dt, rc["q_horizontal"], rc["q_vertical"]))
    gate, var, sd2 = Gate(rc), range_variance(rc), rc["sigma_depth"] ** 2
    out = {k: [] for k in (*STATE, "P", "nis", "gated")}
    nis, gated, fixed = 0.0, False, False
    for last_substep, slot, row, now, epoch in slots(ts, cfg, ratio):
        ukf.predict()
        if slot:
            ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)  # redrawn from the predicted mean and covariance
            gated = False
            use = False
            if fresh(row):
                b = np.array([row.beacon_x, row.beacon_y, row.beacon_z])
                A = back(now, epoch)
                joint = copy.deepcopy(ukf)
                joint.update(np.array([row.range, row.depth]), R=np.diag([var, sd2]),
                             hx=lambda x, b=b, A=A: np.array([np.linalg.norm((A @ x[:6])[[0, 2, 4]] - b), x[4]]))

                use = gate(row.beacon_id, joint.y[0], joint.S[0, 0], row.range, b, epoch,
                           linearized(ukf.x[:6], ukf.P[:6, :6], var, now))  # the re-acquisition: at the mean
                gated = not use
            if use:
                ukf, fixed = joint, True
            else:
                ukf.update(np.array([row.depth]), R=np.array([[sd2]]), hx=lambda x: x[4:5])
            nis = float(ukf.y @ np.linalg.solve(ukf.S, ukf.y))
        if last_substep:
            for i, n in enumerate(STATE):
                out[n].append(ukf.x[i] if fixed else np.nan)  # no estimate before the first range taken
            out["P"].append(ukf.P[np.ix_([0, 2, 4], [0, 2, 4])].copy())
            out["nis"].append(nis)
            out["gated"].append(gated)
    return {k: np.array(v) for k, v in out.items()}


@pytest.fixture(scope="module", params=[("ekf-seq", 1), ("ekf-seq", 3), ("ukf", 1),
                                          pytest.param(("ukf", 3), marks=pytest.mark.slow)],
                ids=["ekf-seq-ratio1", "ekf-seq-ratio3", "ukf-ratio1", "ukf-ratio3"])
def recorded(request):
    receiver, ratio = request.param
    overrides = ["simulation.duration=30", "acoustics.loss_pct=20", "acoustics.outlier_pct=10",
                 f"simulation.ekf_rate_ratio={ratio}", f"receiver={receiver}", "receiver.gate_probability=0.99"]
    if receiver == "ukf":  # scaling other than the defaults
        overrides += ["receiver.alpha=0.8", "receiver.kappa=1"]
    cfg = load_config("semicircle", overrides, seed=5)
    return receiver, ratio, run(cfg, "local", replicates=[0, 1])


def covariance(ts):
    c = {ab: ts[f"cov_{ab}"].to_numpy() for ab in ("xx", "xy", "xz", "yy", "yz", "zz")}
    return np.stack([np.stack([c["xx"], c["xy"], c["xz"]], -1), np.stack([c["xy"], c["yy"], c["yz"]], -1),
                     np.stack([c["xz"], c["yz"], c["zz"]], -1)], -2)


def test_receiver_equals_an_independent_filterpy_replay(recorded):
    receiver, ratio, result = recorded
    cfg = result.config
    assert cfg["simulation"]["receiver"] == receiver and cfg["simulation"]["ekf_rate_ratio"] == ratio
    replay = replay_ekf_seq if receiver == "ekf-seq" else replay_ukf
    for rep, ts in result.timeseries.groupby("replicate"):
        ts = ts.sort_values("time")
        ref = replay(ts, cfg, ratio)
        # what the recording exercises: losses, outliers, ranges gated and ranges used
        assert (~ts["packet_valid"].astype(bool)).sum() > 10 and ts["outlier"].astype(bool).sum() > 10
        assert 5 < ref["gated"].sum() < 0.5 * ts["packet_valid"].astype(bool).sum()
        np.testing.assert_array_equal(ts["gated"].to_numpy(bool), ref["gated"], err_msg=f"gated, replicate {rep}")
        first = int(np.argmax(np.isfinite(ref["x"])))  # the first range taken: an estimate from there on
        assert 0 < first < 5 and np.isfinite(ref["x"][first:]).all()
        for n in STATE:  # NaN where the replay has no estimate yet, equal where it has
            np.testing.assert_allclose(ts[f"est_{n}"].to_numpy(), ref[n], rtol=0, atol=1e-9,
                                       err_msg=f"est_{n}, replicate {rep}")
        np.testing.assert_allclose(covariance(ts), ref["P"], rtol=1e-8, atol=1e-14, err_msg=f"cov, replicate {rep}")
        np.testing.assert_allclose(ts["nis"].to_numpy(), ref["nis"], rtol=1e-8, atol=1e-12,
                                   err_msg=f"nis, replicate {rep}")
        # the gate caught the multipath: most gated ranges are outliers
        outlier = ts["outlier"].to_numpy(bool)
        assert outlier[ref["gated"]].mean() > 0.8
