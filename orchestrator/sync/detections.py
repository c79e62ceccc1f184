"""Reading raw detections of an acoustic-telemetry array, as hostile input (``sblsim sync``, ``toa``, ``track``).

A raw detection is what one receiver logs when it decodes a transmitter: a time on the receiver's **own clock**, the
receiver and the transmitter (tag). The receivers' own exports are read into one tidy table
(:func:`read_detections`; the format named, or read from the file's first line by :func:`sniff_format`):

* the **YAPS tables** (Baktoft et al. 2017, Sci. Rep. 7:14294): detections with the columns ``epo`` (whole seconds
  since 1970-01-01 UTC) and ``frac`` (the fraction of that second, in [0, 1)), or ``ts`` alone (an ISO 8601 time,
  UTC), ``tag`` and ``serial`` (the receiver); with ``epo`` and ``frac``, ``ts`` is not used; others are ignored,
  named;
* the **Vemco/Innovasea VUE export CSV**: ``Date and Time (UTC)`` (ISO 8601: ``YYYY-MM-DD hh:mm:ss[.ffffff]`` or
  ``…T…Z``; a header ``Date and Time (UTC+hh:mm)`` gives a fixed zone, converted to UTC), ``Receiver``
  (``VR2W-128355``: the model and the serial, the serial kept), ``Transmitter`` (the full ID ``A69-1602-59335``:
  the tag, its code space also in a column of its own), ``Sensor Value`` and ``Sensor Unit`` (kept per detection:
  a depth in metres, or a raw ``ADC`` value), ``Station Name``; the other columns are ignored;
* the **Innovasea Fathom (VDAT) CSV**, **GLATOS** and **OTN** detection extracts: :mod:`.exports`.

A detection's tag is its full transmitter ID where the file gives the code space (VUE, Fathom, GLATOS, OTN), else its
id (:mod:`.transmitters`): one id in two code spaces is two tags.

The receivers (hydrophones) table: ``serial``, ``sync_tag`` (the id of the sync tag at that receiver, empty for
none), ``x``, ``y`` [, ``z``] or ``x_m``, ``y_m`` [, ``z_m``] [m] in a local metric frame; an ``idx`` column is
ignored (:func:`read_hydrophones`; a study's deployment tables, in latitude and longitude, with dates:
:mod:`sblsim.orchestrator.telemetry.deployments`). The sound-speed series: ``epo`` [s] and ``sound_speed_m_s`` (or
``ss``) [m/s], other columns ignored (:func:`read_sound_speed`).

Each file must be a regular file (a FIFO or a device is refused before it is opened), is read to at most
:data:`MAX_DETECTION_BYTES` bytes and :data:`MAX_DETECTIONS` rows (counted in what was read), is refused before
pandas builds a cell where a line is longer than 1 MiB or holds more than 512 cells, or the table more than
:data:`MAX_DETECTION_CELLS` cells (the other tables: :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`; counted by
:func:`~sblsim.orchestrator.io.tables.check_cells`), and its cells are parsed by pandas as text and every one
checked (its pattern, finite, within its range); no name or text in a file is
ever taken as a path. A receiver whose time goes back in the file's order by more than :data:`CLOCK_TOLERANCE` (its
clock reset at a download, kept in the order it logged) is not sorted: its rows from there on are a new **clock
part** (the frame's ``clock_part`` column, 1, 2, … per receiver, added where a receiver's time goes back), each
reset kept in :attr:`Detections.clock_resets` (its line, the step and the times either side) for the
synchronisation to split the clock there and say it. Rows not in the receiver's logging order are refused, not
taken for resets: more than :data:`MAX_CLOCK_RESETS` back-steps at one receiver, or parts that share no tag (a file
sorted by tag). Every error is one line naming the file, its line or column and the allowed range
(:class:`ModelError`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import iso_utc, utc_seconds
from sblsim.orchestrator.sync import exports
from sblsim.orchestrator.sync.cells import column, numbers, pattern, read_text, refuse, shown_header, text_table
from sblsim.orchestrator.sync.transmitters import TRANSMITTER, match, split

#: The largest file read [bytes] and the most rows (detections; receivers; points of a sound-speed series).
MAX_DETECTION_BYTES = 256 * 2**20
MAX_DETECTIONS = 3_000_000
MAX_HYDROPHONES = 1000
MAX_SERIES = 1_000_000
#: The most cells a detections file holds [1]: 3 million detections of 11 cells (a VUE export has 10 columns, a
#: Fathom DET record about 20, a GLATOS or OTN extract about 30 in rows a few hundred bytes long); a table of as many
#: cells of one character each is parsed in about 0.9 GiB.
MAX_DETECTION_CELLS = 2**25
#: The allowed times [s since 1970-01-01 UTC] (to the year 2286), coordinates [m] and sound speeds [m/s].
MAX_EPOCH = 10_000_000_000
MAX_COORDINATE = 1e7
SOUND_SPEED_RANGE = (1300.0, 1700.0)
#: A receiver's serial or a tag's id: letters, digits, ``. _ -``, 1 to 40 characters, a letter or digit first.
IDENTIFIER = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,39}")
_INTEGER = re.compile(r"[0-9]{1,11}")
_VUE_ZONE = re.compile(r"date and time \(utc(?:([+-])([0-9]{2}):?([0-9]{2}))?\)")
#: The VUE export's columns (lower case) this reader uses; the others of the export are ignored.
VUE_COLUMNS = ("receiver", "transmitter", "sensor value", "sensor unit", "station name")
#: The formats of :func:`read_detections`.
FORMATS = ("yaps", "vue", "fathom", "glatos", "otn")
#: A receiver's time going back in the file's order by at most this much [s] is taken as rows logged within one
#: timestamp's resolution (a VR2W's 1 ms), the same clock; by more, a reset: a new clock part.
CLOCK_TOLERANCE = 1e-3
#: The most resets (times going back in the file's order) one receiver may have; more: rows not in its order.
MAX_CLOCK_RESETS = 20


@dataclass
class Detections:
    """Raw detections, each on its receiver's own clock.

    Attributes
    ----------
    frame : pandas.DataFrame
        One row per detection in the file's order: ``receiver`` (str, the serial), ``tag`` (str, the full ID where
        the file gives a code space, else the id), ``code_space`` (str, ``""`` for none), ``time`` [s since
        1970-01-01 UTC on the receiver's clock], ``sensor_value`` (float, NaN without one), ``sensor_unit`` (str,
        ``""`` without one; ``raw`` for a raw value a tag sheet's slope and intercept convert), ``line`` (the file's
        line, from 1 at its first); a VUE or Fathom file adds ``receiver_model`` and ``station``, a YAPS file with a
        ``species`` column keeps it.
    source : str
        The file read.
    format : str
        One of :data:`FORMATS`.
    ignored_columns : list of str
        The file's columns not used.
    clock_resets : list of dict
        Each place a receiver's time goes back in the file's order (by more than :data:`CLOCK_TOLERANCE`): its
        ``receiver``, the ``line`` of the first row after it and the ``previous_line``, the ``step_s`` [s] (< 0),
        the times ``before_s`` and ``after_s`` [s since 1970 UTC on its clock] and the new ``clock_part``; the frame
        then has a ``clock_part`` column. Empty where no receiver's time goes back.
    """

    frame: pd.DataFrame
    source: str
    format: str
    ignored_columns: list[str] = field(default_factory=list)
    clock_resets: list[dict] = field(default_factory=list)

    def tag(self, given: str) -> str | None:
        """The detected tag a user's name stands for (a full ID, or an id where it is unique:
        :func:`~sblsim.orchestrator.sync.transmitters.match`), None where none."""
        return match(given, self.frame["tag"].unique())


# --------------------------------------------------------------------------- the text of a table

def _table(path: Path, what: str, max_rows: int) -> tuple[list[str], pd.DataFrame, list[int]]:
    """A CSV file's header (stripped) and its rows as text cells, with each row's line in the file (1: the header);
    blank lines skipped: :func:`~sblsim.orchestrator.sync.cells.read_text` (at most :data:`MAX_DETECTION_BYTES` bytes
    and ``max_rows`` rows) and :func:`~sblsim.orchestrator.sync.cells.text_table`."""
    return text_table(read_text(path, what, MAX_DETECTION_BYTES, max_rows), str(path), what, max_rows)


#: The cell checks, under the names the readers of this package import them by.
_pattern, _numbers, _column, _refuse = pattern, numbers, column, refuse


# --------------------------------------------------------------------------- detections

def _format_of(first: str, name: str) -> str:
    """The format a detections file's first line shows (:func:`sniff_format`)."""
    found = exports.format_of(first)
    if found is not None:
        return found
    header = text_table(first + "\n", name, "detections", 1)[0] if first.strip() else []
    if {"tag", "serial"} <= {h.lower() for h in header}:
        return "yaps"
    raise ModelError(f"detections: {name!r}: its first line is no format sblsim reads; allowed: a YAPS table "
                     "(epo,frac,tag,serial or ts,tag,serial), a VUE export, a Fathom (VDAT) CSV, a GLATOS or an OTN "
                     "detection extract (--format yaps|vue|fathom|glatos|otn)")


def sniff_format(path: Path | str) -> str:
    """The format of a detections file, read from its first line (at most 64 KiB of the file): Fathom's ``VEMCO
    DATA LOG``, VUE's ``Date and Time (UTC…)``, GLATOS's ``detection_timestamp_utc``, OTN's ``dateCollectedUTC``
    (or ``datecollected``), else the YAPS table (``tag`` and ``serial``).

    Raises
    ------
    ModelError
        A file that cannot be read, or whose first line is none of these.
    """
    path = Path(path)
    head = read_text(path, "detections", MAX_DETECTION_BYTES, MAX_DETECTIONS, prefix=65536)
    return _format_of(head.split("\n", 1)[0].rstrip("\r"), str(path))


def read_detections(path: Path | str, format: str | None = "yaps") -> Detections:
    """Read raw detections (the module docstring's formats) into one table, checked.

    Parameters
    ----------
    path : str or Path
        The detections file (CSV).
    format : str, optional
        One of :data:`FORMATS`; None: read from the file's first line (:func:`sniff_format`).

    Returns
    -------
    Detections

    Raises
    ------
    ModelError
        One line naming the file, its line and column and the allowed range: a file too large, a cell outside
        its pattern or range, a missing column, a receiver whose rows are not in its logging order (more than
        :data:`MAX_CLOCK_RESETS` back-steps, or parts that share no tag).
    """
    if format is not None and format not in FORMATS:
        raise ModelError(f"format: {format!r} is not one of {', '.join(FORMATS)}")
    path, what = Path(path), "detections"
    name = str(path)
    # a Windows export in Latin-1 (VUE writes a temperature tag's unit as °C in it) read, not refused
    text = read_text(path, what, MAX_DETECTION_BYTES, MAX_DETECTIONS, max_cells=MAX_DETECTION_CELLS,
                     fallback="latin-1")
    if format is None:
        format = _format_of(text[:65536].split("\n", 1)[0].rstrip("\r"), name)
    if format == "fathom":
        header, body, lines = exports.fathom_records(text, name, what, MAX_DETECTIONS, MAX_DETECTION_CELLS)
    else:
        header, body, lines = text_table(text, name, what, MAX_DETECTIONS, max_cells=MAX_DETECTION_CELLS)
    del text
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no detections")
    reader = {"yaps": _yaps, "vue": _vue, "fathom": exports.fathom, "glatos": exports.glatos,
              "otn": exports.otn}[format]
    frame, used = reader(header, body, lines, name, what)
    if "line" not in frame:  # a reader that adds rows of its own (Fathom's sensor records) gives their lines
        frame["line"] = np.asarray(lines, np.int64)
    frame = frame.reset_index(drop=True)
    resets = clock_parts(frame, name, what)
    ignored = [h for k, h in enumerate(header) if k not in used and h]
    return Detections(frame, name, format, ignored, resets)


def _yaps(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
          ) -> tuple[pd.DataFrame, set[int]]:
    index = {key: _column(header, (key,)) for key in ("epo", "frac", "ts", "tag", "serial", "species")}
    timed = (index["epo"] is not None and index["frac"] is not None) or index["ts"] is not None
    missing = [key for key in ("tag", "serial") if index[key] is None] + ([] if timed else ["epo and frac (or ts)"])
    if missing:
        raise ModelError(f"{what}: {name!r}: the header needs the columns epo, frac, tag, serial (or ts, tag, serial: "
                         f"YAPS); {', '.join(missing)} missing, got {shown_header(header)}")
    if index["epo"] is not None and index["frac"] is not None:
        epo = _pattern(body[index["epo"]], _INTEGER, what, name, lines, "epo",
                       f"whole seconds since 1970-01-01 UTC in [0, {MAX_EPOCH}]")
        seconds = epo.astype(np.int64).to_numpy()
        if (seconds > MAX_EPOCH).any():
            k = int(np.flatnonzero(seconds > MAX_EPOCH)[0])
            raise _refuse(what, name, lines[k], "epo", epo.iloc[k], f"whole seconds in [0, {MAX_EPOCH}]")
        frac = _numbers(body[index["frac"]], what, name, lines, "frac", 0.0, 1.0, high_open=True, unit="s")
        time = seconds + frac
        used = {index["epo"], index["frac"]}
    else:
        time = utc_seconds(body[index["ts"]], f"{what}: {name!r}", lines, header[index["ts"]])
        used = set()
    if index["ts"] is not None:
        used.add(index["ts"])
    tag = _pattern(body[index["tag"]], IDENTIFIER, what, name, lines, "tag",
                   "an id of 1 to 40 letters, digits, '.', '_' or '-'")
    serial = _pattern(body[index["serial"]], IDENTIFIER, what, name, lines, "serial",
                      "a receiver's serial of 1 to 40 letters, digits, '.', '_' or '-'")
    frame = pd.DataFrame({"receiver": serial.to_numpy(), "tag": tag.to_numpy(), "code_space": "", "time": time,
                          "sensor_value": np.full(len(body), np.nan), "sensor_unit": ""})
    used |= {index["tag"], index["serial"]}
    if index["species"] is not None:
        frame["species"] = body[index["species"]].astype(str).str.strip().str.slice(0, 80).to_numpy()
        used.add(index["species"])
    return frame, used


#: A receiver as VUE names it: ``MODEL-SERIAL`` (``VR2W-128355``), or the serial alone.
RECEIVER = re.compile(r"(?:[A-Za-z0-9._]{1,20}-)?[A-Za-z0-9._]{1,40}")


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
    seconds = utc_seconds(body[when], f"{what}: {name!r}", lines, header[when])
    if zone.group(1):
        shift = (int(zone.group(2)) * 3600 + int(zone.group(3)) * 60) * (1 if zone.group(1) == "+" else -1)
        seconds = seconds - shift  # local time = UTC + shift
    receiver = _pattern(body[index["receiver"]], RECEIVER, what, name, lines, header[index["receiver"]],
                        "a receiver as MODEL-SERIAL, e.g. VR2W-128355")
    parts = receiver.str.rpartition("-")
    transmitter = _pattern(body[index["transmitter"]], TRANSMITTER, what, name, lines, header[index["transmitter"]],
                           "a transmitter as CODESPACE-ID, e.g. A69-1602-59335")
    frame = pd.DataFrame({"receiver": parts[2].to_numpy(), "tag": transmitter.to_numpy(),
                          "code_space": [split(t)[0] for t in transmitter], "time": seconds})
    frame["sensor_value"], frame["sensor_unit"] = exports.sensor_columns(
        body, index["sensor value"], index["sensor unit"], header, lines, name, what)
    frame["receiver_model"] = parts[0].to_numpy()
    if index["station name"] is not None:
        frame["station"] = body[index["station name"]].astype(str).str.strip().str.slice(0, 80).to_numpy()
    used = {when} | {k for k in index.values() if k is not None}
    return frame, used


def clock_parts(frame: pd.DataFrame, name: str, what: str) -> list[dict]:
    """Each receiver's clock parts in the file's order (the module docstring): where its time goes back by more than
    :data:`CLOCK_TOLERANCE`, a ``clock_part`` column (1 first) is added to ``frame`` (in place) and each reset
    returned (:attr:`Detections.clock_resets`); none: the frame unchanged, an empty list.

    Raises
    ------
    ModelError
        A receiver with more than :data:`MAX_CLOCK_RESETS` resets, or whose parts share no tag (rows sorted by tag,
        not logged in that order): one line naming the line, the receiver and the step.
    """
    step = frame.groupby("receiver", sort=False)["time"].diff().to_numpy()
    back = np.flatnonzero(step < -CLOCK_TOLERANCE)
    if not len(back):
        return []
    receiver = frame["receiver"].to_numpy(dtype=object)
    reset = np.zeros(len(frame), np.int64)
    reset[back] = 1
    part = pd.Series(reset).groupby(receiver, sort=False).cumsum().to_numpy() + 1
    previous = frame.index.to_series().groupby(receiver, sort=False).shift().to_numpy()
    lines = frame["line"].to_numpy()
    for r in pd.unique(receiver[back]):
        mine = np.flatnonzero(receiver == r)
        steps = back[receiver[back] == r]
        k = int(steps[0])
        where = (f"{what}: {name!r} line {lines[k]}: receiver {r}'s clock goes back {-step[k]:.6g} s from line "
                 f"{lines[int(previous[k])]}")
        if len(steps) > MAX_CLOCK_RESETS:
            raise ModelError(f"{where} ({len(steps)} such steps in the file): rows not in the receiver's own order; "
                             f"allowed: each receiver's rows in the order it logged them, its time going back at "
                             f"most {MAX_CLOCK_RESETS} times (a clock reset)")
        tags = frame["tag"].to_numpy(dtype=object)[mine]
        sets = [set(tags[part[mine] == p]) for p in range(1, len(steps) + 2)]
        if all(not (a & b) for a, b in zip(sets[:-1], sets[1:])):
            raise ModelError(f"{where} where its tag changes, its parts sharing no tag: rows sorted by tag, not in "
                             "the receiver's own order; allowed: each receiver's rows in the order it logged them "
                             "(its time going back only at a clock reset)")
    frame["clock_part"] = part
    time = frame["time"].to_numpy(float)
    return [{"receiver": str(receiver[k]), "line": int(lines[k]), "previous_line": int(lines[int(previous[k])]),
             "step_s": float(step[k]), "before_s": float(time[int(previous[k])]), "after_s": float(time[k]),
             "clock_part": int(part[k])} for k in back]


def reset_line(reset: dict) -> str:
    """One line naming a receiver's time going back in the file's order (an entry of
    :attr:`Detections.clock_resets`)."""
    before, after = (text[:23] for text in iso_utc([reset["before_s"], reset["after_s"]]))
    return (f"receiver {reset['receiver']}: its time goes back {-reset['step_s']:.6g} s at line {reset['line']} "
            f"(its clock from {before} to {after} UTC): a new clock segment (part {reset['clock_part']})")


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


__all__ = ["CLOCK_TOLERANCE", "Detections", "FORMATS", "IDENTIFIER", "MAX_CLOCK_RESETS", "MAX_DETECTIONS",
           "MAX_DETECTION_BYTES", "MAX_DETECTION_CELLS", "MAX_EPOCH", "MAX_HYDROPHONES", "MAX_SERIES",
           "SOUND_SPEED_RANGE", "clock_parts", "read_detections", "read_hydrophones", "read_sound_speed",
           "reset_line"]
