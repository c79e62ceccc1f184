"""Hostile-safe reading of the text files sblsim is given: their bytes, lines, cells and numbers.

A file is checked to be a regular file before it is opened (a FIFO would block). A file read whole
(:func:`read_lines`, :func:`read_bounded`) larger than its stated bytes (default :data:`MAX_LOG_BYTES`) or lines
(default :data:`MAX_LOG_ROWS`) is refused before it is read whole, and one whose line is longer than
:data:`MAX_LINE_BYTES`, holds more than :data:`MAX_LINE_CELLS` cells, or whose lines hold more than
:data:`MAX_CELLS` in all is refused before anything parses it (:func:`check_cells`, which every table reader of
sblsim goes through: a file's bytes alone do not bound the memory its cells take, a line of commas being a cell a
byte). A log of any length is read in pieces instead, with the per-line bounds alone
(:mod:`sblsim.orchestrator.io.log_tables`). Every reader checks every cell itself (:func:`number`,
:data:`NUMBER`) and names the line and the column of a bad one.
"""

from __future__ import annotations

import csv
import math
import os
import re
import stat
from pathlib import Path
from typing import BinaryIO, Callable, Sequence

import numpy as np

from sblsim.models.declarations import ModelError

#: The largest file read whole [bytes] and the most rows, by default (checked before reading it whole).
MAX_LOG_BYTES = 256 * 2**20
MAX_LOG_ROWS = 2_000_000
#: The most cells a line of a table holds [1] (the widest a reader takes, a GLATOS or OTN extract, has about 40
#: columns; a TOA matrix, one a receiver, passes its own), the most cells a table holds [1] (its rows times its widest
#: row: 2**24, parsed into text cells at 20 to 70 bytes each, well under 1 GiB) and the longest line [bytes].
MAX_LINE_CELLS = 512
MAX_CELLS = 2**24
MAX_LINE_BYTES = 2**20
#: The bytes :func:`check_cells` scans at once (its temporaries: 10 to 70 bytes a byte scanned, the most for a
#: piece of line ends alone).
_PIECE = 2**20
#: A number in a log: ASCII digits, an optional sign, point and exponent, or inf / nan (refused as not finite
#: where a finite number is needed); not what else Python's float() takes (``1_0.0``, other scripts' digits).
NUMBER = re.compile(r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)", re.IGNORECASE)


# --------------------------------------------------------------------------- reading tables

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


def _first_row(data: bytes, longest: int) -> bytes:
    """The first line of ``data`` that is neither blank nor a comment (``#``), at most ``longest`` bytes of it."""
    found = re.search(rb"^[ \t]*[^#\s][^\r\n]{0,%d}" % longest, data, re.M)
    return found.group(0) if found else b""


def check_line(name: str, what: str, number: int, cells: int, length: int, *, max_line_cells: int | None = None,
               max_line_bytes: int | None = None, comma: bool = True) -> None:
    """Refuse line ``number`` of a table's text that holds more than ``max_line_cells`` cells or is longer than
    ``max_line_bytes`` (default :data:`MAX_LINE_CELLS`, :data:`MAX_LINE_BYTES`): the message of
    :func:`check_cells`, its cells counted as ``comma`` says (its commas and one, else its runs of non-spaces).

    Raises
    ------
    ModelError
        ``what: 'name' line N holds C cells; allowed at most L cells a line (...)`` or ``... line N is B bytes long;
        allowed at most L bytes a line``.
    """
    max_line_cells = MAX_LINE_CELLS if max_line_cells is None else max_line_cells
    max_line_bytes = MAX_LINE_BYTES if max_line_bytes is None else max_line_bytes
    if cells > max_line_cells:
        raise ModelError(f"{what}: {name!r} line {number} holds {cells:,} cells; allowed at most "
                         f"{max_line_cells:,} cells a line ({_counted(comma)})")
    if length > max_line_bytes:
        raise ModelError(f"{what}: {name!r} line {number} is {length:,} bytes long; allowed at most "
                         f"{max_line_bytes:,} bytes a line")


def _counted(comma: bool) -> str:
    return ("commas" if comma else "runs of characters between spaces") + " counted before parsing"


def check_cells(data: bytes, name: str, what: str, delimiter: str = ",", *, max_line_cells: int | None = None,
                max_cells: int | None = None, max_line_bytes: int | None = None, comments: bool = False,
                first_line: int = 1) -> int:
    """Refuse a table's text before anything parses it into cells: a line longer than ``max_line_bytes``, a line of
    more than ``max_line_cells`` cells, or more than ``max_cells`` cells in all. The cells are counted in the bytes,
    :data:`_PIECE` bytes at a time (at most about 70 MiB besides the text, whatever its shape).

    A line ends at ``\\n``, ``\\r\\n`` or a lone ``\\r`` (pandas' parser ends a row at each). Its cells: with
    ``delimiter`` ``","``, its commas and one (a comma inside quotes counted too: an upper bound of what a parser
    makes of it; a row whose quoted cell spans lines holds at most the cells of its lines); with ``" "``, its runs of
    characters other than spaces and tabs (a whitespace-separated table); with ``"auto"``, ``","`` where the first
    line that is neither blank nor a comment holds a comma, else ``" "`` (the rule of a TOA matrix).

    Parameters
    ----------
    data : bytes
        The file's bytes (before decoding: UTF-8 keeps these ASCII characters single bytes).
    name, what : str
        The file and what it is, as the error names them.
    delimiter : str
        ``","``, ``" "`` or ``"auto"``.
    max_line_cells, max_cells : int, optional
        The most cells a line holds and a table holds [1]; default :data:`MAX_LINE_CELLS`, :data:`MAX_CELLS`.
    max_line_bytes : int, optional
        The longest line [bytes], its line end not counted; default :data:`MAX_LINE_BYTES`.
    comments : bool
        A line whose first character is ``#`` is a comment the reader drops unparsed: its cells are not counted,
        its length is.
    first_line : int
        The number of the text's first line in its file (a piece of a file read in pieces), as the errors name it.

    Returns
    -------
    int
        The cells counted [1].

    Raises
    ------
    ModelError
        One line naming the file, the limit and the count: ``what: 'name' line N holds C cells; allowed at most L
        cells a line``, ``... line N is B bytes long; allowed at most L bytes a line``, ``... holds C cells; allowed
        at most L cells in a table``.
    """
    max_line_cells = MAX_LINE_CELLS if max_line_cells is None else max_line_cells
    max_cells = MAX_CELLS if max_cells is None else max_cells
    max_line_bytes = MAX_LINE_BYTES if max_line_bytes is None else max_line_bytes
    if delimiter == "auto":
        delimiter = "," if b"," in _first_row(data, max_line_bytes) else " "
    if delimiter not in (",", " "):
        raise ValueError(f"check_cells: delimiter {delimiter!r}; allowed ',', ' ' or 'auto'")
    comma = delimiter == ","

    def check(number: int, cells: int, length: int) -> None:  # one line's cells and bytes
        check_line(name, what, number, cells, length, max_line_cells=max_line_cells, max_line_bytes=max_line_bytes,
                   comma=comma)

    raw = np.frombuffer(data, np.uint8)
    size = raw.size
    line, start, carried, total = first_line, 0, 0, 0  # the current line's number, first byte, cells in earlier pieces
    spaced = True  # the byte before the piece is a space or a line end (or there is none)
    for at in range(0, size, _PIECE):
        piece = raw[at:at + _PIECE]
        newline, cr = piece == 10, piece == 13
        ends = newline.copy()
        if cr.any():  # a \r ends a line unless a \n follows it
            followed = np.zeros(piece.size, bool)
            followed[:-1] = newline[1:]
            followed[-1] = at + piece.size < size and raw[at + piece.size] == 10
            ends |= cr & ~followed
        if comma:
            marks = piece == 44
        else:  # the first byte of each run of non-spaces
            space = (piece == 32) | (piece == 9) | newline | cr
            marks = ~space
            marks[0] &= spaced
            marks[1:] &= space[:-1]
            spaced = bool(space[-1])
        counted = np.cumsum(marks, dtype=np.int32)  # at most _PIECE
        where = np.flatnonzero(ends)
        if not where.size:  # the line goes on: checked where it ends
            carried += int(counted[-1])
            continue
        before = counted[where].astype(np.int64)
        cells = np.diff(before, prepend=0)
        cells[0] += carried
        cells += comma
        firsts = np.concatenate(([start], at + where[:-1] + 1))
        if comments:
            cells[raw[firsts] == 35] = 0
        lengths = at + where - firsts
        lengths -= (lengths > 0) & (raw[np.maximum(at + where - 1, 0)] == 13)  # a \r\n's \r: the line's end
        bad = np.flatnonzero((cells > max_line_cells) | (lengths > max_line_bytes))
        if bad.size:
            k = int(bad[0])
            check(line + k, int(cells[k]), int(lengths[k]))
        total += int(cells.sum())
        line += where.size
        start = at + int(where[-1]) + 1
        carried = int(counted[-1] - before[-1])
    if start < size:  # the last line, without a line end
        cells = 0 if comments and raw[start] == 35 else carried + comma
        check(line, cells, size - start)
        total += cells
    if total > max_cells:
        raise ModelError(f"{what}: {name!r} holds {total:,} cells; allowed at most {max_cells:,} cells in a table "
                         f"({_counted(comma)})")
    return total


def read_bounded(path: Path, what: str, max_bytes: int, max_lines: int,
                 refuse: Callable[[str, str, str], ModelError], *, delimiter: str | None = ",",
                 max_line_cells: int | None = None, max_cells: int | None = None, comments: bool = False,
                 stream: BinaryIO | None = None) -> bytes:
    """A regular file's bytes, refused before it is read whole when it is larger than ``max_bytes`` or holds more
    than ``max_lines`` lines (counted in what was read, not only from the file's size): ``refuse(name, what,
    amount)`` the error of a file too large; and, unless ``delimiter`` is None (a file that is not a table), refused
    before anything parses it when a line is longer than :data:`MAX_LINE_BYTES` or holds more than
    ``max_line_cells`` cells, or the table more than ``max_cells`` (:func:`check_cells`, with ``delimiter`` and
    ``comments``).

    With ``stream`` (the file's text as an archive holds it, decompressed as it is read), its bytes read to the same
    bounds instead of the file's.

    Raises
    ------
    ModelError
        ``what: ...`` for a missing or unreadable file, one that is not a regular file, one too large, a line too
        long or too wide, too many cells.
    """
    name = str(path)
    size = regular_file(path, what)
    if size > max_bytes:
        raise refuse(name, what, f"is {size / 2**20:.0f} MiB")
    if stream is not None:
        data = stream.read(max_bytes + 1)
    else:
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
    if delimiter is not None:
        check_cells(data, name, what, delimiter, max_line_cells=max_line_cells, max_cells=max_cells,
                    comments=comments)
    return data


def read_lines(path: Path, what: str, encoding: str = "utf-8-sig", *, max_bytes: int | None = None,
               max_rows: int | None = None, extra_lines: int = 10_000,
               refuse: Callable[[str, str, str], ModelError] | None = None, delimiter: str | None = ",",
               max_line_cells: int | None = None, max_cells: int | None = None, comments: bool = False) -> list[str]:
    """The lines of a regular text file (split as :func:`text_lines`), refused before it is read whole when it
    is larger than ``max_bytes`` or holds more than ``max_rows`` rows and ``extra_lines`` lines besides (a
    header and comments); the sizes are checked in what was read, not only from the file's size. A table's cells are
    counted before it is decoded (:func:`check_cells`): a line too long or too wide, or too many cells, refused.

    Parameters
    ----------
    max_bytes, max_rows : int, optional
        The limits [bytes], [1]; default a log's, :data:`MAX_LOG_BYTES` and :data:`MAX_LOG_ROWS`.
    extra_lines : int
        The lines allowed besides the rows [1].
    refuse : callable, optional
        ``refuse(name, what, amount)``: the error of a file too large (default :func:`too_large`, a log's).
    delimiter : str or None
        The table's: ``","``, ``" "`` (whitespace-separated) or ``"auto"`` (:func:`check_cells`); None for a file
        that is not a table (its lines' length still bounded by ``max_bytes`` alone).
    max_line_cells, max_cells : int, optional
        The most cells a line and the table hold [1] (default :data:`MAX_LINE_CELLS`, :data:`MAX_CELLS`).
    comments : bool
        The caller drops the lines that start with ``#`` unparsed: their cells are not counted.

    Raises
    ------
    ModelError
        ``what: ...`` for a missing or unreadable file, one that is not a regular file, one too large, a line too
        long or too wide, too many cells, or one that is not text in ``encoding`` ("utf-8-sig" or "ascii").
    """
    max_bytes = MAX_LOG_BYTES if max_bytes is None else max_bytes
    max_rows = MAX_LOG_ROWS if max_rows is None else max_rows
    data = read_bounded(path, what, max_bytes, max_rows + extra_lines, refuse or too_large, delimiter=delimiter,
                        max_line_cells=max_line_cells, max_cells=max_cells, comments=comments)
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


__all__ = ["MAX_CELLS", "MAX_LINE_BYTES", "MAX_LINE_CELLS", "MAX_LOG_BYTES", "MAX_LOG_ROWS", "NUMBER", "check_cells",
           "check_line", "csv_cells", "number", "read_bounded", "read_lines", "regular_file", "text_lines", "too_large"]
