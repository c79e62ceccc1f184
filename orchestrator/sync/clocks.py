"""A synchronisation read back from its folder (``sblsim sync --out DIR``) for a times-of-arrival matrix: the
receivers' clocks (``offsets.csv``) and, where the positions were refined, the receivers' positions
(``positions.csv``).

The clocks are read from the folder's ``offsets.csv`` only, by that fixed name, as hostile input like any table
(bounded, every cell checked, nothing in it taken as a path); each receiver's offset is the file's knots interpolated
at the detection's own time (the sync's model: piecewise linear, continuous across the bins), extended with the end
bin's drift (:meth:`Clocks.offset`).

A synchronisation also writes each receiver's timing noise from its sync-tag residuals (``offsets.csv``'s
``toa_sigma_s``) and its clock offset's own uncertainty (``clock_sigma_s``): read where the file has them (a folder
written before those columns has none).

Where a receiver's clock broke (jumped or went back), ``offsets.csv`` has a set of rows per clock segment
(``segment``, and the times of the receiver's own clock it holds for, ``clock_from`` to ``clock_to``): each
detection takes the segment that holds its time (:meth:`Clocks.rows`), and one between two segments is set aside.
Where a receiver's time went back in the detections file's order, ``offsets.csv`` also says each segment's clock
part (``clock_part``) and a detection takes a segment of its own part (:mod:`.detections`): two parts may read the
same times.

A synchronisation made with ``--refine-positions`` also wrote ``positions.csv``: its refined horizontal positions
(read the same way, :func:`read_positions`) replace the receivers table's ``x``, ``y`` of the receivers it lists
(:func:`with_positions`), and each one's error (:func:`read_position_sigmas`) goes with them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.sync.mean_offset import mean_offset_sigma
from sblsim.models.tracking.timing import CLOCK_SIGMA_RANGE, TOA_SIGMA_RANGE
from sblsim.orchestrator.io.paths import inside
from sblsim.orchestrator.readers.cells import file_table
from sblsim.orchestrator.readers.cells import numbers as _numbers
from sblsim.orchestrator.readers.cells import pattern as _pattern
from sblsim.orchestrator.readers.limits import IDENTIFIER, MAX_COORDINATE, MAX_EPOCH
from sblsim.orchestrator.readers.receivers_file import SURVEY_SIGMA_RANGE

#: The most rows of ``offsets.csv`` read (receivers × bins) and the largest offset [s] it may hold.
MAX_OFFSET_ROWS = 1_000_000
MAX_OFFSET = 30 * 86400.0
#: ``offsets.csv``'s columns of each row's offsets' σ at its start and end [s] and its drift's σ [s/s], with the most
#: each may say and its unit (:attr:`Clocks.knot_sigma`; all three or none).
SPREAD_COLUMNS = (("offset_start_sigma_s", MAX_OFFSET, "s"), ("offset_end_sigma_s", MAX_OFFSET, "s"),
                  ("drift_sigma", 1.0, "s/s"))


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
    #: Each receiver's offset's σ at each edge (R, K+1) [s] and its drift's σ in each bin (R, K) [s/s]
    #: (``offsets.csv``'s ``offset_start_sigma_s``, ``offset_end_sigma_s``, ``drift_sigma``; NaN where not
    #: computed), for a still tag's clock term averaged over its arrivals (:meth:`averaged_sigma`); None where the
    #: file has none, or a clock broke (a row per segment).
    knot_sigma: np.ndarray | None = None
    drift_sigma: np.ndarray | None = None

    def averaged_sigma(self, rows: list[int], times: np.ndarray) -> np.ndarray | None:
        """Each of ``rows``' (receivers of :attr:`knots`) offset error averaged over a tag's arrivals at it,
        ``times`` (pings, len(rows)) [s since 1970 UTC] (NaN: not heard): the bias a still tag's pooled pings share
        (:func:`~sblsim.models.sync.mean_offset.mean_offset_sigma`), [s]; a receiver with an edge its arrivals lean
        on without a σ keeps :attr:`clock_sigma`'s. None without both."""
        if self.clock_sigma is None or self.knot_sigma is None:
            return None
        out = np.array(self.clock_sigma[rows], float)
        for k, row in enumerate(rows):
            heard = times[np.isfinite(times[:, k]), k]
            if len(heard):
                mean = mean_offset_sigma(self.knot_sigma[row], self.drift_sigma[row], self.edges, heard)
                out[k] = mean if np.isfinite(mean) else out[k]
        return out

    def reference(self) -> str | None:
        """The reference receiver: the one whose clock the synchronisation took as the time base (its offset 0 at
        every edge, and the only such receiver); None where none or several are (clocks taken as logged)."""
        rows = np.arange(len(self.knots)) if self.owner is None else self.owner
        zero = np.all(self.knots == 0.0, axis=1)
        found = {int(r) for r in rows[zero]} - {int(r) for r in rows[~zero]}
        return self.receivers[found.pop()] if len(found) == 1 else None

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
    :data:`~sblsim.models.tracking.timing.TOA_SIGMA_RANGE`, the same on each of its rows, and ``clock_sigma_s``,
    its clock offset's own uncertainty [s] in [0, 1], likewise; ``offset_start_sigma_s``, ``offset_end_sigma_s``
    [s] and ``drift_sigma`` [s/s] where it has all three, each offset's and drift's σ (empty: not computed); other
    columns ignored).

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
                                       "clock_part", *(c for c, _, _ in SPREAD_COLUMNS)))
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
    spread = None
    if all(c in col for c, _, _ in SPREAD_COLUMNS):  # (a folder before them: none)
        spread = tuple(_numbers(body[col[c]], what, name, lines, c, 0.0, high, missing=True, unit=unit)
                       for c, high, unit in SPREAD_COLUMNS)
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
    return clocks_of(receiver, bins, start, end, first, last, f"{what}: {name!r}", noise, parts, clock_sigma,
                     spread)


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
                     offsets["clock_sigma_s"].to_numpy(float) if "clock_sigma_s" in offsets else None,
                     tuple(offsets[c].to_numpy(float) for c, _, _ in SPREAD_COLUMNS)
                     if all(c in offsets for c, _, _ in SPREAD_COLUMNS) else None)


def logged_clocks(receivers: list[str], start: float, end: float) -> Clocks:
    """Clocks taken as logged (every offset zero from ``start`` to ``end`` [s since 1970 UTC]): receivers whose
    times are synchronised already, where the study has no sync tag."""
    return Clocks(list(receivers), np.array([start, max(end, start + 1.0)]), np.zeros((len(receivers), 2)))


def clocks_of(receiver: np.ndarray, bins: np.ndarray, start: np.ndarray, end: np.ndarray, first: np.ndarray,
              last: np.ndarray, where: str, toa_sigma: np.ndarray | None = None,
              segments: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
              clock_sigma: np.ndarray | None = None,
              spread: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> Clocks:
    """Each receiver's offsets at the bins' edges from one row per receiver and bin (``offsets.csv``'s columns), and
    its timing noise where ``toa_sigma`` (one per row [s]) is given, its clock offset's uncertainty where
    ``clock_sigma`` (one per row [s]) is; where ``segments`` (``segment``, ``clock_from``,
    ``clock_to`` per row: a clock broke; and ``clock_part`` where its time went back in the detections' order) is
    given, one set of rows per receiver and segment, each segment holding for its receiver's own times from
    ``clock_from`` to ``clock_to`` (NaN: open) in its part; ``spread`` the rows' offsets' σ at their start and end
    and their drift's σ (:attr:`Clocks.knot_sigma`, kept where no clock broke).

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
        clocks = Clocks(names, edges, knots, noise, offset_sigma)
        if spread is not None:
            clocks.knot_sigma = np.full(knots.shape, np.nan)
            clocks.knot_sigma[j, b] = spread[0]
            clocks.knot_sigma[j, b + 1] = spread[1]
            clocks.drift_sigma = np.full((len(names), n_bins), np.nan)
            clocks.drift_sigma[j, b] = spread[2]
        return clocks
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
    header, body, lines = file_table(path, what, MAX_OFFSET_ROWS)
    name = str(path)
    lower = [h.lower() for h in header]
    missing = [c for c in needed if c not in lower]
    if missing or not len(body):
        raise ModelError(f"{what}: {name!r}: needs the columns {', '.join(needed)} and rows ({source}); "
                         f"{', '.join(missing) or 'no rows'} missing")
    return body, lines, name, {c: lower.index(c) for c in (*needed, *(o for o in optional if o in lower))}


def _positions_rows(folder: Path | str, needed: tuple[str, ...], optional: tuple[str, ...] = ()) -> tuple | None:
    """A synchronisation's ``positions.csv`` read back (:func:`_columns`): its body, line numbers, name, columns and
    each row's receiver serial (checked); None where the folder has none."""
    path = _in_folder(Path(folder), "positions.csv")
    if not path.exists():
        return None
    body, lines, name, col = _columns(path, "sync", ("serial", *needed),
                                      "sblsim sync --refine-positions' positions.csv", optional)
    serial = _pattern(body[col["serial"]], IDENTIFIER, "sync", name, lines, "serial",
                      "a receiver's serial of 1 to 40 letters, digits, '.', '_' or '-'").tolist()
    return body, lines, name, col, serial


def _by_serial(serial: list[str], values, name: str) -> dict:
    """Each receiver's value by its serial.

    Raises
    ------
    ModelError
        A receiver listed twice (one line).
    """
    if len(set(serial)) != len(serial):
        raise ModelError(f"sync: {name!r}: a receiver is listed twice; allowed: one row per receiver")
    return dict(zip(serial, values))


def read_positions(folder: Path | str) -> dict[str, tuple[float, float]] | None:
    """The refined positions of a synchronisation's folder (``positions.csv``: ``serial``, ``x_m``, ``y_m``; other
    columns ignored), None where it has none (the positions were not refined).

    Raises
    ------
    ModelError
        One line: a cell outside its pattern or range, a receiver twice.
    """
    read = _positions_rows(folder, ("x_m", "y_m"))
    if read is None:
        return None
    body, lines, name, col, serial = read
    x = _numbers(body[col["x_m"]], "sync", name, lines, "x_m", -MAX_COORDINATE, MAX_COORDINATE, unit="m")
    y = _numbers(body[col["y_m"]], "sync", name, lines, "y_m", -MAX_COORDINATE, MAX_COORDINATE, unit="m")
    return _by_serial(serial, [(float(a), float(b)) for a, b in zip(x, y)], name)


def read_position_sigmas(folder: Path | str) -> dict[str, float] | None:
    """Each receiver's position error [m per horizontal axis] in a synchronisation's folder whose positions were
    refined (``positions.csv``'s ``position_sigma_m``: its posterior σ in the array's shape where refined, the
    survey's where the table's position was kept), by its serial; None where the folder has no ``positions.csv``,
    or one written before that column.

    Raises
    ------
    ModelError
        One line: a cell outside its pattern or range
        (:data:`~sblsim.orchestrator.readers.receivers_file.SURVEY_SIGMA_RANGE`), a receiver twice.
    """
    read = _positions_rows(folder, (), ("position_sigma_m",))
    if read is None or "position_sigma_m" not in read[3]:
        return None
    body, lines, name, col, serial = read
    sigma = _numbers(body[col["position_sigma_m"]], "sync", name, lines, "position_sigma_m", *SURVEY_SIGMA_RANGE,
                     unit="m")
    return _by_serial(serial, [float(v) for v in sigma], name)


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


__all__ = ["Clocks", "MAX_OFFSET", "MAX_OFFSET_ROWS", "SPREAD_COLUMNS", "clocks_of", "logged_clocks", "offsets_clocks",
           "read_clocks", "read_position_sigmas", "read_positions", "with_positions"]
