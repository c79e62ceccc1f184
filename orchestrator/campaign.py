"""Campaigns: run a study's scenarios × design cells × replicates, resumably, locally or on Dask.

Work is split into **chunks**: consecutive design cells of one scenario that
share every setting a batch cannot vary (e.g. the sampling time), up to
``batch`` runs. On the ``local`` engine a chunk is one batch: all its runs
are stepped together, the cells' factor levels given per replicate
(any numeric FMU parameter may differ per run). On the ``fmu`` engine a chunk's runs
are stepped one at a time through the FMUs, loaded once per worker process.
Chunks run in worker processes (``--workers``) or on a Dask distributed
cluster (``--scheduler``); only this process writes files.

Every run draws its random numbers from its own Philox streams, keyed by
(seed, scenario_key, cell, replicate, component, purpose) (docs/model.md, "Time and randomness"), and
a run's arithmetic does not depend on the batch it is stepped in, so
``runs.parquet`` is the same whatever the worker count, batch size,
scheduler or order of execution.

Campaign directory::

    study.toml          the resolved study (written first)
    chunks/ID.parquet   finished chunks, each written atomically
    manifest.json       each finished chunk's rows, cells, replicates and SHA-256, rewritten atomically after it
    timeseries/ID.parquet  per-step series (``--save-timeseries`` only)
    runs.parquet        all runs, sorted by scenario_key, cell, replicate

``--resume`` keeps only the chunks that verify: the manifest's checksum, and
the rows, cells and replicates the plan expects; a missing, damaged,
foreign or incomplete chunk is recomputed, with a line saying so. Without a
manifest (deleted by the user) every chunk is checked by its content alone.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import sys
import tempfile
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from sblsim.models import COMPONENTS
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.config import receiver_label
from sblsim.orchestrator.metrics import RUN_METRICS
from sblsim.orchestrator.run import ENGINES, fmu_paths, run_batch, system_sources, with_replicates
from sblsim.orchestrator.study import Study

#: Default runs per chunk on each engine.
DEFAULT_BATCH = {"local": 800, "fmu": 50}


class CampaignError(ModelError):
    """Invalid campaign request (output directory, scheduler, engine)."""


class CampaignInterrupted(Exception):
    """The campaign was interrupted; finished chunks are on disk."""

    def __init__(self, done: int, total: int, out: Path) -> None:
        super().__init__(f"interrupted: {done} of {total} runs saved in {out}; finish with --resume")
        self.done, self.total, self.out = done, total, out


@dataclass
class Chunk:
    """Consecutive design cells of one scenario, stepped as one batch.

    Attributes
    ----------
    id : str
        File stem, ``SCENARIOKEY-FIRSTCELL-LASTCELL``.
    scenario : str
    cells : list of int
    configs : list of dict
        Resolved configuration of each cell (replicate 0).
    replicates : int
    steps : int
        Macro steps per run (cost estimate).
    """

    id: str
    scenario: str
    cells: list[int]
    configs: list[dict] = field(repr=False)
    replicates: int = 1
    steps: int = 0

    @property
    def runs(self) -> int:
        return len(self.cells) * self.replicates


def batch_key(cfg: dict) -> tuple:
    """What the runs of one batch must share: the simulation settings, every text value and every
    configuration-only key (they make tables or files); numeric FMU parameters may differ per run."""
    key = [("simulation", name, value) for name, value in sorted(cfg["simulation"].items())]
    for section, model in COMPONENTS.items():
        fmu = {v.name for v in model.fmu_parameters_declared()}
        key.extend((section, name, value) for name, value in sorted(cfg[section].items())
                   if isinstance(value, str) or name not in fmu)
    return tuple(key)


def cell_configs(study: Study) -> dict[str, list[dict]]:
    """Resolved configuration of every design cell of every scenario (replicate 0).

    Raises
    ------
    ConfigError, ModelError
        If a design cell does not make a valid configuration.
    """
    return {scenario: [study.cell_config(scenario, c) for c in range(study.cells)] for scenario in study.scenarios}


def plan(study: Study, batch: int, configs: dict[str, list[dict]] | None = None) -> list[Chunk]:
    """Split a study into chunks of at most ``batch`` runs (at least one cell each).

    Cells are grouped by :func:`batch_key` in design order; the plan depends
    only on the study and ``batch``.
    """
    configs = configs if configs is not None else cell_configs(study)
    chunks = []
    per_chunk = max(1, batch // study.replicates)
    for scenario in study.scenarios:
        groups: dict[tuple, list[int]] = {}
        for c, cfg in enumerate(configs[scenario]):
            groups.setdefault(batch_key(cfg), []).append(c)
        for cells in groups.values():
            for start in range(0, len(cells), per_chunk):
                part = cells[start:start + per_chunk]
                cfg = configs[scenario][part[0]]
                sim = cfg["simulation"]
                steps = int(math.floor(sim["duration"] / sim["sampling_time"] + 1e-9)) * sim["ekf_rate_ratio"]
                chunks.append(Chunk(f"{cfg['run']['scenario_key']:03d}-{part[0]:05d}-{part[-1]:05d}", scenario,
                                    part, [configs[scenario][c] for c in part], study.replicates, steps))
    return chunks


def run_chunk(chunk: Chunk, study: Study, engine: str = "local", fmu_dir: str | None = None,
              timeseries: bool = False) -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """Simulate one chunk (in a worker) and return its result rows.

    Returns
    -------
    rows : pandas.DataFrame
        One row per run: identity, factor levels (coded and physical) and metrics.
    series : pandas.DataFrame or None
        Per-step time series with ``cell`` and ``replicate`` columns, if asked.
    """
    start = time.perf_counter()
    cfgs = [cfg for base in chunk.configs for cfg in with_replicates(base, range(chunk.replicates))]
    result = run_batch(cfgs, engine, fmu_dir=fmu_dir, timeseries=timeseries)
    cells = np.repeat(chunk.cells, chunk.replicates)
    first = chunk.configs[0]["run"]
    rows: dict[str, Any] = {
        "scenario": first["scenario"], "scenario_key": np.int64(first["scenario_key"]),
        "cell": cells.astype(np.int64), "replicate": result.metrics["replicate"].to_numpy(np.int64),
        "seed": np.int64(study.seed),
    }
    for k, factor in enumerate(study.factors):
        coded = study.matrix[cells, k]
        rows[factor.name] = coded.astype(np.int64)
        rows[f"{factor.name}_value"] = np.where(coded < 0, factor.low, factor.high)
    rows["receiver"] = receiver_label(chunk.configs[0])  # a chunk shares its receiver (batch_key)
    rows.update({m: result.metrics[m].to_numpy() for m in RUN_METRICS})
    series = None
    if timeseries:
        series = result.timeseries
        series.insert(0, "cell", np.repeat(cells, result.steps))
        series.insert(0, "scenario_key", np.int64(first["scenario_key"]))
    frame = pd.DataFrame(rows)
    frame.attrs["seconds"] = time.perf_counter() - start  # the worker's time for the chunk (in the manifest)
    return frame, series


def _write_atomic(frame: pd.DataFrame, path: Path) -> None:
    """Write a Parquet file through a temporary file in the same folder and an atomic rename."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        frame.to_parquet(tmp, index=False)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


MANIFEST = "manifest.json"
#: The manifest's entry recording the chunk plan (engine, batch size), beside the chunks' entries.
PLAN = "_plan"


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(out: Path) -> dict[str, dict] | None:
    """The campaign's manifest (chunk id -> entry), or None when there is none.

    Raises
    ------
    CampaignError
        If it cannot be read, saying what to do.
    """
    path = out / MANIFEST
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
        if not isinstance(manifest, dict) or not all(isinstance(v, dict) for v in manifest.values()):
            raise ValueError("not a table of chunks")
    except (ValueError, UnicodeDecodeError) as exc:
        raise CampaignError(f"--resume: {str(path)!r} is damaged ({str(exc).splitlines()[0]}); delete it and "
                            "resume again: every chunk is then checked by its content") from None
    return manifest


def write_manifest(out: Path, manifest: dict[str, dict]) -> None:
    """Write the manifest atomically."""
    fd, tmp = tempfile.mkstemp(prefix=f".{MANIFEST}.", suffix=".tmp", dir=out)
    with os.fdopen(fd, "w") as handle:
        json.dump(manifest, handle, indent=1, sort_keys=True)
    os.replace(tmp, out / MANIFEST)


def manifest_entry(chunk: "Chunk", path: Path, series: Path | None = None, seconds: float | None = None
                   ) -> dict[str, Any]:
    """What the manifest records of a finished chunk (with the worker's seconds for it, when known)."""
    entry = {"rows": chunk.runs, "cells": list(chunk.cells), "replicates": chunk.replicates,
             "sha256": file_digest(path)}
    if seconds is not None:
        entry["seconds"] = round(float(seconds), 3)
    if series is not None:
        entry["series_sha256"] = file_digest(series)
    return entry


def verify_chunk(chunk: "Chunk", path: Path, entry: dict | None, scenario_key: int, study: Study) -> str:
    """Why a chunk file cannot be kept ('' if it can): checksum, rows, cells, replicates, scenario, and the
    seed and factor levels of its rows (a chunk of another study is refused even with the same cells)."""
    if not path.is_file():
        return "missing"
    if entry is not None:
        if entry.get("sha256") != file_digest(path):
            return "its checksum differs from the manifest's"
        if entry.get("cells") != list(chunk.cells) or entry.get("rows") != chunk.runs:
            return "the manifest records other cells"
    levels = [f"{f.name}_value" for f in study.factors]
    try:
        frame = pd.read_parquet(path, columns=["scenario_key", "cell", "replicate", "seed", *levels])
    except Exception as exc:  # pyarrow raises several kinds on a damaged file
        return f"unreadable ({type(exc).__name__})"
    expected = {(c, r) for c in chunk.cells for r in range(chunk.replicates)}
    got = set(zip(frame["cell"].tolist(), frame["replicate"].tolist()))
    if len(frame) != chunk.runs or got != expected or set(frame["scenario_key"].tolist()) != {scenario_key}:
        return "it holds other runs than the plan's"
    cells = frame["cell"].to_numpy()
    for k, (factor, column) in enumerate(zip(study.factors, levels)):
        want = np.where(study.matrix[cells, k] < 0, factor.low, factor.high)
        if not np.array_equal(frame[column].to_numpy(), want) or not (frame["seed"] == study.seed).all():
            return "its rows belong to another study (seed or factor levels)"
    return ""


@dataclass
class CampaignResult:
    """Outcome of :func:`run_campaign`.

    Attributes
    ----------
    out : Path
        Campaign directory.
    total : int
        Runs in ``runs.parquet``.
    computed : int
        Runs simulated by this call (0 when a finished campaign is resumed).
    wall_time : float
        Wall-clock time of this call's simulation [s].
    """

    out: Path
    total: int
    computed: int
    wall_time: float
    _runs: pd.DataFrame | None = field(default=None, repr=False)

    @property
    def runs(self) -> pd.DataFrame:
        """``runs.parquet``, read when first asked for (a large study's table is not kept in memory)."""
        if self._runs is None:
            self._runs = pd.read_parquet(self.out / "runs.parquet")
        return self._runs

    def column(self, name: str) -> np.ndarray:
        """One column of ``runs.parquet`` (read alone)."""
        return pq.read_table(self.out / "runs.parquet", columns=[name]).column(name).to_numpy()

    @property
    def runs_per_second(self) -> float:
        return self.computed / self.wall_time if self.wall_time > 0 else float("nan")


#: ``--scheduler`` value that starts a Dask ``LocalCluster`` on this machine.
LOCAL_CLUSTER = "local"


def connect(scheduler: str, timeout: float = 10.0, workers: int | None = None):
    """A Dask distributed client of a scheduler address, or of a new ``LocalCluster`` (:data:`LOCAL_CLUSTER`:
    ``workers`` processes of one thread each, closed with the client).

    Raises
    ------
    CampaignError
        If no scheduler answers at the address.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - dask[distributed] is a dependency
        raise CampaignError("--scheduler: dask.distributed is not installed") from None
    if scheduler == LOCAL_CLUSTER:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster, set_as_default=False)
        client.cluster_owned = cluster  # closed with the client (close_client)
        return client
    try:
        return Client(scheduler, timeout=f"{timeout}s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CampaignError(f"--scheduler: no Dask scheduler reachable at {scheduler!r} ({reason})") from None


def close_client(client) -> None:
    """Close a Dask client, and the LocalCluster it started."""
    client.close()
    cluster = getattr(client, "cluster_owned", None)
    if cluster is not None:
        cluster.close()


def prepare_directory(out: Path, study: Study, resume: bool, engine: str, batch: int) -> int:
    """Check or create the campaign directory; return the batch size to use.

    A new directory gets ``study.toml`` (with the engine and batch size in an
    ``[execution]`` table). ``--resume`` requires the same study and engine
    and re-uses the recorded batch size, so the chunk plan is unchanged.

    Raises
    ------
    CampaignError
        If the directory holds another campaign, or a campaign without
        ``--resume``, or is a non-empty folder without a campaign.
    """
    import tomllib

    study_file = out / "study.toml"
    text = study.to_toml()
    if out.exists() and not out.is_dir():
        raise CampaignError(f"--out: {str(out)!r} exists and is not a directory")
    if study_file.is_file():
        if not resume:
            raise CampaignError(f"--out: {str(out)!r} already holds a campaign; add --resume to finish it "
                                "or choose another directory")
        try:
            recorded = tomllib.loads(study_file.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise CampaignError(f"--resume: {str(study_file)!r} is damaged ({str(exc).splitlines()[0]}); delete it "
                                "and resume again: it is rewritten from the study you give, and every chunk is "
                                "checked against that study") from None
        execution = recorded.pop("execution", {})
        if not isinstance(execution, dict):
            execution = {}
        if recorded != tomllib.loads(text):
            raise CampaignError(f"--resume: {str(out)!r} holds a different study; choose another --out")
        if execution.get("engine", engine) != engine:
            raise CampaignError(f"--engine: {str(out)!r} was run on the {execution['engine']} engine; "
                                "resume it with the same engine")
        return int(execution.get("batch", batch))
    if out.is_dir() and any(out.iterdir()):
        if not (resume and (out / "chunks").is_dir()):
            raise CampaignError(f"--out: {str(out)!r} is not empty and holds no campaign; choose another directory")
        # a campaign whose study.toml was deleted: rewritten from the study given, with the recorded plan
        plan_record = (read_manifest(out) or {}).get(PLAN, {})
        if plan_record.get("engine", engine) != engine:
            raise CampaignError(f"--engine: {str(out)!r} was run on the {plan_record['engine']} engine; "
                                "resume it with the same engine")
        batch = int(plan_record.get("batch", batch))
        print(f"campaign: {str(study_file)!r} was missing; written again from the study given", file=sys.stderr)
    out.mkdir(parents=True, exist_ok=True)
    (out / "chunks").mkdir(exist_ok=True)
    import tomli_w
    execution = "\n# how the campaign is executed (does not change the results)\n" + tomli_w.dumps(
        {"execution": {"engine": engine, "batch": batch}})
    tmp = out / ".study.toml.tmp"
    tmp.write_text(text + execution)
    os.replace(tmp, study_file)
    return batch


def run_campaign(study: Study, out: Path | str, workers: int | None = None, scheduler: str | None = None,
                 resume: bool = False, engine: str = "local", batch: int | None = None,
                 fmu_dir: str | Path | None = None, save_timeseries: bool = False,
                 progress: bool | None = None) -> CampaignResult:
    """Run (or finish) a campaign and write ``runs.parquet``.

    Parameters
    ----------
    study : Study
        Validated study (:func:`sblsim.orchestrator.study.load_study`).
    out : path
        Campaign directory.
    workers : int, optional
        Worker processes (default: all cores); 1 runs in this process.
        Ignored with a scheduler.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``).
    resume : bool
        Finish the campaign in ``out``, computing only missing chunks.
    engine : {'local', 'fmu'}
    batch : int, optional
        Runs per chunk (default :data:`DEFAULT_BATCH` of the engine).
    fmu_dir : path, optional
        Directory of the built FMUs (fmu engine).
    save_timeseries : bool
        Also write the per-step time series of every run.
    progress : bool, optional
        Progress bar (default: when stderr is a terminal; else log lines).

    Returns
    -------
    CampaignResult

    Raises
    ------
    CampaignError, ModelError
        Bad input; nothing is written.
    CampaignInterrupted
        On Ctrl-C; finished chunks are kept for ``--resume``.
    """
    out = Path(out)
    if engine not in ENGINES:
        raise CampaignError(f"--engine: {engine!r} is not one of {', '.join(ENGINES)}")
    if workers is not None and workers < 1:
        raise CampaignError(f"--workers: {workers} is outside the allowed range [1, inf)")
    if batch is not None and batch < 1:
        raise CampaignError(f"--batch: {batch} is outside the allowed range [1, inf)")
    batch = batch or DEFAULT_BATCH[engine]
    configs = cell_configs(study)  # every cell resolves before anything is written
    if engine == "fmu":  # refuse missing FMUs before anything is written
        for sources in {tuple(system_sources(cfg).items()) for cfgs in configs.values() for cfg in cfgs}:
            fmu_paths(fmu_dir, dict(sources))
        fmu_dir = str(Path(fmu_dir).resolve()) if fmu_dir is not None else None
    client = connect(scheduler, workers=workers) if scheduler else None
    new = not out.exists()
    try:
        batch = prepare_directory(out, study, resume, engine, batch)
    except BaseException:
        if client is not None:
            close_client(client)
        raise
    try:
        return _run_prepared(study, out, batch, configs, workers, client, engine, fmu_dir, save_timeseries,
                             progress)
    except KeyboardInterrupt:  # chunk files are written whole (then renamed): each one present is kept
        done = sum(pq.ParquetFile(f).metadata.num_rows for f in (out / "chunks").glob("*.parquet"))
        raise CampaignInterrupted(done, study.runs, out) from None
    except Exception:
        if new and not any((out / "chunks").glob("*.parquet")):  # nothing done: leave no half-made folder
            shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        if client is not None:
            close_client(client)


def _run_prepared(study: Study, out: Path, batch: int, configs: dict, workers, client, engine: str, fmu_dir,
                  save_timeseries: bool, progress: bool | None) -> CampaignResult:
    """Run the missing chunks of a prepared campaign directory and write ``runs.parquet``."""
    chunks = plan(study, batch, configs)
    chunk_dir, series_dir = out / "chunks", out / "timeseries"
    chunk_dir.mkdir(exist_ok=True)
    if save_timeseries:
        series_dir.mkdir(exist_ok=True)
    for folder in (out, chunk_dir, series_dir):  # temporary files left by a killed process
        for stale in folder.glob(".*.tmp"):
            stale.unlink()
    manifest = read_manifest(out)
    rebuilt = manifest is None
    manifest = manifest or {}
    manifest[PLAN] = {"engine": engine, "batch": batch}
    todo = []
    for c in chunks:
        path, series = chunk_dir / f"{c.id}.parquet", series_dir / f"{c.id}.parquet"
        entry = manifest.get(c.id)
        reason = verify_chunk(c, path, entry, c.configs[0]["run"]["scenario_key"], study)
        if not reason and save_timeseries:
            if not series.is_file():
                reason = "its time series are missing"
            elif entry is not None and entry.get("series_sha256") not in (None, file_digest(series)):
                reason = "its time series' checksum differs from the manifest's"
        if reason:
            if reason != "missing":
                print(f"campaign: chunk {c.id} is recomputed: {reason}", file=sys.stderr, flush=True)
            manifest.pop(c.id, None)
            todo.append(c)
        elif entry is None:  # a chunk that verifies by its content, without a manifest entry
            manifest[c.id] = manifest_entry(c, path, series if save_timeseries else None)
    if rebuilt and manifest:
        write_manifest(out, manifest)
    total = study.runs
    done = total - sum(c.runs for c in todo)
    start = time.perf_counter()
    computed = 0
    if todo:
        todo.sort(key=lambda c: -c.steps * c.runs)  # longest first: better load balance
        reporter = _Progress(total, done, progress)
        try:
            for chunk, (rows, series) in _execute(todo, study, engine, fmu_dir, save_timeseries,
                                                  workers, client):
                path = chunk_dir / f"{chunk.id}.parquet"
                seconds = rows.attrs.pop("seconds", None)  # not into the file: its bytes depend on the results only
                if series is not None:
                    _write_atomic(series, series_dir / f"{chunk.id}.parquet")
                _write_atomic(rows, path)
                manifest[chunk.id] = manifest_entry(chunk, path, series_dir / f"{chunk.id}.parquet"
                                                    if series is not None else None, seconds)
                write_manifest(out, manifest)
                computed += chunk.runs
                reporter.update(chunk.runs)
        finally:
            reporter.close()
    wall = time.perf_counter() - start
    if computed or not (out / "runs.parquet").is_file():
        collect(out, chunks, out / "runs.parquet")
    return CampaignResult(out, pq.ParquetFile(out / "runs.parquet").metadata.num_rows, computed, wall)


#: Rows per row group of runs.parquet (and what collect holds at once, besides a few chunks).
ROW_GROUP = 8192


def collect(out: Path, chunks: list[Chunk], path: Path, cached: int = 8) -> None:
    """Write the chunk files of a campaign as one table sorted by scenario_key, cell, replicate, atomically.

    A streaming merge: each design cell's runs lie in one chunk, in replicate order, so the cells are taken in
    order from their chunks, holding only the few chunks in use (``cached``) and one row group: the memory
    is bounded by the chunk size, not by the study's.
    """
    from collections import OrderedDict

    import pyarrow as pa

    order = sorted((c.configs[0]["run"]["scenario_key"], cell, c.id, k, c.replicates)
                   for c in chunks for k, cell in enumerate(c.cells))
    tables: OrderedDict[str, pa.Table] = OrderedDict()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    writer, parts, rows = None, [], 0
    try:
        for _, _, chunk_id, k, replicates in order:
            if chunk_id not in tables:
                tables[chunk_id] = pq.read_table(out / "chunks" / f"{chunk_id}.parquet")
                if len(tables) > cached:
                    tables.popitem(last=False)
            tables.move_to_end(chunk_id)
            parts.append(tables[chunk_id].slice(k * replicates, replicates))
            rows += replicates
            if rows >= ROW_GROUP:
                writer = _write_parts(writer, tmp, parts)
                parts, rows = [], 0
        if parts or writer is None:
            writer = _write_parts(writer, tmp, parts)
        writer.close()
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _write_parts(writer, tmp: str, parts: list):
    import pyarrow as pa

    table = pa.concat_tables(parts) if parts else None
    if writer is None:
        writer = pq.ParquetWriter(tmp, table.schema)
    if table is not None:
        writer.write_table(table, row_group_size=ROW_GROUP)
    return writer


def _execute(chunks: list[Chunk], study: Study, engine: str, fmu_dir, timeseries: bool, workers: int | None,
             client) -> Iterator[tuple[Chunk, tuple[pd.DataFrame, pd.DataFrame | None]]]:
    """Yield each chunk with its result as soon as it is finished."""
    if client is not None:
        from distributed import as_completed

        futures = {client.submit(run_chunk, c, study, engine, fmu_dir, timeseries, pure=False,
                                 key=f"sblsim-{study.name}-{c.id}-{os.getpid()}-{time.time_ns()}"): c
                   for c in chunks}
        try:
            for future in as_completed(futures, loop=client.loop):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()
        return
    workers = workers or os.cpu_count() or 1
    if workers == 1 or len(chunks) == 1:
        for c in chunks:
            yield c, run_chunk(c, study, engine, fmu_dir, timeseries)
        return
    import multiprocessing

    pool = ProcessPoolExecutor(max_workers=min(workers, len(chunks)),
                               mp_context=multiprocessing.get_context("spawn"), initializer=watch_parent,
                               initargs=(os.getpid(),))
    try:
        pending = {pool.submit(run_chunk, c, study, engine, fmu_dir, timeseries): c for c in chunks}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                yield pending.pop(future), future.result()
    finally:
        pool.shutdown(wait=False, cancel_futures=True)


def watch_parent(parent: int, every: float = 0.5) -> None:
    """In a worker process: exit as soon as the campaign's process is gone (killed, even by SIGKILL).

    A daemon thread compares the parent's process id with ``parent`` every
    ``every`` seconds; the pool's own shutdown covers a parent that exits
    normally.
    """
    def watch() -> None:
        while True:
            time.sleep(every)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="sblsim-parent-watch", daemon=True).start()


class _Progress:
    """Runs done, runs per second and time left: a tqdm bar on a terminal, log lines otherwise."""

    def __init__(self, total: int, done: int, bar: bool | None, every: float = 10.0) -> None:
        self.total, self.done, self.every = total, done, every
        self.start = self.last = time.perf_counter()
        self.first = done
        if bar is None:
            bar = sys.stderr.isatty()
        self.bar = None
        if bar:
            from tqdm import tqdm
            self.bar = tqdm(total=total, initial=done, unit="run", desc="campaign", smoothing=0.1)
        else:
            self._log(force=True)

    def update(self, runs: int) -> None:
        self.done += runs
        if self.bar is not None:
            self.bar.update(runs)
        else:
            self._log(force=self.done >= self.total)

    def _log(self, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last < self.every:
            return
        self.last = now
        rate = (self.done - self.first) / (now - self.start) if now > self.start else 0.0
        left = f", about {(self.total - self.done) / rate:.0f} s left" if rate > 0 and self.done < self.total else ""
        print(f"campaign: {self.done}/{self.total} runs ({100.0 * self.done / self.total:.0f} %), "
              f"{rate:.1f} runs/s{left}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
