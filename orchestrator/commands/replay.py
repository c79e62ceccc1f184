"""``sblsim replay`` and ``sblsim.replay``: a receiver on a recorded log (docs/log-format.md), with its errors and
consistency against a truth track when one is given (:mod:`sblsim.orchestrator.replay`).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from sblsim.orchestrator.commands.common import (
    Overrides,
    check_engine,
    flag_argument,
    override_items,
    path_argument,
    prepare_out,
    real_argument,
    text_argument,
)
from sblsim.orchestrator.commands.console import FMU_DIR_HELP, output_folder, print_metrics
from sblsim.orchestrator.cosim.config import MODEL_PREFIX, ConfigError, external_path
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.plan import Config, RunPlan, thaw
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.tracks.track import track, write

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class ReplayResult:
    """The outcome of :func:`replay`.

    Attributes
    ----------
    config : Config
        The configuration the receiver ran with.
    source : str
        Where that configuration came from.
    engine : str
    summary : dict
        ``summary.json``: a run's keys (errors None without a truth track), ``log`` (what was read of the
        log) and ``truth``.
    timeseries : pandas.DataFrame
        One row per macro step: ``time`` [s] on the log's clock, ``log_row``, the receiver's inputs and
        outputs; with a truth track ``true_*`` [m], ``pcrb`` and the errors ``e_*`` [m].
    out : Path or None
    """

    config: Config
    source: str
    engine: str
    summary: dict[str, Any]
    timeseries: pd.DataFrame
    out: Path | None = None
    resolve_plan: Any = field(default=None, repr=False)

    def plot(self) -> dict[str, Figure]:
        """The figures of a run over the steps the truth track covers (empty without truth)."""
        from sblsim.orchestrator.io.plots import run_figures

        ts = self.timeseries
        covered = ts[np.isfinite(ts["true_x"].to_numpy())] if "true_x" in ts else ts.iloc[:0]
        if not len(covered):
            return {}
        receiver = self._plan.receiver_label if self._plan is not None else self.config.plan().receiver_label
        if "replicate" not in covered:
            covered = covered.assign(replicate=0)
        return run_figures(covered, f"replay of {self.summary['log']['file']}, {receiver} ({self.engine})", receiver)


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
    from sblsim.orchestrator.replay import replay_config

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


@dataclass
class TrackResult:
    """The outcome of :func:`replay_toa`.

    Attributes
    ----------
    summary : dict
        ``summary.json``: the sound speed (given or calibrated), the ping interval, and per estimator (``rts``,
        ``ekf``, ``fix``, ``reference``) the pings positioned and, with a truth track, the 2-D errors' count,
        mean, median, RMS, 90th and 95th percentiles [m] and the mean 2-D NEES.
    tracks : pandas.DataFrame
        ``track.csv``: one row per ping and estimator: ``ping``, ``time`` (the estimated emission time) [s],
        ``x``, ``y`` [m], ``sigma_x``, ``sigma_y`` [m], ``receivers_heard``, ``estimator``.
    errors : pandas.DataFrame or None
        ``errors.csv`` (with a truth track): ``estimator``, ``ping``, ``time`` [s], ``error_2d_m`` [m].
    out : Path or None
    """

    summary: dict[str, Any]
    tracks: pd.DataFrame
    errors: pd.DataFrame | None
    out: Path | None = None


def replay_toa(toa: str | Path, *, receivers: str | Path, truth: str | Path | None = None,
               reference: str | Path | None = None, smooth: bool = True, sound_speed: float | None = None,
               out: str | Path | None = None, force: bool = False) -> TrackResult:
    """Track a pinger from recorded times of arrival at a fixed array (an inverted LBL): ``sblsim replay TOA_FILE
    --format toa`` (docs/tracking.md).

    Parameters
    ----------
    toa : str or Path
        The TOA matrix: one row per ping, one column per receiver [s], ``NA`` or empty where not heard.
    receivers : str or Path
        The receivers' positions: a CSV (name, ``x_m``, ``y_m``[, ``z_m``][, ``status``]) or a TOML file.
    truth : str or Path, optional
        A truth track (``x y t`` [m, m, s] under a header, e.g. GPS): the errors.
    reference : str or Path, optional
        Another solution (``x y t``) scored beside, on its own rows.
    smooth : bool
        Also run the RTS smoother (the ``rts`` rows).
    sound_speed : float, optional
        [m/s] in [1300, 1700]; default calibrated from the pings (single-ping fixes).
    out : str or Path, optional
        Write ``track.csv``, ``summary.json``, ``errors.csv`` and ``track.png`` there.
    force : bool
        Replace an earlier result in ``out``.

    Returns
    -------
    TrackResult

    Raises
    ------
    ModelError, ConfigError
        A file that cannot be read or holds a value outside its range (one line naming the file, line and
        column), bad options.
    """
    toa = path_argument(toa, "toa", optional=False)
    receivers = path_argument(receivers, "receivers", optional=False)
    truth = path_argument(truth, "truth")
    reference = path_argument(reference, "reference")
    smooth = flag_argument(smooth, "smooth")
    if sound_speed is not None:
        sound_speed = real_argument(sound_speed, "sound_speed", 1300.0, 1700.0, "m/s")
    target = prepare_out(out, force, "summary.json", "track")
    outcome = track(toa, receivers, truth, reference, smooth, sound_speed)
    if target is not None:
        write(outcome, target, truth)
    return TrackResult(outcome.summary, outcome.tracks, outcome.errors, target)


def _replay_plan(plan: RunPlan, source: str, log: Path, truth: Path | None, engine: str,
                 fmu_dir: str | Path | None, prepare: Callable[[], Path | None]) -> ReplayResult:
    """:func:`replay` of a plan (and ``sblsim replay``): read the log and the truth track, ``prepare()`` the
    output folder (None: nothing is written), replay and write."""
    from sblsim.orchestrator.receiver_log import read_log, read_truth
    from sblsim.orchestrator.replay import replay as _replay
    from sblsim.orchestrator.replay import write_replay

    data = read_log(log, plan.n_beacons, plan.system, plan["acoustics"]["sound_speed_assumed"])
    track = read_truth(truth) if truth is not None else None
    target = prepare()
    result = _replay(data, plan, engine, fmu_dir, track)
    if target is not None:
        write_replay(result, target)
    return ReplayResult(Config(thaw(result.config)), source, result.engine, result.summary, result.timeseries,
                        target, result.config)


NAME = "replay"
HELP = "run a receiver on a recorded log (docs/log-format.md)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim replay``'s arguments."""
    p.add_argument("log", type=Path, help="the log: .csv or .parquet (sblsim run --export-log writes one); with "
                   "--format toa, the matrix of times of arrival (docs/tracking.md)")
    p.add_argument("--format", choices=("log", "toa"), default="log",
                   help="log: a receiver's log (default); toa: times of arrival of a pinger at a fixed array "
                        "(an inverted LBL), tracked by the single-ping fix, the EKF and (--smooth) the RTS smoother")
    p.add_argument("--receivers", type=Path, default=None, metavar="FILE",
                   help="--format toa: the receivers' positions (CSV name,x_m,y_m[,z_m][,status], or TOML)")
    p.add_argument("--reference", type=Path, default=None, metavar="FILE",
                   help="--format toa: another solution (x y t) scored beside against --truth")
    p.add_argument("--smooth", action="store_true", help="--format toa: also the RTS smoother (the rts rows)")
    p.add_argument("--sound-speed", type=float, default=None, metavar="M_S",
                   help="--format toa: the sound speed [m/s] (default: calibrated from the pings)")
    p.add_argument("--receiver", default=None,
                   help="ekf, ekf-seq, ukf, lsq, model:PATH.py or fmu:PATH (default: the configuration's)")
    p.add_argument("--config", default=None, metavar="CONFIG",
                   help="the receiver's parameters, T and rate ratio: a built-in scenario or CONFIG.toml (default: "
                        "the configuration an exported log carries, else the semicircle scenario's)")
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
    if args.format == "toa":
        return _main_toa(args)
    given = [o for o, v in (("--receivers", args.receivers), ("--reference", args.reference),
                            ("--smooth", args.smooth), ("--sound-speed", args.sound_speed)) if v]
    if given:
        raise ConfigError(f"{given[0]}: only with --format toa (times of arrival); allowed for a log: --receiver, "
                          "--config, --truth, --engine, --set")
    from sblsim.orchestrator.replay import replay_config

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
    print_metrics(s, truth is not None)
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


def _main_toa(args: argparse.Namespace) -> int:
    """``sblsim replay TOA_FILE --format toa``: the track's lines printed."""
    if args.receivers is None:
        raise ConfigError("--receivers: required with --format toa (the receivers' positions, a CSV or TOML file)")
    other = [o for o, v in (("--receiver", args.receiver), ("--config", args.config), ("--set", args.overrides),
                            ("--fmu-dir", args.fmu_dir)) if v]
    if other or args.engine != "local":
        raise ConfigError(f"{other[0] if other else '--engine'}: not used with --format toa; allowed: --receivers, "
                          "--truth, --reference, --smooth, --sound-speed, --out, --force")
    speed = None if args.sound_speed is None else real_argument(args.sound_speed, "--sound-speed", 1300.0, 1700.0,
                                                                "m/s")
    outcome = track(args.log, args.receivers, args.truth, args.reference, args.smooth, speed)
    out = output_folder(args.out, Path("results") / f"track_{folder_name(args.log.stem)}", args.force,
                        "summary.json", "track")
    write(outcome, out, args.truth)
    s = outcome.summary
    c = s["sound_speed"]
    print(f"track of {args.log}: {s['n_pings']} pings at {len(s['receivers'])} receivers, sound speed "
          f"{c['sound_speed_m_s']:.1f} m/s ({c['source']}), ping interval {s['ping_interval_s']:.4f} s, in "
          f"{s['wall_time_s']:.1f} s")
    names = {"rts": "RTS smoother", "ekf": "EKF (causal)", "fix": "single-ping fix", "reference": "reference"}
    if args.truth is not None:
        print(f"  2-D error against {args.truth} [m]:")
        print(f"  {'estimator':<16} {'pings':>6} {'median':>7} {'RMS':>8} {'p90':>7} {'p95':>7}")
        for key, e in s["estimators"].items():
            if "median_m" in e:
                print(f"  {names[key]:<16} {e['n_scored']:>6} {e['median_m']:>7.3f} {e['rms_m']:>8.3f} "
                      f"{e['p90_m']:>7.3f} {e['p95_m']:>7.3f}")
    else:
        for key, e in s["estimators"].items():
            print(f"  {names[key]}: {e['n_fixed']} pings positioned")
    print(f"  written to {out}/ (track.csv, summary.json, {'errors.csv, ' if args.truth else ''}track.png)")
    return 0
