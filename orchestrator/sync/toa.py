"""``sblsim toa``'s work: one tag's raw detections on the synchronised clocks, grouped into pings, as the times-of-
arrival matrix the tracker reads (``toa.txt``), with ``pings.csv``, ``receivers.csv`` and ``toa.json``.

The clocks are read back from a synchronisation's folder (``sblsim sync --out DIR``): its ``offsets.csv`` only, by
that fixed name, as hostile input like any table (bounded, every cell checked, nothing in it taken as a path); each
receiver's offset is the file's knots interpolated at the detection's own time (the sync's model: piecewise linear,
continuous across the bins), extended by at most one bin beyond the synchronised span (detections further out are
left out and counted). The grouping is :mod:`sblsim.models.sync.pings`'s, its window the array's largest travel time
at the slowest sound speed allowed (1,300 m/s) plus :data:`TOLERANCE`, the echo limit the shortest burst interval
(the ping type's, else as the detections show it) less that window.

A synchronisation also writes each receiver's timing noise from its sync-tag residuals (``offsets.csv``'s
``toa_sigma_s``): it goes into the matrix's ``receivers.csv`` (a ``toa_sigma_s`` column), whose receivers the tracker
then weighs each by its own noise. A synchronisation's folder written before that column has none: read all the same,
the tracker's default then taken (said).

Where a receiver's clock broke (jumped or went back), ``offsets.csv`` has a set of rows per clock segment
(``segment``, and the times of the receiver's own clock it holds for, ``clock_from`` to ``clock_to``): each
detection takes the segment that holds its time, and one between two segments (the stretch around the break) is set
aside and counted (``at_clock_breaks``). Where a receiver's time went back in the detections file's order (a reset
kept in its logging order), ``offsets.csv`` also says each segment's clock part (``clock_part``) and a detection
takes a segment of its own part (the detections' ``clock_part``, :mod:`.detections`): two parts may read the same
times.

A synchronisation made with ``--refine-positions`` also wrote ``positions.csv``: its refined horizontal positions
(read the same way) replace the receivers table's ``x``, ``y`` of the receivers it lists, and ``toa.json`` says so.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time as clock
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.sync.pings import build_pings, inferred_shortest, interval_seen, largest_travel_time
from sblsim.models.tracking.schedule import PING_TYPES
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.io.frames import Frame
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.io.paths import inside
from sblsim.orchestrator.io.tables import NUMBER
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.sync.declared import check_matrix
from sblsim.orchestrator.sync.detections import FORMATS as DETECTION_FORMATS
from sblsim.orchestrator.sync.detections import (
    IDENTIFIER,
    MAX_COORDINATE,
    MAX_EPOCH,
    Detections,
    _numbers,
    _pattern,
    _table,
    read_detections,
)
from sblsim.orchestrator.sync.run import rounding_warning
from sblsim.orchestrator.telemetry.deployments import assign, read_deployments
from sblsim.orchestrator.tracks.toa import DEPTH_COLUMN, read_burst_sequence
from sblsim.orchestrator.tracks.tracker import CLOCK_SIGMA_RANGE, SIGMA_TOA, TOA_SIGMA_RANGE

#: The slowest sound speed the window allows for [m/s] and the synchronisation's tolerance added to it [s].
SLOWEST_SOUND_SPEED = 1300.0
TOLERANCE = 0.02
#: The most rows of ``offsets.csv`` read (receivers × bins) and the largest offset [s] it may hold.
MAX_OFFSET_ROWS = 1_000_000
MAX_OFFSET = 30 * 86400.0
#: The detections' formats, the ping types and the burst intervals taken [s].
FORMATS = DETECTION_FORMATS
PING_TYPE_NAMES = tuple(PING_TYPES)
BURST_LIMITS = (0.1, 86400.0)
#: The sensor units given a column name of their own in ``pings.csv`` (others: ``sensor_<unit>``).
SENSOR_COLUMNS = {"m": "depth_m", "°c": "temperature_c", "c": "temperature_c", "m/s²": "acceleration_m_s2",
                  "m/s2": "acceleration_m_s2"}


@dataclass
class Clocks:
    """A synchronisation read back: ``receivers`` (R,) the synchronised receivers, ``edges`` (K+1,) [s since 1970
    UTC] the bins' edges, ``knots`` (R, K+1) [s] each receiver's offset at each edge, ``toa_sigma`` (R,) [s] each
    receiver's timing noise from the sync-tag residuals (None: the synchronisation does not give it, an older
    folder or clocks taken as logged), ``clock_sigma`` (R,) [s] each receiver's clock offset's own uncertainty (part
    of ``toa_sigma``; a bias a still tag's pooled pings share; None where not given)."""

    receivers: list[str]
    edges: np.ndarray
    knots: np.ndarray
    toa_sigma: np.ndarray | None = None
    clock_sigma: np.ndarray | None = None
    #: Where a receiver's clock broke (``offsets.csv``'s ``segment``, ``clock_from``, ``clock_to``): the rows of
    #: :attr:`knots` are clock segments, ``owner`` (rows,) the receiver of each (an index into :attr:`receivers`)
    #: and ``spans`` (rows, 2) [s since 1970 UTC on its own clock] the times each holds for (±inf open); None: a row
    #: per receiver.
    owner: np.ndarray | None = None
    spans: np.ndarray | None = None
    #: Where a receiver's time went back in the detections file's order (``offsets.csv``'s ``clock_part``): (rows,)
    #: the clock part each segment holds for (1 first); None: every segment part 1.
    parts: np.ndarray | None = None

    def rows(self, receiver: np.ndarray, time: np.ndarray, part: np.ndarray | None = None) -> np.ndarray:
        """(n,) int, the row of :attr:`knots` of ``receiver`` (n,) int (an index into :attr:`receivers`) at its own
        clock's ``time`` (n,) [s] in its clock ``part`` (n,) int (the detections' ``clock_part``; default 1): the
        receiver's own, or where its clock broke the segment of that part that holds the time; -1 where none does
        (a stretch set aside between two segments, or a part not synchronised)."""
        receiver = np.asarray(receiver, np.int64)
        if self.owner is None:
            return receiver.copy() if part is None else np.where(np.asarray(part) == 1, receiver, -1)
        part = np.ones(receiver.shape, np.int64) if part is None else np.asarray(part, np.int64)
        own = np.ones(len(self.owner), np.int64) if self.parts is None else self.parts
        out = np.full(receiver.shape, -1, np.int64)
        for row, j in enumerate(self.owner):
            inside = (time >= self.spans[row, 0]) & (time <= self.spans[row, 1])
            out[(receiver == j) & (part == own[row]) & inside] = row
        return out

    def offset(self, receiver: np.ndarray, time: np.ndarray) -> np.ndarray:
        """(n,) [s] the offset of ``receiver`` (n,) int (rows of :attr:`knots`) at its own clock's ``time`` (n,)
        [s]: the knots interpolated, extended with the end bin's drift."""
        width = np.diff(self.edges)
        k = np.clip(np.searchsorted(self.edges, time, side="right") - 1, 0, len(width) - 1)
        f = (time - self.edges[k]) / width[k]
        return self.knots[receiver, k] * (1 - f) + self.knots[receiver, k + 1] * f


def read_clocks(folder: Path | str) -> Clocks:
    """Read ``offsets.csv`` of a synchronisation's folder (``receiver``, ``bin``, ``start``, ``end``,
    ``offset_start_s``, ``offset_end_s``, and where it has one ``toa_sigma_s``, a receiver's timing noise [s] in
    :data:`~sblsim.orchestrator.tracks.tracker.TOA_SIGMA_RANGE`, the same on each of its rows, and ``clock_sigma_s``,
    its clock offset's own uncertainty [s] in [0, 1], likewise; other columns ignored).

    Raises
    ------
    ModelError
        One line: the folder or its file missing, a cell outside its pattern or range, bins that are not the same
        contiguous edges for every receiver, an offset not continuous across a bin's edge, a receiver's
        ``toa_sigma_s`` or ``clock_sigma_s`` not the same on all its rows.
    """
    folder = Path(folder)
    what = "sync"
    if not folder.is_dir():
        raise ModelError(f"{what}: {str(folder)!r} is not a folder; allowed: the folder sblsim sync --out wrote "
                         "(its offsets.csv)")
    path = _in_folder(folder, "offsets.csv")
    if not path.exists():
        raise ModelError(f"{what}: {str(folder)!r} holds no offsets.csv; allowed: the folder sblsim sync --out wrote")
    body, lines, name, col = _columns(path, what, ("receiver", "bin", "start", "end", "offset_start_s",
                                                   "offset_end_s"), "sblsim sync's offsets.csv",
                                      ("toa_sigma_s", "clock_sigma_s", "segment", "clock_from", "clock_to",
                                       "clock_part"))
    receiver = _pattern(body[col["receiver"]], IDENTIFIER, what, name, lines, "receiver",
                        "a receiver's serial of 1 to 40 letters, digits, '.', '_' or '-'").to_numpy()
    bins = _numbers(body[col["bin"]], what, name, lines, "bin", 0, MAX_OFFSET_ROWS)
    if (bins != np.round(bins)).any():
        k = int(np.flatnonzero(bins != np.round(bins))[0])
        raise ModelError(f"{what}: {name!r} line {lines[k]} column bin: {bins[k]:g} is not allowed; allowed: a whole "
                         "number")
    start = _numbers(body[col["start"]], what, name, lines, "start", 0.0, float(MAX_EPOCH), unit="s")
    end = _numbers(body[col["end"]], what, name, lines, "end", 0.0, float(MAX_EPOCH), unit="s")
    first = _numbers(body[col["offset_start_s"]], what, name, lines, "offset_start_s", -MAX_OFFSET, MAX_OFFSET,
                     unit="s")
    last = _numbers(body[col["offset_end_s"]], what, name, lines, "offset_end_s", -MAX_OFFSET, MAX_OFFSET, unit="s")
    noise = None
    if "toa_sigma_s" in col:  # a synchronisation written before the column has none
        noise = _numbers(body[col["toa_sigma_s"]], what, name, lines, "toa_sigma_s", *TOA_SIGMA_RANGE, unit="s")
    clock_sigma = None
    if "clock_sigma_s" in col:  # (0 at the reference receiver)
        clock_sigma = _numbers(body[col["clock_sigma_s"]], what, name, lines, "clock_sigma_s", *CLOCK_SIGMA_RANGE,
                               unit="s")
    parts = None
    if "segment" in col:  # a receiver's clock broke: its segments' rows, each with the times it holds for
        if not {"clock_from", "clock_to"} <= set(col):
            raise ModelError(f"{what}: {name!r}: a segment column needs clock_from and clock_to beside it (sblsim "
                             "sync's offsets.csv)")
        segment = _numbers(body[col["segment"]], what, name, lines, "segment", 1, MAX_OFFSET_ROWS)
        if (segment != np.round(segment)).any():
            k = int(np.flatnonzero(segment != np.round(segment))[0])
            raise ModelError(f"{what}: {name!r} line {lines[k]} column segment: {segment[k]:g} is not allowed; "
                             "allowed: a whole number from 1")
        parts = (segment, *(_numbers(body[col[c]], what, name, lines, c, 0.0, float(MAX_EPOCH), missing=True,
                                     unit="s") for c in ("clock_from", "clock_to")))
        if "clock_part" in col:  # a receiver's time went back in the detections' order: each segment's part
            clock_part = _numbers(body[col["clock_part"]], what, name, lines, "clock_part", 1, MAX_OFFSET_ROWS)
            if (clock_part != np.round(clock_part)).any():
                k = int(np.flatnonzero(clock_part != np.round(clock_part))[0])
                raise ModelError(f"{what}: {name!r} line {lines[k]} column clock_part: {clock_part[k]:g} is not "
                                 "allowed; allowed: a whole number from 1")
            parts = (*parts, clock_part)
    return clocks_of(receiver, bins, start, end, first, last, f"{what}: {name!r}", noise, parts, clock_sigma)


def _in_folder(folder: Path, name: str) -> Path:
    """A synchronisation's own file in its folder; refused where it (links followed) leaves the folder
    (:func:`sblsim.orchestrator.io.paths.inside`: the folder a user names holds the tables, it does not point at
    others)."""
    return inside(folder, name, f"sync: {str(folder)[:80]!r}", "synchronisation")


def offsets_clocks(offsets: pd.DataFrame) -> Clocks:
    """The clocks of a synchronisation made in this process (its ``offsets.csv`` table:
    :attr:`~sblsim.orchestrator.sync.run.SyncOutcome.offsets`), with each receiver's timing noise where it has the
    ``toa_sigma_s`` column."""
    return clocks_of(offsets["receiver"].astype(str).to_numpy(), offsets["bin"].to_numpy(float),
                     offsets["start"].to_numpy(float), offsets["end"].to_numpy(float),
                     offsets["offset_start_s"].to_numpy(float), offsets["offset_end_s"].to_numpy(float),
                     "sync: the synchronisation's offsets",
                     offsets["toa_sigma_s"].to_numpy(float) if "toa_sigma_s" in offsets else None,
                     tuple(offsets[c].to_numpy(float) for c in ("segment", "clock_from", "clock_to", "clock_part")
                           if c in offsets) if "segment" in offsets else None,
                     offsets["clock_sigma_s"].to_numpy(float) if "clock_sigma_s" in offsets else None)


def logged_clocks(receivers: list[str], start: float, end: float) -> Clocks:
    """Clocks taken as logged (every offset zero from ``start`` to ``end`` [s since 1970 UTC]): receivers whose
    times are synchronised already, where the study has no sync tag."""
    return Clocks(list(receivers), np.array([start, max(end, start + 1.0)]), np.zeros((len(receivers), 2)))


def clocks_of(receiver: np.ndarray, bins: np.ndarray, start: np.ndarray, end: np.ndarray, first: np.ndarray,
              last: np.ndarray, where: str, toa_sigma: np.ndarray | None = None,
              segments: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
              clock_sigma: np.ndarray | None = None) -> Clocks:
    """Each receiver's offsets at the bins' edges from one row per receiver and bin (``offsets.csv``'s columns), and
    its timing noise where ``toa_sigma`` (one per row [s]) is given, its clock offset's uncertainty where
    ``clock_sigma`` (one per row [s]) is; where ``segments`` (``segment``, ``clock_from``,
    ``clock_to`` per row: a clock broke; and ``clock_part`` where its time went back in the detections' order) is
    given, one set of rows per receiver and segment, each segment holding for its receiver's own times from
    ``clock_from`` to ``clock_to`` (NaN: open) in its part.

    Raises
    ------
    ModelError
        One line naming ``where``: bins that are not the same contiguous edges for every receiver, a receiver
        lacking a bin, an offset not continuous across a bin's edge, a receiver's timing noise (or its clock's
        uncertainty) not the same on all its rows, a segment whose times differ between its rows or overlap
        another's of its receiver.
    """
    owner_names = receiver
    if segments is not None:  # one clock per receiver and segment
        receiver = np.array([f"{r} segment {int(k)}" for r, k in zip(receiver, segments[0])], dtype=object)
    names = list(dict.fromkeys(receiver.tolist()))
    index = {n: j for j, n in enumerate(names)}
    j = np.array([index[n] for n in receiver])
    n_bins = int(bins.max()) + 1
    if len(receiver) != len(names) * n_bins:
        raise ModelError(f"{where} has {len(receiver)} rows for {len(names)} receivers and {n_bins} bins; "
                         "allowed: one row per receiver and bin (sblsim sync's offsets.csv)")
    seen = np.zeros((len(names), n_bins), bool)
    seen[j, bins.astype(np.int64)] = True
    if not seen.all():
        raise ModelError(f"{where}: receiver {names[int(np.argwhere(~seen)[0][0])]} lacks a bin or has one twice; "
                         "allowed: one row per receiver and bin")
    b = bins.astype(np.int64)
    edges = np.full(n_bins + 1, np.nan)
    edges[b] = start
    edges[b + 1] = end
    if not (np.allclose(edges[b], start, rtol=0, atol=1e-6) and np.allclose(edges[b + 1], end, rtol=0, atol=1e-6)
            and (np.diff(edges) > 0).all()):
        raise ModelError(f"{where}: the bins' start and end are not the same increasing edges for every receiver; "
                         "allowed: sblsim sync's offsets.csv")
    knots = np.full((len(names), n_bins + 1), np.nan)
    knots[j, b] = first
    knots[j, b + 1] = last
    if not (np.allclose(knots[j, b], first, rtol=0, atol=1e-6) and np.allclose(knots[j, b + 1], last, rtol=0,
                                                                                  atol=1e-6)):
        raise ModelError(f"{where}: an offset is not continuous across a bin's edge (a bin's end differs from the "
                         "next bin's start); allowed: sblsim sync's offsets.csv")
    noise = None if toa_sigma is None else _one_per_row(toa_sigma, names, j, "toa_sigma_s", where)
    offset_sigma = None if clock_sigma is None else _one_per_row(clock_sigma, names, j, "clock_sigma_s", where)
    if segments is None:
        return Clocks(names, edges, knots, noise, offset_sigma)
    clocks = _segmented(names, j, owner_names, segments, edges, knots, noise, where)
    if offset_sigma is not None:  # per receiver (every segment's the receiver's own)
        clocks.clock_sigma = np.full(len(clocks.receivers), np.nan)
        clocks.clock_sigma[clocks.owner] = offset_sigma
    return clocks


def _one_per_row(values: np.ndarray, names: list[str], j: np.ndarray, column: str, where: str) -> np.ndarray:
    """(len(names),) the value of each clock row from the file's rows (``j`` each one's clock row).

    Raises
    ------
    ModelError
        A clock row's ``column`` differs between its rows (one line).
    """
    out = np.full(len(names), np.nan)
    out[j] = values
    if not np.array_equal(out[j], values):
        bad = names[int(j[np.flatnonzero(out[j] != values)[0]])]
        raise ModelError(f"{where}: receiver {bad}'s {column} differs between its rows; allowed: one value per "
                         "receiver (sblsim sync's offsets.csv)")
    return out


def _segmented(keys: list[str], j: np.ndarray, owner_names: np.ndarray, segments: tuple, edges: np.ndarray,
               knots: np.ndarray, noise: np.ndarray | None, where: str) -> Clocks:
    """The clocks of :func:`clocks_of` whose rows are clock segments (``keys``, each file row's ``j``): each
    segment's receiver and span, checked (the same on all its rows, not overlapping its receiver's others)."""
    receivers = list(dict.fromkeys(owner_names.tolist()))
    index = {n: k for k, n in enumerate(receivers)}
    owner = np.zeros(len(keys), np.int64)
    owner[j] = [index[n] for n in owner_names]
    spans = np.zeros((len(keys), 2))
    low = np.where(np.isnan(segments[1]), -np.inf, segments[1])
    high = np.where(np.isnan(segments[2]), np.inf, segments[2])
    spans[j, 0], spans[j, 1] = low, high
    part = np.ones(len(keys), np.int64)
    given = segments[3] if len(segments) > 3 else np.ones(len(j))
    part[j] = given
    if not (np.array_equal(spans[j, 0], low) and np.array_equal(spans[j, 1], high)
            and np.array_equal(part[j], given)):
        bad = keys[int(j[np.flatnonzero((spans[j, 0] != low) | (spans[j, 1] != high) | (part[j] != given))[0]])]
        raise ModelError(f"{where}: receiver {bad}'s clock_from, clock_to or clock_part differs between its rows; "
                         "allowed: one span per segment (sblsim sync's offsets.csv)")
    for k in range(len(receivers)):
        for p in np.unique(part[owner == k]):  # a part's segments one after the other (two parts may overlap)
            mine = np.flatnonzero((owner == k) & (part == p))
            mine = mine[np.argsort(spans[mine, 0], kind="stable")]
            if (spans[mine, 0] > spans[mine, 1]).any() or (spans[mine[1:], 0] <= spans[mine[:-1], 1]).any():
                raise ModelError(f"{where}: receiver {receivers[k]}'s clock segments hold for times that overlap or "
                                 "run backwards (clock_from, clock_to); allowed: sblsim sync's offsets.csv")
    per_receiver = None
    if noise is not None:
        per_receiver = np.full(len(receivers), np.nan)
        per_receiver[owner] = noise
    return Clocks(receivers, edges, knots, per_receiver, owner=owner, spans=spans,
                  parts=part if len(segments) > 3 else None)


def _columns(path: Path, what: str, needed: tuple[str, ...], source: str, optional: tuple[str, ...] = ()) -> tuple:
    """One of ``sblsim sync``'s own tables read back (:func:`_table`, at most :data:`MAX_OFFSET_ROWS` rows): its
    body, line numbers, name and the index of each ``needed`` column and of each ``optional`` one the table has
    (header case ignored, other columns ignored).

    Raises
    ------
    ModelError
        One line naming the columns needed and ``source`` (what writes the table), where one is missing or there
        are no rows.
    """
    header, body, lines = _table(path, what, MAX_OFFSET_ROWS)
    name = str(path)
    lower = [h.lower() for h in header]
    missing = [c for c in needed if c not in lower]
    if missing or not len(body):
        raise ModelError(f"{what}: {name!r}: needs the columns {', '.join(needed)} and rows ({source}); "
                         f"{', '.join(missing) or 'no rows'} missing")
    return body, lines, name, {c: lower.index(c) for c in (*needed, *(o for o in optional if o in lower))}


def read_positions(folder: Path | str) -> dict[str, tuple[float, float]] | None:
    """The refined positions of a synchronisation's folder (``positions.csv``: ``serial``, ``x_m``, ``y_m``; other
    columns ignored), None where it has none (the positions were not refined).

    Raises
    ------
    ModelError
        One line: a cell outside its pattern or range, a receiver twice.
    """
    path = _in_folder(Path(folder), "positions.csv")
    if not path.exists():
        return None
    what = "sync"
    body, lines, name, col = _columns(path, what, ("serial", "x_m", "y_m"),
                                      "sblsim sync --refine-positions' positions.csv")
    serial = _pattern(body[col["serial"]], IDENTIFIER, what, name, lines, "serial",
                      "a receiver's serial of 1 to 40 letters, digits, '.', '_' or '-'").tolist()
    x = _numbers(body[col["x_m"]], what, name, lines, "x_m", -MAX_COORDINATE, MAX_COORDINATE, unit="m")
    y = _numbers(body[col["y_m"]], what, name, lines, "y_m", -MAX_COORDINATE, MAX_COORDINATE, unit="m")
    if len(set(serial)) != len(serial):
        raise ModelError(f"{what}: {name!r}: a receiver is listed twice; allowed: one row per receiver")
    return {n: (float(a), float(b)) for n, a, b in zip(serial, x, y)}


def with_positions(table: pd.DataFrame, refined: dict[str, tuple[float, float]] | None) -> tuple[pd.DataFrame, int]:
    """The receivers table (``receiver``, ``x``, ``y``, ...) with a synchronisation's refined horizontal positions
    (:func:`read_positions`; None: none) in place of the table's for the receivers it lists; and how many it moved."""
    if refined is None:
        return table, 0
    table = table.copy()
    moved = table["receiver"].isin(refined).to_numpy()
    table.loc[moved, "x"] = [refined[n][0] for n in table.loc[moved, "receiver"]]
    table.loc[moved, "y"] = [refined[n][1] for n in table.loc[moved, "receiver"]]
    return table, int(moved.sum())


@dataclass
class ToaOutcome:
    """What :func:`build_toa` computed: ``toa`` (P, R) [s] on the base ``origin`` [s since 1970 UTC], ``names`` the
    receivers (columns), ``positions`` (R, dim) [m], ``pings`` (``pings.csv``), ``summary`` (``toa.json``),
    ``frame`` (the positions' metric frame; None without a CRS) and ``toa_sigma`` (R,) [s] each receiver's timing
    noise from the synchronisation (None where it gives none), ``clock_sigma`` (R,) [s] its clock offset's own
    uncertainty (likewise)."""

    toa: np.ndarray
    names: list[str]
    positions: np.ndarray
    pings: pd.DataFrame
    summary: dict[str, Any]
    origin: float
    frame: Frame | None = None
    toa_sigma: np.ndarray | None = None
    clock_sigma: np.ndarray | None = None


def tags_present(detections: Detections, limit: int = 8) -> str:
    """The tags with the most detections, for a refusal's allowed values."""
    counts = detections.frame["tag"].value_counts()
    return ", ".join(f"{t} ({n})" for t, n in counts.head(limit).items())


def build_toa(detections: Detections, hydrophones: pd.DataFrame, clocks: Clocks, tag: str,
              shortest: float | None = None, ping_type: dict[str, Any] | None = None,
              force_interval: bool = False) -> ToaOutcome:
    """One tag's times-of-arrival matrix (the module docstring).

    Parameters
    ----------
    detections : Detections
        The raw detections (:func:`~sblsim.orchestrator.sync.detections.read_detections`).
    hydrophones : pandas.DataFrame
        The receivers (:func:`~sblsim.orchestrator.sync.detections.read_hydrophones`).
    clocks : Clocks
        The synchronisation (:func:`read_clocks`).
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
        detections it drops; refused without.

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
    raw = use["time"].to_numpy(float)
    part = use["clock_part"].to_numpy(np.int64) if "clock_part" in use else None  # a reset in the file's order
    j_sync = clocks.rows(use["receiver"].map(synced).to_numpy(np.int64), raw, part)  # -1: between two segments
    width = float(np.max(np.diff(clocks.edges)))
    inside = (raw >= clocks.edges[0] - width) & (raw <= clocks.edges[-1] + width) & (j_sync >= 0)
    times = raw - clocks.offset(np.maximum(j_sync, 0), raw)
    receiver = use["receiver"].map(column).to_numpy(np.int64)
    window = largest_travel_time(positions, SLOWEST_SOUND_SPEED) + TOLERANCE
    source = "given"
    if shortest is None:
        shortest = inferred_shortest(receiver[inside], times[inside], window)
        source = "inferred"
        if shortest is None:
            raise ModelError(f"tag: {tag!r} has too few successive detections at one receiver to show its shortest "
                             "burst interval; allowed: give it (--ping-type rbi --burst-interval MIN:MAX)")
    seen = interval_seen(receiver[inside], times[inside], window, shortest) if source == "given" else None
    said = None
    if seen is not None and seen.contradicted:  # said before the echo limit drops the detections
        given = (ping_type or {}).get("burst_interval_s")
        stated = f"{given[0]:g}:{given[1]:g} s" if given else f"a shortest interval of {shortest:g} s"
        said = (f"burst interval: {stated} stated, but the detections' steps at one receiver show "
                f"{seen.low:.0f}-{seen.high:.0f} s ({seen.below} of {seen.steps} steps below {shortest:g} s less the "
                f"{window:.3g} s window)")
        if not force_interval:
            raise ModelError(f"{said}; allowed: the tag's interval, or --force-interval to use it anyway")
    pings = build_pings(receiver[inside], times[inside], len(columns), window, shortest)
    if said is not None:
        said += (f"; taken (--force-interval): {int(pings.echo.sum())} of {int(inside.sum())} detections dropped as "
                 "multipath echoes by it")
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
    return ToaOutcome(toa - origin, columns, positions, table_pings, summary, origin, toa_sigma=noise,
                      clock_sigma=offset_sigma)


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


def sensor_depth(outcome: ToaOutcome) -> tuple[np.ndarray | None, str | None]:
    """The tag's depth per ping from its depth sensor (``pings``' ``depth_m``: readings in metres, a VUE export's
    calibrated depth or a tag sheet's conversion) for the tracker, where the receivers are in 3-D; else None, and a
    note where readings are left to ``pings.csv`` (a 2-D array has no depth to take them).

    Returns
    -------
    depth : ndarray, (P,) or None
        [m] per ping, NaN where the ping has no reading.
    note : str or None
    """
    if "depth_m" not in outcome.pings or not np.isfinite(outcome.pings["depth_m"].to_numpy(float)).any():
        return None, None
    if outcome.positions.shape[1] != 3:
        return None, (f"tag {outcome.summary['tag']}: its depth readings are not used by the tracker (the receivers "
                      "have no depths: 2-D); they are in its pings.csv")
    return outcome.pings["depth_m"].to_numpy(float), None


def write_toa_folder(outcome: ToaOutcome, out: Path) -> None:
    """``toa.txt`` (the replay's format: a header of receiver names, ``NA`` where not heard, [s] from
    ``origin_epoch_s``; no header where every name is a number: :func:`header_line`; the tag's depth per ping
    first where its sensor gives one in 3-D, :func:`sensor_depth`), ``receivers.csv`` (``name, x_m, y_m[, z_m]``),
    ``pings.csv`` and ``toa.json``, all or nothing."""
    with staged_directory(out) as tmp:
        write_matrix(outcome, tmp, sensor_depth(outcome)[0])
        outcome.pings.to_csv(tmp / "pings.csv", index=False, float_format="%.9f")
        (tmp / "toa.json").write_text(json.dumps(outcome.summary, indent=2, allow_nan=False) + "\n")


def header_line(names: list[str]) -> bool:
    """Whether ``toa.txt`` has a header of the receivers' names: not where every name reads as a number (serials
    such as ``1623``), which the replay would take for a row of times; then the columns are ``receivers.csv``'s rows
    in order, as the replay reads a matrix without a header."""
    return not all(NUMBER.fullmatch(n) for n in names)


def write_matrix(outcome: ToaOutcome, folder: Path, depth: np.ndarray | None = None) -> tuple[Path, Path]:
    """``toa.txt`` and ``receivers.csv`` in ``folder`` (what the replay reads); returns their paths. With ``depth``
    (P,) [m] the tag's depth per ping (NaN where none), ``toa.txt`` has a ``depth_m`` column first (and a header
    whatever the receivers' names: the column's name is not a number). ``receivers.csv`` has each receiver's
    timing noise (``toa_sigma_s`` [s]) and its clock offset's uncertainty (``clock_sigma_s`` [s]) where the
    synchronisation gives them."""
    frame = pd.DataFrame(outcome.toa, columns=outcome.names)
    if depth is not None:
        frame.insert(0, DEPTH_COLUMN, depth)
    toa = folder / "toa.txt"
    frame.to_csv(toa, sep=" ", na_rep="NA", index=False, float_format="%.9f",
                 header=depth is not None or header_line(outcome.names))
    axes = ["x_m", "y_m", "z_m"][:outcome.positions.shape[1]]
    receivers = folder / "receivers.csv"
    table = pd.DataFrame(outcome.positions, columns=axes)
    table.insert(0, "name", outcome.names)
    if outcome.toa_sigma is not None:  # seconds: significant figures, not the positions' four decimals
        table["toa_sigma_s"] = [f"{v:.6g}" for v in outcome.toa_sigma]
    if outcome.clock_sigma is not None:
        table["clock_sigma_s"] = [f"{v:.6g}" for v in outcome.clock_sigma]
    table.to_csv(receivers, index=False, float_format="%.4f")
    return toa, receivers


# --------------------------------------------------------------------------- the commands' shared steps

def _burst(value: Any, where: str) -> tuple[float, float] | None:
    """``MIN:MAX`` [s] (a text or a pair), 0.1 ≤ MIN ≤ MAX ≤ 86,400 s."""
    if value is None:
        return None
    allowed = f"MIN:MAX [s] with {BURST_LIMITS[0]:g} <= MIN <= MAX <= {BURST_LIMITS[1]:g}, e.g. 60:120"
    try:
        pair = tuple(float(p) for p in (value.split(":") if isinstance(value, str) else value))
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: {str(value)[:40]!r}; allowed: {allowed}") from None
    if len(pair) != 2 or not BURST_LIMITS[0] <= pair[0] <= pair[1] <= BURST_LIMITS[1]:
        raise ConfigError(f"{where}: {str(value)[:40]!r}; allowed: {allowed}")
    return pair


def check_ping_type(ping_type: Any, burst_interval: Any, burst_sequence: Any, names: tuple[str, str, str]
                    ) -> tuple[str | None, tuple[float, float] | None, Path | None]:
    """The ping type's three options checked together (``names``: how they are spelled where they were given)."""
    if ping_type is not None and ping_type not in PING_TYPE_NAMES:
        raise ConfigError(f"{names[0]}: {str(ping_type)[:40]!r}; allowed: {', '.join(PING_TYPE_NAMES)}")
    interval = _burst(burst_interval, names[1])
    if burst_sequence is not None and not isinstance(burst_sequence, (str, os.PathLike)):
        raise ConfigError(f"{names[2]}: {type(burst_sequence).__name__}; allowed: a file (a text or a path)")
    sequence = None if burst_sequence is None else Path(burst_sequence)
    if interval is not None and ping_type != "rbi":
        raise ConfigError(f"{names[1]}: only with {names[0]} rbi (a random burst interval)")
    if sequence is not None and ping_type != "pbi":
        raise ConfigError(f"{names[2]}: only with {names[0]} pbi (a pseudo-random burst interval)")
    if ping_type == "pbi" and sequence is None:
        raise ConfigError(f"{names[0]} pbi: needs {names[2]} (the tag's intervals [s], one per row)")
    return ping_type, interval, sequence


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
    study's deployments (:func:`~sblsim.orchestrator.telemetry.deployments.read_deployments`, in ``crs``, projected
    to ``frame``), each detection at its deployment (the others set aside: ``summary["set_aside"]``); a stated
    interval the detections contradict refused unless ``force_interval`` (then a warning).

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
    assigned = assign(read_detections(detections, format), deployments)
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
    if refined is not None:
        outcome.summary["positions"] = {"source": "the synchronisation's positions.csv (refined)",
                                        "receivers": moved}
    return outcome


def run_lines(outcome, where: str) -> list[str]:
    """The console's lines on a built matrix."""
    s = outcome.summary
    d = s["detections"]
    heard = s["heard_per_ping"]
    lines = [f"times of arrival of tag {s['tag']}: {s['pings']} pings at {len(s['receivers'])} receivers from "
             f"{d['of_tag']} detections ({d['used']} used, {d['multipath']} multipath echoes dropped, "
             f"{d['outside_sync_span']} outside the synchronised span, "
             + (f"{d['at_clock_breaks']} at clock breaks (set aside), " if d.get("at_clock_breaks") else "")
             + f"{d['at_receivers_not_in_table']} at receivers "
             f"not in the table, {d['at_receivers_not_synchronised']} at receivers not synchronised) in "
             f"{s['wall_time_s']:.2f} s",
             f"  window {s['window_s'] * 1e3:.0f} ms (the array's largest travel time at 1300 m/s and 20 ms), shortest "
             f"burst interval {s['shortest_interval_s']:.4g} s ({s['shortest_interval_source']}); receivers per ping: "
             + ", ".join(f"{k}: {v}" for k, v in heard.items()),
             f"  time base of toa.txt: {s['origin_epoch_s']:.0f} s since 1970-01-01 UTC"
             + (f"; sensor values per ping: {', '.join(s['sensors'])}" if s["sensors"] else "")]
    if "positions" in s:
        lines.append(f"  receivers' positions: {s['positions']['receivers']} from the synchronisation's "
                     "positions.csv (refined)")
    noise = s.get("toa_sigma_s")
    if noise:
        values = np.array(list(noise.values()))
        lines.append(f"  TOA noise per receiver from the synchronisation's residuals (receivers.csv's toa_sigma_s, "
                     f"the tracker's): median {np.median(values) * 1e3:.3g} ms, {values.min() * 1e3:.3g} to "
                     f"{values.max() * 1e3:.3g} ms")
    elif noise is None and "toa_sigma_s" in s:
        lines.append("  TOA noise: the synchronisation's offsets.csv gives none (written before its toa_sigma_s): the "
                     f"tracker will assume {SIGMA_TOA * 1e3:g} ms (give --toa-sigma to the replay)")
    if where:
        lines.append(f"  written to {where}/ (toa.txt, receivers.csv, pings.csv, toa.json)")
    return lines


def say_warnings(summary: dict[str, Any]) -> None:
    """A built matrix's warnings (``summary["warnings"]``: times rounded too coarsely), each a line on stderr."""
    for warning in summary.get("warnings", []):
        print(f"sblsim: warning: {warning}", file=sys.stderr)


#: ``sblsim replay --format``'s names of raw detections (``detections``: read from the file's first line).
REPLAY_FORMATS = {"detections": None, **{f: f for f in DETECTION_FORMATS}}


@contextmanager
def replay_matrix(args: argparse.Namespace) -> Iterator[argparse.Namespace]:
    """``sblsim replay DETECTIONS --format detections|yaps|vue --receivers HYDROPHONES --sync DIR --tag ID``: the
    tag's matrix built as ``sblsim toa`` builds it (its lines printed), written with its receivers into a temporary
    folder (named by the tag, so the track's default folder is ``results/track_TAG``), and yielded as the arguments
    of ``replay --format toa`` on them; the folder is removed when the replay ends.

    Raises
    ------
    ConfigError, ModelError
        ``--sync``, ``--tag`` or ``--receivers`` missing; what :func:`build` refuses.
    """
    missing = [o for o, v in (("--receivers", args.receivers), ("--sync", args.sync), ("--tag", args.tag)) if v is None]
    if missing:
        raise ConfigError(f"{missing[0]}: required with --format {args.format} (raw detections: --receivers "
                          "HYDROPHONES --sync DIR --tag ID)")
    kind, interval, sequence = check_ping_type(args.ping_type, args.burst_interval, args.burst_sequence,
                                               ("--ping-type", "--burst-interval", "--burst-sequence"))
    outcome = build(args.log, args.receivers, args.sync, args.tag, REPLAY_FORMATS[args.format], kind, interval,
                    sequence, args.crs, args.frame, args.force_interval)
    for line in run_lines(outcome, ""):
        print(line, flush=True)
    say_warnings(outcome.summary)
    with tempfile.TemporaryDirectory(prefix="sblsim-toa-") as tmp:
        folder = Path(tmp) / "".join(c if c.isalnum() or c in "._-" else "_" for c in args.tag)
        folder.mkdir()
        depth, note = sensor_depth(outcome)
        if note:
            print(f"note: {note}", file=sys.stderr)
        toa, receivers = write_matrix(outcome, folder, depth)
        named = toa.with_name(f"{folder.name}.txt")
        toa.rename(named)
        yield argparse.Namespace(**{**vars(args), "log": named, "receivers": receivers, "format": "toa",
                                    "sync": None, "tag": None, "time_origin": outcome.origin,
                                    "crs": None if outcome.frame is None else outcome.frame.crs, "frame": None})


__all__ = ["BURST_LIMITS", "Clocks", "FORMATS", "PING_TYPE_NAMES", "REPLAY_FORMATS", "SENSOR_COLUMNS",
           "SLOWEST_SOUND_SPEED", "TOLERANCE", "ToaOutcome", "build", "build_toa", "check_ping_type", "clocks_of",
           "header_line", "logged_clocks", "offsets_clocks", "read_clocks", "replay_matrix", "run_lines",
           "say_warnings", "sensor_depth", "tags_present", "with_positions", "write_matrix", "write_toa_folder"]
