"""Tests of the least-squares receiver and of the packet handling it shares with the EKF receiver.

The compiled receivers are stepped through :class:`tests.helpers.Core`.
Reference values are computed independently in this file: exact geometry,
``scipy.optimize.least_squares`` on the same weighted cost, finite-difference
Jacobians in plain numpy, and hand-built packet streams.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from sblsim.models.acoustics.channel.lanes import lane_variables
from sblsim.models.declarations import SEED_PARAMETERS, ModelError
from sblsim.models.receiver import LeastSquaresReceiver, PaperEKF, receiver_interface
from sblsim.models.receiver.interface import (
    arrival_interface,
    beacon_parameters,
    clock_parameters,
    estimate_validity,
    range_law_parameters,
)
from sblsim.models.receiver.lsq import SHARED_PARAMETERS
from sblsim.models.receiver.profile import profile_parameters
from sblsim.models.systems.usbl import receiver_parameters as usbl_parameters
from tests.helpers import Core

AXES = ("x", "y", "z")
OUTPUTS = [v.name for v in receiver_interface() + estimate_validity() if v.causality == "output"]
LSQ = dict(sigma_range=0.3, sigma_depth=0.05, x0_x=2.0, x0_y=-1.0, x0_z=4.0)


# ----------------------------------------------------------------------------
# Independent references and helpers
# ----------------------------------------------------------------------------

def cross(L=20.0, h=1.0):
    """4 beacons L(cos θ, sin θ, 0) + (0, 0, h), θ = 0, 90, 180, 270 deg."""
    return np.array([[L, 0.0, h], [0.0, L, h], [-L, 0.0, h], [0.0, -L, h]])


def weighted_residuals(p, ranges, beacons, depth, sr, sd):
    """(r_i − ‖p − b_i‖)/σ_r for the finite ranges, then (d − p_z)/σ_d."""
    have = np.isfinite(ranges)
    rho = np.sqrt(np.sum((p[None, :] - beacons[have]) ** 2, axis=1))
    return np.append((ranges[have] - rho) / sr, (depth - p[2]) / sd)


def scipy_fix(ranges, beacons, depth, sr, sd, start):
    sol = least_squares(weighted_residuals, start, args=(ranges, beacons, depth, sr, sd), method="lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=10000)
    return sol.x


def fd_spread(p, ranges, beacons, depth, sr, sd, eps=1e-6):
    """sqrt(trace(inv(JᵀWJ))) with J from central differences of the weighted residuals (W absorbed)."""
    J = np.empty((np.isfinite(ranges).sum() + 1, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = eps
        J[:, k] = -(weighted_residuals(p + e, ranges, beacons, depth, sr, sd)
                    - weighted_residuals(p - e, ranges, beacons, depth, sr, sd)) / (2 * eps)
    return float(np.sqrt(np.trace(np.linalg.inv(J.T @ J))))


def packet(seq, beacon_id, tx_time, range_value, beacon, depth, valid=True, rx_time=None):
    """Receiver inputs of one packet (arriving at ``rx_time``, default its ``tx_time``); values are scalars or
    arrays of shape (B,). A lost packet carries range 0 and beacon position 0, as the acoustics component sends
    it."""
    beacon = np.asarray(beacon, dtype=float)
    valid_b = np.asarray(valid, dtype=bool)
    return dict(packet_seq=seq, beacon_id=beacon_id, packet_valid=valid, tx_time=tx_time,
                range=np.where(valid_b, range_value, 0.0),
                beacon_x=np.where(valid_b, beacon[..., 0], 0.0), beacon_y=np.where(valid_b, beacon[..., 1], 0.0),
                beacon_z=np.where(valid_b, beacon[..., 2], 0.0), depth=depth,
                rx_time=tx_time if rx_time is None else rx_time)


def snapshot(core):
    return {name: np.array(value, copy=True) for name, value in core.outputs.items()}


def position(out, prefix="est_"):
    """The (B, 3) vector of outputs ``prefix + x, y, z``."""
    return np.column_stack([out[f"{prefix}{a}"] for a in AXES])


def lsq_core(params, replicates, per_replicate=None):
    """A least-squares receiver; per-replicate FMU values (arrays of shape (B,)) set directly."""
    core = Core(LeastSquaresReceiver, params, replicates=replicates)
    core.values.update(per_replicate or {})
    return core.initialize(0.0)


def noisy_case(seed, B, sr=0.3, sd=0.05):
    """Random targets around a perturbed 20 m cross, noisy ranges and depth (one range of replicate 1 lost)."""
    rng = np.random.default_rng(seed)
    truth = np.column_stack([rng.uniform(-30, 30, B), rng.uniform(-30, 30, B), rng.uniform(4, 25, B)])
    beacons = cross()[None] + rng.normal(scale=0.5, size=(B, 4, 3))
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1) + sr * rng.normal(size=(B, 4))
    depth = truth[:, 2] + sd * rng.normal(size=B)
    valid = np.ones((B, 4), dtype=bool)
    valid[1, 2] = False
    return truth, beacons, ranges, depth, valid


def feed_round(core, beacons, ranges, depth, valid=None, t0=0.0, seq0=0, T=1.0):
    """One packet per beacon (ids 1 … n), one slot of length T each, per-replicate values."""
    B, n = ranges.shape
    valid = np.ones((B, n), dtype=bool) if valid is None else valid
    t, seq = t0, seq0
    for i in range(n):
        seq += 1
        core.set_inputs(packet(seq, i + 1, t + T, ranges[:, i], beacons[:, i], depth, valid[:, i]))
        core.step(t, T)
        t += T
    return t, seq


def check_no_fix(out, x0):
    """Before the first fix: no estimate (NaN position and velocity, never the starting guess x0), and every fit
    output is 0 (never NaN)."""
    assert np.isnan(position(out)).all() and np.isnan(position(out, "est_v")).all()
    np.testing.assert_array_equal(position(out, "instr_"), 0.0)
    assert not out["instr_valid"].any()
    np.testing.assert_array_equal(out["nis"], 0.0)
    np.testing.assert_array_equal(out["pos_std"], 0.0)


# ----------------------------------------------------------------------------
# Fixes
# ----------------------------------------------------------------------------

def test_lsq_noise_free_fix_is_the_true_position_and_nis_vanishes():
    truth = np.array([[8.0, -3.0, 5.0], [-12.0, 6.5, 9.0], [0.5, 15.0, 3.0]])
    B = truth.shape[0]
    beacons = np.broadcast_to(cross(), (B, 4, 3))
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1)
    core = lsq_core(LSQ, [0, 1, 2])
    x0 = np.array([LSQ["x0_x"], LSQ["x0_y"], LSQ["x0_z"]])
    check_no_fix(core.outputs, x0)
    t = 0.0
    for i in range(4):
        core.set_inputs(packet(i + 1, i + 1, t + 1.0, ranges[:, i], beacons[:, i], truth[:, 2]))
        core.step(t, 1.0)
        t += 1.0
        if i < 2:
            check_no_fix(core.outputs, x0)  # fewer than 3 ranges: no fix, no estimate
            continue
        out = core.outputs
        assert out["instr_valid"].all()
        np.testing.assert_allclose(position(out), truth, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(position(out, "instr_"), position(out))
        assert np.all(out["nis"] >= 0.0) and np.all(out["nis"] < 1e-10)
        assert np.all(np.isfinite(out["pos_std"])) and np.all(out["pos_std"] > 0.0)
        # a static target: the two fixes agree, so the velocity is zero
        np.testing.assert_allclose(position(out, "est_v"), 0.0, atol=1e-6)


def test_lsq_fix_and_nis_match_scipy_least_squares_on_noisy_data():
    """Converged fixes (50 iterations, 1e-6 σ): within 1e-6 m of scipy, after three and after four ranges."""
    B = 40
    truth, beacons, ranges, depth, valid = noisy_case(5, B)
    sr, sd = LSQ["sigma_range"], LSQ["sigma_depth"]
    core = lsq_core(LSQ, range(B))
    feed_round(core, beacons[:, :3], ranges[:, :3], depth, valid[:, :3])
    three = snapshot(core)
    core.set_inputs(packet(4, 4, 4.0, ranges[:, 3], beacons[:, 3], depth))
    core.step(3.0, 1.0)
    out = core.outputs
    held = np.where(valid, ranges, np.nan)
    assert out["instr_valid"].all()
    assert three["instr_valid"].tolist() == [b != 1 for b in range(B)]  # replicate 1 lost beacon 3
    for b in range(B):
        ref = scipy_fix(held[b], beacons[b], depth[b], sr, sd, truth[b])
        np.testing.assert_allclose(position(out)[b], ref, rtol=0, atol=1e-6, err_msg=f"replicate {b}")
        rss = np.sum(weighted_residuals(ref, held[b], beacons[b], depth[b], sr, sd) ** 2)
        assert out["nis"][b] == pytest.approx(rss, rel=1e-6, abs=1e-9)
        if b != 1:
            held3 = np.append(held[b, :3], np.nan)
            ref3 = scipy_fix(held3, beacons[b], depth[b], sr, sd, truth[b])
            np.testing.assert_allclose(position(three)[b], ref3, rtol=0, atol=1e-6, err_msg=f"replicate {b}, 3")
    # the noise matters: the fixes are not the truth and the residuals are not zero
    assert np.all(np.linalg.norm(position(out) - truth, axis=1) > 1e-3)
    assert np.all(out["nis"] > 1e-4)


def test_lsq_pos_std_is_the_gauss_newton_covariance_at_the_fix():
    B = 6
    _, beacons, ranges, depth, _ = noisy_case(9, B)
    sigma_range = np.linspace(0.1, 1.0, B)
    core = lsq_core(LSQ, range(B), dict(sigma_range=sigma_range))  # per-replicate weights
    feed_round(core, beacons[:, :3], ranges[:, :3], depth)  # 3 ranges
    held = ranges.copy()
    held[:, 3] = np.nan
    for stage in ("three ranges", "four ranges"):
        out = core.outputs
        fix = position(out)
        for b in range(B):
            ref = fd_spread(fix[b], held[b], beacons[b], depth[b], sigma_range[b], LSQ["sigma_depth"])
            assert out["pos_std"][b] == pytest.approx(ref, rel=1e-6), (stage, b)
        if stage == "three ranges":
            before = out["pos_std"].copy()
            core.set_inputs(packet(4, 4, 4.0, ranges[:, 3], beacons[:, 3], depth))
            core.step(3.0, 1.0)
            held = ranges
    assert np.all(core.outputs["pos_std"] < before)  # a fourth range sharpens the fix


# ----------------------------------------------------------------------------
# Velocity and timing
# ----------------------------------------------------------------------------

def test_lsq_velocity_is_the_difference_of_scipy_fixes_over_their_transmit_epochs():
    """A constant-velocity target, noise-free ranges, irregular transmit epochs that fall between the
    receiver's step ends, a lost packet: each fix is scipy's fit of the held ranges (fresh and stale), and
    est_v = Δfix / Δtx_time of the last two fixes (not over the step ends or a nominal slot length). A
    slot whose packet was lost refits the same held ranges (instr_*) but changes neither the estimate
    nor the velocity."""
    h = 0.5
    p0, v = np.array([-10.0, 6.0, 8.0]), np.array([0.6, -0.35, 0.05])
    beacons = cross()
    sr, sd = LSQ["sigma_range"], LSQ["sigma_depth"]
    core = lsq_core(LSQ, [0])
    x0 = np.array([LSQ["x0_x"], LSQ["x0_y"], LSQ["x0_z"]])
    rng = np.random.default_rng(23)
    epochs = np.cumsum(rng.uniform(0.3, 1.7, size=14)) + 0.13  # never on a step end (multiples of h)
    lost = {7}
    held = np.full(4, np.nan)
    fixes, previous_fix, last = [], x0, None
    t = 0.0
    for seq, tx in enumerate(epochs, start=1):
        i = (seq - 1) % 4
        target = p0 + v * tx
        valid = seq not in lost
        core.set_inputs(packet(seq, i + 1, tx, np.linalg.norm(target - beacons[i]), beacons[i], target[2], valid))
        while t + h < tx - 1e-9:  # steps before the epoch: outputs held
            before = snapshot(core)
            core.step(t, h)
            t += h
            for name in OUTPUTS:
                np.testing.assert_array_equal(core.outputs[name], before[name], err_msg=name)
        core.step(t, h)
        t += h
        assert tx <= t < tx + h
        if valid:
            held[i] = np.linalg.norm(target - beacons[i])
        out = core.outputs
        if np.isfinite(held).sum() < 3:
            check_no_fix(out, x0)
            continue
        ref = scipy_fix(held, beacons, target[2], sr, sd, previous_fix)
        assert out["instr_valid"][0]
        np.testing.assert_allclose(position(out, "instr_")[0], ref, rtol=0, atol=1e-6, err_msg=f"seq {seq}")
        if not valid:  # nothing new: the estimate and its velocity stay
            np.testing.assert_array_equal(position(out), position(last))
            np.testing.assert_array_equal(position(out, "est_v"), position(last, "est_v"))
            continue
        previous_fix = ref
        fixes.append((tx, ref))
        last = snapshot(core)
        np.testing.assert_allclose(position(out)[0], ref, rtol=0, atol=1e-6, err_msg=f"seq {seq}")
        if len(fixes) == 1:
            np.testing.assert_array_equal(position(out, "est_v"), 0.0)  # one fix only
        else:
            (t1, f1), (t2, f2) = fixes[-2:]
            np.testing.assert_allclose(position(out, "est_v")[0], (f2 - f1) / (t2 - t1), rtol=0,
                                       atol=2e-6 / (t2 - t1), err_msg=f"seq {seq}")
    assert len(fixes) == len(epochs) - 2 - len(lost)
    assert np.linalg.norm(position(out, "est_v")[0]) > 1e-2  # the check above is not a trivial zero


def test_lsq_velocity_is_the_difference_of_the_last_two_fixes_over_their_slot_times():
    """Round-robin at slot T with the receiver stepping at T/4: the outputs change only at the steps
    that reach a transmit epoch, and est_v = Δ(est) / Δ(tx_time) of the last two fixes."""
    T, r = 1.0, 4
    dt = T / r
    rng = np.random.default_rng(3)
    p0, v = np.array([[-10.0, 6.0, 8.0], [15.0, 2.0, 12.0]]), np.array([[0.6, -0.35, 0.05], [-0.2, 0.4, 0.0]])
    beacons = np.broadcast_to(cross(), (2, 4, 3))
    core = lsq_core(LSQ, [0, 1])
    fixes = []  # (tx_time, fix) of every valid fix
    t, before = 0.0, snapshot(core)
    for seq in range(1, 14):
        i = (seq - 1) % 4
        tx = seq * T
        target = p0 + v * tx
        core.set_inputs(packet(seq, i + 1, tx, np.linalg.norm(target - beacons[:, i], axis=-1)
                               + 0.1 * rng.normal(size=2), beacons[:, i], target[:, 2]))
        for j in range(r):
            core.step(t, dt)
            t += dt
            out = snapshot(core)
            if j < r - 1:
                for name in OUTPUTS:
                    np.testing.assert_array_equal(out[name], before[name], err_msg=name)
                continue
            assert t == pytest.approx(tx)
            if seq >= 3:
                assert out["instr_valid"].all()
                fixes.append((tx, position(out)))
            if len(fixes) >= 2:
                (t1, f1), (t2, f2) = fixes[-2:]
                np.testing.assert_allclose(position(out, "est_v"), (f2 - f1) / (t2 - t1), rtol=1e-12, atol=1e-15)
            elif fixes:
                np.testing.assert_array_equal(position(out, "est_v"), 0.0)  # one fix only
            else:
                assert np.isnan(position(out, "est_v")).all()  # no fix yet: no estimate
        before = out
    assert len(fixes) == 11
    assert np.all(np.abs(position(before, "est_v")) > 1e-3)  # the check above is not a trivial zero


# ----------------------------------------------------------------------------
# Batching, interface, shared packet handling
# ----------------------------------------------------------------------------

def _random_run(params, per_replicate, replicates, seed=11, steps=80, T=1.0, r=4):
    """A packet stream with per-replicate noise, losses and a bad beacon id."""
    rng = np.random.default_rng(seed)
    reps = np.asarray(replicates)
    core = lsq_core(params, replicates, per_replicate)
    out = [snapshot(core)]
    dt, t, seq = T / r, 0.0, 0
    all_reps = 6  # random numbers are drawn for every replicate, then picked: the same in every batch
    for k in range(steps):
        if k % r == 0:
            seq += 1
        tx = seq * T
        i = (seq - 1) % 4
        target = np.column_stack([8.0 + 0.3 * tx + np.arange(all_reps), np.full(all_reps, -3.0 - 0.2 * tx),
                                  6.0 + 0.5 * np.arange(all_reps)])
        b = cross()[i] + rng.normal(scale=0.3, size=(all_reps, 3))
        ranges = np.linalg.norm(target - b, axis=1) + rng.normal(scale=0.3, size=all_reps)
        valid = rng.uniform(size=all_reps) > 0.2
        depth = target[:, 2] + rng.normal(scale=0.05, size=all_reps)
        ids = np.where(rng.uniform(size=all_reps) < 0.03, 9, i + 1)
        core.set_inputs(packet(seq, ids[reps], tx, ranges[reps], b[reps], depth[reps], valid[reps]))
        core.step(t, dt)
        t += dt
        out.append(snapshot(core))
    return {name: np.stack([o[name] for o in out]) for name in out[0]}  # (steps + 1, B)


def test_lsq_batch_equals_single_replicate_runs_bit_for_bit():
    replicates = [0, 1, 2, 3, 4, 5]
    per_rep = dict(sigma_range=np.array([0.1, 0.3, 1.0, 0.2, 0.5, 2.0]),
                   sigma_depth=np.array([0.01, 0.05, 0.2, 0.05, 0.01, 0.1]),
                   x0_x=np.array([0.0, 5.0, -5.0, 30.0, 1.0, 2.0]),
                   x0_y=np.array([0.0, -5.0, 5.0, 30.0, 1.0, 2.0]),
                   x0_z=np.array([1.0, 3.0, 5.0, 20.0, 1.0, 2.0]),
                   cell=np.array([0, 0, 1, 1, 2, 2]))
    batch = _random_run({}, per_rep, replicates)
    for k, rep in enumerate(replicates):
        single = _random_run({name: value[k].item() for name, value in per_rep.items()}, {}, [rep])
        for name in OUTPUTS:
            np.testing.assert_array_equal(batch[name][:, k], single[name][:, 0], err_msg=f"{name}, replicate {rep}",
                                          strict=True)
    # the run exercises fixes and non-zero velocities, and the replicates differ
    assert batch["instr_valid"][-20:].all() and not batch["instr_valid"][:8].any()
    assert np.all(np.abs(batch["est_vx"][-1]) > 0.0)
    assert len(np.unique(batch["est_x"][-1])) == len(replicates)


def test_lsq_interface_equals_the_receiver_interface_of_the_ekf():
    def key(v):
        return (v.name, v.causality, v.type, v.unit)

    lsq, ekf = LeastSquaresReceiver.variables(4), PaperEKF.variables(4)
    valid = estimate_validity()  # est_valid, declared after every other variable
    assert lsq[-len(valid):] == ekf[-len(valid):] == valid and [v.name for v in valid] == ["est_valid"]
    lsq, ekf = lsq[:-len(valid)], ekf[:-len(valid)]
    law = range_law_parameters()  # the range law, declared after every other but est_valid
    assert lsq[-len(law):] == ekf[-len(law):] == law and [v.name for v in law] == ["range_k"]
    lsq, ekf = lsq[:-len(law)], ekf[:-len(law)]
    signals = [key(v) for v in lsq if v.causality != "parameter"]
    assert signals == [key(v) for v in ekf if v.causality != "parameter"]
    lanes = lane_variables(4, "input")  # the later lanes of a delivery, declared last of all
    assert lanes and signals == [key(v) for v in receiver_interface() + arrival_interface() + lanes]
    assert tuple(v for v in lsq if v.causality != "parameter") == receiver_interface() + arrival_interface() + lanes
    assert lsq[-len(lanes):] == ekf[-len(lanes):] == lanes
    ekf = ekf[:-len(lanes)]
    # parameters: the EKF's own declarations of the shared ones, then the seed keys, then the receiver's clock and
    # the USBL angle (declared after it), then the receiver's sound-speed profile, then the transceiver's
    # uncertainty the USBL packet fix weighs (declared last)
    ekf_params = {v.name: v for v in ekf if v.causality == "parameter"}
    params = [v for v in lsq if v.causality == "parameter"]
    shared = ["sigma_range", "sigma_depth", "x0_x", "x0_y", "x0_z"]
    assert list(SHARED_PARAMETERS) == shared
    assert params == ([ekf_params[n] for n in shared] + list(SEED_PARAMETERS) + list(clock_parameters())
                      + list(usbl_parameters()) + list(profile_parameters()) + list(beacon_parameters()))
    # declared last: the earlier value references stay (the clock and USBL angle, the arrival epoch, the profile)
    n = len(profile_parameters())
    assert ekf[-3 - n:] == clock_parameters() + usbl_parameters() + arrival_interface() + profile_parameters()
    assert LeastSquaresReceiver.name == "receiver_lsq" and LeastSquaresReceiver.component_index == 3
    core = Core(LeastSquaresReceiver, {"seed": 3, "scenario_key": 1, "cell": 2, "replicate": 4}).initialize(0.0)
    assert list(core.outputs) == OUTPUTS
    assert core.handle.input_names == [v.name for v in receiver_interface() + arrival_interface() + lanes
                                       if v.causality == "input"]
    with pytest.raises(ModelError, match=r"^receiver_lsq\.q_horizontal: not a parameter"):
        Core(LeastSquaresReceiver, {"q_horizontal": 0.1}).initialize(0.0)


def test_both_receivers_share_the_packet_handling():
    """Same packet stream (late arrivals, a lost packet, a repeated packet, a bad id): same held state."""
    x0 = dict(x0_x=3.0, x0_y=-2.0, x0_z=5.0)
    ekf = Core(PaperEKF, x0, replicates=[0, 1]).initialize(0.0)
    lsq = Core(LeastSquaresReceiver, x0, replicates=[0, 1]).initialize(0.0)
    beacons = cross()
    stream = [  # (seq, beacon_id, rx_time, range, valid), each on the inputs for 4 steps of 0.25 s
        (1, 1, 0.75, [20.0, 21.0], [True, True]),
        (2, 2, 1.75, [22.0, 23.0], [True, False]),
        (2, 2, 1.75, [22.0, 23.0], [True, False]),  # the same packet again: no new slot
        (3, 9, 3.75, [5.0, 5.0], [True, True]),  # no such beacon: a slot that stores nothing
        (4, 3, 4.6, [24.0, 25.0], [True, True]),  # arrival between step ends: used at 4.75 s
    ]
    expected_ranges, expected_beacons, expected_heard = np.zeros((2, 4)), np.zeros((2, 12)), np.zeros((2, 4))
    expected_seq = np.zeros(2)
    t, dt = 0.0, 0.25
    for seq, bid, tx, rng_value, valid in stream:
        valid = np.array(valid)
        for core in (ekf, lsq):
            core.set_inputs(packet(seq, bid, tx - 0.5, np.array(rng_value), beacons[min(bid, 4) - 1], 6.0, valid,
                                   rx_time=tx))
        for _ in range(4):
            reached = t + dt >= tx - 1e-9
            for core in (ekf, lsq):
                core.step(t, dt)
            t += dt
            if reached:
                expected_seq[:] = seq
                if bid <= 4:
                    expected_ranges[valid, bid - 1] = np.array(rng_value)[valid]
                    expected_beacons[valid, 3 * (bid - 1):3 * bid] = beacons[bid - 1]
                    expected_heard[valid, bid - 1] = 1.0
            e, s = ekf.state, lsq.state
            for name in ("ranges", "beacons", "heard", "last_seq", "slot_time"):
                np.testing.assert_array_equal(e[name], s[name], err_msg=name)
            np.testing.assert_array_equal(e["ranges"], expected_ranges)
            np.testing.assert_array_equal(e["beacons"], expected_beacons)
            np.testing.assert_array_equal(e["heard"], expected_heard)
            np.testing.assert_array_equal(e["last_seq"][:, 0], expected_seq)
    assert ekf.state["slot_time"][:, 0].tolist() == [4.1, 4.1]  # the packet's transmit epoch, not the step end
    assert lsq.outputs["instr_valid"].tolist() == [True, False]  # replicate 1 lost beacon 2: two ranges
    assert ekf.outputs["instr_valid"].tolist() == [True, False]
