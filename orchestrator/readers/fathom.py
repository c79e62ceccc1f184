"""The detection exports of Innovasea's Fathom software, read into the table of
:func:`sblsim.orchestrator.readers.detections.read_detections` (which reads the text, bounded, and calls these).

**Fathom (VDAT) CSV** (the export of Innovasea's current receivers: HR2, VR2Tx, VR2AR, NexTrak; glatos's
``vdat_csv_schema`` lists its record types and columns): a first line ``VEMCO DATA LOG,<format version>,<writer>``,
then record types interleaved, each line's first field naming its type, each type's columns given once by a
``<TYPE>_DESC`` line. The ``DET`` records are the detections: ``Device Time (UTC)`` (the receiver's own clock,
before Fathom's corrections: what the clocks' synchronisation needs), ``Serial Number``, ``Model``, ``Full ID``
(the transmitter), ``Raw Data`` (a sensor tag's raw value, format 2) or ``Sensor Value`` and ``Sensor Unit``
(format 1), ``Station Name``; the ``DET_SENS`` records (format 2) give a sensor detection's converted ``Sensor
Value`` and ``Sensor Unit``: where one is also a ``DET`` record (the same time, receiver and transmitter) its
value is that detection's, else it is a detection of its own. Only these record types are parsed: the lines of
the others are skipped unread by their first field (a regular expression selects the lines; pandas parses them).

Times are ISO 8601 (UTC unless a zone is given) or epoch seconds (:mod:`sblsim.orchestrator.io.times`), the fraction
of a second kept. Each transmitter is its full ID (code space and id): one id in two code spaces is two tags.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import (
    SEPARATORS,
    column,
    pattern,
    shown_header,
    text_table,
    too_large,
    trimmed,
)
from sblsim.orchestrator.readers.sensors import sensor_columns
from sblsim.orchestrator.readers.transmitters import TAG_ID, TRANSMITTER, before_last_dash

#: Fathom's first line.
FATHOM_MARK = "VEMCO DATA LOG"
#: The Fathom record types read: the detections and the sensor detections.
FATHOM_RECORDS = ("DET", "DET_SENS")


def fathom_records(text: str, name: str, what: str, max_rows: int, max_cells: int | None = None
                   ) -> tuple[list[str], pd.DataFrame, list[int]]:
    """A Fathom CSV's ``DET`` records as a table (:func:`~sblsim.orchestrator.readers.cells.text_table`: the
    ``DET_DESC`` line its header, each row's line in the file), the ``DET_SENS`` records' table attached as
    ``body.attrs["sensors"]`` (header, body, lines) where there are any. Each record type's table is refused before
    pandas parses it where it would hold more than ``max_cells`` cells [1] (its lines times its ``_DESC`` line's
    cells; default :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`; the file's own lines are counted as it is
    read).

    Raises
    ------
    ModelError
        One line: a first line that is not Fathom's, no ``DET_DESC`` line, a record pandas cannot parse, a table of
        too many cells.
    """
    tables = fathom_tables(text, name, what, FATHOM_RECORDS, max_rows, max_cells)
    if "DET" not in tables:
        raise no_det_desc(text, name, what)
    header, body, lines = tables["DET"]
    if "DET_SENS" in tables:
        body.attrs["sensors"] = tables["DET_SENS"]
    return header, body, lines


def no_det_desc(text: str, name: str, what: str) -> ModelError:
    """The one-line refusal of a Fathom CSV ``text`` (its whole text, or its first part) without a ``DET_DESC`` line
    Fathom wrote: one whose columns a spreadsheet saved again with semicolons or tabs is said to be so."""
    separated = re.search(r'(?m)^[ "]*DET_DESC"?[ ]*([;\t])', text)
    if separated is not None:  # Fathom writes commas: a spreadsheet saved it again
        return ModelError(f"{what}: {name!r}: its DET_DESC line's columns are separated by "
                          f"{SEPARATORS[separated[1]]}; allowed: Fathom's own CSV, comma-separated (export it again "
                          "from Fathom)")
    return ModelError(f"{what}: {name!r}: no DET_DESC line (the detections' columns); allowed: a Fathom CSV holding "
                      "detection records")


def fathom_tables(text: str, name: str, what: str, records: tuple[str, ...], max_rows: int,
                  max_cells: int | None = None) -> dict[str, tuple[list[str], pd.DataFrame, list[int]]]:
    """A Fathom CSV's records of the types ``records``, each type's as a table
    (:func:`~sblsim.orchestrator.readers.cells.text_table`; each row's line in the file), by type; a type without a
    ``_DESC`` line is left out. Every ``<TYPE>_DESC`` line defines the columns of the records of its type that
    follow it, until the next one (two exports concatenated, the second's columns in another order, are each read
    under their own header); the table's header is the first ``_DESC``'s columns, then any new ones of the later,
    each record's cells under its own header's names (case ignored; a column a header lacks: empty). The lines are
    chosen by their first field (a regular expression; a quoted cell may span lines): the other types' lines are
    skipped unread. Each header's rows are refused before pandas parses them where they would hold more than
    ``max_cells`` cells [1] (default :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`), and a type of more than
    ``max_rows`` rows in all.

    Raises
    ------
    ModelError
        One line: a first line that is not Fathom's, a record pandas cannot parse, a table of too many rows or cells.
    """
    if not text.lstrip('"').startswith(FATHOM_MARK):
        raise ModelError(f"{what}: {name!r}: a Fathom CSV starts with the line {FATHOM_MARK},…; allowed: the file "
                         "Fathom (or vdat.exe) wrote, unchanged")
    newlines = np.fromiter((m.start() for m in re.finditer("\n", text)), np.int64)
    tables = {}
    for record in records:
        chosen = list(re.finditer(rf'^"?{record}(?:_DESC)?"?,(?:[^"\n]+|"[^"]*")*[^\n]*', text, flags=re.M))
        is_desc = [m.group(0).lstrip('"').startswith(f"{record}_DESC") for m in chosen]
        if not any(is_desc):
            continue
        first = is_desc.index(True)  # records before the first header have no columns: not read
        headers, bodies, lines = [], [], []
        for k in range(first, len(chosen)):
            if is_desc[k]:
                headers.append(chosen[k])
                bodies.append([])
            else:
                bodies[-1].append(chosen[k])
        if sum(len(b) for b in bodies) > max_rows:
            raise too_large(name, what, f"has {sum(len(b) for b in bodies):,} {record} records", 2**62, max_rows)
        combined: list[str] = []
        known: list[str] = []
        parts = []
        for desc, rows in zip(headers, bodies):
            table = "\n".join([desc.group(0).rstrip("\r")] + [m.group(0).rstrip("\r") for m in rows]) + "\n"
            header, body, _ = text_table(table, name, what, max_rows, first_line=0, max_cells=max_cells)
            keys = [h.lower() or f"#{j}" for j, h in enumerate(header)]  # an unnamed column by its place
            for h, key in zip(header, keys):
                if key not in known:
                    known.append(key)
                    combined.append(h)
            body.columns = [known.index(key) for key in keys[:body.shape[1]]]
            parts.append(body)
            lines.extend((np.searchsorted(newlines, [m.start() for m in rows]) + 1).tolist())
        body = pd.concat(parts, ignore_index=True).reindex(columns=range(len(combined)), fill_value="")
        tables[record] = (combined, body.fillna(""), lines)
    return tables


def _fathom_table(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
                  ) -> tuple[pd.DataFrame, set[int]]:
    """One Fathom record type's rows as detections (receiver, tag, code space, time, sensor value and unit, model,
    station) and the columns used."""
    index = {key: column(header, (key,)) for key in ("device time (utc)", "serial number", "full id", "model",
                                                     "raw data", "sensor value", "sensor unit", "station name")}
    shown = {"device time (utc)": "Device Time (UTC)", "serial number": "Serial Number", "full id": "Full ID"}
    missing = [shown[key] for key in shown if index[key] is None]
    if missing:
        raise ModelError(f"{what}: {name!r}: Fathom's {header[0] or 'DET_DESC'} line needs the columns Device Time "
                         f"(UTC), Serial Number and Full ID; {', '.join(missing)} missing, got {shown_header(header)}")
    time = utc_seconds(body[index["device time (utc)"]], f"{what}: {name!r}", lines, "Device Time (UTC)")
    serial = pattern(body[index["serial number"]], TAG_ID, what, name, lines, "Serial Number",
                     "a receiver's serial of 1 to 40 letters, digits, '.' or '_'")
    tag = pattern(body[index["full id"]], TRANSMITTER, what, name, lines, "Full ID",
                  "a transmitter's full ID CODESPACE-ID, e.g. A69-1602-4555")
    frame = pd.DataFrame({"receiver": serial.array, "tag": tag.array, "code_space": before_last_dash(tag).array,
                          "time": time})
    if index["sensor value"] is not None:
        frame["sensor_value"], frame["sensor_unit"] = sensor_columns(
            body, index["sensor value"], index["sensor unit"], header, lines, name, what)
    else:  # format 2's DET: a sensor tag's raw value
        frame["sensor_value"], _ = sensor_columns(body, index["raw data"], None, header, lines, name, what)
        frame["sensor_unit"] = np.where(np.isfinite(frame["sensor_value"].to_numpy(float)), "raw", "")
    frame["receiver_model"] = "" if index["model"] is None else trimmed(body[index["model"]], 40)
    if index["station name"] is not None:
        frame["station"] = trimmed(body[index["station name"]], 80)
    return frame, {k for k in index.values() if k is not None} | {0}


def fathom(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
           ) -> tuple[pd.DataFrame, set[int]]:
    """Fathom's ``DET`` records (and ``DET_SENS``: the module docstring) as detections, in the file's order, with
    their lines in the file (``line``)."""
    frame, used = _fathom_table(header, body, lines, name, what)
    frame["line"] = lines
    sensors = body.attrs.get("sensors")
    if sensors is not None and len(sensors[1]):  # (an empty table's merge would make the columns objects)
        extra, _ = _fathom_table(*sensors, name, what)
        extra["line"] = sensors[2]
        keys = ["time", "receiver", "tag"]
        both = frame.reset_index().merge(extra[keys + ["sensor_value", "sensor_unit"]], on=keys, how="inner",
                                         suffixes=("", "_sens")).drop_duplicates("index")
        at = both["index"].to_numpy()
        frame.loc[at, "sensor_value"] = both["sensor_value_sens"].to_numpy()
        frame.loc[at, "sensor_unit"] = both["sensor_unit_sens"].to_numpy()
        alone = extra.merge(frame[keys], on=keys, how="left", indicator=True)
        alone = alone[alone["_merge"] == "left_only"].drop(columns="_merge")
        alone = alone.assign(**{c: "" for c in frame.columns if c not in alone})  # a station DET_SENS lacks: none
        frame = pd.concat([frame, alone], ignore_index=True).sort_values("line", kind="stable")
    return frame.reset_index(drop=True), used


__all__ = ["FATHOM_MARK", "FATHOM_RECORDS", "fathom", "fathom_records", "fathom_tables"]
