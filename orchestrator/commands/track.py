"""``sblsim track`` and ``sblsim.track``: a telemetry study in one command, its people's own files in (the receivers'
deployments in latitude and longitude with dates, their detection exports, a tag sheet), every tag tracked with its
own ping type, the tracks out in latitude, longitude and UTC (:mod:`sblsim.orchestrator.telemetry.study`).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from sblsim.orchestrator.commands.common import add_water_arguments
from sblsim.orchestrator.commands.console import add_receivers, add_refinement, output_folder
from sblsim.orchestrator.io.arguments import path_argument, prepare_out
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.io.progress import ProgressSpec, check_progress
from sblsim.orchestrator.telemetry.study_options import FORMATS, _options
from sblsim.orchestrator.telemetry.study_report import closing_line, study_lines
from sblsim.orchestrator.telemetry.study_run import _run
from sblsim.orchestrator.tracks.options import sound_speed_arguments, water_arguments
from sblsim.orchestrator.tracks.outputs import figure

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class StudyResult:
    """The outcome of :func:`track`.

    Attributes
    ----------
    tracks : pandas.DataFrame
        ``tracks.csv``: every tracked tag's rows: ``tag``, ``time_utc`` (the emission, ISO 8601 UTC), ``epoch_s``
        [s since 1970 UTC], ``lat``, ``lon`` [° WGS 84; NaN without a CRS], ``x``, ``y`` [m in the frame] (``z``),
        ``sigma_x``, ``sigma_y`` [m] (``sigma_z``), ``receivers_heard``, ``quality`` (``ok``, ``restart``,
        ``flagged``).
    tags : pandas.DataFrame
        ``tags.csv``: one row per tag asked for: ``status`` ``tracked`` (a row positioned at least) or ``refused``
        with its ``reason_code`` and ``reason``; its detections, the receivers that heard it, its pings (those
        heard by enough receivers at once), positioned, set aside and not positioned (by why; the three sum to its
        pings), flagged, the median 2-D σ of its rows not flagged [m], the ping type stated and taken, the sound
        speed, its times' resolution, its first and last row's UTC time, its folder.
    receivers : pandas.DataFrame
        ``receivers.csv``: the deployments, in the frame and in latitude and longitude, with their dates.
    summary : dict
        ``study.json``: the files, the frame (its CRS and scale factor), the detections used and set aside (per
        reason and serial), the clocks, the tags, the notes.
    tracked : dict
        Each tracked tag's own outcome (:class:`~sblsim.orchestrator.tracks.outcome.TrackOutcome`: ``track``,
        ``estimates``, ``summary``), by tag (with ``out``, ``estimates`` None: in the tag's folder, not memory).
    out : Path or None
    reference_tags : pandas.DataFrame
        ``reference_tags.csv``: each reference tag's place against its known position and each sync tag left out of
        the synchronisation in turn (``kind``), its error [m], σ [m], 2-D NEES and rows flagged
        (:mod:`sblsim.orchestrator.telemetry.reference_tags`; pooled in ``summary["reference_tags"]``).
    """

    tracks: pd.DataFrame
    tags: pd.DataFrame
    receivers: pd.DataFrame
    summary: dict[str, Any]
    tracked: dict[str, Any] = field(default_factory=dict)
    out: Path | None = None
    reference_tags: pd.DataFrame | None = None
    _outcome: Any = field(default=None, repr=False)

    def plot(self) -> dict[str, Figure]:
        """The figures: ``map`` (every track over the receivers) and each tag's own (``track_TAG``)."""
        from sblsim.orchestrator.telemetry.outputs import study_map

        figures = {"map": study_map(self._outcome)}
        for folder, outcome in self._outcome.outcomes.items():
            figures[f"track_{folder}"] = figure(outcome)
        return figures


def track(detections: str | Path | Sequence[str | Path], *, receivers: str | Path | None = None,
          tags: str | Path | None = None, spatial: str | Path | None = None, tz: str | None = None,
          tag: str | Sequence[str] | None = None, sync: str | Path | None = None, format: str | None = None,
          crs: str | None = None, frame: str | None = None, sound_speed: float | None = None,
          sound_speed_file: str | Path | None = None, temperature: float | None = None,
          salinity: float | None = None, bin_hours: float = 1.0, workers: int | None = None,
          scheduler: str | None = None, toa_sigma: float | None = None,
          temperature_file: str | Path | None = None, water_depth: float | None = None,
          force_interval: bool = False, refine_positions: bool = False, survey_sigma: float | None = None,
          out: str | Path | None = None, force: bool = False, progress: ProgressSpec = False) -> StudyResult:
    """Track every tag of a telemetry study: ``sblsim track`` (docs/telemetry.md).

    Parameters
    ----------
    detections : str or Path, or a sequence of them
        The receivers' detections (raw: each receiver's own clock): files (a YAPS table, a VUE export, a Fathom
        (VDAT) CSV, a GLATOS or an OTN detection extract, actel's detections, a Thelma TBR export; each file's
        format told from its first line), a folder of them (its ``*.csv``), or an actel workspace folder
        (``deployments.csv``, ``spatial.csv``, ``biometrics.csv`` and a ``detections`` folder or
        ``detections.csv``: :mod:`sblsim.orchestrator.readers.study_files`).
    receivers : str or Path, optional
        The receivers: deployments in ``lat``, ``lon`` with dates (GLATOS ``receiver_locations``, OTN deployments:
        ``ins_serial_no``, ``deploy_lat``, ``deploy_long``, ``deploy_date_time``, ``recover_date_time``,
        ``instrument_depth``, ``transmitter`` for a co-located sync tag), ``serial, sync_tag, x_m, y_m``, or actel's
        deployments (``Receiver``, ``Station.name``, ``Start``, ``Stop``: with ``spatial`` and ``tz``); default an
        actel workspace's.
    tags : str or Path, optional
        The tag sheet (``transmitter``, ``ping_type``, ``min_delay``, ``max_delay``, ``role``, sensor columns:
        :mod:`sblsim.orchestrator.readers.tag_sheet`), or actel's biometrics (``Signal``, ``Code.space``,
        ``Release.date``: each signal an animal tag, its ping type inferred). Without one every detected tag that is
        not a sync tag is tracked, its ping type inferred.
    spatial : str or Path, optional
        actel's stations (``Station.name``, ``Latitude``, ``Longitude``, ``Type``): the positions of actel's
        deployments, joined by station (release sites are no receivers); default an actel workspace's.
    tz : str, optional
        The study's IANA time zone (``Europe/Copenhagen``): actel's deployments and release dates are in local
        time, each converted to UTC with that date's offset; without it such a time is refused unless it carries
        its offset (never taken as UTC).
    tag : str or sequence of str, optional
        Only these transmitters (full IDs or ids; a text separated by commas, or a list).
    sync : str or Path, optional
        A synchronisation's folder (``sblsim sync --out DIR``); default: synchronised here from the deployments'
        sync tags (or the clocks taken as logged where there are none, said).
    format : str, optional
        ``yaps``, ``vue``, ``fathom``, ``glatos`` or ``otn``; default read from the file's first line.
    crs : str, optional
        The receivers' CRS (default WGS 84 for ``lat``, ``lon``; a projected one for ``x_m``, ``y_m``).
    frame : str, optional
        The metric frame (a projected CRS in metres; default the UTM zone of the array's centre).
    sound_speed : float, optional
        [m/s] in [1300, 1700], constant.
    sound_speed_file : str or Path, optional
        A series (``epo`` or ISO 8601 ``time_utc``, and ``sound_speed_m_s``) for the synchronisation and the tracks.
    temperature, salinity : float, optional
        The water's temperature [°C] and practical salinity (PSS-78), both or neither: the fallback sound speed
        (TEOS-10) where the pings cannot determine it.
    bin_hours : float
        [h] in [0.05, 168]: the synchronisation's bins.
    workers : int, optional
        Worker processes in [1, 256] (default the CPU count).
    scheduler : str, optional
        A Dask scheduler (``tcp://HOST:PORT`` or ``local``): the tags run on its workers.
    toa_sigma : float, optional
        The timing noise of every time of arrival [s] in [1e-6, 1]; default each receiver's from the
        synchronisation's residuals (``offsets.csv``'s ``toa_sigma_s``), else 0.15 ms (``summary["toa_noise"]``).
    temperature_file : str or Path, optional
        A water-temperature series (``time_utc`` or ``epo`` in UTC, ``temperature_c`` [°C]), or the receivers' own
        records (their Fathom CSV or VUE receiver events: :mod:`sblsim.orchestrator.readers.receiver_temperature`),
        made each tag's sound speed by TEOS-10 at ``salinity`` (:mod:`sblsim.orchestrator.readers.water`); not with
        ``sound_speed``, ``sound_speed_file`` or ``temperature``.
    water_depth : float, optional
        The water's depth [m] in (0, 11000], which bounds each tag's depth (the deployments' depths needed); default
        the deepest ``bottom_depth`` of the deployments that heard the tag, where the deployments give it
        (``summary["water_depth"]``).
    force_interval : bool
        Take a tag's stated interval (the sheet's) where its detections contradict it as a whole (a note says how
        many detections it drops); without it such a tag is a refused row of ``tags.csv`` naming the interval.
    refine_positions, survey_sigma : bool, float
        Refine the receivers' positions from the study's pings (:mod:`sblsim.orchestrator.telemetry.study_positions`);
        the survey's σ per axis [m]: the refinement's prior in [0.01, 1000], 3 by default; without, the stated error
        in every σ in [0, 1000] (0: the positions exact; default: the error the synchronisation sees, where seen).
    out : str or Path, optional
        Write the study's files there (``study.json``, ``tracks.csv``, ``tags.csv``, ``receivers.csv``,
        ``reference_tags.csv``, ``tracks.geojson``, ``map.png``, ``report.html`` with ``detections_daily.csv``,
        ``sync/``, ``tags/``: a folder per tag), all or nothing; stopped and run again, it resumes (docs/telemetry.md).
    force : bool
        Replace an earlier study in ``out``.
    progress : bool, str or callable
        ``True``: a bar on standard error as the tags end; a callable ``(done, total)``.

    Returns
    -------
    StudyResult

    Raises
    ------
    ModelError, ConfigError
        A file refused by its reader (one line naming the file, its line and column and the allowed values), no
        detection inside a deployment, bad options. A tag that cannot be tracked is a row of ``tags.csv`` saying why.
    """
    detections = [path_argument(d, "detections", optional=False) for d in
                  (detections if isinstance(detections, (list, tuple)) else [detections])]
    receivers = path_argument(receivers, "receivers")
    tags = path_argument(tags, "tags")
    spatial = path_argument(spatial, "spatial")
    sync = path_argument(sync, "sync")
    check_progress(progress)
    medium = sound_speed_arguments(sound_speed, sound_speed_file, temperature, salinity,
                                   ("sound_speed", "sound_speed_file", "temperature", "salinity"), temperature_file)
    options = _options(format, crs, frame, tag, bin_hours, workers, scheduler, medium,
                       {k: k for k in ("format", "crs", "frame", "tag", "bin_hours", "workers", "toa_sigma",
                                       "force_interval", "tz", "refine_positions", "survey_sigma")},
                       toa_sigma, force_interval, tz, refine_positions, survey_sigma) \
        | water_arguments(temperature_file, water_depth, ("temperature_file", "water_depth"))
    options["spatial"] = spatial
    target = prepare_out(out, force, "study.json", "study")
    outcome = _run(detections[0] if len(detections) == 1 else detections, receivers, tags, sync, options, target,
                   progress)
    return _result(outcome, target)


def _result(outcome, target: Path | None) -> StudyResult:
    from sblsim.orchestrator.telemetry.reference_tags import table  # pandas: loaded with the study

    return StudyResult(outcome.tracks, outcome.tags, outcome.deployments.written(), outcome.summary,
                       {outcome.matrices[f].summary["tag"]: o for f, o in outcome.outcomes.items()}, target,
                       table(outcome.summary.get("reference_tags")), outcome)


NAME = "track"
HELP = "track every tag of a telemetry study: deployments, detection exports and a tag sheet in, tracks in lat/lon out"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim track``'s arguments."""
    p.add_argument("detections", type=Path, nargs="+", metavar="DETECTIONS",
                   help="the receivers' detections: files (a YAPS table, a VUE export, a Fathom CSV, a GLATOS or "
                        "an OTN extract, actel's detections, a Thelma export), a folder of them, an actel workspace "
                        "(deployments.csv, spatial.csv, biometrics.csv, detections/) or a store (sblsim store)")
    add_receivers(p, required=False)
    p.add_argument("--spatial", type=Path, default=None, metavar="CSV",
                   help="actel's stations (Station.name, Latitude, Longitude, Type) for actel's deployments (Receiver, "
                        "Station.name, Start, Stop) given as --receivers (default: the workspace's spatial.csv)")
    p.add_argument("--tz", default=None, metavar="ZONE",
                   help="the study's time zone, an IANA name (Europe/Copenhagen): actel's deployments and release "
                        "dates are local times (refused without it unless they carry their UTC offset)")
    p.add_argument("--tags", type=Path, default=None, metavar="SHEET",
                   help="the tag sheet: a CSV of transmitter, ping_type (sbi/rbi/pbi), min_delay, max_delay [s], "
                        "role (animal/sync/reference), sensor_type, sensor_slope, sensor_intercept; Innovasea's tag "
                        "specification workbook (.xls/.xlsx, its Tag Summary) or OTN's tag metadata workbook; OTN's "
                        "tag releases table; or actel's biometrics.csv (default: the workspace's biometrics.csv, else "
                        "every detected tag that is not a sync tag, its ping type inferred)")
    p.add_argument("--tag", default=None, metavar="IDS",
                   help="only these transmitters (full IDs or ids, separated by commas)")
    p.add_argument("--sync", type=Path, default=None, metavar="DIR",
                   help="a synchronisation's folder (sblsim sync --out DIR); default: synchronised here from the "
                        "receivers' sync tags")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="the detections' format (default: read from the file's first line)")
    speed = p.add_mutually_exclusive_group()
    speed.add_argument("--sound-speed", type=float, default=None, metavar="M_S",
                       help="a constant sound speed [m/s] (default: calibrated from each tag's pings)")
    speed.add_argument("--sound-speed-file", type=Path, default=None, metavar="CSV",
                       help="a sound-speed series (epo or time_utc, sound_speed_m_s)")
    p.add_argument("--temperature", type=float, default=None, metavar="C",
                   help="the water's temperature [°C] for the fallback sound speed (TEOS-10; with --salinity)")
    p.add_argument("--salinity", type=float, default=None, metavar="S",
                   help="the water's practical salinity (PSS-78) for the fallback (0 fresh water, about 35 the open "
                        "sea)")
    p.add_argument("--toa-sigma", type=float, default=None, metavar="S",
                   help="the timing noise of every time of arrival [s] in [1e-6, 1] (default: each receiver's from "
                        "the synchronisation's residuals; else 0.00015)")
    add_water_arguments(p, times="time_utc or epo, in UTC", depth=" (default: the deepest bottom_depth of the "
                        "deployments that heard the tag, where the receivers file gives it)")
    p.add_argument("--bin-hours", type=float, default=1.0, metavar="H",
                   help="the synchronisation's bins [h] in [0.05, 168] (default 1)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes in [1, 256] (default: the CPU count)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a Dask scheduler (tcp://HOST:PORT, or local) whose workers track the tags")
    p.add_argument("--force-interval", action="store_true",
                   help="take a tag's stated interval (the sheet's) where its detections contradict it as a whole "
                        "(that tag refused otherwise); a note says how many detections it drops")
    add_refinement(p, "by the sync tags and the moving tags' pings, and track again on them where the pings "
                      "left out and the reference tags say it helps")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/study_DETECTIONS)")
    p.add_argument("--force", action="store_true", help="replace an earlier study in --out")


def main(args: argparse.Namespace) -> int:
    """``sblsim track`` from its parsed arguments: its lines printed, its exit status returned."""
    medium = sound_speed_arguments(args.sound_speed, args.sound_speed_file, args.temperature, args.salinity,
                                   ("--sound-speed", "--sound-speed-file", "--temperature", "--salinity"),
                                   args.temperature_file, "--temperature-file")
    options = _options(args.format, args.crs, args.frame, args.tag, args.bin_hours, args.workers, args.scheduler,
                       medium, {k: "--" + k.replace("_", "-") for k in ("format", "crs", "frame", "tag", "bin_hours",
                                                                       "workers", "toa_sigma", "force_interval",
                                                                       "tz", "refine_positions", "survey_sigma")},
                       args.toa_sigma, args.force_interval, args.tz, args.refine_positions, args.survey_sigma) \
        | water_arguments(args.temperature_file, args.water_depth, ("--temperature-file", "--water-depth"))
    options |= {"spatial": args.spatial, "keep_tracks": False}  # (no table returned: tracks.csv a tag at a time)
    out = output_folder(args.out, Path("results") / f"study_{folder_name(args.detections[0].stem)}", args.force,
                        "study.json", "study")
    from sblsim.orchestrator.readers.study_files import DetectionFiles  # pandas: loaded as the study starts

    detections = args.detections[0] if len(args.detections) == 1 else DetectionFiles(args.detections)
    outcome = _run(detections, args.receivers, args.tags, args.sync, options, out, "auto", lines=True)
    for line, warning in study_lines(outcome):
        print(line, file=sys.stderr if warning else sys.stdout)
    for note in outcome.summary["notes"]:
        print(f"note: {note}", file=sys.stderr)
    print(closing_line(outcome.tags, outcome.summary["wall_time_s"], out,
                       f"tracks.csv, tags.csv, receivers.csv, reference_tags.csv, study.json, "
                       f"{'tracks.geojson, ' if (out / 'tracks.geojson').exists() else ''}"
                       f"{'positions.csv, ' if outcome.positions is not None else ''}map.png, report.html, "
                       f"{'sync/, ' if outcome.sync is not None else ''}tags/: a folder per tag"))
    return 0


__all__ = ["StudyResult", "track"]
