"""Campaigns: results independent of execution, resume after a kill or Ctrl-C, designs, engines, errors.

The studies are small (two scenarios, three factors, a few replicates, 10 s
runs) so that every campaign takes a second or two.
"""

from __future__ import annotations

import itertools
import json
import math
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import tomli_w

from sblsim.orchestrator.campaign import plan, run_campaign
from sblsim.orchestrator.campaign.factorial import design_matrix, full_factorial
from sblsim.orchestrator.campaign.study import load_study
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.metrics import FLAG_NAMES, RUN_METRICS
from sblsim.orchestrator.cosim.run import run
from tests.helpers import signal_and_wait, start_for_signals

ROOT = Path(__file__).resolve().parents[2]
REPLICATES = 3
#: Two scenarios; factors on the platform, the acoustics (tied to the receiver's R) and the
#: sampling time (a setting a batch cannot vary, so the cells split into two batch groups).
STUDY = {
    "study": {"name": "tiny", "scenarios": ["semicircle", "spiral"], "replicates": REPLICATES, "seed": 11,
              "set": ["simulation.duration=10", "acoustics.loss_pct=10"]},
    "factors": [
        {"name": "baseline", "key": "platform.baseline", "low": 0.4, "high": 3.0},
        {"name": "range", "key": "acoustics.sigma_range", "low": 0.1, "high": 1.0},
        {"name": "T", "key": "simulation.sampling_time", "low": 0.1, "high": 0.5},
    ],
}


def study_table(**changes) -> dict:
    table = {"study": {**STUDY["study"]}, "factors": [dict(f) for f in STUDY["factors"]]}
    table["study"].update(changes)
    return table


def write_study(path: Path, table: dict) -> Path:
    path.write_text(tomli_w.dumps(table))
    return path


def sblsim(*args, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout, check=False)


def start_sblsim(*args, cwd: Path) -> subprocess.Popen:
    """A campaign in the background, to be signalled (SIGINT and SIGTERM at their defaults in it)."""
    return start_for_signals([sys.executable, "-m", "sblsim.orchestrator.cli", *map(str, args)], cwd=cwd,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def assert_usage_error(proc: subprocess.CompletedProcess, *needles: str) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    line = lines[0]
    assert line.startswith("sblsim: error:"), line
    for needle in needles:
        assert needle in line, (needle, line)
    return line


def read_runs(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "runs.parquet")


def assert_same_runs(got: pd.DataFrame, want: pd.DataFrame) -> None:
    pd.testing.assert_frame_equal(got, want, check_exact=True)


def chunk_files(out: Path) -> list[Path]:
    return sorted((out / "chunks").glob("*.parquet"))


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tiny study run in this process, one worker, default batch (a chunk spans every cell it can)."""
    out = tmp_path_factory.mktemp("reference") / "campaign"
    study = load_study(study_table())
    result = run_campaign(study, out, workers=1, progress=False)
    return study, result


# --------------------------------------------------------------------------- same results however run

def test_reference_campaign_layout(reference):
    study, result = reference
    runs = result.runs
    assert study.cells == 8 and study.runs == 2 * 8 * REPLICATES
    assert result.computed == study.runs and len(runs) == study.runs
    assert_same_runs(read_runs(result.out), runs)
    # sorted by scenario_key, cell, replicate; every run once
    keys = list(zip(runs["scenario_key"], runs["cell"], runs["replicate"]))
    assert keys == sorted(keys) == [(s, c, r) for s in (1, 2) for c in range(8) for r in range(REPLICATES)]
    # factor levels of each row follow pyDOE3's ff2n (first factor slowest)
    for k, factor in enumerate(study.factors):
        coded = 2 * ((runs["cell"].to_numpy() >> (2 - k)) & 1) - 1
        np.testing.assert_array_equal(runs[factor.name].to_numpy(), coded)
        np.testing.assert_array_equal(runs[f"{factor.name}_value"].to_numpy(),
                                      np.where(coded < 0, factor.low, factor.high))
    assert np.all(np.isfinite(runs["e_tot_rms"])) and runs["e_tot_rms"].nunique() == len(runs)
    # default batch: the sampling time splits each scenario's cells into two chunks
    assert len(chunk_files(result.out)) == 4
    assert (result.out / "study.toml").is_file()


@pytest.mark.slow
def test_same_runs_with_two_worker_processes(reference, tmp_path):
    study, ref = reference
    result = run_campaign(study, tmp_path / "w2", workers=2, progress=False)
    assert result.computed == study.runs
    assert_same_runs(read_runs(tmp_path / "w2"), ref.runs)


def test_same_runs_with_one_cell_per_chunk(reference, tmp_path):
    study, ref = reference
    out = tmp_path / "b"
    result = run_campaign(study, out, workers=1, batch=REPLICATES, progress=False)
    assert len(chunk_files(out)) == 2 * study.cells == len(plan(study, REPLICATES))
    assert result.computed == study.runs
    assert_same_runs(read_runs(out), ref.runs)


@pytest.mark.slow
def test_same_runs_on_a_dask_cluster(reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    study, ref = reference
    out = tmp_path / "dask"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        result = run_campaign(study, out, scheduler=cluster.scheduler_address, batch=2 * REPLICATES,
                              progress=False)
    assert len(chunk_files(out)) == study.cells  # two cells per chunk
    assert result.computed == study.runs
    assert_same_runs(read_runs(out), ref.runs)


# --------------------------------------------------------------------------- resume

#: One scenario, 8 cells of 4 replicates, 30 s runs, one cell per chunk: 8 chunks of some 0.3 s each.
KILL_TABLE = {
    "study": {"name": "killme", "scenarios": ["semicircle"], "replicates": 4, "seed": 5,
              "set": ["simulation.duration=30"]},
    "factors": [
        {"name": "baseline", "key": "platform.baseline", "low": 0.4, "high": 3.0},
        {"name": "range", "key": "acoustics.sigma_range", "low": 0.1, "high": 1.0},
        {"name": "gps", "key": "platform.gps_sigma", "low": 0.1, "high": 3.5},
    ],
}
KILL_BATCH = 4
KILL_CHUNKS = 8


@pytest.fixture(scope="module")
def kill_reference(tmp_path_factory):
    """The uninterrupted campaign (in this process, all cells in one batch)."""
    out = tmp_path_factory.mktemp("kill_reference") / "campaign"
    study = load_study(KILL_TABLE)
    assert len(plan(study, KILL_BATCH)) == KILL_CHUNKS
    return run_campaign(study, out, workers=1, progress=False).runs


def _start_and_stop_part_way(tmp_path: Path, sig: int) -> tuple[subprocess.Popen, Path, str, str]:
    study_file = write_study(tmp_path / "killme.toml", KILL_TABLE)
    out = tmp_path / "out"
    proc = start_sblsim("campaign", study_file, "--workers", "1", "--batch", KILL_BATCH, "--out", out,
                        cwd=tmp_path)
    deadline = time.monotonic() + 120
    try:
        while not ((out / "chunks").is_dir() and chunk_files(out)):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk written in 120 s"
            time.sleep(0.005)
        assert not (out / "runs.parquet").exists()
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc, out, stdout, stderr


def _resume(tmp_path: Path, out: Path, saved_chunks: int) -> None:
    proc = sblsim("campaign", tmp_path / "killme.toml", "--workers", "1", "--out", out, "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    # only the missing chunks were computed
    computed = (KILL_CHUNKS - saved_chunks) * KILL_BATCH
    assert proc.stdout.splitlines()[-1].startswith(f"{computed} runs in "), proc.stdout
    assert len(chunk_files(out)) == KILL_CHUNKS
    assert not list((out / "chunks").glob(".*.tmp"))


@pytest.mark.slow
def test_resume_after_kill_gives_the_uninterrupted_result(kill_reference, tmp_path):
    proc, out, _, _ = _start_and_stop_part_way(tmp_path, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    saved = len(chunk_files(out))
    assert 1 <= saved < KILL_CHUNKS, saved  # really interrupted part-way
    assert not (out / "runs.parquet").exists()
    # a temporary file a killed writer would leave behind is cleaned up
    (out / "chunks" / ".001-00007-00007.parquet.dead.tmp").write_bytes(b"half a parquet file")
    _resume(tmp_path, out, saved)
    assert_same_runs(read_runs(out), kill_reference)


@pytest.mark.slow
def test_ctrl_c_exits_130_and_resume_gives_the_uninterrupted_result(kill_reference, tmp_path):
    proc, out, _, stderr = _start_and_stop_part_way(tmp_path, signal.SIGINT)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    last = stderr.splitlines()[-1]
    assert "interrupted" in last and "--resume" in last, stderr
    saved = len(chunk_files(out))
    assert 1 <= saved < KILL_CHUNKS, saved
    assert f"{saved * KILL_BATCH} of {KILL_CHUNKS * KILL_BATCH} runs" in last, last
    assert not (out / "runs.parquet").exists()
    _resume(tmp_path, out, saved)
    assert_same_runs(read_runs(out), kill_reference)


def test_an_interruption_says_what_is_kept_and_how_to_finish(tmp_path):
    """The interruption the runner raises (its processes' signals are the slow tests above and below): the runs
    saved of all, the folder, and ``--resume``; not an error of the error kinds (finished work is kept)."""
    from sblsim.models.errors import SblsimError
    from sblsim.orchestrator.campaign.errors import CampaignInterrupted

    stop = CampaignInterrupted(12, 40, tmp_path)
    assert str(stop) == f"interrupted: 12 of 40 runs saved in {tmp_path}; finish with --resume"
    assert (stop.done, stop.total, stop.out) == (12, 40, tmp_path) and not isinstance(stop, SblsimError)


@pytest.mark.slow
def test_sigterm_keeps_the_work_and_says_how_to_finish(kill_reference, tmp_path):
    proc, out, _, stderr = _start_and_stop_part_way(tmp_path, signal.SIGTERM)
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert "Traceback" not in stderr
    last = stderr.splitlines()[-1]
    saved = len(chunk_files(out))
    assert f"{saved * KILL_BATCH} of {KILL_CHUNKS * KILL_BATCH} runs" in last and "--resume" in last, stderr
    _resume(tmp_path, out, saved)
    assert_same_runs(read_runs(out), kill_reference)


def _finished(tmp_path: Path) -> tuple[Path, Path]:
    study_file = write_study(tmp_path / "killme.toml", KILL_TABLE)
    out = tmp_path / "out"
    proc = sblsim("campaign", study_file, "--workers", "1", "--batch", KILL_BATCH, "--out", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    return study_file, out


@pytest.mark.slow
def test_resume_recomputes_damaged_foreign_and_missing_chunks(kill_reference, tmp_path):
    study_file, out = _finished(tmp_path)
    files = chunk_files(out)
    assert len(files) == KILL_CHUNKS and (out / "manifest.json").is_file()
    (out / "runs.parquet").unlink()
    files[0].write_bytes(files[0].read_bytes()[: files[0].stat().st_size // 2])  # cut in half
    files[1].write_bytes(b"")  # zeroed
    a, b = files[2].read_bytes(), files[3].read_bytes()  # two chunks swapped
    files[2].write_bytes(b)
    files[3].write_bytes(a)
    files[4].unlink()  # missing
    proc = sblsim("campaign", study_file, "--workers", "1", "--out", out, "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    recomputed = [line for line in proc.stderr.splitlines() if "is recomputed" in line]
    assert sorted(line.split()[2] for line in recomputed) == sorted(f.stem for f in files[:4]), proc.stderr
    assert proc.stdout.splitlines()[-1].startswith(f"{5 * KILL_BATCH} runs in "), proc.stdout
    assert_same_runs(read_runs(out), kill_reference)


@pytest.mark.slow
def test_resume_without_a_manifest_checks_the_chunks_by_content(kill_reference, tmp_path):
    study_file, out = _finished(tmp_path)
    files = chunk_files(out)
    (out / "manifest.json").write_text("{ not json")
    proc = sblsim("campaign", study_file, "--workers", "1", "--out", out, "--resume", cwd=tmp_path)
    assert_usage_error(proc, "manifest.json", "is damaged", "delete it")
    (out / "manifest.json").unlink()
    a, b = files[2].read_bytes(), files[3].read_bytes()  # swapped: other cells than the plan's
    files[2].write_bytes(b)
    files[3].write_bytes(a)
    proc = sblsim("campaign", study_file, "--workers", "1", "--out", out, "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("holds other runs than the plan's") == 2, proc.stderr
    assert_same_runs(read_runs(out), kill_reference)
    assert set(json.loads((out / "manifest.json").read_text())) == {f.stem for f in files} | {"_plan"}


@pytest.mark.slow
def test_a_damaged_study_file_stops_resume_with_one_line_and_deleting_it_recovers(kill_reference, tmp_path):
    study_file, out = _finished(tmp_path)
    (out / "study.toml").write_text("[study\nname = ")
    (out / "runs.parquet").unlink()
    chunk_files(out)[5].write_bytes(b"")
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    proc = sblsim("campaign", study_file, "--workers", "1", "--out", out, "--resume", cwd=tmp_path)
    assert_usage_error(proc, "study.toml", "is damaged", "delete it and resume again")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    (out / "study.toml").unlink()  # as the message says
    proc = sblsim("campaign", study_file, "--workers", "1", "--out", out, "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "written again" in proc.stderr and proc.stderr.count("is recomputed") == 1, proc.stderr
    assert proc.stdout.splitlines()[-1].startswith(f"{KILL_BATCH} runs in "), proc.stdout  # the same plan
    assert_same_runs(read_runs(out), kill_reference)


@pytest.mark.slow
def test_a_chunk_of_another_study_with_the_same_cells_is_recomputed(kill_reference, tmp_path):
    study_file, out = _finished(tmp_path)
    other = {**KILL_TABLE, "study": {**KILL_TABLE["study"], "seed": 6}}  # same plan, other seed
    other_file, other_out = write_study(tmp_path / "other.toml", other), tmp_path / "other"
    proc = sblsim("campaign", other_file, "--workers", "1", "--batch", KILL_BATCH, "--out", other_out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    (out / "manifest.json").unlink()  # no checksum to catch it: the content must
    (out / "runs.parquet").unlink()
    chunk_files(out)[1].write_bytes(chunk_files(other_out)[1].read_bytes())
    proc = sblsim("campaign", study_file, "--workers", "1", "--out", out, "--resume", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "belong to another study" in proc.stderr, proc.stderr
    assert_same_runs(read_runs(out), kill_reference)


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="needs /proc to find the worker processes")
def test_workers_do_not_outlive_a_killed_campaign(tmp_path):
    table = {**KILL_TABLE, "study": {**KILL_TABLE["study"], "replicates": 40, "set": ["simulation.duration=200"]}}
    study_file = write_study(tmp_path / "long.toml", table)
    proc = start_sblsim("campaign", study_file, "--workers", "2", "--batch", 40, "--out", tmp_path / "out",
                        cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        workers: list[int] = []
        while len(workers) < 2:  # the pool's processes (and its resource tracker)
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no worker started in 120 s"
            time.sleep(0.2)
            workers = [p for p in _children(proc.pid) if "multiprocessing" in Path(f"/proc/{p}/cmdline").read_text()]
        time.sleep(1.0)  # the workers are busy with their chunks
        proc.kill()
        proc.wait()
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in workers) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not [p for p in workers if _alive(p)], "workers outlived the killed campaign by 10 s"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_resume_of_a_finished_campaign_does_nothing(tmp_path):
    study = load_study(study_table(scenarios=["semicircle"]))
    out = tmp_path / "done"
    first = run_campaign(study, out, workers=1, batch=2 * REPLICATES, progress=False)
    files = [out / "runs.parquet", out / "study.toml", *chunk_files(out)]
    stamps = {p: p.stat().st_mtime_ns for p in files}
    listing = sorted(p.relative_to(out) for p in out.rglob("*"))
    time.sleep(0.05)  # a rewrite would get a later time stamp

    again = run_campaign(study, out, workers=1, resume=True, progress=False)
    assert again.computed == 0
    assert_same_runs(again.runs, first.runs)
    proc = sblsim("campaign", write_study(tmp_path / "done.toml", study_table(scenarios=["semicircle"])),
                  "--out", out, "--resume", "--workers", "1", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1].startswith("nothing to do"), proc.stdout
    assert {p: p.stat().st_mtime_ns for p in files} == stamps
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == listing

    # without --resume: a one-line error, nothing written
    proc = sblsim("campaign", tmp_path / "done.toml", "--out", out, "--workers", "1", cwd=tmp_path)
    assert_usage_error(proc, "--resume")
    assert {p: p.stat().st_mtime_ns for p in files} == stamps
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == listing


# --------------------------------------------------------------------------- fractional designs

def _products(columns: np.ndarray, exclude: int) -> list[np.ndarray]:
    """Products of two distinct columns other than ``exclude``."""
    others = [j for j in range(columns.shape[1]) if j != exclude]
    return [columns[:, a] * columns[:, b] for a, b in itertools.combinations(others, 2)]


def main_effects_clear_of_each_other(m: np.ndarray) -> bool:
    return not any(np.array_equal(m[:, i], s * m[:, j])
                   for i, j in itertools.combinations(range(m.shape[1]), 2) for s in (1, -1))


def main_effects_clear_of_two_factor_interactions(m: np.ndarray) -> bool:
    return not any(np.array_equal(m[:, i], s * p)
                   for i in range(m.shape[1]) for p in _products(m, i) for s in (1, -1))


def _check_two_level_balanced(m: np.ndarray, k: int) -> None:
    assert m.ndim == 2 and m.shape[1] == k
    assert set(np.unique(m)) == {-1, 1}
    assert np.all(m.sum(axis=0) == 0)
    assert len({tuple(r) for r in m}) == m.shape[0]  # no repeated run


def test_fractional_design_resolution_four():
    m = design_matrix(7, "fractional", resolution=4)
    _check_two_level_balanced(m, 7)
    assert m.shape[0] == 16  # 2^(7-3): the smallest resolution IV design of 7 factors
    assert main_effects_clear_of_each_other(m)
    assert main_effects_clear_of_two_factor_interactions(m)
    # orthogonal main effects
    np.testing.assert_array_equal(m.T @ m, m.shape[0] * np.eye(7, dtype=int))


def test_fractional_design_resolution_three_aliases_main_effects_with_interactions():
    m = design_matrix(7, "fractional", resolution=3)
    _check_two_level_balanced(m, 7)
    # pyDOE3's fracfact_by_res(7, 3) builds 7 factors on 4 base factors (16 runs), not the
    # saturated 2^(7-4) of 8 runs; either way it is resolution III
    assert m.shape[0] in (8, 16)
    assert main_effects_clear_of_each_other(m)
    assert not main_effects_clear_of_two_factor_interactions(m)  # the check can fail


def test_saturated_resolution_three_design_from_generators():
    m = design_matrix(7, "fractional", generators="a b c ab ac bc abc")
    _check_two_level_balanced(m, 7)
    assert m.shape[0] == 8
    assert main_effects_clear_of_each_other(m)
    assert not main_effects_clear_of_two_factor_interactions(m)
    # in the saturated 2^(7-4) every main effect is aliased with three 2FIs
    for i in range(7):
        aliases = sum(np.array_equal(m[:, i], s * p) for p in _products(m, i) for s in (1, -1))
        assert aliases == 3, (i, aliases)


def test_the_full_factorial_is_pydoe3s():
    """The full factorial is written in sblsim (pyDOE3's import costs every campaign half a second): the same
    rows as pyDOE3's ff2n, for 1 to 16 factors (65,536 cells)."""
    import pyDOE3

    for k in range(1, 17):
        np.testing.assert_array_equal(full_factorial(k), pyDOE3.ff2n(k))
        assert full_factorial(k).dtype == np.int64
    assert "pyDOE3" not in subprocess.run(
        [sys.executable, "-c", "import sys; from sblsim.orchestrator.campaign.factorial import design_matrix; "
                               "design_matrix(7); print(sorted(m for m in sys.modules if m.startswith('pyDOE3')))"],
        capture_output=True, text=True, check=True).stdout


def test_full_design_and_explicit_generators():
    full = design_matrix(3, "full")
    np.testing.assert_array_equal(full, [[s0, s1, s2] for s0 in (-1, 1) for s1 in (-1, 1) for s2 in (-1, 1)])
    m = design_matrix(4, "fractional", generators="a b c abc")
    _check_two_level_balanced(m, 4)
    np.testing.assert_array_equal(m[:, 3], m[:, 0] * m[:, 1] * m[:, 2])


# --------------------------------------------------------------------------- engines, run(), time series

def test_engines_agree(fmu_dir, tmp_path):
    """The same runs.parquet on both engines, to the bit: they run the same generated C."""
    table = {"study": {"name": "engines", "scenarios": ["semicircle", "harbour"], "replicates": 2, "seed": 3,
                       "set": ["simulation.duration=5", "acoustics.loss_pct=20", "acoustics.outlier_pct=5"]},
             "factors": [{"name": "range", "key": "acoustics.sigma_range", "low": 0.1, "high": 1.0}]}
    study = load_study(table)
    local = run_campaign(study, tmp_path / "local", workers=1, progress=False).runs
    fmu = run_campaign(study, tmp_path / "fmu", workers=1, engine="fmu", fmu_dir=fmu_dir, progress=False).runs
    assert len(local) == len(fmu) == 8
    pd.testing.assert_frame_equal(fmu, local, check_exact=True)
    runs = {engine: pd.read_parquet(tmp_path / engine / "runs.parquet") for engine in ("fmu", "local")}
    assert runs["fmu"].equals(runs["local"])
    assert np.all(np.isfinite(local["e_tot_rms"]))


def test_campaign_row_equals_a_single_run(reference):
    _, result = reference
    runs = result.runs
    rng = np.random.default_rng(0)
    picks = [0, len(runs) - 1, *rng.choice(len(runs), size=4, replace=False)]
    for k in picks:
        row = runs.iloc[k]
        overrides = list(STUDY["study"]["set"])
        overrides += [f"{f['key']}={float(row[f['name'] + '_value'])!r}" for f in STUDY["factors"]]
        overrides += [f"run.cell={int(row['cell'])}", f"run.replicate={int(row['replicate'])}"]
        cfg = load_config(row["scenario"], overrides, seed=int(row["seed"]))
        assert cfg["run"]["scenario_key"] == row["scenario_key"]
        single = run(cfg, "local").metrics.iloc[0]
        assert single["replicate"] == row["replicate"]
        for name in RUN_METRICS + FLAG_NAMES:  # the metrics and the flags a run says when its numbers mislead
            assert single[name] == row[name] or (math.isnan(single[name]) and math.isnan(row[name])), \
                (k, name, single[name], row[name])


def test_save_timeseries(reference, tmp_path):
    study, ref = reference
    out = tmp_path / "series"
    result = run_campaign(study, out, workers=1, batch=2 * REPLICATES, save_timeseries=True, progress=False)
    assert_same_runs(result.runs, ref.runs)  # saving the series does not change the results
    series_files = sorted((out / "timeseries").glob("*.parquet"))
    assert [p.name for p in series_files] == [p.name for p in chunk_files(out)]
    series = pd.concat([pd.read_parquet(p) for p in series_files], ignore_index=True)
    runs = result.runs.set_index(["scenario_key", "cell", "replicate"])
    groups = series.groupby(["scenario_key", "cell", "replicate"], sort=True)
    assert len(groups) == len(runs)
    for key, g in groups:
        row = runs.loc[key]
        steps = round(10.0 / row["T_value"])  # duration / sampling time
        assert len(g) == steps, (key, len(g))
        np.testing.assert_allclose(g["time"].to_numpy(), row["T_value"] * np.arange(1, steps + 1), rtol=1e-12)
        e = np.sqrt(sum((g[f"true_{a}"].to_numpy() - g[f"est_{a}"].to_numpy()) ** 2 for a in "xyz"))
        np.testing.assert_allclose(g["e_tot"].to_numpy(), e, rtol=1e-14)
        ok = np.isfinite(e)
        rms = math.sqrt(np.mean(e[ok] ** 2))
        assert rms == pytest.approx(row["e_tot_rms"], rel=1e-12), key
        ie = np.sqrt(sum((g[f"true_{a}"].to_numpy() - g[f"instr_{a}"].to_numpy()) ** 2 for a in "xyz"))
        ok = g["instr_valid"].to_numpy()  # steps with a fix
        assert math.sqrt(np.mean(ie[ok] ** 2)) == pytest.approx(row["instr_e_tot_rms"], rel=1e-12), key


# --------------------------------------------------------------------------- bad input

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _bad_factor_key(table):
    table["factors"][0]["key"] = "platform.nokey"
    return ["factors.baseline.key", "platform.nokey"]


def _level_out_of_range(table):
    table["factors"][1] = {"name": "loss", "key": "acoustics.loss_pct", "low": 0.0, "high": 150.0}
    return ["factors.loss.high", "[0, 100]"]


def _zero_replicates(table):
    table["study"]["replicates"] = 0
    return ["study.replicates", "[1, 1000000]"]


BAD_STUDIES = {"unknown factor key": _bad_factor_key, "level out of range": _level_out_of_range,
               "zero replicates": _zero_replicates}


@pytest.mark.parametrize("case", [case if k == 0 else pytest.param(case, marks=pytest.mark.slow)
                                  for k, case in enumerate(BAD_STUDIES)])
def test_bad_study_is_one_line_and_writes_nothing(tmp_path, case):
    table = study_table()
    needles = BAD_STUDIES[case](table)
    study_file = write_study(tmp_path / "bad.toml", table)
    out = tmp_path / "out"
    proc = sblsim("campaign", study_file, "--out", out, "--workers", "1", cwd=tmp_path)
    assert_usage_error(proc, *needles)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_unknown_study_name(tmp_path):
    out = tmp_path / "out"
    proc = sblsim("campaign", "nosuchstudy", "--out", out, cwd=tmp_path)
    assert_usage_error(proc, "'nosuchstudy'", "paper")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_unreachable_scheduler(tmp_path):
    study_file = write_study(tmp_path / "s.toml", study_table())
    out = tmp_path / "out"
    address = f"tcp://127.0.0.1:{_free_port()}"
    proc = sblsim("campaign", study_file, "--out", out, "--scheduler", address, cwd=tmp_path, timeout=120)
    assert_usage_error(proc, "--scheduler", address)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


@pytest.mark.slow
def test_something_else_answering_at_the_scheduler_address(tmp_path):
    """A server on 127.0.0.1 that answers with garbage: one line naming --scheduler, in seconds, nothing written."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    port = server.getsockname()[1]

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                try:
                    conn.sendall(b"\xff" * 64 + b"HTTP/1.1 200 OK\r\n\r\nnot a Dask scheduler\n" * 20)
                except OSError:
                    pass

    threading.Thread(target=serve, daemon=True).start()
    study_file = write_study(tmp_path / "s.toml", study_table())
    address = f"tcp://127.0.0.1:{port}"
    try:
        start = time.monotonic()
        proc = sblsim("campaign", study_file, "--out", tmp_path / "out", "--scheduler", address, cwd=tmp_path,
                      timeout=120)
        seconds = time.monotonic() - start
    finally:
        server.close()
    assert_usage_error(proc, "--scheduler", address)
    assert seconds < 30, seconds
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


#: Long chunks (about 4 s each on two cores): an interrupt arrives while the workers are in the middle of them.
LONG_TABLE = {
    "study": {"name": "long", "scenarios": ["semicircle"], "replicates": 20, "seed": 5,
              "set": ["simulation.duration=1500"]},
    "factors": [{"name": "baseline", "key": "platform.baseline", "low": 1.0, "high": 3.0},
                {"name": "gps", "key": "platform.gps_sigma", "low": 0.1, "high": 1.0}],
}


@pytest.mark.slow
def test_ctrl_c_stops_the_worker_processes_at_once(tmp_path):
    """Ctrl-C with two worker processes busy: exit 130 within seconds (the chunks under way are dropped, not
    finished), and --resume finishes the campaign as an uninterrupted one."""
    study_file = write_study(tmp_path / "long.toml", LONG_TABLE)
    out = tmp_path / "out"
    proc = start_sblsim("campaign", study_file, "--workers", "2", "--batch", 20, "--out", out, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        while not (out / "chunks").is_dir():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.01)
        time.sleep(2.0)  # the workers are started and inside their first chunks
        assert proc.poll() is None
    except BaseException:
        proc.kill()
        proc.wait()
        raise
    _, stderr, delay = signal_and_wait(proc, signal.SIGINT)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert "interrupted" in stderr.splitlines()[-1], stderr
    assert delay < 10.0, delay  # a hang guard: the campaign's chunks would run on for minutes
    saved = len(chunk_files(out))
    resumed = sblsim("campaign", study_file, "--workers", "2", "--out", out, "--resume", cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stdout.splitlines()[-1].startswith(f"{(4 - saved) * 20} runs in "), resumed.stdout
    want = run_campaign(load_study(LONG_TABLE), tmp_path / "whole", workers=1, batch=20, progress=False).runs
    assert_same_runs(read_runs(out), want)


@pytest.mark.slow
def test_scheduler_local_starts_a_dask_local_cluster(reference, tmp_path):
    study, ref = reference
    study_file = write_study(tmp_path / "tiny.toml", study_table())
    proc = sblsim("campaign", study_file, "--scheduler", "local", "--workers", "2", "--batch", 2 * REPLICATES,
                  "--out", tmp_path / "local", cwd=tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "Dask scheduler local" in proc.stdout
    assert_same_runs(read_runs(tmp_path / "local"), ref.runs)


PEAK = """
import resource, sys
from sblsim.orchestrator.campaign import run_campaign
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run_batch, with_replicates
from sblsim.orchestrator.campaign.study import load_study
run_batch(with_replicates(load_config("semicircle", ["simulation.duration=2"]), range(500)), timeseries=False)
base = int(open("/proc/self/status").read().split("VmRSS:")[1].split()[0])  # after a chunk's worth of warm-up
levels = [("platform.baseline", 1.0, 3.0), ("platform.gps_sigma", 0.1, 1.0), ("acoustics.sigma_range", 0.1, 0.5),
          ("platform.imu_sigma_deg", 1.0, 5.0), ("target.depth_sigma", 0.01, 0.1), ("acoustics.loss_pct", 0.0, 20.0),
          ("platform.heading_deg", 0.0, 45.0)]
factors = [{"name": f"f{k}", "key": key, "low": low, "high": high} for k, (key, low, high) in enumerate(levels)]
table = {"study": {"name": "mem", "scenarios": ["semicircle"], "replicates": 500, "seed": 3,
                   "set": ["simulation.duration=2"]}, "factors": factors[:int(sys.argv[1])]}
run_campaign(load_study(table), sys.argv[2], workers=1, batch=500, progress=False)
print(base, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="/proc/self/status and ru_maxrss in kB as on Linux")
def test_peak_memory_is_bounded_by_the_chunk_not_the_study(tmp_path):
    """Twice the design cells (twice the chunks, of the same 500 runs: 32,000 against 64,000 runs) raise the
    campaign's peak resident memory above the warmed-up process by ≤ 10 %."""
    growth = []
    for factors in (6, 7):
        proc = subprocess.run([sys.executable, "-c", PEAK, str(factors), str(tmp_path / f"f{factors}")],
                              capture_output=True, text=True, timeout=900, check=False, cwd=ROOT)
        assert proc.returncode == 0, proc.stderr[-2000:]
        base, peak = map(int, proc.stdout.split()[-2:])
        growth.append(peak - base)
    assert len(pd.read_parquet(tmp_path / "f7" / "runs.parquet")) == 64000
    assert growth[1] <= 1.10 * growth[0] + 2048, growth  # kB; 2 MB of allocator noise
