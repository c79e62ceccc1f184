"""``sblsim sync`` and ``sblsim.sync``: the receivers' clocks of a telemetry array synchronised from its sync tags
(the raw detections read by :mod:`sblsim.orchestrator.readers.detections`, the model of :mod:`sblsim.models.sync`).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sblsim.models.sync.windows import WINDOW_DAYS
from sblsim.orchestrator.commands.console import add_receivers, add_refinement, output_folder
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.io.arguments import flag_argument, path_argument, prepare_out, real_argument, text_argument
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.sync.survey_console import speed_said, survey_line
from sblsim.orchestrator.sync.toa_console import say_warnings
from sblsim.orchestrator.telemetry.study_options import survey_sigma_argument

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure

#: The formats of the detections file (None: read from its first line), the bins' allowed width [h] and the sound
#: speed's range [m/s].
BIN_HOURS = (0.05, 168.0)
#: The windows' length [days] allowed (0: one fit; the default :data:`~sblsim.models.sync.windows.WINDOW_DAYS`).
WINDOW_DAYS_RANGE = (0.0, 366.0)
SOUND_SPEED = (1300.0, 1700.0)


@dataclass
class SyncResult:
    """The outcome of :func:`sync`.

    Attributes
    ----------
    summary : dict
        ``sync.json``: the model, the reference receiver, the bins' edges, per receiver its offsets [s] and drifts
        [s/s] per bin with their sigmas, its rejected share and residuals, the receivers not synchronised, notes.
    offsets : pandas.DataFrame
        ``offsets.csv``: one row per synchronised receiver and time bin (offset at the bin's start and end [s],
        drift [s/s], their sigmas, the kept arrivals, ``bridged``); where a receiver's clock broke (jumped or went
        back: ``summary["clock_breaks"]``, each named in a warning), one row per clock segment and bin, with
        ``segment``, ``clock_from`` and ``clock_to`` (the times of its own clock the segment holds for).
    residuals : pandas.DataFrame
        ``residuals.csv``: every sync-tag arrival: receiver, tag, emission, ``time`` (its clock) and ``time_sync``
        [s], residual [s] and [m], ``kept`` and the reason of a rejection.
    sync_tags : pandas.DataFrame
        ``sync_tags.csv``: each sync tag positioned from the other receivers' synchronised arrivals (its own left
        out, the clocks fitted without it): errors [m] against its known position and the fixes' own sigmas. The
        sigmas hold the timing noise and the geometry, not an error of the table's positions (a tag that is not
        where the table says is positioned where it is): an error far above its sigma and the same for all of a
        tag's emissions (``median_position_error_m`` near ``median_error_m``) is the table's, as on the boats
        array (docs/sync.md: its clock-free two-way distances differ from the table's by 5.8 m RMS). With the
        positions refined, the errors are against the tag's receiver's position refined without the tag's
        arrivals (``truth_x_m``, ``truth_y_m``, ``truth_sigma_m``), the table's error beside them.
    out : Path or None
    positions : pandas.DataFrame or None
        ``positions.csv`` with ``refine_positions``: per receiver ``serial``, the refined ``x_m``, ``y_m`` [m], the
        table's, the shift [m] and its sigmas [m]; else None.
    """

    summary: dict[str, Any]
    offsets: pd.DataFrame
    residuals: pd.DataFrame
    sync_tags: pd.DataFrame
    out: Path | None = None
    _outcome: Any = None
    positions: pd.DataFrame | None = None

    def plot(self) -> dict[str, Figure]:
        """The figures: ``offsets``, ``residuals`` and ``coverage``."""
        from sblsim.orchestrator.sync.outputs import figures

        return figures(self._outcome)

    def correct(self, receiver: str, times: Any, part: int = 1) -> Any:
        """Times logged by ``receiver`` [s since 1970 UTC on its clock] in its clock ``part`` (the detections'
        ``clock_part``: 1 before its time first went back in the file's order, 2 after, ...) on the reference
        receiver's clock (NaN where its clock broke: a time between two of its clock segments, set aside, or a time
        outside the part's span).

        Raises
        ------
        ConfigError
            A receiver that was not synchronised, a part it does not have (one line naming its parts).
        """
        if receiver not in self.summary["synchronised"]:
            raise ConfigError(f"receiver: {receiver!r} was not synchronised; allowed: one of "
                              f"{', '.join(self.summary['synchronised'])}")
        from sblsim.orchestrator.sync.run import corrected_times

        return corrected_times(self._outcome, receiver, times, part)


def sync(detections: str | Path, *, receivers: str | Path, format: str | None = None,
         sound_speed: float | None = None, sound_speed_file: str | Path | None = None, bin_hours: float = 1.0,
         reference: str | None = None, out: str | Path | None = None, force: bool = False,
         refine_positions: bool = False, survey_sigma: float | None = None, crs: str | None = None,
         frame: str | None = None, window_days: float = WINDOW_DAYS) -> SyncResult:
    """Synchronise the receivers' clocks from the sync tags: ``sblsim sync``.

    Parameters
    ----------
    detections : str or Path
        Raw detections: the YAPS table (``epo, frac, tag, serial``), a VUE export, a Fathom (VDAT) CSV, a GLATOS or
        an OTN detection extract.
    receivers : str or Path
        The receivers: ``serial, sync_tag, x_m, y_m[, z_m]`` (or ``x, y, z``), or a study's deployments (``lat``,
        ``lon``, dates, GLATOS and OTN names: :mod:`sblsim.orchestrator.readers.deployments`).
    format : str, optional
        one of :data:`~sblsim.orchestrator.readers.formats.FORMATS`; default read from the file's first line.
    sound_speed : float, optional
        [m/s] in [1300, 1700], constant.
    sound_speed_file : str or Path, optional
        A series ``epo, sound_speed_m_s`` interpolated at each arrival. Neither given: the sound speed is estimated
        with the clocks.
    bin_hours : float
        [h] in [0.05, 168]: the time bins' width (one drift per bin).
    reference : str, optional
        The reference receiver's serial (its clock the time base); default the one with the most shared arrivals.
    out : str or Path, optional
        Write ``sync.json``, ``offsets.csv``, ``residuals.csv``, ``sync_tags.csv`` and the figures there.
    force : bool
        Replace an earlier result in ``out``.
    refine_positions : bool
        Refine the receivers' horizontal positions with the clocks (their sync tags with them), a Gaussian prior at
        the table's positions; written as ``positions.csv``. Default: the table's positions fixed.
    survey_sigma : float, optional
        [m], the table's horizontal sigma per axis: with ``refine_positions`` the prior in [0.01, 1000] (default
        3 m, a handheld GPS's); without, the survey's stated error in the sync tags' NEES, in [0, 1000] (0: the
        table's positions taken as exact; default: the error the residuals between receivers show where seen,
        ``sync.json``'s ``survey_sigma_from`` ``"seen"``, else exact).
    crs : str, optional
        The receivers' CRS (``EPSG:…``; WGS 84 for ``lat``, ``lon`` by default).
    frame : str, optional
        The metric frame (a projected CRS in metres; default the UTM zone of the array's centre).
    window_days : float
        [days] in [0, 366]: a season longer than a window (and its overlaps) fitted window by window
        (:mod:`sblsim.models.sync.windows`); 0: one fit however long.

    Returns
    -------
    SyncResult

    Raises
    ------
    ModelError, ConfigError
        A file that cannot be read or holds a value outside its range (one line naming the file, line and column),
        a receiver clock going back, bad options.
    """
    detections = path_argument(detections, "detections", optional=False)
    receivers = path_argument(receivers, "receivers", optional=False)
    if format is not None and format not in FORMATS:
        raise ConfigError(f"format: {format!r} is not one of {', '.join(FORMATS)}")
    crs, frame = text_argument(crs, "crs"), text_argument(frame, "frame")
    if sound_speed is not None and sound_speed_file is not None:
        raise ConfigError("sound_speed: give sound_speed or sound_speed_file, not both")
    if sound_speed is not None:
        sound_speed = real_argument(sound_speed, "sound_speed", *SOUND_SPEED, "m/s")
    sound_speed_file = path_argument(sound_speed_file, "sound_speed_file")
    bin_hours = real_argument(bin_hours, "bin_hours", *BIN_HOURS, "h")
    reference = text_argument(reference, "reference")
    flag_argument(force, "force")
    flag_argument(refine_positions, "refine_positions")
    survey_sigma = survey_sigma_argument(survey_sigma, refine_positions, "survey_sigma")
    window_days = real_argument(window_days, "window_days", *WINDOW_DAYS_RANGE, "days")
    target = prepare_out(out, force, "sync.json", "synchronisation")
    from sblsim.orchestrator.sync.study_sync import synchronise_files

    outcome = synchronise_files(detections, receivers, format, sound_speed, sound_speed_file, bin_hours, reference,
                                refine_positions, survey_sigma, crs, frame, window_days)
    if target is not None:
        from sblsim.orchestrator.sync.outputs import write

        write(outcome, target)
    return SyncResult(outcome.summary, outcome.offsets, outcome.residuals, outcome.sync_tags, target, outcome,
                      outcome.positions)


NAME = "sync"
HELP = "synchronise the receivers' clocks of a telemetry array from its sync tags (raw detections)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim sync``'s arguments."""
    p.add_argument("detections", type=Path, help="raw detections: a YAPS table (epo,frac,tag,serial), a VUE export, "
                   "a Fathom (VDAT) CSV, a GLATOS or an OTN detection extract, or a store (sblsim store)")
    add_receivers(p)
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="the detections' format (default: read from the file's first line)")
    speed = p.add_mutually_exclusive_group()
    speed.add_argument("--sound-speed", type=float, default=None, metavar="M_S",
                       help="a constant sound speed [m/s] (default: estimated with the clocks)")
    speed.add_argument("--sound-speed-file", type=Path, default=None, metavar="CSV",
                       help="a sound-speed series (epo,sound_speed_m_s), interpolated at each arrival")
    p.add_argument("--bin-hours", type=float, default=1.0, metavar="H",
                   help="the time bins' width [h] in [0.05, 168] (one drift per receiver and bin; default 1)")
    p.add_argument("--reference", default=None, metavar="SERIAL",
                   help="the reference receiver (default: the one with the most arrivals shared with others)")
    add_refinement(p, "with the clocks")
    p.add_argument("--window-days", type=float, default=WINDOW_DAYS, metavar="D",
                   help=f"a season fitted in windows of D days [0, 366] (default {WINDOW_DAYS:g}; 0: one fit)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/sync_DETECTIONS)")
    p.add_argument("--force", action="store_true", help="replace an earlier synchronisation in --out")


def main(args: argparse.Namespace) -> int:
    """``sblsim sync`` from its parsed arguments: its lines printed, its exit status returned."""
    speed = None if args.sound_speed is None else real_argument(args.sound_speed, "--sound-speed", *SOUND_SPEED,
                                                                "m/s")
    hours = real_argument(args.bin_hours, "--bin-hours", *BIN_HOURS, "h")
    survey = survey_sigma_argument(args.survey_sigma, args.refine_positions, "--survey-sigma")
    window = real_argument(args.window_days, "--window-days", *WINDOW_DAYS_RANGE, "days")
    from sblsim.orchestrator.sync.outputs import write
    from sblsim.orchestrator.sync.study_sync import synchronise_files

    outcome = synchronise_files(args.detections, args.receivers, args.format, speed, args.sound_speed_file, hours,
                                args.reference, args.refine_positions, survey, args.crs, args.frame, window)
    out = output_folder(args.out, Path("results") / f"sync_{folder_name(args.detections.stem)}", args.force,
                        "sync.json", "synchronisation")
    write(outcome, out)
    s = outcome.summary
    d = s["detections"]
    speed_text = speed_said(s)
    print(f"sync of {args.detections}: {d['sync_arrivals']} sync-tag arrivals of {d['rows']} detections, "
          f"{len(s['synchronised'])} receivers synchronised against {s['reference_receiver']} in "
          f"{len(s['bin_edges']) - 1} bins of {s['bin_hours']:g} h, sound speed {speed_text}, in "
          f"{s['wall_time_s']:.1f} s")
    if "windows" in s:
        w = s["windows"]
        print(f"  fitted in {w['count']} windows of {w['days']:g} days ({w['overlap_hours']:g} h overlap each side)")
    rejected = d["used"] - d["kept"]
    print(f"  arrivals: {d['kept']} kept, {rejected} rejected, {d['multipath']} multipath, {d['single_receiver']} "
          f"heard by one receiver only; median |residual| {s['median_abs_residual_m']:.3g} m")
    seen = survey_line(s.get("survey_error"), s.get("survey_sigma_m"), s.get("survey_sigma_from"))
    if seen:
        print(f"  {seen}")
    noise = {r: v["toa_sigma_s"] for r, v in s.get("toa_noise", {}).items() if math.isfinite(v["toa_sigma_s"])}
    if noise:
        low, high = min(noise, key=noise.get), max(noise, key=noise.get)
        print(f"  TOA noise per receiver (offsets.csv's toa_sigma_s, the tracker's): median "
              f"{np.median(list(noise.values())) * 1e3:.3g} ms, {noise[low] * 1e3:.3g} ms ({low}) to "
              f"{noise[high] * 1e3:.3g} ms ({high})")
    if "positions" in s:
        q = s["positions"]
        if q["refined"]:
            print(f"  positions refined (prior {q['survey_sigma_m']:g} m per axis): median shift "
                  f"{q['median_shift_m']:.3g} m, the largest {q['largest_shift_m']:.3g} m "
                  f"({q['largest_shift_receiver']}); {q['determined']} of {q['receivers']} receivers determined by "
                  "the sync tags, the others keep the table's (positions.csv's reason); each one's error for a "
                  f"tracker {min(q['position_sigma_m']):.3g} to {max(q['position_sigma_m']):.3g} m per axis")
        loo = q.get("leave_one_out")
        if loo:
            print(f"  sync tags' leave-one-out median error: {_loo_text(loo['table'])} with the table's positions "
                  f"(NEES with the survey sigma), {_loo_text(loo['refined'])} refined; the {loo['kept']} positions "
                  "kept")
    if s["sync_tags"]:
        t = s["sync_tags"]
        nees = t["nees_mean_inside"]
        against = (" (against their receivers' positions refined without them)" if "positions" in s else
                   f" (the survey's error seen, {s['survey_sigma_m']:.3g} m per axis, in their NEES)"
                   if s.get("survey_sigma_from") == "seen" else
                   " (the table's positions taken as exact: --survey-sigma 0)" if s.get("survey_sigma_m") == 0 else
                   f" (the survey's {s['survey_sigma_m']:g} m per axis in their NEES)" if "survey_sigma_m" in s else "")
        print(f"  sync tags positioned without their own receiver ({t['tags']}){against}: median error "
              f"{t['median_error_m']:.3g} m" + ("" if nees is None or not math.isfinite(nees) else
                                                 f", NEES {nees:.3g} inside the array (2 when consistent)"))
        if t.get("places"):
            print(f"  each as one place from all its arrivals, its own receiver's too ({t['places']}): median error "
                  f"{t['place_median_error_m']:.3g} m, NEES {t['place_nees_mean']:.3g} (2 when consistent), "
                  f"{t['place_flagged']:,} of {t['place_rows']:,} emissions flagged as moved")
    for note in s["notes"]:
        print(f"note: {note}", file=sys.stderr)
    say_warnings(s)
    if s["not_synchronised"]:
        print(f"sblsim: warning: not synchronised: {', '.join(s['not_synchronised'])}", file=sys.stderr)
    extra = "positions.csv, " if outcome.positions is not None else ""
    print(f"  written to {out}/ (sync.json, offsets.csv, residuals.csv, sync_tags.csv, {extra}offsets.png, "
          "residuals.png, coverage.png)")
    return 0


def _loo_text(loo: dict | None) -> str:
    """A leave-one-out's median error [m] and NEES inside the array, as the console says them."""
    if loo is None:
        return "none positioned"
    nees = loo["nees_mean_inside"]
    return f"{loo['median_error_m']:.3g} m" + ("" if nees is None or not math.isfinite(nees) else f" (NEES {nees:.3g})")


__all__ = ["SyncResult", "sync"]
