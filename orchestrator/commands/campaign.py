"""``sblsim campaign`` and ``sblsim.campaign``: a factorial Monte Carlo study run in chunks on worker processes
or a Dask cluster, resumable (:mod:`sblsim.orchestrator.campaign`); ``--analyze`` and
:meth:`CampaignResult.analyze` run the ``analyze`` command on its folder.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sblsim.models.declarations import shown
from sblsim.orchestrator.commands.analyze import AnalysisResult, analyze, analyze_folder
from sblsim.orchestrator.commands.common import Progress, check_engine
from sblsim.orchestrator.commands.console import interrupted_status
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.io.arguments import check_integer, check_seed, flag_argument, path_argument, text_argument
from sblsim.orchestrator.io.output import check_writable, folder_name
from sblsim.orchestrator.io.progress import check_progress

if TYPE_CHECKING:  # the heavy modules are imported when a function runs (the campaign package's: pandas)
    import pandas as pd


@dataclass
class CampaignResult:
    """The outcome of :func:`campaign`.

    Attributes
    ----------
    out : Path
        The campaign directory.
    total : int
        Runs in ``runs.parquet``.
    computed : int
        Runs simulated by this call (0 when a finished campaign is resumed).
    wall_time : float
        Wall-clock time of the simulation [s].
    """

    out: Path
    total: int
    computed: int
    wall_time: float
    _result: Any = field(default=None, repr=False)

    @property
    def runs(self) -> pd.DataFrame:
        """``runs.parquet``: one row per run, the factors' levels and the metrics (read when first asked)."""
        return self._result.runs

    def analyze(self, **options: Any) -> AnalysisResult:
        """:func:`analyze` of this campaign (options as for :func:`analyze`)."""
        return analyze(self.out, **options)


def campaign(study: str | Path | Mapping, out: str | Path, *, seed: int | None = None, engine: str = "local",
             workers: int | None = None, scheduler: str | None = None, resume: bool = False,
             batch: int | None = None, save_timeseries: bool = False, fmu_dir: str | Path | None = None,
             progress: Progress = False) -> CampaignResult:
    """A factorial Monte Carlo study: ``sblsim campaign``.

    Parameters
    ----------
    study : str, Path or mapping
        A built-in study (``paper``), a ``STUDY.toml`` or a study's tables.
    out : str or Path
        The campaign directory (written: ``study.toml``, ``chunks/``, ``manifest.json``, ``runs.parquet``).
    seed : int, optional
        The campaign seed (default the study's).
    engine : {'local', 'fmu'}
    workers : int, optional
        Worker processes (default all cores; 1: in this process).
    scheduler : str, optional
        A Dask distributed scheduler ``tcp://host:port``, or ``local``.
    resume : bool
        Finish the campaign in ``out`` (missing chunks only).
    batch : int, optional
        Runs per chunk (does not change the results).
    save_timeseries : bool
        Also write every run's per-step time series.
    fmu_dir : str or Path, optional
        The built FMUs (fmu engine).
    progress : bool or callable
        Report the runs done (``True``: a bar; a callable ``progress(done, total)`` [runs]).

    Returns
    -------
    CampaignResult

    Raises
    ------
    SblsimError
        Bad input (nothing is written).
    sblsim.orchestrator.campaign.CampaignInterrupted
        On Ctrl-C: the finished chunks are kept (``resume=True`` finishes).
    """
    from sblsim.orchestrator.campaign import Study, load_study, run_campaign

    seed = check_seed(seed)
    check_engine(engine)
    out = path_argument(out, "out", optional=False)
    fmu_dir = path_argument(fmu_dir, "fmu_dir")
    scheduler = text_argument(scheduler, "scheduler")
    resume, save_timeseries = flag_argument(resume, "resume"), flag_argument(save_timeseries, "save_timeseries")
    workers = check_integer(workers, "workers")  # their ranges the campaign's
    batch = check_integer(batch, "batch")
    check_progress(progress)
    if isinstance(study, Study):  # validated already (sblsim campaign loads it to name its output)
        if seed is not None:
            raise ConfigError("seed: a loaded study holds its seed; give the seed to load_study")
        loaded = study
    else:
        if isinstance(study, Mapping):
            study = dict(study)
        elif isinstance(study, Path):
            study = str(study)
        elif not isinstance(study, str):
            raise ConfigError(f"study: expected a built-in study, a STUDY.toml or a study's tables, got "
                              f"{shown(study)}")
        loaded = load_study(study, seed=seed)
    check_writable(out, "out")
    # "auto" (sblsim campaign): a bar at a terminal, log lines otherwise
    spec: Any = (None if isinstance(progress, str) and progress == "auto" else "off" if progress in (False, None)
                 else True if progress is True else progress)
    result = run_campaign(loaded, out, workers=workers, scheduler=scheduler, resume=resume, engine=engine,
                          batch=batch, fmu_dir=fmu_dir, save_timeseries=save_timeseries, progress=spec)
    return CampaignResult(result.out, result.total, result.computed, result.wall_time, result)


NAME = "campaign"
HELP = "run a factorial Monte Carlo study (built-in: paper)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim campaign``'s arguments."""
    p.add_argument("study", help="built-in study (paper) or STUDY.toml")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: all cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="Dask distributed scheduler, e.g. tcp://host:8786, or 'local' for a Dask LocalCluster of "
                        "--workers processes (instead of a process pool)")
    p.add_argument("--out", type=Path, default=None, help="campaign directory (default results/STUDYNAME)")
    p.add_argument("--resume", action="store_true", help="finish the campaign in --out (missing chunks only)")
    p.add_argument("--engine", choices=ENGINES, default="local", help="component engine (default local)")
    p.add_argument("--seed", type=int, default=None, help="campaign seed (default: the study's)")
    p.add_argument("--batch", type=int, default=None,
                   help="runs per chunk (default 800 local, 50 fmu); does not change the results")
    p.add_argument("--save-timeseries", action="store_true", help="also write every run's per-step time series")
    p.add_argument("--fmu-dir", type=Path, default=None, help="directory of the built FMUs (fmu engine)")
    p.add_argument("--analyze", action="store_true", help="run `sblsim analyze` on the results at the end")


def main(args: argparse.Namespace) -> int:
    """``sblsim campaign`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.campaign import CampaignInterrupted, load_study

    study = load_study(args.study, seed=args.seed)
    out = args.out or Path("results") / folder_name(study.name)
    check_writable(out)
    workers = args.workers if args.workers is not None else os.cpu_count()
    where = f"Dask scheduler {args.scheduler}" if args.scheduler else f"{workers} worker process(es)"
    print(f"{study.name}: {len(study.scenarios)} scenarios x {study.cells} cells x {study.replicates} replicates "
          f"= {study.runs} runs on the {args.engine} engine, {where}")
    try:
        result = campaign(study, out, workers=args.workers, scheduler=args.scheduler, resume=args.resume,
                              engine=args.engine, batch=args.batch, fmu_dir=args.fmu_dir,
                              save_timeseries=args.save_timeseries, progress="auto")
    except CampaignInterrupted as exc:
        print(f"sblsim: {exc}", file=sys.stderr)
        return interrupted_status()
    if result.computed:
        print(f"{result.computed} runs in {result.wall_time:.1f} s ({result._result.runs_per_second:.0f} runs/s); "
              f"{result.total} runs in {out / 'runs.parquet'}")
    else:
        print(f"nothing to do: {result.total} runs already in {out / 'runs.parquet'}")
    diverged = int(result._result.column("diverged").sum())
    if diverged:
        print(f"sblsim: warning: the receiver diverged in {diverged} of {result.total} runs (column diverged of "
              "runs.parquet): their numbers mean nothing", file=sys.stderr)
    if args.analyze:
        return analyze_folder(out)
    return 0
