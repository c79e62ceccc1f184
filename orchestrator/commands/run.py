"""``sblsim run`` and ``sblsim.run``: one scenario, configuration file or SSP package, run for its replicates
(:mod:`sblsim.orchestrator.cosim.run`); the command also writes its output folder and, with ``--export-log``, the
receiver's inputs as a log that ``sblsim replay`` reproduces, and with ``--export-detections`` an inverted LBL's run
as the raw detections of a telemetry array (:mod:`sblsim.orchestrator.sync.export`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.commands.common import Overrides, Progress, check_engine, resolve_plan
from sblsim.orchestrator.commands.console import (
    check_seed_option,
    config_options,
    output_folder,
    print_metrics,
)
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.master import ALGORITHMS
from sblsim.orchestrator.cosim.metrics import DIVERGENCE_DISTANCE, DIVERGENCE_RATIO, DIVERGENCE_REJECTIONS
from sblsim.orchestrator.cosim.plan import Config, thaw
from sblsim.orchestrator.cosim.replicates import _simulate
from sblsim.orchestrator.cosim.run_warnings import _run_warnings
from sblsim.orchestrator.cosim.ssp_read import read_ssp
from sblsim.orchestrator.io.arguments import check_count, path_argument, prepare_out
from sblsim.orchestrator.io.output import check_writable, folder_name
from sblsim.orchestrator.io.progress import check_progress

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class RunResult:
    """The outcome of :func:`run`.

    Attributes
    ----------
    config : Config
        The resolved configuration that ran.
    engine : str
        ``local`` or ``fmu``.
    timeseries : pandas.DataFrame
        One row per replicate and macro step: the columns of ``timeseries.parquet`` (``replicate``,
        ``time`` [s], ``true_*``, ``est_*``, ``instr_*`` [m], [m/s], the acoustic packet, the errors
        ``e_x``, ``e_y``, ``e_z``, ``e_tot`` [m], the receiver's covariance [m²] and the bound ``pcrb`` [m];
        the log-format page lists them).
    metrics : pandas.DataFrame
        One row per replicate: the metrics of ``summary.json`` (errors [m], NEES, NIS, coverage, ...).
    steps : int
        Macro steps per replicate.
    wall_time : float
        Wall-clock time of the simulation [s].
    out : Path or None
        Where the run was written (``out`` of :func:`run`), else None.
    """

    config: Config
    engine: str
    timeseries: pd.DataFrame
    metrics: pd.DataFrame
    steps: int
    wall_time: float
    out: Path | None = None
    _result: Any = field(default=None, repr=False)

    @property
    def summary(self) -> dict[str, Any]:
        """``summary.json`` of the first replicate (``run.replicate``): the keys ``sblsim run`` writes
        (``e_tot_rms`` [m], ``nees_mean``, ``coverage_95``, ``pcrb_rms`` [m], ``steps``, ``seed``, ...); a
        metric without a value is None."""
        return self.summaries[0]

    @property
    def summaries(self) -> list[dict[str, Any]]:
        """``summary.json`` of every replicate, in order."""
        from sblsim.orchestrator.cosim.run import RunRecord
        from sblsim.orchestrator.cosim.run_output import summary

        r = self._result
        out = []
        for k in range(len(r.metrics)):
            row = r.metrics.iloc[[k]].reset_index(drop=True)
            plan = r.plan.with_replicate(int(row["replicate"].iloc[0]))
            out.append(summary(RunRecord(plan.config, r.engine, r.timeseries, row, r.steps, r.wall_time, plan=plan)))
        return out

    def plot(self, replicate: int | None = None) -> dict[str, Figure]:
        """The figures ``sblsim run`` writes, of one replicate (default the first).

        Returns
        -------
        dict
            ``trajectory_xy``, ``trajectory_3d``, ``errors``, ``error_bounds`` -> matplotlib Figure (close
            them with ``matplotlib.pyplot.close`` when done).

        Raises
        ------
        ConfigError
            A replicate the run does not have.
        """
        from sblsim.orchestrator.io.plots import run_figures

        ts = self.timeseries
        if replicate is not None:
            if replicate not in set(ts["replicate"].unique().tolist()):
                raise ConfigError(f"replicate: {replicate!r} is not one of the run's "
                                  f"{sorted(ts['replicate'].unique().tolist())}")
            ts = ts[ts["replicate"] == replicate]
        receiver = self._result.plan.receiver_label
        return run_figures(ts, f"{self.config.scenario}, {receiver} ({self.engine})", receiver)


def run(config_or_scenario: str | Path | Mapping, *, engine: str = "local", replicates: int = 1,
        seed: int | None = None, set: Overrides = None, out: str | Path | None = None, force: bool = False,
        fmu_dir: str | Path | None = None, progress: Progress = False) -> RunResult:
    """Simulate a scenario: the numbers of ``sblsim run``.

    Parameters
    ----------
    config_or_scenario : str, Path or mapping
        A built-in scenario, a ``CONFIG.toml`` or a configuration (:func:`load`).
    engine : {'local', 'fmu'}
        The component engine (:data:`ENGINES`); ``fmu`` needs the FMUs (``sblsim fmus build``, or built on
        demand for other beacon counts).
    replicates : int
        Replicates to run, ``run.replicate`` … ``run.replicate + replicates - 1`` [1, 100000] (stepped
        together on the local engine; each replicate's numbers are those of a run of it alone).
    seed : int, optional
        The campaign seed ``run.seed``; default the configuration's.
    set : mapping or sequence of str, optional
        Overrides, as for :func:`load`.
    out : str or Path, optional
        Write ``summary.json``, ``config.toml``, ``timeseries.parquet`` and the figures there (one
        replicate only), atomically; default: nothing is written.
    force : bool
        Replace an earlier run in ``out``.
    fmu_dir : str or Path, optional
        The built FMUs (fmu engine; default ``fmus/build``).
    progress : bool or callable
        Report the steps done, a unit being one macro step of one replicate (:data:`Progress`).

    Returns
    -------
    RunResult

    Raises
    ------
    ConfigError, SblsimError
        Bad input of any kind (nothing is run or written).
    """
    from sblsim.orchestrator.cosim.run_output import write_run

    plan = resolve_plan(config_or_scenario, seed, set)
    check_engine(engine)
    replicates = check_count(replicates, "replicates", 1, 100_000)
    fmu_dir = path_argument(fmu_dir, "fmu_dir")
    check_progress(progress)
    if out is not None and replicates != 1:
        raise ConfigError(f"out: writes one run (the files of sblsim run); replicates is {replicates}")
    target = prepare_out(out, force, "summary.json", "run")
    result = _simulate(plan, engine, replicates, fmu_dir, progress)
    if target is not None:
        write_run(result, target)
    return _run_result(result, target)


def _run_result(result: Any, target: Path | None = None) -> RunResult:
    """The API's result of the kernel's record of a run (:class:`~sblsim.orchestrator.cosim.run.RunRecord`), its
    output folder ``target`` (None: nothing written)."""
    return RunResult(Config(thaw(result.config)), result.engine, result.timeseries, result.metrics, result.steps,
                     result.wall_time, target, result)


NAME = "run"
HELP = "run one scenario, configuration file or SSP package"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim run``'s arguments."""
    p.add_argument("scenario", nargs="?", default=None,
                   help="built-in scenario (semicircle, spiral, random, square, harbour, random-walk) or CONFIG.toml")
    p.add_argument("--ssp", type=Path, default=None, metavar="FILE.ssp",
                   help="run an SSP package instead: its FMUs, connections and parameter sets")
    p.add_argument("--engine", choices=ENGINES, default=None,
                   help="component engine (default local; fmu with --ssp, which runs the package's FMUs)")
    p.add_argument("--master", choices=ALGORITHMS, default=None,
                   help="master algorithm (default: the configuration's, gauss-seidel; event: with --engine fmu "
                        "--fmi-version 3, steps end at the acoustic arrivals)")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=None,
                   help="with --engine fmu: FMI 2.0 (default) or 3.0 FMUs (the folder fmi3 of the FMU folder; "
                        "the same numbers)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/SCENARIO)")
    p.add_argument("--force", action="store_true", help="replace an earlier run in --out (and --export-log files)")
    p.add_argument("--export-log", type=Path, default=None, metavar="FILE",
                   help="also write the receiver's inputs as a log (.csv or .parquet; docs/log-format.md) and the "
                        "truth track beside it (FILE's stem + _truth): `sblsim replay FILE` reproduces the receiver")
    p.add_argument("--export-detections", type=Path, default=None, metavar="DIR",
                   help="platform.system = ilbl: also write the run as raw detections on the hydrophones' own "
                        "clocks, with a sync tag at each (acoustics.receiver_clock_*, sync_interval_*): the YAPS "
                        "tables detections.csv and hydrophones.csv that sblsim sync and sblsim toa read, and the "
                        "truth (clocks.csv, truth.csv)")
    config_options(p)


def main(args: argparse.Namespace) -> int:
    """``sblsim run`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.cosim.run_output import write_run

    check_seed_option(args.seed)
    if (args.scenario is None) == (args.ssp is None):
        raise ModelError("run: give either a scenario (or CONFIG.toml) or --ssp FILE.ssp")
    overrides = args.overrides + ([f"simulation.master={args.master}"] if args.master else []) + \
        ([f"simulation.fmi_version={args.fmi_version}"] if args.fmi_version else [])
    system = None
    if args.ssp is not None:
        engine = args.engine or "fmu"
        system = read_ssp(args.ssp, overrides, args.seed)
        plan = system.config
    else:
        engine = args.engine or "local"
        plan = resolve_plan(args.scenario, args.seed, overrides)  # the run's one resolution
    if args.export_log is not None:
        from sblsim.orchestrator.logs.log_export import _check_export_apart, check_export

        check_export(args.export_log, args.force)
        check_writable(args.export_log.parent if str(args.export_log.parent) else Path("."), "--export-log")
    if args.export_detections is not None:
        from sblsim.orchestrator.sync.export import check_folder, check_keys

        if "toa" not in plan.system.ranging:  # the system whose receivers hear the target's pinger
            raise ModelError(f"--export-detections: raw detections are an inverted LBL's (platform.system = 'ilbl'); "
                             f"this run's system is {plan.config['platform']['system']!r}")
        check_keys(plan.config["acoustics"])
        check_folder(args.export_detections, args.force)
        check_writable(args.export_detections, "--export-detections")
    out = output_folder(args.out, Path("results") / folder_name(plan.scenario), args.force, "summary.json",
                        "run", before=None if args.export_log is None else lambda out: _check_export_apart(
                            args.export_log, out))
    if system is None:
        result = run(plan, engine=engine, fmu_dir=args.fmu_dir, progress="auto")
    else:  # the package's connections and, on the fmu engine, its FMUs
        result = _run_result(_simulate(plan, engine, fmu_dir=args.fmu_dir, progress="auto", ssp=system))
    exported: dict[str, Any] = {}

    def exports() -> None:
        """The run's exports, written before its own files move into place: a failed one leaves no run folder."""
        try:
            if args.export_log is not None:
                from sblsim.orchestrator.logs.log_export import export_log

                exported["log"] = export_log(result._result, args.export_log)
            if args.export_detections is not None:
                from sblsim.orchestrator.sync.export import export_detections

                exported["detections"] = export_detections(result._result, args.export_detections)
        except ModelError as exc:  # e.g. a full disk
            done = f"; the log was written ({exported['log'][0]})" if "log" in exported else ""
            raise ModelError(f"{exc}; nor were the run's results ({str(out)!r} is as it was){done}") from None

    write_run(result._result, out, exports)
    s = result.summary
    print(f"{s['scenario']} on the {s['engine']} engine ({plan.master}, receiver {s['receiver']}), "
          f"seed {s['seed']}: {s['steps']} steps in {s['wall_time']:.2f} s")
    print_metrics(s)
    if s["diverged"]:
        print(f"sblsim: warning: the {s['receiver']} receiver diverged (an estimate more than "
              f"{DIVERGENCE_DISTANCE:g} m and {DIVERGENCE_RATIO:g} times the diver's distance from the platform "
              f"off the truth, or {DIVERGENCE_REJECTIONS} received packets in a row its gate rejected): its numbers "
              "mean nothing; see error_bounds.png", file=sys.stderr)
    for line in _run_warnings(s, plan):
        print(f"sblsim: warning: {line}", file=sys.stderr)
    print(f"  written to {out}/ (summary.json, config.toml, timeseries.parquet, figures)")
    if "log" in exported:
        log, truth = exported["log"]
        print(f"  log of the receiver's inputs: {log} (replay it: sblsim replay {log} --truth {truth})")
    if "detections" in exported:
        export = exported["detections"]
        sync = (export.detections["tag"] != "T1").sum()
        print(f"  raw detections: {args.export_detections}/ (detections.csv: {len(export.detections) - sync} of the "
              f"tag T1, {sync} of the sync tags; hydrophones.csv; the truth in clocks.csv and truth.csv)")
    return 0
