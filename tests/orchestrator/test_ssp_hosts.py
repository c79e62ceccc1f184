"""Integration: the exported SSP runs unchanged in libcosim, ecos and fmpy's SSP simulator.

Each host runs in its own process (``ssp_hosts.py``, which imports no sblsim
code). Its receiver estimate is compared with sblsim's own master in Jacobi
mode, which is how the hosts exchange values.

Tolerances, and why they are not zero:

* libcosim counts time in integer nanoseconds, ecos and fmpy accumulate
  ``t += h``, sblsim computes ``t0 + k h``; the trajectory is a function of
  t, so the communication points differ by round-off (1e-16 s relative) and
  the estimates by about 1e-13 m. We allow 1e-9 m. (The slot epochs do not
  depend on the host's time: the channel counts slots on its own clock.)
* fmpy's ``simulate_ssp`` starts every connector at 0.0 instead of
  exchanging the components' initial outputs, so the channel's first slot
  is computed from a beacon and a diver at the origin. Against a Jacobi run
  whose initial exchange gives zeros too, fmpy agrees to the same 1e-9 m;
  against the plain Jacobi run it differs by metres in the first seconds,
  and the gap decays as the filter forgets that slot (about 1e-7 m after
  30 s here, 5e-12 m at the end of the 94 s semicircle).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.connections import default_connections
from sblsim.orchestrator.cosim.local_engine import LocalHandle
from sblsim.orchestrator.cosim.master import simulate
from sblsim.orchestrator.cosim.run import merge_params, run
from sblsim.orchestrator.cosim.ssp import export_ssp

pytestmark = pytest.mark.slow

HOSTS = Path(__file__).with_name("ssp_hosts.py")
TOL = 1e-9  # [m]
OVERRIDES = ["simulation.duration=30", "acoustics.loss_pct=10", "acoustics.outlier_pct=5"]


@pytest.fixture(scope="module")
def package(fmu_dir, tmp_path_factory):
    cfg = load_config("semicircle", OVERRIDES, seed=12)  # slot 1 is received: fmpy's zero start shows
    return cfg, export_ssp(cfg, tmp_path_factory.mktemp("hosts") / "semicircle.ssp", fmu_dir)


def host_run(host: str, ssp: Path) -> dict[str, np.ndarray]:
    out = ssp.with_name(f"{host}.npz")
    scratch = ssp.with_name(f"{host}-tmp")  # the host's own temporary folders (ecos leaves its SSP's unpacked)
    scratch.mkdir(exist_ok=True)
    done = subprocess.run([sys.executable, str(HOSTS), host, str(ssp), str(out)], capture_output=True, text=True,
                          timeout=600, env={**os.environ, "TMPDIR": str(scratch)})
    assert done.returncode == 0, done.stderr[-2000:]
    return dict(np.load(out))


def estimate(frame) -> np.ndarray:
    return np.column_stack([frame[f"est_{a}"] for a in "xyz"])


def host_estimate(data) -> np.ndarray:
    return np.column_stack([data[f"est_{a}"] for a in "xyz"])


@pytest.fixture(scope="module")
def jacobi_fmu(package, fmu_dir):
    cfg, _ = package
    return run({**cfg, "simulation": {**cfg["simulation"], "master": "jacobi"}}, "fmu", fmu_dir=fmu_dir).timeseries


def test_libcosim_runs_the_package_like_the_jacobi_master(package, jacobi_fmu):
    cfg, ssp = package
    data = host_run("libcosim", ssp)
    assert len(data["time"]) == len(jacobi_fmu) == 300
    np.testing.assert_allclose(data["time"], jacobi_fmu["time"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.column_stack([data[f"pos_{a}"] for a in "xyz"]),
                               jacobi_fmu[["true_x", "true_y", "true_z"]].to_numpy(), rtol=0, atol=TOL)
    np.testing.assert_allclose(host_estimate(data), estimate(jacobi_fmu), rtol=0, atol=TOL)
    # and Gauss-Seidel is a different algorithm: the comparison can tell them apart
    gauss_seidel = run(cfg).timeseries
    # (over the steps where both have an estimate: neither has one before its first fix)
    assert np.nanmax(np.abs(host_estimate(data) - estimate(gauss_seidel))) > 1e-3


def test_ecos_runs_the_package_like_the_jacobi_master(package, jacobi_fmu):
    """ecos applies the one named parameter set to every component and steps at the base step."""
    cfg, ssp = package
    data = host_run("ecos", ssp)
    assert len(data["time"]) == len(jacobi_fmu) == 300
    np.testing.assert_allclose(np.column_stack([data[f"pos_{a}"] for a in "xyz"]),
                               jacobi_fmu[["true_x", "true_y", "true_z"]].to_numpy(), rtol=0, atol=TOL)
    np.testing.assert_allclose(host_estimate(data), estimate(jacobi_fmu), rtol=0, atol=TOL)


class ZeroStart:
    """A handle whose outputs read 0 until its first step: fmpy's connectors before the first exchange."""

    def __init__(self, handle):
        self.handle, self.started = handle, False

    def __getattr__(self, name):
        return getattr(self.handle, name)

    def do_step(self, t, h):
        self.started = True
        self.handle.do_step(t, h)

    def output_vector(self):
        outputs = self.handle.output_vector()
        return outputs if self.started else np.zeros_like(outputs)


def test_fmpy_runs_the_package_like_the_jacobi_master(package):
    cfg, ssp = package
    data = host_run("fmpy", ssp)
    sim = cfg["simulation"]
    handles = {}
    for name in ("platform", "acoustics", "target", "receiver"):
        handle = LocalHandle(name)
        params, reps = merge_params([cfg], name)
        handle.setup(params, reps)
        handles[name] = ZeroStart(handle)
    zero_start = simulate(handles, default_connections(), {}, sim["sampling_time"], 300, algorithm="jacobi")
    ours = np.column_stack([zero_start[f"receiver.est_{a}"][:, 0] for a in "xyz"])
    np.testing.assert_allclose(host_estimate(data), ours, rtol=0, atol=TOL)
    assert zero_start["acoustics.packet_valid"][0, 0] > 0.5  # slot 1, ranged from the origin, is used
    # against the plain Jacobi run (initial outputs exchanged): apart at first, then together
    plain = estimate(run({**cfg, "simulation": {**sim, "master": "jacobi"}}).timeseries)
    gap = np.linalg.norm(host_estimate(data) - plain, axis=1)  # NaN where either has no estimate yet
    assert np.nanmax(gap[:20]) > 1.0
    assert np.all(np.isfinite(gap[-50:]))
    assert gap[-50:].max() < 1e-5 * np.nanmax(gap[:20])  # the filter forgets the zero slot


def test_run_ssp_on_the_fmu_engine_equals_the_jacobi_master(package, jacobi_fmu, tmp_path):
    cfg, ssp = package
    done = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "run", "--ssp", str(ssp),
                           "--master", "jacobi", "--out", str(tmp_path / "r")], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "fmu engine (jacobi" in done.stdout
    import pandas as pd

    got = pd.read_parquet(tmp_path / "r" / "timeseries.parquet")
    np.testing.assert_array_equal(estimate(got), estimate(jacobi_fmu))
