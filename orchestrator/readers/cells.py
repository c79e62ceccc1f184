"""The text of a telemetry table read as hostile input, and its cells checked: what every reader of raw detections,
receivers, deployments, tag sheets and sound-speed series shares.

A file must be a regular file (a FIFO or a device is refused before it is opened), is read to at most a stated
number of bytes and rows (counted in what was read), must be UTF-8 text (a byte-order mark is dropped) without a NUL
byte (a spreadsheet's UTF-16 named as such), not cut short (:func:`cut_short`), and is refused before pandas builds
a cell where a line is longer than 1 MiB or holds more than :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS`
cells, or the table more than a stated number of cells in all (:func:`~sblsim.orchestrator.io.tables.check_cells`:
its rows times its first row's cells, as pandas pads a short row); it is then parsed by pandas into text cells (from
the text's UTF-8 bytes a piece at a time, not a copy of it whole; a header of one cell of columns separated by
semicolons or tabs named as such), every one of which the reader then checks itself (its pattern, finite, within its
range); no name or text in a file is ever taken as a path. Every error is one line naming the file, its line and
column and the allowed range (:class:`ModelError`).
"""

from __future__ import annotations

import csv
import io
import re
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io import tables
from sblsim.orchestrator.io.tables import MAX_LINE_BYTES, NUMBER, check_cells, read_bounded
from sblsim.orchestrator.readers.binary import archive_error, archive_kind, archive_stream, not_text, refuse_log
from sblsim.orchestrator.readers.limits import MAX_DETECTION_BYTES

#: The separators a spreadsheet saves a table with other than the comma, as a refusal names them.
SEPARATORS = {";": "semicolons (as a spreadsheet in a decimal-comma locale saves CSV)", "\t": "tabs"}
#: The options every table is parsed with (each cell a str, none taken as missing; blank lines kept as rows).
_CSV = dict(header=None, dtype=str, keep_default_na=False, na_filter=False, skip_blank_lines=False, engine="c",
            quotechar='"', on_bad_lines="error")


def too_large(name: str, what: str, amount: str, max_bytes: int, rows: int, hint: str = "") -> ModelError:
    return ModelError(f"{what}: {name!r} {amount}; allowed at most {max_bytes // 2**20} MiB and {rows:,} rows{hint}")


def read_text(path: Path, what: str, max_bytes: int, max_rows: int, prefix: int | None = None, *,
              max_cells: int | None = None, max_line_cells: int | None = None, fallback: str | None = None,
              hint: str = "", archives: bool = False) -> str:
    """A regular file's text, refused before it is read whole when it is larger than ``max_bytes`` or holds more
    than ``max_rows`` lines and 1,000 besides, and before it is decoded when a line is longer than
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_BYTES` or holds more than ``max_line_cells`` cells (its commas and
    one), or its lines more than ``max_cells`` cells in all (:func:`~sblsim.orchestrator.io.tables.check_cells`);
    UTF-8 (a byte-order mark dropped), no NUL byte; a receiver's binary log (VRL, VDAT: :mod:`.binary`) refused
    first, by its extension or first bytes, in a line naming its CSV export. With ``prefix``, only the file's first
    ``prefix`` bytes (a character cut at the end dropped), its size not checked, its lines' cells checked. With
    ``fallback`` (an
    encoding: ``"latin-1"``, as Windows exports write a ``°``), a text that is not UTF-8 is decoded in it instead.

    Parameters
    ----------
    max_bytes, max_rows : int
        The file's limits [bytes], [1].
    max_cells, max_line_cells : int, optional
        The most cells the table and one of its lines hold [1]; default
        :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`, :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS`.
    fallback : str, optional
        The encoding a text that is not UTF-8 is read in (one that decodes every byte, ``"latin-1"``); default
        none: such a text refused.
    hint : str
        Said after the refusal of a file too large (what to do with a larger one).
    archives : bool
        Read the one CSV a zip or gzip archive holds (:func:`~.binary.archive_stream`: decompressed to the same
        bounds, nothing written), where the file is one; else an archive is refused as not text.

    Raises
    ------
    ModelError
        One line naming the file and the limit or the fault (with the count: the bytes, lines or cells).
    """
    name = str(path)
    refuse_log(Path(path), what)  # a receiver's binary log: named, with the export that makes its CSV

    def whole(stream=None) -> bytes:  # the text to its bounds (of the file, or of the stream an archive holds)
        return read_bounded(path, what, max_bytes, max_rows + 1000,
                            lambda name, what, amount: too_large(name, what, amount, max_bytes, max_rows, hint),
                            max_line_cells=max_line_cells, max_cells=max_cells, stream=stream)

    if archives and archive_kind(Path(path)) is not None:  # a zipped (gzipped) CSV, read as it decompresses
        data = _archived(Path(path), what, prefix, whole)
    elif prefix is not None:
        try:
            with open(path, "rb") as handle:
                data = handle.read(prefix)
        except OSError as exc:
            raise ModelError(f"{what}: {name!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    else:
        data = whole()
    nul = data.find(b"\0")
    if nul >= 0:
        raise not_text(name, what, data, nul)
    if prefix is not None:
        check_cells(data, name, what, max_line_cells=max_line_cells, max_cells=max_cells)
        if len(data) == prefix:
            return data.decode("utf-8-sig", errors="ignore")
    return _decoded(data, name, what, fallback)


def _archived(path: Path, what: str, prefix: int | None, whole) -> bytes:
    """:func:`read_text`'s bytes of the CSV an archive holds: its first ``prefix`` bytes, or ``whole(stream)`` (its
    text to the file's bounds)."""
    with archive_stream(path, what) as stream:
        try:
            return stream.read(prefix) if prefix is not None else whole(stream)
        except (OSError, EOFError, zlib.error, zipfile.BadZipFile) as exc:  # a damaged stream, a checksum
            raise archive_error(str(path), what, exc) from None


#: The characters of a text's end :func:`cut_short` reads: two of its longest lines.
TAIL_CHARS = 2 * MAX_LINE_BYTES


def cut_short(text: str, name: str, what: str, by_record: bool = False, whole: bool = True) -> None:
    """Refuse a CSV text cut short (an export, a download or a copy interrupted): it ends without a line break and
    its last record holds fewer cells than the record before it (Python's :mod:`csv` reads the records, a quoted cell
    across lines one record; ``by_record``: than the last record before it whose first cell is the same, a Fathom
    CSV's record type, or, a record of one cell (cut inside its type), than the one before it). A text that ends in
    a line break, or whose last record holds as many cells, passes (a file cut at a line's end, or inside a line's
    last cell, cannot be told from a whole one).

    Parameters
    ----------
    text : str
        The text (only its last :data:`TAIL_CHARS` characters are read, from the first line that starts in them).
    name, what : str
        The file's name and what it is, for the refusal.
    by_record : bool
        Records of several types, each of its own width (Fathom's).
    whole : bool
        ``text`` begins where the file does (false: its first line may be cut where it begins, and is not read).

    Raises
    ------
    ModelError
        One line naming the file, the two records' cells and what to do.
    """
    if not text or text.endswith(("\n", "\r")):
        return
    tail = text[-TAIL_CHARS:]
    if not whole or len(tail) < len(text):  # from the first line that starts in it
        tail = tail[min((k for k in (tail.find("\n"), tail.find("\r")) if k >= 0), default=len(tail)) + 1:]
    try:
        records = [r for r in csv.reader(io.StringIO(tail, newline="")) if any(c.strip() for c in r)]
    except csv.Error:  # a cell beyond csv's field limit: not judged here (the table's own reading bounds it)
        return
    if len(records) < 2:
        return
    last = records[-1]
    # by record type: the last record before it of its type, else (a cut inside its first cell) any record before it
    before = next((r for r in reversed(records[:-1]) if not by_record or r[:1] == last[:1]),
                  records[-2] if len(last) == 1 else last)
    if len(last) < len(before):
        raise ModelError(f"{what}: {name!r}: its last line ends without a line break and holds {len(last)} cells "
                         f"where the line before holds {len(before)}: the file is cut short (an export, download or "
                         "copy interrupted); allowed: whole lines (export it again, or delete the cut line)")


def tail_text(path: Path, size: int = TAIL_CHARS) -> tuple[str, bool]:
    """A file's last ``size`` bytes as text (UTF-8, else Latin-1; a character cut where they begin replaced), and
    whether they are the whole file (:func:`cut_short`'s ``whole``)."""
    with open(path, "rb") as handle:
        handle.seek(0, io.SEEK_END)
        end = handle.tell()
        handle.seek(max(0, end - size))
        data = handle.read(size)
    try:
        return data.decode("utf-8"), end <= size
    except UnicodeDecodeError:
        return (data.decode("utf-8", errors="replace") if end > size else data.decode("latin-1")), end <= size


def _decoded(data: bytes, name: str, what: str, fallback: str | None = None) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        if fallback is not None:
            return data.decode(fallback)
        raise ModelError(f"{what}: {name!r} is not UTF-8 text (byte {exc.start})") from None


class _Utf8(io.RawIOBase):
    """A text read as its UTF-8 bytes, ``piece`` characters at a time (default
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_BYTES`): pandas parses the table of a text without a copy of it
    (``io.StringIO`` holds up to four bytes a character, ``encode`` the whole text one more copy): ``sblsim track``
    on a detections file of 2^25 cells of two characters peaked at 1.07 GiB with ``io.StringIO``, 0.76 GiB so."""

    def __init__(self, text: str, piece: int = MAX_LINE_BYTES):
        super().__init__()
        self._text, self._at, self._size, self._piece, self._used = text, 0, piece, b"", 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        if self._used == len(self._piece):
            if self._at >= len(self._text):
                return 0
            self._piece, self._used = self._text[self._at:self._at + self._size].encode("utf-8"), 0
            self._at += self._size
        n = min(len(buffer), len(self._piece) - self._used)
        buffer[:n] = self._piece[self._used:self._used + n]
        self._used += n
        return n


def _width(text: str, name: str, what: str) -> int | None:
    """The cells of a text's first row as pandas parses it, from at most its first 2 MiB (a quoted cell may span
    lines); None where pandas finds no row there (the whole text's parse then says why)."""
    head = text[:2 * MAX_LINE_BYTES]
    try:
        return pd.read_csv(io.StringIO(head), nrows=1, **_CSV).shape[1]
    except Exception as exc:
        if len(head) < len(text) and "EOF inside string" in str(exc):
            raise ModelError(f"{what}: {name!r}: its first row does not end in its first {len(head):,} characters (a "
                             "quoted cell spanning lines); allowed: a header line") from None
        return None


def _spanned(frame: pd.DataFrame, text: str) -> np.ndarray | int:
    """The lines before each row of ``frame`` that quoted cells spanning lines took (a legal line break inside a
    quoted cell): 0 where the text has as many line breaks as rows (none spans), else per row the line breaks in the
    cells of the rows before it, so that a row's line is the file's line, as an editor numbers it."""
    breaks = text.count("\n") + text.count("\r") - text.count("\r\n")
    if breaks <= len(frame):  # one line break a row at most: none inside a cell
        return 0
    inside = np.zeros(len(frame), np.int64)
    for k in frame.columns:
        cells = frame[k]
        inside += (cells.str.count("\r\n|\r|\n")).to_numpy(np.int64)
    return np.concatenate([[0], np.cumsum(inside)[:-1]])


def text_table(text: str, name: str, what: str, max_rows: int, first_line: int = 1, *, max_cells: int | None = None,
               max_line_cells: int | None = None) -> tuple[list[str], pd.DataFrame, list[int]]:
    """A CSV text's header (stripped) and its rows as text cells (pandas, every cell a str; a short row padded with
    empty cells), with each row's line in the file (``first_line``: the header's); blank lines skipped.

    Before pandas parses the text whole, its first row's cells are counted (pandas on at most its first 2 MiB) and the
    table's, its lines times those (pandas pads a short row to the first's and refuses a longer one): a text whose
    first row holds more than ``max_line_cells`` cells, or whose table would hold more than ``max_cells``, is refused
    (default :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS`, :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`;
    the text's lines themselves are counted by :func:`read_text`).

    Raises
    ------
    ModelError
        One line: a text pandas cannot parse (a row longer than the header), no header, a column named twice, more
        than ``max_rows`` rows, a first row or a table of too many cells (naming the limit and the count).
    """
    max_line_cells = tables.MAX_LINE_CELLS if max_line_cells is None else max_line_cells
    max_cells = tables.MAX_CELLS if max_cells is None else max_cells
    width = _width(text, name, what)
    if width is not None:
        rows = text.count("\n") + text.count("\r") - text.count("\r\n") + (not text.endswith(("\n", "\r")))
        if width > max_line_cells:
            raise ModelError(f"{what}: {name!r}: its first row holds {width:,} cells; allowed at most "
                             f"{max_line_cells:,} cells a row")
        if rows * width > max_cells:
            raise ModelError(f"{what}: {name!r} holds {rows:,} lines of {width:,} cells (its first row's: a shorter "
                             f"row is padded); allowed at most {max_cells:,} cells in a table")
    try:
        frame = pd.read_csv(io.BufferedReader(_Utf8(text)), encoding="utf-8", **_CSV)
    except pd.errors.EmptyDataError:
        raise ModelError(f"{what}: {name!r} is empty; allowed: a header line and rows") from None
    except Exception as exc:  # pandas' parser errors name the line
        raise ModelError(f"{what}: {name!r} does not parse as CSV ({' '.join(str(exc).split())[:160]})") from None
    blank = np.ones(len(frame), bool)
    for k in frame.columns:  # column by column: no copy of the whole table
        blank &= (frame[k].str.strip() == "").to_numpy(bool)
    lines = (np.arange(len(frame)) + first_line + _spanned(frame, text))[~blank]
    if blank.any():
        frame = frame[~blank]
    if not len(frame):
        raise ModelError(f"{what}: {name!r} holds no header; allowed: a header line and rows")
    header = [str(h).strip() for h in frame.iloc[0].tolist()]
    separated = next((sep for sep in SEPARATORS if len(header) == 1 and sep in header[0]), None)
    if separated is not None:  # one cell holding the columns: another separator than the comma
        raise ModelError(f"{what}: {name!r}: its header is one cell of columns separated by {SEPARATORS[separated]}; "
                         "allowed: comma-separated values (save it as CSV with commas and decimal points)")
    lower = [h.lower() for h in header]
    twice = next((h for h, low in zip(header, lower) if low and lower.count(low) > 1), None)
    if twice is not None:
        raise ModelError(f"{what}: {name!r}: the column {twice[:40]!r} is given twice in the header")
    body = frame.iloc[1:].reset_index(drop=True)
    if len(body) > max_rows:
        raise too_large(name, what, f"has {len(body):,} rows", 2**62, max_rows)
    body.columns = range(body.shape[1])
    return header, body, lines[1:].tolist()


def file_table(path: Path | str, what: str, max_rows: int, max_bytes: int = MAX_DETECTION_BYTES, *,
               fallback: str | None = None) -> tuple[list[str], pd.DataFrame, list[int]]:
    """A CSV file's header (stripped) and its rows as text cells, with each row's line in the file (1: the header);
    blank lines skipped: :func:`read_text` (at most ``max_bytes`` bytes and ``max_rows`` rows; ``fallback`` its
    encoding where not UTF-8), :func:`cut_short` and :func:`text_table`.

    Raises
    ------
    ModelError
        One line: each of theirs.
    """
    path = Path(path)
    text = read_text(path, what, max_bytes, max_rows, fallback=fallback)
    cut_short(text, str(path), what)
    return text_table(text, str(path), what, max_rows)


def refuse(what: str, name: str, line: int, column: str, text: str, allowed: str) -> ModelError:
    shown = text if len(text) <= 40 else text[:40] + "..."
    return ModelError(f"{what}: {name!r} line {line} column {column}: {shown!r} is not allowed; allowed: {allowed}")


def per_value(cells: pd.Series, function):
    """``function`` of a column (a map of each cell alone: a pattern's match, a part of the text) computed once for
    each distinct cell where they repeat (a detections file's receivers and transmitters: a few hundred names in a
    million rows), else over the column; the result in the column's order and index.

    Parameters
    ----------
    cells : pandas.Series
        (n,) the column.
    function : callable
        A Series of cells to a Series (or a DataFrame) of as many results, each of its cell alone.
    """
    codes, distinct = pd.factorize(cells, use_na_sentinel=False)
    if len(distinct) * 8 > len(cells):
        return function(cells)
    done = function(pd.Series(distinct, dtype=cells.dtype)).take(codes)
    done.index = cells.index
    return done


def trimmed(cells: pd.Series, most: int):
    """A column's cells stripped and cut to ``most`` characters (a receiver's model, a station's name), each distinct
    cell once (:func:`per_value`), as an array in the column's order."""
    return per_value(cells, lambda v: v.astype(str).str.strip().str.slice(0, most)).array


def pattern(values: pd.Series, regex: re.Pattern, what: str, name: str, lines: list[int], column: str,
            allowed: str) -> pd.Series:
    """The stripped cells of one column, each matching ``regex`` (else the first bad one refused); each distinct
    cell matched once (:func:`per_value`)."""
    def checked(v: pd.Series) -> pd.DataFrame:
        stripped = v.astype(str).str.strip()
        return pd.DataFrame({"cells": stripped, "ok": stripped.str.fullmatch(regex.pattern).fillna(False)})

    both = per_value(values, checked)
    cells, bad = both["cells"], ~both["ok"].to_numpy(bool)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise refuse(what, name, lines[k], column, cells.iloc[k], allowed)
    return cells


#: A whole number written as a decimal (``802357.0``): a spreadsheet's or pandas' number column with blank cells (a
#: float column) written to CSV.
DECIMAL_WHOLE = re.compile(r"[0-9]+\.0+")


def whole_ids(cells: pd.Series) -> tuple[pd.Series, int]:
    """An id column's cells with each whole number written as a decimal (:data:`DECIMAL_WHOLE`: ``802357.0``) read
    as the whole number (``802357``), and how many were.

    A sheet's column of sync tags or serials with blank cells is a float column to pandas and to a spreadsheet, which
    write ``802357.0`` where the receivers logged ``802357`` (no receiver logs an id of digits as a decimal). Every
    reader of an id (a sheet's and a detections table's) reads it so, so that the two still name one tag alike.

    Parameters
    ----------
    cells : pandas.Series
        (n,) the column's stripped cells (text).
    """
    decimal = per_value(cells, lambda v: v.str.fullmatch(DECIMAL_WHOLE.pattern).fillna(False)).to_numpy(bool)
    if not decimal.any():
        return cells, 0
    return cells.where(~decimal, cells.str.replace(r"\.0+$", "", regex=True)), int(decimal.sum())


def numbers(values: pd.Series, what: str, name: str, lines: list[int], column: str, low: float, high: float,
            high_open: bool = False, missing: bool = False, unit: str = "") -> np.ndarray:
    """The cells of one column as floats, each a number (:data:`NUMBER`), finite, in [low, high] (``[low, high)``
    with ``high_open``); empty cells NaN where ``missing``."""
    cells = values.astype(str).str.strip()
    empty = (cells == "").to_numpy(bool)
    if missing and empty.all():  # a column left empty (a VUE export's sensor value without sensor tags)
        return np.full(len(cells), np.nan)
    parsed = np.array(pd.to_numeric(cells.where(cells != "", "nan"), errors="coerce"), float)
    text_ok = cells.str.fullmatch(NUMBER.pattern).fillna(False).to_numpy(bool)
    inside = np.isfinite(parsed) & (parsed >= low) & ((parsed < high) if high_open else (parsed <= high))
    bad = ~((text_ok & inside) | (empty & missing))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        allowed = f"a finite number in [{low:g}, {high:g}{')' if high_open else ']'}{' ' + unit if unit else ''}" \
            + (" or empty" if missing else "")
        raise refuse(what, name, lines[k], column, cells.iloc[k], allowed)
    parsed[empty] = np.nan
    return parsed


def column(header: list[str], names: tuple[str, ...]) -> int | None:
    """The index of the first of ``names`` in the header (case ignored), None where none is there."""
    lower = [h.lower() for h in header]
    return next((lower.index(n) for n in names if n in lower), None)


def normal_name(text: str) -> str:
    """A header's name as the readers match it: lower case, a trailing unit or note in brackets dropped
    (``DEPLOY_DATE_TIME   (yyyy-mm-ddThh:mm:ss)``, ``depth [m]``), spaces, dashes and dots as one ``_``."""
    text = re.sub(r"\s*[\(\[][^\)\]]*[\)\]]\s*$", "", text.strip().lower())
    return re.sub(r"[\s\-.]+", "_", text).strip("_")


def named(header: list[str], names: tuple[str, ...]) -> int | None:
    """The index of the first of ``names`` among the header's :func:`normal_name` s, None where none is there."""
    normal = [normal_name(h) for h in header]
    return next((normal.index(n) for n in names if n in normal), None)


#: The units an ERDDAP-style table (OTN's receiver, tag and animal tables) states in the row under its header, by
#: the kind of column that holds them (CF / UDUNITS names, case ignored): what the readers read those columns in.
UNITS = {"latitude": ("degrees_north", "degree_north", "degree_n", "degrees_n"),
         "longitude": ("degrees_east", "degree_east", "degree_e", "degrees_e"),
         "time": ("utc", "seconds since 1970-01-01t00:00:00z"),
         "metres": ("m", "meter", "meters", "metre", "metres")}
#: A unit's name in such a row: words of letters, digits and ``_ / ^ . - *``, not a number.
UNIT_NAME = re.compile(r"[A-Za-z%\u00b0][A-Za-z0-9_/^.\-*%\u00b0:+ ]{0,59}")


def units_row(header: list[str], body: pd.DataFrame, lines: list[int], kinds: dict[int, str], name: str, what: str
              ) -> tuple[pd.DataFrame, list[int], int | None]:
    """The rows of a table without the units row an ERDDAP-style table has under its header (OTN's receiver, tag and
    animal tables: ``,,degrees_north,degrees_east,UTC,,m``), and that row's line (None where there is none).

    The first row is that units row where every cell it fills is a unit's name (:data:`UNIT_NAME`, not a number or
    a time) and one of them a position's or a time's (``degrees_north``, ``degrees_east``, ``UTC``: :data:`UNITS`);
    each column of ``kinds`` (its index: ``"latitude"``, ``"longitude"``, ``"time"``, ``"metres"``) the reader uses
    must then state one of its kind's units, or none.

    Raises
    ------
    ModelError
        A used column whose stated unit is not its kind's (one line naming the line, the column and the units read):
        its values are not converted.
    """
    if not len(body):
        return body, lines, None
    cells = body.iloc[0].astype(str).str.strip().str.lower()
    given = cells[cells != ""]
    strong = {u for kind in ("latitude", "longitude", "time") for u in UNITS[kind]}
    if not len(given) or not given.isin(strong).any() or \
            not given.str.fullmatch(UNIT_NAME.pattern).fillna(False).all():
        return body, lines, None
    for k, kind in kinds.items():
        if k < len(cells) and cells.iloc[k] and cells.iloc[k] not in UNITS[kind]:
            raise ModelError(f"{what}: {name!r} line {lines[0]} column {header[k]}: the units row gives "
                             f"{body.iloc[0, k].strip()[:40]!r}; allowed: {' or '.join(UNITS[kind][:2])} (or empty), "
                             "the values are read in it, not converted")
    return body.iloc[1:].reset_index(drop=True), lines[1:], lines[0]


def shown_header(header: list[str]) -> str:
    """A header as a refusal shows it: its first twelve names, each cut to 20 characters."""
    return ",".join(h[:20] for h in header[:12]) + (",..." if len(header) > 12 else "")


__all__ = ["DECIMAL_WHOLE", "SEPARATORS", "TAIL_CHARS", "UNITS", "UNIT_NAME", "column", "cut_short", "file_table",
           "named", "normal_name", "numbers", "pattern", "per_value", "read_text", "refuse", "shown_header",
           "tail_text", "text_table", "too_large", "trimmed", "units_row", "whole_ids"]
