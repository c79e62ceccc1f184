"""Reading recorded times of arrival at a fixed array (an inverted LBL), as hostile input.

* the TOA matrix: one row per ping, one column per receiver, comma-separated (if its first row holds a comma) or
  whitespace-separated, an optional header of receiver names; ``NA`` or an empty cell where the ping was not
  heard (Lake Hald's ``toa.txt``);
* the receivers' positions: a CSV with a name column and ``x_m``, ``y_m`` [, ``z_m``] [, ``status``] (or
  ``x``, ``y``, ``z``), a receiver without a position not used (Lake Hald's ``hydrophones.csv``), or a TOML
  file of ``[[receiver]]`` tables with ``name``, ``x_m``, ``y_m`` [, ``z_m``]; in a CSV the positions may be
  ``lat``, ``lon`` (or ``latitude``, ``longitude``) instead, WGS 84 degrees (or the geographic ``crs`` given),
  projected to a metric frame (:mod:`sblsim.orchestrator.io.frames`: the UTM zone of the array's centre, or the
  ``frame`` given), and x, y may be given in a projected ``crs`` (kept in it): then every output has latitude and
  longitude too;
* a track (the truth, or a reference solution): columns ``x``, ``y`` [, ``z``] [m] (or ``lat``, ``lon`` [°] where
  the receivers have a CRS) and ``t`` (or ``time``, ``top``) [s] under a header line (Lake Hald's ``gps.txt``,
  ``umap.txt``);
* a measured sound-speed series: columns ``time_s`` (or ``t``, ``time``) [s] and ``sound_speed_m_s`` (or ``c``,
  ``sound_speed``) [m/s] under a header line (a temperature logger's series converted, a CTD's time series).

A time column holds seconds on the times of arrival's own base, or **absolute** times: ISO 8601 text (UTC unless a
zone is given) or, under a column named ``epo``, ``epoch``, ``epoch_s``, ``time_utc``, ``timestamp`` or
``datetime``, seconds since 1970-01-01 UTC (:mod:`sblsim.orchestrator.io.times`), taken to the base by the times of
arrival's stated origin (``origin``: the UTC time of their zero; refused in one line without one).

Each file must be a regular file (a FIFO or a device such as ``/dev/zero`` is refused before it is opened) and is
read to at most :data:`MAX_TOA_BYTES` bytes and :data:`MAX_PINGS` rows, counted in what was read. Its rows are
parsed by the csv module (:func:`~sblsim.orchestrator.io.tables.csv_cells`: a quoted cell may hold the separator),
every row must have the header's (or the first row's) number of cells, and every cell is checked (finite, within
its range); no name or text in a file is ever taken as a path. An error is one line naming the file, the line as
an editor numbers it, the column and the allowed range (:class:`ModelError`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from itertools import chain
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.frames import (
    CHOSEN_INPUT,
    Frame,
    check_crs,
    check_latlon,
    check_metric,
    frame_for,
    is_geographic,
    transform,
)
from sblsim.orchestrator.io.tables import NUMBER, csv_cells, number, read_lines
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.tracks.tracker import CLOCK_SIGMA_RANGE, TOA_SIGMA_RANGE

#: The largest file read [bytes] and the most rows (pings, receivers, track points).
MAX_TOA_BYTES = 64 * 2**20
MAX_PINGS = 500_000
MAX_RECEIVERS = 1000
#: The most cells a line holds [1] (a TOA matrix's: a receiver's each and the depth column) and a file [1] (150,000
#: pings at 28 receivers, Lake Hald's, or 60,000 at 70; parsed by the csv module at about 130 bytes a cell, well under
#: 1 GiB: split a longer matrix in time).
MAX_ROW_CELLS = MAX_RECEIVERS + 1
MAX_TOA_CELLS = 2**22
#: The allowed times [s] (a time of arrival or a track's time) and coordinates [m].
MAX_TIME = 1e10
MAX_COORDINATE = 1e7
#: The texts of a cell that was not heard.
MISSING = ("NA", "")


def _too_large(name: str, what: str, amount: str) -> ModelError:
    return ModelError(f"{what}: {name!r} {amount}; allowed at most {MAX_TOA_BYTES // 2**20} MiB and {MAX_PINGS:,} "
                      "rows")


def _lines(path: Path, what: str) -> list[tuple[int, str]]:
    """The numbered lines of a regular text file (:func:`~sblsim.orchestrator.io.tables.read_lines`), refused when
    it holds more than :data:`MAX_TOA_BYTES` bytes or :data:`MAX_PINGS` rows and 1,000 lines besides (counted in
    what was read), or when a line is longer than 1 MiB or holds more than :data:`MAX_ROW_CELLS` cells, or the file
    more than :data:`MAX_TOA_CELLS` (:func:`~sblsim.orchestrator.io.tables.check_cells`, before it is parsed);
    comments (``#``) and blank lines dropped, the others with their line numbers from 1."""
    lines = read_lines(path, what, max_bytes=MAX_TOA_BYTES, max_rows=MAX_PINGS, extra_lines=1000, refuse=_too_large,
                       delimiter="auto", max_line_cells=MAX_ROW_CELLS, max_cells=MAX_TOA_CELLS, comments=True)
    return [(k, line) for k, line in enumerate(lines, start=1) if line.strip() and not line.lstrip().startswith("#")]


def _rows(path: Path, what: str) -> list[tuple[int, list[str]]]:
    """The file's rows (:func:`_lines`) as (line number, cells), parsed by the csv module: comma-separated if the
    first row holds a comma, else whitespace-separated; quotes honoured (``"H1, north"`` is one cell). The cells
    keep trailing spaces (:func:`_stripped`, :func:`_numbers` strip them)."""
    lines = _lines(path, what)
    delimiter = "," if lines and "," in lines[0][1] else " "
    return csv_cells(lines, f"{what}: {str(path)!r}", delimiter)


def _stripped(cells: list[str]) -> list[str]:
    return [c.strip() for c in cells]


def _is_cell(text: str) -> bool:
    return text in MISSING or bool(NUMBER.fullmatch(text))


def _numbers(rows: list[tuple[int, list[str]]], name: str, what: str, header: list[str], low: float, high: float,
             missing: bool, named: bool = True) -> np.ndarray:
    """The cells of ``rows`` (:func:`_rows`) as a float matrix, each checked: a number (``NA``/empty allowed only
    where ``missing``), finite, within [low, high]; every row with the header's number of cells (``named``: the
    file's header; else the first row's). An error names the line and the column, or the line and its cells. The
    cells are checked as one column of Arrow text (about 20 bytes a cell, whatever the widest cell's length)."""
    width = len(header)
    ragged = next(((number, len(cells)) for number, cells in rows if len(cells) != width), None)
    if ragged is not None:
        against = f"the header {width} ({','.join(header)[:80]})" if named else f"the first row {width}"
        raise ModelError(f"{what}: {name!r} line {ragged[0]} has {ragged[1]} cells, {against}; allowed: "
                         f"{width} cells a row" + (" (NA or an empty cell where not heard)" if missing else ""))
    allowed = f"a finite number in [{low:g}, {high:g}]" + (" or NA/empty (not heard)" if missing else "")
    lines = [number for number, _ in rows]
    shape = (len(rows), width)
    stripped = pc.utf8_trim_whitespace(pa.array(chain.from_iterable(row for _, row in rows), pa.string(),
                                                size=shape[0] * width))  # row by row, as str.strip strips
    valid = pc.match_substring_regex(stripped, f"^(?:{NUMBER.pattern})$", ignore_case=True)
    values = np.array(pc.cast(pc.if_else(valid, stripped, "nan"), pa.float64()), float).reshape(shape)  # writable
    empty = pc.is_in(stripped, pa.array(MISSING)).to_numpy(zero_copy_only=False).reshape(shape)
    valid = valid.to_numpy(zero_copy_only=False).reshape(shape)
    bad = ~(valid | (empty & missing))
    bad |= valid & ~np.isfinite(values)
    bad |= valid & np.isfinite(values) & ((values < low) | (values > high))
    if bad.any():
        i, j = map(int, np.argwhere(bad)[0])
        text = stripped[i * width + j].as_py()
        raise ModelError(f"{what}: {name!r} line {lines[i]} column {header[j]}: {text[:40]!r} is not "
                         f"allowed; allowed: {allowed}")
    values[empty] = np.nan
    return values


@dataclass
class ToaMatrix:
    """Times of arrival: ``toa`` (pings, receivers) [s], NaN where not heard; ``names`` the columns' receiver names
    (None: no header, the columns in the receivers file's order); ``depth`` the tag's depth-sensor reading per ping
    [m] (a ``depth_m`` column of the header: positive down, NaN where none; None without one)."""

    toa: np.ndarray
    names: list[str] | None
    depth: np.ndarray | None = None


#: The column of a TOA matrix's header that holds the tag's depth reading per ping, not a receiver's times.
DEPTH_COLUMN = "depth_m"
#: The depth readings allowed [m] (a pressure sensor reads a little above the surface; the deepest trench).
DEPTH_RANGE = (-10.0, 11000.0)


def read_toa(path: Path | str) -> ToaMatrix:
    """Read a TOA matrix (module docstring); times in [0, :data:`MAX_TIME`] s.

    Raises
    ------
    ModelError
        One line naming the file, the line and column, and the allowed range.
    """
    path, what = Path(path), "toa"
    rows = _rows(path, what)
    if not rows:
        raise ModelError(f"{what}: {str(path)!r} holds no rows; allowed: a matrix of times of arrival [s]")
    first = _stripped(rows[0][1])
    names = None
    if not all(_is_cell(c) for c in first):
        names, rows = first, rows[1:]
        if len(set(names)) != len(names):
            raise ModelError(f"{what}: {str(path)!r}: a receiver name is given twice in the header")
        if not rows:
            raise ModelError(f"{what}: {str(path)!r} holds a header and no rows")
    width = len(names) if names else len(first)
    if not 1 <= width <= MAX_RECEIVERS:
        raise ModelError(f"{what}: {str(path)!r} has {width} columns; allowed 1 to {MAX_RECEIVERS}")
    header = names or [f"{k + 1}" for k in range(width)]
    if names is None or DEPTH_COLUMN not in names:
        return ToaMatrix(_numbers(rows, str(path), what, header, 0.0, MAX_TIME, True, names is not None), names)
    values = _numbers(rows, str(path), what, header, -MAX_TIME, MAX_TIME, True)
    at = names.index(DEPTH_COLUMN)
    depth, toa = values[:, at], np.delete(values, at, axis=1)
    receivers = [n for n in names if n != DEPTH_COLUMN]
    for cells, low, high, columns in ((depth[:, None], *DEPTH_RANGE, [DEPTH_COLUMN]), (toa, 0.0, MAX_TIME, receivers)):
        bad = np.argwhere((cells < low) | (cells > high))
        if len(bad):
            i, j = map(int, bad[0])
            raise ModelError(f"{what}: {str(path)!r} line {rows[i][0]} column {columns[j]}: {cells[i, j]:.10g} is not "
                             f"allowed; allowed: a finite number in [{low:g}, {high:g}] or NA/empty")
    if not receivers:
        raise ModelError(f"{what}: {str(path)!r} holds a depth column and no receiver's")
    return ToaMatrix(toa, receivers, depth)


@dataclass
class Receivers:
    """The receivers: ``names`` (n,), ``positions`` (n, dim) [m], NaN rows where a receiver has no position
    (not used), ``sigma`` (n,) each one's survey error per axis [m] (a ``sigma_m`` column; NaN where not given,
    None without the column), ``frame`` the metric frame of the positions (None: a local frame without a
    CRS), and ``toa_sigma`` (n,) each one's timing noise [s] (a ``toa_sigma_s`` column, as ``sblsim toa`` writes
    it from a synchronisation's residuals; NaN where not given, None without the column), ``clock_sigma`` (n,) its
    clock offset's own uncertainty [s] (a ``clock_sigma_s`` column, as ``sblsim toa`` writes it from the
    synchronisation's offsets; likewise)."""

    names: list[str]
    positions: np.ndarray
    sigma: np.ndarray | None = None
    frame: Frame | None = None
    toa_sigma: np.ndarray | None = None
    clock_sigma: np.ndarray | None = None


#: The survey errors a receivers file's ``sigma_m`` column may give [m] (a standard deviation per axis).
SURVEY_SIGMA_RANGE = (0.0, 1000.0)


#: The header names of latitude and longitude (a receivers file's, a track's).
LATITUDE, LONGITUDE = ("lat", "latitude"), ("lon", "long", "longitude")


def read_receivers(path: Path | str, crs: str | None = None, frame: str | None = None) -> Receivers:
    """Read the receivers' positions: a CSV (a name column, ``x_m``/``x``, ``y_m``/``y`` [, ``z_m``/``z``], or
    ``lat``, ``lon`` [°] [, ``z_m``]; [, ``sigma_m``] [, ``toa_sigma_s``] [, ``clock_sigma_s``] [, ``status``]) or a
    TOML file
    (``[[receiver]]`` with ``name``, ``x_m``, ``y_m`` [, ``z_m``] [, ``sigma_m``]); ``sigma_m`` the survey's standard
    deviation per axis [m] (:data:`SURVEY_SIGMA_RANGE`), ``toa_sigma_s`` the receiver's timing noise [s]
    (:data:`~sblsim.orchestrator.tracks.tracker.TOA_SIGMA_RANGE`; empty: not known), ``clock_sigma_s`` its clock
    offset's own uncertainty [s] (:data:`~sblsim.orchestrator.tracks.tracker.CLOCK_SIGMA_RANGE`; empty: not known).
    A receiver whose coordinates
    are empty is kept without a position (its column of the TOA matrix is not used). Latitude and longitude (WGS 84,
    or the geographic ``crs``) are projected to ``frame`` (a metric CRS; default the UTM zone of their centre); x and
    y in a projected ``crs`` stay in it.

    Raises
    ------
    ModelError
        One line naming the file, its row or key, and the allowed range; a CRS that does not fit the columns.
    """
    path, what = Path(path), "receivers"
    name = str(path)
    if crs is not None:
        check_crs(crs, "crs")
    if path.suffix.lower() == ".toml":
        if crs is not None or frame is not None:
            raise ModelError("crs: not with a TOML receivers file (x_m, y_m in a local frame); allowed: a CSV")
        return _receivers_toml(path, what)
    parsed = _rows(path, what)
    if len(parsed) < 2:
        raise ModelError(f"{what}: {name!r} holds no receivers; allowed: a header (name, x_m, y_m[, z_m]) and rows")
    header = [h.lower() for h in _stripped(parsed[0][1])]
    rows = [(lineno, _stripped(cells)) for lineno, cells in parsed[1:]]
    if len(rows) > MAX_RECEIVERS:
        raise ModelError(f"{what}: {name!r} has {len(rows)} receivers; allowed at most {MAX_RECEIVERS}")
    axes = []
    geographic = any(h in LATITUDE for h in header) and any(h in LONGITUDE for h in header) and \
        (crs is None or is_geographic(crs))
    horizontal = (LONGITUDE, LATITUDE) if geographic else (("x_m", "x"), ("y_m", "y"))
    for aliases in (*horizontal, ("z_m", "z")):
        found = [k for k, h in enumerate(header) if h in aliases]
        axes.append(found[0] if found else None)
    if axes[0] is None or axes[1] is None:
        raise ModelError(f"{what}: {name!r}: the header needs x_m and y_m (or x, y; or lat, lon) columns, got "
                         f"{','.join(header)[:120]}")
    if crs is not None and not geographic and is_geographic(crs):
        raise ModelError(f"crs: {crs!r} is geographic (degrees); allowed: lat and lon columns with it, or a projected "
                         "CRS for x_m and y_m")
    if frame is not None and crs is None and not geographic:
        raise ModelError("frame: given for positions without a CRS; allowed: with --crs (the positions' CRS), or "
                         "positions as lat and lon")
    used = [k for k in axes if k is not None]
    status = header.index("status") if "status" in header else None
    survey = header.index("sigma_m") if "sigma_m" in header else None
    noise = header.index("toa_sigma_s") if "toa_sigma_s" in header else None
    offset = header.index("clock_sigma_s") if "clock_sigma_s" in header else None
    label = next((k for k in range(len(header)) if k not in used and k not in (status, survey, noise, offset)),
                 None)
    names, positions, sigma, timing, offsets = [], [], [], [], []
    for k, (lineno, cells) in enumerate(rows, start=1):
        if len(cells) != len(header):
            raise ModelError(f"{what}: {name!r} line {lineno} has {len(cells)} cells, the header {len(header)} "
                             f"({','.join(header)[:80]})")
        names.append(cells[label] if label is not None else str(k))
        if survey is not None:
            sigma.append(math.nan if cells[survey] in MISSING else number(
                cells[survey], f"{what}: {name!r} line {lineno}", "sigma_m", *SURVEY_SIGMA_RANGE))
        if noise is not None:
            timing.append(math.nan if cells[noise] in MISSING else number(
                cells[noise], f"{what}: {name!r} line {lineno}", "toa_sigma_s", *TOA_SIGMA_RANGE))
        if offset is not None:
            offsets.append(math.nan if cells[offset] in MISSING else number(
                cells[offset], f"{what}: {name!r} line {lineno}", "clock_sigma_s", *CLOCK_SIGMA_RANGE))
        coordinates = [cells[k] for k in used]
        if all(c in MISSING for c in coordinates):
            positions.append([math.nan] * len(used))
            continue
        positions.append([number(c, f"{what}: {name!r} line {lineno}", header[k], -MAX_COORDINATE, MAX_COORDINATE)
                          for c, k in zip(coordinates, used)])
    if len(set(names)) != len(names):
        raise ModelError(f"{what}: {name!r}: a receiver name is given twice")
    positions = np.array(positions, float)
    chosen = None
    if geographic:
        lon, lat = positions[:, 0], positions[:, 1]
        check_latlon(lat, lon, f"{what}: {name!r}")
        if crs is not None:
            lon, lat = transform(crs, "EPSG:4326", lon, lat)
        chosen = frame_for(lat, lon, frame)
        positions[:, 0], positions[:, 1] = chosen.from_latlon(lat, lon)
    elif crs is not None:
        chosen = Frame(check_metric(crs, "crs"), CHOSEN_INPUT) if frame is None else Frame(check_metric(frame,
                                                                                                        "frame"))
        if frame is not None:
            positions[:, 0], positions[:, 1] = transform(crs, chosen.crs, positions[:, 0], positions[:, 1])
    return Receivers(names, positions, np.array(sigma, float) if survey is not None else None, chosen,
                     np.array(timing, float) if noise is not None else None,
                     np.array(offsets, float) if offset is not None else None)


def _receivers_toml(path: Path, what: str) -> Receivers:
    name = str(path)
    text = "\n".join(line for _, line in _lines(path, what))
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(f"{what}: {name!r} is not valid TOML ({exc})") from None
    unknown = set(data) - {"receiver"}
    if unknown or not isinstance(data.get("receiver"), list) or not data["receiver"]:
        raise ModelError(f"{what}: {name!r}: expected [[receiver]] tables only (name, x_m, y_m[, z_m]), got "
                         f"{', '.join(sorted(unknown)) or 'no receiver'}")
    names, positions, sigma = [], [], []
    dims = set()
    for k, table in enumerate(data["receiver"], start=1):
        extra = set(table) - {"name", "x_m", "y_m", "z_m", "sigma_m"}
        if extra or "x_m" not in table or "y_m" not in table:
            raise ModelError(f"{what}: {name!r}: receiver {k}: the keys are name, x_m, y_m[, z_m][, sigma_m]; got "
                             f"{', '.join(sorted(table))}")
        value = table.get("sigma_m", math.nan)
        low, high = SURVEY_SIGMA_RANGE
        if "sigma_m" in table and (isinstance(value, bool) or not isinstance(value, (int, float))
                                   or not low <= value <= high):
            raise ModelError(f"{what}: {name!r}: receiver {k}: sigma_m = {value!r} is not allowed; allowed: a "
                             f"number in [{low:g}, {high:g}] m")
        sigma.append(float(value))
        row = []
        for key in ("x_m", "y_m", "z_m"):
            if key not in table:
                continue
            value = table[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or abs(value) > MAX_COORDINATE:
                raise ModelError(f"{what}: {name!r}: receiver {k}: {key} = {value!r} is not allowed; allowed: a "
                                 f"finite number in [{-MAX_COORDINATE:g}, {MAX_COORDINATE:g}] m")
            row.append(float(value))
        dims.add(len(row))
        names.append(str(table.get("name", k)))
        positions.append(row)
    if len(dims) != 1:
        raise ModelError(f"{what}: {name!r}: every receiver needs the same coordinates (all with z_m or none)")
    given = np.array(sigma, float)
    return Receivers(names, np.array(positions, float), given if np.isfinite(given).any() else None)


#: The time columns whose numbers are absolute times (seconds since 1970-01-01 UTC), not on the TOA file's base.
ABSOLUTE_TIME_NAMES = ("epo", "epoch", "epoch_s", "time_utc", "timestamp", "datetime", "date_time")


def _same_width(rows: list[tuple[int, list[str]]], header: list[str], name: str, what: str) -> None:
    """Refuse the first row whose cells are not as many as the header's (one line, its line number), before some of
    its columns are read."""
    ragged = next(((line, len(cells)) for line, cells in rows if len(cells) != len(header)), None)
    if ragged is not None:
        raise ModelError(f"{what}: {name!r} line {ragged[0]} has {ragged[1]} cells, the header {len(header)} "
                         f"({','.join(header)[:80]}); allowed: {len(header)} cells a row")


def _times(rows: list[tuple[int, list[str]]], k: int, header: list[str], name: str, what: str,
           origin: float | None) -> np.ndarray | None:
    """The time column ``k`` of ``rows`` on the times of arrival's base [s] where it holds absolute times (ISO 8601
    text, or numbers under a name of :data:`ABSOLUTE_TIME_NAMES`): less ``origin``; None where it holds numbers on
    that base already (the caller checks them).

    Raises
    ------
    ModelError
        Absolute times without an origin, or a time that is neither form (one line).
    """
    cells = [cells[k].strip() for _, cells in rows]
    if header[k] not in ABSOLUTE_TIME_NAMES and all(NUMBER.fullmatch(c) for c in cells):
        return None
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


#: The shortest and longest interval of a burst sequence [s].
BURST_RANGE = (0.1, 86400.0)


def read_burst_sequence(path: Path | str) -> np.ndarray:
    """Read a pseudo-random tag's burst sequence: its intervals [s] in the tag's order, one per row, under an optional
    header (a column ``interval_s`` or ``interval`` where there are several; else the only column).

    Raises
    ------
    ModelError
        One line naming the file, the line and column, and the allowed range (each interval in
        :data:`BURST_RANGE`).
    """
    path, what = Path(path), "burst sequence"
    name = str(path)
    parsed = _rows(path, what)
    if not parsed:
        raise ModelError(f"{what}: {name!r} holds no rows; allowed: the tag's intervals [s], one per row")
    first = _stripped(parsed[0][1])
    headed = not all(_is_cell(c) for c in first)
    header = [h.lower() for h in first] if headed else ["interval_s"] + [str(k + 2) for k in range(len(first) - 1)]
    rows = parsed[1:] if headed else parsed
    if not rows:
        raise ModelError(f"{what}: {name!r} holds no intervals; allowed: the tag's intervals [s], one per row")
    found = [k for k, h in enumerate(header) if h in ("interval_s", "interval")]
    if len(header) > 1 and not found:
        raise ModelError(f"{what}: {name!r}: {len(header)} columns and none named interval_s; allowed: one column, "
                         "or a header naming interval_s")
    values = _numbers(rows, name, what, header, *BURST_RANGE, False, headed)
    return values[:, found[0] if found else 0]


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


__all__ = ["ABSOLUTE_TIME_NAMES", "BURST_RANGE", "DEPTH_COLUMN", "DEPTH_RANGE", "LATITUDE", "LONGITUDE",
           "MAX_COORDINATE", "MAX_PINGS", "MAX_RECEIVERS", "MAX_TIME", "MAX_TOA_BYTES", "Receivers",
           "SERIES_SPEED_RANGE", "SURVEY_SIGMA_RANGE", "ToaMatrix", "read_burst_sequence", "read_receivers",
           "read_sound_speed_series", "read_toa", "read_track"]
