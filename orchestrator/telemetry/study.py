"""A telemetry study in one call (``sblsim track``, :func:`sblsim.track`): the receivers' deployments, their own
detection exports and a tag sheet in; every tag tracked with its own ping type, in parallel; the tracks out in
latitude, longitude and UTC.

1. The deployments are read and projected (:mod:`.deployments`), the detections read in any export
   (:func:`~sblsim.orchestrator.readers.detections.read_detections`; a store's a batch of tags at a time, never all
   at once: :mod:`.study_detections`) and each put at its deployment, those outside one set aside and counted
   (:func:`~.deployments.assign`); the array is the deployments that logged a detection kept,
   in a frame chosen over them (:func:`~sblsim.orchestrator.readers.in_water.in_water`: a network's other
   deployments listed as not used, in one line); the tag sheet is read (:mod:`.tag_sheet`).
2. The clocks: a synchronisation's folder given (``sync``: its ``offsets.csv``, its refined positions where it has
   them); else synchronised here, once, from the deployments' sync tags
   (:func:`~sblsim.orchestrator.sync.run.synchronise`); else, where no deployment has a sync tag, taken as logged
   (the receivers' times synchronised already: said).
3. The tags: those named (``tags``), else the sheet's animal and reference tags, else every detected tag that is not
   a sync tag. Each is found among the detections by its full ID or id
   (:func:`~sblsim.orchestrator.readers.transmitters.match`); its depth per detection from its sensor values and the
   sheet's slope and intercept; counted before anything is asked of its schedule (:mod:`.census`: a tag one receiver,
   too few at once or whole seconds on unsynchronised clocks cannot position is a row saying so, with its counts);
   its times-of-arrival matrix built with the ping type the sheet states
   (:func:`~sblsim.orchestrator.sync.toa.build_toa`), a column per receiver that heard it, and written into the
   tag's folder; then every matrix tracked
   (:func:`~sblsim.orchestrator.tracks.track.track`, the robust smoother's rows the track, a reference tag as
   stationary; of the causal filters only the EKF the smoothers start from) in worker processes or on a Dask
   scheduler (:func:`~sblsim.orchestrator.tracks.many.run_tracks`). A tag that cannot be tracked is a row saying
   why; the others finish. Every ping of a tag is counted once in its row (:mod:`.tag_rows`).
4. The reference tags and the sync tags left out of the synchronisation in turn scored against their known
   positions (:mod:`.reference_tags`: ``study.json``'s ``reference_tags``).
5. The tracks together (``tracks.csv``: ``tag``, ``time_utc``, ``epoch_s``, ``lat``, ``lon``, ``x``, ``y``,
   ``sigma_x``, ``sigma_y``, ``quality``, ...), a row per tag (``tags.csv``), the deployments (``receivers.csv``),
   the reference tags' scores (``reference_tags.csv``) and the summary (``study.json``): :mod:`.outputs`.
"""

from __future__ import annotations

import contextlib
import os
import time as clock
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.sync.identifiability import SURVEY_SIGMA
from sblsim.orchestrator.io.memory import arrow_pool, emptied, release, spilled
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.readers.assign import serials_as_logged
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.in_water import counted_in_water
from sblsim.orchestrator.readers.sound_speed import read_sound_speed
from sblsim.orchestrator.readers.study_files import read_study, study_files
from sblsim.orchestrator.readers.tag_sheet import TagSheet, TagSpec, spec_for
from sblsim.orchestrator.readers.transmitters import match
from sblsim.orchestrator.readers.water import read_temperature_series
from sblsim.orchestrator.store.read import is_store
from sblsim.orchestrator.sync.matrix_files import write_toa_files
from sblsim.orchestrator.sync.study_sync import rounding_warning
from sblsim.orchestrator.sync.toa import build_toa
from sblsim.orchestrator.telemetry.census import TRACK_OPTIONS, code_of, count, verdict
from sblsim.orchestrator.telemetry.kept_clocks import kept_study_clocks
from sblsim.orchestrator.telemetry.reference_tags import score as score_references
from sblsim.orchestrator.telemetry.study_clocks import TOO_COARSE, taken_survey
from sblsim.orchestrator.telemetry.study_detections import StudyDetections, Tally
from sblsim.orchestrator.telemetry.study_offsets import aligned, fits, fitted_options, fitted_study
from sblsim.orchestrator.telemetry.study_offsets import said as clocks_said
from sblsim.orchestrator.telemetry.study_positions import REFINED_FOLDER, refined_study
from sblsim.orchestrator.telemetry.study_tracks import TRACK_COLUMNS, TrackParts, combined_tracks
from sblsim.orchestrator.telemetry.tag_rows import heard_columns, tracked_row, unpositioned
from sblsim.orchestrator.tracks.depth import bottom_water_depth, study_water_depth
from sblsim.orchestrator.tracks.many import run_tracks
from sblsim.orchestrator.tracks.outputs import written_main
from sblsim.orchestrator.tracks.resume import Resume
from sblsim.orchestrator.tracks.tracker import toa_noise

#: The columns of ``tags.csv``: a tag's ``pings`` are always ``positioned`` + ``set_aside`` + ``not_positioned``
#: (``not_positioned_why``: the count of each reason), ``status`` ``tracked`` only with a row positioned, else
#: ``refused`` with its ``reason_code`` (:data:`~sblsim.orchestrator.telemetry.census.REASON_CODES`) and ``reason``;
#: ``two_places`` the line saying a tracked tag's pings show a second place heard at once (its rows flagged).
TAG_COLUMNS = ("tag", "transmitter", "name", "role", "motion", "ping_type_stated", "status", "reason_code", "reason",
               "detections", "receivers", "pings", "pings_at_once", "positioned", "set_aside", "not_positioned",
               "not_positioned_why", "flagged", "share_flagged", "two_places", "median_sigma_m", "ping_type", "track",
               "sound_speed_m_s", "sound_speed_source", "time_resolution_s", "first_utc", "last_utc", "folder",
               "wall_time_s")
#: The columns of ``tags.csv`` that are counts (whole numbers; empty for a tag never detected).
COUNT_COLUMNS = ("detections", "receivers", "pings", "pings_at_once", "positioned", "set_aside", "not_positioned",
                 "flagged")


@dataclass
class StudyOutcome:
    """What :func:`run_study` computed.

    Attributes
    ----------
    tracks : pandas.DataFrame or None
        ``tracks.csv``: every tracked tag's rows (:data:`~.study_tracks.TRACK_COLUMNS`), by tag and time; None where
        they are read from the tags' files as they are written (``parts``).
    tags : pandas.DataFrame
        ``tags.csv``: one row per tag asked for (:data:`TAG_COLUMNS`).
    deployments : Deployments
        The receivers as read (``receivers.csv``: :meth:`Deployments.written`).
    summary : dict
        ``study.json``.
    outcomes : dict
        Each tracked tag's :class:`~sblsim.orchestrator.tracks.outcome.TrackOutcome`, by its folder's name.
    matrices : dict
        Each tag's :class:`~sblsim.orchestrator.sync.toa.ToaOutcome`, by its folder's name.
    sync : SyncOutcome or None
        The synchronisation made here (None where given or taken as logged).
    daily : pandas.DataFrame or None
        The kept detections per deployment and UTC day (``detections_daily.csv``: :mod:`.report.daily`).
    positions : pandas.DataFrame or None
        ``positions.csv``: the receivers' positions refined from the moving tags (with ``refine_positions``;
        :class:`~.study_positions.StudyRefinement`).
    written : set of str
        The tags' folders written already (``write_tags``: their outcomes hold their track alone, matrices no rows).
    parts : TrackParts or None
        ``tracks.csv`` a tag at a time from the tags' own files (``keep_tracks`` False: the outcomes hold no track).
    clocks : Clocks or None
        The clocks the tags were tracked on.
    """

    tracks: pd.DataFrame | None
    tags: pd.DataFrame
    deployments: Deployments
    summary: dict[str, Any]
    outcomes: dict[str, Any] = field(default_factory=dict)
    matrices: dict[str, Any] = field(default_factory=dict)
    sync: Any = None
    daily: Any = None
    positions: Any = None
    written: set = field(default_factory=set)
    parts: TrackParts | None = None
    clocks: Any = None


#: The folder of the tags' folders in a study's folder (``tags/<id>/``: an id such as ``sync`` or ``tracks.csv`` is
#: never one of the study's own files).
TAGS_FOLDER = "tags"
def _chosen(names: Sequence[str] | None, sheet: TagSheet | None, tally: Tally,
            sync_tags: set[str]) -> list[tuple[str, TagSpec]]:
    """The tags to track (module docstring, step 3): each as named, with its spec."""
    if names:
        return [(n, spec_for(sheet, n)) for n in names]
    if sheet is not None:
        return [(t.transmitter, t) for t in sheet.of_role("animal", "reference")]
    counts, labelled = tally.tags, tally.labelled
    base = {t.rsplit(".", 1)[0] for t in sync_tags}  # a sync tag named per deployment (SYNC.k)
    return [(t, TagSpec(t)) for t in counts.index if t not in sync_tags and t not in base and t not in labelled]


def _key(name: str, detected) -> str | ModelError | None:
    """The detected tag ``name`` stands for (:func:`~sblsim.orchestrator.readers.transmitters.match`), None where
    none, the refusal where two code spaces share it."""
    try:
        return match(name, detected)
    except ModelError as exc:
        return exc


def _found(name: str, detected, ambiguous: str | None = None) -> str | None:
    """The detected tag ``name`` stands for (:func:`~sblsim.orchestrator.readers.transmitters.match`), None where none;
    a name two code spaces share is ``ambiguous`` (None: not found)."""
    try:
        return match(name, detected)
    except ModelError:
        return ambiguous


def _tag_detections(mine: pd.DataFrame, spec: TagSpec) -> pd.DataFrame:
    """A tag's detections with its depth sensor's values as depths [m] (unit ``m``) where the sheet says how."""
    if spec.sensor != "depth":
        return mine
    depth = spec.depths(mine["sensor_value"].to_numpy(float), mine["sensor_unit"].to_numpy(dtype=str))
    return mine.assign(sensor_value=depth, sensor_unit=np.where(np.isfinite(depth), "m", ""))


def run_study(detections: Path | Sequence[Path], receivers: Path | None, tags: Path | None = None, *, workdir: Path,
              sync: Path | None = None, format: str | None = None, crs: str | None = None, frame: str | None = None,
              chosen: Sequence[str] | None = None, sound_speed: float | None = None,
              sound_speed_file: Path | None = None, temperature: float | None = None, salinity: float | None = None,
              bin_hours: float = 1.0, workers: int | None = None, scheduler: str | None = None,
              toa_sigma: float | None = None, started: Callable[[list[str], dict[str, Any]], None] | None = None,
              ended: Callable[[dict[str, Any]], None] | None = None, temperature_path: Path | None = None,
              water_depth: float | None = None, force_interval: bool = False, spatial: Path | None = None,
              tz: str | None = None, refine_positions: bool = False,
              survey_sigma: float | None = None, resume: Resume | None = None,
              write_tags: bool = False, keep_tracks: bool = True) -> StudyOutcome:
    """Every tag of a study tracked (the module docstring).

    Parameters
    ----------
    detections : Path or sequence of Path
        The detections (any export): files, a folder of them, or an actel workspace (its deployments, stations and
        biometrics too: :mod:`~sblsim.orchestrator.readers.study_files`).
    receivers : Path or None
        The receivers or deployments (None: an actel workspace's).
    tags : Path, optional
        The tag sheet (or actel's biometrics).
    workdir : Path
        The folder each tag's folder is written into (its matrix, then its track).
    sync : Path, optional
        A synchronisation's folder (``sblsim sync --out DIR``).
    format, crs, frame
        The detections' format (None: read from the file) and the receivers' CRS and metric frame.
    chosen : sequence of str, optional
        The tags to track (full IDs or ids).
    sound_speed, sound_speed_file, temperature, salinity
        The sound speed: constant [m/s], a series (``epo`` or ISO times, ``sound_speed_m_s``), or calibrated from
        the pings with the fallback of a temperature [°C] and a practical salinity.
    bin_hours : float
        [h] the synchronisation's bins.
    workers, scheduler
        Worker processes, or a Dask scheduler.
    toa_sigma : float, optional
        [s] the timing noise of every arrival; default each receiver's from the synchronisation's residuals (made
        here, or the folder's ``offsets.csv`` ``toa_sigma_s``), else the tracker's default (``summary["toa_noise"]``
        says which: :func:`~sblsim.orchestrator.tracks.tracker.toa_noise`).
    started : callable, optional
        Called with the tags' folders and the summary so far, before the tracking.
    ended : callable, optional
        Called with each tracked tag's ``tags.csv`` row as its tracking ends.
    temperature_path : Path, optional
        A water-temperature series in UTC times (:func:`~sblsim.orchestrator.readers.water.read_temperature_series`,
        read here first), made each tag's sound speed by TEOS-10 at ``salinity``.
    water_depth : float, optional
        [m] the water's depth bounding every tag's depth (the deployments' depths needed); default each tag's the
        deepest ``bottom_depth`` of the deployments that heard it, where the deployments give it
        (:func:`~sblsim.orchestrator.tracks.depth.bottom_water_depth`; ``summary["water_depth"]`` says which).
    force_interval : bool
        Take each tag's stated interval (the sheet's) where its detections contradict it as a whole (said in a note
        with the detections it drops); else that tag is a refused row of ``tags.csv`` saying so
        (:func:`~sblsim.orchestrator.sync.toa.build_toa`).
    spatial : Path, optional
        actel's stations (``spatial.csv``) for actel's deployments (default: an actel workspace's).
    tz : str, optional
        The study's IANA time zone (``Europe/Copenhagen``) of actel's local times (deployments, release dates);
        without it such times are refused unless they carry their offset.
    refine_positions : bool
        Refine the receivers' horizontal positions from the moving tags' own pings and make the study again on them
        where that helps (:mod:`.study_positions`: ``summary["positions"]``, the outcome's ``positions``).
    survey_sigma : float, optional
        [m] the receivers' surveyed positions' σ per horizontal axis: with ``refine_positions`` the refinement's
        prior (default :data:`~sblsim.models.sync.identifiability.SURVEY_SIGMA`); without, the survey's stated
        error, a consider term of every σ (each tag's track, the reference tags' known positions at a deployment,
        the sync tags left out: :func:`~sblsim.orchestrator.telemetry.reference_tags.score`), 0: the positions taken
        as exact; default: the survey error the synchronisation made here sees in its residuals between receivers
        (:mod:`sblsim.models.sync.survey_error`), taken as the stated one where seen
        (``summary["clocks"]["survey_sigma_from"]`` ``"seen"``), else exact.
    resume : Resume, optional
        The tags kept by an interrupted run of the same output (:mod:`~sblsim.orchestrator.tracks.resume`): a tag
        whose inputs are unchanged is taken from it, each tag that ends is kept (``summary["resumed"]``).
    write_tags : bool
        Write each tracked tag's files into its folder as it ends (a study written to a folder:
        :func:`~sblsim.orchestrator.tracks.outputs.write`) and keep of it its track alone (``estimates``,
        ``errors``, ``bound`` and ``set_aside`` None; its matrix without rows; a reference tag kept whole, for its
        scoring), so that a season's tags are never in memory together; not with ``refine_positions`` (the
        refinement reads every moving tag's whole outcome).
    keep_tracks : bool
        With ``write_tags``, False: not even a tag's track kept (``StudyOutcome.parts``: ``tracks.csv`` written from
        the tags' files, ``StudyOutcome.tracks`` None), so that a season's rows are never in memory together.

    Returns
    -------
    StudyOutcome

    Raises
    ------
    ModelError
        A file refused by its reader, no detection inside a deployment, a synchronisation that cannot be made
        (one line). A tag that cannot be tracked is a row of ``tags.csv``.
    """
    begun = clock.perf_counter()
    arrow_pool()
    files = study_files(detections, receivers, spatial, tags)
    stored = len(files.detections) == 1 and is_store(files.detections[0])  # read a batch of tags at a time
    deployments, data, sheet, notes = read_study(files, format, crs, frame, tz, detections=not stored)
    source = StudyDetections.stored(files.detections[0], format) if stored else StudyDetections(data)
    data = source.data
    deployments, said = serials_as_logged(deployments, source.receivers())  # VR2AR-461000 as 461000
    notes.extend([said] if said else [])
    series = read_sound_speed(sound_speed_file) if sound_speed_file is not None else None
    if temperature_path is not None:  # refused here in one line, not once per tag
        read_temperature_series(temperature_path, 0.0, absolute=True)
    assigned, tally = source.assigned(deployments)
    sheet_deployments = deployments  # each tag's rows of a store assigned as the sync tags' were
    # the deployments that logged the study: the array from here on
    array = counted_in_water(tally.kept, tally.span, tally.serials, assigned, deployments)
    deployments, assigned = array.deployments, array.assigned
    if array.line():
        notes.append(array.line())
    bottom, water_info = study_water_depth(deployments.table, water_depth, notes)
    detected = tally.tags.index.to_numpy(dtype=object)
    sync_tags = set(assigned.hydrophones["sync_tag"]) - {""}
    if sheet is not None:
        sync_tags |= {k for t in sheet.of_role("sync") if (k := _found(t.transmitter, detected)) is not None}
    asked = _chosen(chosen, sheet, tally, sync_tags)
    if not asked:
        raise ModelError("tags: no tag to track (the tag sheet lists no animal or reference tag, and every detected "
                         "tag is a sync tag); allowed: a sheet with animal or reference tags, or --tag")
    if all(_found(n, detected, ambiguous=n) is None for n, _ in asked):  # said before the clocks are fitted
        counts = tally.tags
        raise ModelError(f"tag: none of the tags asked for ({', '.join(n for n, _ in asked[:8])}) is detected inside "
                         f"a deployment in {data.source!r}; allowed: a detected tag, e.g. "
                         + ", ".join(f"{t} ({c} detections)" for t, c in counts.head(6).items()))
    rounded = rounding_warning(assigned.detections, assigned.hydrophones, sound_speed, tally.quantum)
    if rounded:
        notes.append(rounded)

    def attempt(deployments, assigned, notes: list[str], workdir: Path, survey=None, errors=None,
                fitted=None, untracked=None) -> StudyOutcome:
        """The study from its clocks on, on these deployments' positions, its tags' folders in ``workdir``; ``survey``
        each receiver's position's error [m per axis] in the reference tags' and sync tags' scores and in each tag's
        track (else the stated survey's); ``errors`` their joint covariance (names, (2R, 2R) [m²]: refined together)
        in each moving tag's consider terms; ``fitted`` the clocks and their summary as the tags' pings checked them
        (:func:`~.study_offsets.fitted_study`); ``untracked`` the tags' matrices made, none tracked (None: where
        the clocks taken as logged are to be checked)."""
        scored = stated if survey is None else survey
        clocks, table, clocks_info, synced = (fitted[0], assigned.hydrophones, fitted[1], None) if fitted else \
            kept_study_clocks(resume, sync, assigned, deployments, sound_speed, series, bin_hours, notes, scored,
                              not refine_positions, light and stored)
        notes.extend(clocks_said(fitted[1]) if fitted else [])
        clocks, clocks_info = (clocks, clocks_info) if fitted else aligned(clocks, clocks_info, assigned, table)
        # the synchronisation's row per sync-tag arrival kept on disk while the tags' matrices are made and the
        # tags tracked (read back for the reference tags' scores and the study's sync/ folder)
        with spilled(synced, "residuals", workdir) if light and synced is not None else contextlib.nullcontext():
            taken = taken_survey(stated, refine_positions, clocks_info)  # the survey's error in every σ by receiver
            survey, taken = (taken, None) if survey is None and isinstance(taken, dict) else (survey, taken)
            scored = taken if survey is None else survey
            _, noise_info = toa_noise(toa_sigma, clocks.toa_sigma, clocks.receivers)
            frame_crs = None if deployments.frame is None else deployments.frame.crs
            rows: dict[str, dict[str, Any]] = {}
            jobs, matrices, folders = [], {}, {}
            logged = clocks_info["source"].startswith("as logged")
            untracked = fits(clocks_info["source"]) if untracked is None else untracked
            lean = light and not untracked  # (a clocks' fit reads the tags' matrices)
            keys = [_key(name, detected) for name, _ in asked]
            first: dict[str, int] = {}  # each tag's folder, by the first name asking for it
            for i, key in enumerate(keys):
                if isinstance(key, str):  # (never one of the study's own names)
                    first.setdefault(f"{TAGS_FOLDER}/{folder_name(key, 'tag')}", i)
            built: dict[int, tuple] = {}  # each tag's folder, matrix, job and notes, in the order read
            for i, stored_rows in source.frames([k if isinstance(k, str) else None for k in keys], tally,
                                                sheet_deployments, assigned):
                name, spec = asked[i]
                key = keys[i]
                row = {"transmitter": name, "name": spec.name, "role": spec.role, "motion": spec.motion,
                       "ping_type_stated": spec.described(), "status": "refused", "reason": "", "reason_code": "",
                       **unpositioned(0)}
                try:
                    if isinstance(key, ModelError):
                        raise key
                    if key is None:
                        raise ModelError(f"tag: {name!r} is never detected inside a deployment in {data.source!r}")
                    folder = f"{TAGS_FOLDER}/{folder_name(key, 'tag')}"
                    if first[folder] != i:
                        raise ModelError(f"tag: {name!r} is tracked twice (as {key})")
                    mine = _tag_detections(stored_rows, spec)
                    counted = count(mine, table, clocks, logged)  # the true reason first: counted before any interval
                    row |= {"tag": key, "detections": int(len(mine)), "receivers": len(counted.per_receiver),
                            "time_resolution_s": counted.quantum} | unpositioned(counted.pings, counted.at_once)
                    found = verdict(counted, mine["time"].to_numpy(float), spec.motion == "stationary",
                                    clocks_info["source"] == TOO_COARSE)
                    if found is not None:
                        rows[name] = row | {"reason_code": found[0], "reason": found[1]} | unpositioned(
                            counted.pings, counted.at_once, found[0])
                        continue
                    kind = {"type": spec.ping_type, "burst_interval_s": None if spec.burst_interval is None else
                            list(spec.burst_interval), "interval_s": spec.interval,
                            "burst_sequence": None if spec.burst_sequence is None else spec.burst_sequence.name}
                    matrix = heard_columns(build_toa(replace(assigned.detections, frame=mine), table, clocks, key,
                                                      spec.shortest_interval(), kind, force_interval, TRACK_OPTIONS))
                    if survey is not None:  # refined positions: each one's own error in the track's σ (sigma_m)
                        matrix.survey_sigma = np.array([survey.get(n, max(survey.values())) for n in matrix.names])
                    said = [f"tag {key}: {matrix.summary['interval_warning']}"] if matrix.summary.get(
                        "interval_warning") else []
                    heard = np.isfinite(matrix.toa).sum(axis=1)
                    row |= unpositioned(len(heard), int((heard >= counted.need).sum()))
                    write_toa_files(matrix, workdir / folder, said)
                    options = {"smooth": True, "sound_speed": sound_speed, "sound_speed_path": speed_path,
                               "temperature": temperature, "salinity": salinity, "ping_type": spec.ping_type,
                               "burst_interval": spec.burst_interval, "burst_sequence_path": spec.burst_sequence,
                               "motion": spec.motion, "crs": frame_crs, "time_origin": matrix.origin,
                               "other_filters": False, "toa_sigma": toa_sigma, "water_depth": water_depth,
                               "force_interval": force_interval, "temperature_path": water_path, "survey_sigma": taken}
                    if errors is not None and spec.motion != "stationary":  # refined together: correlated errors
                        options["survey_covariance"] = errors
                    options |= fitted_options(clocks_info, spec.motion != "stationary")  # (clocks fitted here)
                    if bottom is not None:  # each tag's water from the bottom at the receivers that heard it
                        options["water_depth"] = bottom_water_depth(bottom[matrix.names].to_numpy(float),
                                                                    np.isfinite(matrix.toa).any(axis=0))
                    if lean:  # written: its rows let go (a season's matrices are never in memory together), its empty
                        # tables made anew (a slice of them, a view, would hold them whole)
                        matrix = replace(matrix, toa=np.empty((0, matrix.toa.shape[1])), pings=emptied(matrix.pings))
                    built[i] = (folder, matrix, (folder, workdir / folder / "toa.txt",
                                                 workdir / folder / "receivers.csv", options), said)
                    row["folder"] = folder
                except ModelError as exc:
                    code = code_of(str(exc))
                    row |= {"reason": str(exc), "reason_code": code} | unpositioned(row["pings"], row["pings_at_once"],
                                                                                     code)
                rows[name] = row
            stored_rows = None  # (the last tag's rows; a store's sync-tag rows let go already where synchronised here)
            if lean:  # no later stage reads the detections' rows (the tags' matrices are made): not held through the
                assigned.detections.frame = emptied(assigned.detections.frame)  # tracking (a season's sync tags' rows)
            for i in sorted(built):  # in the order asked, whatever the order read
                folder, matrix, job, said = built.pop(i)
                notes.extend(said)
                matrices[folder] = matrix
                folders[asked[i][0]] = folder
                jobs.append(job)
                if bottom is not None:
                    water_info["per_tag_m"][keys[i]] = job[3]["water_depth"]
            summary = _summary(data, deployments, tally, clocks_info, sheet, notes)
            summary["toa_noise"] = noise_info
            if water_info:
                summary["water_depth"] = water_info
            if started is not None and not untracked:
                started([j[0] for j in jobs], summary)
            by_folder = {folder: name for name, folder in folders.items()}
            specs = dict(asked)
            tick = clock.perf_counter()
            parts = TrackParts(workdir) if lean and not keep_tracks else None
            finish = {f: partial(written_main, out=workdir / f) for f, *_ in jobs  # a tag's files written as it ends
                      if lean and specs[by_folder[f]].role != "reference"}  # (in its worker, on this machine)

            def done(folder: str, result):
                name = by_folder[folder]
                if isinstance(result, str):  # a staging folder is no path the user gave: the tag's folder in the
                    result = result.replace(str(workdir) + os.sep, "")  # study's
                rows[name] |= tracked_row(result, clock.perf_counter() - tick, rows[name])
                if ended is not None:
                    ended(rows[name])
                if parts is not None and not isinstance(result, str) and rows[name]["status"] == "tracked":
                    parts.add(rows[name]["tag"], folder, result.track)  # tracks.csv's rows from its file, at the end
                if folder in finish and not isinstance(result, str):  # its files written as it ended: its track kept
                    return replace(result, estimates=None) if parts is None else replace(result, estimates=None,
                                                                                         track=None)
                return None  # (a reference tag kept whole, for its scoring: its files written with the study's)

            kept = 0 if resume is None else resume.kept
            release()  # what making the tags' matrices freed handed back before the tracking
            results = run_tracks(jobs, workers, scheduler, done, resume, finish) if jobs and not untracked else {}
        if resume is not None and (resume.kept > kept or resume.taken):
            summary["resumed"] = {"tags_kept": resume.kept - kept, "tags": len(jobs), "taken": resume.taken[:]}
            resume.taken.clear()
        # a tag's track only where it has a position: a tag the tracker positioned nowhere is a row saying why
        # in the order asked, not the order the workers ended them in (tracks.geojson's receivers name their tags so)
        outcomes = {f: results[f] for f, *_ in jobs if f in results and rows[by_folder[f]]["status"] == "tracked"}
        table_tags = pd.DataFrame([rows[n] for n, _ in asked], columns=list(TAG_COLUMNS))
        table_tags = table_tags.astype({c: "Int64" for c in COUNT_COLUMNS})  # counts as counts, empty where none
        tracks = combined_tracks(outcomes, matrices) if parts is None else None
        summary["tags"] = {"asked": len(asked), "tracked": int((table_tags["status"] == "tracked").sum()),
                           "refused": int((table_tags["status"] == "refused").sum()),
                           "reasons": {str(k): int(v) for k, v in table_tags["reason_code"].value_counts().items()
                                       if k}}
        summary["reference_tags"] = score_references(asked, table_tags, outcomes, deployments, synced, sync, scored)
        summary["wall_time_s"] = clock.perf_counter() - begun
        return StudyOutcome(tracks, table_tags, deployments, summary, outcomes, matrices, synced, tally.daily,
                            written={f for f in outcomes if outcomes[f].estimates is None}, parts=parts, clocks=clocks)

    light = write_tags and not refine_positions  # the refinement reads every moving tag's matrix and estimates
    speed_path = None if sound_speed_file is None else Path(sound_speed_file).absolute()
    water_path = None if temperature_path is None else Path(temperature_path).absolute()
    stated = None if refine_positions else survey_sigma  # the survey's stated error in every σ (else the prior)
    outcome, fitted = attempt(deployments, assigned, list(notes), workdir), None
    speed_given = sound_speed if sound_speed_file is None else None  # (a series: its scale fitted with the clocks)
    if fits(outcome.summary["clocks"]["source"]):  # clocks taken as logged: checked against the tags' pings first
        outcome, fitted = fitted_study(outcome, lambda f, u: attempt(deployments, assigned, list(notes), workdir,
                                                                     fitted=f, untracked=u), deployments,
                                       assigned.kept_span(), workdir, TAGS_FOLDER, speed_given, toa_sigma)
    if refine_positions:
        outcome = refined_study(outcome, lambda d, a, q, e: attempt(d, a, list(notes), workdir / REFINED_FOLDER, q,
                                                                    e, fitted, False),
                                deployments, assigned, SURVEY_SIGMA if survey_sigma is None else survey_sigma,
                                workdir, TAGS_FOLDER)
    outcome.summary["wall_time_s"] = clock.perf_counter() - begun
    return outcome


def _summary(data: Detections, deployments: Deployments, tally: Tally, clocks: dict[str, Any],
             sheet: TagSheet | None, notes: list[str]) -> dict[str, Any]:
    """``study.json`` before the tracking (the files, the frame, the detections used and set aside, the clocks)."""
    return {"detections": {"file": data.source, "format": data.format, "rows": tally.rows, "used": tally.used,
                           "set_aside": tally.rows - tally.used, "reasons": tally.set_aside,
                           "ignored_columns": data.ignored_columns, "duplicates": data.duplicates,
                           "first_utc": iso_utc([tally.span[0]])[0], "last_utc": iso_utc([tally.span[1]])[0]},
            "receivers": deployments.summary(), "frame": deployments.summary()["frame"], "clocks": clocks,
            "tag_sheet": None if sheet is None else {"file": sheet.source, "transmitters": len(sheet.tags)},
            "times": "UTC: each row's time is its estimated emission on the reference receiver's clock, which "
                     "the synchronisation takes as UTC", "notes": notes}


__all__ = ["StudyOutcome", "TAGS_FOLDER", "TAG_COLUMNS", "TRACK_COLUMNS", "combined_tracks", "run_study"]
