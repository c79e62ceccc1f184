"""Reading the timed series beside the times of arrival, as hostile input (:mod:`.input_rows`):

* a track (the truth, or a reference solution): columns ``x``, ``y`` [, ``z``] [m] (or ``lat``, ``lon`` [°] where
  the receivers have a CRS) and ``t`` (or ``time``, ``top``) [s] under a header line (Lake Hald's ``gps.txt``,
  ``umap.txt``);
* a measured sound-speed series: columns ``time_s`` (or ``t``, ``time``) [s] and ``sound_speed_m_s`` (or ``c``,
  ``sound_speed``) [m/s] under a header line (a temperature logger's series converted, a CTD's time series).

A time column holds seconds on the times of arrival's own base, or **absolute** times: ISO 8601 text (UTC unless a
zone is given) or, under a column named ``epo``, ``epoch``, ``epoch_s``, ``time_utc``, ``timestamp`` or
``datetime``, seconds since 1970-01-01 UTC (:mod:`sblsim.orchestrator.io.times`), taken to the base by the times of
arrival's stated origin (``origin``: the UTC time of their zero; refused in one line without one).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.frames import Frame, check_latlon
from sblsim.orchestrator.io.tables import NUMBER
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.input_rows import MAX_COORDINATE, MAX_TIME, _numbers, _rows, _stripped
from sblsim.orchestrator.readers.receivers_file import LATITUDE, LONGITUDE

#: The time columns whose numbers are absolute times (seconds since 1970-01-01 UTC), not on the TOA file's base.
ABSOLUTE_TIME_NAMES = ("epo", "epoch", "epoch_s", "time_utc", "timestamp", "datetime", "date_time")


def _same_width(rows: list[tuple[int, list[str]]], header: list[str], name: str, what: str) -> None:
    """Refuse the first row whose cells are not as many as the header's (one line, its line number), before some of
    its columns are read."""
    ragged = next(((line, len(cells)) for line, cells in rows if len(cells) != len(header)), None)
    if ragged is not None:
        raise ModelError(f"{what}: {name!r} line {ragged[0]} has {ragged[1]} cells, the header {len(header)} "
                         f"({','.join(header)[:80]}); allowed: {len(header)} cells a row")


#: How long before the times of arrival's origin [s] a time column's numbers may start and still be taken as epoch
#: seconds (a truth logged from a day before the first ping).
EPOCH_MARGIN = 86_400.0


def _times(rows: list[tuple[int, list[str]]], k: int, header: list[str], name: str, what: str,
           origin: float | None) -> np.ndarray | None:
    """The time column ``k`` of ``rows`` on the times of arrival's base [s] where it holds absolute times (ISO 8601
    text, numbers under a name of :data:`ABSOLUTE_TIME_NAMES`, or, where ``origin`` [s since 1970] is known, numbers
    none of which is before it by more than :data:`EPOCH_MARGIN`: epoch seconds as logged): less ``origin``; None
    where it holds numbers on that base already (the caller checks them).

    Raises
    ------
    ModelError
        Absolute times without an origin, or a time that is neither form (one line).
    """
    cells = [cells[k].strip() for _, cells in rows]
    if header[k] not in ABSOLUTE_TIME_NAMES and all(NUMBER.fullmatch(c) for c in cells):
        if origin is None or not cells or min(float(c) for c in cells) < origin - EPOCH_MARGIN:
            return None
        # numbers from (about) the times of arrival's own origin on: epoch seconds (the base's numbers are a study's
        # span, far below an origin after 1970 + EPOCH_MARGIN)
    seconds = utc_seconds(cells, f"{what}: {name!r}", [line for line, _ in rows], header[k])
    if origin is None:
        raise ModelError(f"{what}: {name!r}: its times are absolute (UTC: ISO 8601 or {header[k]}) and the times of "
                         "arrival have no stated origin; allowed: --time-origin (the UTC time of the TOA file's zero), "
                         "or times on the TOA file's own base")
    return seconds - origin


def read_track(path: Path | str, what: str, increasing: bool = True, origin: float | None = None,
               frame: Frame | None = None) -> np.ndarray:
    """Read a track (the truth, or a reference solution): columns x, y [, z] [m] (or lat, lon [°, WGS 84], projected
    to ``frame``) and t (``time``, ``top``; absolute times: the module docstring, taken to the base by ``origin``)
    [s] under a header, the times increasing (a truth track, which is interpolated) or in any order (``increasing``
    False: a reference solution, which is only compared at its own rows); returns (m, 3) ``t, x, y`` or (m, 4)
    ``t, x, y, z``.

    Raises
    ------
    ModelError
        One line naming the file, the line and column, and the allowed range; latitude and longitude without a
        frame (receivers without a CRS), absolute times without an origin.
    """
    path = Path(path)
    name = str(path)
    rows = _rows(path, what)
    if len(rows) < 3:
        raise ModelError(f"{what}: {name!r} needs a header (x y t) and at least two rows")
    header = [h.lower() for h in _stripped(rows[0][1])]
    geographic = any(h in LATITUDE for h in header) and any(h in LONGITUDE for h in header)
    index = {}
    for key, aliases in (("t", ("t", "time", "top", "time_s", "t_s") + ABSOLUTE_TIME_NAMES),
                         ("x", LONGITUDE if geographic else ("x", "x_m")),
                         ("y", LATITUDE if geographic else ("y", "y_m")), ("z", ("z", "z_m"))):
        found = [k for k, h in enumerate(header) if h in aliases]
        if found:
            index[key] = found[0]
    if not {"t", "x", "y"} <= set(index):
        raise ModelError(f"{what}: {name!r}: the header needs x, y (or lat, lon) and t columns, got "
                         f"{' '.join(header)[:120]}")
    if geographic and frame is None:
        raise ModelError(f"{what}: {name!r}: given in latitude and longitude and the receivers have no CRS; allowed: "
                         "receivers with lat and lon (or --crs), or x and y in the receivers' frame")
    _same_width(rows[1:], header, name, what)
    times = _times(rows[1:], index["t"], header, name, what, origin)
    keep = [k for k in range(len(header)) if times is None or k != index["t"]]
    used = [k for k in keep if k in index.values()]
    values = np.full((len(rows) - 1, len(header)), np.nan)
    values[:, used] = _numbers([(line, [cells[k] for k in used]) for line, cells in rows[1:]], name, what,
                               [header[k] for k in used], -MAX_TIME, MAX_TIME, False)
    if times is not None:
        values[:, index["t"]] = times
    track = values[:, [index[k] for k in ("t", "x", "y", "z") if k in index]]
    if geographic:
        check_latlon(track[:, 2], track[:, 1], f"{what}: {name!r}")
        track[:, 1], track[:, 2] = frame.from_latlon(track[:, 2], track[:, 1])
    if np.abs(track[:, 1:]).max() > MAX_COORDINATE:
        raise ModelError(f"{what}: {name!r}: a coordinate is outside the allowed range [{-MAX_COORDINATE:g}, "
                         f"{MAX_COORDINATE:g}] m")
    steps = np.diff(track[:, 0])
    if increasing and (steps <= 0).any():
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ModelError(f"{what}: {name!r} line {rows[k + 2][0]}: the time {track[k + 1, 0]:.10g} s does not "
                         "increase; "
                         "allowed: times in increasing order")
    return track



#: The sound speeds a measured series may hold [m/s] (the tracker's own range).
SERIES_SPEED_RANGE = (1300.0, 1700.0)


def read_sound_speed_series(path: Path | str, origin: float | None = None) -> np.ndarray:
    """Read a measured sound-speed series: ``time_s`` [s] (on the times of arrival's time base; or absolute times,
    ISO 8601 or ``epo`` seconds since 1970 UTC, taken to that base by ``origin``: the module docstring) and
    ``sound_speed_m_s`` [m/s] columns under a header (aliases ``t``, ``time`` and ``c``, ``sound_speed``, ``ss``:
    YAPS's and ``sblsim sync``'s names), the times increasing; returns (k, 2) ``t, c``.

    Raises
    ------
    ModelError
        One line naming the file, the line and column, and the allowed range (each speed in
        :data:`SERIES_SPEED_RANGE`, the times increasing, at least one row); absolute times without an origin.
    """
    path, what = Path(path), "sound speed file"
    name = str(path)
    rows = _rows(path, what)
    if len(rows) < 2:
        raise ModelError(f"{what}: {name!r} needs a header (time_s, sound_speed_m_s) and at least one row")
    header = [h.lower() for h in _stripped(rows[0][1])]
    index = {}
    for key, aliases in (("t", ("time_s", "t", "time", "t_s") + ABSOLUTE_TIME_NAMES),
                         ("c", ("sound_speed_m_s", "sound_speed", "c", "ss"))):
        found = [k for k, h in enumerate(header) if h in aliases]
        if not found:
            raise ModelError(f"{what}: {name!r}: the header needs time_s and sound_speed_m_s columns, got "
                             f"{' '.join(header)[:80]}")
        index[key] = found[0]
    _same_width(rows[1:], header, name, what)
    times = _times(rows[1:], index["t"], header, name, what, origin)
    columns = [index["c"]] if times is not None else [index["t"], index["c"]]
    values = _numbers([(line, [cells[k] for k in columns]) for line, cells in rows[1:]], name, what,
                      [header[k] for k in columns], -MAX_TIME, MAX_TIME, False)
    series = np.c_[times, values[:, 0]] if times is not None else values
    low, high = SERIES_SPEED_RANGE
    bad = np.flatnonzero((series[:, 1] < low) | (series[:, 1] > high))
    if len(bad):
        raise ModelError(f"{what}: {name!r} line {rows[bad[0] + 1][0]} column {header[index['c']]}: "
                         f"{series[bad[0], 1]:.6g} "
                         f"m/s is not allowed; allowed: [{low:g}, {high:g}] m/s")
    steps = np.diff(series[:, 0])
    if (steps <= 0).any():
        k = int(np.flatnonzero(steps <= 0)[0])
        raise ModelError(f"{what}: {name!r} line {rows[k + 2][0]}: the time {series[k + 1, 0]:.10g} s does not "
                         "increase; "
                         "allowed: times in increasing order")
    return series



__all__ = ["ABSOLUTE_TIME_NAMES", "SERIES_SPEED_RANGE", "read_sound_speed_series", "read_track"]
