"""Reading raw detections of an acoustic-telemetry array, as hostile input (``sblsim sync``).

A raw detection is what one receiver logs when it decodes a transmitter: a time on the receiver's **own clock**, the
receiver and the transmitter (tag). Two formats are read into one tidy table (:func:`read_detections`):

* the **YAPS tables** (Baktoft et al. 2017, Sci. Rep. 7:14294): detections with the columns ``epo`` (whole seconds
  since 1970-01-01 UTC), ``frac`` (the fraction of that second, in [0, 1)), ``tag``, ``serial`` (the receiver) and
  optionally ``ts`` (a text time stamp, not used: ``epo + frac`` is the time) and others (ignored, named);
* the **Vemco/Innovasea VUE export CSV**: ``Date and Time (UTC)`` (``YYYY-MM-DD hh:mm:ss[.ffffff]``; a header
  ``Date and Time (UTC+hh:mm)`` gives a fixed zone, converted to UTC), ``Receiver`` (``VR2W-128355``: the model and
  the serial, the serial kept), ``Transmitter`` (``A69-1602-59335``: the code space and the id, the id kept as the
  tag, its code space in a column of its own), ``Transmitter Name``, ``Transmitter Serial``, ``Sensor Value`` and
  ``Sensor Unit`` (kept per detection, e.g. a depth in metres), ``Station Name``, ``Latitude``, ``Longitude``.

The receivers (hydrophones) table: ``serial``, ``sync_tag`` (the id of the sync tag at that receiver, empty for
none), ``x``, ``y`` [, ``z``] or ``x_m``, ``y_m`` [, ``z_m``] [m] in a local metric frame; an ``idx`` column is
ignored (:func:`read_hydrophones`). The sound-speed series: ``epo`` [s] and ``sound_speed_m_s`` (or ``ss``) [m/s],
other columns ignored (:func:`read_sound_speed`).

Each file must be a regular file (a FIFO or a device is refused before it is opened), is read to at most
:data:`MAX_DETECTION_BYTES` bytes and :data:`MAX_DETECTIONS` rows (counted in what was read), and its cells are
parsed by pandas as text and every one checked (its pattern, finite, within its range); no name or text in a file is
ever taken as a path. A receiver whose times go back in the file's order (its clock reset or jumped back, or the
rows are not in the order the receiver logged them) is refused, not sorted: the line, the receiver and the jump are
named. Every error is one line naming the file, its line or column and the allowed range (:class:`ModelError`).
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.tables import NUMBER, regular_file

#: The largest file read [bytes] and the most rows (detections; receivers; points of a sound-speed series).
MAX_DETECTION_BYTES = 256 * 2**20
MAX_DETECTIONS = 3_000_000
MAX_HYDROPHONES = 1000
MAX_SERIES = 1_000_000
#: The allowed times [s since 1970-01-01 UTC] (to the year 2286), coordinates [m] and sound speeds [m/s].
MAX_EPOCH = 10_000_000_000
MAX_COORDINATE = 1e7
SOUND_SPEED_RANGE = (1300.0, 1700.0)
#: A receiver's serial or a tag's id: letters, digits, ``. _ -``, 1 to 40 characters, a letter or digit first.
IDENTIFIER = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,39}")
_INTEGER = re.compile(r"[0-9]{1,11}")
_VUE_TIME = re.compile(r"[0-9]{4}-[0-9]{2}-[0-9]{2} [0-9]{2}:[0-9]{2}:[0-9]{2}(?:\.[0-9]{1,6})?")
_VUE_ZONE = re.compile(r"date and time \(utc(?:([+-])([0-9]{2}):?([0-9]{2}))?\)")
#: The VUE export's columns (lower case) this reader uses; the others of the export are ignored.
VUE_COLUMNS = ("receiver", "transmitter", "sensor value", "sensor unit", "station name")
#: The formats of :func:`read_detections`.
FORMATS = ("yaps", "vue")


@dataclass
class Detections:
    """Raw detections, each on its receiver's own clock.

    Attributes
    ----------
    frame : pandas.DataFrame
        One row per detection in the file's order: ``receiver`` (str), ``tag`` (str), ``time`` [s since 1970-01-01
        UTC on the receiver's clock], ``sensor_value`` (float, NaN without one), ``sensor_unit`` (str, ``""``
        without one), ``line`` (the file's line, from 1 at the header); a VUE file adds ``code_space``,
        ``receiver_model`` and ``station``, a YAPS file with a ``species`` column keeps it.
    source : str
        The file read.
    format : str
        ``yaps`` or ``vue``.
    ignored_columns : list of str
        The file's columns not used.
    """

    frame: pd.DataFrame
    source: str
    format: str
    ignored_columns: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------- the text of a table

def _too_large(name: str, what: str, amount: str, rows: int) -> ModelError:
    return ModelError(f"{what}: {name!r} {amount}; allowed at most {MAX_DETECTION_BYTES // 2**20} MiB and "
                      f"{rows:,} rows")


def _table(path: Path, what: str, max_rows: int) -> tuple[list[str], pd.DataFrame, list[int]]:
    """A CSV file's header (stripped) and its rows as text cells (pandas, every cell a str), with each row's line
    in the file (1: the header); blank lines skipped. Refused before it is read whole when it is larger than
    :data:`MAX_DETECTION_BYTES` or holds more than ``max_rows`` rows (and 1,000 lines besides)."""
    name = str(path)
    size = regular_file(path, what)
    if size > MAX_DETECTION_BYTES:
        raise _too_large(name, what, f"is {size / 2**20:.0f} MiB", max_rows)
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_DETECTION_BYTES + 1)
    except OSError as exc:
        raise ModelError(f"{what}: {name!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    if len(data) > MAX_DETECTION_BYTES:
        raise _too_large(name, what, f"is more than {MAX_DETECTION_BYTES // 2**20} MiB", max_rows)
    count = data.count(b"\n")
    if count > max_rows + 1000:
        raise _too_large(name, what, f"has {count:,} lines", max_rows)
    nul = data.find(b"\0")
    if nul >= 0:
        raise ModelError(f"{what}: {name!r} holds a NUL byte (byte {nul}); allowed: CSV text")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ModelError(f"{what}: {name!r} is not UTF-8 text (byte {exc.start})") from None
    del data
    try:
        frame = pd.read_csv(io.StringIO(text), header=None, dtype=str, keep_default_na=False, na_filter=False,
                            skip_blank_lines=False, engine="c", quotechar='"', on_bad_lines="error")
    except pd.errors.EmptyDataError:
        raise ModelError(f"{what}: {name!r} is empty; allowed: a header line and rows") from None
    except Exception as exc:  # pandas' parser errors name the line
        raise ModelError(f"{what}: {name!r} does not parse as CSV ({' '.join(str(exc).split())[:160]})") from None
    del text
    blank = (frame.apply(lambda column: column.str.strip()) == "").all(axis=1).to_numpy(bool)
    lines = np.flatnonzero(~blank) + 1
    frame = frame[~blank]
    if not len(frame):
        raise ModelError(f"{what}: {name!r} holds no header; allowed: a header line and rows")
    header = [str(h).strip() for h in frame.iloc[0].tolist()]
    if len(set(h.lower() for h in header)) != len(header):
        twice = next(h for h in header if [x.lower() for x in header].count(h.lower()) > 1)
        raise ModelError(f"{what}: {name!r}: the column {twice[:40]!r} is given twice in the header")
    body = frame.iloc[1:].reset_index(drop=True)
    if len(body) > max_rows:
        raise _too_large(name, what, f"has {len(body):,} rows", max_rows)
    body.columns = range(body.shape[1])
    return header, body, lines[1:].tolist()


def _refuse(what: str, name: str, line: int, column: str, text: str, allowed: str) -> ModelError:
    shown = text if len(text) <= 40 else text[:40] + "..."
    return ModelError(f"{what}: {name!r} line {line} column {column}: {shown!r} is not allowed; allowed: {allowed}")


def _pattern(values: pd.Series, pattern: re.Pattern, what: str, name: str, lines: list[int], column: str,
             allowed: str) -> pd.Series:
    """The stripped cells of one column, each matching ``pattern`` (else the first bad one refused)."""
    cells = values.astype(str).str.strip()
    bad = ~cells.str.fullmatch(pattern.pattern).fillna(False).to_numpy(bool)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise _refuse(what, name, lines[k], column, cells.iloc[k], allowed)
    return cells


def _numbers(values: pd.Series, what: str, name: str, lines: list[int], column: str, low: float, high: float,
             high_open: bool = False, missing: bool = False, unit: str = "") -> np.ndarray:
    """The cells of one column as floats, each a number (:data:`NUMBER`), finite, in [low, high] (``[low, high)``
    with ``high_open``); empty cells NaN where ``missing``."""
    cells = values.astype(str).str.strip()
    numbers = np.array(pd.to_numeric(cells.where(cells != "", "nan"), errors="coerce"), float)
    text_ok = cells.str.fullmatch(NUMBER.pattern).fillna(False).to_numpy(bool)
    empty = (cells == "").to_numpy(bool)
    inside = np.isfinite(numbers) & (numbers >= low) & ((numbers < high) if high_open else (numbers <= high))
    bad = ~((text_ok & inside) | (empty & missing))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        allowed = f"a finite number in [{low:g}, {high:g}{')' if high_open else ']'}{' ' + unit if unit else ''}" \
            + (" or empty" if missing else "")
        raise _refuse(what, name, lines[k], column, cells.iloc[k], allowed)
    numbers[empty] = np.nan
    return numbers


def _column(header: list[str], names: tuple[str, ...]) -> int | None:
    lower = [h.lower() for h in header]
    return next((lower.index(n) for n in names if n in lower), None)


# --------------------------------------------------------------------------- detections

def read_detections(path: Path | str, format: str = "yaps") -> Detections:
    """Read raw detections (the module docstring's formats) into one table, checked.

    Parameters
    ----------
    path : str or Path
        The detections file (CSV).
    format : str
        ``yaps`` (``epo, frac, tag, serial[, ts]``) or ``vue`` (the VUE export).

    Returns
    -------
    Detections

    Raises
    ------
    ModelError
        One line naming the file, its line and column and the allowed range: a file too large, a cell outside
        its pattern or range, a missing column, a receiver whose clock goes back in the file's order.
    """
    if format not in FORMATS:
        raise ModelError(f"format: {format!r} is not one of {', '.join(FORMATS)}")
    path, what = Path(path), "detections"
    header, body, lines = _table(path, what, MAX_DETECTIONS)
    name = str(path)
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no detections")
    reader = _yaps if format == "yaps" else _vue
    frame, used = reader(header, body, lines, name, what)
    frame["line"] = np.asarray(lines, np.int64)
    _check_clocks(frame, name, what)
    ignored = [h for k, h in enumerate(header) if k not in used]
    return Detections(frame.reset_index(drop=True), name, format, ignored)


def _yaps(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
          ) -> tuple[pd.DataFrame, set[int]]:
    index = {key: _column(header, (key,)) for key in ("epo", "frac", "tag", "serial", "species")}
    missing = [key for key in ("epo", "frac", "tag", "serial") if index[key] is None]
    if missing:
        raise ModelError(f"{what}: {name!r}: the header needs the columns epo, frac, tag, serial (YAPS; optionally "
                         f"ts); {', '.join(missing)} missing, got {','.join(h[:20] for h in header[:12])}")
    epo = _pattern(body[index["epo"]], _INTEGER, what, name, lines, "epo",
                   f"whole seconds since 1970-01-01 UTC in [0, {MAX_EPOCH}]")
    seconds = epo.astype(np.int64).to_numpy()
    if (seconds > MAX_EPOCH).any():
        k = int(np.flatnonzero(seconds > MAX_EPOCH)[0])
        raise _refuse(what, name, lines[k], "epo", epo.iloc[k], f"whole seconds in [0, {MAX_EPOCH}]")
    frac = _numbers(body[index["frac"]], what, name, lines, "frac", 0.0, 1.0, high_open=True, unit="s")
    tag = _pattern(body[index["tag"]], IDENTIFIER, what, name, lines, "tag",
                   "an id of 1 to 40 letters, digits, '.', '_' or '-'")
    serial = _pattern(body[index["serial"]], IDENTIFIER, what, name, lines, "serial",
                      "a receiver's serial of 1 to 40 letters, digits, '.', '_' or '-'")
    frame = pd.DataFrame({"receiver": serial.to_numpy(), "tag": tag.to_numpy(), "time": seconds + frac,
                          "sensor_value": np.full(len(body), np.nan), "sensor_unit": ""})
    used = {index[k] for k in ("epo", "frac", "tag", "serial")}
    ts = _column(header, ("ts",))
    if ts is not None:
        used.add(ts)
    if index["species"] is not None:
        frame["species"] = body[index["species"]].astype(str).str.strip().str.slice(0, 80).to_numpy()
        used.add(index["species"])
    return frame, used


def _vue(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
         ) -> tuple[pd.DataFrame, set[int]]:
    lower = [h.lower() for h in header]
    when = next((k for k, h in enumerate(lower) if h.startswith("date and time")), None)
    zone = _VUE_ZONE.fullmatch(lower[when]) if when is not None else None
    index = {key: (lower.index(key) if key in lower else None) for key in VUE_COLUMNS}
    missing = [key for key in ("receiver", "transmitter") if index[key] is None]
    if zone is None or missing:
        raise ModelError(f"{what}: {name!r}: a VUE export needs the columns 'Date and Time (UTC)' (or 'Date and "
                         f"Time (UTC+hh:mm)'), 'Receiver' and 'Transmitter'; "
                         f"{'the date column' if zone is None else ', '.join(missing)} not found")
    times = _pattern(body[when], _VUE_TIME, what, name, lines, header[when],
                     "a time YYYY-MM-DD hh:mm:ss[.ffffff]")
    stamps = pd.to_datetime(times, format="%Y-%m-%d %H:%M:%S.%f", errors="coerce")
    whole = stamps.isna() & ~times.str.contains(".", regex=False)
    if whole.any():
        stamps[whole] = pd.to_datetime(times[whole], format="%Y-%m-%d %H:%M:%S", errors="coerce")
    if stamps.isna().any():
        k = int(np.flatnonzero(stamps.isna().to_numpy())[0])
        raise _refuse(what, name, lines[k], header[when], times.iloc[k], "a date and time that exists")
    nanoseconds = stamps.to_numpy().astype("datetime64[ns]").astype(np.int64)
    seconds, rest = np.divmod(nanoseconds, 1_000_000_000)
    if zone.group(1):
        shift = (int(zone.group(2)) * 3600 + int(zone.group(3)) * 60) * (1 if zone.group(1) == "+" else -1)
        seconds = seconds - shift  # local time = UTC + shift
    if (seconds < 0).any() or (seconds > MAX_EPOCH).any():
        k = int(np.flatnonzero((seconds < 0) | (seconds > MAX_EPOCH))[0])
        raise _refuse(what, name, lines[k], header[when], times.iloc[k], "a time from 1970 to 2286 (UTC)")
    receiver = _pattern(body[index["receiver"]], re.compile(r"(?:[A-Za-z0-9._]{1,20}-)?[A-Za-z0-9._]{1,40}"), what,
                        name, lines, header[index["receiver"]], "a receiver as MODEL-SERIAL, e.g. VR2W-128355")
    parts = receiver.str.rpartition("-")
    transmitter = _pattern(body[index["transmitter"]],
                           re.compile(r"(?:[A-Za-z0-9._]{1,20}-){0,3}[A-Za-z0-9._]{1,40}"), what, name, lines,
                           header[index["transmitter"]], "a transmitter as CODESPACE-ID, e.g. A69-1602-59335")
    tparts = transmitter.str.rpartition("-")
    frame = pd.DataFrame({"receiver": parts[2].to_numpy(), "tag": tparts[2].to_numpy(),
                          "time": seconds.astype(float) + rest / 1e9})
    if index["sensor value"] is not None:
        frame["sensor_value"] = _numbers(body[index["sensor value"]], what, name, lines, header[index["sensor value"]],
                                         -1e6, 1e6, missing=True)
    else:
        frame["sensor_value"] = np.nan
    if index["sensor unit"] is not None:
        unit = _pattern(body[index["sensor unit"]], re.compile(r"[^\x00-\x1f\x7f]{0,20}"), what, name, lines,
                        header[index["sensor unit"]], "a unit of at most 20 printable characters")
        frame["sensor_unit"] = unit.to_numpy()
    else:
        frame["sensor_unit"] = ""
    frame["code_space"] = tparts[0].to_numpy()
    frame["receiver_model"] = parts[0].to_numpy()
    if index["station name"] is not None:
        frame["station"] = body[index["station name"]].astype(str).str.strip().str.slice(0, 80).to_numpy()
    spaces = frame.groupby("tag")["code_space"].nunique()
    if (spaces > 1).any():
        tag = str(spaces[spaces > 1].index[0])
        both = sorted(frame.loc[frame["tag"] == tag, "code_space"].unique())[:2]
        raise ModelError(f"{what}: {name!r}: transmitter id {tag} is in two code spaces ({both[0]}, {both[1]}); "
                         "allowed: one code space per id (the tag is named by its id)")
    used = {when} | {k for k in index.values() if k is not None}
    return frame, used


def _check_clocks(frame: pd.DataFrame, name: str, what: str) -> None:
    """Refuse a receiver whose time goes back in the file's order: its clock reset or jumped back (or the rows are
    not in the order it logged them), named with the line, the previous line and the jump."""
    step = frame.groupby("receiver", sort=False)["time"].diff().to_numpy()
    back = np.flatnonzero(step < 0)
    if not len(back):
        return
    k = int(back[0])
    receiver = frame["receiver"].iloc[k]
    earlier = frame.index[(frame["receiver"] == receiver).to_numpy()]
    previous = int(earlier[earlier < frame.index[k]][-1])
    line, before = int(frame["line"].iloc[k]), int(frame["line"].loc[previous])
    raise ModelError(f"{what}: {name!r} line {line}: receiver {receiver}'s clock goes back {-step[k]:.6g} s from "
                     f"line {before} ({len(back)} such step{'s' * (len(back) > 1)} in the file): a clock reset or "
                     "jump, or rows not in the receiver's own order; allowed: each receiver's times not decreasing "
                     "(split the file at a reset; never sorted here)")


# --------------------------------------------------------------------------- receivers, sound speed

def read_hydrophones(path: Path | str) -> pd.DataFrame:
    """Read the receivers (hydrophones): ``serial``, ``sync_tag`` (empty: none), ``x``/``x_m``, ``y``/``y_m``
    [, ``z``/``z_m``] [m]; ``idx`` ignored.

    Returns
    -------
    pandas.DataFrame
        ``receiver`` (str), ``sync_tag`` (str, ``""`` for none), ``x``, ``y``, ``z`` [m] (``z`` NaN where the
        file gives no depths), in the file's order.

    Raises
    ------
    ModelError
        One line: a missing column, a bad serial or id, a coordinate outside [-1e7, 1e7] m, a serial or sync tag
        given twice.
    """
    path, what = Path(path), "receivers"
    name = str(path)
    header, body, lines = _table(path, what, MAX_HYDROPHONES)
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no receivers")
    serial = _column(header, ("serial", "receiver", "name"))
    sync = _column(header, ("sync_tag",))
    axes = [_column(header, (f"{a}_m", a)) for a in "xyz"]
    if serial is None or axes[0] is None or axes[1] is None:
        raise ModelError(f"{what}: {name!r}: the header needs serial, x_m and y_m (or x, y) columns, optionally "
                         f"sync_tag and z_m; got {','.join(h[:20] for h in header[:12])}")
    receivers = _pattern(body[serial], IDENTIFIER, what, name, lines, header[serial],
                         "a serial of 1 to 40 letters, digits, '.', '_' or '-'")
    if sync is not None:
        tags = body[sync].astype(str).str.strip()
        given = (tags != "").to_numpy()
        _pattern(tags[given], IDENTIFIER, what, name, [lines[k] for k in np.flatnonzero(given)], header[sync],
                 "a tag id of 1 to 40 letters, digits, '.', '_' or '-', or empty")
    else:
        tags = pd.Series([""] * len(body))
    frame = pd.DataFrame({"receiver": receivers.to_numpy(), "sync_tag": tags.to_numpy()})
    for axis, k in zip("xyz", axes):
        frame[axis] = np.nan if k is None else _numbers(body[k], what, name, lines, header[k], -MAX_COORDINATE,
                                                        MAX_COORDINATE, unit="m")
    twice = frame["receiver"][frame["receiver"].duplicated()]
    if len(twice):
        raise ModelError(f"{what}: {name!r}: receiver {twice.iloc[0]} is given twice")
    tags = frame["sync_tag"][frame["sync_tag"] != ""]
    if tags.duplicated().any():
        raise ModelError(f"{what}: {name!r}: sync tag {tags[tags.duplicated()].iloc[0]} is at two receivers; "
                         "allowed: one receiver per sync tag")
    return frame


def read_sound_speed(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Read a sound-speed series: ``epo`` (or ``time``) [s since 1970-01-01 UTC], increasing, and
    ``sound_speed_m_s`` (or ``ss``) [m/s] in :data:`SOUND_SPEED_RANGE`; other columns ignored.

    Returns
    -------
    times, speeds : numpy.ndarray
        (m,) [s] and (m,) [m/s].

    Raises
    ------
    ModelError
        One line naming the file, the line and column and the allowed range.
    """
    path, what = Path(path), "sound speed"
    name = str(path)
    header, body, lines = _table(path, what, MAX_SERIES)
    t, c = _column(header, ("epo", "time", "time_s")), _column(header, ("sound_speed_m_s", "ss", "sound_speed"))
    if t is None or c is None:
        raise ModelError(f"{what}: {name!r}: the header needs epo (or time) and sound_speed_m_s (or ss) columns; got "
                         f"{','.join(h[:20] for h in header[:12])}")
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no rows")
    times = _numbers(body[t], what, name, lines, header[t], 0.0, float(MAX_EPOCH), unit="s")
    speeds = _numbers(body[c], what, name, lines, header[c], *SOUND_SPEED_RANGE, unit="m/s")
    steps = np.diff(times)
    if (steps <= 0).any():
        k = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise ModelError(f"{what}: {name!r} line {lines[k]}: the time {times[k]:.10g} s does not increase; allowed: "
                         "times in increasing order")
    return times, speeds


__all__ = ["Detections", "FORMATS", "IDENTIFIER", "MAX_DETECTIONS", "MAX_DETECTION_BYTES", "MAX_EPOCH",
           "MAX_HYDROPHONES", "MAX_SERIES", "SOUND_SPEED_RANGE", "read_detections", "read_hydrophones",
           "read_sound_speed"]
