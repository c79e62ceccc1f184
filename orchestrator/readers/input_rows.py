"""The rows and cells of the tracking's input files, read as hostile input (the times of arrival, the receivers, a
track, a sound-speed series, a burst sequence: :mod:`.toa`, :mod:`.receivers_file`, :mod:`.time_series`).

Each file must be a regular file (a FIFO or a device such as ``/dev/zero`` is refused before it is opened) and is
read to at most :data:`MAX_TOA_BYTES` bytes and :data:`MAX_PINGS` rows, counted in what was read; but a TOA matrix, a
season's every ping, read a piece at a time (:func:`row_pieces`) to at most :data:`MAX_MATRIX_PINGS` rows and
:data:`MAX_MATRIX_CELLS` cells, its numbers' memory (8 bytes a cell). Its rows are
parsed by the csv module (:func:`~sblsim.orchestrator.io.tables.csv_cells`: a quoted cell may hold the separator),
every row must have the header's (or the first row's) number of cells, and every cell is checked (finite, within
its range); no name or text in a file is ever taken as a path. An error is one line naming the file, the line as
an editor numbers it, the column and the allowed range (:class:`ModelError`).
"""

from __future__ import annotations

from itertools import chain
from pathlib import Path
from typing import Iterator

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.log_tables import line_chunks
from sblsim.orchestrator.io.tables import NUMBER, csv_cells, read_lines

#: The largest file read [bytes] and the most rows (pings, receivers, track points).
MAX_TOA_BYTES = 64 * 2**20
MAX_PINGS = 500_000
MAX_RECEIVERS = 1000
#: The most cells a line holds [1] (a TOA matrix's: a receiver's each and the depth column) and a file [1] (150,000
#: pings at 28 receivers, Lake Hald's, or 60,000 at 70; parsed by the csv module at about 130 bytes a cell, well under
#: 1 GiB: split a longer matrix in time).
MAX_ROW_CELLS = MAX_RECEIVERS + 1
MAX_TOA_CELLS = 2**22
#: A TOA matrix is read a piece at a time (:func:`row_pieces`): its bounds are its numbers' memory (8 bytes a cell),
#: not its text's: a season of a tag that pings every 2.5 s (3.1 M pings; at 16 receivers 50 M cells, 0.4 GiB).
MAX_MATRIX_PINGS = 4_000_000
MAX_MATRIX_CELLS = 2**26
#: The allowed times [s] (a time of arrival or a track's time) and coordinates [m].
MAX_TIME = 1e10
MAX_COORDINATE = 1e7
#: The texts of a cell that was not heard.
MISSING = ("NA", "")


def _too_large(name: str, what: str, amount: str) -> ModelError:
    return ModelError(f"{what}: {name!r} {amount}; allowed at most {MAX_TOA_BYTES // 2**20} MiB and {MAX_PINGS:,} "
                      "rows")


def _lines(path: Path, what: str) -> list[tuple[int, str]]:
    """The numbered lines of a regular text file (:func:`~sblsim.orchestrator.io.tables.read_lines`), refused when
    it holds more than :data:`MAX_TOA_BYTES` bytes or :data:`MAX_PINGS` rows and 1,000 lines besides (counted in
    what was read), or when a line is longer than 1 MiB or holds more than :data:`MAX_ROW_CELLS` cells, or the file
    more than :data:`MAX_TOA_CELLS` (:func:`~sblsim.orchestrator.io.tables.check_cells`, before it is parsed);
    comments (``#``) and blank lines dropped, the others with their line numbers from 1."""
    lines = read_lines(path, what, max_bytes=MAX_TOA_BYTES, max_rows=MAX_PINGS, extra_lines=1000, refuse=_too_large,
                       delimiter="auto", max_line_cells=MAX_ROW_CELLS, max_cells=MAX_TOA_CELLS, comments=True)
    return _data_lines(enumerate(lines, start=1))


def _data_lines(numbered) -> list[tuple[int, str]]:
    """The numbered lines that hold a row: comments (``#``) and blank lines dropped."""
    return [(k, line) for k, line in numbered if line.strip() and not line.lstrip().startswith("#")]


def _delimiter(lines: list[tuple[int, str]]) -> str:
    """A table's delimiter: ``","`` where its first row holds a comma, else ``" "`` (whitespace-separated)."""
    return "," if lines and "," in lines[0][1] else " "


def _rows(path: Path, what: str) -> list[tuple[int, list[str]]]:
    """The file's rows (:func:`_lines`) as (line number, cells), parsed by the csv module: comma-separated if the
    first row holds a comma, else whitespace-separated; quotes honoured (``"H1, north"`` is one cell). The cells
    keep trailing spaces (:func:`_stripped`, :func:`_numbers` strip them)."""
    lines = _lines(path, what)
    return csv_cells(lines, f"{what}: {str(path)!r}", _delimiter(lines))


def row_pieces(path: Path, what: str, max_cells: int | None = None) -> Iterator[list[tuple[int, list[str]]]]:
    """:func:`_rows`' rows a piece at a time (:func:`~sblsim.orchestrator.io.log_tables.line_chunks`, its lines
    checked before they are parsed: at most :data:`MAX_ROW_CELLS` cells and 1 MiB a line), for a file of any size:
    the delimiter the first row's, comments and blank lines dropped, each row with its line in the file.

    Raises
    ------
    ModelError
        As :func:`_rows`, but for the file's size; more than ``max_cells`` cells in all (default
        :data:`MAX_MATRIX_CELLS`; counted to the file's end, its rows no longer kept).
    """
    max_cells = MAX_MATRIX_CELLS if max_cells is None else max_cells
    delimiter, total = None, 0
    for lines in line_chunks(path, what, delimiter="auto", comments=True, max_line_cells=MAX_ROW_CELLS):
        kept = _data_lines(lines)
        if kept and delimiter is None:
            delimiter = _delimiter(kept)
        if total > max_cells:  # the rest counted, not parsed (a quoted separator counted as one)
            total += sum(line.count(",") + 1 if delimiter == "," else len(line.split()) for _, line in kept)
            continue
        rows = csv_cells(kept, f"{what}: {str(path)!r}", delimiter or " ")
        total += sum(len(cells) for _, cells in rows)
        if total <= max_cells:
            yield rows
    if total > max_cells:
        raise ModelError(f"{what}: {str(path)!r} holds {total:,} cells; allowed at most {max_cells:,} cells in a "
                         "table")


def _stripped(cells: list[str]) -> list[str]:
    return [c.strip() for c in cells]


def _is_cell(text: str) -> bool:
    return text in MISSING or bool(NUMBER.fullmatch(text))


def _numbers(rows: list[tuple[int, list[str]]], name: str, what: str, header: list[str], low: float, high: float,
             missing: bool, named: bool = True) -> np.ndarray:
    """The cells of ``rows`` (:func:`_rows`) as a float matrix, each checked: a number (``NA``/empty allowed only
    where ``missing``), finite, within [low, high]; every row with the header's number of cells (``named``: the
    file's header; else the first row's). An error names the line and the column, or the line and its cells. The
    cells are checked as one column of Arrow text (about 20 bytes a cell, whatever the widest cell's length)."""
    width = len(header)
    ragged = next(((number, len(cells)) for number, cells in rows if len(cells) != width), None)
    if ragged is not None:
        against = f"the header {width} ({','.join(header)[:80]})" if named else f"the first row {width}"
        raise ModelError(f"{what}: {name!r} line {ragged[0]} has {ragged[1]} cells, {against}; allowed: "
                         f"{width} cells a row" + (" (NA or an empty cell where not heard)" if missing else ""))
    allowed = f"a finite number in [{low:g}, {high:g}]" + (" or NA/empty (not heard)" if missing else "")
    lines = [number for number, _ in rows]
    shape = (len(rows), width)
    stripped = pc.utf8_trim_whitespace(pa.array(chain.from_iterable(row for _, row in rows), pa.string(),
                                                size=shape[0] * width))  # row by row, as str.strip strips
    valid = pc.match_substring_regex(stripped, f"^(?:{NUMBER.pattern})$", ignore_case=True)
    values = np.array(pc.cast(pc.if_else(valid, stripped, "nan"), pa.float64()), float).reshape(shape)  # writable
    empty = pc.is_in(stripped, pa.array(MISSING)).to_numpy(zero_copy_only=False).reshape(shape)
    valid = valid.to_numpy(zero_copy_only=False).reshape(shape)
    bad = ~(valid | (empty & missing))
    bad |= valid & ~np.isfinite(values)
    bad |= valid & np.isfinite(values) & ((values < low) | (values > high))
    if bad.any():
        i, j = map(int, np.argwhere(bad)[0])
        text = stripped[i * width + j].as_py()
        raise ModelError(f"{what}: {name!r} line {lines[i]} column {header[j]}: {text[:40]!r} is not "
                         f"allowed; allowed: {allowed}")
    values[empty] = np.nan
    return values



__all__ = ["MAX_COORDINATE", "MAX_MATRIX_CELLS", "MAX_MATRIX_PINGS", "MAX_PINGS", "MAX_RECEIVERS", "MAX_ROW_CELLS",
           "MAX_TIME", "MAX_TOA_BYTES", "MAX_TOA_CELLS", "MISSING", "row_pieces"]
