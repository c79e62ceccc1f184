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
"""

from __future__ import annotations

import time as clock
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial import Delaunay

from sblsim.models.declarations import ModelError
from sblsim.models.sync.breaks import fit_with_breaks, part_shifts
from sblsim.models.sync.clocks import ClockFit, Geometry, connected, fit_clocks, sync_emissions
from sblsim.models.sync.identifiability import MAX_SIGMA_RATIO, Identifiability, identify
from sblsim.models.sync.noise import receiver_noise
from sblsim.models.sync.pings import largest_travel_time
from sblsim.models.sync.positions import AMBIGUOUS, FAILED, UNCHECKED, position_emissions
from sblsim.models.sync.resolution import resolution_warning
from sblsim.orchestrator.sync import segments
from sblsim.orchestrator.sync.detections import Detections, reset_line
from sblsim.orchestrator.sync.transmitters import match
from sblsim.orchestrator.telemetry.deployments import assign

#: A bin with fewer kept arrivals than this at a receiver is bridged by the drift model (flagged).
MIN_BIN_ARRIVALS = 5
#: The bins' allowed width [h].
BIN_HOURS_RANGE = (0.05, 168.0)
#: [s] the longest a receiver is taken to have been off between the last detection before its time went back in
#: the file's order and the first after (a download's), for the search of its new part's shift (breaks.part_shifts).
RESET_GAP = 86400.0
#: The survey's horizontal sigma per axis [m] by default (a handheld GPS's at the surface above a moored receiver),
#: and its allowed range.
SURVEY_SIGMA = 3.0
SURVEY_SIGMA_RANGE = (0.01, 1000.0)


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
                survey_sigma: float = SURVEY_SIGMA, timings: dict | None = None) -> SyncOutcome:
    """Synchronise the receivers' clocks (the module docstring).

    With ``refine_positions`` the receivers' positions are refined only where the sync tags determine them
    (:mod:`sblsim.models.sync.identifiability`: the others keep the table's, ``positions.csv``'s ``reason``), and
    the refinement is kept only where it does not worsen the sync tags' leave-one-out: the synchronisation with the
    table's positions is made too (its NEES with ``survey_sigma`` as the table's error), and where the refined
    positions' median leave-one-out error is larger, the table's outcome is returned (``positions.csv`` the
    table's, ``refined`` false, said in a warning). ``summary["positions"]["leave_one_out"]`` holds both.

    Parameters
    ----------
    detections : Detections
        The raw detections (:func:`~sblsim.orchestrator.sync.detections.read_detections`).
    hydrophones : pandas.DataFrame
        The receivers (:func:`~sblsim.orchestrator.sync.detections.read_hydrophones`).
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
    survey_sigma : float
        [m] the table's horizontal sigma per axis: the refinement's prior.
    timings : dict, optional
        Filled with each stage's seconds (``grouping``, ``fit`` and the fit's own stages, ``leave_one_out``,
        ``tables``) for a benchmark (the refined synchronisation's).

    Returns
    -------
    SyncOutcome

    Raises
    ------
    ModelError
        No sync tag heard by two receivers, a reference receiver not in the table or not synchronisable; with
        ``refine_positions``, no receiver's position determined by the sync tags (a sparse sync array).
    """
    started = clock.perf_counter()
    args = (detections, hydrophones, sound_speed, series, bin_hours, reference, leave_one_out)
    if not refine_positions:
        return _synchronise(*args, timings=timings)
    refined = _synchronise(*args, refine_positions=True, survey_sigma=survey_sigma, timings=timings)
    table = _synchronise(*args, table_sigma=survey_sigma)
    outcome = _kept(refined, table, float(survey_sigma))
    outcome.summary["wall_time_s"] = clock.perf_counter() - started
    return outcome


def _loo(summary: dict[str, Any]) -> dict[str, Any] | None:
    """The sync tags' leave-one-out in a summary: their median error [m] and NEES inside the array, or None."""
    t = summary.get("sync_tags") or {}
    if not t:
        return None
    return {"median_error_m": t["median_error_m"], "nees_mean_inside": t["nees_mean_inside"],
            "nees_median_inside": t["nees_median_inside"], "tags": t["tags"]}


def _kept(refined: SyncOutcome, table: SyncOutcome, survey_sigma: float) -> SyncOutcome:
    """The refined synchronisation where its sync tags' leave-one-out median error is not larger than the table's
    (both recorded in ``summary["positions"]["leave_one_out"]``), else the table's, said in one warning."""
    before, after = _loo(table.summary), _loo(refined.summary)
    worse = after is None or (before is not None and after["median_error_m"] > before["median_error_m"])
    record = {"table": before, "refined": after, "kept": "table" if worse else "refined",
              "rule": "the refined positions kept where their sync tags' median leave-one-out error is not larger "
                      "than the table's (the table's NEES with the survey sigma as its error)"}
    record["table_nees_survey_sigma_m"] = survey_sigma
    if not worse:
        refined.summary["positions"]["leave_one_out"] = record
        return refined
    positions = refined.positions.copy()
    was = "none positioned" if after is None else f"{after['median_error_m']:.3g} m"
    why = f"the refinement worsened the sync tags' leave-one-out (median error {before['median_error_m']:.3g} m " \
          f"with the table's, {was} refined)" if before is not None else "the refinement could not be checked"
    positions["reason"] = np.where(positions["refined"], why, positions["reason"])
    positions["refined"] = False
    positions[["x_m", "y_m"]] = positions[["table_x_m", "table_y_m"]].to_numpy()
    positions[["shift_x_m", "shift_y_m", "shift_m"]] = 0.0
    positions[["sigma_x_m", "sigma_y_m", "correlation_xy"]] = np.nan
    table.positions = positions
    table.summary["positions"] = {**refined.summary["positions"], "refined": False, "leave_one_out": record}
    table.summary.setdefault("warnings", []).append(f"refine positions: {why}: the table's positions kept")
    return table


def _synchronise(detections: Detections, hydrophones: pd.DataFrame, sound_speed: float | None = None,
                 series: tuple[np.ndarray, np.ndarray] | None = None, bin_hours: float = 1.0,
                 reference: str | None = None, leave_one_out: bool = True, refine_positions: bool = False,
                 survey_sigma: float = SURVEY_SIGMA, timings: dict | None = None,
                 table_sigma: float | None = None) -> SyncOutcome:
    """One synchronisation, with the positions refined (only where the sync tags determine them: else refused) or
    the table's (the sync tags' NEES with ``table_sigma`` [m] per axis as the table's error where given); the rest
    as :func:`synchronise` (its parameters, ``table_sigma`` aside).

    Returns
    -------
    SyncOutcome

    Raises
    ------
    ModelError
        No sync tag heard by two receivers, a reference receiver not in the table or not synchronisable.
    """
    started = clock.perf_counter()
    notes: list[str] = []
    frame = detections.frame
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
    sync = frame[pick]
    if len(sync) < 2:
        raise ModelError("sync: fewer than two detections of the receivers table's sync tags; allowed: raw "
                         "detections in which receivers hear the sync tags named in the table's sync_tag column")
    receiver = sync["receiver"].map(index).to_numpy(np.int64)
    tag = sync["tag"].map(tag_index).to_numpy(np.int64)
    origin = float(np.floor(sync["time"].min()))
    time = sync["time"].to_numpy(float) - origin
    n_receivers = len(names)
    never = [tag_names[i] for i in range(len(tag_names)) if not (tag == i).any()]
    if never:
        notes.append(f"sync tags never heard: {', '.join(never)}")

    # a receiver whose time went back in the file's order: each later part of its rows a clock of its own, its
    # arrivals aligned to the others' for the grouping alone (the reader's clock_part; models.sync.breaks)
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

    if sound_speed is not None:
        slowness = np.full(len(time), 1.0 / sound_speed)
        speed_source = "given"
    elif series is not None:
        times, speeds = series
        absolute = time + origin
        if absolute.min() < times[0] - 86400 or absolute.max() > times[-1] + 86400:
            notes.append("the sound-speed series does not cover the detections' span (more than a day outside): "
                         "its end values held")
        slowness = 1.0 / np.interp(absolute, times, speeds)
        speed_source = "series"
    else:
        slowness = None
        speed_source = "estimated"

    counts = np.bincount(receiver[used], minlength=n_receivers)
    if reference is None:
        start = int(np.argmax(counts))
    else:
        if reference not in index:
            raise ModelError(f"reference: receiver {reference!r} is not in the receivers table; allowed: one of "
                             f"{', '.join(names[:30])}")
        start = index[reference]
    linked = connected(receiver[used], emission[used], n_receivers, start)
    if not linked[start]:
        raise ModelError(f"reference: receiver {names[start]} hears no sync-tag emission that another receiver hears; "
                         "allowed: a receiver that can be synchronised")
    left_out = [names[j] for j in range(n_receivers) if not linked[j]]
    if left_out:
        notes.append("receivers that cannot be synchronised (they hear no sync-tag emission another synchronised "
                     f"receiver hears), left out: {', '.join(left_out)}")
    width = bin_hours * 3600.0
    timings = {} if timings is None else timings
    timings["grouping"] = clock.perf_counter() - started
    tick = clock.perf_counter()
    geometry = Geometry(tag_home[tag], positions, float(survey_sigma)) if refine_positions else None
    # a receiver whose clock jumped or went back split into clock segments (sblsim.models.sync.breaks): each clock
    # row a receiver's (its first segment) or a later segment's, `rows` each arrival's (-1 set aside at a break)
    fit = fit_with_breaks(receiver, emission, time, distance, slowness, used, linked, start, width, tag,
                          geometry=geometry, timings=timings, part=part)
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

    reason = np.where(duplicate, "multipath", np.where(single, "single receiver", np.where(
        rows < 0, "clock break", np.where(~on, "not synchronised", np.where(fit.kept, "", "rejected")))))
    emission_slowness = (np.full(len(time), fit.slowness) if slowness is None else slowness)
    residuals = pd.DataFrame({
        "receiver": np.array(names, dtype=object)[receiver], "tag": np.array(tag_names, dtype=object)[tag],
        "emission": emission, "time": time + origin,
        "time_sync": time + origin - np.where(on, fit.offset(np.maximum(rows, 0), time), np.nan),
        "distance_m": distance, "residual_s": fit.residual, "residual_m": fit.residual / emission_slowness,
        "standardised": fit.standardised, "kept": fit.kept, "reason": reason, "line": sync["line"].to_numpy()})

    if fit.site is not None:
        residuals["segment"] = np.where(rows >= 0, segments.segment_numbers(fit)[np.maximum(rows, 0)], 0)
    offsets = _offsets(fit, names, synced, bridged, origin)
    # each receiver's timing noise (its residuals' robust scale and its clock's sigma), for the tracker
    noise = receiver_noise(receiver, fit.standardised * fit.scale[np.maximum(rows, 0)],
                           segments.receiver_sigmas(fit, n_receivers), linked)
    if np.isfinite(noise.sigma[linked]).all():  # (none where no receiver has residuals enough to measure it)
        offsets["toa_sigma_s"] = noise.sigma[[names.index(r) for r in offsets["receiver"]]]
        # its clock offset's own uncertainty beside it: a bias common to all its arrivals of a still tag, which
        # pooling them does not average (the stationary fix's consider term)
        offsets["clock_sigma_s"] = noise.clock[[names.index(r) for r in offsets["receiver"]]]
    tick = clock.perf_counter()
    sync_tags = _sync_tags(fit, receiver, tag, emission, time, distance, slowness, used & (rows >= 0), synced, start,
                           width, positions, tag_names, tag_home, names, leave_one_out, notes, geometry, rows, site,
                           fits, table_sigma)
    refined = _positions(fit, positions, names, linked, identified, tag_names) if refine_positions else None
    timings["leave_one_out"] = clock.perf_counter() - tick
    summary = _summary(fit, names, tag_names, receiver, tag, used, duplicate, single, linked, start, bridged,
                       residuals, sync_tags, speed_source, sound_speed, bin_hours, origin, notes, detections,
                       dim, clock.perf_counter() - started)
    summary["clock_breaks"] = segments.breaks_summary(fit, names, origin, _resets(detections, sync))
    for entry in summary["clock_breaks"]:  # each named in one line (the command prints the warnings)
        summary.setdefault("warnings", []).append(segments.break_line(entry))
        # its entry's offsets and drifts are its first segment's; offsets.csv has every segment's
        mine = summary["receivers"][entry["receiver"]]
        mine["clock_segments"] = max(mine.get("clock_segments", 1), entry["segment_after"])
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
            "gauge": "the arrivals fix the array's shape only; its translation and rotation come from the prior",
            "determined": int(identified.determined.sum()), "receivers": len(names),
            "held": [names[j] for j in np.flatnonzero(~identified.determined)],
            "identifiability": f"a receiver refined where its posterior sigma in the array's shape is below "
                               f"{identified.threshold:g} of the survey's in every direction, in the fit with every "
                               "sync tag and with each one left out (sblsim.models.sync.identifiability); the others' "
                               "positions the table's (the clocks fitted with every receiver at the survey's prior)"}
        summary["wall_time_s"] = clock.perf_counter() - started
    return SyncOutcome(summary, offsets, residuals, sync_tags, receivers, fit, origin, refined)


def _positions(fit: ClockFit, positions: np.ndarray, names: list[str], linked: np.ndarray,
               identified: Identifiability, tag_names: list[str]) -> pd.DataFrame:
    """``positions.csv``: each receiver's refined horizontal position, the table's, the shift and its sigmas; a
    receiver the sync tags do not determine (``identified``; in the fit at the survey's prior like the others) or
    not synchronised keeps the table's (``refined`` false, its ``reason``; its sigmas NaN); ``sigma_ratio`` and
    ``sigma_ratio_without`` its posterior sigma in the array's shape over the survey's, with every sync tag and the
    worst with one left out (``worst_tag``)."""
    refined = linked & identified.determined
    shift = np.where(refined[:, None], fit.shift, 0.0)
    cov = fit.shift_covariance
    ratio, without = identified.ratio, identified.ratio_without
    heard = [tag_names[i] for i in identified.tags] if identified.tags is not None else []
    worst = np.array([heard[k] if 0 <= k < len(heard) else "" for k in identified.worst], dtype=object)
    reason = np.where(~linked, "not synchronised", np.where(
        ~(ratio < identified.threshold),
        [f"its posterior sigma {r:.2f} of the survey's (needs < {identified.threshold:g})" for r in ratio],
        np.where(~(without < identified.threshold),
                 [f"determined only with sync tag {t} (without it {r:.2f} of the survey's, needs < "
                  f"{identified.threshold:g})"
                  for t, r in zip(worst, without, strict=True)], "")))
    return pd.DataFrame({
        "serial": names, "x_m": positions[:, 0] + shift[:, 0], "y_m": positions[:, 1] + shift[:, 1],
        "table_x_m": positions[:, 0], "table_y_m": positions[:, 1], "shift_x_m": shift[:, 0],
        "shift_y_m": shift[:, 1], "shift_m": np.hypot(shift[:, 0], shift[:, 1]),
        "sigma_x_m": np.where(refined, np.sqrt(cov[:, 0, 0]), np.nan),
        "sigma_y_m": np.where(refined, np.sqrt(cov[:, 1, 1]), np.nan),
        "correlation_xy": np.where(refined, cov[:, 0, 1] / np.sqrt(cov[:, 0, 0] * cov[:, 1, 1]), np.nan),
        "refined": refined, "reason": np.where(refined, "", reason), "sigma_ratio": ratio,
        "sigma_ratio_without": without, "worst_tag": worst})


def _fit_without(i: int, fit: ClockFit, c, tag, emission, time, distance, slowness, used, start, width, n_rows: int,
                 geometry: Geometry | None, site, steady) -> tuple[ClockFit, np.ndarray] | None:
    """The clocks fitted without sync tag ``i``'s arrivals (the kept arrivals and scales of ``fit``; with
    ``geometry`` the positions refined from ``fit``'s) and the clock rows still synchronised; None where they
    cannot be fitted without it."""
    without = used & (tag != i)
    still = connected(c[without], emission[without], n_rows, start)
    loo = None if geometry is None else Geometry(geometry.source, geometry.positions, geometry.sigma, fit.shift, site)
    try:
        this = fit_clocks(c, emission, time, distance, slowness, without, still, start, width, keep=fit.kept,
                          scale=fit.scale, sigmas=False, geometry=loo, steady=steady)
    except ModelError:
        return None
    return this, still


def _identify(fit: ClockFit, args: tuple, geometry: Geometry, positions: np.ndarray, names: list[str],
              tag_names: list[str], linked: np.ndarray, survey_sigma: float
              ) -> tuple[Identifiability, dict[int, tuple[ClockFit, np.ndarray] | None]]:
    """The identifiability test of the refined positions (:func:`sblsim.models.sync.identifiability.identify`)
    on ``fit`` and on its fits with each sync tag heard left out (returned too, by tag, for the leave-one-out).

    Raises
    ------
    ModelError
        No receiver's position determined (a sparse sync array): the refinement refused in one line.
    """
    receiver, tag, emission, time, distance, slowness, used, start, width = args
    rows, site = segments.clock_rows(fit, receiver)
    ok = used & (rows >= 0)
    steady = None if len(site) == len(names) else site == start
    heard = [int(i) for i in np.unique(tag[ok])]
    fits = {i: _fit_without(i, fit, rows, tag, emission, time, distance, slowness, ok, start, width, len(site),
                            geometry, site, steady) for i in heard}
    identified = identify(positions[:, :2], fit.shift_covariance_all, survey_sigma, linked,
                          [None if f is None else f[0].shift_covariance_all for f in fits.values()])
    identified = Identifiability(identified.ratio, identified.ratio_without, identified.worst, identified.determined,
                                 identified.threshold, np.array(heard, np.int64))
    if not identified.determined.any():
        worst = np.fmax(identified.ratio, np.nan_to_num(identified.ratio_without, nan=1.0))
        best = int(np.argmin(np.where(linked, worst, np.inf)))
        raise ModelError(
            f"refine positions: the {len(heard)} sync tags heard among {len(names)} receivers determine no "
            f"receiver's position (the best, {names[best]}, has a posterior sigma {worst[best]:.2f} of the "
            f"survey's with a sync tag left out; needed: < {MAX_SIGMA_RATIO:g}, i.e. 3 sync tags not on one line "
            "heard by a receiver with any one left out: 4 or more around the array); allowed: the table's positions "
            "(without refining them)")
    return identified, fits


def _offsets(fit: ClockFit, names: list[str], linked: np.ndarray, bridged: np.ndarray, origin: float
             ) -> pd.DataFrame:
    """``offsets.csv``: one row per synchronised receiver (per clock row: ``linked`` (rows,)) and bin; where a
    receiver's clock broke, its segments' rows each, with ``segment``, ``clock_from`` and ``clock_to``
    (:func:`~sblsim.orchestrator.sync.segments.segment_columns`)."""
    rows = []
    edges = fit.edges + origin
    site, number = segments.clock_rows(fit, np.zeros(0, np.int64))[1], segments.segment_numbers(fit)
    order = sorted(np.flatnonzero(linked), key=lambda j: (site[j], number[j]))  # a receiver's segments together
    for j in order:
        for k in range(len(edges) - 1):
            rows.append((names[site[j]], k, edges[k], edges[k + 1], fit.knots[j, k], fit.knot_sigma[j, k],
                         fit.knots[j, k + 1], fit.knot_sigma[j, k + 1], fit.drift[j, k], fit.drift_sigma[j, k],
                         int(fit.counts[j, k]), bool(bridged[j, k])))
    table = pd.DataFrame(rows, columns=["receiver", "bin", "start", "end", "offset_start_s", "offset_start_sigma_s",
                                        "offset_end_s", "offset_end_sigma_s", "drift", "drift_sigma", "arrivals",
                                        "bridged"])
    for key, values in (segments.segment_columns(fit, origin) or {}).items():
        table[key] = np.repeat(values[order], len(edges) - 1)
    return table


def _sync_tags(fit: ClockFit, receiver, tag, emission, time, distance, slowness, used, linked, start, width,
               positions, tag_names, tag_home, names, leave_one_out: bool, notes: list[str],
               geometry: Geometry | None = None, clock: np.ndarray | None = None,
               site: np.ndarray | None = None, fits: dict | None = None,
               table_sigma: float | None = None) -> pd.DataFrame:
    """``sync_tags.csv``: each sync tag positioned emission by emission from the other receivers' synchronised
    arrivals (its own receiver left out), with the clocks fitted without its arrivals (``leave_one_out``), against
    its known position: the table's, or with ``geometry`` its receiver's position refined without the tag's
    arrivals (``truth_x_m``, ``truth_y_m``, its sigma ``truth_sigma_m``; the NEES with the fix's covariance and
    that position's summed: two estimates from disjoint arrivals), the error against the table beside it
    (``table_error_m``).

    Each fix is robust and checked (:func:`~sblsim.models.sync.positions.position_emissions`): the statistics are
    over the trusted fixes (``fixes``); ``fixes_unchecked`` (no redundancy: the arrivals fitted exactly, nothing to
    check them), ``fixes_failed`` (the overall test failed with a redundancy of 1: an outlier not identifiable) and
    ``fixes_ambiguous`` (a rejected arrival could be swapped for a kept one) are counted beside them,
    ``fixes_scaled`` the fixes whose covariance the a-posteriori variance factor scaled, ``arrivals_rejected`` the
    arrivals the trusted fixes rejected, ``median_redundancy`` theirs. The clock fit's own rejections of the tag's
    arrivals are not carried into its fixes: that fit saw the tag at its known
    position, so its rejections would use the position the fixes are checked against.

    Where a receiver's clock broke, ``clock`` (n,) is each arrival's clock row and ``site`` each row's receiver
    (:func:`~sblsim.orchestrator.sync.segments.clock_rows`), ``linked`` per clock row. ``fits``: the fits without
    each tag already made (:func:`_fit_without`, by tag). ``table_sigma`` [m]: without ``geometry``, the table's
    horizontal sigma per axis, summed into the NEES's covariance (the survey's stated error)."""
    dim = positions.shape[1]
    rows = []
    c = receiver if clock is None else clock
    steady = None if site is None or len(site) == len(names) else site == start
    knot_sigma = segments.receiver_sigmas(fit, len(names))
    for i, name in enumerate(tag_names):
        home = tag_home[i]
        mine = (tag == i) & used & linked[c] & (receiver != home)
        if mine.sum() < dim + 2:
            continue
        this = fit
        if leave_one_out:
            got = fits[i] if fits is not None and i in fits else _fit_without(
                i, fit, c, tag, emission, time, distance, slowness, used, start, width, len(linked), geometry,
                None if clock is None else site, steady)
            if got is None:
                notes.append(f"sync tag {name}: the clocks cannot be fitted without it; not positioned")
                continue
            this, still = got
            mine &= still[c]
        rows_e = np.flatnonzero(mine)
        ems, local = np.unique(emission[rows_e], return_inverse=True)
        arrival = np.full((len(ems), len(names)), np.nan)
        arrival[local, receiver[rows_e]] = time[rows_e] - this.offset(c[rows_e], time[rows_e])
        s = np.full(len(ems), this.slowness if slowness is None else np.nan)
        if slowness is not None:
            s = np.bincount(local, slowness[rows_e]) / np.bincount(local)
        sigma = segments.receiver_values(np.where(np.isfinite(this.scale), this.scale, 1e-3), fit, len(names))
        known = np.isfinite(knot_sigma)
        offset_sigma = np.array([np.median(knot_sigma[j][known[j]]) if known[j].any() else 0.0
                                 for j in range(len(names))])
        sigma = np.sqrt(sigma ** 2 + offset_sigma ** 2)
        where = positions
        truth_cov = np.zeros((dim, dim))
        if geometry is None and table_sigma is not None:
            truth_cov[:2, :2] = table_sigma ** 2 * np.eye(2)
        if geometry is not None:  # the receivers where the fit without this tag puts them
            where = positions.copy()
            where[:, :2] += this.shift
            truth_cov[:2, :2] = this.shift_covariance[home]
            ranging = np.nanmedian(s) * np.sqrt(np.trace(this.shift_covariance, axis1=1, axis2=2) / 2)
            sigma = np.sqrt(sigma ** 2 + ranging ** 2)
        fixes = position_emissions(arrival, where, sigma, s)
        ok = fixes.ok
        if not ok.any():
            continue
        truth = where[home]
        error = fixes.position[ok] - truth
        error_m = np.linalg.norm(error, axis=1)
        own_sigma = np.sqrt(np.trace(fixes.covariance[ok], axis1=1, axis2=2))
        nees = np.einsum("ek,ekl,el->e", error, np.linalg.inv(fixes.covariance[ok] + truth_cov), error)
        heard = np.flatnonzero(fixes.used[ok].any(axis=0))
        mean = np.median(fixes.position[ok], axis=0)
        rows.append({"tag": name, "receiver": names[home], "x_m": truth[0], "y_m": truth[1],
                     "emissions": len(ems), "fixes": int(ok.sum()), "receivers_used": len(heard),
                     "median_error_m": float(np.median(error_m)), "median_sigma_m": float(np.median(own_sigma)),
                     "rms_error_m": float(np.sqrt(np.mean(error_m ** 2))),
                     "p90_error_m": float(np.percentile(error_m, 90)), "nees_mean": float(np.mean(nees)),
                     "nees_median": float(np.median(nees)), "median_x_m": mean[0], "median_y_m": mean[1],
                     "median_position_error_m": float(np.linalg.norm(mean - truth)),
                     "inside_array": _inside(truth, where[heard]), "leave_one_out": leave_one_out})
        if geometry is not None:
            rows[-1].update({"x_m": positions[home, 0], "y_m": positions[home, 1], "truth_x_m": truth[0],
                             "truth_y_m": truth[1], "truth_sigma_m": float(np.sqrt(np.trace(truth_cov))),
                             "table_error_m": float(np.median(np.linalg.norm(fixes.position[ok] - positions[home],
                                                                             axis=1)))})
        rows[-1].update({"fixes_unchecked": int((fixes.status == UNCHECKED).sum()),
                         "fixes_failed": int((fixes.status == FAILED).sum()),
                         "fixes_ambiguous": int((fixes.status == AMBIGUOUS).sum()),
                         "fixes_scaled": int((fixes.variance_factor[ok] > 1).sum()),
                         "arrivals_rejected": int(fixes.rejected[ok].sum()),
                         "median_redundancy": float(np.median(fixes.redundancy[ok]))})
    columns = ["tag", "receiver", "x_m", "y_m", "emissions", "fixes", "receivers_used", "median_error_m",
               "median_sigma_m", "rms_error_m", "p90_error_m", "nees_mean", "nees_median", "median_x_m", "median_y_m",
               "median_position_error_m", "inside_array", "leave_one_out"]
    if geometry is not None:
        columns += ["truth_x_m", "truth_y_m", "truth_sigma_m", "table_error_m"]
    columns += ["fixes_unchecked", "fixes_failed", "fixes_ambiguous", "fixes_scaled", "arrivals_rejected",
                "median_redundancy"]
    return pd.DataFrame(rows, columns=columns)


def _resets(detections: Detections, sync: pd.DataFrame) -> dict[tuple[str, int], dict]:
    """The reader's resets (:attr:`~sblsim.orchestrator.sync.detections.Detections.clock_resets`) by the
    synchronisation's receiver and the clock part each starts (a study's receiver is its serial's deployment)."""
    if not detections.clock_resets or "clock_part" not in sync:
        return {}
    serial = sync["serial"] if "serial" in sync else sync["receiver"]
    named = dict(zip(zip(serial.astype(str), sync["clock_part"].astype(int)), sync["receiver"].astype(str)))
    return {(named[(r["receiver"], r["clock_part"])], r["clock_part"]): r for r in detections.clock_resets
            if (r["receiver"], r["clock_part"]) in named}


def _inside(point: np.ndarray, points: np.ndarray) -> bool:
    """Whether ``point`` is inside the convex hull of ``points`` (horizontally)."""
    try:
        return bool(Delaunay(points[:, :2]).find_simplex(point[:2]) >= 0)
    except Exception:  # fewer than three points, or all on a line
        return False


def _summary(fit, names, tag_names, receiver, tag, used, duplicate, single, linked, start, bridged, residuals,
             sync_tags, speed_source, sound_speed, bin_hours, origin, notes, detections, dim, wall) -> dict[str, Any]:
    """``sync.json``: the model, per receiver and bin the offset, drift and their sigmas, and the diagnostics."""
    per_receiver = {}
    edges = (fit.edges + origin).tolist()
    for j, name in enumerate(names):
        mine = receiver == j
        fitted = mine & used
        kept = fit.kept & mine
        entry: dict[str, Any] = {
            "synchronised": bool(linked[j]), "reference": j == start, "arrivals": int(mine.sum()),
            "used": int(fitted.sum()), "kept": int(kept.sum()),
            "rejected_share": float(1 - kept.sum() / fitted.sum()) if fitted.sum() else None,
            "multipath": int((duplicate & mine).sum()),
            "sync_tags_heard": sorted({tag_names[i] for i in np.unique(tag[fitted])}),
        }
        if linked[j]:
            r = residuals.loc[residuals["kept"].to_numpy() & mine]
            entry.update({
                "noise_scale_s": float(fit.scale[j]),
                "median_abs_residual_m": float(np.median(np.abs(r["residual_m"]))) if len(r) else None,
                "median_abs_residual_s": float(np.median(np.abs(r["residual_s"]))) if len(r) else None,
                "bins_bridged": int(bridged[j].sum()),
                "offset_s": fit.knots[j].tolist(), "offset_sigma_s": _finite(fit.knot_sigma[j]),
                "drift": fit.drift[j].tolist(), "drift_sigma": _finite(fit.drift_sigma[j])})
        per_receiver[name] = entry
    speed = {"source": speed_source}
    if speed_source == "given":
        speed["sound_speed_m_s"] = sound_speed
    elif speed_source == "estimated":
        speed["sound_speed_m_s"] = 1.0 / fit.slowness
        speed["sound_speed_sigma_m_s"] = fit.slowness_sigma / fit.slowness ** 2 if fit.slowness_sigma else None
    loo = {}
    if len(sync_tags):
        inside = sync_tags[sync_tags["inside_array"]]
        loo = {"median_error_m": float(sync_tags["median_error_m"].median()),
               "tags": int(len(sync_tags)), "nees_mean_inside": float(inside["nees_mean"].mean())
               if len(inside) else None,
               "nees_median_inside": float(inside["nees_median"].median()) if len(inside) else None,
               "median_sigma_m": float(sync_tags["median_sigma_m"].median()),
               "fixes": int(sync_tags["fixes"].sum()), "fixes_unchecked": int(sync_tags["fixes_unchecked"].sum()),
               "fixes_failed": int(sync_tags["fixes_failed"].sum()),
               "fixes_ambiguous": int(sync_tags["fixes_ambiguous"].sum()),
               "fix_model": "robust (Student-t IRLS from several starts, then Baarda's data snooping and the overall "
                            "test at a test size of 0.001: Baarda 1968); a fix without redundancy is unchecked, not "
                            "counted"}
    kept = residuals["kept"].to_numpy()
    return {
        "model": "piecewise-linear clock offset per receiver, continuous across time bins (drift constant in a bin), "
                 "the reference receiver fixed, sync-tag emission times unknown; robust IRLS (Student-t, nu=3) then "
                 "arrivals beyond 4 sigma rejected (Baktoft et al. 2017, Sci. Rep. 7:14294; YAPS's sync model)",
        "detections": {"file": detections.source, "format": detections.format, "rows": int(len(detections.frame)),
                       "sync_arrivals": int(len(receiver)), "used": int(used.sum()), "kept": int(kept.sum()),
                       "multipath": int(duplicate.sum()), "single_receiver": int(single.sum()),
                       "ignored_columns": detections.ignored_columns},
        "reference_receiver": names[start], "bin_hours": bin_hours, "bin_edges": edges, "dimensions": dim,
        "sound_speed": speed, "receivers": per_receiver,
        "synchronised": [n for j, n in enumerate(names) if linked[j]],
        "not_synchronised": [n for j, n in enumerate(names) if not linked[j]],
        "median_abs_residual_m": float(np.median(np.abs(residuals.loc[kept, "residual_m"]))) if kept.any() else None,
        "sync_tags": loo, "iterations": fit.iterations, "notes": notes, "wall_time_s": wall,
    }


def _finite(values: np.ndarray) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in values]


def rounding_warning(detections: Detections, hydrophones: pd.DataFrame, sound_speed: float | None) -> str | None:
    """One line where the detections' times are rounded too coarsely for the array
    (:func:`sblsim.models.sync.resolution.resolution_warning`; ``hydrophones``' ``x``, ``y``, ``z`` [m] give the
    largest travel time at ``sound_speed`` [m/s], 1,480 m/s where not known), else None."""
    speed = sound_speed or 1480.0
    xyz = np.nan_to_num(hydrophones[["x", "y", "z"]].to_numpy(float))  # a depth not given: the horizontal alone
    return resolution_warning(detections.frame["time"].to_numpy(float), largest_travel_time(xyz, speed), speed,
                              f"detections {detections.source!r}")


def synchronise_study(detections: Detections, deployments, sound_speed: float | None = None,
                      series: tuple[np.ndarray, np.ndarray] | None = None, bin_hours: float = 1.0,
                      reference: str | None = None, **options: Any) -> SyncOutcome:
    """:func:`synchronise` on a study's receivers (a
    :class:`~sblsim.orchestrator.telemetry.deployments.Deployments`): each detection at its deployment first (the
    others set aside, counted in ``summary["set_aside"]``), the frame and the deployments in
    ``summary["receivers_file"]``, and the refined positions (``positions.csv``) in latitude and longitude too where
    the frame is known; ``options`` as :func:`synchronise` takes them.

    Raises
    ------
    ModelError
        As :func:`synchronise`, or no detection inside a deployment.
    """
    assigned = assign(detections, deployments)
    outcome = synchronise(assigned.detections, assigned.hydrophones, sound_speed, series, bin_hours, reference,
                          **options)
    outcome.summary["set_aside"] = assigned.set_aside
    outcome.summary["receivers_file"] = deployments.summary()
    line = rounding_warning(assigned.detections, assigned.hydrophones, outcome.summary["sound_speed"].get(
        "sound_speed_m_s"))
    if line:  # times rounded so coarsely that the clocks and every position from them are poor
        outcome.summary.setdefault("warnings", []).append(line)
    frame = deployments.frame
    if outcome.positions is not None and frame is not None:
        outcome.positions["lat"], outcome.positions["lon"] = frame.to_latlon(outcome.positions["x_m"].to_numpy(),
                                                                             outcome.positions["y_m"].to_numpy())
    return outcome


__all__ = ["BIN_HOURS_RANGE", "MIN_BIN_ARRIVALS", "SyncOutcome", "rounding_warning", "synchronise",
           "synchronise_study"]
