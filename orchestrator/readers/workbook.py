"""A tag sheet delivered as a workbook (``.xls`` or ``.xlsx``), read as hostile input into the text cells of one
sheet, its header row found, for :func:`~sblsim.orchestrator.readers.tag_sheet.read_tag_sheet` to check cell by cell.

Three layouts, each told by its header (searched in a sheet's first :data:`HEADER_ROWS` rows: a vendor's title may
stand above it), the sheets ``Tag Summary`` and ``Tag Metadata`` searched first:

* **Innovasea's (Vemco's) tag specifications**, the workbook a tag order is delivered with (sheet ``Tag Summary``;
  its columns as glatos's ``vemco_tag_spec_schema`` lists them): ``VUE Tag ID`` (the full ID; a tag of two IDs, a
  sensor tag's, has a row per ID), the programme's four steps ``Step N Status`` (``ON``/``OFF``), ``Step N Min Delay
  (sec)`` and ``Step N Max Delay (sec)``, and the sensor's ``Sensor type``, ``Units``, ``Slope``, ``Intercept``. A tag
  pings at a random interval between a step's delays while that step runs, step after step: the interval stated is
  the bounds every step that is ``ON`` keeps, the least of their ``Min Delay`` to the greatest of their ``Max
  Delay`` (the first step's alone where it is the only one ON, as it most often is). A step's delays are each in
  [0.1, 86400] s and its ``Min Delay`` at most its ``Max Delay``; a depth sensor's ``Units`` is metres.
* **OTN's tagging metadata** (sheet ``Tag Metadata``, OTN's template ``version 4.1``, the header under a title):
  ``TAG_CODE_SPACE`` and ``TAG_ID_CODE`` (the full ID: ``A69-9001`` and ``24403``), ``ANIMAL_ID`` (the tag's name);
  a row whose ``TAG_TYPE`` is not acoustic (a satellite, PIT or ID tag) is not a transmitter and is skipped.
* Any other sheet whose header names a transmitter column as a CSV tag sheet does: read as that sheet.

A file is refused before it is opened where it is larger than :data:`MAX_WORKBOOK_BYTES`; an ``.xlsx`` (a zip
archive) where it holds more than :data:`MAX_MEMBERS` parts or its parts' uncompressed sizes add up to more than
:data:`MAX_UNPACKED_BYTES` (a zip bomb: Python's zip reader stops each part at its stated size), or its parts hold
more than :data:`MAX_ELEMENTS` XML elements (counted as they unpack, before a library parses one). Only a sheet's first
:data:`MAX_COLUMNS` columns and its first rows (a header and the tags) are read. Formulas are never evaluated: a
formula cell is the value the workbook last saved for it (openpyxl's ``data_only``, xlrd's cell values), empty where
none was saved; macros are never run. A number is its shortest text (``24403.0`` is ``24403``), a date ISO 8601.
Refusals are one line naming the file, the sheet, its row (as a spreadsheet numbers it, from 1) and column
(:func:`located`).
"""

from __future__ import annotations

import io
import math
import warnings
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import date, datetime, time, timedelta
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.tables import regular_file
from sblsim.orchestrator.readers.burst_sequence import BURST_RANGE
from sblsim.orchestrator.readers.cells import normal_name, numbers, pattern, refuse
from sblsim.orchestrator.readers.transmitters import CODE_SPACE, TAG_ID

#: The largest workbook read [bytes] (a tag order's is tens of KiB, OTN's template under 1 MiB): an .xls of as many
#: bytes holds at most about 1.5 million cells, which xlrd builds in about 100 MiB.
MAX_WORKBOOK_BYTES = 8 * 2**20
#: The most parts an .xlsx holds, the most bytes its parts unpack to [bytes] and the most XML elements they hold, in
#: all [1] (a cell is one or two: ``<c r="A1"><v>40</v></c>``; Innovasea's 44 columns of 5,000 tags fit): openpyxl
#: builds a row's cells at once, about 300 bytes a cell, so a row of half a million empty cells took 170 MiB.
MAX_MEMBERS = 1000
MAX_UNPACKED_BYTES = 64 * 2**20
MAX_ELEMENTS = 2**19
#: The columns of a sheet read, and the rows its header is searched in.
MAX_COLUMNS = 256
HEADER_ROWS = 30
#: The most sheets searched for a header.
MAX_SHEETS = 50
#: The sheets searched first (their names, case and spaces ignored), by layout.
SHEETS = {"tag summary": "innovasea", "tag metadata": "otn"}
#: The steps of an Innovasea tag's programme.
STEPS = 4
#: The values of a step's ``Status`` (case ignored; empty: a step without one).
STATUS = ("on", "off")


@dataclass
class SheetTable:
    """One sheet of a workbook as text cells.

    Attributes
    ----------
    sheet : str
        The sheet's name.
    layout : str
        ``"innovasea"``, ``"otn"`` or ``"plain"`` (the module docstring).
    header : list of str
        The header row's names (stripped); columns the reader adds (an Innovasea tag's delays over its steps, an OTN
        tag's full ID) last.
    body : pandas.DataFrame
        The rows under the header, blank rows dropped, every cell a str.
    lines : list of int
        Each row's number in the sheet (from 1, as a spreadsheet shows it).
    index : dict or None
        The tag sheet's fields (``transmitter``, ``min_delay``, ``max_delay``, ``sensor_type``, ``unit``, ``slope``,
        ``intercept``, ``name``) to their columns, for a vendor's layout (a field not in it is not read); None for a
        sheet read by the tag sheet's column names.
    """

    sheet: str
    layout: str
    header: list[str]
    body: pd.DataFrame
    lines: list[int]
    index: dict[str, int | None] | None


def _text(value: object) -> str:
    """A cell's value as the text a CSV cell would hold."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        return str(int(value)) if math.isfinite(value) and value.is_integer() and abs(value) < 2**53 else repr(value)
    if isinstance(value, (datetime, date, time)):
        return value.isoformat()
    if isinstance(value, timedelta):
        return repr(value.total_seconds())
    return str(value)


@contextmanager
def located(name: str, sheet: str) -> Iterator[None]:
    """Refusals raised inside naming a row of the sheet: ``'FILE' line N`` said ``'FILE' sheet 'S' row N``."""
    try:
        yield
    except ModelError as exc:
        text = str(exc).replace(f"{name!r} line ", f"{name!r} sheet {sheet!r} row ", 1)
        raise ModelError(text) from None


def _bytes(path: Path, what: str) -> bytes:
    name = str(path)
    size = regular_file(path, what)
    if size > MAX_WORKBOOK_BYTES:
        raise ModelError(f"{what}: {name!r} is {size / 2**20:.0f} MiB; allowed at most "
                         f"{MAX_WORKBOOK_BYTES // 2**20} MiB for a workbook")
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_WORKBOOK_BYTES + 1)
    except OSError as exc:
        raise ModelError(f"{what}: {name!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    if len(data) > MAX_WORKBOOK_BYTES:
        raise ModelError(f"{what}: {name!r} is more than {MAX_WORKBOOK_BYTES // 2**20} MiB; allowed at most that for "
                         "a workbook")
    return data


def _unreadable(name: str, what: str, kind: str, exc: Exception) -> ModelError:
    reason = " ".join(str(exc).split())[:120] or type(exc).__name__
    return ModelError(f"{what}: {name!r} is not a readable .{kind} workbook ({reason}); allowed: an .xls or .xlsx "
                      "workbook, or CSV text")


def _ordered(titles: list[str]) -> list[str]:
    """A workbook's sheets in the order they are searched: those named in :data:`SHEETS` first, at most
    :data:`MAX_SHEETS`."""
    return sorted(titles, key=lambda t: " ".join(t.lower().split()) not in SHEETS)[:MAX_SHEETS]


def _guarded(rows: Iterator[list[str]], name: str, what: str, kind: str) -> Iterator[list[str]]:
    """A sheet's rows, a library's error while parsing them refused in one line."""
    try:
        yield from rows
    except Exception as exc:  # a damaged part: the libraries' many error types
        raise _unreadable(name, what, kind, exc) from None


def _elements(data: bytes, name: str, what: str) -> int:
    """The XML elements of an .xlsx's parts, in all (its ``<`` less its ``</``, comments counted too), counted as
    they unpack, a MiB at a time (each part stops at its stated size: a part whose data says otherwise fails its
    checksum and is refused)."""
    count = 0
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            for member in archive.infolist():
                with archive.open(member) as part:
                    last = b""
                    while chunk := part.read(2**20):
                        count += chunk.count(b"<") - chunk.count(b"</") - (last == b"<" and chunk[:1] == b"/")
                        last = chunk[-1:]
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, NotImplementedError, RuntimeError) as exc:
        raise _unreadable(name, what, "xlsx", exc) from None
    return count


def _xlsx_sheets(data: bytes, name: str, what: str, rows: int) -> Iterator[tuple[str, Iterator[list[str]]]]:
    """An .xlsx's sheets, each its name and its rows (lists of text cells), its parts' sizes checked first."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            members = archive.infolist()
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise _unreadable(name, what, "xlsx", exc) from None
    unpacked = sum(m.file_size for m in members)
    if len(members) > MAX_MEMBERS or unpacked > MAX_UNPACKED_BYTES:
        raise ModelError(f"{what}: {name!r} holds {len(members):,} parts unpacking to {unpacked / 2**20:,.0f} MiB; "
                         f"allowed at most {MAX_MEMBERS:,} parts and {MAX_UNPACKED_BYTES // 2**20} MiB unpacked")
    elements = _elements(data, name, what)
    if elements > MAX_ELEMENTS:
        raise ModelError(f"{what}: {name!r} holds {elements:,} XML elements (cells, strings, styles); allowed at most "
                         f"{MAX_ELEMENTS:,} in a workbook")
    import openpyxl  # a workbook's library loaded when a workbook is read (0.3 s of every study's start else)

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # openpyxl's notes on features it skips (data validation, styles)
            book = openpyxl.load_workbook(io.BytesIO(data), read_only=True, data_only=True, keep_links=False)
    except Exception as exc:  # a damaged archive or part: openpyxl's many error types
        raise _unreadable(name, what, "xlsx", exc) from None
    try:
        for title in _ordered(book.sheetnames):
            sheet = book[title]
            if hasattr(sheet, "iter_rows"):  # not a chart sheet
                cells = sheet.iter_rows(min_row=1, max_row=rows, max_col=MAX_COLUMNS, values_only=True)
                yield title, _guarded(([_text(v) for v in row] for row in cells), name, what, "xlsx")
    finally:
        book.close()


def _xls_sheets(data: bytes, name: str, what: str, rows: int) -> Iterator[tuple[str, Iterator[list[str]]]]:
    """An .xls's sheets, each its name and its rows (lists of text cells), each sheet parsed when it is reached."""
    import xlrd

    try:
        book = xlrd.open_workbook(file_contents=data, on_demand=True, logfile=io.StringIO(), verbosity=0)
    except Exception as exc:  # xlrd's errors, and a damaged file's struct or index errors
        raise _unreadable(name, what, "xls", exc) from None

    def cell(c) -> str:  # an xlrd.sheet.Cell
        if c.ctype == xlrd.XL_CELL_DATE:
            try:
                return xlrd.xldate.xldate_as_datetime(c.value, book.datemode).isoformat()
            except (ValueError, OverflowError, xlrd.xldate.XLDateError):
                return _text(c.value)
        if c.ctype == xlrd.XL_CELL_BOOLEAN:
            return "TRUE" if c.value else "FALSE"
        if c.ctype == xlrd.XL_CELL_ERROR:
            return xlrd.error_text_from_code.get(c.value, "#ERROR")
        return _text(c.value)

    def sheet_rows(sheet) -> Iterator[list[str]]:  # an xlrd.sheet.Sheet
        for r in range(min(sheet.nrows, rows)):
            yield [cell(c) for c in sheet.row_slice(r, 0, min(sheet.row_len(r), MAX_COLUMNS))]

    try:
        for title in _ordered(book.sheet_names()):
            try:
                sheet = book.sheet_by_name(title)
            except Exception as exc:
                raise _unreadable(name, what, "xls", exc) from None
            yield title, _guarded(sheet_rows(sheet), name, what, "xls")
            book.unload_sheet(title)
    finally:
        book.release_resources()


def _layout(names: list[str], plain: tuple[str, ...]) -> str | None:
    """The layout a header row's normalised names show, None for none."""
    if "vue_tag_id" in names:
        return "innovasea"
    if {"tag_code_space", "tag_id_code"} <= set(names):
        return "otn"
    if any(n in names for n in plain):
        return "plain"
    return None


def read_workbook(path: Path | str, kind: str, what: str, plain: tuple[str, ...], max_rows: int) -> SheetTable:
    """The sheet of a workbook that holds a tag sheet (the module docstring), as text cells.

    Parameters
    ----------
    path : str or Path
        The workbook.
    kind : str
        ``"xls"`` or ``"xlsx"`` (:func:`~sblsim.orchestrator.readers.binary.kind_of`).
    what : str
        What the file is, as a refusal names it (``"tags"``).
    plain : tuple of str
        The normalised names of a tag sheet's transmitter column (a sheet in the CSV layout).
    max_rows : int
        The most rows under the header [1].

    Returns
    -------
    SheetTable

    Raises
    ------
    ModelError
        One line: a file too large or unpacking too large, a file neither library can read, no sheet with a tag
        sheet's header in its first :data:`HEADER_ROWS` rows (the sheets named), more than ``max_rows`` rows, a
        column named twice, a step's delays or status, an OTN tag's code space or id (naming the sheet, the row
        and the column).
    """
    path = Path(path)
    name = str(path)
    data = _bytes(path, what)
    limit = HEADER_ROWS + max_rows + 1
    sheets = (_xlsx_sheets if kind == "xlsx" else _xls_sheets)(data, name, what, limit)
    try:
        return _sheet_table(sheets, name, what, plain, max_rows)
    finally:
        sheets.close()


def _sheet_table(sheets: Iterator[tuple[str, Iterator[list[str]]]], name: str, what: str, plain: tuple[str, ...],
                 max_rows: int) -> SheetTable:
    """The first sheet (in the order searched) whose first rows hold a tag sheet's header, read."""
    seen, found = [], None
    for title, rows in sheets:
        seen.append(title)
        for number, row in enumerate(rows, 1):
            layout = _layout([normal_name(c) for c in row], plain)
            if layout is not None:
                found = title, layout, number, row, rows
                break
            if number >= HEADER_ROWS:
                break
        if found is not None:
            break
    if found is None:
        raise ModelError(f"{what}: {name!r}: no sheet holds a tag sheet's header in its first {HEADER_ROWS} rows "
                         "(Innovasea's VUE Tag ID; OTN's TAG_CODE_SPACE and TAG_ID_CODE; a transmitter column); "
                         f"its sheets: {', '.join(repr(s[:31]) for s in seen[:8]) or 'none'}")
    title, layout, number, header_row, rows = found
    header = [h.strip() for h in header_row]
    while header and not header[-1]:
        header.pop()
    body, lines = [], []
    with located(name, title):
        lower = [h.lower() for h in header]
        twice = next((h for h, low in zip(header, lower) if low and lower.count(low) > 1), None)
        if twice is not None:
            raise ModelError(f"{what}: {name!r} line {number}: the column {twice[:40]!r} is given twice in the header")
        for line, row in enumerate(rows, number + 1):
            cells = (row + [""] * len(header))[:len(header)]
            if any(c.strip() for c in cells):
                if len(body) == max_rows:
                    raise ModelError(f"{what}: {name!r} line {line}: more than {max_rows:,} rows under the header; "
                                     f"allowed at most {max_rows:,} tags")
                body.append(cells)
                lines.append(line)
        frame = pd.DataFrame(body, columns=range(len(header)), dtype=object) if body else \
            pd.DataFrame(columns=range(len(header)), dtype=object)
        index = None
        if layout == "innovasea":
            index = _innovasea(header, frame, lines, number, name, what)
        elif layout == "otn":
            frame, lines, index = _otn(header, frame, lines, name, what)
    return SheetTable(title, layout, header, frame, lines, index)


def _innovasea(header: list[str], body: pd.DataFrame, lines: list[int], header_line: int, name: str, what: str
               ) -> dict:
    """Innovasea's columns: the delays over the steps that are ON (two columns added to ``header`` and ``body``)."""
    normal = [normal_name(h) for h in header]

    def at(key: str) -> int | None:
        return normal.index(key) if key in normal else None

    least = np.full(len(body), np.inf)
    most = np.full(len(body), -np.inf)
    for step in range(1, STEPS + 1):
        state, low, high = (at(f"step_{step}_{k}") for k in ("status", "min_delay", "max_delay"))
        if low is None and high is None:
            continue
        if low is None or high is None:
            raise ModelError(f"{what}: {name!r} line {header_line}: step {step} has a "
                             f"{header[low if high is None else high]!r} column and no "
                             f"{'Max' if high is None else 'Min'} Delay; allowed: both delays of a step, or neither")
        on = np.ones(len(body), bool)
        if state is not None:
            cells = body[state].astype(str).str.strip().str.lower()
            bad = ~cells.isin(STATUS + ("",))
            if bad.any():
                k = int(np.flatnonzero(bad.to_numpy())[0])
                raise refuse(what, name, lines[k], header[state], body.iloc[k, state], "ON, OFF or empty")
            on = (cells == "on").to_numpy()
        delays = [numbers(body[c], what, name, lines, header[c], *BURST_RANGE, missing=True, unit="s")
                  for c in (low, high)]
        given = np.isfinite(delays[0]) | np.isfinite(delays[1])
        for k in np.flatnonzero(on & given):
            if not (np.isfinite(delays[0][k]) and np.isfinite(delays[1][k])):
                column = header[low if np.isnan(delays[0][k]) else high]
                raise ModelError(f"{what}: {name!r} line {lines[k]} column {column}: empty in a step that is ON; "
                                 "allowed: both delays [s] of a step that is ON")
            if delays[0][k] > delays[1][k]:
                raise ModelError(f"{what}: {name!r} line {lines[k]}: step {step}'s Min Delay {delays[0][k]:g} s is "
                                 f"more than its Max Delay {delays[1][k]:g} s; allowed: Min Delay <= Max Delay")
            least[k] = min(least[k], delays[0][k])
            most[k] = max(most[k], delays[1][k])
    stated = np.isfinite(least)
    for label, values in (("Min Delay (steps ON)", least), ("Max Delay (steps ON)", most)):
        body[len(header)] = [repr(float(v)) if ok else "" for v, ok in zip(values, stated)]
        header.append(label)
    return {"transmitter": at("vue_tag_id"), "min_delay": len(header) - 2, "max_delay": len(header) - 1,
            "sensor_type": at("sensor_type"), "unit": at("units"), "slope": at("slope"),
            "intercept": at("intercept")}


def _otn(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
         ) -> tuple[pd.DataFrame, list[int], dict]:
    """OTN's tagging metadata: the acoustic tags' rows, their full IDs a column added to ``header`` and ``body``."""
    normal = [normal_name(h) for h in header]
    space_at, ident_at = normal.index("tag_code_space"), normal.index("tag_id_code")
    if "tag_type" in normal:
        kind = body[normal.index("tag_type")].astype(str).str.strip().str.lower()
        keep = ((kind == "") | kind.str.contains("acoustic", regex=False)).to_numpy()
        body, lines = body[keep].reset_index(drop=True), [n for n, k in zip(lines, keep) if k]
    space = pattern(body[space_at], CODE_SPACE, what, name, lines, header[space_at], "a code space, e.g. A69-9001")
    ident = pattern(body[ident_at], TAG_ID, what, name, lines, header[ident_at], "a transmitter's id, e.g. 24403")
    body[len(header)] = (space + "-" + ident).to_numpy()
    header.append("full ID (TAG_CODE_SPACE-TAG_ID_CODE)")
    return body, lines, {"transmitter": len(header) - 1, "name": normal.index("animal_id") if "animal_id" in normal
                         else None}


__all__ = ["HEADER_ROWS", "MAX_COLUMNS", "MAX_ELEMENTS", "MAX_MEMBERS", "MAX_SHEETS", "MAX_UNPACKED_BYTES",
           "MAX_WORKBOOK_BYTES", "SHEETS", "STATUS", "STEPS", "SheetTable", "located", "read_workbook"]
