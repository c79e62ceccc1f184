"""``sblsim calibrate`` and ``sblsim.calibrate``: seafloor transponders located from a surface survey's two-way
travel times, recorded (survey A, NCL1, SeaGap's and GARPOS's files) or simulated (box-in replicates against the
truth) (:mod:`sblsim.orchestrator.surveys`; docs/calibration.md).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from sblsim.orchestrator.commands.common import Overrides, Progress, override_items
from sblsim.orchestrator.commands.console import output_folder
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.io.arguments import check_integer, path_argument, prepare_out, text_argument
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.io.progress import check_progress

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd


@dataclass
class CalibrationResult:
    """The outcome of :func:`calibrate`.

    Attributes
    ----------
    name : str
        The survey's name (the default output folder's).
    sound_speed : str
        What the travel times were computed with: a sound speed, straight rays at each transponder's harmonic
        mean of a profile, or eigenrays through one.
    segments : int
        The survey's segments, each solved on its own before they are combined.
    solution : dict
        ``solution.json``: each transponder's position from its a-priori ENU [m] with its sigma [m], the
        sound speed [m/s], the residuals' RMS [s], the solver's settings; a simulated survey's truth, errors
        [m] and bound [m].
    residuals : pandas.DataFrame
        ``residuals.csv``: one row per reply, its TWTT residual [s] and whether it was used.
    running : pandas.DataFrame or None
        ``running.csv``: the running solution (Kalman form), one row per reply.
    ntd : pandas.DataFrame or None
        ``ntd.csv``: the sound-speed perturbation of each reply (a moving-ocean solve).
    search : pandas.DataFrame or None
        ``criterion.csv``: the candidates of the number of bases' search.
    replicates : pandas.DataFrame or None
        ``replicates.parquet``: a simulated survey's replicates (errors against the truth [m], NEES, bound).
    notes, warnings : list of str
        What was left out of the log, and what a user must know about the solution (one line each).
    out : Path or None
    """

    name: str
    sound_speed: str
    segments: int
    solution: dict[str, Any]
    residuals: pd.DataFrame
    running: pd.DataFrame | None
    ntd: pd.DataFrame | None
    search: pd.DataFrame | None
    replicates: pd.DataFrame | None
    notes: list[str]
    warnings: list[str]
    out: Path | None = None


def calibrate(survey: str | Path, *, format: str | None = None, initcfg: str | Path | None = None,
              svp: str | Path | None = None, set: Overrides = None, replicates: int | None = None,
              out: str | Path | None = None, force: bool = False, progress: Progress = False) -> CalibrationResult:
    """Locate seafloor transponders from a surface survey's two-way travel times: ``sblsim calibrate``.

    The box-in least squares of GNSS-Acoustic calibration (docs/calibration.md), with the moving-ocean
    perturbation of SeaGap and GARPOS where the survey asks for it; a simulated survey (``box-in`` or a
    ``CONFIG.toml``) is solved against its truth.

    Parameters
    ----------
    survey : str or Path
        A built-in survey (``xie-2021-07-23``, ``ncl1-2022-208``, ``seagap-example``, ``box-in``, ...), a
        survey log (``.csv`` or ``.parquet``; a text file with ``format='xie'``; a SeaGap folder with
        ``format='seagap'``) or a simulated survey's ``CONFIG.toml``.
    format : str, optional
        The log's format: ``sblsim`` (default), ``xie``, ``seagap`` or ``garpos`` (with ``initcfg`` and
        ``svp``).
    initcfg, svp : str or Path, optional
        ``format='garpos'``: GARPOS's initial site-parameter file (the paths it names are not read) and its
        sound-speed profile.
    set : mapping or sequence of str, optional
        Solver settings (``solver.sound_speed_mps``, ...) or a simulated survey's ``survey.KEY`` /
        ``platform.KEY``.
    replicates : int, optional
        A simulated survey: solve this many replicates (``replicates`` of the result).
    out : str or Path, optional
        Write ``solution.json``, ``residuals.csv`` and the figures there (and the tables above that exist).
    force : bool
        Replace an earlier calibration in ``out``.
    progress : bool or callable
        Report a simulated survey's replicates solved, or a recorded survey's moving-ocean solve or search (its
        Gauss-Newton iterations).

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ConfigError, SblsimError
        A survey that cannot be read (the message names the row and column), bad settings or options.
    """
    source = str(path_argument(survey, "survey", optional=False))
    fmt = text_argument(format, "format")
    initcfg, svp = path_argument(initcfg, "initcfg"), path_argument(svp, "svp")
    replicates = check_integer(replicates, "replicates")  # its range the survey's
    check_progress(progress)
    prepare_out(out, force, "solution.json", "calibration")  # before any work (and again before the write)
    return _calibrate(source, fmt, override_items(set), initcfg, svp, replicates, progress,
                      lambda name: prepare_out(out, force, "solution.json", "calibration"), lambda n: n)


def _calibrate(source: str, fmt: str | None, overrides: list[str], initcfg: Path | str | None,
               svp: Path | str | None, replicates: int | None, progress: Any,
               prepare: Callable[[str], Path | None], option: Callable[[str], str]) -> CalibrationResult:
    """:func:`calibrate` (and ``sblsim calibrate``): read the survey, solve it, ``prepare(name)`` the output
    folder (None: nothing is written; a survey's log is solved first, a simulated survey's folder prepared
    first) and write. ``option(name)`` is how an option is named in a message (``--replicates`` on the command
    line)."""
    from sblsim.orchestrator.surveys.calibrate import calibrate as solve
    from sblsim.orchestrator.surveys.calibrate import load_survey, write_calibration
    from sblsim.orchestrator.surveys.log import write_log
    from sblsim.orchestrator.surveys.simulate import REPLICATES_RANGE, is_simulated, load_simulated, run_simulated

    table, extra = None, {}
    if not is_simulated(source):
        if replicates is not None:
            raise ConfigError(f"{option('replicates')}: only a simulated survey (box-in or a CONFIG.toml) has "
                              "replicates")
        survey = load_survey(source, fmt, overrides, initcfg, svp)  # all read first
        result, name = solve(survey, progress), survey.name
        target = prepare(name)
    else:
        if fmt is not None or initcfg is not None or svp is not None:
            raise ConfigError(f"{option('format')}: a simulated survey has no log format; give "
                              f"{option('format')} with a log")
        if replicates is not None and not REPLICATES_RANGE[0] <= replicates <= REPLICATES_RANGE[1]:
            raise ConfigError(f"{option('replicates')}: {replicates} is outside the allowed range "
                              f"[{REPLICATES_RANGE[0]}, {REPLICATES_RANGE[1]}]")
        sim = load_simulated(source, overrides)  # every input read and checked first
        name = sim.name
        target = prepare(name)
        result, table = run_simulated(sim, replicates, progress=progress)
        survey = result.survey
        extra = {"survey_log.csv": lambda path: write_log(survey.log, path)}  # replicate 0's log
        if table is not None:
            extra["replicates.parquet"] = lambda path: table.to_parquet(path, index=False)
    if target is not None:
        write_calibration(result, target, extra)
    s = result.solution
    profile = s["solver"]["sound_speed_profile"] or "the survey's own profile"
    if s["solver"]["propagation"] == "ray":
        speed = f"eigenrays through {profile}"
    elif s["solver"]["sound_speed_profile"] or survey.profile is not None:
        speed = f"straight rays at each transponder's harmonic mean of {profile}"
    else:
        speed = f"sound speed {s['sound_speed_mps']:.6g} m/s"
    return CalibrationResult(name, speed, len(result.segments), s, result.residuals, result.running,
                             result.ntd, result.search, table, list(survey.notes), list(result.warnings), target)


NAME = "calibrate"
HELP = ("locate seafloor transponders from a surface survey's two-way travel times "
       "(docs/calibration.md)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim calibrate``'s arguments."""
    p.add_argument("survey", metavar="SURVEY|LOG|CONFIG",
                   help="a built-in survey (xie-2021-07-23, the other days xie-2021-08-23-1065 ..., ncl1-2022-208, "
                        "seagap-example; box-in, simulated), a survey log (.csv or .parquet; any text file with "
                        "--format xie; a SeaGap folder with --format seagap) or a simulated survey CONFIG.toml")
    p.add_argument("--format", default=None, metavar="FORMAT",
                   help="the log's format: sblsim (default), xie (survey A's text files), seagap (a folder of "
                        "SeaGap's files) or garpos (GARPOS's observation CSV, with --initcfg and --svp)")
    p.add_argument("--initcfg", default=None, metavar="FILE",
                   help="--format garpos: GARPOS's initial site-parameter file (the paths it names are not read)")
    p.add_argument("--svp", default=None, metavar="FILE", help="--format garpos: GARPOS's sound-speed profile (CSV)")
    p.add_argument("--replicates", type=int, default=None, metavar="N",
                   help="a simulated survey: solve N replicates and write replicates.parquet (errors against the "
                        "truth, NEES, the horizontal bound)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/calibrate_NAME)")
    p.add_argument("--force", action="store_true", help="replace an earlier calibration in --out")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="TABLE.KEY=VALUE",
                   help="override a solver setting, e.g. solver.sound_speed_mps=1500 or solver.solve_sound_speed=true, "
                        "or a simulated survey's survey.KEY / platform.KEY (repeatable)")


def main(args: argparse.Namespace) -> int:
    """``sblsim calibrate`` from its parsed arguments: its lines printed, its exit status returned."""
    result = _calibrate(
        args.survey, args.format, args.overrides, args.initcfg, args.svp, args.replicates, "auto",
        lambda name: output_folder(args.out, Path("results") / f"calibrate_{folder_name(name)}", args.force,
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
    print(_determination_line(s["determination"]))
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
    """A calibration's warnings, one line each on standard error."""
    for warning in result.warnings:
        print(f"sblsim: warning: {warning}", file=sys.stderr)


def _determination_line(d: dict) -> str:
    """The console line of ``solution.json``'s ``determination``: the equilibrated condition, the largest pairwise
    correlation, the largest multiple correlation (its variance inflation, the kinds of unknowns), the share the
    gradients take beyond the background, the iterations."""
    correlation = (f"; largest correlation {d['max_correlation']:.4f} ({d['position']} with the {d['parameter']})"
                   if d["max_correlation"] is not None else "")
    multiple = (f"; multiple correlation R² {d['multiple_r2']:.6f} (variance inflation {d['variance_inflation']:.3g}, "
                f"{d['multiple_position']} with {d['multiple_group']} together)"
                if d.get("variance_inflation") is not None else "")
    if d.get("gradient_inflation") is not None:
        multiple += (f"; the gradients take {d['gradient_r2']:.2%} of what the background leaves of the "
                     f"{d['gradient_position']} (variance inflation {d['gradient_inflation']:.3g})")
    return (f"  determination: condition {d['condition']:.3g}{correlation}{multiple}; converged in {d['iterations']} "
            "iteration(s)")


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
    print(_determination_line(s["determination"]))
    if table is not None:
        r = s["replicates"]
        print(f"  {r['count']} replicates: horizontal RMS error {r['rms_h_m']:.4f} m, bound {r['pcrb_h_m']:.4f} m "
              f"(ratio {r['rms_h_m'] / r['pcrb_h_m']:.3f}); RMS N {r['rms_n_m']:.4f} E {r['rms_e_m']:.4f} "
              f"U {r['rms_u_m']:.4f} m; mean NEES {r['nees_mean']:.2f} (3 when consistent)")
    if s["lbl_set"] is not None:
        print(f"  survey error for an LBL design ({s['survey_sigma_from']}): --set {s['lbl_set']}")
    else:
        a = s["bound_agreement"]
        print(f"  no survey error suggested for an LBL design: {a['measured']} and the bound disagree (ratio "
              f"{'undefined' if a['ratio'] is None else format(a['ratio'], '.3g')}, outside [1/3, 3]; "
              f"solution.json's bound_agreement)")
    files = "solution.json, residuals.csv, survey_log.csv" + (", replicates.parquet" if table is not None else "")
    print(f"  written to {result.out}/ ({files}, figures)")
    return 0
