"""A log's table (a CSV or Parquet file of a recorder's or a survey's rows) as text cells: read whole (a small
table: :func:`read_table`) or in pieces of bounded memory whatever its length (:func:`table_chunks`).

Every cell is handed to the reader as text, which checks it itself (:func:`~sblsim.orchestrator.io.tables.number`)
and names its line and column. The bounds are by shape, not by size (docs/log-format.md): a line longer than
:data:`~sblsim.orchestrator.io.tables.MAX_LINE_BYTES` or of more than
:data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS` cells is refused before it is parsed, in whichever piece it
lies (:func:`~sblsim.orchestrator.io.tables.check_cells`; a line of 200 M commas is scanned, never held); a piece is
at most :data:`CHUNK_BYTES` of text, so a reader that keeps numbers, not text, reads a file of any length in
memory its rows' numbers take. Such a reader counts the rows first (:func:`table_length`, a pass over the bytes)
and refuses, before the work, a table whose rows would not fit in the memory available
(:func:`check_fits`). A table read whole keeps the whole-table bounds of
:mod:`sblsim.orchestrator.io.tables` (:data:`~sblsim.orchestrator.io.tables.MAX_LOG_BYTES`,
:data:`~sblsim.orchestrator.io.tables.MAX_LOG_ROWS`, :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`). A
table never names a path that is then read or written.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, Iterable, Iterator

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io import tables
from sblsim.orchestrator.io.tables import (
    MAX_LINE_BYTES,
    check_cells,
    check_line,
    csv_cells,
    read_lines,
    regular_file,
    text_lines,
    too_large,
)

#: Comment lines of an exported CSV log that hold the run's resolved configuration (TOML), one line each.
CONFIG_PREFIX = "#% "
#: Parquet schema metadata keys of an exported log: its title and the run's configuration.
META_TITLE, META_CONFIG = b"sblsim.title", b"sblsim.config"
#: Suffixes of the formats read and written.
SUFFIXES = (".csv", ".parquet")
#: The text of a CSV table parsed at once [bytes] (its text cells take about 10 times that while a piece is converted;
#: a calibration log of 10**6 replies read with 2 MiB pieces peaks 100 MB lower than with 8 MiB, in the same time)
#: and the bytes a Parquet table's piece is sized by (16 a cell).
CHUNK_BYTES = 2 * 2**20
#: The bytes a file is scanned in (:func:`table_length`, the rest of a line too long).
_BLOCK = 2**20


def cell(value: Any) -> str:
    """A Parquet cell as the text a CSV cell would hold ('' for a missing value)."""
    if value is None or value is pd.NA or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return str(value)


@dataclass
class TextTable:
    """A CSV or Parquet file as text cells: its header, its rows (where, cells) and its metadata."""

    path: Path
    header: list[str]
    rows: list[tuple[str, list[str]]]
    config: str = ""
    title: str = ""


def read_parquet(path: Path, what: str) -> TextTable:
    """A Parquet file's columns as text cells (:func:`read_table`); its pandas metadata is not used. One of more
    than :data:`~sblsim.orchestrator.io.tables.MAX_LOG_ROWS` rows,
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS` columns or :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`
    cells is refused from its metadata, before a cell is read."""
    name = str(path)
    try:
        import pyarrow.parquet as pq

        meta = pq.ParquetFile(path).metadata
        rows, width = meta.num_rows, meta.num_columns
        if rows > tables.MAX_LOG_ROWS:
            raise too_large(name, what, f"has {rows:,} rows")
        if width > tables.MAX_LINE_CELLS or rows * width > tables.MAX_CELLS:  # refused from its metadata
            raise ModelError(f"{what}: {name!r} holds {rows:,} rows of {width:,} columns; allowed at most "
                             f"{tables.MAX_LINE_CELLS:,} columns and {tables.MAX_CELLS:,} cells in a table")
        table = pq.read_table(path)
        meta = table.schema.metadata or {}
        header = [str(c).strip() for c in table.column_names]
        rows = parquet_rows(table)
    except ModelError:
        raise
    except Exception as exc:  # pyarrow raises its own errors on a damaged file
        raise unreadable_parquet(name, what, exc) from None
    return TextTable(path, header, rows, meta.get(META_CONFIG, b"").decode("utf-8", "replace"),
                     meta.get(META_TITLE, b"").decode("utf-8", "replace"))


def unreadable_parquet(name: str, what: str, exc: Exception) -> ModelError:
    """The one line of a Parquet file that pyarrow cannot read (its own error's words, at most 200 characters)."""
    return ModelError(f"{what}: {name!r} is not a readable Parquet file ({' '.join(str(exc).split())[:200]})")


def parquet_rows(table: Any, first: int = 1) -> list[tuple[str, list[str]]]:
    """A pyarrow table's rows as text cells (:func:`cell`), each with its place (``row N``, from ``first``)."""
    columns = [[cell(v) for v in table.column(k).to_pylist()] for k in range(table.num_columns)]
    cells = [list(values) for values in zip(*columns)] if columns else []
    return [(f"row {first + k}", c) for k, c in enumerate(cells)]


def read_table(path: Path, what: str) -> TextTable:
    """Read a CSV (``#`` comment lines, blank lines skipped) or Parquet file into text cells, whole.

    Lines end at ``\\n`` (or ``\\r\\n``) only. A file larger than :data:`~sblsim.orchestrator.io.tables.MAX_LOG_BYTES`
    or with more than :data:`~sblsim.orchestrator.io.tables.MAX_LOG_ROWS` rows is refused before it is read whole (a
    log of any length is read in pieces: :func:`table_chunks`).

    Raises
    ------
    ModelError
        ``what: ...`` for a missing or unreadable file, one that is not a regular file, a suffix other than
        .csv or .parquet, a file too large, no header, or a line whose field count differs from the header's
        (with its line number).
    """
    name = str(path)
    check_suffix(path, what)
    if path.suffix.lower() == ".parquet":
        size = regular_file(path, what)
        if size > tables.MAX_LOG_BYTES:
            raise too_large(name, what, f"is {size / 2**20:.0f} MiB")
        return read_parquet(path, what)
    head = TableHead()
    lines = enumerate(read_lines(path, what, comments=True), start=1)
    rows = table_rows(lines, path, what, head, tables.MAX_LOG_ROWS)
    if head.header is None:
        raise no_header(name, what)
    return TextTable(path, head.header, rows, "\n".join(head.config), head.title)


def check_suffix(path: Path, what: str) -> None:
    """Refuse a table whose suffix is not one of :data:`SUFFIXES`."""
    if path.suffix.lower() not in SUFFIXES:
        raise ModelError(f"{what}: {str(path)!r} must be a .csv or .parquet file")


def no_header(name: str, what: str) -> ModelError:
    return ModelError(f"{what}: {name!r} holds no header line (and no rows)")


@dataclass
class TableHead:
    """What a CSV table's first lines say: its header (None until its first line that is neither blank nor a
    comment), the configuration lines (``#%``) and the title (the first other comment) before it."""

    header: list[str] | None = None
    config: list[str] = field(default_factory=list)
    title: str = ""


def table_rows(lines: Iterable[tuple[int, str]], path: Path, what: str, head: TableHead,
               max_rows: int | None = None) -> list[tuple[str, list[str]]]:
    """The rows of a CSV table's numbered lines as text cells (``line N``, the cells stripped), blank and comment
    lines skipped; ``head`` is what the lines before said (a fresh one for a file's first lines) and takes the
    header, configuration and title these lines give. A line that is not the header is a row of the header's
    fields.

    Parameters
    ----------
    lines : iterable of (int, str)
        The lines (split as :func:`text_lines`) with their numbers in the file.
    max_rows : int, optional
        Refuse more rows than this (a table read whole).

    Raises
    ------
    ModelError
        A line that does not parse as CSV (:func:`csv_cells`), a row whose field count differs from the header's,
        more than ``max_rows`` rows.
    """
    name = str(path)
    data: list[tuple[int, str]] = []
    for number, line in lines:
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            if head.header is None and not data:
                if line.startswith(CONFIG_PREFIX.rstrip()):
                    head.config.append(line[len(CONFIG_PREFIX):] if line.startswith(CONFIG_PREFIX) else "")
                elif not head.title:
                    head.title = stripped.lstrip("#").strip()
            continue
        data.append((number, line))
        if max_rows is not None and len(data) > max_rows + (head.header is None):  # the header and the rows
            raise too_large(name, what, f"has more than {max_rows:,} rows (line {number})")
    parsed = csv_cells(data, f"{what}: {name!r}") if data else []
    if head.header is None and parsed:
        head.header = [c.strip() for c in parsed[0][1]]
        parsed = parsed[1:]
    rows: list[tuple[str, list[str]]] = []
    width = len(head.header or ())
    for number, cells in parsed:
        if len(cells) != width:
            raise ModelError(f"{what}: {name!r} line {number} has {len(cells)} fields, the header "
                             f"{width} ({','.join(head.header)})")
        rows.append((f"line {number}", [c.strip() for c in cells]))
    return rows


def columns(table: TextTable, what: str) -> dict[str, int]:
    """Column name -> position; a name given twice is refused."""
    index: dict[str, int] = {}
    for k, name in enumerate(table.header):
        if name in index:
            raise ModelError(f"{what}: {str(table.path)!r}: the column {name!r} is given twice")
        index[name] = k
    return index


# --------------------------------------------------------------------------- reading a table in pieces

def table_chunks(path: Path, what: str, chunk_bytes: int = CHUNK_BYTES) -> Iterator[TextTable]:
    """A CSV or Parquet table read in pieces: each a :class:`TextTable` of the header, the configuration and title
    and the rows of about ``chunk_bytes`` of the file (the first one yielded once the header is read, even without
    rows), so that the memory the text takes stays bounded whatever the file's length.

    A CSV piece ends at a line's end and is checked before it is decoded or parsed (a line longer than
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_BYTES` or of more than
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS` cells refused, naming its line and its length or cells,
    counted to its end without holding it); lines, comments, the configuration and the title as
    :func:`read_table`'s. A Parquet file of more than :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS` columns
    is refused from its metadata; its rows are read in record batches.

    Parameters
    ----------
    path : Path
        A ``.csv`` or ``.parquet`` file.
    what : str
        What it is, as the errors name it (``log``).
    chunk_bytes : int
        About the text a piece holds [bytes].

    Yields
    ------
    TextTable
        A piece: its ``rows`` those of the piece (``line N``, ``row N``: their places in the file).

    Raises
    ------
    ModelError
        As :func:`read_table`, but for the file's size and row count (not bounded here): a missing or unreadable
        file, one that is not a regular file, a suffix other than .csv or .parquet, a line too long or too wide,
        text that is not UTF-8, no header, a line whose field count differs from the header's.
    """
    path = Path(path)
    check_suffix(path, what)
    regular_file(path, what)
    if path.suffix.lower() == ".parquet":
        yield from _parquet_chunks(path, what, chunk_bytes)
        return
    head, yielded = TableHead(), False
    for lines in line_chunks(path, what, comments=True, chunk_bytes=chunk_bytes):
        rows = table_rows(lines, path, what, head)
        if head.header is not None and (rows or not yielded):
            yielded = True
            yield TextTable(path, head.header, rows, "\n".join(head.config), head.title)
    if head.header is None:
        raise no_header(str(path), what)


def line_chunks(path: Path, what: str, encoding: str = "utf-8-sig", *, delimiter: str = ",", comments: bool = False,
                chunk_bytes: int = CHUNK_BYTES, max_line_cells: int | None = None) -> Iterator[list[tuple[int, str]]]:
    """A regular text file's numbered lines (split as :func:`~sblsim.orchestrator.io.tables.text_lines`) in pieces
    of about ``chunk_bytes``, each piece ending at a line's end and checked before it is decoded: a line longer than
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_BYTES` or of more than
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS` cells refused, naming its line and its length or cells
    (:func:`~sblsim.orchestrator.io.tables.check_cells` with ``delimiter`` and ``comments``; a line longer than a
    piece counted to its end without holding it).

    Parameters
    ----------
    encoding : str
        ``"utf-8-sig"`` (a byte-order mark dropped) or ``"ascii"``.
    max_line_cells : int, optional
        The most cells a line holds [1] (default :data:`~sblsim.orchestrator.io.tables.MAX_LINE_CELLS`).

    Yields
    ------
    list of (int, str)
        A piece's lines with their numbers in the file.

    Raises
    ------
    ModelError
        A missing or unreadable file, one that is not a regular file, a line too long or too wide, text that is
        not in ``encoding`` (naming the byte).
    """
    path = Path(path)
    name = str(path)
    regular_file(path, what)
    first_line, offset = 1, 0
    try:
        handle = open(path, "rb")
    except OSError as exc:
        raise ModelError(f"{what}: {name!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    with handle:
        while True:
            piece = handle.read(chunk_bytes)
            if not piece:
                break
            if not piece.endswith(b"\n"):  # to the end of its last line (a line too long refused there)
                piece += _rest_of_line(handle, piece, name, what, first_line, delimiter == ",")
            check_cells(piece, name, what, delimiter, max_cells=math.inf, comments=comments, first_line=first_line,
                        max_line_cells=max_line_cells)
            try:
                text = piece.decode("utf-8" if encoding == "utf-8-sig" and offset else encoding)
            except UnicodeDecodeError as exc:
                kind = "ASCII" if encoding == "ascii" else "UTF-8"
                raise ModelError(f"{what}: {name!r} is not {kind} text (byte {offset + exc.start})") from None
            yield list(enumerate(text_lines(text), start=first_line))
            first_line += piece.count(b"\n")
            offset += len(piece)


def _rest_of_line(handle: BinaryIO, piece: bytes, name: str, what: str, first_line: int, comma: bool) -> bytes:
    """The rest of ``piece``'s last line from ``handle``; a line longer than
    :data:`~sblsim.orchestrator.io.tables.MAX_LINE_BYTES` is scanned to its end, its bytes and cells (``comma``: its
    commas and one, else its runs of non-spaces) counted, not kept, and refused as
    :func:`~sblsim.orchestrator.io.tables.check_cells` refuses it."""
    rest = handle.readline(MAX_LINE_BYTES + 2)
    if rest.endswith(b"\n") or len(rest) < MAX_LINE_BYTES + 2:
        return rest
    start = piece.rfind(b"\n") + 1
    line = piece[start:] + rest
    length, comment = len(line), line[:1] == b"#"
    cells, spaced = _cells(line, comma, True)
    while True:
        block = handle.read(_BLOCK)
        end = block.find(b"\n")
        block = block if end < 0 else block[:end]
        length += len(block)
        more, spaced = _cells(block, comma, spaced)
        cells += more
        if end >= 0 or not block:
            break
    number = first_line + piece.count(b"\n", 0, start)
    check_line(name, what, number, 0 if comment else cells + comma, length - (block[-1:] == b"\r"), comma=comma)
    raise AssertionError("a line longer than MAX_LINE_BYTES passed check_line")  # pragma: no cover


def _cells(data: bytes, comma: bool, spaced: bool) -> tuple[int, bool]:
    """The cells that start in ``data`` (its commas; else its runs of non-spaces, the byte before a space when
    ``spaced``) and whether its last byte is a space."""
    if comma:
        return data.count(b","), spaced
    raw = np.frombuffer(data, np.uint8)
    if not raw.size:
        return 0, spaced
    space = (raw == 32) | (raw == 9) | (raw == 13)
    starts = ~space
    starts[1:] &= space[:-1]
    starts[0] &= spaced
    return int(starts.sum()), bool(space[-1])


def _parquet_chunks(path: Path, what: str, chunk_bytes: int) -> Iterator[TextTable]:
    """:func:`table_chunks` of a Parquet file: record batches of about ``chunk_bytes`` (16 bytes a cell)."""
    name = str(path)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        handle = pq.ParquetFile(path)
        rows, width = handle.metadata.num_rows, handle.metadata.num_columns
        if width > tables.MAX_LINE_CELLS:  # refused before a cell is read: its metadata's
            raise ModelError(f"{what}: {name!r} holds {rows:,} rows of {width:,} columns; allowed at most "
                             f"{tables.MAX_LINE_CELLS:,} columns")
        meta = handle.schema_arrow.metadata or {}
        header = [str(c).strip() for c in handle.schema_arrow.names]
        batches = handle.iter_batches(batch_size=max(1, chunk_bytes // (16 * max(width, 1))))
    except ModelError:
        raise
    except Exception as exc:  # pyarrow raises its own errors on a damaged file
        raise unreadable_parquet(name, what, exc) from None
    config, title = (meta.get(key, b"").decode("utf-8", "replace") for key in (META_CONFIG, META_TITLE))
    first, yielded = 1, False
    while True:
        try:
            batch = next(batches, None)
            rows = [] if batch is None else parquet_rows(pa.Table.from_batches([batch]), first)
        except Exception as exc:
            raise unreadable_parquet(name, what, exc) from None
        if batch is None:
            break
        first += batch.num_rows
        yielded = True
        yield TextTable(path, header, rows, config, title)
    if not yielded:
        yield TextTable(path, header, [], config, title)


def table_length(path: Path, what: str) -> int:
    """The most rows a table holds [1], counted before it is read: a CSV file's lines (:func:`line_count`), a
    Parquet file's rows (its metadata).

    Raises
    ------
    ModelError
        A missing or unreadable file, one that is not a regular file, a suffix other than .csv or .parquet.
    """
    path = Path(path)
    check_suffix(path, what)
    if path.suffix.lower() != ".parquet":
        return line_count(path, what)
    regular_file(path, what)
    try:
        import pyarrow.parquet as pq

        return int(pq.ParquetFile(path).metadata.num_rows)
    except Exception as exc:  # pyarrow's errors on a damaged file
        raise unreadable_parquet(str(path), what, exc) from None


def line_count(path: Path, what: str) -> int:
    """The lines of a regular file [1] (its line ends, and a last line without one), counted in a pass over its
    bytes, :data:`_BLOCK` at a time, before it is read.

    Raises
    ------
    ModelError
        A missing or unreadable file, one that is not a regular file.
    """
    path = Path(path)
    regular_file(path, what)
    lines, last = 0, b"\n"
    try:
        with open(path, "rb") as handle:
            while block := handle.read(_BLOCK):
                lines += block.count(b"\n")
                last = block[-1:]
    except OSError as exc:
        raise ModelError(f"{what}: {str(path)!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    return lines + (last != b"\n")


def check_fits(path: Path, what: str, rows: int, row_bytes: float, available: float) -> None:
    """Refuse, before the work, a table whose ``rows`` would take more than ``available`` memory at ``row_bytes``
    each (what its reader keeps of a row and its work's copies).

    Raises
    ------
    ModelError
        One line naming the file, its rows, the memory they need and the memory available [MiB].
    """
    need = rows * row_bytes
    if need > available:
        raise ModelError(f"{what}: {str(Path(path))!r} holds up to {rows:,} rows, about {need / 2**20:,.0f} MiB in "
                         f"memory to read; {available / 2**20:,.0f} MiB is available here: read it on a machine with "
                         "more memory, or in parts")


__all__ = ["CHUNK_BYTES", "CONFIG_PREFIX", "META_CONFIG", "META_TITLE", "SUFFIXES", "TableHead", "TextTable", "cell",
           "check_fits", "check_suffix", "columns", "line_chunks", "line_count", "no_header", "parquet_rows",
           "read_parquet", "read_table", "table_chunks", "table_length", "table_rows", "unreadable_parquet"]
