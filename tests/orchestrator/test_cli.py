"""The ``sblsim`` command line: one-line errors with nothing written, and a complete successful run."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models import MODELS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.config import load_config

SUMMARY_METRICS = ("e_x_mean", "e_y_mean", "e_z_mean", "e_tot_mean", "e_tot_rms", "e_tot_std")
FIGURES = ("trajectory_xy.png", "trajectory_3d.png", "errors.png", "error_bounds.png")


def sblsim(*args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def assert_usage_error(proc: subprocess.CompletedProcess, *needles: str) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert proc.stderr.endswith("\n")
    line = lines[0]
    assert line.startswith("sblsim: error:"), line
    for needle in needles:
        assert needle in line, (needle, line)
    assert proc.stdout == ""
    return line


# --------------------------------------------------------------------------- errors
# (the bad-input corpus of every command is tests/test_bad_input.py)


def test_main_in_process_returns_2(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "semicircle", "--set", "platform.baseline=0", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [captured.err.strip()]
    assert captured.err.startswith("sblsim: error: platform.baseline:")
    assert not out.exists()


# --------------------------------------------------------------------------- a successful run

@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    base = tmp_path_factory.mktemp("cli_run")
    out = base / "run1"
    proc = sblsim("run", "semicircle", "--seed", "3", "--set", "simulation.duration=5", "--out", out, cwd=base)
    assert proc.returncode == 0, proc.stderr
    return base, out, proc


def test_run_writes_all_outputs(short_run):
    base, out, proc = short_run
    expected = {"summary.json", "config.toml", "timeseries.parquet", *FIGURES}
    assert {p.name for p in out.iterdir()} == expected
    for name in FIGURES:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Traceback" not in proc.stderr
    assert str(out) in proc.stdout
    # no temporary directories left beside the output
    assert [p.name for p in base.iterdir() if p.name.startswith(".")] == []


def test_summary_keys_and_values(short_run):
    _, out, _ = short_run
    s = json.loads((out / "summary.json").read_text())
    for key in (*SUMMARY_METRICS, *("instr_" + k for k in SUMMARY_METRICS), "engine", "seed", "steps"):
        assert key in s, key
    assert s["engine"] == "local"
    assert s["seed"] == 3
    assert s["steps"] == 50  # 5 s at T = 0.1 s


def test_summary_matches_timeseries(short_run):
    """Metrics recomputed from the true and estimated positions in timeseries.parquet."""
    _, out, _ = short_run
    s = json.loads((out / "summary.json").read_text())
    ts = pd.read_parquet(out / "timeseries.parquet")
    assert len(ts) == s["steps"]
    truth = ts[["true_x", "true_y", "true_z"]].to_numpy()
    for prefix, cols in (("", ["est_x", "est_y", "est_z"]), ("instr_", ["instr_x", "instr_y", "instr_z"])):
        est = ts[cols].to_numpy()
        # the instrumentation counts only the steps with a fix (instr_valid); its instr_* are 0 otherwise
        ok = ts["instr_valid"].to_numpy() if prefix else np.all(np.isfinite(est), axis=1)
        assert ok.sum() > 10
        d = np.abs(truth[ok] - est[ok])
        tot = np.sqrt((d ** 2).sum(axis=1))
        expect = {"e_x_mean": d[:, 0].mean(), "e_y_mean": d[:, 1].mean(), "e_z_mean": d[:, 2].mean(),
                  "e_tot_mean": tot.mean(), "e_tot_rms": np.sqrt(np.mean(tot ** 2)), "e_tot_std": tot.std()}
        for key, value in expect.items():
            assert s[prefix + key] == pytest.approx(value, rel=1e-9, abs=1e-12), prefix + key


def test_config_toml_is_the_resolved_configuration(short_run):
    _, out, _ = short_run
    written = tomllib.loads((out / "config.toml").read_text())
    assert written == load_config("semicircle", ["simulation.duration=5"], seed=3)


def test_rerun_from_config_reproduces_timeseries(short_run):
    base, out, _ = short_run
    out2 = base / "run2"
    proc = sblsim("run", out / "config.toml", "--out", out2, cwd=base)
    assert proc.returncode == 0, proc.stderr
    first = pd.read_parquet(out / "timeseries.parquet")
    again = pd.read_parquet(out2 / "timeseries.parquet")
    pd.testing.assert_frame_equal(first, again, check_exact=True)
    s1 = json.loads((out / "summary.json").read_text())
    s2 = json.loads((out2 / "summary.json").read_text())
    assert {k: v for k, v in s1.items() if k != "wall_time"} == {k: v for k, v in s2.items() if k != "wall_time"}


def test_fmu_engine_run_matches_local(short_run, fmu_dir):
    base, out, _ = short_run
    out3 = base / "run_fmu"
    proc = sblsim("run", "semicircle", "--seed", "3", "--set", "simulation.duration=5", "--engine", "fmu",
                  "--fmu-dir", fmu_dir, "--out", out3, cwd=base)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((out3 / "summary.json").read_text())["engine"] == "fmu"
    local = pd.read_parquet(out / "timeseries.parquet")
    fmu = pd.read_parquet(out3 / "timeseries.parquet")
    pd.testing.assert_frame_equal(local, fmu, check_exact=False, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- fmus validate

def test_fmus_validate(fmu_dir, tmp_path):
    proc = sblsim("fmus", "validate", fmu_dir, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("0 problems") == len(MODELS)
    lines = [line for line in proc.stdout.splitlines() if line.endswith("problems")]
    assert sorted(Path(line.split(":")[0]).name for line in lines) == sorted(
        f"sblsim_{n}.fmu" for n in MODELS)


def test_fmus_validate_missing_dir(tmp_path):
    proc = sblsim("fmus", "validate", tmp_path / "nothing", cwd=tmp_path)
    assert_usage_error(proc, "FMU not found", "sblsim fmus build")
