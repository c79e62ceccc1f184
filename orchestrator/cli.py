"""Command line: ``sblsim run``, ``replay``, ``calibrate``, ``compare``, ``budget``, ``map``, ``campaign``, ``analyze``,
``ssp export``, ``fmus build|validate|variables`` and ``codegen receiver``.

Bad input of any kind ends with a one-line ``sblsim: error: ...`` naming the
field and the allowed range, exit status 2, and nothing written.

Each command imports the module that runs it when it runs (``run``, ``metrics``,
``compare``, ``budget``, ``maps``, ``replay``, ``campaign``, ``study``,
``analysis``, ``codegen``): they load scipy.stats, pandas or matplotlib, which
``sblsim --help`` and a usage error do not need. Everything else is imported
here; ``tests/test_import_graph.py`` holds both rules.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Callable

import numpy as np

from sblsim.fmus.build import DEFAULT_DIR, beacons_dir, build_fmu, fmu_path, validate
from sblsim.fmus.compiler import COMPILERS
from sblsim.fmus.embedded import write_receiver
from sblsim.fmus.variables import markdown_tables
from sblsim.models import MODELS, RECEIVERS
from sblsim.models.declarations import ModelError, shown
from sblsim.models.errors import SblsimError
from sblsim.models.platform.core import MAX_BEACONS, MIN_BEACONS
from sblsim.models.systems import SYSTEMS, interface_owners
from sblsim.orchestrator import api
from sblsim.orchestrator.cosim.config import (
    MODEL_PREFIX,
    check_receiver,
    external_path,
    parse_compare,
)
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.master import ALGORITHMS
from sblsim.orchestrator.cosim.metrics import DIVERGENCE_DISTANCE, DIVERGENCE_RATIO, DIVERGENCE_REJECTIONS, REACH_RATIO
from sblsim.orchestrator.cosim.plugins import user_model
from sblsim.orchestrator.cosim.systems import describe_defaults, parse_systems, system_overrides
from sblsim.orchestrator.io.output import OutputLock, check_output, check_writable, folder_name
from sblsim.orchestrator.scenario_fmus import build_scenario_fmus
from sblsim.orchestrator.ssp import export_ssp, read_ssp
from sblsim.orchestrator.study import load_study

EXIT_USAGE = 2
#: --fmu-dir: where the fmu engine looks when it is not given (fmus/build of a checkout, else the user cache).
FMU_DIR_HELP = (f"directory of the built FMUs (default {DEFAULT_DIR}; FMUs missing there are built into the "
                "user cache)")
#: The registered systems (the command line's words: :data:`sblsim.models.systems.SYSTEMS`).
_ALL_SYSTEMS = ",".join(SYSTEMS)
#: The systems that own components' interfaces (``fmus build --system``): the layout-sized one first.
_OWNERS = tuple(s.name for s in interface_owners())
_FIXED = ", ".join(name for name in _OWNERS if SYSTEMS[name].interface_beacons is not None)
EXIT_INTERRUPTED = 130


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2 (argparse prints usage too)
        self.exit(EXIT_USAGE, f"sblsim: error: {message}\n")


def _version() -> str:
    """The installed distribution's version (``pip show sblsim``)."""
    try:
        return version("sblsim")
    except PackageNotFoundError:  # run from a checkout that was never installed
        return "unknown (not installed)"


def _config_options(p: argparse.ArgumentParser) -> None:
    """``--seed``, ``--set`` and ``--fmu-dir``: the options of a command that resolves a configuration."""
    p.add_argument("--seed", type=int, default=None, help="campaign seed (default: from the configuration, 0)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key, e.g. platform.baseline=3 or receiver=lsq (repeatable)")
    p.add_argument("--fmu-dir", type=Path, default=None, help=FMU_DIR_HELP)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="sblsim", description="SBL acoustic underwater positioning co-simulation")
    p.add_argument("--version", action="version", version=f"sblsim {_version()}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser("run", help="run one scenario, configuration file or SSP package")
    r.add_argument("scenario", nargs="?", default=None,
                   help="built-in scenario (semicircle, spiral, random, square, harbour, random-walk) or CONFIG.toml")
    r.add_argument("--ssp", type=Path, default=None, metavar="FILE.ssp",
                   help="run an SSP package instead: its FMUs, connections and parameter sets")
    r.add_argument("--engine", choices=ENGINES, default=None,
                   help="component engine (default local; fmu with --ssp, which runs the package's FMUs)")
    r.add_argument("--master", choices=ALGORITHMS, default=None,
                   help="master algorithm (default: the configuration's, gauss-seidel)")
    r.add_argument("--out", type=Path, default=None, help="output directory (default results/SCENARIO)")
    r.add_argument("--force", action="store_true", help="replace an earlier run in --out (and --export-log files)")
    r.add_argument("--export-log", type=Path, default=None, metavar="FILE",
                   help="also write the receiver's inputs as a log (.csv or .parquet; docs/log-format.md) and the "
                        "truth track beside it (FILE's stem + _truth): `sblsim replay FILE` reproduces the receiver")
    _config_options(r)

    y = sub.add_parser("replay", help="run a receiver on a recorded log (docs/log-format.md)")
    y.add_argument("log", type=Path, help="the log: .csv or .parquet (sblsim run --export-log writes one)")
    y.add_argument("--receiver", default=None,
                   help="ekf, ekf-seq, ukf, lsq, model:PATH.py or fmu:PATH (default: the configuration's)")
    y.add_argument("--config", default=None, metavar="CONFIG",
                   help="the receiver's parameters, T and rate ratio: a built-in scenario or CONFIG.toml (default: "
                        "the configuration an exported log carries, else the semicircle scenario's)")
    y.add_argument("--truth", type=Path, default=None, metavar="FILE",
                   help="truth track (time_s, n_m, e_m, d_m; .csv or .parquet): errors, consistency, figures")
    y.add_argument("--engine", choices=ENGINES, default="local", help="component engine (default local)")
    y.add_argument("--out", type=Path, default=None, help="output directory (default results/replay_LOGNAME)")
    y.add_argument("--force", action="store_true", help="replace an earlier replay in --out")
    y.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key, e.g. receiver.q_horizontal=0.05 (repeatable)")
    y.add_argument("--fmu-dir", type=Path, default=None, help=FMU_DIR_HELP)

    k = sub.add_parser("calibrate", help="locate seafloor transponders from a surface survey's two-way travel times "
                                         "(docs/calibration.md)")
    k.add_argument("survey", metavar="SURVEY|LOG|CONFIG",
                   help="a built-in survey (xie-2021-07-23, the other days xie-2021-08-23-1065 ..., ncl1-2022-208, "
                        "seagap-example; box-in, simulated), a survey log (.csv or .parquet; any text file with "
                        "--format xie; a SeaGap folder with --format seagap) or a simulated survey CONFIG.toml")
    k.add_argument("--format", default=None, metavar="FORMAT",
                   help="the log's format: sblsim (default), xie (survey A's text files), seagap (a folder of "
                        "SeaGap's files) or garpos (GARPOS's observation CSV, with --initcfg and --svp)")
    k.add_argument("--initcfg", default=None, metavar="FILE",
                   help="--format garpos: GARPOS's initial site-parameter file (the paths it names are not read)")
    k.add_argument("--svp", default=None, metavar="FILE", help="--format garpos: GARPOS's sound-speed profile (CSV)")
    k.add_argument("--replicates", type=int, default=None, metavar="N",
                   help="a simulated survey: solve N replicates and write replicates.parquet (errors against the "
                        "truth, NEES, the horizontal bound)")
    k.add_argument("--out", type=Path, default=None, help="output directory (default results/calibrate_NAME)")
    k.add_argument("--force", action="store_true", help="replace an earlier calibration in --out")
    k.add_argument("--set", dest="overrides", action="append", default=[], metavar="TABLE.KEY=VALUE",
                   help="override a solver setting, e.g. solver.sound_speed_mps=1500 or solver.solve_sound_speed=true, "
                        "or a simulated survey's survey.KEY / platform.KEY (repeatable)")

    m = sub.add_parser("compare", help="run several receivers (or positioning systems) on the same replicates of a "
                                       "scenario")
    m.add_argument("scenario", help="built-in scenario or CONFIG.toml")
    m.add_argument("--receivers", default="ekf,ekf-seq,ukf,lsq",
                   help="comma-separated receivers (default ekf,ekf-seq,ukf,lsq; model:PATH.py or fmu:PATH for "
                        "your own)")
    m.add_argument("--systems", default=None, metavar="SYSTEMS",
                   help=f"compare positioning systems, e.g. {_ALL_SYSTEMS}: every system, with every receiver, "
                        "on the same diver paths, replicates and error levels, each from its defaults, your --set "
                        f"over them: {describe_defaults()}")
    m.add_argument("--replicates", type=int, default=20, help="runs per receiver (default 20)")
    m.add_argument("--engine", choices=ENGINES, default="local", help="component engine (default local)")
    m.add_argument("--out", type=Path, default=None, help="output directory (default results/compare_SCENARIO)")
    m.add_argument("--force", action="store_true", help="replace an earlier comparison in --out")
    _config_options(m)

    u = sub.add_parser("budget", help="error budget: each error source's share of the position error")
    u.add_argument("scenario", help="built-in scenario or CONFIG.toml")
    u.add_argument("--replicates", type=int, default=None,
                   help="runs per configuration: the all-on one, the all-off one and one per source switched off "
                        "(default 500)")
    u.add_argument("--receiver", default=None,
                   help="the receiver (default: the configuration's); ekf, ekf-seq, ukf, lsq, model:PATH.py or "
                        "fmu:PATH")
    u.add_argument("--compare", default=None, metavar="KEY=V1,V2,...",
                   help=f"one budget per value, side by side, e.g. platform.system={_ALL_SYSTEMS}")
    u.add_argument("--out", type=Path, default=None, help="output directory (default results/budget_SCENARIO)")
    u.add_argument("--force", action="store_true", help="replace an earlier budget in --out")
    u.add_argument("--seed", type=int, default=None, help="campaign seed (default: from the configuration, 0)")
    u.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key (repeatable)")

    g = sub.add_parser("map", help="accuracy map: horizontal standard deviation of a fix around the platform")
    g.add_argument("scenario", help="built-in scenario or CONFIG.toml (geometry and error levels)")
    g.add_argument("--extent", type=float, default=30.0,
                   help="half-width of the square grid [m] (default 30; at most 100000)")
    g.add_argument("--step", type=float, default=0.5, help="grid spacing [m] (default 0.5)")
    g.add_argument("--levels", default="0.5,1,2", help="accuracy prescriptions to contour [m] (default 0.5,1,2)")
    g.add_argument("--compare", default=None, metavar="KEY=V1,V2,...",
                   help="one map per value, side by side, e.g. platform.baseline=0.4,1,3; "
                        f"platform.system={_ALL_SYSTEMS} "
                        "maps each system from the defaults of compare --systems, your --set over them")
    g.add_argument("--depth", type=float, default=None,
                   help="the diver's depth of the maps [m] (default target.depth, or the median depth of a "
                        "trajectory file); above the site's water depth acoustics.water_depth and, LBL, above its "
                        "seafloor transponders")
    g.add_argument("--out", type=Path, default=None, help="output directory (default results/map_SCENARIO)")
    g.add_argument("--force", action="store_true", help="replace an earlier map in --out")
    g.add_argument("--seed", type=int, default=None, help=argparse.SUPPRESS)
    g.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key (repeatable)")

    c = sub.add_parser("campaign", help="run a factorial Monte Carlo study (built-in: paper)")
    c.add_argument("study", help="built-in study (paper) or STUDY.toml")
    c.add_argument("--workers", type=int, default=None, help="worker processes (default: all cores)")
    c.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="Dask distributed scheduler, e.g. tcp://host:8786, or 'local' for a Dask LocalCluster of "
                        "--workers processes (instead of a process pool)")
    c.add_argument("--out", type=Path, default=None, help="campaign directory (default results/STUDYNAME)")
    c.add_argument("--resume", action="store_true", help="finish the campaign in --out (missing chunks only)")
    c.add_argument("--engine", choices=ENGINES, default="local", help="component engine (default local)")
    c.add_argument("--seed", type=int, default=None, help="campaign seed (default: the study's)")
    c.add_argument("--batch", type=int, default=None,
                   help="runs per chunk (default 800 local, 50 fmu); does not change the results")
    c.add_argument("--save-timeseries", action="store_true", help="also write every run's per-step time series")
    c.add_argument("--fmu-dir", type=Path, default=None, help="directory of the built FMUs (fmu engine)")
    c.add_argument("--analyze", action="store_true", help="run `sblsim analyze` on the results at the end")

    s = sub.add_parser("ssp", help="export the system as an SSP 1.0 package for other FMI hosts")
    ssub = s.add_subparsers(dest="ssp_command", required=True, parser_class=_Parser)
    e = ssub.add_parser("export", help="write SystemStructure.ssd, the FMUs and the parameter sets as FILE.ssp")
    e.add_argument("scenario", help="built-in scenario or CONFIG.toml")
    e.add_argument("--out", type=Path, required=True, help="the .ssp file to write")
    e.add_argument("--force", action="store_true", help="replace an existing package")
    _config_options(e)

    a = sub.add_parser("analyze", help="factorial analysis and report of a campaign directory")
    a.add_argument("dir", type=Path, help="campaign directory (with runs.parquet)")
    a.add_argument("--out", type=Path, default=None, help="output directory (default: the campaign directory)")
    a.add_argument("--metric", default="e_tot_rms",
                   help="response column: an error metric [m] (default e_tot_rms) or detected_pct [%%]")
    a.add_argument("--order", type=int, default=2, help="highest interaction order in the model (default 2)")
    a.add_argument("--transform", choices=("none", "log", "boxcox"), default="none",
                   help="fit the model to the metric (none, default), its logarithm (log: effects as factors) or "
                        "its Box-Cox transform (boxcox: lambda by maximum likelihood); see diagnostics.csv")

    f = sub.add_parser("fmus", help="build, validate or list the FMI 2.0 Co-Simulation FMUs")
    fsub = f.add_subparsers(dest="fmus_command", required=True, parser_class=_Parser)
    b = fsub.add_parser("build", help="build the native FMUs (four components and the alternative receivers)")
    b.add_argument("--out", type=Path, default=None, help=f"output directory (default {DEFAULT_DIR})")
    b.add_argument("--compiler", choices=COMPILERS, default="auto",
                   help="C compiler: auto (the system's, else zig), system or zig")
    b.add_argument("--cross", action=argparse.BooleanOptionalAction, default=None,
                   help="also build Windows and macOS binaries with zig (default: when the compiler is zig)")
    b.add_argument("--model", type=Path, default=None, metavar="PATH.py",
                   help="build only the receiver model this Python file defines (see docs/extending.md, "
                        "Write your own receiver)")
    b.add_argument("--beacons", type=int, default=4, metavar="N",
                   help="beacons of the interfaces (default 4; other N go to the folder beacons<N> of the output)")
    b.add_argument("--system", choices=_OWNERS, default=_OWNERS[0],
                   help=f"{_FIXED}: the interfaces of that system (its folder of the output); the others use the "
                        f"{_OWNERS[0]} interfaces of --beacons N (default {_OWNERS[0]})")
    b.add_argument("--scenario", default=None, metavar="NAME|CONFIG.toml",
                   help="build that scenario's FMUs (the set `sblsim ssp export` packs, into --out, which is "
                        "required) with its parameters as their start values and compiled-in defaults: a host that "
                        "sets nothing runs the scenario (docs/interop.md)")
    b.add_argument("--seed", type=int, default=None, help="with --scenario: the campaign seed (default: the "
                   "configuration's, 0)")
    b.add_argument("--receiver", default=None,
                   help="with --scenario: ekf, ekf-seq, ukf, lsq or model:PATH.py (default: the scenario's)")
    b.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="with --scenario: override a configuration key (repeatable)")
    fsub.add_parser("variables", help="print every FMU's variables as Markdown tables (from the declarations)")
    v = fsub.add_parser("validate", help="validate the FMUs with fmpy")
    v.add_argument("dir", type=Path, nargs="?", default=None, help=f"directory of the FMUs (default {DEFAULT_DIR})")
    v.add_argument("--beacons", type=int, default=4, metavar="N",
                   help="validate the FMUs built for N beacons (default 4: the folder beacons<N> for others)")
    v.add_argument("--system", choices=_OWNERS, default=_OWNERS[0],
                   help=f"{_FIXED}: validate that system's interfaces' FMUs (its folder)")
    g = sub.add_parser("codegen", help="write embeddable C code of a component (no FMI, no Python)")
    gsub = g.add_subparsers(dest="codegen_command", required=True, parser_class=_Parser)
    r = gsub.add_parser("receiver", help="the receiver's C source, header and an example main.c")
    r.add_argument("--receiver", default="ekf", help="built-in receiver: ekf (default), ekf-seq, ukf or lsq")
    r.add_argument("--system", default=next(iter(SYSTEMS)), choices=tuple(SYSTEMS),
                   help=f"the positioning system whose packets the receiver takes (default {next(iter(SYSTEMS))}): "
                        + "; ".join(f"{s.name}: {s.title}" for s in SYSTEMS.values()))
    r.add_argument("--out", type=Path, required=True, help="directory to write (created; must be empty or new)")
    return p


def _check_seed(seed: int | None) -> None:
    if seed is not None and not 0 <= seed <= 2**31 - 1:
        raise ModelError(f"--seed: {shown(seed)} is outside the allowed range [0, 2147483647]")


def _run(args: argparse.Namespace) -> int:
    from sblsim.orchestrator.cosim.run import write_run

    _check_seed(args.seed)
    if (args.scenario is None) == (args.ssp is None):
        raise ModelError("run: give either a scenario (or CONFIG.toml) or --ssp FILE.ssp")
    overrides = args.overrides + ([f"simulation.master={args.master}"] if args.master else [])
    system = None
    if args.ssp is not None:
        engine = args.engine or "fmu"
        system = read_ssp(args.ssp, overrides, args.seed)
        plan = system.config
    else:
        engine = args.engine or "local"
        plan = api._plan(args.scenario, args.seed, overrides)  # the run's one resolution
    if args.export_log is not None:
        from sblsim.orchestrator.replay import check_export

        check_export(args.export_log, args.force)
        _check_writable(args.export_log.parent if str(args.export_log.parent) else Path("."), "--export-log")
    out = _output(args.out, Path("results") / folder_name(plan.scenario), args.force, "summary.json",
                  "run", before=lambda out: _check_export_apart(args.export_log, out))
    if system is None:
        result = api.run(plan, engine=engine, fmu_dir=args.fmu_dir, progress="auto")
    else:  # the package's connections and, on the fmu engine, its FMUs
        result = api._run_result(api._simulate(plan, engine, fmu_dir=args.fmu_dir, progress="auto", ssp=system))
    write_run(result._result, out)
    s = result.summary
    print(f"{s['scenario']} on the {s['engine']} engine ({plan.master}, receiver {s['receiver']}), "
          f"seed {s['seed']}: {s['steps']} steps in {s['wall_time']:.2f} s")
    _print_metrics(s)
    if s["diverged"]:
        print(f"sblsim: warning: the {s['receiver']} receiver diverged (an estimate more than "
              f"{DIVERGENCE_DISTANCE:g} m and {DIVERGENCE_RATIO:g} times the diver's distance from the platform "
              f"off the truth, or {DIVERGENCE_REJECTIONS} received packets in a row its gate rejected): its numbers "
              "mean nothing; see error_bounds.png", file=sys.stderr)
    for line in _run_warnings(s, plan):
        print(f"sblsim: warning: {line}", file=sys.stderr)
    print(f"  written to {out}/ (summary.json, config.toml, timeseries.parquet, figures)")
    if args.export_log is not None:
        from sblsim.orchestrator.replay import export_log

        try:
            log, truth = export_log(result._result, args.export_log)
        except ModelError as exc:  # e.g. a full disk: the run's own files are written, say so
            raise ModelError(f"{exc}; the run's results were written to {out}/") from None
        print(f"  log of the receiver's inputs: {log} (replay it: sblsim replay {log} --truth {truth})")
    return 0


#: The files ``sblsim run`` writes into its output folder that an ``--export-log`` file could replace.
RUN_FILES = ("summary.json", "config.toml", "timeseries.parquet")


def _check_export_apart(export: Path | None, out: Path) -> None:
    """Refuse an ``--export-log`` file (or its truth track) that is one of the run's own files in ``out``.

    Raises
    ------
    ModelError
        Naming ``--export-log`` and the file.
    """
    if export is None:
        return
    from sblsim.orchestrator.replay import truth_path

    folder = out.resolve()
    for target in (export, truth_path(export)):
        if target.resolve().parent == folder and target.name.lower() in RUN_FILES:
            raise ModelError(f"--export-log: {str(target)!r} is the run's own {target.name} in --out {str(out)!r}; "
                             "give the log another name or folder")


def _print_metrics(s: dict, truth: bool = True) -> None:
    """The metric lines of ``run`` and ``replay`` from a summary (``n/a`` for a metric without a value)."""
    def v(key: str, spec: str = ".3f", scale: float = 1.0) -> str:
        return "n/a" if s[key] is None else format(scale * s[key], spec)

    label = f"{s['receiver']}:"
    width = max(len(label), len("instrumentation:")) + 1
    if truth:
        print(f"  {label:<{width}}e_tot mean {v('e_tot_mean')} m, RMS {v('e_tot_rms')} m, std {v('e_tot_std')} m")
        print(f"  {'instrumentation:':<{width}}e_tot mean {v('instr_e_tot_mean')} m, "
              f"RMS {v('instr_e_tot_rms')} m, std {v('instr_e_tot_std')} m")
        print(f"  {'consistency:':<{width}}NEES {v('nees_mean', '.2f')} (3 if consistent), truth inside the 95 % "
              f"ellipsoid {v('coverage_95', '.1f', 100)} % of steps, mean NIS {v('nis_mean', '.2f')}, "
              f"gated {v('gated_pct', '.1f')} % of ranges")
        print(f"  {'accuracy limit:':<{width}}PCRB RMS {v('pcrb_rms')} m")
    else:
        print(f"  {label:<{width}}no truth track (--truth FILE for errors and consistency): {s['updates']} "
              f"updates, {s['fix_steps']} steps with a multilateration fix, mean NIS {v('nis_mean', '.2f')}, "
              f"gated {v('gated_pct', '.1f')} % of ranges")


def _replay(args: argparse.Namespace) -> int:
    from sblsim.orchestrator.replay import replay_config

    notes: list[str] = []
    plan, source = replay_config(args.log, args.config, args.receiver, args.overrides, notes)
    receiver = plan.receiver
    if external_path(receiver, MODEL_PREFIX) or external_path(receiver):
        given = "--receiver" if args.receiver else "--set" if any("receiver=" in o for o in args.overrides) \
            else "--config"
        notes.append(f"the receiver is your own program, {receiver} ({given}): it runs as you")

    def prepare() -> Path:  # after the log and truth track are read, before the replay
        out = _output(args.out, Path("results") / f"replay_{folder_name(args.log.stem)}", args.force,
                      "summary.json", "replay")
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
        return out

    result = api._replay_plan(plan, source, args.log, args.truth, args.engine, args.fmu_dir, prepare)
    out, truth = result.out, args.truth
    s, c = result.summary, result.summary["log"]
    sim = plan["simulation"]
    print(f"replay of {args.log} on the {s['engine']} engine (receiver {s['receiver']}, configuration {source}): "
          f"{s['steps']} steps of {sim['sampling_time']:g} s from {s['start_time']:.10g} s in {s['wall_time']:.2f} s")
    skipped = c["duplicate"] + c["unknown_beacon"] + c["same_step"] + c["not_reached"]
    print(f"  log: {c['rows']} rows, {c['used']} used ({c['depth_only']} depth readings only), {skipped} skipped "
          f"({c['duplicate']} duplicated, {c['unknown_beacon']} with an unknown beacon id, {c['same_step']} in a step "
          f"that used another row" + (f", {c['not_reached']} after the last step" if c["not_reached"] else "")
          + f"), {c['out_of_order']} out of order (sorted); rows every {c['typical_gap_s']:.6g} s (median), the "
          f"longest gap {c['longest_gap_s']:.6g} s"
          + (f" (before its {c['longest_gap_before']})" if c["longest_gap_s"] > 1.5 * c["typical_gap_s"] else "")
          + (f"; ignored columns: {', '.join(c['ignored_columns'])}" if c["ignored_columns"] else ""))
    if truth is not None:
        t = s["truth"]
        print(f"  truth: {args.truth}, interpolated at {t['steps']} of {s['steps']} steps"
              + (f" ({t['steps_without']} outside its span: no errors there)" if t["steps_without"] else ""))
    _print_metrics(s, truth is not None)
    if c["same_step"]:
        print(f"sblsim: warning: {c['same_step']} rows of the log fell in a step whose other row was used (one row "
              f"per step of {sim['sampling_time'] / sim['ekf_rate_ratio']:g} s): a smaller simulation.sampling_time "
              "or a larger simulation.ekf_rate_ratio (--set) uses them", file=sys.stderr)
    if truth is not None and s["diverged"]:
        print(f"sblsim: warning: the {s['receiver']} receiver diverged: its numbers mean nothing; see "
              "error_bounds.png", file=sys.stderr)
    if s["updates"] == 0:
        print(f"sblsim: warning: the {s['receiver']} receiver never made a fix: no row of the log brought a range "
              "it used", file=sys.stderr)
    print(f"  written to {out}/ (summary.json, config.toml, timeseries.parquet, figures)")
    return 0


def _run_warnings(s: dict, plan) -> list[str]:
    """What a run's numbers do not say by themselves: a receiver that never made a fix, exchanges heard into the
    next slot, and a diver beyond what the geometry serves (:func:`sblsim.orchestrator.cosim.metrics.run_flags`)."""
    out = []
    if s["updates"] == 0:
        out.append(f"the {s['receiver']} receiver never made a fix: no slot of the run brought a range it used "
                   "(every packet lost or gated); its numbers measure its starting guess (receiver.x0_*) and what "
                   "its motion model predicts from it (summary.json: updates = 0)")
    elif s["fix_steps"] == 0 and plan.latency_steps > 0:
        # the record shows what the diver sees: the receiver's outputs receiver.latency late
        latency = f"receiver.latency = {plan['receiver']['latency']:g} s"
        if plan.latency_steps >= s["steps"]:
            what = (f"{latency} is as long as the run: the diver never sees an output the receiver computed from a "
                    f"packet (every recorded estimate is its starting guess), though it used {s['updates']} ranges")
        else:
            what = (f"no multilateration fix reached the diver within the run (none was made, or {latency} delayed "
                    "every one past its end)")
        out.append(f"{what}; the instr_ metrics have no value (summary.json: fix_steps = 0 counts the steps the "
                   "diver saw a fix)")
    elif s["fix_steps"] == 0:
        out.append("no multilateration fix was ever made (never ranges of three beacons): the instr_ metrics have "
                   "no value, and a receiver that reports that fix (lsq) never left its starting guess "
                   "(summary.json: fix_steps = 0)")
    if s.get("slot_overrun"):
        out.append(f"an exchange was still heard {s['slot_overrun']:.4g} s after its slot began (its last arrival, "
                   f"multipath included), beyond simulation.sampling_time = {plan.sampling_time:g} s: the next "
                   "slot's packet overlaps it, which the channel does not model; give a sampling time of at least "
                   f"{s['slot_overrun']:.4g} s (summary.json: slot_overrun)")
    if s["beyond_geometry"]:
        spread = plan.horizontal_spread
        ratio = f"{s['max_distance'] / spread:.0f} times" if spread > 0 else "infinitely many times"
        bound = "n/a" if s["pcrb_rms"] is None else f"{s['pcrb_rms']:.3f}"
        out.append(f"the diver went {s['max_distance']:.6g} m from the platform, {ratio} the beacons' horizontal "
                   f"spread ({spread:.4g} m; the geometry serves up to {REACH_RATIO:g} times): the errors are the "
                   f"system's real accuracy there (PCRB RMS {bound} m), not a divergence "
                   "(summary.json: beyond_geometry)")
    return out


def _ssp(args: argparse.Namespace) -> int:
    _check_seed(args.seed)
    cfg = api._plan(args.scenario, args.seed, args.overrides)  # the export's one resolution
    _check_writable(args.out.parent if str(args.out.parent) else Path("."))
    if args.out.is_dir():
        raise ModelError(f"--out: {str(args.out)!r} is a directory; give the .ssp file to write")
    if args.out.exists() and not args.force:
        raise ModelError(f"--out: {str(args.out)!r} exists; add --force to replace it or choose another file")
    path = export_ssp(cfg, args.out, args.fmu_dir)
    print(f"wrote {path} ({cfg['run']['scenario']}, seed {cfg['run']['seed']}, receiver "
          f"{cfg['simulation']['receiver']}); it validates against the SSP 1.0 schemas")
    return 0


def _output_name(scenario: str) -> str:
    """The name a default output folder takes from a scenario argument: a file's stem, a built-in's name (any
    character that is not a plain file-name character replaced: :func:`sblsim.orchestrator.io.output.folder_name`)."""
    return folder_name(Path(scenario).stem if scenario.endswith(".toml") else Path(scenario).name)


def _calibrate(args: argparse.Namespace) -> int:
    result = api._calibrate(
        args.survey, args.format, args.overrides, args.initcfg, args.svp, args.replicates, "auto",
        lambda name: _output(args.out, Path("results") / f"calibrate_{folder_name(name)}", args.force,
                             "solution.json", "calibration"), lambda name: f"--{name}")
    s, out = result.solution, result.out
    if "simulation" in s:
        return _simulated_lines(result)
    for note in result.notes:  # after the write: a write that fails says one line
        print(f"note: {note}", file=sys.stderr)
    _calibration_warnings(result)
    print(f"calibration of {result.name} ({s['format']} log, {s['log']['rows']} replies, "
          f"{result.segments} segment(s), {result.sound_speed})")
    for t in s["transponders"]:
        own = f", {t['sound_speed_mps']:.3f} m/s" if "sound_speed_mps" in t else ""
        print(f"  transponder {t['id']}: N {t['n_m']:+.4f} E {t['e_m']:+.4f} U {t['u_m']:+.4f} m from the a-priori "
              f"(sigma {t['sigma_n_m']:.4f} {t['sigma_e_m']:.4f} {t['sigma_u_m']:.4f} m{own})")
    if "perturbation" in s:
        d = s["array_displacement"]
        print(f"  array displacement: E {d['e_m']:+.6f} N {d['n_m']:+.6f} U {d['u_m']:+.6f} m (sigma "
              f"{d['sigma_e_m'] * 1e3:.2f} {d['sigma_n_m'] * 1e3:.2f} {d['sigma_u_m'] * 1e3:.2f} mm; realistic x"
              f"{s['realistic_sigma_scale']:.2f})")
        criteria = ", ".join(f"{k.upper()} {s[k]:.2f}" for k in ("aic", "bic", "abic") if s[k] is not None)
        grad = f"; deep gradient E {s['gradient']['e']:.6g} N {s['gradient']['n']:.6g}" if s["gradient"] else ""
        print(f"  perturbation {s['perturbation']['kind']}: {s['n_bases']} bases, {criteria}{grad}")
    print(f"  {s['pings_used']} pings used, {s['pings_rejected']} rejected; TWTT residual RMS "
          f"{s['twtt_residual_rms_s'] * 1e6:.2f} us")
    if "running" in s:
        print(f"  running solution (Kalman form, running.csv): {s['running']['replies']} replies, mean NIS "
              f"{s['running']['nis_mean']:.2f}")
    extra = ", ntd.csv" if result.ntd is not None else ""
    extra += ", criterion.csv" if result.search is not None else ""
    print(f"  written to {out}/ (solution.json, residuals.csv{extra}, figures)")
    return 0


def _calibration_warnings(result) -> None:
    for warning in result.warnings:
        print(f"sblsim: warning: {warning}", file=sys.stderr)


def _simulated_lines(result) -> int:
    """``sblsim calibrate`` of a simulated survey: replicate 0 against the truth, the replicates, the survey
    error an LBL design takes."""
    _calibration_warnings(result)
    s, table = result.solution, result.replicates
    survey = s["simulation"]["survey"]
    t, e, truth = s["transponders"][0], s["errors"][0], s["truth"][0]
    print(f"simulated calibration {result.name}: {survey['pattern']} of {survey['radius_m']:g} m around a "
          f"transponder {survey['depth_m']:g} m deep, {s['log']['rows']} replies, seed {survey['seed']}")
    print(f"  replicate 0: error N {e['e_n_m']:+.4f} E {e['e_e_m']:+.4f} U {e['e_u_m']:+.4f} m against the truth "
          f"(N {truth['n_m']:+.3f} E {truth['e_m']:+.3f} U {truth['u_m']:+.3f} m); sigma {t['sigma_n_m']:.4f} "
          f"{t['sigma_e_m']:.4f} {t['sigma_u_m']:.4f} m; horizontal bound (CRB) {e['pcrb_h_m']:.4f} m")
    if table is not None:
        r = s["replicates"]
        print(f"  {r['count']} replicates: horizontal RMS error {r['rms_h_m']:.4f} m, bound {r['pcrb_h_m']:.4f} m "
              f"(ratio {r['rms_h_m'] / r['pcrb_h_m']:.3f}); RMS N {r['rms_n_m']:.4f} E {r['rms_e_m']:.4f} "
              f"U {r['rms_u_m']:.4f} m; mean NEES {r['nees_mean']:.2f} (3 when consistent)")
    print(f"  survey error for an LBL design ({s['survey_sigma_from']}): --set {s['lbl_set']}")
    files = "solution.json, residuals.csv, survey_log.csv" + (", replicates.parquet" if table is not None else "")
    print(f"  written to {result.out}/ ({files}, figures)")
    return 0


def _compare(args: argparse.Namespace) -> int:
    from sblsim.orchestrator.compare import markdown, parse_receivers, write

    _check_seed(args.seed)
    receivers = parse_receivers(args.receivers)
    systems = parse_systems(args.systems) if args.systems is not None else None
    if systems is not None:
        system_overrides(systems[0], args.overrides)  # refuses a --set platform.system before any work
    out = _output(args.out, Path("results") / f"compare_{_output_name(args.scenario)}", args.force, "compare.csv",
                  "comparison")
    result = api.compare(args.scenario, receivers=receivers, systems=systems, replicates=args.replicates,
                         seed=args.seed, set=args.overrides, engine=args.engine, fmu_dir=args.fmu_dir,
                         progress="auto")
    print(result.title)
    if result.note:
        print(result.note)
    print(markdown(result.table), end="")
    write(result.table, out, result.title, result.note)
    print(f"written to {out}/ (compare.csv, compare.md, compare.png)")
    return 0


def _budget(args: argparse.Namespace) -> int:
    from sblsim.orchestrator.budget import DEFAULT_REPLICATES, check_replicates, write

    _check_seed(args.seed)
    replicates = DEFAULT_REPLICATES if args.replicates is None else args.replicates
    check_replicates(replicates)
    compare = parse_compare(args.compare, f"platform.system={_ALL_SYSTEMS}") if args.compare else None
    if args.receiver is not None:
        check_receiver(args.receiver, "--receiver")
    target: list[Path] = []

    def prepare() -> None:  # after every configuration is checked (resolved once), before any run
        target.append(_output(args.out, Path("results") / f"budget_{_output_name(args.scenario)}", args.force,
                              "budget.csv", "budget"))

    result = api._budget(args.scenario, list(args.overrides), args.seed, args.receiver, compare, replicates,
                         "auto", prepare)
    out = target[0]
    results, heading = result.budgets, result.title
    print(heading)
    print("\n".join(result.lines()))
    for b in results:
        if b.diverged:
            print(f"sblsim: warning: the receiver diverged in {b.diverged} of {b.runs} runs of {b.label}: the budget "
                  "means nothing", file=sys.stderr)
    write(results, out, heading, compare[0] if compare else None)
    print(f"{sum(b.runs for b in results)} runs in {sum(b.wall_time for b in results):.1f} s; written to {out}/ "
          "(budget.csv, budget.md, budget.png, config.toml)")
    return 0


def _map(args: argparse.Namespace) -> int:
    from sblsim.orchestrator.maps import diver_depth, grid, parse_levels, write

    _check_seed(args.seed)
    levels = parse_levels(args.levels)
    compare = parse_compare(args.compare) if args.compare else None
    out = _output(args.out, Path("results") / f"map_{_output_name(args.scenario)}", args.force, "map.csv", "map",
                  before=lambda _: grid(args.extent, args.step))
    result = api._accuracy_map(args.scenario, list(args.overrides), args.seed, args.extent, args.step, levels, compare,
                               args.depth, "auto", lambda: None, ("--extent", "--step", "--depth"))
    labels, configs, east, north, maps = result.labels, result.configs, result.east, result.north, result.maps
    depth = configs[0]["target"]["depth"]
    where = "--depth" if args.depth is not None else diver_depth(configs[0])[1]  # (compared systems' defaults)
    print(f"maps at {depth:g} m depth ({where}; --depth D to choose)")
    for label, m in zip(labels, maps):
        cells = m.size
        shares = ", ".join(f"{100 * float((m <= v).sum()) / cells:.0f} % within {v:g} m" for v in levels)
        print(f"{label}: horizontal DRMS {np.nanmin(m):.3f} … {np.nanmax(m[np.isfinite(m)]):.3f} m over "
              f"±{args.extent:g} m; {shares}")
    write(labels, configs, east, north, maps, levels, out, compare)
    print(f"written to {out}/ (map.csv, map.png)")
    return 0


def _campaign(args: argparse.Namespace) -> int:
    from sblsim.orchestrator.campaign import CampaignInterrupted

    study = load_study(args.study, seed=args.seed)
    out = args.out or Path("results") / folder_name(study.name)
    _check_writable(out)
    workers = args.workers if args.workers is not None else os.cpu_count()
    where = f"Dask scheduler {args.scheduler}" if args.scheduler else f"{workers} worker process(es)"
    print(f"{study.name}: {len(study.scenarios)} scenarios x {study.cells} cells x {study.replicates} replicates "
          f"= {study.runs} runs on the {args.engine} engine, {where}")
    try:
        result = api.campaign(study, out, workers=args.workers, scheduler=args.scheduler, resume=args.resume,
                              engine=args.engine, batch=args.batch, fmu_dir=args.fmu_dir,
                              save_timeseries=args.save_timeseries, progress="auto")
    except CampaignInterrupted as exc:
        print(f"sblsim: {exc}", file=sys.stderr)
        return _interrupted_status()
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
        return _analyze_dir(out)
    return 0


def _analyze_dir(directory: Path, out: Path | None = None, metric: str = "e_tot_rms", order: int = 2,
                 transform: str = "none") -> int:
    from sblsim.orchestrator.analysis import compute, write

    _check_writable(out or directory)
    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    analysis = compute(directory, metric, order, progress=say, transform=transform)
    for note in analysis.warnings:
        print(f"note: {note}", file=sys.stderr)
    target = write(analysis, out or directory, progress=say)
    for scenario, result in analysis.fits.items():
        effects = result.effects
        significant = effects[effects["p_value"] < analysis.alpha].sort_values("t", key=abs, ascending=False)
        if "ratio" in significant.columns:  # log: the factor by which each term multiplies the metric
            names = [f"{t} (x{r:.3g})" for t, r in zip(significant["term"].head(5), significant["ratio"].head(5))]
        else:
            names = list(significant["term"].head(5))
        print(f"{scenario}: significant terms, largest first: {', '.join(names) or 'none'}")
        if result.lmbda is not None:
            low, high = result.lmbda_ci
            print(f"{scenario}: Box-Cox lambda = {result.lmbda:.3g} (95 % CI {low:.3g} to {high:.3g})")
    print(f"analysis written to {target}/ (report.html, report.md, effects.csv, diagnostics.csv, anova.csv, "
          "tables.csv, figures)")
    return 0


def _fmus(args: argparse.Namespace) -> int:
    n_beacons = getattr(args, "beacons", 4)
    if not MIN_BEACONS <= n_beacons <= MAX_BEACONS:
        raise ModelError(f"--beacons: {n_beacons} is outside the allowed range [{MIN_BEACONS}, {MAX_BEACONS}]")
    system = SYSTEMS[getattr(args, "system", _OWNERS[0])]
    if system.interface_beacons is not None:  # a system of a fixed interface (USBL's one transceiver)
        if n_beacons != 4:
            raise ModelError(f"--beacons: {n_beacons} with --system {system.name}, whose interface has "
                             f"{system.interface_beacons}")
        n_beacons = system.interface_beacons
    if args.fmus_command == "variables":
        print(markdown_tables())
        return 0
    if args.fmus_command == "build":
        def say(line: str) -> None:  # each target's binary takes seconds (cross: a minute): progress lines
            print(f"sblsim: {line}", file=sys.stderr, flush=True)

        if args.scenario is not None:
            return _scenario_fmus(args, say)
        for option, given in (("--seed", args.seed is not None), ("--receiver", args.receiver is not None),
                              ("--set", bool(args.overrides))):
            if given:
                raise ModelError(f"{option}: only with --scenario NAME|CONFIG.toml (the scenario's FMUs)")
        out = beacons_dir(args.out or DEFAULT_DIR, n_beacons)
        _check_writable(out)
        if args.model is not None:
            check_receiver(f"{MODEL_PREFIX}{args.model}", "--model")
            model = user_model(args.model)
            print(f"built {build_fmu(model, out, n_beacons, compiler=args.compiler, cross=args.cross, report=say)}",
                  flush=True)
            return 0
        for name in MODELS:
            print(f"built {build_fmu(name, out, n_beacons, compiler=args.compiler, cross=args.cross, report=say)}",
                  flush=True)
        return 0
    directory = beacons_dir(args.dir or DEFAULT_DIR, n_beacons)
    failures = 0
    for name in MODELS:
        path = fmu_path(directory, name)
        if not path.is_file():
            raise ModelError(f"fmus validate: {name} FMU not found at {str(path)!r}; run `sblsim fmus build`")
        problems = validate(path)
        failures += bool(problems)
        print(f"{path}: {len(problems)} problems")
        for problem in problems:
            print(f"  {problem}")
    return 1 if failures else 0


def _scenario_fmus(args: argparse.Namespace, say: Callable[[str], None]) -> int:
    """``sblsim fmus build --scenario``: the scenario's FMUs, its parameters as their defaults."""
    for option, given in (("--model", args.model is not None), ("--beacons", args.beacons != 4),
                          ("--system", args.system != _OWNERS[0])):
        if given:
            raise ModelError(f"{option}: not with --scenario, whose configuration sets the system, beacons and "
                             "receiver (--receiver NAME)")
    if args.out is None:
        raise ModelError("--out: give the folder for the scenario's FMUs (--scenario needs --out DIR)")
    _check_seed(args.seed)
    overrides = list(args.overrides)
    if args.receiver is not None:
        check_receiver(args.receiver, "--receiver")
        if external_path(args.receiver):
            raise ModelError(f"--receiver: {args.receiver!r} is an FMU; a scenario is built into the FMUs sblsim "
                             "generates: ekf, ekf-seq, ukf, lsq or model:PATH.py")
        overrides.append(f"receiver={args.receiver}")
    plan = api._plan(args.scenario, args.seed, overrides)
    _check_writable(args.out)
    for path in build_scenario_fmus(plan, args.out, args.compiler, args.cross, report=say):
        print(f"built {path}", flush=True)
    print(f"the FMUs' start values are {plan.scenario}'s (seed {plan.seed}, receiver {plan.receiver}); a host "
          f"that sets nothing runs it for {plan.duration:g} s in steps of "
          f"{plan.sampling_time / plan.ekf_rate_ratio:g} s")
    return 0


def _output(given: Path | None, default: Path, force: bool, marker: str, what: str,
            before: Callable[[Path], None] | None = None) -> Path:
    """The output folder of a command: ``--out`` as given, or the default folder.

    An earlier result is never replaced silently. A folder given with ``--out`` that holds one (its
    ``marker`` file) needs ``--force``; the default folder, when it holds one, is kept and the next free
    numbered folder beside it is used (``results/semicircle-2``), said on the command line, so that the
    documented commands run one after the other. Checked before any work (:func:`_check_output`, then
    ``before(out)``). The folder is then locked until the command ends
    (:class:`sblsim.orchestrator.io.output.OutputLock`): a second command into it meanwhile is refused.
    """
    if given is not None or force or not (default / marker).exists():
        out = given or default
    else:
        out = next(default.with_name(f"{default.name}-{k}") for k in range(2, 1_000_000)
                   if not (default.with_name(f"{default.name}-{k}") / marker).exists())
        print(f"note: {default}/ holds an earlier {what} (kept); writing to {out}/ (--out DIR to choose, --force "
              "to replace)", file=sys.stderr)
    _check_output(out, force, marker, what)
    if before is not None:
        before(out)
    _LOCKS.append(OutputLock(out).acquire())
    return out


def _check_output(out: Path, force: bool, marker: str, what: str) -> None:
    """:func:`sblsim.orchestrator.io.output.check_output` naming ``--out``."""
    check_output(out, force, marker, what)


def _check_writable(directory: Path, option: str = "--out") -> None:
    """:func:`sblsim.orchestrator.io.output.check_writable` naming ``option``."""
    check_writable(directory, option)


def _codegen(args: argparse.Namespace) -> int:
    from sblsim.orchestrator.codegen import example_files

    _check_writable(args.out)
    if args.receiver not in RECEIVERS:
        raise ModelError(f"--receiver: {args.receiver!r} is not one of {', '.join(RECEIVERS)}")
    example, about, n_beacons = example_files(args.receiver, args.system)
    files = write_receiver(args.receiver, args.out, n_beacons, example=example, about=about)
    print(f"wrote {len(files)} files to {args.out}/ ({', '.join(p.name for p in files)}); see its README.md")
    return 0


_SIGNAL: list[int] = []
#: The output folders this command holds locked (released when it ends).
_LOCKS: list[OutputLock] = []


class _PipeSafeStream:
    """Standard output that a closed pipe does not stop (``sblsim run ... | head -1``).

    When the reader goes away, the first write or flush that fails with :class:`BrokenPipeError` points the
    stream's file descriptor at ``os.devnull`` (as Python's documentation of SIGPIPE recommends, so that
    nothing fails again at exit) and drops the rest: the command finishes its work (every result written)
    and exits with its own status, without an error about a pipe nobody reads.
    """

    def __init__(self, stream) -> None:
        self._stream = stream
        self.broken = False

    def _closed_pipe(self) -> None:
        self.broken = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, AttributeError):  # a stream without a descriptor (a test's capture)
            pass

    def write(self, text: str) -> int:
        if self.broken:
            return len(text)
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._closed_pipe()
            return len(text)

    def flush(self) -> None:
        if self.broken:
            return
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._closed_pipe()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _terminate(signum: int, frame) -> None:
    """SIGTERM or SIGHUP: stop as Ctrl-C does (finished work is kept, the same message), exit 128 + signal."""
    _SIGNAL.append(signum)
    raise KeyboardInterrupt


def _interrupted_status() -> int:
    return 128 + _SIGNAL[-1] if _SIGNAL else EXIT_INTERRUPTED


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``sblsim`` console script."""
    args = _parser().parse_args(argv)
    _SIGNAL.clear()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for name in ("SIGTERM", "SIGHUP"):
            if hasattr(signal, name):
                previous[name] = signal.signal(getattr(signal, name), _terminate)
    stdout = sys.stdout
    sys.stdout = _PipeSafeStream(stdout)
    try:
        status = _command(args)
        sys.stdout.flush()
        return status
    finally:
        sys.stdout = stdout
        for name, handler in previous.items():
            signal.signal(getattr(signal, name), handler)


def _command(args: argparse.Namespace) -> int:
    try:
        if args.command == "run":
            return _run(args)
        if args.command == "replay":
            return _replay(args)
        if args.command == "campaign":
            return _campaign(args)
        if args.command == "calibrate":
            return _calibrate(args)
        if args.command == "compare":
            return _compare(args)
        if args.command == "budget":
            return _budget(args)
        if args.command == "map":
            return _map(args)
        if args.command == "ssp":
            return _ssp(args)
        if args.command == "analyze":
            return _analyze_dir(args.dir, args.out, args.metric, args.order, args.transform)
        if args.command == "codegen":
            return _codegen(args)
        return _fmus(args)
    except SblsimError as exc:  # every kind of sblsim's errors (sblsim.models.errors): one line, exit 2
        print(f"sblsim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # a full disk or a folder that refused a write during the work: one line, no traceback
        reason = os.strerror(exc.errno) if exc.errno else str(exc)
        where = f": {exc.filename}" if exc.filename else ""
        resume = (" (a campaign keeps its finished chunks: run it again with --resume)" if args.command == "campaign"
                  else "")
        print(f"sblsim: error: {reason}{where}; nothing in the output folder was replaced{resume}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("sblsim: interrupted", file=sys.stderr)
        return _interrupted_status()
    finally:
        while _LOCKS:
            _LOCKS.pop().release()


if __name__ == "__main__":
    sys.exit(main())
