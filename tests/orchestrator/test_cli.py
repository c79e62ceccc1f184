"""The ``sblsim`` command line: one-line errors with nothing written, and a complete successful run."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models import MODELS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.io.manifest import MANIFEST
from tests.helpers import start_for_signals

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


@pytest.mark.slow
def test_run_writes_all_outputs(short_run):
    base, out, proc = short_run
    expected = {"summary.json", "config.toml", "timeseries.parquet", MANIFEST, *FIGURES}
    assert {p.name for p in out.iterdir()} == expected
    for name in FIGURES:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Traceback" not in proc.stderr
    assert str(out) in proc.stdout
    # no temporary directories left beside the output
    assert [p.name for p in base.iterdir() if p.name.startswith(".")] == []


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
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


# --------------------------------------------------------------------------- outputs

@pytest.mark.slow
def test_exported_log_and_truth_have_the_mode_of_the_run_s_files(tmp_path):
    """0666 less the umask, as every other file of the run (not mkstemp's 0600); under two umasks."""
    for umask in (0o022, 0o027):
        out = tmp_path / f"o{umask:o}"
        proc = subprocess.run([sys.executable, "-c", f"import os, sys; os.umask({umask}); "
                               "from sblsim.orchestrator.cli import main; sys.exit(main(sys.argv[1:]))",
                               "run", "semicircle", "--set", "simulation.duration=2", "--out", str(out),
                               "--export-log", str(out / "log" / "l.csv")], capture_output=True, text=True,
                              timeout=300)
        assert proc.returncode == 0, proc.stderr
        modes = {p.name: p.stat().st_mode & 0o777 for p in [*out.iterdir(), *(out / "log").iterdir()] if p.is_file()}
        assert modes["l.csv"] == modes["l_truth.csv"] == modes["summary.json"] == 0o666 & ~umask, modes


@pytest.mark.slow
def test_a_closed_pipe_does_not_fail_a_finished_run(tmp_path):
    """``sblsim run ... | head -1``: every result is written, no error about the pipe, exit status 0."""
    command = (f"{sys.executable} -m sblsim.orchestrator.cli run semicircle --set simulation.duration=3 --out o "
               "--export-log l.csv | head -c 0; echo \"status ${PIPESTATUS[0]}\" >&2")
    proc = subprocess.run(["bash", "-c", command], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.stderr.strip() == "status 0", proc.stderr
    assert (tmp_path / "o" / "summary.json").is_file() and (tmp_path / "l_truth.csv").is_file()
    proc = subprocess.run(["bash", "-c", command.replace("head -c 0", "head -1 >/dev/null").replace(
        "l.csv", "l.csv --force")], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.stderr.strip() == "status 0", proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("command", [["budget", "semicircle", "--replicates", "4000"],
                                     ["compare", "semicircle", "--replicates", "4000", "--receivers", "ekf,ukf"]],
                         ids=["budget", "compare"])
def test_a_second_command_into_the_same_folder_is_refused_while_the_first_runs(tmp_path, command):
    """A first command far too long to end on its own holds the folder's lock: a second into the same folder is
    refused in one line; the first, interrupted (Ctrl-C), exits 130, removes its lock and writes nothing; then a
    command into that folder runs."""
    first = start_for_signals([sys.executable, "-m", "sblsim.orchestrator.cli", *command, "--out", "c"],
                              cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lock = tmp_path / ".c.lock"
        for _ in range(600):
            if lock.exists() or first.poll() is not None:
                break
            time.sleep(0.1)
        assert lock.exists(), first.communicate()
        second = sblsim(*command, "--out", "c", cwd=tmp_path)
        assert first.poll() is None, "the first command ended before the second was refused: make it longer"
        assert_usage_error(second, "--out:", "is being written by another sblsim command")
        first.send_signal(signal.SIGINT)
    finally:
        out, err = first.communicate(timeout=900)
    assert first.returncode == 130, err[-2000:]
    assert not lock.exists() and not (tmp_path / "c").exists()
    third = sblsim(*command[:2], "--replicates", "2", "--out", "c", cwd=tmp_path)
    assert third.returncode == 0, third.stderr[-2000:]  # the lock went with the first


def test_a_latency_as_long_as_the_run_is_said_so(tmp_path, capsys):
    assert main(["run", "semicircle", "--set", "simulation.duration=5", "--set", "receiver.latency=5",
                 "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "receiver.latency = 5 s is as long as the run" in err and "though it used 49 ranges" in err, err
    assert "no multilateration fix was ever made" not in err
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["fix_steps"] == 0 and summary["updates"] == 49  # the 50th range is in flight at the end


@pytest.mark.slow  # 1 s once compiled; three LBL transponders a library of their own on a fresh machine
def test_set_applies_over_the_compared_systems_defaults(tmp_path, capsys):
    """docs/systems-compare.md: --set applies over each system's defaults (the LBL circle takes
    platform.beacons = 3), in compare --systems and in map --compare platform.system, though the scenario's cross
    would refuse it."""
    assert main(["compare", "semicircle", "--systems", "lbl", "--receivers", "ekf", "--replicates", "2",
                 "--set", "platform.beacons=3", "--set", "simulation.duration=3", "--out", str(tmp_path / "c")]) == 0
    assert main(["map", "semicircle", "--compare", "platform.system=lbl,usbl", "--set", "platform.beacons=3",
                 "--extent", "4", "--step", "1", "--out", str(tmp_path / "m")]) == 0
    capsys.readouterr()
    assert (tmp_path / "c" / "compare.csv").is_file() and (tmp_path / "m" / "map.csv").is_file()
    with pytest.raises(Exception, match="platform.beacons"):
        load_config("semicircle", ["platform.beacons=3"])  # what refused them before
    assert load_config("semicircle", ["platform.system=lbl", "platform.layout=circle", "platform.beacons=3"])[
        "platform"]["beacons"] == 3
