"""A water-temperature series (a logger's record) read for the tracker's sound speed: a CSV of times and in-situ
temperatures [°C] under a header, read as hostile input (:mod:`sblsim.orchestrator.readers.cells`: bounded in bytes and
rows, parsed by pandas into text cells, every cell checked, a refusal one line naming the file, its line and column and
what is allowed).

The time column is ``time_s`` (or ``t``, ``time``) holding numbers on the times of arrival's own base [s], or absolute
times: ISO 8601 (UTC unless a zone is given) or epoch seconds under a name of :data:`ABSOLUTE_NAMES` (``epo``,
``time_utc``, ``timestamp``, ``date_and_time``, ...; :mod:`sblsim.orchestrator.io.times`), taken to that base by the
times of arrival's origin. The temperature column is ``temperature_c`` (or ``temperature``, ``temp``,
``water_temperature``, ...; a unit in brackets after the name is ignored: ``Temperature (°C)``). Each temperature is
made a speed by TEOS-10 at the stated salinity (:func:`sblsim.models.tracking.sound_speed.water_speed`).

The receivers' own temperature records are read as well, the file recognised by its first line: a Fathom (VDAT) CSV
(its TEMP, TEMP_STATS and DIAG records' ambient temperature) or a VUE receiver-events export (its temperature events),
several receivers averaged (:mod:`sblsim.orchestrator.readers.receiver_temperature`); their times are UTC, read within
the detections' limits (:data:`~sblsim.orchestrator.readers.limits.MAX_DETECTION_BYTES`). A file that is not UTF-8
is read as Latin-1 (a Windows export's ``°C``).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.sound_speed import TEMPERATURE_RANGE
from sblsim.orchestrator.io.tables import NUMBER
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import file_table, named, numbers, read_text, shown_header
from sblsim.orchestrator.readers.input_rows import MAX_TIME
from sblsim.orchestrator.readers.limits import MAX_DETECTION_BYTES, MAX_DETECTION_CELLS, MAX_DETECTIONS
from sblsim.orchestrator.readers.receiver_temperature import FALLBACK_ENCODING, receiver_kind, receiver_temperatures
from sblsim.orchestrator.readers.time_series import ABSOLUTE_TIME_NAMES

#: The largest temperature file read [bytes] and the most rows: a logger every 30 s for a year is 1.05 million rows.
MAX_TEMPERATURE_BYTES = 64 * 2**20
MAX_TEMPERATURE_ROWS = 2_000_000
#: The bytes of a file's start its kind is read from (its first line).
FIRST_LINE_BYTES = 65536
#: The time column's names: on the times of arrival's base where its cells are numbers (``time`` too), else absolute.
RELATIVE_TIME_NAMES = ("time_s", "t", "t_s", "time")
ABSOLUTE_NAMES = ABSOLUTE_TIME_NAMES + ("date_and_time", "date_time_utc", "time_utc_s")
#: The temperature column's names (:func:`~sblsim.orchestrator.readers.cells.normal_name`: case, spaces and a unit in
#: brackets do not matter).
TEMPERATURE_NAMES = ("temperature_c", "temperature", "temp_c", "temp", "water_temperature", "water_temperature_c",
                     "temperature_degc", "temp_degc", "t_c")


def read_temperature_series(path: Path | str, origin: float | None = None, absolute: bool = False) -> np.ndarray:
    """Read a water-temperature series (the module docstring).

    Parameters
    ----------
    path : Path or str
        The CSV file, or the receivers' Fathom CSV or VUE receiver-events export.
    origin : float, optional
        The UTC time of the times of arrival's zero [s since 1970]: needed where the file's times are absolute.
    absolute : bool
        Only absolute times taken (a study, whose tags' times of arrival each have their own base).

    Returns
    -------
    ndarray, (k, 2)
        Time [s] on the times of arrival's base (increasing) and in-situ temperature [°C].

    Raises
    ------
    ModelError
        One line naming the file (and the line and column): a file too large or not CSV text, no time or temperature
        column, a cell that is not a number or a time, a temperature outside
        :data:`~sblsim.models.tracking.sound_speed.TEMPERATURE_RANGE`, times that do not increase, absolute times
        without an origin, times on the times of arrival's base where ``absolute``; a receivers' export holding no
        temperature record, or one in a unit other than °C.
    """
    path, what = Path(path), "temperature file"
    name = str(path)
    head = read_text(path, what, MAX_TEMPERATURE_BYTES, MAX_TEMPERATURE_ROWS, prefix=FIRST_LINE_BYTES,
                     fallback=FALLBACK_ENCODING)
    kind = receiver_kind(head.split("\n", 1)[0].rstrip("\r"))
    if kind is not None:
        stat = path.stat()
        series = _receiver_series(name, kind, stat.st_size, stat.st_mtime_ns)
        if origin is None:
            raise ModelError(f"{what}: {name!r}: the receivers' records are in UTC and the times of arrival have no "
                             "stated origin; allowed: --time-origin (the UTC time of the TOA file's zero)")
        return np.column_stack([series[:, 0] - origin, series[:, 1]])
    header, body, lines = file_table(path, what, MAX_TEMPERATURE_ROWS, MAX_TEMPERATURE_BYTES,
                                     fallback=FALLBACK_ENCODING)
    t = named(header, ABSOLUTE_NAMES + RELATIVE_TIME_NAMES)
    c = named(header, TEMPERATURE_NAMES)
    if t is None or c is None:
        raise ModelError(f"{what}: {name!r}: the header needs a time (time_s on the times of arrival's base, or "
                         f"time_utc / epo in UTC) and a temperature_c column; got {shown_header(header)}")
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no rows; allowed: at least one time and temperature")
    cells = body[t].astype(str).str.strip()
    given = named([header[t]], ABSOLUTE_NAMES) is not None or not cells.str.fullmatch(NUMBER.pattern).all()
    if absolute and not given:
        raise ModelError(f"{what}: {name!r} column {header[t]}: times on no stated base; allowed: UTC times (a "
                         "time_utc column in ISO 8601, or epo in seconds since 1970): each tag's times of arrival "
                         "have their own base")
    if given:
        times = utc_seconds(cells, f"{what}: {name!r}", lines, header[t])
        if origin is None:
            raise ModelError(f"{what}: {name!r}: its times are absolute (UTC: ISO 8601 or epoch seconds in "
                             f"{header[t]}) and the times of arrival have no stated origin; allowed: --time-origin "
                             "(the UTC time of the TOA file's zero), or times on the TOA file's own base (time_s)")
        times = times - origin
    else:
        times = numbers(cells, what, name, lines, header[t], -MAX_TIME, MAX_TIME, unit="s")
    temperatures = numbers(body[c], what, name, lines, header[c], *TEMPERATURE_RANGE, unit="°C")
    steps = np.diff(times)
    if (steps <= 0).any():
        k = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise ModelError(f"{what}: {name!r} line {lines[k]} column {header[t]}: the time does not increase; allowed: "
                         "times in increasing order")
    return np.column_stack([times, temperatures])


@lru_cache(maxsize=4)
def _receiver_series(name: str, kind: str, size: int, mtime_ns: int) -> np.ndarray:
    """A receivers' export's temperature series in UTC (:func:`read_temperature_series`), read once per file as it
    is (its size and modification time in the key): a study's tags each take it, and the export may be the
    detections file itself, hundreds of megabytes."""
    what = "temperature file"
    text = read_text(Path(name), what, MAX_DETECTION_BYTES, MAX_DETECTIONS, max_cells=MAX_DETECTION_CELLS,
                     fallback=FALLBACK_ENCODING)
    series = receiver_temperatures(text, kind, name, what, MAX_DETECTIONS, MAX_DETECTION_CELLS)
    series.setflags(write=False)
    return series


__all__ = ["ABSOLUTE_NAMES", "FIRST_LINE_BYTES", "MAX_TEMPERATURE_BYTES", "MAX_TEMPERATURE_ROWS", "RELATIVE_TIME_NAMES",
           "TEMPERATURE_NAMES", "read_temperature_series"]
