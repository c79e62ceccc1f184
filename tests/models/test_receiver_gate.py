"""The NIS gate of the Kalman-type receivers, on hand-set packets and in a simulated channel.

A range whose NIS is just above the χ²(1) quantile of the gate probability
(scipy) is gated; one just below, or one shorter than predicted by any
amount (multipath only lengthens ranges), is used. When the latest ranges of
``gate_max_rejections`` beacons failed, a failing range that agrees with its
beacon's previous failed one is used (a lost track is re-acquired: no
lock-out), and an outlier is not: a stream of outliers after a run of
rejections gets none in. In a simulated channel with 10 % multipath
outliers, the gate rejects the outliers and, at the stated probability,
leaves correct ranges alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from sblsim.models.receiver import SequentialReceiver, UnscentedReceiver
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
from tests.helpers import Core
from tests.models.test_receiver import RX, _x0_P0, packet
from tests.models.test_receiver_filterpy import phi, white_noise_q

BEACONS = np.array([[3.0, 0, 1], [0, 3.0, 1], [-3.0, 0, 1], [0, -3.0, 1]])
GATE = dict(RX, gate_probability=0.99, beacon_gps_sigma=0.1, beacon_attitude_sigma_deg=1.0, beacon_arm=3.2,
            gate_max_rejections=2)
#: A filter sure of its position (5 cm, 1 cm/s) and at rest: a range a metre or more longer fails its test.
SURE = dict(GATE, p0_position=0.05, p0_velocity=0.01, x0_vx=0.0, x0_vy=0.0, x0_vz=0.0)


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
    # a gated range leaves the filter's state where the depth update put it, and, its first packet refused, the
    # receiver has no estimate yet (NaN); the ranges taken give one
    x_depth_only = Core(model, GATE).initialize(0.0)
    x_depth_only.set_inputs(packet(1, 1, 0.5, 0.0, BEACONS[0], depth, valid=False))
    x_depth_only.step(0.0, 0.5)
    ref = x_depth_only.state["x"][0]
    state = core.state["x"]
    assert state[1][0] == pytest.approx(ref[0], abs=1e-12)
    assert state[2][0] != pytest.approx(ref[0], abs=1e-3)
    assert np.isnan(out["est_x"][1]) and np.isfinite(out["est_x"][[0, 2, 3]]).all()
    np.testing.assert_array_equal(out["est_x"][[0, 2, 3]], state[[0, 2, 3], 0])


def feed(core, stream, t=0.0, n_beacons=4, transceiver=None):
    """Feed ``(beacon, range)`` packets one per half second; the ``gated`` flag of each."""
    gated = []
    for seq, (beacon, rng) in enumerate(stream, start=1):
        where = BEACONS[beacon - 1] if transceiver is None else transceiver
        inputs = packet(seq, beacon, t + 0.5, rng, where, core.state["x"][0][4])
        if transceiver is not None:  # a USBL packet: a level array, the direction straight down (the transceiver
            # is above the filter's prior)
            inputs.update(azimuth=0.0, elevation=np.pi / 2, doa_x=0.0, doa_y=0.0, doa_roll=0.0, doa_pitch=0.0,
                          doa_yaw=0.0)
        core.set_inputs(inputs)
        gated.append(bool(core.step(t, 0.5)["gated"][0]))
        t += 0.5
    return gated


def distance(core, beacon):
    return float(np.linalg.norm(core.state["x"][0][[0, 2, 4]] - BEACONS[beacon - 1]))


@pytest.mark.parametrize("model", [SequentialReceiver, UnscentedReceiver], ids=["ekf-seq", "ukf"])
def test_a_lost_track_is_reacquired_by_consistent_ranges(model):
    """The diver is 15 m from where the filter believes it: every range fails its test at first; once two beacons
    failed, a range that agrees with its own beacon's previous failed one is used, and the filter recovers (no
    lock-out). A failing range whose beacon had not failed before is not let in."""
    core = Core(model, GATE).initialize(0.0)
    truth = core.state["x"][0][[0, 2, 4]] + [15.0, 0.0, 0.0]
    stream = [(k % 4 + 1, float(np.linalg.norm(truth - BEACONS[k % 4]))) for k in range(20)]
    gated = feed(core, stream)
    # the first round fails throughout (beacons 3 and 4 have no failed range before theirs); the second is re-acquired
    assert gated[:4] == [True, True, True, True]
    assert gated[4:6] == [False, False]
    assert np.linalg.norm(core.state["x"][0][[0, 2, 4]] - truth) < 1.5  # from 15 m off, in 16 ranges


@pytest.mark.parametrize("model", [SequentialReceiver, UnscentedReceiver], ids=["ekf-seq", "ukf"])
def test_after_a_run_of_rejections_no_outlier_is_let_in(model):
    """The filter is right; two beacons' ranges are multipath outliers (a few metres long): they fail, and the gate's
    guard is open. Outliers follow on every beacon, each with its own random excess: none is used (before, the guard
    let the next range in whatever it was); then correct ranges pass."""
    core = Core(model, SURE).initialize(0.0)
    excess = [5.0, 7.0, 3.0, 4.0, 9.0, 2.0, 6.5, 8.0]  # each beacon's two differ by metres
    stream = [(k % 4 + 1, distance(core, k % 4 + 1) + e) for k, e in enumerate(excess)]
    gated = feed(core, stream)
    assert gated == [True] * len(excess), gated
    correct = [(b, distance(core, b)) for b in (1, 2, 3, 4)]
    assert feed(core, correct, t=4.0) == [False] * 4


@pytest.mark.parametrize("model", [SequentialReceiver, UnscentedReceiver], ids=["ekf-seq", "ukf"])
def test_the_one_transceiver_of_a_usbl_interface_reacquires_and_keeps_outliers_out(model):
    """USBL: one "beacon", so the guard opens after one failed packet (every beacon of the interface failed). Two
    consecutive packets that agree (a drift) are used from the second on; outliers of random excess are not."""
    transceiver = np.array([GATE["x0_x"], GATE["x0_y"], 1.0])  # straight above the filter's prior
    core = Core(model, GATE, n_beacons=1).initialize(0.0)
    below = float(core.state["x"][0][4] - transceiver[2])
    gated = feed(core, [(1, below + 20.0), (1, below + 20.0)], transceiver=transceiver)
    assert gated == [True, False]
    core = Core(model, SURE, n_beacons=1).initialize(0.0)
    gated = feed(core, [(1, below + e) for e in (6.0, 2.0, 9.0, 4.0)], transceiver=transceiver)
    assert gated == [True] * 4
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
    # a metre-long outlier is gated: the re-acquisition after a run of failures lets in only a range that agrees
    # with its beacon's previous failed one (before, the guard let any range in: about 3 % of the outliers)
    assert gated[long].mean() > 0.995
    # a correct range passes with at least the stated probability (one-sided test: about 1 − (1 − p)/2)
    assert 0 < gated[~outlier].mean() < 1 - p
