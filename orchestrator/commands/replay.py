"""``sblsim replay`` and ``sblsim.replay``: a receiver on a recorded log (docs/log-format.md), with its errors and
consistency against a truth track when one is given (:mod:`sblsim.orchestrator.logs.replay`).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from sblsim.models.errors import ConfigError
from sblsim.orchestrator.commands.common import (
    Overrides,
    add_water_arguments,
    check_engine,
    override_items,
)
from sblsim.orchestrator.commands.console import FMU_DIR_HELP, output_folder, print_metrics
from sblsim.orchestrator.cosim.config import MODEL_PREFIX, external_path
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.io.arguments import path_argument, prepare_out, real_argument, text_argument
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.logs.replay_result import ReplayResult, _replay_plan
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.tracks.format_options import refuse_toa_only, toa_arguments
from sblsim.orchestrator.tracks.many import tag_files, track_tags
from sblsim.orchestrator.tracks.options import PING_TYPE_NAMES, check_depth_sigma
from sblsim.orchestrator.tracks.outputs import write
from sblsim.orchestrator.tracks.replay import check_positioned
from sblsim.orchestrator.tracks.report import tag_line, tags_line, track_lines
from sblsim.orchestrator.tracks.track import MOTIONS, track


def replay(log: str | Path, *, receiver: str | None = None, config: str | Path | None = None,
           truth: str | Path | None = None, engine: str = "local", set: Overrides = None,
           fmu_dir: str | Path | None = None, out: str | Path | None = None, force: bool = False) -> ReplayResult:
    """Run a receiver on a recorded log: ``sblsim replay``.

    Parameters
    ----------
    log : str or Path
        The log, ``.csv`` or ``.parquet`` (the log-format page; ``sblsim run --export-log`` writes one).
    receiver : str, optional
        ``ekf``, ``ekf-seq``, ``ukf``, ``lsq``, ``model:PATH.py`` or ``fmu:PATH`` (default the
        configuration's).
    config : str or Path, optional
        The receiver's parameters, T and rate ratio: a built-in scenario or ``CONFIG.toml`` (default the
        configuration an exported log carries, else the semicircle scenario's).
    truth : str or Path, optional
        Truth track (``time_s``, ``n_m``, ``e_m``, ``d_m``): errors, consistency and figures.
    engine, set, fmu_dir
        As for :func:`run`.
    out : str or Path, optional
        Write ``summary.json``, ``config.toml``, ``timeseries.parquet`` and the figures there.
    force : bool
        Replace an earlier replay in ``out``.

    Returns
    -------
    ReplayResult

    Raises
    ------
    ConfigError, SblsimError
        A log or truth track that cannot be read (the message names the row and column), bad options.
    """
    from sblsim.orchestrator.logs.configuration import replay_config

    check_engine(engine)
    log = path_argument(log, "log", optional=False)
    truth = path_argument(truth, "truth")
    fmu_dir = path_argument(fmu_dir, "fmu_dir")
    receiver = text_argument(receiver, "receiver")
    config = None if config is None else str(path_argument(config, "config"))
    prepare_out(out, force, "summary.json", "replay")  # before any work (and again once the log is read)
    plan, source = replay_config(log, config, receiver, override_items(set))
    return _replay_plan(plan, source, log, truth, engine, fmu_dir,
                        lambda: prepare_out(out, force, "summary.json", "replay"))


NAME = "replay"
HELP = "run a receiver on a recorded log (docs/log-format.md)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim replay``'s arguments."""
    p.add_argument("log", type=Path, help="the log: .csv or .parquet (sblsim run --export-log writes one); with "
                   "--format toa, the matrix of times of arrival (docs/tracking.md), or a folder of one per tag")
    p.add_argument("--format", choices=("log", "toa", "detections", *FORMATS),
                   default="log",
                   help="log: a receiver's log (default); toa: times of arrival of a pinger at a fixed array "
                        "(an inverted LBL), tracked by the single-ping fix, the EKF and (--smooth) the RTS and robust "
                        "smoothers; detections (the format read from the file's first line), "
                        f"{', '.join(FORMATS)}: raw detections, with --sync and --tag, made into the tag's times of "
                        "arrival as sblsim toa makes them, then tracked")
    p.add_argument("--sync", type=Path, default=None, metavar="DIR",
                   help="raw detections: the synchronisation's folder (sblsim sync --out DIR)")
    p.add_argument("--tag", default=None, metavar="ID", help="raw detections: the tag's full ID or id")
    p.add_argument("--receivers", type=Path, default=None, metavar="FILE",
                   help="--format toa: the receivers' positions (CSV name,x_m,y_m[,z_m][,status], or TOML)")
    p.add_argument("--reference", type=Path, default=None, metavar="FILE",
                   help="--format toa: another solution (x y t) scored beside against --truth")
    p.add_argument("--smooth", action="store_true",
                   help="--format toa: also the RTS and the robust smoother, the robust smoother's rows as the "
                        "track (default: the causal EKF's)")
    p.add_argument("--sound-speed", type=float, default=None, metavar="M_S",
                   help="--format toa: the sound speed [m/s] (default: calibrated from the pings)")
    p.add_argument("--receivers-kept", default=None, metavar="NAMES",
                   help="--format toa: use only these receivers (their names, separated by commas): a thinned array")
    p.add_argument("--drop-detections", type=float, default=None, metavar="SHARE",
                   help="--format toa: remove each detection with this probability in [0, 0.99] before tracking "
                        "(seeded by --seed)")
    p.add_argument("--seed", type=int, default=None,
                   help="--format toa: the seed of --drop-detections's draw (default 0)")
    p.add_argument("--receiver", default=None,
                   help="ekf, ekf-seq, ukf, lsq, model:PATH.py or fmu:PATH (default: the configuration's)")
    p.add_argument("--config", default=None, metavar="CONFIG",
                   help="the receiver's parameters, T and rate ratio: a built-in scenario or CONFIG.toml (default: "
                        "the configuration an exported log carries, else the semicircle scenario's)")
    p.add_argument("--ping-type", choices=PING_TYPE_NAMES, default=None,
                   help="--format toa: the tag's ping type: sbi (stable burst interval), rbi (random), pbi "
                        "(pseudo-random, --burst-sequence); default inferred from the first arrivals' spacing")
    p.add_argument("--burst-interval", default=None, metavar="MIN:MAX",
                   help="--format toa: a random burst interval's bounds [s], e.g. 20:40 (rbi)")
    p.add_argument("--burst-sequence", type=Path, default=None, metavar="FILE",
                   help="--format toa: a pseudo-random tag's intervals [s] in order, one per row (pbi)")
    p.add_argument("--force-interval", action="store_true",
                   help="take the stated --burst-interval or --burst-sequence where the detections contradict it as "
                        "a whole (refused otherwise); a warning says how much it sets aside")
    p.add_argument("--no-other-filters", dest="other_filters", action="store_false",
                   help="--format toa: without the sequential EKF and the UKF run beside for comparison (the track "
                        "and the EKF's, the smoothers' and the fixes' rows the same, in about half the time)")
    p.add_argument("--acceleration-psd", type=float, default=None, metavar="M2_S3",
                   help="--format toa: the motion model's white-noise acceleration [m²/s³] in (0, 1] (default: "
                        "estimated from the pings by EM)")
    p.add_argument("--sound-speed-file", type=Path, default=None, metavar="CSV",
                   help="--format toa: a measured sound-speed series (time_s, sound_speed_m_s under a header; the "
                        "times on the times of arrival's base)")
    p.add_argument("--temperature", type=float, default=None, metavar="C",
                   help="--format toa: the water's temperature [°C] for the fallback sound speed (TEOS-10) where the "
                        "pings cannot determine it (with --salinity; default fallback 1500 m/s)")
    p.add_argument("--salinity", type=float, default=None, metavar="S",
                   help="--format toa: the water's practical salinity (PSS-78) for the fallback or --temperature-file "
                        "(0 fresh water, about 35 the open sea)")
    add_water_arguments(p, "--format toa: ")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="--format toa with a folder of tags: worker processes in [1, 256] (default: the CPU count)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="--format toa with a folder of tags: a Dask scheduler (tcp://HOST:PORT, or local) whose "
                        "workers track the tags")
    p.add_argument("--tag-depth", type=float, default=None, metavar="M",
                   help="--format toa: the tag's depth [m] at every ping (a tag at a known depth; receivers with z_m), "
                        "where the times of arrival carry no depth_m column")
    p.add_argument("--depth-sigma", type=float, default=None, metavar="M",
                   help="--format toa: the standard deviation of a depth reading [m] in (0, 100] (default 0.3); "
                        "only with a depth (--tag-depth or a depth_m column)")
    p.add_argument("--survey-sigma", type=float, default=None, metavar="M",
                   help="--format toa: the receivers' survey error per axis [m] in [0, 1000], for those without a "
                        "sigma_m column, in the fix's and the smoother's covariances; raw detections: every "
                        "receiver's, in place of the one the synchronisation saw (0: the positions as exact)")
    p.add_argument("--motion", choices=MOTIONS, default=None,
                   help="--format toa: moving (default) or stationary (a sync or reference tag: one position for all "
                        "pings)")
    p.add_argument("--toa-sigma", type=float, default=None, metavar="S",
                   help="--format toa: the timing noise of every time of arrival [s] in [1e-6, 1] (default: each "
                        "receiver's toa_sigma_s in the receivers file, from a synchronisation's residuals; else "
                        "0.00015)")
    p.add_argument("--truth-sigma", type=float, default=None, metavar="M",
                   help="--format toa: the truth's own error per horizontal axis [m] in [0, 100] (GPS, lever arm), "
                        "in the NEES against it (default 0: the truth taken as exact)")
    p.add_argument("--crs", default=None, metavar="EPSG",
                   help="--format toa: the receivers file's CRS (lat,lon in a geographic one, WGS 84 by default; x_m,"
                        "y_m in a projected one): the outputs gain lat, lon")
    p.add_argument("--frame", default=None, metavar="EPSG",
                   help="--format toa: the metric frame lat, lon are projected to (default: the UTM zone of the "
                        "array's centre)")
    p.add_argument("--time-origin", default=None, metavar="UTC",
                   help="--format toa: the UTC time of the TOA file's zero (ISO 8601 or epoch seconds): the outputs "
                        "gain epoch_s and time_utc, and a truth or sound-speed series may be in UTC")
    p.add_argument("--truth", type=Path, default=None, metavar="FILE",
                   help="truth track (time_s, n_m, e_m, d_m; .csv or .parquet): errors, consistency, figures; with "
                        "--format toa: x y t [m, m, s] under a header (e.g. GPS)")
    p.add_argument("--engine", choices=ENGINES, default="local", help="component engine (default local)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/replay_LOGNAME)")
    p.add_argument("--force", action="store_true", help="replace an earlier replay in --out")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key, e.g. receiver.q_horizontal=0.05 (repeatable)")
    p.add_argument("--fmu-dir", type=Path, default=None, help=FMU_DIR_HELP)


def main(args: argparse.Namespace) -> int:
    """``sblsim replay`` from its parsed arguments: its lines printed, its exit status returned."""
    if args.format in ("detections", *FORMATS):  # raw detections: the tag's matrix
        # (sblsim toa), then tracked
        from sblsim.orchestrator.tracks.replay_detections import replay_matrix

        with replay_matrix(args) as toa_args:
            return _main_toa(toa_args)
    if args.sync is not None or args.tag is not None:
        raise ConfigError(f"{'--sync' if args.sync is not None else '--tag'}: only with --format detections, "
                          f"{', '.join(FORMATS)} (raw detections)")
    if args.format == "toa":
        return _main_toa(args)
    refuse_toa_only(args)
    from sblsim.orchestrator.logs.configuration import replay_config
    from sblsim.orchestrator.logs.replay import replay_lines

    notes: list[str] = []
    plan, source = replay_config(args.log, args.config, args.receiver, args.overrides, notes)
    receiver = plan.receiver
    if external_path(receiver, MODEL_PREFIX) or external_path(receiver):
        given = "--receiver" if args.receiver else "--set" if any("receiver=" in o for o in args.overrides) \
            else "--config"
        notes.append(f"the receiver is your own program, {receiver} ({given}): it runs as you")

    def prepare() -> Path:  # after the log and truth track are read, before the replay
        out = output_folder(args.out, Path("results") / f"replay_{folder_name(args.log.stem)}", args.force,
                      "summary.json", "replay")
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
        return out

    result = _replay_plan(plan, source, args.log, args.truth, args.engine, args.fmu_dir, prepare)
    lines, warnings = replay_lines(result.summary, plan, source, args.log, args.truth)
    print("\n".join(lines))
    print_metrics(result.summary, args.truth is not None)
    for warning in warnings:
        print(warning, file=sys.stderr)
    out = result.out
    print(f"  written to {out}/ (summary.json, config.toml, timeseries.parquet, figures)")
    return 0


def _main_tags(args: argparse.Namespace, options: dict[str, Any]) -> int:
    """``sblsim replay FOLDER --format toa``: each tag's line as it ends, then the table's summary."""
    given = [o for o, v in (("--truth", args.truth), ("--reference", args.reference)) if v]
    if given:
        raise ConfigError(f"{given[0]}: not with a folder of tags (one truth per tag: replay each tag's file)")
    workers = None if args.workers is None else int(real_argument(args.workers, "--workers", 1, 256, ""))
    scheduler = None
    if args.scheduler is not None:
        from sblsim.orchestrator.campaign.executors import check_address

        scheduler = check_address(args.scheduler)
    files = tag_files(args.log)
    out = output_folder(args.out, Path("results") / f"tags_{folder_name(args.log.name)}", args.force, "tags.csv",
                        "tags")

    def progress(row: dict[str, Any], count: int, total: int) -> None:
        line, warning = tag_line(row, count, total)
        print(line, file=sys.stderr if warning else sys.stdout, flush=True)

    where = f"on {scheduler}" if scheduler else f"in {workers or os.cpu_count() or 1} worker processes"
    print(f"tracking {len(files)} tags of {args.log} at {args.receivers} {where}", flush=True)
    done = track_tags(files, args.receivers, options, workers, scheduler, out, progress)
    print(tags_line(done.table, out))
    return 0


def _main_toa(args: argparse.Namespace) -> int:
    """``sblsim replay TOA_FILE --format toa``: the track's lines printed."""
    options = toa_arguments(args)
    if args.log.is_dir():
        return _main_tags(args, options)
    if args.workers is not None or args.scheduler is not None:
        raise ConfigError(f"{'--workers' if args.workers is not None else '--scheduler'}: only with a folder of tags "
                          "(one times-of-arrival file per tag, tracked in parallel)")
    check_depth_sigma(args.log, args.tag_depth, args.depth_sigma, ("--tag-depth", "--depth-sigma"))
    outcome = track(args.log, args.receivers, args.truth, args.reference, **options)
    check_positioned(outcome, args.log)
    out = output_folder(args.out, Path("results") / f"track_{folder_name(args.log.stem)}", args.force,
                        "track.csv", "track")
    write(outcome, out)
    for line, warning in track_lines(outcome, args.log, args.truth, options["receivers_kept"], options["drop"],
                                     options["seed"], out):
        print(line, file=sys.stderr if warning else sys.stdout)
    return 0
