"""The receiver on its own, fed a recorded run: by fmpy.simulate_fmu, and as embeddable C.

A run of the whole system (semicircle, 25 % packet loss, 5 % multipath)
records every input the receiver was given and its estimate. Two other
hosts replay those inputs and must give the same estimate to 1e-9 m:

* fmpy's ``simulate_fmu`` with the inputs as a signal table. Time alignment
  (docs/interop.md): the master gives the receiver, for its step from
  t_(k-1) to t_k, the packet the channel produced at the end of that macro
  step (recorded with time t_k); fmpy applies the signal value at the
  current communication point before ``doStep``, so the recorded row of
  time t_k is stamped t_(k-1).
* the ``sblsim codegen receiver`` example program, compiled by the test.
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from sblsim.fmus.build import fmu_path
from sblsim.fmus.compiler import find_compiler
from sblsim.fmus.embedded import write_receiver
from sblsim.models import MODELS, RECEIVERS
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run

INPUTS = [v.name for v in MODELS["receiver"].inputs()]
#: The later lanes of a delivery: empty in these runs (a lane a run never used is not in its time series).
EMPTY = 0.0
TOL = 1e-9  # [m]


@pytest.fixture(scope="module", params=list(RECEIVERS))
def recorded(request):
    cfg = load_config("semicircle", ["simulation.duration=40", "acoustics.loss_pct=25", "acoustics.outlier_pct=5",
                                     f"receiver={request.param}"], seed=9)
    result = run(cfg)
    series = result.timeseries
    assert not series["packet_valid"].all() and series["outlier"].any()  # lost packets and outliers are in it
    return request.param, cfg, series


def receiver_parameters(cfg, receiver):
    model = MODELS[RECEIVERS[receiver]]
    names = {v.name for v in model.fmu_parameters_declared()}
    return model, {k: v for k, v in cfg["receiver"].items() if k in names}


def test_fmpy_simulate_fmu_fed_a_recorded_run_reproduces_its_estimate(recorded, fmu_dir):
    from fmpy import simulate_fmu

    receiver, cfg, series = recorded
    model, params = receiver_parameters(cfg, receiver)
    T = cfg["simulation"]["sampling_time"]
    n = len(series)
    types = {"packet_seq": np.int32, "beacon_id": np.int32, "packet_valid": np.bool_}
    signals = np.zeros(n, dtype=[("time", np.float64)] + [(name, types.get(name, np.float64)) for name in INPUTS])
    signals["time"] = T * np.arange(n)  # row k (recorded at t_(k+1)) drives the step from t_k
    for name in INPUTS:
        signals[name] = series[name].to_numpy() if name in series else EMPTY
    result = simulate_fmu(str(fmu_path(fmu_dir, model.name)), start_values=params, input=signals,
                          stop_time=n * T, output_interval=T, output=["est_x", "est_y", "est_z"])
    assert len(result) == n + 1
    for a in "xyz":
        np.testing.assert_allclose(result[f"est_{a}"][1:], series[f"est_{a}"].to_numpy(), rtol=0, atol=TOL)


@pytest.mark.slow
def test_codegen_receiver_example_reproduces_the_recorded_estimate(recorded, tmp_path):
    receiver, cfg, series = recorded
    _, params = receiver_parameters(cfg, receiver)
    out = tmp_path / "receiver_c"
    files = write_receiver(receiver, out)
    assert {p.name for p in files} >= {"main.c", "README.md", "sblsim_embedded.h", "sblsim_runtime.c"}
    assert not any("fmi2" in p.read_text() for p in files if p.suffix in (".c", ".h"))  # no FMI in it
    main_lines = [line for line in (out / "main.c").read_text().splitlines()
                  if line.strip() and not line.lstrip().startswith(("/*", "*", "#include"))]
    assert len(main_lines) <= 25
    exe = out / "receiver"
    cc = find_compiler("system")
    subprocess.run([*cc.command, "-O2", "-std=c99", "-ffp-contract=off", "-Wall", "-Werror",
                    *map(str, sorted(out.glob("*.c"))), "-lm", "-o", str(exe)], check=True, capture_output=True)
    T = cfg["simulation"]["sampling_time"]
    lines = []
    for k, row in enumerate(series.itertuples(index=False)):
        values = [float(getattr(row, name, EMPTY)) for name in INPUTS]
        lines.append(" ".join(repr(x) for x in [k * T, T, *values]))
    args = [f"{k}={v!r}" for k, v in params.items()]
    done = subprocess.run([str(exe), *args], input="\n".join(lines) + "\n", capture_output=True, text=True,
                          env={}, timeout=120)
    assert done.returncode == 0, done.stderr
    printed = np.array([[float(x) for x in line.split()] for line in done.stdout.splitlines()])
    assert printed.shape == (len(series), 4)
    np.testing.assert_allclose(printed[:, 0], series["time"].to_numpy(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(printed[:, 1:], series[["est_x", "est_y", "est_z"]].to_numpy(), rtol=0, atol=TOL)


def test_the_example_files_are_the_recorded_run_as_text():
    """orchestrator/cosim/codegen.py's example (no C compiled): the run's own estimates, one row per step at its
    times, the packets one row per step with the receiver's inputs, every [receiver] parameter but the seeds, as a
    fresh run of the same scenario gives them (sblsim.run, the command line's)."""
    import sblsim
    from sblsim.orchestrator.cosim.codegen import EXAMPLE, example_files

    files, about, n_beacons = example_files("ekf")
    scenario, overrides, seed = EXAMPLE
    series = sblsim.run(scenario, seed=seed, set=[*overrides, "receiver=ekf"]).timeseries
    expected = np.array([[float(x) for x in line.split()] for line in files["expected.txt"].splitlines()])
    np.testing.assert_array_equal(expected, series[["time", "est_x", "est_y", "est_z"]].to_numpy())
    packets = files["packets.txt"].splitlines()
    model = MODELS[RECEIVERS["ekf"]]
    assert len(packets) == len(series) and all(len(p.split()) == 2 + len(model.inputs(n_beacons)) for p in packets)
    parameters = dict(item.split("=", 1) for item in files["parameters.txt"].split())
    assert "seed" not in parameters and "x0_vx" in parameters and n_beacons == 4
    assert "sblsim run semicircle --seed 1" in about


def test_codegen_refuses_a_bad_receiver_and_a_used_directory(tmp_path):
    from sblsim.models.declarations import ModelError

    with pytest.raises(ModelError, match="--receiver: 'kalman' is not one of ekf, ekf-seq, ukf, lsq"):
        write_receiver("kalman", tmp_path / "a")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "keep.txt").write_text("mine")
    with pytest.raises(ModelError, match="not an empty directory"):
        write_receiver("ekf", tmp_path / "b")
    assert (tmp_path / "b" / "keep.txt").read_text() == "mine" and len(list((tmp_path / "b").iterdir())) == 1


@pytest.mark.slow
def test_codegen_readme_run_line_reproduces_its_example(tmp_path):
    """The generated folder's own example, as its README runs it: ./receiver $(cat parameters.txt) < packets.txt
    gives the recorded run's estimates (expected.txt)."""
    from sblsim.orchestrator.cli import main

    out = tmp_path / "receiver_c"
    assert main(["codegen", "receiver", "--receiver", "ukf", "--out", str(out)]) == 0
    readme = (out / "README.md").read_text()
    build = next(line.strip() for line in readme.splitlines() if line.strip().startswith("cc "))
    run_line = next(line.strip() for line in readme.splitlines() if line.strip().startswith("./receiver"))
    cc = " ".join(find_compiler("system").command)
    done = subprocess.run(f"{cc} {build[3:]} && {run_line}", shell=True, cwd=out, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    estimates, expected = np.loadtxt(out / "estimates.txt"), np.loadtxt(out / "expected.txt")
    assert estimates.shape == expected.shape and len(expected) == 200
    np.testing.assert_allclose(estimates, expected, rtol=0, atol=TOL)
    assert "x0_vx=" in (out / "parameters.txt").read_text()  # every parameter of the run, the velocity too
