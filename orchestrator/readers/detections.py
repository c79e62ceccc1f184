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
* the **Innovasea Fathom (VDAT) CSV** (:mod:`.fathom`), **GLATOS** (:mod:`.glatos`) and **OTN** (:mod:`.otn`)
  detection extracts;
* **actel**'s standard detections (:mod:`.actel`) and the **Thelma** TBR exports in both layouts (:mod:`.thelma`),
  each told from its header's names as actel tells them.

A network's extract (GLATOS, OTN) is a database query sorted by animal, then time: its rows are put in each
receiver's order after reading (by receiver and time, stable; :func:`.network.ordered`), exact duplicates (the same
receiver, tag and time: one row in two extracts) dropped and counted, and no clock is judged in its order
(:attr:`Detections.row_order`). A receiver's own log (VUE, Fathom, YAPS) is taken in the order it logged (below).

A detection's tag is its full transmitter ID where the file gives the code space (VUE, Fathom, GLATOS, OTN), else its
id (:mod:`.transmitters`): one id in two code spaces is two tags.

The receivers (hydrophones) table: ``serial``, ``sync_tag`` (the id of the sync tag at that receiver, empty for
none), ``x``, ``y`` [, ``z``] or ``x_m``, ``y_m`` [, ``z_m``] [m] in a local metric frame; an ``idx`` column is
ignored (:func:`read_hydrophones`; a study's deployment tables, in latitude and longitude, with dates:
:mod:`sblsim.orchestrator.readers.deployments`). The sound-speed series: ``epo`` [s] and ``sound_speed_m_s`` (or
``ss``) [m/s], other columns ignored (:func:`read_sound_speed`).

Each file must be a regular file (a FIFO or a device is refused before it is opened), is read to at most
:data:`MAX_DETECTION_BYTES` bytes and :data:`MAX_DETECTIONS` rows (counted in what was read), is refused before
pandas builds a cell where a line is longer than 1 MiB or holds more than 512 cells, or the table more than
:data:`MAX_DETECTION_CELLS` cells (the other tables: :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`; counted by
:func:`~sblsim.orchestrator.io.tables.check_cells`), and its cells are parsed by pandas as text and every one
checked (its pattern, finite, within its range); no name or text in a file is ever taken as a path. In a receiver's
own log, a receiver whose time goes back in the file's order by more than :data:`CLOCK_TOLERANCE` (its clock reset
at a download, kept in the order it logged) is not sorted: its rows from there on are a new **clock
part** (the frame's ``clock_part`` column, 1, 2, … per receiver, added where a receiver's time goes back), each
reset kept in :attr:`Detections.clock_resets` (its line, the step and the times either side) for the
synchronisation to split the clock there and say it. Rows not in the receiver's logging order are refused, not
taken for resets: more than :data:`MAX_CLOCK_RESETS` back-steps at one receiver, or parts that share no tag (a file
sorted by tag). Every error is one line naming the file, its line or column and the allowed range
(:class:`ModelError`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.readers import actel, fathom, glatos, network, otn, thelma, vue, yaps
from sblsim.orchestrator.readers.cells import cut_short, read_text, text_table
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.readers.limits import MAX_DETECTION_BYTES, MAX_DETECTION_CELLS, MAX_DETECTIONS
from sblsim.orchestrator.readers.transmitters import match

#: A receiver's time going back in the file's order by at most this much [s] is taken as rows logged within one
#: timestamp's resolution (a VR2W's 1 ms), the same clock; by more, a reset: a new clock part.
CLOCK_TOLERANCE = 1e-3
#: The most resets (times going back in the file's order) one receiver may have; more: rows not in its order.
MAX_CLOCK_RESETS = 20
#: What a refusal of a detections file too large to read whole says to do.
LARGER = " read whole (a larger file: sblsim store FILE --out DIR, then DIR in the file's place)"
#: The formats that are a network's extract (a database query, sorted by animal then time), not a receiver's log.
NETWORKS = ("glatos", "otn")
#: The orders of :attr:`Detections.row_order`: a receiver's own log (VUE, Fathom, YAPS) as logged, its clock judged in
#: that order; a network's extract put in each receiver's order (:func:`~.network.ordered`).
LOGGED = "logged"
SORTED = "sorted by receiver and time (a network extract)"


@dataclass
class Detections:
    """Raw detections, each on its receiver's own clock.

    Attributes
    ----------
    frame : pandas.DataFrame
        One row per detection in the file's order (a network extract's: by receiver and time, :attr:`row_order`):
        ``receiver`` (str, the serial), ``tag`` (str, the full ID where
        the file gives a code space, else the id), ``code_space`` (str, ``""`` for none), ``time`` [s since
        1970-01-01 UTC on the receiver's clock], ``sensor_value`` (float, NaN without one), ``sensor_unit`` (str,
        ``""`` without one; ``raw`` for a raw value a tag sheet's slope and intercept convert), ``line`` (the file's
        line, from 1 at its first); a VUE or Fathom file adds ``receiver_model`` and ``station``, a YAPS file with a
        ``species`` column keeps it; a network extract adds ``station`` where it has one and ``receiver_note``
        (``""`` for none) where a receiver cell holds a note after its serial.
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
        then has a ``clock_part`` column. Empty where no receiver's time goes back, and for a network extract
        (whose order is not a receiver's).
    row_order : str
        :data:`LOGGED` (a receiver's own log, its clock judged in the file's order) or :data:`SORTED` (a GLATOS or
        OTN extract, sorted by receiver and time after reading).
    duplicates : int
        The exact duplicates dropped from a network extract (the same receiver, tag and time) [1]; a receiver's log
        is taken as logged (0).
    notes : list of str
        What the reader decided that a user should know (receiver cells read without their note).
    """

    frame: pd.DataFrame
    source: str
    format: str
    ignored_columns: list[str] = field(default_factory=list)
    clock_resets: list[dict] = field(default_factory=list)
    row_order: str = LOGGED
    duplicates: int = 0
    notes: list[str] = field(default_factory=list)

    def tag(self, given: str) -> str | None:
        """The detected tag a user's name stands for (a full ID, or an id where it is unique:
        :func:`~sblsim.orchestrator.readers.transmitters.match`), None where none."""
        return match(given, self.frame["tag"].unique())


# --------------------------------------------------------------------------- detections

def format_of(first: str) -> str | None:
    """The export a file's first line shows (``fathom``, ``thelma``, ``actel``, ``vue``, ``glatos``, ``otn``), None
    for none of them; Thelma's and actel's told by their columns' names (:func:`.actel.format_by_header`)."""
    lower = first.lower()
    if first.lstrip('"').startswith(fathom.FATHOM_MARK):
        return "fathom"
    by_names = actel.format_by_header(first)  # before VUE's: Thelma's exports share its date column
    if by_names is not None:
        return by_names
    if "date and time (utc" in lower:
        return "vue"
    if "detection_timestamp_utc" in lower:
        return "glatos"
    if "datecollectedutc" in lower or "datecollected" in lower:
        return "otn"
    return None


def _format_of(first: str, name: str) -> str:
    """The format a detections file's first line shows (:func:`sniff_format`)."""
    found = format_of(first)
    if found is not None:
        return found
    header = text_table(first + "\n", name, "detections", 1)[0] if first.strip() else []
    if {"tag", "serial"} <= {h.lower() for h in header}:
        return "yaps"
    raise ModelError(f"detections: {name!r}: its first line is no format sblsim reads; allowed: a YAPS table "
                     "(epo,frac,tag,serial or ts,tag,serial), a VUE export, a Fathom (VDAT) CSV, a GLATOS or an OTN "
                     "detection extract, actel's detections (Timestamp,Receiver,CodeSpace,Signal) or a Thelma TBR "
                     "export (--format " + "|".join(FORMATS) + ")")


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
        One line naming the file, its line and column and the allowed range: a file too large or cut short
        (:func:`~sblsim.orchestrator.readers.cells.cut_short`), a cell outside its pattern or range, a missing
        column, a receiver whose rows are not in its logging order (more than :data:`MAX_CLOCK_RESETS` back-steps,
        or parts that share no tag).
    """
    if format is not None and format not in FORMATS:
        raise ModelError(f"format: {format!r} is not one of {', '.join(FORMATS)}")
    path, what = Path(path), "detections"
    name = str(path)
    # a Windows export in Latin-1 (VUE writes a temperature tag's unit as °C in it) read, not refused
    text = read_text(path, what, MAX_DETECTION_BYTES, MAX_DETECTIONS, max_cells=MAX_DETECTION_CELLS,
                     fallback="latin-1", hint=LARGER, archives=True)  # a zipped extract, as a network hands it out
    if format is None:
        format = _format_of(text[:65536].split("\n", 1)[0].rstrip("\r"), name)
    cut_short(text, name, what, by_record=format == "fathom")
    if format == "fathom":
        header, body, lines = fathom.fathom_records(text, name, what, MAX_DETECTIONS, MAX_DETECTION_CELLS)
    else:
        header, body, lines = text_table(text, name, what, MAX_DETECTIONS, max_cells=MAX_DETECTION_CELLS)
    del text
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no detections")
    frame, used = rows_read(format, header, body, lines, name, what)
    if format in NETWORKS:  # a database query's order (by animal, then time), not a receiver's: no clock judged
        frame, duplicates, notes = network.ordered(frame)
        resets, order = [], SORTED
    else:
        resets, order, duplicates, notes = clock_parts(frame, name, what), LOGGED, 0, []
    ignored = [h for k, h in enumerate(header) if k not in used and h]
    return Detections(frame, name, format, ignored, resets, order, duplicates, notes)


#: Each format's reader of a table's text rows into detections.
READERS = {"yaps": yaps.yaps, "vue": vue.vue, "fathom": fathom.fathom, "glatos": glatos.glatos, "otn": otn.otn,
           "actel": actel.actel, "thelma": thelma.thelma}


def rows_read(format: str, header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
              ) -> tuple[pd.DataFrame, set[int]]:
    """A table's text rows (a file's, or a piece's: :mod:`sblsim.orchestrator.store.ingest`) read by ``format``'s
    reader (:data:`READERS`) into detections in the rows' order, each with its ``line`` in the file, the index from 0;
    and the header's columns used.

    Raises
    ------
    ModelError
        The reader's refusals (one line naming the file, its line and column).
    """
    frame, used = READERS[format](header, body, lines, name, what)
    if "line" not in frame:  # a reader that adds rows of its own (Fathom's sensor records) gives their lines
        frame["line"] = np.asarray(lines, np.int64)
    return frame.reset_index(drop=True), used


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
        tags = frame["tag"].to_numpy(dtype=object)[mine]
        check_parts(r, int(lines[k]), int(lines[int(previous[k])]), float(step[k]), len(steps),
                    [set(tags[part[mine] == p]) for p in range(1, len(steps) + 2)], name, what)
    frame["clock_part"] = part
    time = frame["time"].to_numpy(float)
    return [{"receiver": str(receiver[k]), "line": int(lines[k]), "previous_line": int(lines[int(previous[k])]),
             "step_s": float(step[k]), "before_s": float(time[int(previous[k])]), "after_s": float(time[k]),
             "clock_part": int(part[k])} for k in back]


def check_parts(receiver: str, line: int, previous_line: int, step: float, resets: int, tags: list[set], name: str,
                what: str) -> None:
    """Refuse a receiver's clock parts that are not its logging order (:func:`clock_parts`): more than
    :data:`MAX_CLOCK_RESETS` resets, or parts sharing no tag with the next (``tags``: each part's tags, in order);
    ``line``, ``previous_line`` and ``step`` [s] are its first reset's.

    Raises
    ------
    ModelError
        One line naming the line, the receiver and the step.
    """
    where = (f"{what}: {name!r} line {line}: receiver {receiver}'s clock goes back {-step:.6g} s from line "
             f"{previous_line}")
    if resets > MAX_CLOCK_RESETS:
        raise ModelError(f"{where} ({resets} such steps in the file): rows not in the receiver's own order; "
                         f"allowed: each receiver's rows in the order it logged them, its time going back at "
                         f"most {MAX_CLOCK_RESETS} times (a clock reset)")
    if all(not (a & b) for a, b in zip(tags[:-1], tags[1:])):
        raise ModelError(f"{where} where its tag changes, its parts sharing no tag: rows sorted by tag, not in "
                         "the receiver's own order; allowed: each receiver's rows in the order it logged them "
                         "(its time going back only at a clock reset)")


def reset_line(reset: dict) -> str:
    """One line naming a receiver's time going back in the file's order (an entry of
    :attr:`Detections.clock_resets`; of many files, the file's named)."""
    before, after = (text[:23] for text in iso_utc([reset["before_s"], reset["after_s"]]))
    where = f"line {reset['line']}" + (f" of {reset['file']}" if reset.get("file") else "")
    return (f"receiver {reset['receiver']}: its time goes back {-reset['step_s']:.6g} s at {where} "
            f"(its clock from {before} to {after} UTC): a new clock segment (part {reset['clock_part']})")


__all__ = ["CLOCK_TOLERANCE", "Detections", "FORMATS", "LOGGED", "MAX_CLOCK_RESETS", "NETWORKS", "SORTED",
           "READERS", "check_parts", "clock_parts", "format_of", "read_detections", "reset_line", "rows_read",
           "sniff_format"]
