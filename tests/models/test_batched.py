"""Batched numerics: the casadi → numpy translation, per-replicate parameters, and the multilateration.

Every check compares with an independent computation: casadi's own
evaluation, central finite differences, batches of a single parameter value,
and scipy's least-squares solver.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import least_squares

from models.acoustics.core import AcousticsCore
from models.core import ModelError
from models.platform.core import PlatformCore
from models.receiver.jacobian import (
    numpy_function,
    position_range_numpy,
    range_and_jacobian,
)
from models.receiver.multilateration import linear_fix, multilaterate
from orchestrator.config import load_config
from orchestrator.run import run_batch, with_replicates

# --------------------------------------------------------------------------- numpy_function

def _many_ops_function() -> ca.Function:
    """An SX function with most operations the translation knows, and a sparse Jacobian output."""
    x = ca.SX.sym("x", 4)
    y = ca.SX.sym("y", 2)
    f = ca.vertcat(
        ca.sin(x[0]) * ca.cos(x[1]) + ca.exp(x[2] / 5.0),
        ca.log(x[0] ** 2 + 1.25) - ca.sqrt(x[1] ** 2 + 2.0),
        (x[0] ** 2 + 0.5) ** y[0],  # pow with a symbolic exponent
        x[1] ** 3 / (1.0 + x[2] ** 2),  # constant power and division
        ca.atan2(x[1], x[0]) + ca.fabs(x[2] - y[1]),
        ca.tanh(x[3]) * 3.7 - ca.hypot(x[0], y[1]) + ca.fmin(x[0], y[0]) - ca.fmax(x[1], y[1]),
        ca.sinh(x[0] / 3.0) + ca.cosh(x[1] / 3.0) + ca.atan(x[2]) - 1.0 / (2.0 + x[3] ** 2),
    )
    s = ca.dot(f, f) + x[0] * x[1]  # scalar: its gradient is dense in x, not in (x, y)
    # gradient of the first output w.r.t. (x, y): a sparse column (y and x[3] do not enter it)
    grad = ca.jacobian(f[0], ca.vertcat(x, y)).T
    return ca.Function("many_ops", [x, y], [f, grad, s], ["x", "y"], ["f", "grad", "s"])


def _points(rng, n):
    x = rng.uniform(-2.0, 2.0, size=(4, n))
    y = rng.uniform(-1.5, 1.5, size=(2, n))
    return x, y


def test_numpy_function_matches_casadi_on_many_operations():
    fun = _many_ops_function()
    ops = {fun.instruction_id(k) for k in range(fun.n_instructions())}
    # the function really uses the operations named in the test
    for op in (ca.OP_SIN, ca.OP_COS, ca.OP_EXP, ca.OP_LOG, ca.OP_SQRT, ca.OP_POW, ca.OP_DIV, ca.OP_ATAN2,
               ca.OP_FABS, ca.OP_CONST, ca.OP_TANH, ca.OP_HYPOT, ca.OP_FMIN, ca.OP_FMAX, ca.OP_SINH, ca.OP_COSH):
        assert op in ops, op
    assert not fun.sparsity_out(1).is_dense()
    n = 500
    x, y = _points(np.random.default_rng(11), n)
    f_np, grad_np, s_np = numpy_function(fun)(x, y)
    assert f_np.shape == (7, n) and grad_np.shape == (6, n) and s_np.shape == (1, n)

    mapped = fun.map(n)
    f_ca, grad_ca, s_ca = (np.array(v) for v in mapped(x, y))
    for ours, theirs in ((f_np, f_ca), (grad_np, grad_ca), (s_np, s_ca)):
        assert np.all(np.isfinite(theirs))
        np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-300)

    # structural zeros of the sparse output are exact zeros
    structural = np.setdiff1d(np.arange(6), fun.sparsity_out(1).row())
    assert set(structural) == {3, 4, 5}
    assert np.all(grad_np[structural] == 0.0)


def test_numpy_function_broadcasts_inputs():
    """Inputs of different (broadcastable) shapes give the outputs of every combination."""
    fun = _many_ops_function()
    rng = np.random.default_rng(3)
    x, y = _points(rng, 5)
    f, grad, s = numpy_function(fun)(x[:, :, None], y[:, None, :3])  # (4, 5, 1) and (2, 1, 3)
    assert f.shape == (7, 5, 3) and s.shape == (1, 5, 3)
    # an output that does not depend on y keeps y's axis of length 1 (it broadcasts)
    grad = np.broadcast_to(grad, (6, 5, 3))
    for i in range(5):
        for j in range(3):
            ref = [np.array(v).ravel() for v in fun(x[:, i], y[:, j])]
            np.testing.assert_allclose(f[:, i, j], ref[0], rtol=1e-12)
            np.testing.assert_allclose(grad[:, i, j], ref[1], rtol=1e-12)
            np.testing.assert_allclose(s[:, i, j], ref[2], rtol=1e-12)


def test_numpy_function_outputs_keep_their_values_when_work_slots_are_reused():
    """casadi re-uses a work slot once its value is output; the translation must read it then."""
    x = ca.SX.sym("x", 2)
    pt = np.array([0.3, 0.7])
    stacked = ca.Function("stacked", [x], [ca.vertcat(ca.sin(x[0]), ca.cos(x[1]))])
    np.testing.assert_allclose(numpy_function(stacked)(pt)[0], [np.sin(0.3), np.cos(0.7)], rtol=1e-15)
    separate = ca.Function("separate", [x], [ca.sin(x[0]), ca.cos(x[1])])
    got = numpy_function(separate)(pt)
    np.testing.assert_allclose([got[0][0], got[1][0]], [np.sin(0.3), np.cos(0.7)], rtol=1e-15)


def test_numpy_function_non_finite_constants():
    """Constants are translated as numbers, also inf and nan (casadi evaluates them)."""
    x = ca.SX.sym("x", 2)
    fun = ca.Function("nonfinite", [x], [ca.vertcat(x[0] / ca.SX(np.inf) + ca.atan2(x[1], ca.SX(np.inf)),
                                                    x[0] * np.nan + 1.0)])
    pt = np.array([0.3, 0.7])
    np.testing.assert_array_equal(numpy_function(fun)(pt)[0], np.array(fun(pt)).ravel())


def test_numpy_function_matrix_output_is_refused_or_correct():
    """A non-column output (a full Jacobian matrix) must not come back silently wrong."""
    x = ca.SX.sym("x", 3)
    jac = ca.jacobian(ca.vertcat(ca.sin(x[0]) * x[1], x[2] ** 2), x)  # 2 x 3, sparse
    fun = ca.Function("jacobian_matrix", [x], [jac])
    pt = np.array([0.3, 0.7, 1.1])
    try:
        (got,) = numpy_function(fun)(pt)
    except ValueError:
        return
    np.testing.assert_allclose(np.reshape(got, (2, 3)), np.array(fun(pt)), rtol=1e-15)


def test_numpy_function_refuses_unknown_operations_and_matrix_inputs():
    x = ca.SX.sym("x", 2)
    with pytest.raises(ValueError, match="no numpy translation"):
        numpy_function(ca.Function("e", [x], [ca.erf(x[0])]))
    m = ca.SX.sym("m", 2, 2)
    with pytest.raises(ValueError, match="dense column vector"):
        numpy_function(ca.Function("m", [m], [m[0, 0]]))


def _central_differences(fun, x0, eps):
    cols = []
    for k in range(x0.shape[-1]):
        e = np.zeros(x0.shape[-1])
        e[k] = eps
        cols.append((fun(x0 + e) - fun(x0 - e)) / (2.0 * eps))
    return np.stack(cols, axis=-1)


def test_range_and_jacobian_against_numpy_and_central_differences():
    rng = np.random.default_rng(5)
    B, n = 7, 4
    states = np.column_stack([rng.uniform(-30, 30, B), rng.normal(size=B), rng.uniform(-30, 30, B),
                              rng.normal(size=B), rng.uniform(1, 20, B), rng.normal(size=B)])
    beacons = rng.uniform(-3, 3, size=(B, n, 3))
    h, H = range_and_jacobian(states, beacons)
    assert h.shape == (B, n) and H.shape == (B, n, 6)
    pos = states[:, [0, 2, 4]]
    np.testing.assert_allclose(h, np.linalg.norm(pos[:, None, :] - beacons, axis=-1), rtol=1e-14)
    numeric = _central_differences(lambda s: range_and_jacobian(s, beacons)[0], states, 1e-6)  # (B, n, 6)
    np.testing.assert_allclose(H, numeric, rtol=0, atol=1e-8)
    assert np.all(H[..., [1, 3, 5]] == 0.0)  # velocities do not enter a range


def test_position_range_against_central_differences():
    rng = np.random.default_rng(6)
    B, n = 5, 3
    p = rng.uniform(-20, 20, size=(B, 3))
    b = rng.uniform(-2, 2, size=(B, n, 3))

    def ranges(points):
        (h,), _ = position_range_numpy()(np.moveaxis(points, -1, 0)[:, :, None], np.moveaxis(b, -1, 0))
        return h  # (B, n)

    (h,), J = position_range_numpy()(p.T[:, :, None], np.moveaxis(b, -1, 0))
    assert h.shape == (B, n) and J.shape == (3, B, n)
    np.testing.assert_allclose(h, np.linalg.norm(p[:, None, :] - b, axis=-1), rtol=1e-14)
    numeric = _central_differences(ranges, p, 1e-6)  # (B, n, 3)
    np.testing.assert_allclose(np.moveaxis(J, 0, -1), numeric, rtol=0, atol=1e-8)


# --------------------------------------------------------------------------- per-replicate parameters

SEEDS = {"seed": 3, "scenario_key": 1, "cell": 2}


def _interleave(a, b):
    """[a0, b0, a1, b1, ...]: replicate indices of the mixed batch and the value of each."""
    return np.ravel(np.column_stack([a, b]))


def _step_platform(params, replicates, steps=40, dt=0.1):
    core = PlatformCore(params, replicates)
    core.initialize(0.0)
    out = [dict(core.outputs)]
    for k in range(steps):
        core.step(k * dt, dt)
        out.append(dict(core.outputs))
    return {name: np.stack([o[name] for o in out]) for name in out[0]}  # (steps + 1, B)


PLATFORM_LEVELS = [
    {"baseline": 0.4, "transducer_depth": 0.5, "heading_deg": -30.0, "gps_sigma": 0.1, "imu_sigma_deg": 1.0,
     "imu_bias_deg": 0.0, "imu_gyro_bias": 0.0, "gps_tau": 20.0},
    {"baseline": 3.0, "transducer_depth": 2.0, "heading_deg": 45.0, "gps_sigma": 3.5, "imu_sigma_deg": 10.0,
     "imu_bias_deg": 2.0, "imu_gyro_bias": 0.01, "gps_tau": 90.0},
]


@pytest.mark.parametrize("gps_model", ["white", "gauss-markov"])
def test_platform_mixed_batch_equals_scalar_batches(gps_model):
    reps_a, reps_b = np.array([0, 2, 4]), np.array([1, 3, 5])
    mixed_reps = _interleave(reps_a, reps_b)
    low, high = PLATFORM_LEVELS
    mixed = {name: _interleave(np.full(3, low[name]), np.full(3, high[name])) for name in low}
    common = {**SEEDS, "gps_model": gps_model, "beaufort": 3}
    got = _step_platform({**common, **mixed}, mixed_reps)
    ref_a = _step_platform({**common, **low}, reps_a)
    ref_b = _step_platform({**common, **high}, reps_b)
    for name, values in got.items():
        np.testing.assert_array_equal(values[:, 0::2], ref_a[name], err_msg=name, strict=True)
        np.testing.assert_array_equal(values[:, 1::2], ref_b[name], err_msg=name, strict=True)
    # and the two levels really differ
    assert not np.array_equal(ref_a["beacon1_x"], ref_b["beacon1_x"])


def _step_acoustics(params, replicates, steps=60, dt=0.2):
    core = AcousticsCore(params, replicates)
    core.initialize(0.0)
    reps = np.asarray(replicates, dtype=float)
    out = []
    for k in range(steps):
        t = k * dt
        inputs = {}
        for i in range(1, 5):  # deterministic per-replicate inputs: the same in every batch
            for j, a in enumerate("xyz"):
                value = np.cos(0.3 * t + i + j + 0.1 * reps) * (1.0 + 0.2 * i)
                inputs[f"beacon{i}_true_{a}"] = value
                inputs[f"beacon{i}_{a}"] = value + 0.01 * np.sin(t + reps)
        inputs.update(target_x=15.0 * np.cos(0.05 * t + reps), target_y=15.0 * np.sin(0.05 * t + reps),
                      target_z=5.0 + 0.1 * reps, target_vx=-0.75 * np.sin(0.05 * t + reps),
                      target_vy=0.75 * np.cos(0.05 * t + reps), target_vz=np.zeros_like(reps))
        core.set_inputs(inputs)
        core.step(t, dt)
        out.append(dict(core.outputs))
    return {name: np.stack([o[name] for o in out]) for name in out[0]}


def test_acoustics_mixed_batch_equals_scalar_batches():
    low = {"sigma_range": 0.1, "loss_pct": 0.0, "outlier_pct": 0.0, "outlier_excess": 2.0, "clock_drift_ppm": 0.0,
           "sound_speed_assumed": 1500.0}
    high = {"sigma_range": 1.0, "loss_pct": 25.0, "outlier_pct": 30.0, "outlier_excess": 5.0, "clock_drift_ppm": 50.0,
            "sound_speed_assumed": 1480.0}
    reps_a, reps_b = np.array([0, 1, 2, 3]), np.array([7, 8, 9, 10])
    mixed = {name: _interleave(np.full(4, low[name]), np.full(4, high[name])) for name in low}
    got = _step_acoustics({**SEEDS, **mixed}, _interleave(reps_a, reps_b))
    ref_a = _step_acoustics({**SEEDS, **low}, reps_a)
    ref_b = _step_acoustics({**SEEDS, **high}, reps_b)
    for name, values in got.items():
        np.testing.assert_array_equal(values[:, 0::2], ref_a[name], err_msg=name, strict=True)
        np.testing.assert_array_equal(values[:, 1::2], ref_b[name], err_msg=name, strict=True)
    assert ref_b["outlier"].any() and not ref_b["packet_valid"].all()  # the high level is exercised


def _cell_config(cell, levels):
    overrides = ["simulation.duration=8", "acoustics.loss_pct=10", *levels, f"run.cell={cell}"]
    return load_config("semicircle", overrides, seed=4)


def test_run_batch_spanning_two_cells_equals_one_cell_batches():
    """The whole system (all four cores, receiver included) on a batch mixing two cells."""
    low = _cell_config(0, ["platform.baseline=0.4", "acoustics.sigma_range=0.1", "receiver.q_horizontal=0.01",
                           "target.depth_sigma=0.01"])
    high = _cell_config(5, ["platform.baseline=3.0", "acoustics.sigma_range=1.0", "receiver.q_horizontal=0.5",
                            "target.depth_sigma=0.1"])
    a, b = with_replicates(low, [0, 1, 2]), with_replicates(high, [0, 1, 2])
    mixed = run_batch([a[0], b[0], a[1], b[1], a[2], b[2]], "local")
    ref_a, ref_b = run_batch(a, "local"), run_batch(b, "local")
    steps = mixed.steps
    assert steps == ref_a.steps == 80
    for k, (ref, r) in enumerate([(ref_a, 0), (ref_b, 0), (ref_a, 1), (ref_b, 1), (ref_a, 2), (ref_b, 2)]):
        got_metrics = mixed.metrics.iloc[k]
        want_metrics = ref.metrics.iloc[r]
        for name in mixed.metrics.columns:
            assert got_metrics[name] == want_metrics[name] or (np.isnan(got_metrics[name])
                                                               and np.isnan(want_metrics[name])), name
        got_series = mixed.timeseries.iloc[k * steps:(k + 1) * steps].reset_index(drop=True)
        want_series = ref.timeseries.iloc[r * steps:(r + 1) * steps].reset_index(drop=True)
        assert (got_series["replicate"] == r).all()
        # bit-identical, NaN where the other has NaN
        assert got_series.equals(want_series), k
    assert not ref_a.metrics["e_tot_rms"].equals(ref_b.metrics["e_tot_rms"])


def test_array_for_a_non_batched_parameter_is_refused():
    with pytest.raises(ModelError, match=r"platform\.beaufort") as info:
        PlatformCore({**SEEDS, "beaufort": np.array([1, 3])}, [0, 1])
    assert "\n" not in str(info.value)
    with pytest.raises(ModelError, match=r"acoustics\.sound_speed_true"):
        AcousticsCore({**SEEDS, "sound_speed_true": np.array([1490.0, 1510.0])}, [0, 1])
    # the same through run_batch: two configurations differing in a non-batched key
    cfgs = [load_config("semicircle", ["simulation.duration=1", f"platform.beaufort={b}"]) for b in (1, 3)]
    with pytest.raises(ModelError, match=r"platform\.beaufort"):
        run_batch(cfgs, "local")


def test_wrong_length_or_out_of_range_per_replicate_array_is_refused():
    with pytest.raises(ModelError, match=r"platform\.baseline: 3 per-replicate values for a batch of 4"):
        PlatformCore({**SEEDS, "baseline": np.array([0.4, 3.0, 0.4])}, [0, 1, 2, 3])
    with pytest.raises(ModelError, match=r"acoustics\.loss_pct.*\[0, 100\]"):
        AcousticsCore({**SEEDS, "loss_pct": np.array([0.0, 150.0])}, [0, 1])
    # an array whose values are all equal is the scalar itself
    core = PlatformCore({**SEEDS, "baseline": np.array([2.0, 2.0])}, [0, 1])
    assert core.params["baseline"] == 2.0 and isinstance(core.params["baseline"], float)


# --------------------------------------------------------------------------- multilateration

def _cost(p, ranges, beacons, depth, sr, sd):
    """Σ ((r_i − ‖p − b_i‖)/σ_r)² + ((d − p_z)/σ_d)², p (B, 3), NaN ranges left out."""
    h = np.linalg.norm(p[:, None, :] - beacons, axis=-1)
    res = np.where(np.isfinite(ranges), (ranges - h) / sr, 0.0)
    return np.sum(res * res, axis=-1) + ((depth - p[:, 2]) / sd) ** 2


def _scipy_fix(ranges, beacons, depth, sr, sd, start):
    have = np.isfinite(ranges)

    def residuals(p):
        return np.concatenate([(ranges[have] - np.linalg.norm(p - beacons[have], axis=-1)) / sr,
                               [(depth - p[2]) / sd]])

    sol = least_squares(residuals, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=10000)
    return sol.x


def _well_conditioned(rng, B):
    beacons = np.empty((B, 4, 3))
    beacons[..., :2] = rng.uniform(-20.0, 20.0, size=(B, 4, 2))
    beacons[..., 2] = rng.uniform(0.0, 2.0, size=(B, 4))
    truth = np.column_stack([rng.uniform(-25, 25, B), rng.uniform(-25, 25, B), rng.uniform(5, 20, B)])
    sr, sd = 0.2, 0.05
    ranges = np.linalg.norm(truth[:, None, :] - beacons, axis=-1) + sr * rng.normal(size=(B, 4))
    depth = truth[:, 2] + sd * rng.normal(size=B)
    return beacons, truth, ranges, depth, sr, sd


def test_multilaterate_agrees_with_scipy_least_squares():
    rng = np.random.default_rng(21)
    B = 60
    beacons, truth, ranges, depth, sr, sd = _well_conditioned(rng, B)
    ranges[3, 1] = np.nan  # three ranges still make a fix
    guess = truth + rng.normal(scale=3.0, size=(B, 3))
    fix, valid = multilaterate(ranges, beacons, depth, guess, sr, sd, iterations=50, tolerance=1e-9)
    assert valid.all()
    for b in range(B):
        ref = _scipy_fix(ranges[b], beacons[b], depth[b], sr, sd, truth[b])
        np.testing.assert_allclose(fix[b], ref, rtol=0, atol=1e-6, err_msg=f"replicate {b}")
    # the fix minimizes the cost: no point of scipy's is better
    refs = np.array([_scipy_fix(ranges[b], beacons[b], depth[b], sr, sd, truth[b]) for b in range(B)])
    assert np.all(_cost(fix, ranges, beacons, depth, sr, sd) <= _cost(refs, ranges, beacons, depth, sr, sd) + 1e-9)


def test_multilaterate_default_settings_stop_near_the_optimum():
    """With the default cap and tolerance the fix is a negligible fraction of a standard deviation
    from scipy's optimum (the stopping rule is on the step, δᵀ JᵀWJ δ ≤ tolerance²)."""
    rng = np.random.default_rng(27)
    B = 40
    beacons, truth, ranges, depth, sr, sd = _well_conditioned(rng, B)
    guess = truth + rng.normal(scale=1.0, size=(B, 3))
    fix, valid = multilaterate(ranges, beacons, depth, guess, sr, sd)
    assert valid.all()
    refs = np.array([_scipy_fix(ranges[b], beacons[b], depth[b], sr, sd, truth[b]) for b in range(B)])
    diff = refs[:, None, :] - beacons
    J = diff / np.linalg.norm(diff, axis=-1, keepdims=True)
    A = np.einsum("bni,bnj->bij", J, J) / sr**2  # JᵀWJ at the optimum
    A[:, 2, 2] += 1.0 / sd**2
    d = fix - refs
    mahalanobis = np.sqrt(np.einsum("bi,bij,bj->b", d, A, d))
    assert np.all(mahalanobis < 1e-2), mahalanobis.max()
    np.testing.assert_allclose(fix, refs, rtol=0, atol=1e-2 * sr)


@pytest.mark.parametrize("start", ["previous fix", "array centre", "far", "poor depth"])
def test_multilaterate_poor_geometry_never_worse_than_its_start(start):
    """0.4 m baseline, 1 m range noise: LM only takes steps that lower the cost, so no run-away."""
    rng = np.random.default_rng(23)
    B = 500
    L, h = 0.4, 1.0
    cross = np.array([[L, 0, h], [0, L, h], [-L, 0, h], [0, -L, h]])
    beacons = np.broadcast_to(cross, (B, 4, 3)) + 0.02 * rng.normal(size=(B, 4, 3))  # broadcast (GPS/IMU) error
    angle = rng.uniform(0, 2 * np.pi, B)
    distance = rng.uniform(2.0, 30.0, B)
    truth = np.column_stack([distance * np.cos(angle), distance * np.sin(angle), rng.uniform(2, 15, B)])
    sr, sd = 1.0, 0.05
    ranges = np.abs(np.linalg.norm(truth[:, None, :] - beacons, axis=-1) + sr * rng.normal(size=(B, 4)))
    depth = truth[:, 2] + sd * rng.normal(size=B)
    guess = {
        "previous fix": np.column_stack([truth[:, :2] + rng.normal(scale=3.0, size=(B, 2)), depth]),
        "array centre": np.column_stack([np.zeros((B, 2)), depth]),
        "far": np.column_stack([rng.uniform(-60.0, 60.0, size=(B, 2)), depth]),
        "poor depth": truth + rng.normal(scale=10.0, size=(B, 3)),
    }[start]
    fix, valid = multilaterate(ranges, beacons, depth, guess, sr, sd)
    assert valid.all() and np.all(np.isfinite(fix))

    # the start is the guess or the closed-form fix, whichever has the lower cost
    start_linear = linear_fix(ranges, np.moveaxis(beacons, -1, 0), depth, np.isfinite(ranges))
    start_cost = np.minimum(_cost(guess, ranges, beacons, depth, sr, sd),
                            _cost(start_linear, ranges, beacons, depth, sr, sd))
    final_cost = _cost(fix, ranges, beacons, depth, sr, sd)
    assert np.all(final_cost <= start_cost * (1 + 1e-12)), np.max(final_cost - start_cost)
    assert np.mean(final_cost < start_cost) > 0.5  # and it does improve most of them
    if start in ("previous fix", "array centre"):  # the starts the receiver uses
        max_range = np.max(ranges, axis=1)
        assert np.all(np.linalg.norm(fix, axis=1) <= 3.0 * max_range), np.max(np.linalg.norm(fix, axis=1) / max_range)
