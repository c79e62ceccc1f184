"""Hostile-safe reading of the tables sblsim is given: recorded logs (``sblsim replay``, ``sblsim calibrate``).

A table is a CSV file (a header row, ``#`` comment lines and blank lines skipped) or a Parquet file, read
into text cells so that every reader checks every cell itself (:func:`number`) and names the line and the
column of a bad one. A file is checked to be a regular file before it is opened (a FIFO would block), and one
larger than :data:`MAX_LOG_BYTES` or with more than :data:`MAX_LOG_ROWS` rows is refused before it is read
whole. A table never names a path that is then read or written.
"""

from __future__ import annotations

import csv
import math
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError

#: Comment lines of an exported CSV log that hold the run's resolved configuration (TOML), one line each.
CONFIG_PREFIX = "#% "
#: Parquet schema metadata keys of an exported log: its title and the run's configuration.
META_TITLE, META_CONFIG = b"sblsim.title", b"sblsim.config"
#: Suffixes of the formats read and written.
SUFFIXES = (".csv", ".parquet")
#: The largest log read [bytes] and the most rows (a log is read whole, checked before reading it).
MAX_LOG_BYTES = 256 * 2**20
MAX_LOG_ROWS = 2_000_000
#: A number in a log: ASCII digits, an optional sign, point and exponent, or inf / nan (refused as not finite
#: where a finite number is needed); not what else Python's float() takes (``1_0.0``, other scripts' digits).
NUMBER = re.compile(r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)", re.IGNORECASE)


# --------------------------------------------------------------------------- reading tables

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


def regular_file(path: Path, what: str) -> int:
    """The size of a file that is a regular file [bytes] (checked without opening it: a FIFO would block).

    Raises
    ------
    ModelError
        ``what: ...`` for a missing file, a directory or anything that is not a regular file.
    """
    name = str(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise ModelError(f"{what}: no such file {name!r}") from None
    except OSError as exc:
        raise ModelError(f"{what}: {name!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    if stat.S_ISDIR(info.st_mode):
        raise ModelError(f"{what}: {name!r} is a directory")
    if not stat.S_ISREG(info.st_mode):
        raise ModelError(f"{what}: {name!r} is not a regular file (a pipe, a device or a socket); give a file")
    return info.st_size


def too_large(name: str, what: str, amount: str) -> ModelError:
    return ModelError(f"{what}: {name!r} {amount}; a log is read whole, at most {MAX_LOG_ROWS:,} rows and "
                      f"{MAX_LOG_BYTES // 2**20} MiB (docs/log-format.md): split it into parts")


def text_lines(text: str) -> list[str]:
    """The lines of a text, split at ``\\n`` only (a ``\\r\\n`` ending loses its ``\\r``): not at the other line
    boundaries :meth:`str.splitlines` knows (U+2028, form feed, ...), which a comment may hold and which no CSV
    writer takes as a new line, so that line numbers are the ones an editor shows."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [line[:-1] if line.endswith("\r") else line for line in lines]


def read_parquet(path: Path, what: str) -> TextTable:
    """A Parquet file's columns as text cells (:func:`_read_table`); its pandas metadata is not used."""
    name = str(path)
    try:
        import pyarrow.parquet as pq

        rows = pq.ParquetFile(path).metadata.num_rows
        if rows > MAX_LOG_ROWS:
            raise too_large(name, what, f"has {rows:,} rows")
        table = pq.read_table(path)
        meta = table.schema.metadata or {}
        header = [str(c).strip() for c in table.column_names]
        columns = [[cell(v) for v in table.column(k).to_pylist()] for k in range(table.num_columns)]
    except ModelError:
        raise
    except Exception as exc:  # pyarrow raises its own errors on a damaged file
        raise ModelError(f"{what}: {name!r} is not a readable Parquet file ({' '.join(str(exc).split())[:200]})") \
            from None
    cells = [list(values) for values in zip(*columns)] if columns else []
    return TextTable(path, header, [(f"row {k + 1}", c) for k, c in enumerate(cells)],
                  meta.get(META_CONFIG, b"").decode("utf-8", "replace"),
                  meta.get(META_TITLE, b"").decode("utf-8", "replace"))


def read_bounded(path: Path, what: str, max_bytes: int, max_lines: int,
                 refuse: Callable[[str, str, str], ModelError]) -> bytes:
    """A regular file's bytes, refused before it is read whole when it is larger than ``max_bytes`` or holds more
    than ``max_lines`` lines (counted in what was read, not only from the file's size): ``refuse(name, what,
    amount)`` the error of a file too large.

    Raises
    ------
    ModelError
        ``what: ...`` for a missing or unreadable file, one that is not a regular file, one too large.
    """
    name = str(path)
    size = regular_file(path, what)
    if size > max_bytes:
        raise refuse(name, what, f"is {size / 2**20:.0f} MiB")
    try:
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise ModelError(f"{what}: {name!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    if len(data) > max_bytes:
        raise refuse(name, what, f"is more than {max_bytes // 2**20} MiB")
    lines = data.count(b"\n")
    if lines > max_lines:  # a header and comment lines besides the rows
        raise refuse(name, what, f"has {lines:,} lines")
    return data


def read_lines(path: Path, what: str, encoding: str = "utf-8-sig", *, max_bytes: int | None = None,
               max_rows: int | None = None, extra_lines: int = 10_000,
               refuse: Callable[[str, str, str], ModelError] | None = None) -> list[str]:
    """The lines of a regular text file (split as :func:`text_lines`), refused before it is read whole when it
    is larger than ``max_bytes`` or holds more than ``max_rows`` rows and ``extra_lines`` lines besides (a
    header and comments); the sizes are checked in what was read, not only from the file's size.

    Parameters
    ----------
    max_bytes, max_rows : int, optional
        The limits [bytes], [1]; default a log's, :data:`MAX_LOG_BYTES` and :data:`MAX_LOG_ROWS`.
    extra_lines : int
        The lines allowed besides the rows [1].
    refuse : callable, optional
        ``refuse(name, what, amount)``: the error of a file too large (default :func:`too_large`, a log's).

    Raises
    ------
    ModelError
        ``what: ...`` for a missing or unreadable file, one that is not a regular file, one too large, or one
        that is not text in ``encoding`` ("utf-8-sig" or "ascii").
    """
    max_bytes = MAX_LOG_BYTES if max_bytes is None else max_bytes
    max_rows = MAX_LOG_ROWS if max_rows is None else max_rows
    data = read_bounded(path, what, max_bytes, max_rows + extra_lines, refuse or too_large)
    name = str(path)
    try:
        return text_lines(data.decode(encoding))
    except UnicodeDecodeError as exc:
        kind = "ASCII" if encoding == "ascii" else "UTF-8"
        raise ModelError(f"{what}: {name!r} is not {kind} text (byte {exc.start})") from None


def csv_cells(lines: Sequence[tuple[int, str]], where: str, delimiter: str = ",") -> list[tuple[int, list[str]]]:
    """Each numbered line's cells, parsed by the csv module (quotes honoured: ``"a, b"`` is one cell, ``""`` a quote
    inside one); a cell keeps its trailing spaces (the caller strips).

    Parameters
    ----------
    lines : sequence of (int, str)
        The lines to parse with their line numbers in the file (blank and comment lines already dropped); each is
        one row: a quoted cell never spans lines.
    where : str
        The error's start, e.g. ``"toa: 'x.csv'"``.
    delimiter : str
        ``","`` (a CSV file) or ``" "``: a whitespace-separated table (a run of spaces and tabs outside quotes is
        one separator; a tab inside quotes is read as a space).

    Raises
    ------
    ModelError
        ``where line N does not parse as CSV (...)``: a quote not closed on its line, text after a closing quote.
    """
    texts = [line.strip().replace("\t", " ") if delimiter == " " else line.strip() for _, line in lines]
    reader = csv.reader(texts, delimiter=delimiter, skipinitialspace=True, strict=True)
    try:
        rows = list(reader)
        if len(rows) == len(texts) and reader.line_num == len(texts):  # each line one row: the usual case
            return [(number, cells) for (number, _), cells in zip(lines, rows)]
    except csv.Error:
        pass
    reader = csv.reader(texts, delimiter=delimiter, skipinitialspace=True, strict=True)  # find the line, one by one
    out: list[tuple[int, list[str]]] = []
    for number, _ in lines:
        try:
            cells = next(reader)
        except (csv.Error, StopIteration) as exc:
            reason = str(exc) or "unexpected end of data"
            raise ModelError(f"{where} line {number} does not parse as CSV ({reason}: a quote not closed on its "
                             "line?)") from None
        if reader.line_num != len(out) + 1:
            raise ModelError(f"{where} line {number} does not parse as CSV (a quoted cell runs past the line's end)")
        out.append((number, cells))
    return out


def read_table(path: Path, what: str) -> TextTable:
    """Read a CSV (``#`` comment lines, blank lines skipped) or Parquet file into text cells.

    Lines end at ``\\n`` (or ``\\r\\n``) only. A file larger than :data:`MAX_LOG_BYTES` or with more than
    :data:`MAX_LOG_ROWS` rows is refused before it is read whole.

    Raises
    ------
    ModelError
        ``what: ...`` for a missing or unreadable file, one that is not a regular file, a suffix other than
        .csv or .parquet, a file too large, no header, or a line whose field count differs from the header's
        (with its line number).
    """
    name = str(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ModelError(f"{what}: {name!r} must be a .csv or .parquet file")
    if path.suffix.lower() == ".parquet":
        size = regular_file(path, what)
        if size > MAX_LOG_BYTES:
            raise too_large(name, what, f"is {size / 2**20:.0f} MiB")
        return read_parquet(path, what)
    lines = read_lines(path, what)
    data: list[tuple[int, str]] = []
    config: list[str] = []
    title = ""
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            if not data and line.startswith(CONFIG_PREFIX.rstrip()):
                config.append(line[len(CONFIG_PREFIX):] if line.startswith(CONFIG_PREFIX) else "")
            elif not data and not title:
                title = stripped.lstrip("#").strip()
            continue
        data.append((number, line))
        if len(data) > MAX_LOG_ROWS + 1:  # the header and the rows
            raise too_large(name, what, f"has more than {MAX_LOG_ROWS:,} rows (line {number})")
    if not data:
        raise ModelError(f"{what}: {name!r} holds no header line (and no rows)")
    parsed = csv_cells(data, f"{what}: {name!r}")
    header = [c.strip() for c in parsed[0][1]]
    rows: list[tuple[str, list[str]]] = []
    for number, cells in parsed[1:]:
        if len(cells) != len(header):
            raise ModelError(f"{what}: {name!r} line {number} has {len(cells)} fields, the header "
                             f"{len(header)} ({','.join(header)})")
        rows.append((f"line {number}", [c.strip() for c in cells]))
    return TextTable(path, header, rows, "\n".join(config), title)


def columns(table: TextTable, what: str) -> dict[str, int]:
    """Column name -> position; a name given twice is refused."""
    index: dict[str, int] = {}
    for k, name in enumerate(table.header):
        if name in index:
            raise ModelError(f"{what}: {str(table.path)!r}: the column {name!r} is given twice")
        index[name] = k
    return index


def number(text: str, where: str, column: str, low: float, high: float) -> float:
    """A cell as a finite number within [low, high].

    Raises
    ------
    ModelError
        Naming the line, the column and the value.
    """
    if not text:
        raise ModelError(f"{where}: {column} is empty")
    if not NUMBER.fullmatch(text):
        raise ModelError(f"{where}: {column}: {text[:40]!r} is not a number") from None
    value = float(text)
    if not math.isfinite(value):
        raise ModelError(f"{where}: {column}: {text!r} is not a finite number")
    if not low <= value <= high:
        raise ModelError(f"{where}: {column}: {value:.10g} is outside the allowed range [{low:g}, {high:g}]")
    return value


__all__ = ["CONFIG_PREFIX", "MAX_LOG_BYTES", "MAX_LOG_ROWS", "META_CONFIG", "META_TITLE", "NUMBER", "SUFFIXES",
           "TextTable", "cell", "columns", "csv_cells", "number", "read_bounded", "read_lines", "read_parquet",
           "read_table", "regular_file", "text_lines", "too_large"]
