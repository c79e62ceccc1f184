"""The receiver's log (docs/log-format.md): its columns and its reading from a recorder's file or an export.

A log holds, per received packet, its epoch, the beacon
id, the range (or the travel time), the beacon position the packet carried
and the depth reading; for USBL the direction of arrival. A row without a
beacon id is a depth reading only (a slot whose packet was lost, or a depth
sensor's sample). :func:`read_log` reads a CSV or Parquet log and decides
what to do with every kind of flaw a real log has (:func:`read_log`,
"Flaws"); a run's export in that format is :mod:`sblsim.orchestrator.logs.log_export`'s, so
that a replay of the export (:mod:`sblsim.orchestrator.logs.replay`) equals the run; a truth track is
:mod:`sblsim.orchestrator.logs.truth_track`'s, the lowest range a channel measures
:mod:`sblsim.orchestrator.logs.range_floor`'s.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from sblsim.models.acoustics.channel.component import Acoustics
from sblsim.models.declarations import SIGNAL_RANGES, ModelError
from sblsim.models.systems import System
from sblsim.orchestrator.cosim.limits import MEMORY_SHARE, available_memory
from sblsim.orchestrator.io.log_tables import check_fits, table_chunks, table_length
from sblsim.orchestrator.io.log_tables import columns as _columns
from sblsim.orchestrator.io.tables import NUMBER  # the hostile-safe cell checks every log reader shares
from sblsim.orchestrator.io.tables import number as _number
from sblsim.orchestrator.logs.range_floor import range_floor

#: The log format's version (the first comment line of an exported CSV log, ``# sblsim log, format 1``).
FORMAT = 1
LOG_TITLE = f"sblsim log, format {FORMAT}"
TRUTH_TITLE = f"sblsim truth track, format {FORMAT}"
#: The memory a row of a log takes while it is read [bytes] (its numbers and place kept, their pieces joined, sorted
#: and without duplicates).
LOG_ROW_BYTES = 400
#: Rows that come up to this much earlier than a row before them are sorted into place (counted); a row
#: further back is a clock jump and the log is refused [s].
REORDER_WINDOW = 1.0
#: The log's columns: name -> (unit, meaning, when required).
LOG_COLUMNS = {
    "time_s": ("s", "the packet's epoch (its transmit time, the slot's tx_time); for a depth reading, its time",
               "always"),
    "rx_time": ("s", "the packet's arrival at the diver (on time_s's clock, not before it): the replay uses the row "
                "at its first step that reaches it; empty or no column: time_s", "optional"),
    "beacon_id": ("1", "the beacon the packet came from, 1 … N (USBL: 1); empty: the row is a depth reading only",
                  "always (the column)"),
    "range_m": ("m", "the measured range (one-way: c · travel time; two-way: c · (round trip − nominal turnaround) / "
                "2, negative where the turnaround's jitter exceeds the travel)",
                "one of range_m, travel_time_s"),
    "travel_time_s": ("s", "the one-way travel time (two-way ranging: (round trip − turnaround) / 2); range = "
                      "sound speed · travel time", "one of range_m, travel_time_s"),
    "sound_speed_mps": ("m/s", "the sound speed the hardware used to turn travel time into range (empty: the "
                        "configuration's acoustics.sound_speed_assumed)", "optional, with travel_time_s"),
    "beacon_n_m": ("m", "the beacon position the packet carried, North", "always"),
    "beacon_e_m": ("m", "the beacon position the packet carried, East", "always"),
    "beacon_d_m": ("m", "the beacon position the packet carried, Down", "always"),
    "depth_m": ("m", "the depth reading at time_s", "always"),
    "azimuth_rad": ("rad", "USBL: the direction of arrival's azimuth, clockwise from North (NED)", "USBL"),
    "elevation_rad": ("rad", "USBL: the direction of arrival's elevation below the horizontal", "USBL"),
    "doa_x": ("1", "USBL: the direction cosine of the reply along the array's x axis, as the array measured it",
              "USBL"),
    "doa_y": ("1", "USBL: the direction cosine of the reply along the array's y axis, as the array measured it",
              "USBL"),
    "doa_roll_rad": ("rad", "USBL: the roll with which the surface turned the direction into NED (the IMU's)",
                     "USBL"),
    "doa_pitch_rad": ("rad", "USBL: the pitch with which the surface turned the direction into NED", "USBL"),
    "doa_yaw_rad": ("rad", "USBL: the yaw with which the surface turned the direction into NED", "USBL"),
}
_PACKET_COLUMNS = ("beacon_n_m", "beacon_e_m", "beacon_d_m")


# --------------------------------------------------------------------------- the log

@dataclass
class Log:
    """A log read and checked (:func:`read_log`): its usable rows in time order and what was done to the others.

    Attributes
    ----------
    path : Path
    time : ndarray, shape (N,)
        Each row's arrival (``rx_time``, else ``time_s``) [s], non-decreasing: when the replay uses it.
    beacon : ndarray of int, shape (N,)
        Beacon id 1 … n; 0 for a depth reading only.
    range : ndarray, shape (N,)
        Range [m] (0 on a depth-only row).
    beacon_ned : ndarray, shape (N, 3)
        The beacon position the packet carried [m] (0 on a depth-only row).
    depth : ndarray, shape (N,)
        Depth reading [m].
    system_values : ndarray, shape (N, k), or None
        The columns the system adds, in the order of its
        :attr:`~sblsim.models.systems.System.log_columns` (USBL: azimuth and elevation [rad], the array's
        direction cosines [1] and the attitude the surface turned the direction with [rad]; 0 on a depth-only
        row).
    where : list of str
        Each row's place in the file (``line 12``, ``row 11``).
    counts : dict
        ``rows`` (data rows read), ``duplicate``, ``unknown_beacon`` (skipped), ``out_of_order`` (sorted).
    longest_gap : tuple
        (seconds, where the row after the gap is) of the longest time between two rows.
    typical_gap : float
        The median time between two rows [s] (0 for one row).
    ignored : list of str
        Columns the replay does not use.
    config : str
        The configuration an exported log carries (TOML; empty for another log).
    sent : ndarray, shape (N,)
        Each row's ``time_s`` (its transmit epoch) [s]; empty: the arrivals ``time``.
    system_columns : dict
        The system's log columns -> the receiver inputs they feed (those of :attr:`system_values`).
    """

    path: Path
    time: np.ndarray
    beacon: np.ndarray
    range: np.ndarray
    beacon_ned: np.ndarray
    depth: np.ndarray
    system_values: np.ndarray | None
    where: list[str]
    counts: dict[str, int]
    longest_gap: tuple[float, str]
    typical_gap: float = 0.0
    ignored: list[str] = field(default_factory=list)
    config: str = ""
    sent: np.ndarray = field(default_factory=lambda: np.zeros(0))
    system_columns: dict[str, str] = field(default_factory=dict)

    @property
    def transmit(self) -> np.ndarray:
        """Each row's transmit epoch ``time_s`` [s] (its arrival where the log gives none)."""
        return self.sent if self.sent.size == self.time.size else self.time


def log_config(path: Path | str) -> str:
    """The configuration (TOML text) an exported log carries, or '' (read without checking its rows).

    Raises
    ------
    ModelError
        As :func:`read_log` for a file that cannot be read.
    """
    return next(table_chunks(Path(path), "log")).config  # its first piece: the configuration comes first


def read_log(path: Path | str, n_beacons: int, system: System | None = None, sound_speed: float = 1500.0,
             acoustics: Mapping[str, Any] | None = None) -> Log:
    """Read and check a log (docs/log-format.md).

    Parameters
    ----------
    path : path
        A ``.csv`` or ``.parquet`` file.
    n_beacons : int
        Beacons of the configuration (ids 1 … n_beacons are known).
    system : System, optional
        The configuration's positioning system (:mod:`sblsim.models.systems`): the columns it adds to a log
        (:attr:`~sblsim.models.systems.System.log_columns`: USBL's direction of arrival, the array's direction
        cosines and the attitude) are required. Default: none added.
    sound_speed : float
        The sound speed that turns ``travel_time_s`` into range where the log gives none [m/s].
    acoustics : mapping, optional
        The configuration's ``[acoustics]``: a range (or travel time) below the lowest its channel measures
        (:func:`range_floor`) is refused. Default: not known, any range within the receiver's input range.

    Flaws (each a clear decision; a refusal is one line naming the file, the line and the column):

    * a line that does not parse (field count, a number that is not one, a required value that is empty or
      not finite, or outside the receiver's declared input range), a range below the lowest the configuration's
      channel measures (:func:`range_floor`), a missing required column, or both ``range_m`` and
      ``travel_time_s``: **refused**;
    * a beacon id that is not a whole number in 1 … n_beacons: the row is **skipped** (``unknown_beacon``);
    * an ``rx_time`` before the row's ``time_s``: **refused** (an arrival before its transmission), but in a log of
      an inverted LBL (``system`` of ``toa`` ranging), whose ``time_s`` is the ping's nominal epoch and whose
      emission may come before it;
    * a row with the same time and beacon id as an earlier one: **skipped** (``duplicate``);
    * a row that arrives (``rx_time``, else ``time_s``) up to :data:`REORDER_WINDOW` earlier than a row before
      it: **sorted** into place
      (``out_of_order``); further back, a clock jump: **refused** with the line;
    * a gap forward: **stepped through** (the receiver predicts), the longest reported; a gap so long that
      the replay would not fit in memory: refused with the line after it;
    * columns the replay does not know or use: **ignored** and listed.

    Returns
    -------
    Log

    Raises
    ------
    ModelError
        As listed above.
    """
    path = Path(path)
    name = str(path)
    check_fits(path, "log", table_length(path, "log"), LOG_ROW_BYTES, MEMORY_SHARE * available_memory())
    pieces = table_chunks(path, "log")  # in pieces: a log of any length in the memory its numbers take
    first = next(pieces)
    index = _columns(first, "log")
    doc = "see docs/log-format.md"
    extra = tuple(system.log_columns) if system is not None else ()  # the system's own columns (USBL)
    required = ["time_s", "beacon_id", *_PACKET_COLUMNS, "depth_m", *extra]
    missing = [c for c in required if c not in index]
    if missing:
        kind = f" (a {system.name.upper()} log)" if extra and set(missing) <= set(extra) else ""
        raise ModelError(f"log: {name!r} has no column {missing[0]}{kind}; its columns: "
                         f"{','.join(first.header)}; {doc}")
    has_range, has_travel = "range_m" in index, "travel_time_s" in index
    if has_range == has_travel:
        which = "both" if has_range else "neither of"
        raise ModelError(f"log: {name!r} has {which} range_m and travel_time_s; give one of them; {doc}")
    used = set(required) | {"range_m" if has_range else "travel_time_s"}
    if has_travel and "sound_speed_mps" in index:
        used.add("sound_speed_mps")
    has_arrival = "rx_time" in index
    if has_arrival:
        used.add("rx_time")
    # an inverted LBL's log: time_s is a ping's nominal epoch, not its emission, and a range its pseudo-range
    # against that epoch (negative where the ping left early)
    nominal = system is not None and "toa" in system.ranging
    ignored = [c for c in first.header if c not in used]
    speeds = next(v for v in Acoustics.variables() if v.name == "sound_speed_assumed")
    t_lo, t_hi = -1e12, 1e12  # any clock; the receiver runs on times from the log's start
    # a range is a measurement, not a distance: c times a measured time (two-way: the round trip less the nominal
    # turnaround, halved; one-way: on clocks that may be offset; an inverted LBL's: against a nominal epoch) plus
    # its noise, negative where the turnaround's jitter, a clock's offset or the noise exceeds the distance; the
    # run hands it to the receiver as it is, so the replay takes the receiver's input range, negative included
    r_lo, r_hi = SIGNAL_RANGES["range"]
    floor, fall, reason = range_floor(None if nominal else acoustics)
    start = math.nan  # the first row's time_s: a drifting clock's floor falls from there
    p_lo, p_hi = SIGNAL_RANGES["position"]
    d_lo, d_hi = SIGNAL_RANGES["depth"]

    counts = {"rows": 0, "unknown_beacon": 0, "duplicate": 0, "out_of_order": 0}
    parts: list[_Rows] = []
    latest, latest_where = -math.inf, ""
    for table in itertools.chain([first], pieces):
        counts["rows"] += len(table.rows)
        kept: list[tuple[float, int, float, tuple, float, tuple, str, float]] = []
        for where_short, cells in table.rows:
            where = f"log: {name!r} {where_short}"
            sent = _number(cells[index["time_s"]], where, "time_s", t_lo, t_hi)
            start = sent if math.isnan(start) else start
            t = sent  # the row's arrival: when the receiver uses it
            if has_arrival and cells[index["rx_time"]]:
                t = _number(cells[index["rx_time"]], where, "rx_time", t_lo, t_hi)
                if t < sent and not nominal:
                    raise ModelError(f"{where}: rx_time {t:.10g} s is before the row's time_s {sent:.10g} s: a packet "
                                     "arrives after it is sent; leave rx_time empty where the arrival is not known")
            beacon = _beacon(cells[index["beacon_id"]], n_beacons)
            if beacon < 0:
                counts["unknown_beacon"] += 1
                continue
            if t < latest - REORDER_WINDOW:
                column = "rx_time" if t != sent else "time_s"
                raise ModelError(f"{where}: {column} {t:.10g} s is {latest - t:.6g} s before {latest_where}'s "
                                 f"{latest:.10g} s: a clock jump back (rows up to {REORDER_WINDOW:g} s out of order "
                                 f"are sorted); replay the rows before and from {where_short} as two logs, or "
                                 "correct the clock")
            if t < latest:
                counts["out_of_order"] += 1
            elif t > latest:
                latest, latest_where = t, where_short
            depth = _number(cells[index["depth_m"]], where, "depth_m", d_lo, d_hi)
            if beacon == 0:
                kept.append((t, 0, 0.0, (0.0, 0.0, 0.0), depth, (0.0,) * len(extra), where_short, sent))
                continue
            if has_range:
                rng = _number(cells[index["range_m"]], where, "range_m", r_lo, r_hi)
            else:
                travel = _number(cells[index["travel_time_s"]], where, "travel_time_s", -1e3, 1e3)
                speed = sound_speed
                if "sound_speed_mps" in index and cells[index["sound_speed_mps"]]:
                    speed = _number(cells[index["sound_speed_mps"]], where, "sound_speed_mps", speeds.min,
                                    speeds.max)
                rng = speed * travel
            lowest = floor - fall * (abs(sent - start) + REORDER_WINDOW)
            if rng < lowest:
                column, value, low, high = (("range_m", rng, lowest, r_hi) if has_range else
                                            ("travel_time_s", travel, lowest / speed, 1e3))
                raise ModelError(f"{where}: {column}: {value:.10g} is outside the allowed range [{low:.6g}, "
                                 f"{high:g}]: the lowest range this configuration's channel measures ({reason}); see "
                                 "docs/log-format.md")
            position = tuple(_number(cells[index[c]], where, c, p_lo, p_hi) for c in _PACKET_COLUMNS)
            own = tuple(_number(cells[index[c]], where, c, -10.0, 10.0) for c in extra)
            kept.append((t, beacon, rng, position, depth, own, where_short, sent))
        parts.append(_Rows.of(kept, len(extra)))

    # in arrival order (stable: rows of one time keep the file's order), then without duplicates
    rows = _Rows.joined(parts, len(extra))
    del parts
    rows = rows.take(np.argsort(rows.time, kind="stable"))
    keys = np.rec.fromarrays([rows.sent, rows.beacon], names="sent,beacon")
    once = np.sort(np.unique(keys, return_index=True)[1])  # each (time_s, beacon) where it first comes
    counts["duplicate"] = rows.time.size - once.size
    rows = rows.take(once)
    if not rows.time.size:
        raise ModelError(f"log: {name!r} has no row to replay ({counts['rows']} rows; {counts['unknown_beacon']} "
                         f"with a beacon id outside 1 … {n_beacons}); {doc}")
    gaps = np.diff(rows.time)
    gap = (float(gaps.max()), rows.where[int(gaps.argmax()) + 1]) if gaps.size else (0.0, rows.where[0])
    return Log(path=path, time=rows.time, beacon=rows.beacon, range=rows.range, beacon_ned=rows.beacon_ned,
               depth=rows.depth, system_values=rows.system_values if extra else None, where=rows.where, counts=counts,
               longest_gap=gap, typical_gap=float(np.median(gaps)) if gaps.size else 0.0, ignored=ignored,
               config=first.config, sent=rows.sent, system_columns=dict(system.log_columns) if extra else {})


@dataclass
class _Rows:
    """Rows of a log kept as arrays (a piece's, or the whole log's): as :class:`Log`'s fields."""

    time: np.ndarray
    beacon: np.ndarray
    range: np.ndarray
    beacon_ned: np.ndarray
    depth: np.ndarray
    system_values: np.ndarray
    where: list[str]
    sent: np.ndarray

    @classmethod
    def of(cls, kept: list[tuple], k: int) -> _Rows:
        """The rows ``(t, beacon, range, position, depth, own, where, sent)`` of a piece (``k`` system values)."""
        return cls(np.array([r[0] for r in kept], float), np.array([r[1] for r in kept], np.int64),
                   np.array([r[2] for r in kept], float), np.array([r[3] for r in kept], float).reshape(len(kept), 3),
                   np.array([r[4] for r in kept], float), np.array([r[5] for r in kept], float).reshape(len(kept), k),
                   [r[6] for r in kept], np.array([r[7] for r in kept], float))

    @classmethod
    def joined(cls, parts: list[_Rows], k: int) -> _Rows:
        """The pieces' rows, one after the other."""
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("time", "beacon", "range",
                                                                               "beacon_ned", "depth",
                                                                               "system_values")),
                   [w for p in parts for w in p.where], np.concatenate([p.sent for p in parts]))

    def take(self, order: np.ndarray) -> _Rows:
        """The rows at ``order``."""
        return _Rows(self.time[order], self.beacon[order], self.range[order], self.beacon_ned[order],
                     self.depth[order], self.system_values[order], [self.where[k] for k in order], self.sent[order])


def _beacon(text: str, n_beacons: int) -> int:
    """A beacon id cell: 1 … n_beacons, 0 when empty (a depth reading), −1 when it names no beacon of the array."""
    if not text:
        return 0
    if not NUMBER.fullmatch(text):
        return -1
    value = float(text)
    if not math.isfinite(value) or value != round(value) or not 1 <= value <= n_beacons:
        return -1
    return int(value)



__all__ = ["FORMAT", "LOG_COLUMNS", "LOG_ROW_BYTES", "Log", "REORDER_WINDOW", "log_config", "read_log"]
