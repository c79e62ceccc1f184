"""The NIS gate of the Kalman-type receivers, on hand-set packets and in a simulated channel.

A range whose NIS is just above the χ²(1) quantile of the gate probability
(scipy) is gated; one just below, or one shorter than predicted by any
amount (multipath only lengthens ranges), is used. When the latest ranges of
``gate_max_rejections`` beacons failed, the next failing range is used (no
lock-out). In a simulated channel with 10 % multipath outliers, the gate
rejects the outliers and, at the stated probability, leaves correct ranges
alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from sblsim.models.receiver import SequentialReceiver, UnscentedReceiver
from sblsim.orchestrator.config import load_config
from sblsim.orchestrator.run import run
from tests.helpers import Core
from tests.models.test_receiver import RX, _x0_P0, packet
from tests.models.test_receiver_filterpy import phi, white_noise_q

BEACONS = np.array([[3.0, 0, 1], [0, 3.0, 1], [-3.0, 0, 1], [0, -3.0, 1]])
GATE = dict(RX, gate_probability=0.99, beacon_gps_sigma=0.1, beacon_attitude_sigma_deg=1.0, beacon_arm=3.2,
            gate_max_rejections=2)


def predicted_range(h=0.5, depth=None):
    """The range prediction and its innovation variance S after one step of h and the depth update (numpy)."""
    x, P = _x0_P0(GATE)
    F, Q = phi(h), white_noise_q(h, GATE["q_horizontal"], GATE["q_vertical"])
    x, P = F @ x, F @ P @ F.T + Q
    depth = x[4] if depth is None else depth
    H = np.array([[0, 0, 0, 0, 1.0, 0]])
    S = (H @ P @ H.T).item() + GATE["sigma_depth"] ** 2
    K = P @ H.T / S
    x = x + K[:, 0] * (depth - x[4])
    P = (np.eye(6) - K @ H) @ P @ (np.eye(6) - K @ H).T + K @ K.T * GATE["sigma_depth"] ** 2
    b = BEACONS[0]
    d = x[[0, 2, 4]] - b
    g = np.zeros(6)
    g[[0, 2, 4]] = d / np.linalg.norm(d)
    var = GATE["sigma_range"] ** 2 + GATE["beacon_gps_sigma"] ** 2 + (np.radians(1.0) * GATE["beacon_arm"]) ** 2
    return np.linalg.norm(d), g @ P @ g + var, x[4]


@pytest.mark.parametrize("model", [SequentialReceiver, UnscentedReceiver], ids=["ekf-seq", "ukf"])
def test_the_gate_passes_and_rejects_at_the_chi_square_quantile(model):
    h, S, depth = predicted_range()
    gate = np.sqrt(S * chi2.ppf(GATE["gate_probability"], 1))
    ranges = np.array([h + 0.99 * gate, h + 1.01 * gate, h - 3.0 * gate, h + 0.0])
    core = Core(model, GATE, replicates=range(4)).initialize(0.0)
    if model is UnscentedReceiver:  # its S carries the sigma points' spread: test well away from the quantile
        ranges = np.array([h + 0.5 * gate, h + 3.0 * gate, h - 3.0 * gate, h + 0.0])
    core.set_inputs(packet(1, 1, 0.5, ranges, np.tile(BEACONS[0], (4, 1)), depth))
    out = core.step(0.0, 0.5)
    assert out["gated"].tolist() == [False, True, False, False]
    # a gated range leaves the estimate where the depth update put it
    x_depth_only = Core(model, GATE).initialize(0.0)
    x_depth_only.set_inputs(packet(1, 1, 0.5, 0.0, BEACONS[0], depth, valid=False))
    ref = x_depth_only.step(0.0, 0.5)
    assert out["est_x"][1] == pytest.approx(ref["est_x"][0], abs=1e-12)
    assert out["est_x"][2] != pytest.approx(ref["est_x"][0], abs=1e-3)


def test_no_lock_out_after_failures_on_several_beacons():
    core = Core(SequentialReceiver, GATE).initialize(0.0)
    t, gated = 0.0, []
    for seq, beacon in enumerate((1, 2, 3, 4), start=1):  # every range 20 m long: all fail the test
        x = core.state["x"][0]
        d = np.linalg.norm(x[[0, 2, 4]] - BEACONS[beacon - 1])
        core.set_inputs(packet(seq, beacon, t + 0.5, d + 20.0, BEACONS[beacon - 1], x[4]))
        gated.append(bool(core.step(t, 0.5)["gated"][0]))
        t += 0.5
    # two rejected, then (two beacons failed) the gate opens and the ranges are used though they fail
    assert gated == [True, True, False, False]
    assert core.state["failed"][0].tolist() == [1.0, 1.0, 1.0, 1.0]


@pytest.mark.parametrize("model", [SequentialReceiver, UnscentedReceiver], ids=["ekf-seq", "ukf"])
def test_no_lock_out_with_the_one_transceiver_of_a_usbl_interface(model):
    """USBL: one "beacon", so ``gate_max_rejections`` (2) beacons can never have failed; the guard counts every
    beacon of a smaller interface: after one failed packet the next ones are used, though they fail as well, until
    one passes again (without it the gate refused every packet after a drift: an ekf-seq run on random-walk gated
    its packets for 9 s while its error grew to 4 m)."""
    transceiver = np.array([0.0, 0.0, 1.0])
    core = Core(model, GATE, n_beacons=1).initialize(0.0)
    t, gated = 0.0, []
    for seq in range(1, 5):  # every range 20 m long: all fail the test
        x = core.state["x"][0]
        d = x[[0, 2, 4]] - transceiver
        inputs = packet(seq, 1, t + 0.5, np.linalg.norm(d) + 20.0, transceiver, x[4])
        inputs.update(azimuth=np.arctan2(d[1], d[0]), elevation=np.arctan2(d[2], np.hypot(d[0], d[1])))
        core.set_inputs(inputs)
        gated.append(bool(core.step(t, 0.5)["gated"][0]))
        t += 0.5
    assert gated == [True, False, False, False]
    assert core.state["failed"][0].tolist() == [1.0]


def test_gate_off_uses_every_range():
    core = Core(SequentialReceiver, dict(GATE, gate_probability=1.0)).initialize(0.0)
    h, S, depth = predicted_range()
    core.set_inputs(packet(1, 1, 0.5, h + 50.0, BEACONS[0], depth))
    assert not core.step(0.0, 0.5)["gated"][0]


@pytest.mark.parametrize("receiver", ["ekf-seq", "ukf"])
def test_in_a_multipath_channel_the_gate_takes_the_outliers_and_leaves_correct_ranges(receiver):
    """random-walk (a consistent filter), 10 % outliers (exponential excess, mean 2 m), gate at 0.99, 20 runs."""
    p = 0.99
    cfg = load_config("random-walk", [f"receiver={receiver}", "acoustics.outlier_pct=10", "acoustics.outlier_excess=2",
                                      f"receiver.gate_probability={p}"], seed=2)
    ts = run(cfg, replicates=range(20)).timeseries
    slot = ts.groupby("replicate")["packet_seq"].diff().fillna(ts["packet_seq"]).ne(0)
    t = ts[slot & ts["packet_valid"].astype(bool)]  # one row per received range
    outlier, gated = t["outlier"].astype(bool), t["gated"].astype(bool)
    long = outlier & (t["range"] - t["range_true"] > 1.0)
    assert long.sum() > 1000
    # a metre-long outlier is gated unless the latest ranges of two other beacons failed too (the lock-out
    # guard opens the gate then: about 3 % of the time with four beacons and 10 % outliers)
    assert gated[long].mean() > 0.95
    # a correct range passes with at least the stated probability (one-sided test: about 1 − (1 − p)/2)
    assert 0 < gated[~outlier].mean() < 1 - p
