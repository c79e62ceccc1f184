"""``sblsim toa``'s work: one tag's raw detections on the synchronised clocks, grouped into pings, as the times-of-
arrival matrix the tracker reads (``toa.txt``, written by :mod:`.matrix_files` with ``pings.csv``, ``receivers.csv``
and ``toa.json``).

The clocks are a synchronisation's folder read back (:mod:`.clocks`: its ``offsets.csv``, each receiver's offset the
knots interpolated at the detection's own time), extended by at most one bin beyond the synchronised span (detections
further out are left out and counted). The grouping is :mod:`sblsim.models.sync.pings`'s, its window the array's
largest travel time at the slowest sound speed allowed (1,300 m/s) plus :data:`TOLERANCE`, the echo limit the
shortest burst interval (the ping type's, else as the detections show it) less that window.

A synchronisation also writes each receiver's timing noise from its sync-tag residuals (``offsets.csv``'s
``toa_sigma_s``): it goes into the matrix's ``receivers.csv`` (a ``toa_sigma_s`` column), whose receivers the tracker
then weighs each by its own noise. A synchronisation's folder written before that column has none: read all the same,
the tracker's default then taken (said).

Where a receiver's clock broke (jumped or went back), each detection takes the clock segment that holds its time,
and one between two segments (the stretch around the break) is set aside and counted (``at_clock_breaks``); where a
receiver's time went back in the detections file's order, a detection takes a segment of its own clock part.

A synchronisation made with ``--refine-positions`` also wrote ``positions.csv``: its refined horizontal positions
replace the receivers table's ``x``, ``y`` of the receivers it lists, and ``toa.json`` says so; each receiver's
position error goes with them (its posterior σ in the array's shape where refined, the refinement's prior where it
kept the table's position: :func:`~.taken_survey.folder_position_sigmas`), as ``receivers.csv``'s ``sigma_m`` and
``toa.json``'s ``positions.sigma_m``. One made on the table's positions that stated no
survey error took the one its residuals between receivers saw (``sync.json``'s ``survey_sigma_m``, ``survey_sigma_from``
``seen``: :mod:`.taken_survey`): the matrix's ``receivers.csv`` carries it as each receiver's ``sigma_m``, so the
tracker's σ hold it as a study given that folder does (``toa.json``'s ``survey_sigma_m``).
"""

from __future__ import annotations

import time as clock
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.sync.at_once import heard_at_once
from sblsim.models.sync.pings import build_pings, inferred_shortest, interval_seen, largest_travel_time
from sblsim.models.sync.resolution import rounding_sigma, time_quantum
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.io.frames import Frame
from sblsim.orchestrator.io.tables import NUMBER
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.readers.assign import assign, serials_as_logged
from sblsim.orchestrator.readers.burst_sequence import read_burst_sequence
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import FORMATS as DETECTION_FORMATS
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.in_water import in_water
from sblsim.orchestrator.readers.limits import IDENTIFIER
from sblsim.orchestrator.store.read import read_any
from sblsim.orchestrator.sync.clocks import Clocks, read_clocks, read_positions, with_positions
from sblsim.orchestrator.sync.declared import check_matrix
from sblsim.orchestrator.sync.study_sync import rounding_warning
from sblsim.orchestrator.sync.taken_survey import folder_position_sigmas, folder_survey

#: The slowest sound speed the window allows for [m/s] and the synchronisation's tolerance added to it [s].
SLOWEST_SOUND_SPEED = 1300.0
TOLERANCE = 0.02
#: The detections' formats.
FORMATS = DETECTION_FORMATS
#: The sensor units given a column name of their own in ``pings.csv`` (others: ``sensor_<unit>``).
SENSOR_COLUMNS = {"m": "depth_m", "°c": "temperature_c", "c": "temperature_c", "m/s²": "acceleration_m_s2",
                  "m/s2": "acceleration_m_s2"}
#: How ``sblsim toa`` takes a tag's interval and a contradicted one anyway, as its refusals name them (a command
#: that takes them otherwise passes its own to :func:`build_toa`).
OPTION_NAMES = {"interval": "--ping-type rbi --burst-interval MIN:MAX, or pbi --burst-sequence FILE",
                "force_interval": "--force-interval"}


@dataclass
class ToaOutcome:
    """What :func:`build_toa` computed: ``toa`` (P, R) [s] on the base ``origin`` [s since 1970 UTC], ``names`` the
    receivers (columns), ``positions`` (R, dim) [m], ``pings`` (``pings.csv``), ``summary`` (``toa.json``),
    ``frame`` (the positions' metric frame; None without a CRS) and ``toa_sigma`` (R,) [s] each receiver's timing
    noise from the synchronisation (None where it gives none), ``clock_sigma`` (R,) [s] its clock offset's own
    uncertainty (likewise), ``clock_mean`` (R,) [s] that error averaged over the tag's arrivals at it (the bias a
    still tag's pooled pings share: :meth:`~sblsim.orchestrator.sync.clocks.Clocks.averaged_sigma`; None where the
    synchronisation gives no edges' sigmas), ``survey_sigma`` [m per horizontal axis] the survey error the
    synchronisation saw and took, or (R,) each receiver's position's error (on refined positions; None where none),
    ``rounding`` (R,) [s] the rounding σ of the tag's logged times at each receiver
    (:func:`~sblsim.models.sync.resolution.rounding_sigma` of their :func:`~sblsim.models.sync.resolution.time_quantum`,
    0 where finer than a millisecond: a still tag's verdict takes it)."""

    toa: np.ndarray
    names: list[str]
    positions: np.ndarray
    pings: pd.DataFrame
    summary: dict[str, Any]
    origin: float
    frame: Frame | None = None
    toa_sigma: np.ndarray | None = None
    clock_sigma: np.ndarray | None = None
    survey_sigma: float | np.ndarray | None = None
    clock_mean: np.ndarray | None = None
    rounding: np.ndarray | None = None


#: The fewest of a tag's times at a receiver whose own rounding is taken (:func:`build_toa`'s ``rounding``; fewer:
#: the rounding of the tag's times at every receiver): thirty times on a grid twice the step by chance (even
#: milliseconds, :data:`~sblsim.models.sync.resolution.QUANTA`' closest pair), 10⁻⁹.
FEW_TIMES = 30


def tags_present(detections: Detections, limit: int = 8) -> str:
    """The tags with the most detections, for a refusal's allowed values."""
    counts = detections.frame["tag"].value_counts()
    return ", ".join(f"{t} ({n})" for t, n in counts.head(limit).items())


def on_the_clocks(use: pd.DataFrame, clocks: Clocks, synced: dict[str, int]) -> tuple[np.ndarray, np.ndarray,
                                                                                      np.ndarray]:
    """Detections at synchronised receivers on the reference clock: each detection's clock segment (-1 between two
    segments, a clock break), whether it lies within the synchronised span (extended by one bin) on a segment, and
    its time less its receiver's offset there [s].

    Parameters
    ----------
    use : pandas.DataFrame
        The detections (``receiver``, ``time`` [s since 1970 UTC], ``clock_part`` where a receiver's time went back
        in the file's order), every receiver in ``synced``.
    clocks : Clocks
    synced : dict
        Each synchronised receiver's row of ``clocks``.

    Returns
    -------
    tuple of numpy.ndarray
        (n,) int the segments, (n,) bool inside, (n,) [s] the synchronised times.
    """
    raw = use["time"].to_numpy(float)
    part = use["clock_part"].to_numpy(np.int64) if "clock_part" in use else None  # a reset in the file's order
    j_sync = clocks.rows(use["receiver"].map(synced).to_numpy(np.int64), raw, part)  # -1: between two segments
    width = float(np.max(np.diff(clocks.edges)))
    inside = (raw >= clocks.edges[0] - width) & (raw <= clocks.edges[-1] + width) & (j_sync >= 0)
    return j_sync, inside, raw - clocks.offset(np.maximum(j_sync, 0), raw)


def build_toa(detections: Detections, hydrophones: pd.DataFrame, clocks: Clocks, tag: str,
              shortest: float | None = None, ping_type: dict[str, Any] | None = None,
              force_interval: bool = False, options: dict[str, str] | None = None) -> ToaOutcome:
    """One tag's times-of-arrival matrix (the module docstring).

    Parameters
    ----------
    detections : Detections
        The raw detections (:func:`~sblsim.orchestrator.readers.detections.read_detections`).
    hydrophones : pandas.DataFrame
        The receivers (:func:`~sblsim.orchestrator.readers.hydrophones.read_hydrophones`).
    clocks : Clocks
        The synchronisation (:func:`~sblsim.orchestrator.sync.clocks.read_clocks`).
    tag : str
        The tag's id.
    shortest : float, optional
        [s] the tag's shortest burst interval; default as the detections show it
        (:func:`~sblsim.models.sync.pings.inferred_shortest`).
    ping_type : dict, optional
        The ping type's options as given, recorded in ``toa.json``.
    force_interval : bool
        Take a ``shortest`` the detections contradict as a whole
        (:func:`~sblsim.models.sync.pings.interval_seen`), said in ``summary["interval_warning"]`` with the
        detections it drops; refused without. The stated interval is judged against the steps between the pings
        heard by ``dim + 1`` receivers or more at once (:func:`~sblsim.models.sync.at_once.heard_at_once`): a
        detection heard alone (a stray code, a time rounded apart from its ping's) does not contradict it.
    options : dict, optional
        How the command that runs takes the tag's interval (``interval``) and a contradicted one anyway
        (``force_interval``), as the refusals name them; default :data:`OPTION_NAMES`, ``sblsim toa``'s.

    Returns
    -------
    ToaOutcome

    Raises
    ------
    ModelError
        A tag never detected, or detected at no synchronised receiver of the table; too few detections to infer
        the shortest interval; a shortest interval not above twice the window; a stated shortest interval the
        detections contradict, without ``force_interval``.
    """
    started = clock.perf_counter()
    frame = detections.frame
    tag = detections.tag(tag) or tag  # a full ID, or an id alone where one code space has it
    mine = frame[frame["tag"] == tag]
    if not len(mine):
        raise ModelError(f"tag: {tag!r} is never detected in {detections.source!r}; allowed: one of "
                         f"{tags_present(detections)}")
    table = {n: k for k, n in enumerate(hydrophones["receiver"])}
    synced = {n: k for k, n in enumerate(clocks.receivers)}
    xyz = hydrophones[["x", "y", "z"]].to_numpy(float)
    dim = 3 if np.isfinite(xyz[:, 2]).all() else 2
    columns = [n for n in hydrophones["receiver"] if n in synced]
    if len(columns) < 2:
        raise ModelError("sync: fewer than two receivers of the receivers table are in the synchronisation's "
                         "offsets.csv; allowed: the receivers table the synchronisation was made with")
    column = {n: k for k, n in enumerate(columns)}
    positions = xyz[[table[n] for n in columns], :dim]
    unknown = sorted(set(mine["receiver"]) - set(table))
    unsynced = sorted(set(mine["receiver"]) & set(table) - set(synced))
    at = mine["receiver"].isin(column).to_numpy()
    use = mine[at]
    if not len(use):
        raise ModelError(f"tag: {tag!r} is detected only at receivers that are not synchronised or not in the "
                         f"receivers table ({', '.join(sorted(set(mine['receiver']))[:10])})")
    names = OPTION_NAMES | (options or {})
    j_sync, inside, times = on_the_clocks(use, clocks, synced)
    receiver = use["receiver"].map(column).to_numpy(np.int64)
    raw = use["time"].to_numpy(float)
    whole = time_quantum(raw)  # the tag's times' rounding (the pings' grouping, each receiver's rounding below)
    window = largest_travel_time(positions, SLOWEST_SOUND_SPEED) + TOLERANCE
    source = "given"
    if shortest is None:
        shortest = inferred_shortest(receiver[inside], times[inside], window)
        source = "inferred"
        if shortest is None:
            raise ModelError(f"tag: {tag!r} has too few successive detections at its receivers to show its shortest "
                             f"burst interval; allowed: give it ({names['interval']})")
    seen = None
    if source == "given":  # judged on the pings heard at once (the times' rounding added to the tolerance)
        at_once = heard_at_once(receiver[inside], times[inside], positions, SLOWEST_SOUND_SPEED,
                                TOLERANCE + whole)
        rich = at_once.detections_heard_by(dim + 1)
        seen = interval_seen(receiver[inside][rich], times[inside][rich], window, shortest)
    said = None
    if seen is not None and seen.contradicted:  # said before the echo limit drops the detections
        given = (ping_type or {}).get("burst_interval_s")
        stated = f"{given[0]:g}:{given[1]:g} s" if given else f"a shortest interval of {shortest:g} s"
        said = (f"burst interval: {stated} stated, but the detections' steps at one receiver show "
                f"{seen.low:.0f}-{seen.high:.0f} s ({seen.below} of {seen.steps} steps below {shortest:g} s less the "
                f"{window:.3g} s window, between pings heard by {dim + 1} receivers or more at once)")
        if not force_interval:
            raise ModelError(f"{said}; allowed: the tag's interval ({names['interval']}), or "
                             f"{names['force_interval']} to use it anyway")
    pings = build_pings(receiver[inside], times[inside], len(columns), window, shortest)
    if said is not None:
        said += (f"; taken ({names['force_interval']}): {int(pings.echo.sum())} of {int(inside.sum())} detections "
                 "dropped as multipath echoes by it")
    toa = pings.toa
    order = np.argsort(np.nanmin(toa, axis=1), kind="stable")  # rows by first arrival (they are already)
    toa = toa[order]
    first = np.nanmin(toa, axis=1)
    origin = float(np.floor(first[0]))
    heard = np.isfinite(toa)
    table_pings = pd.DataFrame({
        "ping": np.arange(len(toa)), "time": first, "time_utc": iso_utc(first), "time_toa": first - origin,
        "receivers": heard.sum(axis=1),
        "heard": [";".join(columns[k] for k in np.flatnonzero(h)) for h in heard],
        "spread_s": np.nanmax(toa, axis=1) - first})
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    ping_of = np.full(len(use), -1, np.int64)
    kept_rows = np.flatnonzero(inside)
    ping_of[kept_rows[pings.ping >= 0]] = rank[pings.ping[pings.ping >= 0]]
    sensors = _sensors(use, ping_of, len(toa))
    for key, values in sensors.items():
        table_pings[key] = values
    echoes = np.zeros(len(use), bool)
    echoes[kept_rows] = pings.echo
    per_receiver = pd.Series(use["receiver"].to_numpy()[echoes]).value_counts()
    summary = {
        "tag": tag, "detections": {"file": detections.source, "format": detections.format, "of_tag": int(len(mine)),
                                   "used": int(inside.sum() - pings.echo.sum()),
                                   "multipath": int(pings.echo.sum()),
                                   "multipath_per_receiver": {str(k): int(v) for k, v in per_receiver.items()},
                                   "outside_sync_span": int((~inside & (j_sync >= 0)).sum()),
                                   "at_clock_breaks": int((j_sync < 0).sum()),
                                   "at_receivers_not_in_table": int(mine["receiver"].isin(unknown).sum()),
                                   "at_receivers_not_synchronised": int(mine["receiver"].isin(unsynced).sum())},
        "receivers_not_in_table": unknown, "receivers_not_synchronised": unsynced, "receivers": columns,
        "pings": int(len(toa)), "heard_per_ping": {str(k): int(v) for k, v in
                                                   sorted(pd.Series(heard.sum(axis=1)).value_counts().items())},
        "origin_epoch_s": origin, "window_s": window, "echo_limit_s": pings.echo_limit,
        "shortest_interval_s": shortest, "shortest_interval_source": source, "ping_type": ping_type or {},
        "interval_seen": None if seen is None else {"steps": seen.steps, "below": seen.below,
                                                    "low_s": seen.low, "high_s": seen.high,
                                                    "contradicted": seen.contradicted},
        "interval_warning": said,
        "sensors": sorted(sensors), "dimensions": dim, "toa_header": header_line(columns),
        "wall_time_s": clock.perf_counter() - started}
    noise = None if clocks.toa_sigma is None else clocks.toa_sigma[[synced[n] for n in columns]]
    summary["toa_sigma_s"] = None if noise is None else {n: float(v) for n, v in zip(columns, noise)}
    offset_sigma = None if clocks.clock_sigma is None else clocks.clock_sigma[[synced[n] for n in columns]]
    # and averaged over this tag's arrivals at each receiver (the bias a still tag's pooled pings share)
    mean = clocks.averaged_sigma([synced[n] for n in columns], toa)
    # each receiver's logged times' rounding (a still tag's verdict); a receiver with few of the tag's times, the
    # tag's at every receiver (a few times may all be whole multiples of a coarser step by chance)
    counts = np.bincount(receiver, minlength=len(columns))
    rounding = np.array([rounding_sigma(time_quantum(raw[receiver == k]) if counts[k] >= FEW_TIMES else whole)
                         for k in range(len(columns))])
    return ToaOutcome(toa - origin, columns, positions, table_pings, summary, origin, toa_sigma=noise,
                      clock_sigma=offset_sigma, clock_mean=mean, rounding=rounding)


def _sensors(use: pd.DataFrame, ping: np.ndarray, n_pings: int) -> dict[str, np.ndarray]:
    """Each sensor unit's value per ping: the median of the ping's detections' ``sensor_value`` of that unit (NaN
    where none), the column named by :data:`SENSOR_COLUMNS`."""
    out: dict[str, np.ndarray] = {}
    values = use["sensor_value"].to_numpy(float)
    units = use["sensor_unit"].astype(str).str.strip().to_numpy()
    ok = np.isfinite(values) & (ping >= 0)
    for unit in sorted(set(units[ok])):
        key = SENSOR_COLUMNS.get(unit.lower(), "sensor_" + ("".join(c if c.isalnum() else "_" for c in unit)
                                                            or "value"))
        rows = ok & (units == unit)
        column = np.full(n_pings, np.nan)
        frame = pd.DataFrame({"ping": ping[rows], "value": values[rows]}).groupby("ping")["value"].median()
        column[frame.index.to_numpy()] = frame.to_numpy()
        out[key] = column
    return out


def header_line(names: list[str]) -> bool:
    """Whether ``toa.txt`` has a header of the receivers' names: not where every name reads as a number (serials
    such as ``1623``), which the replay would take for a row of times; then the columns are ``receivers.csv``'s rows
    in order, as the replay reads a matrix without a header."""
    return not all(NUMBER.fullmatch(n) for n in names)


def _shortest(ping_type: str | None, interval: tuple[float, float] | None, sequence: Path | None) -> float | None:
    """[s] the shortest burst interval the ping type states (rbi: MIN; pbi: the sequence's least), else None."""
    if interval is not None:
        return interval[0]
    if sequence is not None:
        return float(read_burst_sequence(sequence).min())
    return None


def build(detections: Path, receivers: Path, sync: Path, tag: str, format: str | None, ping_type: str | None,
          interval: tuple[float, float] | None, sequence: Path | None, crs: str | None = None,
          frame: str | None = None, force_interval: bool = False):
    """Read the files and build the tag's matrix (:func:`build_toa`): :class:`ToaOutcome`. The receivers are a
    study's deployments (:func:`~sblsim.orchestrator.readers.deployments.read_deployments`, in ``crs``, projected
    to ``frame``), each detection at its deployment (the others set aside: ``summary["set_aside"]``); a stated
    interval the detections contradict refused unless ``force_interval`` (then a warning). Of a store
    (:mod:`~sblsim.orchestrator.store`), the tag's rows alone are read.

    Raises
    ------
    ModelError, ConfigError
        One line: a bad tag id or format, a file refused by its reader.
    """
    if not IDENTIFIER.fullmatch(tag):
        raise ConfigError(f"tag: {tag[:40]!r} is not allowed; allowed: a tag id of 1 to 40 letters, digits, '.', '_' "
                          "or '-'")
    if format is not None and format not in FORMATS:
        raise ConfigError(f"format: {str(format)[:40]!r} is not one of {', '.join(FORMATS)}")
    clocks = read_clocks(sync)
    shortest = _shortest(ping_type, interval, sequence)
    deployments = read_deployments(receivers, crs, frame)
    read = read_any(detections, format, tags=[tag])  # (of a store, the tag's rows alone)
    deployments = serials_as_logged(deployments, read.frame["receiver"].unique())[0]  # VR2AR-461000: 461000
    array = in_water(read, assign(read, deployments), deployments)  # as the synchronisation took them
    deployments, assigned = array.deployments, array.assigned
    data, table = assigned.detections, assigned.hydrophones
    refined = read_positions(sync)
    table, moved = with_positions(table, refined)
    given = {"type": ping_type, "burst_interval_s": list(interval) if interval else None,
             "burst_sequence": None if sequence is None else sequence.name}
    outcome = build_toa(data, table, clocks, tag, shortest, given, force_interval)
    # the table's positions against the tag's arrivals, a stable interval stated against its pings
    check_matrix(outcome.toa, outcome.positions, outcome.summary["shortest_interval_s"],
                 outcome.summary["window_s"] - TOLERANCE, TOLERANCE, deployments.source, ping_type)
    outcome.frame = deployments.frame
    rounded = rounding_warning(data, table, None)
    outcome.summary["warnings"] = [w for w in (rounded, outcome.summary["interval_warning"]) if w]
    outcome.summary["set_aside"] = assigned.set_aside
    outcome.summary["receivers_file"] = deployments.summary()
    if refined is not None:  # each receiver's position error, as a study given the folder takes it
        sigmas = folder_position_sigmas(sync, outcome.names)
        outcome.survey_sigma = None if sigmas is None else np.array([sigmas[n] for n in outcome.names])
        outcome.summary["positions"] = {"source": "the synchronisation's positions.csv (refined)",
                                        "receivers": moved, "sigma_m": sigmas}
    else:  # the survey error the synchronisation saw and took, as a study given the folder takes it
        outcome.survey_sigma = folder_survey(sync)
        outcome.summary["survey_sigma_m"] = outcome.survey_sigma
    return outcome


__all__ = ["FEW_TIMES", "FORMATS", "OPTION_NAMES", "SENSOR_COLUMNS", "SLOWEST_SOUND_SPEED", "TOLERANCE", "ToaOutcome",
           "build", "build_toa", "header_line", "on_the_clocks", "tags_present"]
