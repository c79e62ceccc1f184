"""Running a campaign: check the request, prepare the directory, run the missing chunks, merge the rows."""

from __future__ import annotations

import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from sblsim.orchestrator.campaign.errors import CampaignError, CampaignInterrupted
from sblsim.orchestrator.campaign.executors import check_address, close_client, connect, execute, start_pool, stop_pool
from sblsim.orchestrator.campaign.manifest import (
    PLAN,
    manifest_entry,
    prepare_directory,
    read_manifest,
    verify_chunk,
    write_manifest,
    write_parquet,
)
from sblsim.orchestrator.campaign.merge import collect
from sblsim.orchestrator.campaign.plan import DEFAULT_BATCH, cell_configs, plan
from sblsim.orchestrator.campaign.study import Study
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.fmu_files import fmu_paths
from sblsim.orchestrator.cosim.limits import check_steps
from sblsim.orchestrator.io.manifest import file_digest
from sblsim.orchestrator.io.progress import Progress


@dataclass
class CampaignRecord:
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


def run_campaign(study: Study, out: Path | str, workers: int | None = None, scheduler: str | None = None,
                 resume: bool = False, engine: str = "local", batch: int | None = None,
                 fmu_dir: str | Path | None = None, save_timeseries: bool = False,
                 progress: bool | None = None) -> CampaignRecord:
    """Run (or finish) a campaign and write ``runs.parquet``.

    Parameters
    ----------
    study : Study
        Validated study (:func:`sblsim.orchestrator.campaign.study.load_study`).
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
    progress : bool, 'off' or callable, optional
        How the runs done are reported (:class:`sblsim.orchestrator.io.progress.Progress`, from the resumed
        campaign's runs, with its first and last line and the runs/s): None (default) a bar when standard
        error is a terminal, else log lines; True a bar; False log lines; ``"off"`` nothing; a callable
        ``progress(done, total)`` [runs].

    Returns
    -------
    CampaignRecord

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
    if scheduler:
        check_address(scheduler)
    batch = batch or DEFAULT_BATCH[engine]
    pool = None
    count = workers or os.cpu_count() or 1
    if not scheduler and count > 1 and study.runs > max(batch, study.replicates):  # two chunks at least
        # the worker processes start first: they import while the cells are resolved and planned
        pool = start_pool(min(count, study.cells * len(study.scenarios)))
    try:
        return _run_campaign(study, out, workers, scheduler, resume, engine, batch, fmu_dir, save_timeseries,
                             progress, pool)
    finally:
        if pool is not None:  # unused (nothing to run, or bad input), or shut down by execute
            stop_pool(pool)


def _run_campaign(study: Study, out: Path, workers: int | None, scheduler: str | None, resume: bool, engine: str,
                  batch: int, fmu_dir, save_timeseries: bool, progress: bool | None, pool) -> CampaignRecord:
    """:func:`run_campaign` after the checks of its arguments (``pool``: worker processes started, or None)."""
    configs = cell_configs(study)  # every cell is resolved into its plan, once, before anything is written
    if engine == "fmu":  # refuse missing FMUs before anything is written
        for sources, n_beacons in {(tuple(p.sources.items()), p.n_beacons) for plans in configs.values()
                                   for p in plans}:
            fmu_paths(fmu_dir, dict(sources), n_beacons)
        fmu_dir = str(Path(fmu_dir).resolve()) if fmu_dir is not None else None
    _check_memory(plan(study, batch, configs), workers, scheduler, save_timeseries)
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
                             progress, pool)
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


def _check_memory(chunks: list, workers: int | None, scheduler: str | None, save_timeseries: bool) -> None:
    """Refuse, before anything is written, a campaign whose chunks' records would not fit in memory: each
    worker process of this machine holds one chunk's record (a scheduler's workers are counted one each).

    Raises
    ------
    ModelError
        As :func:`sblsim.orchestrator.cosim.limits.check_steps`.
    """
    concurrent = 1 if scheduler else min(workers or os.cpu_count() or 1, len(chunks))
    def need(chunk) -> int:
        return chunk.runs * chunk.plans[0].n_steps

    if chunks:
        largest = max(chunks, key=need)
        first = largest.plans[0]
        check_steps(first.duration, first.sampling_time, largest.runs, save_timeseries, concurrent)


def _run_prepared(study: Study, out: Path, batch: int, configs: dict, workers, client, engine: str, fmu_dir,
                  save_timeseries: bool, progress: bool | None, pool=None) -> CampaignRecord:
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
        reason = verify_chunk(c, path, entry, c.plans[0]["run"]["scenario_key"], study)
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
        spec = "auto" if progress is None else "log" if progress is False else progress
        reporter = Progress(total, "campaign", "run", spec, initial=done, ends=True, rate=True)
        try:
            for chunk, (rows, series) in execute(todo, study, engine, fmu_dir, save_timeseries,
                                                  workers, client, pool):
                path = chunk_dir / f"{chunk.id}.parquet"
                seconds = rows.attrs.pop("seconds", None)  # not into the file: its bytes depend on the results only
                if series is not None:
                    write_parquet(series, series_dir / f"{chunk.id}.parquet")
                write_parquet(rows, path)
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
    return CampaignRecord(out, pq.ParquetFile(out / "runs.parquet").metadata.num_rows, computed, wall)
