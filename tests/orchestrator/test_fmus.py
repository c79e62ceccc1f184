"""Integration tests of the five native FMUs' model descriptions and of the two engines (local versus fmu)."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from sblsim.fmus.build import fmu_path, validate
from sblsim.models import MODELS
from sblsim.models.declarations import UNITS, ModelError
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.run import run

COMPONENT_NAMES = list(MODELS)


def model_description(path) -> ET.Element:
    with zipfile.ZipFile(path) as archive:
        return ET.fromstring(archive.read("modelDescription.xml"))


def assert_same_frames(a: pd.DataFrame, b: pd.DataFrame, atol: float = 1e-9) -> None:
    """Same shape and columns, every column equal to ``atol`` with identical NaN positions."""
    assert a.shape == b.shape
    assert list(a.columns) == list(b.columns)
    for column in a.columns:
        x = a[column].to_numpy(dtype=float)
        y = b[column].to_numpy(dtype=float)
        nan_x, nan_y = np.isnan(x), np.isnan(y)
        assert np.array_equal(nan_x, nan_y), f"{column}: NaN positions differ"
        diff = np.abs(x[~nan_x] - y[~nan_y])
        assert diff.size == 0 or diff.max() <= atol, f"{column}: max difference {diff.max()}"


# --------------------------------------------------------------------------- the built FMUs

@pytest.mark.parametrize("name", COMPONENT_NAMES)
def test_fmu_validates_with_zero_problems(fmu_dir, name):
    path = fmu_path(fmu_dir, name)
    assert path.is_file()
    assert validate(path) == []


@pytest.mark.parametrize("name", COMPONENT_NAMES)
def test_fmu_declares_a_defined_unit_on_every_real(fmu_dir, name):
    root = model_description(fmu_path(fmu_dir, name))
    defined = {u.get("name") for u in root.findall("UnitDefinitions/Unit")}
    assert defined, "no UnitDefinitions"
    reals = root.findall("ModelVariables/ScalarVariable/Real")
    assert reals, "no Real variables"
    for sv in root.findall("ModelVariables/ScalarVariable"):
        real = sv.find("Real")
        if real is None:
            continue
        unit = real.get("unit")
        assert unit is not None, f"{sv.get('name')}: Real without unit"
        assert unit in defined, f"{sv.get('name')}: unit {unit!r} not in UnitDefinitions"
    # the unit definitions agree with the declared table (exponents and factor)
    for unit in root.findall("UnitDefinitions/Unit"):
        exponents, factor = UNITS[unit.get("name")]
        base = dict(unit.find("BaseUnit").attrib)
        got_factor = float(base.pop("factor", 1.0))
        assert {k: int(v) for k, v in base.items()} == exponents
        assert got_factor == pytest.approx(factor, rel=1e-15)


@pytest.mark.parametrize("name", COMPONENT_NAMES)
def test_fmu_lists_every_output_as_initial_unknown(fmu_dir, name):
    root = model_description(fmu_path(fmu_dir, name))
    svs = root.findall("ModelVariables/ScalarVariable")
    output_indices = {str(i) for i, sv in enumerate(svs, start=1) if sv.get("causality") == "output"}
    assert output_indices
    initial = {u.get("index") for u in root.findall("ModelStructure/InitialUnknowns/Unknown")}
    outputs = {u.get("index") for u in root.findall("ModelStructure/Outputs/Unknown")}
    assert output_indices <= initial
    assert outputs == output_indices


@pytest.mark.parametrize("name", COMPONENT_NAMES)
def test_fmu_variables_equal_the_declarations(fmu_dir, name):
    root = model_description(fmu_path(fmu_dir, name))
    svs = root.findall("ModelVariables/ScalarVariable")
    got = [(sv.get("name"), sv.get("causality"), sv.get("variability"), int(sv.get("valueReference")))
           for sv in svs]
    declared = MODELS[name].fmu_variables()
    assert got == [(v.name, v.causality, v.variability, k) for k, v in enumerate(declared)]
    # the FMI type, unit and range of each variable match too; no String variable (SSP hosts cannot set them)
    for sv, v in zip(svs, declared):
        typed = sv[0]
        assert typed.tag == v.fmi_type != "String"
        if v.fmi_type == "Real":
            assert typed.get("unit") == v.unit
        if v.causality == "parameter" and v.type == "String":  # a choice: its index, with the choices described
            assert (typed.get("min"), typed.get("max")) == ("0", str(len(v.choices) - 1))
            assert all(f"{k}: {c}" in sv.get("description") for k, c in enumerate(v.choices))


@pytest.mark.parametrize("name", COMPONENT_NAMES)
def test_sampled_signals_are_discrete_and_the_fmu_is_honest_about_itself(fmu_dir, name):
    root = model_description(fmu_path(fmu_dir, name))
    cs = root.find("CoSimulation").attrib
    assert cs["needsExecutionTool"] == "false"
    assert cs["canBeInstantiatedOnlyOncePerProcess"] == "false"
    assert cs["canHandleVariableCommunicationStepSize"] == "true"
    assert cs["canGetAndSetFMUstate"] == cs["canSerializeFMUstate"] == "true"
    variability = {sv.get("name"): sv.get("variability") for sv in root.findall("ModelVariables/ScalarVariable")
                   if sv.get("causality") != "parameter"}
    sampled = {"packet_seq", "beacon_id", "packet_valid", "tx_time", "range", "beacon_x", "beacon_y", "beacon_z",
               "depth", "depth_measured", "est_x", "instr_x", "instr_valid", "nis", "gps_x", "beacon1_x"}
    for signal in sampled & set(variability):
        assert variability[signal] == "discrete", signal
    for signal in {"pos_x", "vel_x", "beacon1_true_x", "roll", "target_x"} & set(variability):
        assert variability[signal] == "continuous", signal
    # the sources it was built from travel with it, and the model description lists them
    with zipfile.ZipFile(fmu_path(fmu_dir, name)) as archive:
        names = set(archive.namelist())
    listed = {f.get("name") for f in root.findall("CoSimulation/SourceFiles/File")}
    assert listed and {f"sources/{f}" for f in listed} <= names
    assert f"binaries/linux64/sblsim_{name}.so" in names


def test_a_plain_simulate_runs_a_whole_scenario(fmu_dir):
    """The default experiment has a stop time, so a host's plain simulate runs the default path's pass (the
    semicircle's 94.2 s), not a host's own default of 1 s."""
    from fmpy import simulate_fmu

    result = simulate_fmu(str(fmu_path(fmu_dir, "target")), output=["pos_y"])
    assert result["time"][-1] == pytest.approx(100.0)
    assert result["pos_y"][-1] == pytest.approx(15.0, abs=0.05)  # the semicircle ends at East 15 m


# --------------------------------------------------------------------------- local versus fmu engine


@pytest.fixture(scope="module")
def fmu_handles(fmu_dir):
    handles = make_handles("fmu", fmu_dir)
    yield handles
    close_handles(handles)


def test_engines_agree_on_full_semicircle(fmu_handles):
    cfg = load_config("semicircle", seed=1)
    local = run(cfg, "local")
    fmu = run(cfg, "fmu", handles=fmu_handles)
    expected_steps = int(np.floor(np.pi * cfg["target"]["radius"] / cfg["target"]["speed"]
                                  / cfg["simulation"]["sampling_time"] + 1e-9))
    assert local.steps == fmu.steps == expected_steps
    assert len(local.timeseries) == expected_steps
    assert_same_frames(local.timeseries, fmu.timeseries)
    assert_same_frames(local.metrics, fmu.metrics)
    # the run is not degenerate: the estimate follows the truth
    assert local.metrics["e_tot_mean"].iloc[0] < 5.0


@pytest.mark.parametrize("name", ["semicircle", "spiral", "random", "square", "harbour", "random-walk"])
def test_engines_agree_on_every_scenario_with_loss_and_multipath(fmu_handles, name):
    """20 % loss and 5 % multipath through both engines: every output equal to 1e-9 (they run the same C)."""
    cfg = load_config(name, ["simulation.duration=30", "acoustics.loss_pct=20", "acoustics.outlier_pct=5"],
                      seed=7)
    local = run(cfg, "local")
    fmu = run(cfg, "fmu", handles=fmu_handles)
    assert local.steps == fmu.steps == 300
    series = local.timeseries
    assert not series["packet_valid"].all() and series["outlier"].any()  # the loss and multipath paths run
    # finite everywhere, but for the instrumentation's steps without a fix and the estimate before the first fix
    estimate = [f"est_{a}" for a in ("x", "y", "z", "vx", "vy", "vz")] + ["e_x", "e_y", "e_z", "e_tot"]
    assert np.all(np.isfinite(series.select_dtypes("number").drop(columns=["instr_e_x", "instr_e_y", "instr_e_z",
                                                                           "instr_e_tot", *estimate])))
    fixed = np.isfinite(series[estimate].to_numpy()).all(axis=1)
    assert fixed.any() and fixed[np.argmax(fixed):].all()  # NaN only before the first fix
    assert_same_frames(local.timeseries, fmu.timeseries)


@pytest.mark.parametrize("receiver", ["ekf-seq", "ukf", "lsq"])
@pytest.mark.parametrize("name", ["random", "random-walk"])
def test_engines_agree_for_every_receiver(fmu_dir, receiver, name):
    """Each alternative receiver on both engines, with loss, multipath and its gate at work: equal to 1e-9."""
    cfg = load_config(name, ["simulation.duration=30", "acoustics.loss_pct=20", "acoustics.outlier_pct=10",
                             f"receiver={receiver}", "simulation.ekf_rate_ratio=2"], seed=8)
    local = run(cfg, "local", replicates=[0, 1])
    fmu = run(cfg, "fmu", fmu_dir=fmu_dir, replicates=[0, 1])
    if receiver != "lsq":
        assert local.timeseries["gated"].any()
    assert_same_frames(local.timeseries, fmu.timeseries)
    assert_same_frames(local.metrics, fmu.metrics)


@pytest.mark.parametrize("name, overrides", [
    ("harbour", ["simulation.duration=10", "simulation.ekf_rate_ratio=3"]),
    ("spiral", ["simulation.duration=10", "platform.gps_model=gauss-markov", "acoustics.clock_drift_ppm=50",
                "acoustics.sound_speed_profile=teos10", "simulation.receiver=lsq"]),
])
def test_engines_agree_on_other_settings(fmu_dir, name, overrides):
    cfg = load_config(name, overrides, seed=5)
    local = run(cfg, "local")
    fmu = run(cfg, "fmu", fmu_dir=fmu_dir)
    assert local.steps == fmu.steps == 100
    assert_same_frames(local.timeseries, fmu.timeseries)


def test_engines_agree_with_the_per_run_platform_errors(fmu_handles):
    """Installation error, IMU scale factor and misalignment on: both engines equal to 1e-9, and the errors
    do change the run (against the same run without them)."""
    errors = ["platform.installation_sigma=0.3", "platform.imu_scale_factor_ppm=5000",
              "platform.imu_misalignment_deg=2"]
    cfg = load_config("random", ["simulation.duration=20"] + errors, seed=9)
    local = run(cfg, "local", replicates=[0, 1, 2])
    fmu = run(cfg, "fmu", handles=fmu_handles, replicates=[0, 1, 2])
    assert_same_frames(local.timeseries, fmu.timeseries)
    assert_same_frames(local.metrics, fmu.metrics)
    without = run(load_config("random", ["simulation.duration=20"], seed=9), "local", replicates=[0, 1, 2])
    for name in ("beacon_x", "e_tot"):
        assert not np.allclose(local.timeseries[name], without.timeseries[name]), name


def test_fmu_handles_reset_between_runs(fmu_handles):
    first = load_config("semicircle", ["simulation.duration=15"], seed=1)
    other = load_config("semicircle", ["simulation.duration=15"], seed=2)
    a = run(first, "fmu", handles=fmu_handles)
    b = run(other, "fmu", handles=fmu_handles)
    c = run(first, "fmu", handles=fmu_handles)
    # the second seed gives different noise, so the comparison below can fail
    assert not np.allclose(a.timeseries["range"], b.timeseries["range"])
    assert_same_frames(a.timeseries, c.timeseries, atol=0.0)
    # and the reused handles reproduce a fresh local run
    assert_same_frames(run(first, "local").timeseries, c.timeseries)


_OWN_HANDLES_SCRIPT = """
import sys
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
cfg = load_config("semicircle", ["simulation.duration=%s"], seed=1)
for k in range(int(sys.argv[2])):
    run(cfg, "fmu", fmu_dir=sys.argv[1]).timeseries.to_parquet(f"{sys.argv[3]}/fmu{k}.parquet")
    print("run", k, "done", flush=True)
"""


def _own_handles_runs(fmu_dir, out, runs, duration):
    return subprocess.run([sys.executable, "-c", _OWN_HANDLES_SCRIPT % duration, str(fmu_dir), str(runs), str(out)],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_fmu_engine_own_handles_full_semicircle(fmu_dir, tmp_path):
    """``run(cfg, 'fmu', fmu_dir=...)`` (handles made and closed by run) equals the local engine."""
    proc = _own_handles_runs(fmu_dir, tmp_path, 1, 0)  # duration 0: one full pass
    assert proc.returncode == 0, proc.stderr[-2000:]
    local = run(load_config("semicircle", seed=1), "local").timeseries
    assert_same_frames(local, pd.read_parquet(tmp_path / "fmu0.parquet"))


@pytest.mark.slow
def test_fmu_engine_runs_twice_in_one_process(fmu_dir, tmp_path):
    """Two ``run(cfg, 'fmu', fmu_dir=...)`` calls in one process give the same result."""
    proc = _own_handles_runs(fmu_dir, tmp_path, 2, 2)
    assert proc.returncode == 0, (f"second fmu run in the same process died with status {proc.returncode}; "
                                  f"stdout {proc.stdout!r}; stderr tail {proc.stderr[-600:]!r}")
    assert_same_frames(pd.read_parquet(tmp_path / "fmu0.parquet"), pd.read_parquet(tmp_path / "fmu1.parquet"),
                       atol=0.0)


def test_missing_fmu_directory_raises(tmp_path):
    missing = tmp_path / "no_fmus_here"
    with pytest.raises(ModelError, match="sblsim fmus build"):
        make_handles("fmu", missing)
    cfg = load_config("semicircle", ["simulation.duration=1"], seed=1)
    with pytest.raises(ModelError, match="sblsim fmus build"):
        run(cfg, "fmu", fmu_dir=missing)


def test_missing_single_fmu_raises(fmu_dir, tmp_path):
    """A directory holding only some of the FMUs names the missing one."""
    import shutil

    partial = tmp_path / "partial"
    partial.mkdir()
    for name in ("platform", "acoustics", "target"):
        shutil.copy(fmu_path(fmu_dir, name), partial)
    with pytest.raises(ModelError, match=r"receiver FMU not found.*sblsim fmus build"):
        make_handles("fmu", partial)


def test_unknown_engine_raises():
    with pytest.raises(ModelError, match="engine"):
        make_handles("matlab")
