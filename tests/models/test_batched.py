"""Batch invariance of the compiled engine and per-replicate parameters.

A replicate's numbers must not depend on the batch it is stepped in
(sblsim.models.philox, "Randomness"): for every model, a replicate stepped alone
(B = 1) equals the same replicate inside a batch, bit for bit; a batch whose
parameters differ per replicate (a batch spanning two design cells) equals
separate batches of one parameter value each; and the whole system run by
``run_batch`` on configurations from two cells equals the runs of each cell
alone. References are the separate runs themselves (independent batches of
the same compiled code) and :meth:`Component.parameter_vector` of each
scalar value.
"""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.fmus.native import NativeBatch
from sblsim.models import Acoustics, LeastSquaresReceiver, PaperEKF, Platform, Target
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim import local_engine
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run_batch, with_replicates
from tests.helpers import Core

SEEDS = {"seed": 3, "scenario_key": 1, "cell": 2}
DT, STEPS = 0.1, 60
CROSS = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [-1.0, 0.0, 1.0], [0.0, -1.0, 1.0]])


def _interleave(a, b):
    """[a0, b0, a1, b1, ...]: replicate indices of the mixed batch and the value of each."""
    return np.ravel(np.column_stack([a, b]))


# --------------------------------------------------------------------------- deterministic per-replicate inputs

def _acoustics_inputs(t, reps):
    inputs = {}
    for i in range(1, 5):
        for j, a in enumerate("xyz"):
            value = np.cos(0.3 * t + i + j + 0.1 * reps) * (1.0 + 0.2 * i)
            inputs[f"beacon{i}_true_{a}"] = value
            inputs[f"beacon{i}_{a}"] = value + 0.01 * np.sin(t + reps)
    inputs.update(target_x=15.0 * np.cos(0.05 * t + reps), target_y=15.0 * np.sin(0.05 * t + reps),
                  target_z=5.0 + 0.1 * reps, target_vx=-0.75 * np.sin(0.05 * t + reps),
                  target_vy=0.75 * np.cos(0.05 * t + reps), target_vz=np.zeros_like(reps))
    return inputs


def _packet_inputs(t, reps):
    """One round-robin packet per step (sent and arrived within the step), some lost, ranges from a moving diver."""
    k = int(round(t / DT))
    beacon = k % 4
    valid = ((k + reps.astype(int)) % 5 != 0).astype(float)
    diver = np.column_stack([15.0 * np.cos(0.05 * t + reps), 15.0 * np.sin(0.05 * t + reps), 5.0 + 0.1 * reps])
    rng = np.linalg.norm(diver - CROSS[beacon], axis=1) + 0.05 * np.sin(3.0 * k + reps)
    return {"packet_seq": np.full(reps.size, k + 1.0), "beacon_id": np.full(reps.size, beacon + 1.0),
            "packet_valid": valid, "tx_time": np.full(reps.size, t + 0.9 * DT), "range": rng * valid,
            "rx_time": np.full(reps.size, t + 0.99 * DT),
            **{f"beacon_{a}": CROSS[beacon, j] * valid for j, a in enumerate("xyz")},
            "depth": diver[:, 2] + 0.01 * np.cos(k + reps)}


INPUTS = {Platform: None, Target: None, Acoustics: _acoustics_inputs, PaperEKF: _packet_inputs,
          LeastSquaresReceiver: _packet_inputs}
#: Scalar parameters of the invariance runs (the stochastic and event-driven paths exercised).
COMMON = {
    Platform: {**SEEDS, "beaufort": 4, "gps_model": "gauss-markov", "gps_tau": 5.0, "imu_gyro_bias": 0.01},
    Target: {**SEEDS, "trajectory": "random", "turn_interval": 0.7, "max_radius": 2.0, "speed": 1.5,
             "depth_sigma": 0.05},
    Acoustics: {**SEEDS, "sigma_range": 0.5, "loss_pct": 25.0, "outlier_pct": 30.0, "slot_period": 0.2,
                "sound_speed_profile": "ctd:11E101663_20120821_122817"},
    PaperEKF: {"x0_x": 14.0, "x0_z": 5.0},
    LeastSquaresReceiver: {**SEEDS, "x0_x": 14.0, "x0_z": 5.0},
}
MODELS = list(INPUTS)


def _core(model, params, replicates, arrays=None):
    """A batch of the compiled model; ``arrays`` are per-replicate FMU parameter values, shape (B,).

    They are set on the FMU parameters the helper resolved from the scalar ``params``, as
    ``sblsim.orchestrator.cosim.run.merge_params`` does (the helper resolves configuration keys one value each).
    """
    core = Core(model, params, replicates=replicates)
    core.values.update(arrays or {})
    return core


def _step(model, params, replicates, arrays=None):
    """Outputs of every step (STEPS + 1, B) and the final state blocks (B, size) of one batch."""
    core = _core(model, params, replicates, arrays)
    core.initialize(0.0)
    reps = np.asarray(replicates, dtype=float)
    out = [dict(core.outputs)]
    for k in range(STEPS):
        t = k * DT
        if INPUTS[model] is not None:
            core.set_inputs(INPUTS[model](t, reps))
        core.step(t, DT)
        out.append(dict(core.outputs))
    return {name: np.stack([o[name] for o in out]) for name in out[0]}, core.state


def _assert_columns_equal(got, want, columns, label):
    for name, values in want.items():
        np.testing.assert_array_equal(got[name][..., columns], values, err_msg=f"{label} {name}", strict=True)


# --------------------------------------------------------------------------- batch invariance

@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_replicate_alone_equals_replicate_in_batch(model):
    batch = [3, 0, 7, 1, 5]
    outs, states = _step(model, COMMON[model], batch)
    for j in (0, 2, 4):
        alone_out, alone_state = _step(model, COMMON[model], [batch[j]])
        _assert_columns_equal(outs, alone_out, slice(j, j + 1), f"{model.name} replicate {batch[j]}")
        for name, block in alone_state.items():
            np.testing.assert_array_equal(states[name][j:j + 1], block, err_msg=f"{model.name} state {name}")
    # the replicates of the batch really differ (the comparison is not between identical columns)
    varying = [name for name, v in outs.items() if not np.all(v == v[:, :1])]
    assert varying, f"{model.name}: every replicate gave the same outputs"


def test_replicate_order_in_batch_does_not_matter():
    outs, _ = _step(Acoustics, COMMON[Acoustics], [0, 1, 2, 3])
    rev, _ = _step(Acoustics, COMMON[Acoustics], [3, 2, 1, 0])
    _assert_columns_equal(outs, {n: v[:, ::-1] for n, v in rev.items()}, slice(None), "reversed")


# --------------------------------------------------------------------------- per-replicate parameters

#: Two design cells per model: the factor levels of each (seed key ``cell`` included).
LEVELS = {
    Platform: [
        {"cell": 2, "baseline": 0.4, "transducer_depth": 0.5, "heading_deg": -30.0, "gps_sigma": 0.1,
         "imu_sigma_deg": 1.0, "imu_bias_deg": 0.0, "imu_gyro_bias": 0.0, "gps_tau": 20.0, "beaufort": 1,
         "installation_sigma": 0.0, "imu_scale_factor_ppm": 0.0, "imu_misalignment_deg": 0.0},
        {"cell": 5, "baseline": 3.0, "transducer_depth": 2.0, "heading_deg": 45.0, "gps_sigma": 3.5,
         "imu_sigma_deg": 10.0, "imu_bias_deg": 2.0, "imu_gyro_bias": 0.01, "gps_tau": 90.0, "beaufort": 5,
         "installation_sigma": 0.2, "imu_scale_factor_ppm": 3000.0, "imu_misalignment_deg": 1.0},
    ],
    Acoustics: [
        {"cell": 2, "sigma_range": 0.1, "loss_pct": 0.0, "outlier_pct": 0.0, "outlier_excess": 2.0,
         "clock_drift_ppm": 0.0, "sound_speed_assumed": 1500.0, "sound_speed_true": 1490.0, "slot_period": 0.2},
        {"cell": 5, "sigma_range": 1.0, "loss_pct": 25.0, "outlier_pct": 30.0, "outlier_excess": 5.0,
         "clock_drift_ppm": 50.0, "sound_speed_assumed": 1480.0, "sound_speed_true": 1520.0, "slot_period": 0.3},
    ],
    Target: [
        {"cell": 2, "speed": 0.5, "depth": 5.0, "radius": 15.0, "depth_sigma": 0.01, "turn_interval": 1.0},
        {"cell": 5, "speed": 1.5, "depth": 12.0, "radius": 8.0, "depth_sigma": 0.2, "turn_interval": 0.5},
    ],
    PaperEKF: [
        {"sigma_range": 0.1, "sigma_depth": 0.01, "q_horizontal": 0.01, "q_vertical": 0.001, "p0_position": 1.0,
         "p0_velocity": 0.5, "x0_x": 14.0},
        {"sigma_range": 1.0, "sigma_depth": 0.1, "q_horizontal": 0.5, "q_vertical": 0.01, "p0_position": 5.0,
         "p0_velocity": 1.0, "x0_x": 10.0},
    ],
    LeastSquaresReceiver: [
        {"cell": 2, "sigma_range": 0.1, "sigma_depth": 0.01, "x0_x": 14.0},
        {"cell": 5, "sigma_range": 1.0, "sigma_depth": 0.1, "x0_x": 10.0},
    ],
}
CASES = [(Platform, {"gps_model": "white"}), (Platform, {"gps_model": "gauss-markov"}),
         (Acoustics, {}), (Target, {"trajectory": "random"}), (Target, {"trajectory": "spiral"}),
         (PaperEKF, {}), (LeastSquaresReceiver, {})]


@pytest.mark.parametrize("model,extra", CASES, ids=lambda c: getattr(c, "name", None) or "-".join(map(str, c.values())))
def test_mixed_batch_equals_scalar_batches(model, extra):
    """Cell a and cell b interleaved in one batch, each with the same replicate numbers (as run_batch does)."""
    reps = np.array([0, 1, 2])
    low, high = LEVELS[model]
    common = {**SEEDS, **extra} if "cell" in low else dict(extra)
    mixed = {name: _interleave(np.full(3, low[name]), np.full(3, high[name])) for name in low}
    got, got_state = _step(model, {**common, **low}, _interleave(reps, reps), arrays=mixed)
    ref_a, state_a = _step(model, {**common, **low}, reps)
    ref_b, state_b = _step(model, {**common, **high}, reps)
    _assert_columns_equal(got, ref_a, slice(0, None, 2), "cell a")
    _assert_columns_equal(got, ref_b, slice(1, None, 2), "cell b")
    for name in state_a:
        np.testing.assert_array_equal(got_state[name][0::2], state_a[name], err_msg=name)
        np.testing.assert_array_equal(got_state[name][1::2], state_b[name], err_msg=name)
    # and the two cells really differ
    assert any(not np.array_equal(ref_a[n], ref_b[n]) for n in ref_a)


def test_acoustics_high_level_is_exercised():
    """The mixed acoustics batch above covers losses, outliers and two slot clocks."""
    low, high = LEVELS[Acoustics]
    ref_b, _ = _step(Acoustics, {**SEEDS, **high}, [0, 1, 2])
    ref_a, _ = _step(Acoustics, {**SEEDS, **low}, [0, 1, 2])
    assert ref_b["outlier"].any() and not ref_b["packet_valid"].all()
    # slot clocks: 6 s at 0.2 s and 0.3 s per slot; the last slot, sent at 6 s, is still in flight
    assert ref_a["packet_seq"][-1].tolist() == [29] * 3 and ref_b["packet_seq"][-1].tolist() == [19] * 3


@pytest.mark.parametrize("model,extra", CASES, ids=lambda c: getattr(c, "name", None) or "-".join(map(str, c.values())))
def test_shared_parameter_rows_equal_one_row_per_replicate(model, extra, monkeypatch):
    """The replicates of a design cell share one parameter row (its derived values prepared once) and key their
    random streams by their own replicate: the same numbers as one row per replicate whose ``replicate``
    parameter keys the streams (as in an FMU)."""
    reps = np.array([3, 0, 7, 1, 5, 2])
    low, high = LEVELS[model]
    common = {**SEEDS, **extra} if "cell" in low else dict(extra)
    cells = {name: np.where(np.arange(6) % 3 == 1, high[name], low[name]) for name in low}  # cells a b a a b a
    shared = _core(model, {**common, **low}, reps, arrays=cells).initialize(0.0)
    assert (shared.handle.batch.batch, shared.handle.batch.rows) == (6, 2)
    got, got_state = _step(model, {**common, **low}, reps, arrays=cells)
    # the reference: one row per replicate, the runtime's draws keyed by each row's replicate parameter
    assign = NativeBatch.assign
    monkeypatch.setattr(local_engine, "parameter_rows", lambda params, size: (np.arange(size), np.arange(size)))
    monkeypatch.setattr(NativeBatch, "assign", lambda self, row_of, replicate=None: assign(self, row_of, None))
    alone = _core(model, {**common, **low}, reps, arrays=cells).initialize(0.0)
    assert alone.handle.batch.rows == 6
    seeded = "cell" in low
    if seeded:
        names = [v.name for v in model.fmu_parameters_declared()]
        np.testing.assert_array_equal(alone.handle.batch.p[:, names.index("replicate")], reps)
    want, want_state = _step(model, {**common, **low}, reps, arrays=cells)
    _assert_columns_equal(got, want, slice(None), "shared rows")
    for name in want_state:
        np.testing.assert_array_equal(got_state[name], want_state[name], err_msg=name)
    if seeded:  # two replicates of one cell really differ: the keys are compared, not ignored
        assert any(not np.array_equal(v[:, 0], v[:, 2]) for v in want.values())


def test_parameter_rows_group_runs_bit_for_bit():
    size = 6
    rows, first = local_engine.parameter_rows({"a": np.array([1.0, 1.0, -0.0, 0.0, 1.0, np.nan]), "b": 2.0,
                                          "replicate": np.arange(size)}, size)
    assert rows.tolist() == [0, 0, 1, 2, 0, 3] and first.tolist() == [0, 2, 3, 5]  # -0.0 is not 0.0
    rows, first = local_engine.parameter_rows({"a": 1.0, "replicate": np.arange(size)}, size)
    assert rows.tolist() == [0] * size and first.tolist() == [0]
    rows, first = local_engine.parameter_rows({"a": np.array(["x", "y", "x"]), "c": np.array([1, 1, 2])}, 3)
    assert rows.tolist() == [0, 1, 2] and first.tolist() == [0, 1, 2]
    # a wrong length: one row each (refused later)
    rows, _ = local_engine.parameter_rows({"a": np.array([1.0, 2.0])}, 3)
    assert rows.tolist() == [0, 1, 2]


def test_parameter_matrix_columns_are_the_scalar_vectors():
    values = {**SEEDS, "baseline": np.array([0.4, 3.0, 0.4]), "beaufort": np.array([1, 5, 3]),
              "gps_model": "gauss-markov"}
    matrix = Platform.parameter_matrix(values, 3)
    for r in range(3):
        scalar = {k: (v[r].item() if isinstance(v, np.ndarray) else v) for k, v in values.items()}
        np.testing.assert_array_equal(matrix[r], Platform.parameter_vector(scalar))
    # an array whose values are all equal is the scalar itself
    np.testing.assert_array_equal(Platform.parameter_matrix({"baseline": np.array([2.0, 2.0])}, 2),
                                  np.tile(Platform.parameter_vector({"baseline": 2.0}), (2, 1)))


@pytest.mark.parametrize("model,values,batch,match", [
    (Platform, {"baseline": np.array([0.4, 3.0, 0.4])}, 4,
     r"^platform\.baseline: 3 per-replicate values for a batch of 4$"),
    (Platform, {"baseline": np.array([[0.4, 3.0], [0.4, 3.0]])}, 2, r"platform\.baseline: 4 per-replicate values"),
    (Acoustics, {"loss_pct": np.array([0.0, 150.0])}, 2, r"acoustics\.loss_pct.*150.*\[0, 100\]"),
    (Acoustics, {"slot_period": np.array([0.1, 0.0])}, 2, r"acoustics\.slot_period.*\[0\.001, 60\]"),
    (Platform, {"baseline": np.array([1.0, 0.0])}, 2, r"platform\.baseline.*\(0, 1000\]"),
    (Platform, {"beaufort": np.array([2, 9])}, 2, r"platform\.beaufort.*\[0, 8\]"),
    (Platform, {"beaufort": np.array([2.0, 2.5])}, 2, r"platform\.beaufort: expected a whole number"),
    (PaperEKF, {"sigma_range": np.array([0.1, np.nan])}, 2, r"receiver\.sigma_range.*not finite"),
    (Target, {"depth": np.array([5.0, -1.0, 5.0])}, 3, r"target\.depth.*\[0, 11000\]"),
    (LeastSquaresReceiver, {"cell": np.array([1, -1])}, 2, r"receiver_lsq\.cell"),
])
def test_parameter_matrix_refuses_wrong_length_or_out_of_range_arrays(model, values, batch, match):
    with pytest.raises(ModelError, match=match) as info:
        model.parameter_matrix(values, batch)
    assert "\n" not in str(info.value)


def test_out_of_range_per_replicate_value_refused_by_the_engine_handle():
    with pytest.raises(ModelError, match=r"acoustics\.loss_pct"):
        _core(Acoustics, SEEDS, [0, 1], {"loss_pct": np.array([0.0, 150.0])}).initialize(0.0)
    with pytest.raises(ModelError, match=r"platform\.baseline: 3 per-replicate values for a batch of 4"):
        _core(Platform, SEEDS, [0, 1, 2, 3], {"baseline": np.array([0.4, 3.0, 0.4])}).initialize(0.0)
    # a per-replicate value the declarations allow but the compiled runtime's own check must also see
    core = _core(Acoustics, SEEDS, [0, 1], {"sigma_range": np.array([0.1, 0.2])})
    core.initialize(0.0)
    core.handle.batch.p[1, [v.name for v in Acoustics.fmu_parameters_declared()].index("loss_pct")] = 150.0
    with pytest.raises(ModelError, match=r"loss_pct: 150 is outside the allowed range \[0, 100\].*replicate 1 of "
                                         r"the batch"):
        core.handle.batch.initialize(0.0)


# --------------------------------------------------------------------------- the whole system

def _cell_config(cell, levels, receiver, duration=8):
    overrides = [f"simulation.duration={duration}", f"simulation.receiver={receiver}", "acoustics.loss_pct=10",
                 *levels, f"run.cell={cell}"]
    return load_config("semicircle", overrides, seed=4)


LOW = ["platform.baseline=0.4", "platform.beaufort=1", "acoustics.sigma_range=0.1", "receiver.sigma_range=0.1",
       "target.depth_sigma=0.01"]
HIGH = ["platform.baseline=3.0", "platform.beaufort=4", "acoustics.sigma_range=1.0", "receiver.sigma_range=1.0",
        "target.depth_sigma=0.1"]
EKF_ONLY = {"low": ["receiver.q_horizontal=0.01"], "high": ["receiver.q_horizontal=0.5"]}


def _assert_batch_equals_separate_runs(low, high):
    """Runs of two configurations interleaved in one batch equal the batches of each configuration alone."""
    a, b = with_replicates(low, [0, 1, 2]), with_replicates(high, [0, 1, 2])
    mixed = run_batch([a[0], b[0], a[1], b[1], a[2], b[2]], "local")
    ref_a, ref_b = run_batch(a, "local"), run_batch(b, "local")
    steps = mixed.steps
    assert steps == ref_a.steps == ref_b.steps == 80
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
    # a run alone is the same run as in the batch
    alone = run_batch([b[1]], "local")
    assert alone.timeseries.equals(ref_b.timeseries.iloc[steps:2 * steps].reset_index(drop=True))


@pytest.mark.parametrize("receiver", ["lsq", "ekf"])
def test_run_batch_spanning_two_cells_equals_one_cell_batches(receiver):
    """The whole system (all four components, receiver included) on a batch mixing two cells."""
    extra = EKF_ONLY if receiver == "ekf" else {"low": [], "high": []}
    _assert_batch_equals_separate_runs(_cell_config(0, LOW + extra["low"], receiver),
                                       _cell_config(5, HIGH + extra["high"], receiver))


def test_run_batch_spanning_two_factor_levels_equals_separate_runs():
    """The paper's EKF system: one cell index, two levels of every numeric factor varied."""
    _assert_batch_equals_separate_runs(_cell_config(3, LOW + EKF_ONLY["low"], "ekf"),
                                       _cell_config(3, HIGH + EKF_ONLY["high"], "ekf"))


def test_run_batch_refuses_runs_differing_in_a_shared_key():
    base = ["simulation.duration=1"]
    text = [load_config("semicircle", base + [f"acoustics.sound_speed_profile={p}"]) for p in ("constant", "teos10")]
    with pytest.raises(ModelError, match=r"acoustics\.sound_speed_profile: must be the same for every run"):
        run_batch(text, "local")
    choice = [load_config("semicircle", base + [f"target.trajectory={p}"]) for p in ("semicircle", "spiral")]
    with pytest.raises(ModelError, match=r"target\.trajectory: must be the same for every run"):
        run_batch(choice, "local")
    sims = [load_config("semicircle", [f"simulation.duration={d}"]) for d in (1, 2)]
    with pytest.raises(ModelError, match=r"simulation: every run of a batch needs the same"):
        run_batch(sims, "local")
