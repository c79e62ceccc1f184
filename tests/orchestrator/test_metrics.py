"""Error metrics against hand-computed values."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.stats import chi2

from sblsim.orchestrator.cosim.metrics import METRIC_NAMES, NEES_95, consistency, errors, nees, slots, summarize

NAN = float("nan")


def test_errors_hand_computed():
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [10.0, -4.0, 2.0]])
    est = np.array([[3.0, 4.0, 0.0], [-1.0, 2.0, 4.0], [10.0, -4.0, 2.0]])
    e = errors(truth, est)
    assert e.shape == (3, 4)
    np.testing.assert_allclose(e[0], [3.0, 4.0, 0.0, 5.0])
    np.testing.assert_allclose(e[1], [2.0, 0.0, 1.0, math.sqrt(5.0)])
    np.testing.assert_allclose(e[2], [0.0, 0.0, 0.0, 0.0])


def test_errors_are_absolute_and_batched():
    rng = np.random.default_rng(0)
    truth = rng.normal(size=(7, 3, 3))
    est = rng.normal(size=(7, 3, 3))
    e = errors(truth, est)
    assert e.shape == (7, 3, 4)
    np.testing.assert_allclose(e[..., :3], np.abs(truth - est))
    np.testing.assert_allclose(e[..., 3], np.linalg.norm(truth - est, axis=-1))
    np.testing.assert_allclose(errors(est, truth), e)  # symmetric


def test_errors_nan_estimate_gives_nan_total():
    e = errors(np.zeros((1, 3)), np.array([[NAN, 1.0, 1.0]]))
    assert math.isnan(e[0, 0]) and math.isnan(e[0, 3])
    assert e[0, 1] == 1.0 and e[0, 2] == 1.0


def test_summarize_hand_computed_with_nan_steps():
    # steps of replicate 0: (3,4,0) -> 5, a step with no estimate, (5,12,0) -> 13, a partial NaN, (0,0,0) -> 0
    # replicate 1: a single valid step (0, 0, 2) -> 2, the rest NaN
    # replicate 2: no valid step at all
    est_r0 = [[3, 4, 0, 5], [NAN] * 4, [5, 12, 0, 13], [1, NAN, 1, NAN], [0, 0, 0, 0]]
    est_r1 = [[NAN] * 4, [0, 0, 2, 2], [NAN] * 4, [NAN] * 4, [NAN] * 4]
    est_r2 = [[NAN] * 4] * 5
    err = np.stack([np.array(est_r0, float), np.array(est_r1, float), np.array(est_r2, float)], axis=1)
    assert err.shape == (5, 3, 4)
    m = summarize(err)
    assert list(m) == list(METRIC_NAMES)
    for v in m.values():
        assert v.shape == (3,)
    # replicate 0: the valid steps are 5, 13 and 0
    assert m["e_x_mean"][0] == pytest.approx(8 / 3)
    assert m["e_y_mean"][0] == pytest.approx(16 / 3)
    assert m["e_z_mean"][0] == pytest.approx(0.0)
    assert m["e_tot_mean"][0] == pytest.approx(6.0)
    assert m["e_tot_rms"][0] == pytest.approx(math.sqrt((25 + 169 + 0) / 3))
    assert m["e_tot_std"][0] == pytest.approx(math.sqrt(((5 - 6) ** 2 + (13 - 6) ** 2 + (0 - 6) ** 2) / 3))
    # replicate 1: one valid step, zero spread
    assert (m["e_x_mean"][1], m["e_y_mean"][1], m["e_z_mean"][1]) == (0.0, 0.0, 2.0)
    assert m["e_tot_mean"][1] == 2.0 and m["e_tot_rms"][1] == 2.0 and m["e_tot_std"][1] == 0.0
    # replicate 2: NaN everywhere
    for name in METRIC_NAMES:
        assert math.isnan(m[name][2]), name


def test_summarize_prefix():
    err = np.array([[[3.0, 4.0, 0.0, 5.0]]])
    m = summarize(err, "instr_")
    assert list(m) == ["instr_" + n for n in METRIC_NAMES]
    assert m["instr_e_tot_mean"][0] == 5.0 and m["instr_e_tot_rms"][0] == 5.0 and m["instr_e_tot_std"][0] == 0.0


def test_summarize_matches_numpy_on_random_errors():
    rng = np.random.default_rng(1)
    truth = rng.normal(size=(50, 4, 3))
    est = truth + rng.normal(scale=0.3, size=truth.shape)
    est[rng.random(size=(50, 4)) < 0.2] = NAN
    err = errors(truth, est)
    m = summarize(err)
    for b in range(4):
        ok = np.isfinite(err[:, b, 3])
        e = err[ok, b]
        assert m["e_x_mean"][b] == pytest.approx(e[:, 0].mean())
        assert m["e_y_mean"][b] == pytest.approx(e[:, 1].mean())
        assert m["e_z_mean"][b] == pytest.approx(e[:, 2].mean())
        assert m["e_tot_mean"][b] == pytest.approx(e[:, 3].mean())
        assert m["e_tot_rms"][b] == pytest.approx(np.sqrt(np.mean(e[:, 3] ** 2)))
        assert m["e_tot_std"][b] == pytest.approx(np.std(e[:, 3], ddof=0))


def test_nees_hand_computed():
    # diagonal: e = (1, 2, 0), P = diag(1, 4, 1) -> 1 + 1 + 0
    assert nees(np.array([1.0, 2.0, 0.0]), np.array([1.0, 0.0, 0.0, 4.0, 0.0, 1.0])) == pytest.approx(2.0)
    # correlated in the plane: P = [[2, 1], [1, 2]] (⊕ 1): P⁻¹ = [[2, -1], [-1, 2]] / 3; e = (1, 1, 3) -> 2/3 + 9
    assert nees(np.array([1.0, 1.0, 3.0]), np.array([2.0, 1.0, 0.0, 2.0, 0.0, 1.0])) == pytest.approx(2.0 / 3.0 + 9.0)
    # not positive-definite (a receiver reporting zeros, or a negative determinant): NaN, not a huge number
    bad = np.array([[0.0] * 6, [1.0, 2.0, 0.0, 1.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0, 0.0, -1e-9]])
    assert np.all(np.isnan(nees(np.ones((3, 3)), bad)))


def test_nees_matches_numpy_on_random_covariances():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(40, 3, 3))
    P = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)
    e = rng.normal(size=(40, 3))
    packed = P[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    expected = np.einsum("ni,nij,nj->n", e, np.linalg.inv(P), e)
    np.testing.assert_allclose(nees(e, packed), expected, rtol=1e-10)


def test_slots_from_the_packet_counter():
    seq = np.array([[0], [1], [1], [2], [3], [3]])
    received = np.array([[False], [True], [True], [False], [True], [True]])
    slot, fresh = slots(seq, received)
    assert slot[:, 0].tolist() == [False, True, False, True, True, False]
    assert fresh[:, 0].tolist() == [False, True, False, False, True, False]


def test_consistency_hand_counted():
    # 5 steps, 2 runs; run 0: NEES 1, 9, 4, NaN (P zero), 0 -> mean 3.5 over 4 valid, 3 of 4 within 7.815
    sigma = np.array([1.0, 1.0, 2.0, 0.0, 1.0])
    err0 = np.array([[1.0, 0, 0], [3.0, 0, 0], [4.0, 0, 0], [1.0, 0, 0], [0.0, 0, 0]])
    cov0 = np.array([[s * s, 0, 0, 1.0, 0, 1.0] for s in sigma])
    cov0[3] = 0.0
    # run 1: identity covariance, errors (0,0,1): NEES 1 at every step
    err = np.stack([err0, np.tile([0.0, 0.0, 1.0], (5, 1))], axis=1)
    cov = np.stack([cov0, np.tile([1.0, 0, 0, 1.0, 0, 1.0], (5, 1))], axis=1)
    seq = np.array([[0, 1], [1, 1], [2, 2], [3, 3], [4, 4]])
    nis = np.array([[7.0, 2.0], [2.0, 2.0], [4.0, 4.0], [6.0, 0.0], [0.0, 0.0]])
    fresh = np.array([[False, True], [True, False], [True, True], [True, True], [True, True]])
    gated = np.array([[True, False], [False, False], [True, False], [False, False], [True, False]])
    bound = np.array([[3.0, 1.0], [4.0, 1.0], [0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])
    out = consistency(err, cov, nis, seq, fresh, gated, bound)
    assert NEES_95 == chi2.ppf(0.95, 3)  # written out in the module (its workers import no scipy.stats)
    np.testing.assert_allclose(out["nees_mean"], [(1 + 9 + 4 + 0) / 4, 1.0])
    np.testing.assert_allclose(out["coverage_95"], [3 / 4, 1.0])
    np.testing.assert_allclose(out["nis_mean"], [(2 + 4 + 6 + 0) / 4, (2 + 2 + 4 + 0 + 0) / 5])  # from the first slot
    np.testing.assert_allclose(out["gated_pct"], [100 * 2 / 4, 0.0])  # the gated step without a slot does not count
    np.testing.assert_allclose(out["pcrb_rms"], [np.sqrt((9 + 16) / 5), 1.0])


def test_the_bound_is_averaged_over_the_steps_with_an_estimate():
    """pcrb_rms is the bound's RMS over the steps e_tot_rms averages: run 0 has no estimate before its first fix at
    step 2, run 1 none at all (NaN, as its errors)."""
    err = np.zeros((5, 2, 3))
    err[:2, 0] = np.nan
    err[:, 1] = np.nan
    cov = np.tile([1.0, 0, 0, 1.0, 0, 1.0], (5, 2, 1))
    seq = np.tile(np.arange(5)[:, None], (1, 2))
    bound = np.array([[5.0, 5.0], [4.0, 4.0], [3.0, 3.0], [2.0, 2.0], [1.0, 1.0]])
    out = consistency(err, cov, np.zeros((5, 2)), seq, seq > 0, np.zeros((5, 2), bool), bound)
    np.testing.assert_allclose(out["pcrb_rms"][0], np.sqrt((9 + 4 + 1) / 3))
    assert np.isnan(out["pcrb_rms"][1]) and np.isnan(summarize(errors(np.zeros((5, 2, 3)), err))["e_tot_rms"][1])
    assert not out["diverged"].any()  # no estimate before the first fix is not a lost diver


def test_the_compiled_pass_equals_the_numpy_metrics_and_the_casadi_bound():
    """run_metrics (one compiled pass, sblsim_metrics.c) against summarize, consistency and the bound's casadi
    reference on a record with everything the metrics skip: estimates missing, no fix, covariances not
    positive-definite, lost packets, foreign beacon ids, the gate at work and a diverged run; the columns are
    strided views of one (N, 24, B) array, as the compiled master records them."""
    from sblsim.models.bound import FIXED, pcrb, pcrb_inputs
    from sblsim.orchestrator.cosim.metrics import METRIC_INPUTS, RUN_METRICS, run_metrics

    rng = np.random.default_rng(7)
    n, b = 300, 5
    record = np.zeros((n, len(METRIC_INPUTS), b))
    col = {name: record[:, k, :] for k, name in enumerate(METRIC_INPUTS)}  # views: writing them fills record
    truth = np.cumsum(rng.normal(0.0, 0.3, (n, b, 3)), axis=0) + [20.0, 5.0, 10.0]
    estimate = truth + rng.normal(0.0, 0.5, (n, b, 3))
    estimate[rng.random(n) < 0.05, 2] = np.nan  # run 2: steps without an estimate (left out; and so diverged)
    estimate[:40, 1] = np.nan  # run 1: no estimate before its first fix (left out, the bound's steps too)
    estimate[150:, 4] += [400.0, 0.0, 0.0]  # run 4 loses the diver
    fix = truth + rng.normal(0.0, 0.8, (n, b, 3))
    for k, a in enumerate("xyz"):
        col[f"true_{a}"][:] = truth[..., k]
        col[f"est_{a}"][:] = estimate[..., k]
        col[f"instr_{a}"][:] = fix[..., k]
    col["instr_valid"][:] = rng.random((n, b)) < 0.8
    col["instr_valid"][:, 3] = 0.0  # run 3: no fix at all (its instrumentation metrics are NaN)
    A = rng.normal(0.0, 0.6, (n, b, 3, 3))
    P = A @ np.swapaxes(A, -1, -2) + 0.05 * np.eye(3)
    P[rng.random((n, b)) < 0.1] = 0.0  # before the first fix: zeros
    P[rng.random((n, b)) < 0.05] *= -1.0  # not positive-definite
    for name, (i, j) in zip(("xx", "xy", "xz", "yy", "yz", "zz"), ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        col[f"cov_{name}"][:] = P[..., i, j]
    col["packet_seq"][:] = np.minimum(np.cumsum(rng.random((n, b)) < 0.6, axis=0), 10 ** 6)
    col["packet_valid"][:] = rng.random((n, b)) < 0.7
    col["beacon_id"][:] = rng.integers(0, 6, (n, b))  # 0 and 5 name no beacon of four
    col["gated"][:] = rng.random((n, b)) < 0.2
    col["nis"][:] = rng.chisquare(1, (n, b))
    beacons = rng.normal(0.0, 2.0, (n, b, 3))
    for k, a in enumerate("xyz"):
        col[f"beacon_{a}"][:] = beacons[..., k]
    arms = rng.normal(0.0, 1.5, (b, 4, 3))
    fixed = np.column_stack([np.full(b, 0.1), rng.uniform(0.01, 0.1, b), rng.uniform(0.001, 0.01, b),
                             rng.uniform(1.0, 10.0, b), rng.uniform(0.5, 2.0, b), rng.uniform(0.01, 0.1, b),
                             rng.uniform(1e-5, 1e-3, b), rng.uniform(1e-4, 1e-2, b),
                             rng.uniform(0.05, 0.3, b), rng.uniform(0.0, 0.01, b)])  # the range law's σ₀ and k

    got, bound = run_metrics(col, fixed, arms, with_bound=True)

    instr = np.where(col["instr_valid"][..., None] > 0.5, fix, np.nan)
    received = (col["packet_valid"] > 0.5) & (col["beacon_id"] >= 1) & (col["beacon_id"] <= 4)
    slot, fresh = slots(col["packet_seq"], received)
    index = np.clip(col["beacon_id"].astype(int) - 1, 0, 3)
    want_bound = pcrb(*pcrb_inputs(truth, slot, fresh, beacons, arms[np.arange(b)[None, :], index],
                                   **{k: fixed[:, i] for i, k in enumerate(FIXED)}))
    cov = np.stack([col[f"cov_{ab}"] for ab in ("xx", "xy", "xz", "yy", "yz", "zz")], axis=-1)
    want = {**summarize(errors(truth, estimate)), **summarize(errors(truth, instr), "instr_"),
            **consistency(truth - estimate, cov, col["nis"], col["packet_seq"], fresh, col["gated"] > 0.5,
                          want_bound, truth)}
    assert list(got) == list(RUN_METRICS)
    np.testing.assert_allclose(bound, want_bound, rtol=1e-13, atol=0)
    for name in RUN_METRICS:
        np.testing.assert_allclose(got[name], want[name], rtol=1e-12, atol=0, err_msg=name)
    assert got["diverged"].tolist() == [False, False, True, False, True]
    assert np.isnan(got["instr_e_tot_rms"][3]) and np.all(np.isfinite(got["e_tot_rms"]))
    assert 0 < got["gated_pct"].min() and got["coverage_95"].max() < 1.0  # every branch exercised


def test_the_compiled_pass_takes_the_later_lanes_of_a_delivery_as_slots_of_the_bound():
    """Packets on the later lanes of a delivery (several arrived in one step): each new one is a slot of the bound at
    the step's end after lane 1's, with no prediction between them. Reference: casadi's bound_step stepped here in
    plain Python, over dt for the step and over 0 s for each new lane packet; every other metric is the record's
    without lanes."""
    from sblsim.models.bound import FIXED, MODEL, bound_step, error_prior
    from sblsim.models.columns import LANE_METRIC_INPUTS
    from sblsim.orchestrator.cosim.metrics import METRIC_INPUTS, RUN_METRICS, run_metrics

    rng = np.random.default_rng(11)
    n, b = 120, 3
    col = {name: np.zeros((n, b)) for name in METRIC_INPUTS}
    truth = np.cumsum(rng.normal(0.0, 0.3, (n, b, 3)), axis=0) + [20.0, 5.0, 10.0]
    for k, a in enumerate("xyz"):
        col[f"true_{a}"][:] = truth[..., k]
        col[f"est_{a}"][:] = truth[..., k] + rng.normal(0.0, 0.5, (n, b))
    for ab in ("xx", "yy", "zz"):
        col[f"cov_{ab}"][:] = 0.25
    seq = np.cumsum(rng.random((n, b)) < 0.5, axis=0) * 10  # lane 1's packets; lanes' ones between them
    col["packet_seq"][:], col["packet_valid"][:], col["beacon_id"][:] = seq, 1.0, rng.integers(1, 5, (n, b))
    beacons = rng.normal(0.0, 20.0, (n, b, 3))
    for k, a in enumerate("xyz"):
        col[f"beacon_{a}"][:] = beacons[..., k]
    lanes = {}
    for m in (2, 3):  # lane m holds a new packet where lane 1 does, some of the time; held (or emptied) after
        new = (np.diff(seq, axis=0, prepend=0) > 0) & (rng.random((n, b)) < 0.5 / (m - 1))
        lane_seq = np.where(new, seq + m - 1, 0.0)
        held = np.where(rng.random((n, b)) < 0.5, np.maximum.accumulate(lane_seq, axis=0), lane_seq)
        lanes[f"lane{m}_packet_seq"] = held
        lanes[f"lane{m}_packet_valid"] = (rng.random((n, b)) < 0.8).astype(float)
        lanes[f"lane{m}_beacon_id"] = rng.integers(0, 6, (n, b)).astype(float)  # 0 and 5: no beacon of four
        for a in "xyz":
            lanes[f"lane{m}_beacon_{a}"] = rng.normal(0.0, 20.0, (n, b))
    assert set(lanes) <= set(LANE_METRIC_INPUTS)
    arms = rng.normal(0.0, 1.5, (b, 4, 3))
    fixed = np.column_stack([np.full(b, 0.1), rng.uniform(0.01, 0.1, b), rng.uniform(0.001, 0.01, b),
                             rng.uniform(1.0, 10.0, b), rng.uniform(0.5, 2.0, b), rng.uniform(0.01, 0.1, b),
                             rng.uniform(1e-5, 1e-3, b), rng.uniform(1e-4, 1e-2, b),
                             rng.uniform(0.05, 0.3, b), rng.uniform(0.0, 0.01, b)])  # the range law's σ₀ and k

    got, bound = run_metrics({**col, **lanes}, fixed, arms, with_bound=True)
    alone, alone_bound = run_metrics(col, fixed, arms, with_bound=True)

    step, f = bound_step(MODEL), {k: fixed[:, i] for i, k in enumerate(FIXED)}
    want = np.empty((n, b))
    for r in range(b):
        symbols = {k: ca.SX.sym(k) for k in FIXED}
        B = ca.Function("prior", list(symbols.values()), [error_prior(MODEL.motion, symbols)])(
            *[f[k][r] for k in FIXED])
        last, held = 0.0, {2: 0.0, 3: 0.0}

        def update(B, dt, beacon, beacon_id, valid, slot, r, k):
            received = float(slot and valid > 0.5 and 1 <= beacon_id <= 4)
            arm = arms[r, int(np.clip(beacon_id, 1, 4)) - 1]
            return step(B, dt, f["q_horizontal"][r], f["q_vertical"][r], truth[k, r], beacon, arm,
                        f["noise_variance"][r], f["attitude_variance"][r], f["depth_variance"][r], slot, received,
                        f["sigma_range"][r], f["range_k"][r])

        for k in range(n):
            slot = float(seq[k, r] != last)
            last = seq[k, r]
            B = update(B, f["dt"][r], beacons[k, r], col["beacon_id"][k, r], 1.0, slot, r, k)
            for m in (2, 3):
                s = lanes[f"lane{m}_packet_seq"][k, r]
                if s > 0 and s != held[m]:
                    held[m] = s
                    B = update(B, 0.0, [lanes[f"lane{m}_beacon_{a}"][k, r] for a in "xyz"],
                               lanes[f"lane{m}_beacon_id"][k, r], lanes[f"lane{m}_packet_valid"][k, r], 1.0, r, k)
            B_ = np.asarray(B).reshape(6, 6, order="F")
            want[k, r] = np.sqrt(B_[0, 0] + B_[2, 2] + B_[4, 4])
    np.testing.assert_allclose(bound, want, rtol=1e-12, atol=0)
    assert np.all(bound[-1] < alone_bound[-1])  # the lanes' packets add information: a lower bound than lane 1's alone
    for name in RUN_METRICS:
        if name != "pcrb_rms":
            np.testing.assert_allclose(got[name], alone[name], rtol=0, atol=0, err_msg=name)


def test_a_new_packet_on_a_later_lane_is_one_it_did_not_hold_last():
    """new_on_lane against a plain loop over the steps: a lane's packet is new when its counter is not 0 (empty)
    and not the last packet the lane held (emptying keeps it in mind), per run."""
    from sblsim.orchestrator.cosim.metrics import new_on_lane

    rng = np.random.default_rng(5)
    seq = rng.integers(1, 4, (200, 6)) * (rng.random((200, 6)) < 0.6)  # repeats, empties and returns
    seq[:, 0] = 0  # a lane never used
    want = np.zeros(seq.shape, bool)
    for r in range(seq.shape[1]):
        held = 0
        for k in range(seq.shape[0]):
            if seq[k, r] > 0:
                want[k, r] = seq[k, r] != held
                held = seq[k, r]
    got = new_on_lane(seq)
    np.testing.assert_array_equal(got, want)
    assert want.any() and (~want & (seq > 0)).any()  # new packets, and held ones that are not
    np.testing.assert_array_equal(new_on_lane(seq[:, 3]), want[:, 3])  # one run: (N,)
