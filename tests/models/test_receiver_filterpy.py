"""The paper's EKF receiver replayed independently with FilterPy on a recorded packet sequence.

A short co-simulation (semicircle scenario, 20 % packet loss, 5 % outliers)
records the receiver's inputs (the acoustics' packet, the depth reading) and
outputs at every macro step. The replay feeds the same inputs to
``filterpy.kalman.ExtendedKalmanFilter``: ``F`` and ``Q`` of the
constant-velocity, white-noise-acceleration model written here, one
``predict()`` per receiver step and, at each new slot, one ``update()`` with
the held range of every beacon heard so far (only those rows) and the depth.
The slot rule (new ``packet_seq`` and step end ≥ ``rx_time`` − 1 ns) and the
range book-keeping are re-implemented here in plain Python.

Tolerance. FilterPy inverts S (``linalg.inv``) where the receiver solves with
a Cholesky factor, and multiplies in a different order; both are backward
stable, so the two filters differ by round-off (~1e-15 relative per step).
The filter is contracting, so these differences do not grow: the positions
agree to 1e-9 m (observed ≤ 1e-14 m), velocities to 1e-9 m/s. NIS is
compared relatively (1e-9, observed ≤ 3e-13): with outliers it reaches ~10³, and
``yᵀ S⁻¹ y`` with ``y`` of a few metres and σ_d = 1 cm amplifies absolute
round-off.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run

N_BEACONS = 4
SLACK = 1e-9  # the slot rule's allowance [s]


def phi(dt):
    F = np.eye(6)
    for k in (0, 2, 4):
        F[k, k + 1] = dt
    return F


def white_noise_q(dt, qh, qv):
    Q = np.zeros((6, 6))
    block = np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    for axis, q in enumerate((qh, qh, qv)):
        Q[2 * axis:2 * axis + 2, 2 * axis:2 * axis + 2] = q * block
    return Q


def h_of(x, beacons):
    """Predicted ranges to the given beacons, then the depth; x is (6, 1)."""
    p = x[[0, 2, 4], 0]
    return np.append(np.linalg.norm(p[None, :] - beacons, axis=1), x[4, 0]).reshape(-1, 1)


def H_of(x, beacons):
    p = x[[0, 2, 4], 0]
    H = np.zeros((len(beacons) + 1, 6))
    diff = p[None, :] - beacons
    H[:-1][:, [0, 2, 4]] = diff / np.linalg.norm(diff, axis=1)[:, None]
    H[-1, 4] = 1.0
    return H


def packet_lanes(ts):
    """The column prefixes of the lanes a run's time series holds: ``""`` (lane 1, the packet columns themselves)
    and ``"lane<m>_"`` for each later lane of a delivery it used (the packets that arrived in a step after lane
    1's, in the order they arrived)."""
    later = sorted({int(c[4:c.index("_")]) for c in ts.columns if c.startswith("lane") and c.endswith("_packet_seq")})
    return [""] + [f"lane{m}_" for m in later]


def delivered_packets(ts):
    """The distinct packets a run's time series delivered on any lane."""
    seqs = np.concatenate([ts[prefix + "packet_seq"].to_numpy() for prefix in packet_lanes(ts)])
    return len(np.unique(seqs[seqs > 0]))


def replay(ts, cfg, ratio):
    """FilterPy replay of one replicate's recorded inputs; estimates at each macro step end (NaN before the first
    update with a received packet: a receiver reports no estimate before its first fix, never its prior x0)."""
    rc = cfg["receiver"]
    T = cfg["simulation"]["sampling_time"]
    dt = T / ratio
    ekf = ExtendedKalmanFilter(dim_x=6, dim_z=N_BEACONS + 1)
    ekf.x = np.array([[rc[f"x0_{n}"]] for n in ("x", "vx", "y", "vy", "z", "vz")], dtype=float)
    ekf.P = np.diag([rc["p0_position"] ** 2, rc["p0_velocity"] ** 2] * 3)
    ekf.F = phi(dt)
    ekf.Q = white_noise_q(dt, rc["q_horizontal"], rc["q_vertical"])
    ranges, beacons = {}, {}
    lanes = packet_lanes(ts)
    last_seq, nis = [0] * len(lanes), 0.0
    out = {k: [] for k in ("x", "vx", "y", "vy", "z", "vz", "nis", "pos_std", "updates")}
    updates, fixed = 0, False
    for k, row in enumerate(ts.itertuples()):
        for j in range(ratio):
            t = k * T + j * dt  # the master's communication points
            ekf.predict()
            for lane, prefix in enumerate(lanes):  # in the order the packets arrived
                seq, rx = getattr(row, prefix + "packet_seq"), getattr(row, prefix + "rx_time")
                if seq == last_seq[lane] or (lane > 0 and seq == 0) or t + dt < rx - SLACK:
                    continue
                last_seq[lane] = seq
                beacon = getattr(row, prefix + "beacon_id")
                if getattr(row, prefix + "packet_valid") and 1 <= beacon <= N_BEACONS:
                    ranges[beacon] = getattr(row, prefix + "range")
                    beacons[beacon] = np.array([getattr(row, f"{prefix}beacon_{a}") for a in "xyz"])
                    fixed = True
                ids = sorted(ranges)
                b = np.array([beacons[i] for i in ids]).reshape(-1, 3)
                z = np.array([ranges[i] for i in ids] + [row.depth]).reshape(-1, 1)
                R = np.diag([rc["sigma_range"] ** 2] * len(ids) + [rc["sigma_depth"] ** 2])
                ekf.update(z, H_of, h_of, R=R, args=(b,), hx_args=(b,))
                nis = (ekf.y.T @ ekf.SI @ ekf.y).item()
                updates += 1
        for i, n in enumerate(("x", "vx", "y", "vy", "z", "vz")):
            out[n].append(ekf.x[i, 0] if fixed else np.nan)
        out["nis"].append(nis)
        out["pos_std"].append(np.sqrt(ekf.P[0, 0] + ekf.P[2, 2] + ekf.P[4, 4]))
        out["updates"].append(updates)
    return {k: np.array(v) for k, v in out.items()}


@pytest.fixture(scope="module", params=[(1, 0.1), (3, 0.1), (1, 0.01)], ids=["ratio1", "ratio3", "lanes"])
def recorded(request):
    """A recorded run at the EKF rate ratio and sampling time T [s] of the parameter; at T = 0.01 s a packet can
    arrive after the next one is sent (the travel times reach 0.012 s), so that several arrive in one step and
    the receiver takes them all at its end, from the delivery's lanes."""
    ratio, T = request.param
    cfg = load_config("semicircle", ["simulation.duration=30", "acoustics.loss_pct=20", "acoustics.outlier_pct=5",
                                     f"simulation.ekf_rate_ratio={ratio}", f"simulation.sampling_time={T}"], seed=3)
    result = run(cfg, "local", replicates=[0, 1])
    if T < 0.1:
        assert len(packet_lanes(result.timeseries)) > 1, "no step delivered two packets"
    return result, ratio


def test_ekf_receiver_equals_filterpy_replay_of_a_recorded_run(recorded):
    result, ratio = recorded
    cfg = result.config
    assert cfg["simulation"]["ekf_rate_ratio"] == ratio
    T = cfg["simulation"]["sampling_time"]
    runs = [ts.sort_values("time") for _, ts in result.timeseries.groupby("replicate")]
    assert len(runs) == 2  # two replicates: two distinct packet sequences
    assert not np.array_equal(runs[0]["range"].to_numpy(), runs[1]["range"].to_numpy())
    for rep, ts in enumerate(runs):
        np.testing.assert_allclose(ts["time"].to_numpy(), T * np.arange(1, len(ts) + 1), rtol=0, atol=1e-9)
        ref = replay(ts, cfg, ratio)
        # the recording exercises what the replay must get right
        assert (~ts["packet_valid"].astype(bool)).sum() > 10, "lost packets"
        assert ts["outlier"].astype(bool).sum() > 3, "outliers"
        assert ref["updates"][-1] == delivered_packets(ts) > 200  # every packet taken once
        assert ref["nis"].max() > 20.0  # an outlier's innovation, not only round-off-sized ones
        first = int(np.argmax(np.isfinite(ref["x"])))  # the first update with a received packet
        assert 0 < first < 5 and np.isfinite(ref["x"][first:]).all()
        for a in ("x", "y", "z"):  # NaN where the replay has no estimate yet, equal where it has
            np.testing.assert_allclose(ts[f"est_{a}"].to_numpy(), ref[a], rtol=0, atol=1e-9,
                                       err_msg=f"est_{a}, replicate {rep}")
            np.testing.assert_allclose(ts[f"est_v{a}"].to_numpy(), ref[f"v{a}"], rtol=0, atol=1e-9,
                                       err_msg=f"est_v{a}, replicate {rep}")
        np.testing.assert_allclose(ts["nis"].to_numpy(), ref["nis"], rtol=1e-9, atol=1e-12,
                                   err_msg=f"nis, replicate {rep}")
        np.testing.assert_allclose(ts["pos_std"].to_numpy(), ref["pos_std"], rtol=1e-9, atol=0,
                                   err_msg=f"pos_std, replicate {rep}")
        # and the filter tracks the true target (median horizontal error well under a metre)
        err = np.hypot(ts["est_x"].to_numpy() - ts["true_x"].to_numpy(),
                       ts["est_y"].to_numpy() - ts["true_y"].to_numpy())
        assert np.median(err[first:]) < 1.0

