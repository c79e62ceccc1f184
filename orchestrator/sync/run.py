"""``sblsim sync``'s work: the sync tags' arrivals picked from raw detections, grouped into emissions, the clocks
fitted (:func:`sblsim.models.sync.clocks.fit_clocks`) and each sync tag positioned with the clocks fitted without
it (:func:`sblsim.models.sync.positions.position_emissions`), as tables and a summary.

Which arrivals are used: a detection of a tag that the receivers table names as a receiver's ``sync_tag``, at a
receiver of that table. A tag without a receiver row (its position unknown) is left out (named: a ``species``
column's ``Sync`` label shows it); so are the detections at receivers missing from the table. A receiver that never
hears a sync-tag emission that another receiver hears cannot be synchronised: named, left out, the rest synchronised.

With ``refine_positions`` the receivers' horizontal positions are refined with the clocks (a prior of the survey's
sigma at the table's positions: :class:`sblsim.models.sync.clocks.Geometry`), written as ``positions.csv``, and each
sync tag's leave-one-out fixes are compared with its receiver's position refined **without that tag's arrivals**
(from the other tags its receiver hears, and the prior), their NEES with the two covariances summed.

The tables are made by their own modules: ``sync_tags.csv`` by :mod:`.sync_tags`, ``positions.csv`` by
:mod:`.refined_positions`, ``offsets.csv`` and ``sync.json`` by :mod:`.clock_tables`; a study's files are
synchronised by :mod:`.study_sync`.
"""

from __future__ import annotations

import time as clock
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError, shown
from sblsim.models.errors import ConfigError
from sblsim.models.sync.breaks import fit_with_breaks
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clock_parts import part_shifts
from sblsim.models.sync.clocks import Geometry
from sblsim.models.sync.emissions import MIN_SHARED, SyncTagsUnheard, components, sync_emissions
from sblsim.models.sync.end_breaks import cut_ends
from sblsim.models.sync.identifiability import SURVEY_SIGMA
from sblsim.models.sync.noise import receiver_noise
from sblsim.models.sync.resolution import residual_warning, rounding_sigma, time_quantum
from sblsim.models.sync.season import breaks_in_windows
from sblsim.models.sync.windows import OVERLAP_HOURS, WINDOW_DAYS, season_windows
from sblsim.orchestrator.io.arguments import whole
from sblsim.orchestrator.io.memory import emptied, release
from sblsim.orchestrator.readers.detections import Detections, reset_line
from sblsim.orchestrator.readers.transmitters import match
from sblsim.orchestrator.sync import segments
from sblsim.orchestrator.sync.clock_tables import _offsets, _reasons, _summary
from sblsim.orchestrator.sync.declared import checks_before_fit
from sblsim.orchestrator.sync.refined_positions import _identify, _kept, _positions
from sblsim.orchestrator.sync.survey_seen import seen_in_fit
from sblsim.orchestrator.sync.sync_tags import _sync_tags

#: The detections' columns the synchronisation copies with its rows (others, as a VUE export's sensor values, not).
SYNC_COLUMNS = ("receiver", "serial", "tag", "time", "line", "clock_part", "species")
#: A bin with fewer kept arrivals than this at a receiver is bridged by the drift model (flagged).
MIN_BIN_ARRIVALS = 5
#: The bins' allowed width [h].
BIN_HOURS_RANGE = (0.05, 168.0)
#: [s] the longest a receiver is taken to have been off between the last detection before its time went back in
#: the file's order and the first after (a download's), for the search of its new part's shift (breaks.part_shifts).
RESET_GAP = 86400.0
#: The note naming the receivers table's sync tags no receiver heard (a sync tag that died, or an ID mistyped).
NEVER_HEARD = "sync tags never heard"


@dataclass
class SyncOutcome:
    """What :func:`synchronise` computed: ``summary`` (``sync.json``), ``offsets``, ``residuals`` and
    ``sync_tags`` (the CSV files' tables), the receivers' table, the fit and, with the positions refined,
    ``positions`` (``positions.csv``)."""

    summary: dict[str, Any]
    offsets: pd.DataFrame
    residuals: pd.DataFrame
    sync_tags: pd.DataFrame
    receivers: pd.DataFrame
    fit: ClockFit = field(repr=False)
    origin: float = 0.0
    positions: pd.DataFrame | None = None


def corrected_times(outcome: SyncOutcome, receiver: str, times: Any, part: Any = 1) -> np.ndarray:
    """Times logged by ``receiver`` (a synchronised receiver's serial) [s since 1970 UTC on its clock] in its clock
    ``part`` (the detections' ``clock_part``, 1 first) on the reference receiver's clock (NaN where its clock broke:
    a time between two of its clock segments, set aside, or outside the part's span).

    Raises
    ------
    ConfigError
        A part the receiver does not have (one line naming its parts).
    """
    names = outcome.receivers["receiver"].tolist()
    t = np.asarray(times, float) - outcome.origin
    fit = outcome.fit
    k = names.index(receiver)
    parts = [1] if fit.site is None or fit.part is None else sorted({int(p) for p in fit.part[fit.site == k]})
    number = whole(part)
    if number not in parts:
        raise ConfigError(f"part: {shown(part)} is not a clock part of receiver {receiver}; allowed: "
                          f"{', '.join(map(str, parts))} (the detections' clock_part)")
    j = fit.rows_at(np.full(t.shape, k), t, np.full(t.shape, number))  # its part's segment where its clock broke
    return np.where(j >= 0, t + outcome.origin - fit.offset(np.maximum(j, 0), t), np.nan)


def _gaps(tag: np.ndarray, receiver: np.ndarray, time: np.ndarray, n_tags: int) -> np.ndarray:
    """(tags,) [s]: a third of each tag's typical interval between detections at the receiver hearing it most
    (the largest spread of one emission's arrivals the grouping allows), in [1, 3600] s."""
    gap = np.full(n_tags, 60.0)
    for i in range(n_tags):
        mine = tag == i
        if mine.sum() < 3:
            continue
        best = np.bincount(receiver[mine]).argmax()
        steps = np.diff(np.sort(time[mine & (receiver == best)]))
        steps = steps[steps > 0]
        if len(steps):
            gap[i] = np.clip(np.median(steps) / 3, 1.0, 3600.0)
    return gap


def synchronise(detections: Detections, hydrophones: pd.DataFrame, sound_speed: float | None = None,
                series: tuple[np.ndarray, np.ndarray] | None = None, bin_hours: float = 1.0,
                reference: str | None = None, leave_one_out: bool = True, refine_positions: bool = False,
                survey_sigma: float | Mapping[str, float] | None = None, timings: dict | None = None,
                receivers_file: str | None = None, alternatives: dict[str, pd.DataFrame] | None = None,
                window_days: float | None = WINDOW_DAYS, take_seen: bool = True,
                release_rows: bool = False) -> SyncOutcome:
    """Synchronise the receivers' clocks (the module docstring).

    Before the clocks are fitted (once the sync tags' arrivals are grouped into emissions) the times' rounding is
    weighed against the array (:func:`sblsim.models.sync.resolution.check_resolution`: refused where it leaves
    nothing to fit) and the table's distances against the sync tags' clock-free travel times
    (:func:`~sblsim.orchestrator.sync.declared.check_sync_positions`: refused in another unit, said where slightly
    off, naming ``receivers_file``); after, a rounding that is the larger part of the residuals is said
    (:func:`~sblsim.models.sync.resolution.residual_warning`).

    With ``refine_positions`` the receivers' positions are refined only where the sync tags determine them
    (:mod:`sblsim.models.sync.identifiability`: the others keep the table's, ``positions.csv``'s ``reason``), and
    the refinement is kept only where it does not worsen the sync tags' leave-one-out: the synchronisation with the
    table's positions is made too (its NEES with ``survey_sigma`` as the table's error), and where the refined
    positions' median leave-one-out error is larger, the table's outcome is returned (``positions.csv`` the
    table's, ``refined`` false, said in a warning). ``summary["positions"]["leave_one_out"]`` holds both.

    Parameters
    ----------
    detections : Detections
        The raw detections (:func:`~sblsim.orchestrator.readers.detections.read_detections`).
    hydrophones : pandas.DataFrame
        The receivers (:func:`~sblsim.orchestrator.readers.hydrophones.read_hydrophones`).
    sound_speed : float, optional
        [m/s] a constant sound speed.
    series : (numpy.ndarray, numpy.ndarray), optional
        A sound-speed series: times [s] and speeds [m/s], interpolated at each arrival. Neither given: one sound
        speed estimated with the clocks.
    bin_hours : float
        [h] the time bins' width.
    reference : str, optional
        The reference receiver's serial; default the receiver with the most arrivals shared with others.
    leave_one_out : bool
        Position each sync tag with the clocks fitted without its arrivals (else with the full fit).
    refine_positions : bool
        Refine the receivers' horizontal positions with the clocks (default: the table's fixed).
    survey_sigma : float or mapping, optional
        [m] the table's horizontal sigma per axis (the survey's stated error): with ``refine_positions`` the
        refinement's prior (default :data:`SURVEY_SIGMA`); without, a term of each sync tag's NEES
        (``sync_tags.csv``: its fixes' or place's covariance and the survey's of its receiver's position summed, and
        of each place's consider covariance), then in ``summary["survey_sigma_m"]``; without ``refine_positions``
        also each receiver's, by its serial (a receiver not named: exact), or 0: the table's positions taken as
        exact. Default without ``refine_positions``: the survey error the residuals between receivers show
        (:mod:`sblsim.models.sync.survey_error`, ``summary["survey_error"]``) where seen, taken as the stated one
        (``summary["survey_sigma_from"]`` ``"seen"``), else exact.
    take_seen : bool
        False: the survey error seen is said, not taken (a study whose positions are refined next).
    release_rows : bool
        ``detections``' rows emptied (:func:`~sblsim.orchestrator.io.memory.emptied`) once the sync tags' arrivals
        are taken from them and checked: the caller reads them no more, and a season's rows are not held through the
        fit. Not with ``refine_positions`` (two synchronisations read them).
    timings : dict, optional
        Filled with each stage's seconds (``grouping``, ``fit`` and the fit's own stages, ``leave_one_out``,
        ``tables``) for a benchmark (the refined synchronisation's).
    receivers_file : str, optional
        The receivers file the table was read from, named where its positions are refused or said (None: "receivers").
    alternatives : dict of str to pandas.DataFrame, optional
        Other readings of the table's positions, by what they assume (``"latitude and longitude swapped"``): the same
        receivers' ``x``, ``y`` [m] as read that way; where the table is refused for its distances and one of these
        fits the travel times, the refusal names it as the cause.
    window_days : float or None
        [days] a season longer than this and its overlaps fitted in windows of it
        (:mod:`sblsim.models.sync.windows`, ``summary["windows"]``); None or 0: one fit. With ``refine_positions``
        one fit (the positions are the season's).

    Returns
    -------
    SyncOutcome

    Raises
    ------
    ModelError
        No sync tag heard by two receivers, a reference receiver not in the table or not synchronisable; with
        ``refine_positions``, no receiver's position determined by the sync tags (a sparse sync array); times rounded
        too coarsely for the array, a table in another unit than metres (one line each, before the clocks are
        fitted).
    TypeError
        Each receiver's ``survey_sigma`` with ``refine_positions`` (the refinement takes one prior).
    """
    started = clock.perf_counter()
    args = (detections, hydrophones, sound_speed, series, bin_hours, reference, leave_one_out)
    if not refine_positions:
        each = isinstance(survey_sigma, Mapping)  # each receiver's (a study on refined positions)
        table = np.array([float(survey_sigma.get(r, 0.0)) for r in hydrophones["receiver"]]) if each else \
            survey_sigma
        outcome = _synchronise(*args, timings=timings, table_sigma=None if not each and table == 0 else table,
                               receivers_file=receivers_file, alternatives=alternatives, window_days=window_days,
                               survey="taken" if survey_sigma is None and take_seen else "said",
                               release_rows=release_rows)
        if survey_sigma is not None:  # said where stated (the sync tags' NEES holds it)
            outcome.summary |= {"survey_sigma_m": dict(survey_sigma) if each else float(survey_sigma),
                                "survey_sigma_from": "stated"}
        return outcome
    if isinstance(survey_sigma, Mapping):
        raise TypeError("survey_sigma: one prior for the refinement, not each receiver's")
    survey_sigma = SURVEY_SIGMA if survey_sigma is None else survey_sigma
    refined = _synchronise(*args, refine_positions=True, survey_sigma=survey_sigma, timings=timings,
                           receivers_file=receivers_file, alternatives=alternatives)
    table = _synchronise(*args, table_sigma=survey_sigma, receivers_file=receivers_file, alternatives=alternatives)
    outcome = _kept(refined, table, float(survey_sigma))
    outcome.summary["wall_time_s"] = clock.perf_counter() - started
    return outcome


def _synchronise(detections: Detections, hydrophones: pd.DataFrame, sound_speed: float | None = None,
                 series: tuple[np.ndarray, np.ndarray] | None = None, bin_hours: float = 1.0,
                 reference: str | None = None, leave_one_out: bool = True, refine_positions: bool = False,
                 survey_sigma: float = SURVEY_SIGMA, timings: dict | None = None,
                 table_sigma: float | np.ndarray | None = None, receivers_file: str | None = None,
                 alternatives: dict[str, pd.DataFrame] | None = None, window_days: float | None = None,
                 survey: str | None = None, release_rows: bool = False) -> SyncOutcome:
    """One synchronisation, with the positions refined (only where the sync tags determine them: else refused) or
    the table's (the sync tags' NEES with ``table_sigma`` [m] per axis as the table's error where given); the rest
    as :func:`synchronise` (its parameters, ``table_sigma`` and ``survey`` aside). ``survey`` ``"said"``: the survey
    error the residuals show (:func:`~sblsim.orchestrator.sync.survey_seen.seen_in_fit`) in
    ``summary["survey_error"]``; ``"taken"`` too, and where seen it is the table's error (``table_sigma``) the sync
    tags are scored with, ``summary["survey_sigma_m"]`` (``survey_sigma_from`` ``"seen"``).

    Returns
    -------
    SyncOutcome

    Raises
    ------
    ModelError
        No sync tag heard by two receivers, a reference receiver not in the table or not synchronisable.
    """
    started, notes, frame = clock.perf_counter(), [], detections.frame
    rows_read = len(frame)  # (sync.json's count, the rows let go before it is written)
    names = hydrophones["receiver"].tolist()
    index = {name: k for k, name in enumerate(names)}
    tags = hydrophones.loc[hydrophones["sync_tag"] != "", ["sync_tag", "receiver"]]
    # each sync tag as the detections name it (a full ID for an id, or the other way round: transmitters.match)
    detected = frame["tag"].unique()
    tag_names = [match(t, detected) or t for t in tags["sync_tag"]]
    if len(set(tag_names)) != len(tag_names):
        twice = next(t for t in tag_names if tag_names.count(t) > 1)
        raise ModelError(f"sync: sync tag {twice} is named at two receivers (as an id and as a full ID); allowed: "
                         "one receiver per sync tag")
    tag_index = {t: k for k, t in enumerate(tag_names)}
    tag_home = np.array([index[r] for r in tags["receiver"]], np.int64)
    unknown = sorted(set(frame["receiver"]) - set(index))
    if unknown:
        notes.append(f"receivers not in the receivers table, their detections left out: {', '.join(unknown[:20])}")
    if "species" in frame:
        labelled = set(frame.loc[frame["species"].str.lower() == "sync", "tag"]) - set(tag_index)
        if labelled:
            notes.append("tags labelled Sync without a receiver row (position unknown), left out: "
                         + ", ".join(sorted(labelled)[:20]))
    pick = frame["tag"].isin(tag_index).to_numpy() & frame["receiver"].isin(index).to_numpy()
    held = [c for c in frame.columns if c in SYNC_COLUMNS]
    # a season's other columns never copied; rows that are all the sync tags' (a study's) not copied at all
    sync = frame if pick.all() and held == list(frame.columns) else frame.loc[pick, held]
    if len(sync) < 2:
        raise SyncTagsUnheard("fewer than two detections of the receivers table's sync tags (an extract of a tag "
                              "project holds its own tags alone)")
    receiver = sync["receiver"].map(index).to_numpy(np.int64)
    tag = sync["tag"].map(tag_index).to_numpy(np.int64)
    origin = float(np.floor(sync["time"].min()))
    time = sync["time"].to_numpy(float) - origin
    n_receivers = len(names)
    never = [tag_names[i] for i in range(len(tag_names)) if not (tag == i).any()]
    if never:
        notes.append(f"{NEVER_HEARD}: {', '.join(never)}")

    # a receiver's time gone back (the reader's clock_part): each later part a clock, aligned for the grouping alone
    part = sync["clock_part"].to_numpy(np.int64) if "clock_part" in sync else None
    if part is not None and (part > 1).any():
        search = max(abs(r["step_s"]) for r in detections.clock_resets) + RESET_GAP
        steps = {(index[r["receiver"]], r["clock_part"]): r["step_s"] for r in detections.clock_resets
                 if r["receiver"] in index}
        shift, _ = part_shifts(tag, receiver, part, time, search, steps=steps)
        aligned = time - shift
    else:
        part, aligned = None, time
    emission, duplicate, single = sync_emissions(tag, receiver, aligned, _gaps(tag, receiver, aligned,
                                                                                len(tag_names)))
    used = ~duplicate & ~single
    xyz = hydrophones[["x", "y", "z"]].to_numpy(float)
    dim = 3 if np.isfinite(xyz[:, 2]).all() else 2
    positions = xyz[:, :dim]
    distance = np.linalg.norm(positions[tag_home[tag]] - positions[receiver], axis=1)
    # said or refused before the work: the table's unit and the times' rounding
    notes_first = checks_before_fit(sync, detections.source, hydrophones, receivers_file, names, tag_names, tag_home,
                                    receiver, tag, emission, duplicate, positions, sound_speed, series,
                                    alternatives or {})
    resets, line = _resets(detections, sync), sync["line"].to_numpy()
    del sync, frame  # (a copy of the season's sync-tag rows, not held through the fit)
    if release_rows:  # nor the caller's rows (it reads them no more)
        detections.frame = emptied(detections.frame)

    if sound_speed is not None:
        slowness, speed_source = np.full(len(time), 1.0 / sound_speed), "given"
    elif series is not None:
        times, speeds = series
        absolute = time + origin
        if absolute.min() < times[0] - 86400 or absolute.max() > times[-1] + 86400:
            notes.append("the sound-speed series does not cover the detections' span (more than a day outside): "
                         "its end values held")
        slowness = 1.0 / np.interp(absolute, times, speeds)
        speed_source = "series"
    else:
        slowness, speed_source = None, "estimated"

    counts = np.bincount(receiver[used], minlength=n_receivers)
    if reference is None:
        start = int(np.argmax(counts))
    else:
        if reference not in index:
            raise ModelError(f"reference: receiver {reference!r} is not in the receivers table; allowed: one of "
                             f"{', '.join(names[:30])}")
        start = index[reference]
    roots, able = components(receiver[used], emission[used], n_receivers)  # connected()'s graph, made once
    linked = (roots == roots[start]) & able
    if not able.any():
        raise SyncTagsUnheard(f"no two receivers share {MIN_SHARED} emissions of a sync tag (each heard by one "
                              "receiver alone)")
    if not linked[start]:
        raise ModelError(f"reference: receiver {names[start]} shares fewer than {MIN_SHARED} sync-tag emissions with "
                         "another receiver; allowed: a receiver that can be synchronised")
    left_out = [names[j] for j in range(n_receivers) if not linked[j]]
    if left_out:
        notes.append(f"{segments.NOT_SYNCHRONISED} (they share fewer than {MIN_SHARED} sync-tag emissions "
                     f"with the synchronised receivers: an offset and a drift need two), left out: "
                     f"{', '.join(left_out)}")
    width, timings = bin_hours * 3600.0, {} if timings is None else timings
    timings["grouping"] = clock.perf_counter() - started
    release()  # the rows' text columns' lookups and copies freed: not kept through the fit (a season's 0.1 GiB)
    tick = clock.perf_counter()
    geometry = Geometry(tag_home[tag], positions, float(survey_sigma)) if refine_positions else None
    # a receiver whose clock jumped or went back split into clock segments (sblsim.models.sync.breaks): each clock
    # row a receiver's (its first segment) or a later segment's, `rows` each arrival's (-1 set aside at a break)
    # a season longer than a window and its overlaps fitted window by window (sblsim.models.sync.windows)
    windows = season_windows(time[used], width, window_days * 86400.0, OVERLAP_HOURS * 3600.0) \
        if window_days and geometry is None else None
    fit = fit_with_breaks(receiver, emission, time, distance, slowness, used, linked, start, width, tag,
                          geometry=geometry, timings=timings, part=part) if windows is None else \
        breaks_in_windows(windows, receiver, emission, time, distance, slowness, used, linked, start, width, tag,
                          timings=timings, part=part)
    # a break within a few arrivals of a clock's end (too near to fit a segment): its times from there set aside
    fit, ends = cut_ends(fit, receiver, emission, time, distance, slowness, used, tag)
    fit, lost, note = segments.without_undetermined(fit, receiver, time, used, names)
    linked &= ~lost
    notes.extend([note] if note else [])
    identified = fits = None
    if refine_positions:  # refined only where the sync tags determine the positions; else refused
        args = (receiver, tag, emission, time, distance, slowness, used, start, width)
        # the others keep the table's positions in positions.csv; the fit keeps every receiver at the survey's
        # prior (held tightly at the table's, the held receivers would fix the array's datum with a false certainty:
        # on 8 simulated receivers, one held, the refined ones' sigmas a third of their errors)
        identified, fits = _identify(fit, args, geometry, positions, names, tag_names, linked, float(survey_sigma))
    rows, site = segments.clock_rows(fit, receiver)
    synced = np.isfinite(fit.knots[:, 0])  # per clock row
    on = (rows >= 0) & synced[np.maximum(rows, 0)]  # per arrival: on a synchronised clock
    timings["fit"] = clock.perf_counter() - tick
    if refine_positions:
        moved = positions.copy()
        moved[:, :2] += fit.shift
        distance = np.linalg.norm(moved[tag_home[tag]] - moved[receiver], axis=1)
    bridged = (fit.counts < MIN_BIN_ARRIVALS) & synced[:, None]
    bridged[start] = False

    offsets = _offsets(fit, names, synced, bridged, origin)
    # each receiver's timing noise (its residuals' robust scale and its clock's sigma), for the tracker
    noise = receiver_noise(receiver, fit.standardised * fit.scale[np.maximum(rows, 0)],
                           segments.receiver_sigmas(fit, n_receivers), linked, time, fit.edges)
    if np.isfinite(noise.sigma[linked]).all():  # (none where no receiver has residuals enough to measure it)
        offsets["toa_sigma_s"] = noise.sigma[[names.index(r) for r in offsets["receiver"]]]
        # its clock offset's own uncertainty beside it: a bias common to all its arrivals of a still tag, which
        # pooling them does not average (the stationary fix's consider term)
        offsets["clock_sigma_s"] = noise.clock[[names.index(r) for r in offsets["receiver"]]]
    tick = clock.perf_counter()
    emission_slowness = (np.full(len(time), fit.slowness) if slowness is None else slowness)
    seen = None if survey is None else seen_in_fit(receiver, tag, fit.residual / emission_slowness, distance, names,
                                                   tag_names, tag_home, positions)  # on the table's positions
    if survey == "taken" and seen is not None and seen.seen:  # the sync tags scored with it
        table_sigma = seen.sigma
    quanta = [time_quantum(time[receiver == j] + origin) for j in range(n_receivers)]  # each receiver's rounding
    sync_tags = _sync_tags(fit, receiver, tag, emission, time, distance, slowness, used & (rows >= 0), synced, start,
                           width, positions, tag_names, tag_home, names, leave_one_out, notes, geometry, rows, site,
                           fits, table_sigma, windows, np.array([rounding_sigma(q) for q in quanta]))
    release()  # the sync tags' refits' freed buffers back to the system before the residuals' table is made
    refined = _positions(fit, positions, names, linked, identified, tag_names, float(survey_sigma)) \
        if refine_positions else None
    timings["leave_one_out"] = clock.perf_counter() - tick
    reason = _reasons(np.select([duplicate, single, rows < 0, ~on, ~fit.kept], [1, 2, 3, 4, 5], 0))
    # every arrival's row made once the sync tags are scored (not held through their refits), on the fit's arrays
    residuals = pd.DataFrame({
        "receiver": np.array(names, dtype=object)[receiver], "tag": np.array(tag_names, dtype=object)[tag],
        "emission": emission, "time": time + origin,
        "time_sync": time + origin - np.where(on, fit.offset(np.maximum(rows, 0), time), np.nan),
        "distance_m": distance, "residual_s": fit.residual, "residual_m": fit.residual / emission_slowness,
        "standardised": fit.standardised, "kept": fit.kept, "reason": reason, "line": line}, copy=False)
    if fit.site is not None:
        residuals["segment"] = np.where(rows >= 0, segments.segment_numbers(fit)[np.maximum(rows, 0)], 0)
    summary = _summary(fit, names, tag_names, receiver, tag, used, duplicate, single, linked, start, bridged,
                       residuals, sync_tags, speed_source, sound_speed, bin_hours, origin, notes, detections,
                       rows_read, dim, clock.perf_counter() - started)
    if survey is not None:
        summary["survey_error"] = None if seen is None else seen.summary()
        if survey == "taken" and table_sigma is not None:
            summary |= {"survey_sigma_m": float(table_sigma), "survey_sigma_from": "seen"}
    rounded = residual_warning(quanta, noise.noise,
                               names, 1.0 / float(np.median(emission_slowness)), f"detections {detections.source!r}")
    if notes_first or rounded:  # said first: the table's unit, the rounding
        summary["warnings"] = notes_first + ([rounded] if rounded else []) + summary.get("warnings", [])
    summary["clock_breaks"] = segments.breaks_summary(fit, names, origin, resets)
    for entry in summary["clock_breaks"]:  # each named in one line (the command prints the warnings)
        summary.setdefault("warnings", []).append(segments.break_line(entry))
        # its entry's offsets and drifts are its first segment's; offsets.csv has every segment's
        mine = summary["receivers"][entry["receiver"]]
        mine["clock_segments"] = max(mine.get("clock_segments", 1), entry["segment_after"])
    gone = time[used].max() - time[used & (receiver == start)].max()
    if gone > width:  # beyond the reference's last arrival no arrival sees the time base (the clocks' common drift)
        summary.setdefault("warnings", []).append(
            f"reference receiver {names[start]}'s sync-tag arrivals end {gone / 86400:.3g} days before the others': "
            "beyond them the times are the other clocks' carried on, good to each other, not to a clock; allowed: a "
            "reference receiver in the water the whole time (--reference)")
    for end in ends:  # each break too near a clock's end named in one line
        summary.setdefault("warnings", []).append(segments.end_line(end, names, origin))
    fitted = {(e["reset"]["receiver"], e["reset"]["line"]) for e in summary["clock_breaks"] if e.get("reset")}
    for reset in detections.clock_resets:  # a reset no fit split (no sync-tag arrival after it, or not at a receiver)
        if (reset["receiver"], reset["line"]) not in fitted:
            summary.setdefault("warnings", []).append(
                f"{reset_line(reset)}: not synchronised (no sync-tag arrival of the table's receivers in it), its "
                "detections set aside")
    summary["toa_noise"] = {names[j]: {"toa_sigma_s": float(noise.sigma[j]), "residuals_s": float(noise.noise[j]),
                                       "clock_s": float(noise.clock[j]), "arrivals": int(noise.arrivals[j]),
                                       "measured": bool(noise.measured[j])} for j in np.flatnonzero(linked)}
    xy = refined[["x_m", "y_m"]].to_numpy() if refine_positions else positions[:, :2]
    receivers = pd.DataFrame({"receiver": names, "x": xy[:, 0], "y": xy[:, 1],
                              "sync_tag": hydrophones["sync_tag"].to_numpy(), "synchronised": linked})
    if refine_positions:
        summary["model"] += (f"; receivers' horizontal positions refined with a prior of {survey_sigma:g} m per axis "
                             "at the table's (network adjustment with a priori information: Tapley, Schutz & Born "
                             "2004, ch. 4)")
        shift = refined.loc[refined["refined"], "shift_m"]
        summary["positions"] = {
            "refined": True, "survey_sigma_m": float(survey_sigma),
            "median_shift_m": float(shift.median()) if len(shift) else None,
            "largest_shift_m": float(shift.max()) if len(shift) else None,
            "largest_shift_receiver": str(refined.loc[shift.idxmax(), "serial"]) if len(shift) else None,
            "position_sigma_m": [float(refined["position_sigma_m"].min()), float(refined["position_sigma_m"].max())],
            "gauge": "the arrivals fix the array's shape only; its translation and rotation come from the prior",
            "determined": int(identified.determined.sum()), "receivers": len(names),
            "held": [names[j] for j in np.flatnonzero(~identified.determined)],
            "identifiability": f"a receiver refined where its posterior sigma in the array's shape is below "
                               f"{identified.threshold:g} of the survey's in every direction, in the fit with every "
                               "sync tag and with each one left out (sblsim.models.sync.identifiability); the others' "
                               "positions the table's (the clocks fitted with every receiver at the survey's prior)"}
        summary["wall_time_s"] = clock.perf_counter() - started
    if windows is not None:
        summary["windows"] = {"days": float(window_days), "overlap_hours": OVERLAP_HOURS, "count": len(windows),
                              "edges": (windows.edges + origin).tolist()}
        if fit.window_slowness is not None:  # each window's own sound speed (the season's water) and its σ
            s, e = fit.window_slowness.T
            summary["windows"] |= {"sound_speed_m_s": (1.0 / s).tolist(),
                                   "sound_speed_sigma_m_s": [None if not np.isfinite(v) else float(v)
                                                             for v in e / s**2]}
    return SyncOutcome(summary, offsets, residuals, sync_tags, receivers, fit, origin, refined)


def _resets(detections: Detections, sync: pd.DataFrame) -> dict[tuple[str, int], dict]:
    """The reader's resets (:attr:`~sblsim.orchestrator.readers.detections.Detections.clock_resets`) by the
    synchronisation's receiver and the clock part each starts (a study's receiver is its serial's deployment)."""
    if not detections.clock_resets or "clock_part" not in sync:
        return {}
    serial = sync["serial"] if "serial" in sync else sync["receiver"]
    named = dict(zip(zip(serial.astype(str), sync["clock_part"].astype(int)), sync["receiver"].astype(str)))
    return {(named[(r["receiver"], r["clock_part"])], r["clock_part"]): r for r in detections.clock_resets
            if (r["receiver"], r["clock_part"]) in named}


__all__ = ["BIN_HOURS_RANGE", "MIN_BIN_ARRIVALS", "SYNC_COLUMNS", "SyncOutcome", "corrected_times", "synchronise"]
