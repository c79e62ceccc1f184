"""A network's detection extract (GLATOS's, OTN's) as detections: each field found by the names :mod:`.glatos` and
:mod:`.otn` declare for it (their ``SCHEMA``), checked cell by cell, and the rows then put in each receiver's order.

An extract is a database query, sorted by animal and then time (or as the query asked), not the order a receiver
logged its detections: :func:`ordered` sorts its rows by receiver and time (stable: rows of one receiver and one time
keep the file's order, each keeps its ``line``), and drops an exact duplicate (the same receiver, tag and time: the
same row in two extracts joined), counted. A receiver cell annotated after its serial (OTN's ``5321(lost/found)``)
is read as the serial (``5321``), its note kept in the ``receiver_note`` column. An ERDDAP-style units row under the
header (``UTC`` over the time) is skipped (:func:`~sblsim.orchestrator.readers.cells.units_row`); a time-zone column
(the older OTN extracts' ``timezone``) must say UTC.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import column, pattern, per_value, refuse, shown_header, trimmed, units_row
from sblsim.orchestrator.readers.sensors import sensor_columns
from sblsim.orchestrator.readers.transmitters import (
    CODE_SPACE,
    FULL_ID,
    TAG_ID,
    after_last_dash,
    before_last_dash,
    full_ids,
)

#: A receiver's serial as the exports give it (``VR2W-128355`` keeps ``128355``).
RECEIVER = re.compile(r"(?:[A-Za-z0-9._]{1,20}-){0,2}[A-Za-z0-9._]{1,40}")
#: A receiver cell with a note after the serial in brackets (OTN's ``5321(lost/found)``): the serial, the note.
ANNOTATED = re.compile(r"(?P<serial>[^()]*[^()\s])\s*\((?P<note>[^()]{0,80})\)")
#: The zones a time-zone column may name: the times are read as UTC.
UTC_NAMES = ("utc", "gmt", "z", "etc/utc", "utc+00:00", "")
#: The fields an extract's ``SCHEMA`` names (each the header names it may have, case ignored; the first shown).
FIELDS = ("time", "receiver", "full_id", "space", "id", "value", "unit", "station", "zone")


def extract(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str, network: str,
            names: dict[str, tuple[str, ...]]) -> tuple[pd.DataFrame, set[int]]:
    """A network's detection extract: ``names`` gives each of :data:`FIELDS` the header names it may have (case
    ignored; a field without names is not read); the rows in the file's order, each with its ``line``.

    Raises
    ------
    ModelError
        A missing column, a cell outside its pattern, a time zone other than UTC, a units row stating another unit for
        the time (one line naming the file, its line and column).
    """
    index = {key: column(header, names.get(key, ())) for key in FIELDS}
    has_tag = index["full_id"] is not None or index["id"] is not None
    missing = [names[key][0] for key in ("time", "receiver") if index[key] is None] + \
        ([] if has_tag else [names["full_id"][0]])
    if missing:
        raise ModelError(f"{what}: {name!r}: an {network} detection extract needs the columns "
                         f"{', '.join(names[k][0] for k in ('time', 'receiver'))} and "
                         f"{names['full_id'][0]} (or {names['space'][0]} and {names['id'][0]}); "
                         f"{', '.join(missing)} missing, got {shown_header(header)}")
    body, lines, _ = units_row(header, body, lines, {index["time"]: "time"}, name, what)
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header, a units row and no detections")
    if index["zone"] is not None:
        zone = body[index["zone"]].astype(str).str.strip()
        other = np.flatnonzero(~zone.str.lower().isin(UTC_NAMES).to_numpy(bool))
        if len(other):
            k = int(other[0])
            raise refuse(what, name, lines[k], header[index["zone"]], zone.iloc[k],
                         f"UTC (the times in {header[index['time']]} are read as UTC)")
    time = utc_seconds(body[index["time"]], f"{what}: {name!r}", lines, header[index["time"]])
    serial, note = annotated(body[index["receiver"]])
    receiver = pattern(serial, RECEIVER, what, name, lines, header[index["receiver"]],
                       "a receiver's serial (or MODEL-SERIAL, e.g. VR2W-128355), a note in brackets after it "
                       "allowed").pipe(after_last_dash)
    if index["full_id"] is not None and (index["id"] is None or index["space"] is None):
        tag = pattern(body[index["full_id"]], FULL_ID, what, name, lines, header[index["full_id"]],
                      "a transmitter's full ID CODESPACE-ID, e.g. A69-1602-4555")
    else:
        space = pattern(body[index["space"]], CODE_SPACE, what, name, lines, header[index["space"]],
                        "a code space, e.g. A69-1602") if index["space"] is not None else \
            pd.Series([""] * len(body))
        ident = pattern(body[index["id"]], TAG_ID, what, name, lines, header[index["id"]],
                        "a transmitter's id of 1 to 40 letters, digits, '.' or '_'")
        tag = full_ids(space, ident)
    frame = pd.DataFrame({"receiver": receiver.array, "tag": tag.array, "code_space": before_last_dash(tag).array,
                          "time": time})
    frame["sensor_value"], frame["sensor_unit"] = sensor_columns(body, index["value"], index["unit"], header, lines,
                                                                 name, what)
    if index["station"] is not None:
        frame["station"] = trimmed(body[index["station"]], 80)
    if (note != "").any():
        frame["receiver_note"] = note
    frame["line"] = np.asarray(lines, np.int64)
    return frame, {k for k in index.values() if k is not None}


def annotated(cells: pd.Series) -> tuple[pd.Series, np.ndarray]:
    """A receiver column's cells with a note in brackets after the serial (``5321(lost/found)``) split: the cells
    without it (stripped), and each note (``""`` where none)."""
    cells = per_value(cells, lambda v: v.astype(str).str.strip())
    parts = per_value(cells, lambda v: v.str.fullmatch(ANNOTATED.pattern).fillna(False)).to_numpy(bool)
    note = np.full(len(cells), "", dtype=object)
    if parts.any():
        found = cells[parts].str.extract(ANNOTATED.pattern)
        cells = cells.copy()
        cells[parts] = found["serial"].to_numpy()
        note[parts] = found["note"].str.strip().to_numpy()
    return cells, note


def ordered(frame: pd.DataFrame) -> tuple[pd.DataFrame, int, list[str]]:
    """An extract's detections in each receiver's order: sorted by ``receiver`` and ``time`` (stable), an exact
    duplicate (the same receiver, tag and time; the first in the file kept) dropped; returns the frame (index from 0),
    the duplicates dropped and the notes (the receiver cells read with a note after the serial, counted)."""
    frame = frame.sort_values("time", kind="stable").sort_values("receiver", kind="stable")
    twice = frame.duplicated(["receiver", "tag", "time"], keep="first").to_numpy(bool)
    frame = frame[~twice].reset_index(drop=True)
    notes = []
    if "receiver_note" in frame:
        said = frame.loc[frame["receiver_note"] != "", ["receiver", "receiver_note"]].value_counts()
        shown = ", ".join(f"{r}({n}): {c:,}" for (r, n), c in list(said.items())[:6])
        notes.append(f"receiver cells with a note after the serial in {int(said.sum()):,} detections ({shown}"
                     f"{', ...' if len(said) > 6 else ''}): the serial read, the note kept (receiver_note)")
    return frame, int(twice.sum()), notes


__all__ = ["ANNOTATED", "FIELDS", "RECEIVER", "UTC_NAMES", "annotated", "extract", "ordered"]
