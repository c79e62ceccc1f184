"""A plain piece of a detections file parsed into text cells by Arrow's CSV reader (multithreaded C++) instead of
pandas', for :mod:`sblsim.orchestrator.store.ingest`: the very cells
:func:`~sblsim.orchestrator.readers.cells.text_table` makes of it, each row's line in the file, then read by the
format's own reader (every cell checked by the same rules, the same refusals).

A piece is **plain** where no rule of the text reader can differ: UTF-8, no quote (no quoted cell, no line break
inside a cell), no carriage return, no blank line, every line as many cells as the header, no row of blank cells
(which the text reader drops), no line longer than
:data:`~sblsim.orchestrator.io.tables.MAX_LINE_BYTES` and the piece's cells within
:data:`~sblsim.orchestrator.readers.limits.MAX_DETECTION_CELLS`. Where any of that does not hold, :func:`plain_body`
returns None and the piece is read by the text reader, which refuses or reads it as it reads a whole file: a fault
is always named by the same reader's line. Parsing a piece of 8 MiB of a VUE export took 16 ms so and 234 ms by
pandas' (137,426 rows; the cells then made Python strings and back into Arrow's).
"""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv

from sblsim.orchestrator.io.tables import MAX_LINE_BYTES, MAX_LINE_CELLS
from sblsim.orchestrator.readers.limits import MAX_DETECTION_CELLS, MAX_DETECTIONS


def _plain_text(piece: bytes) -> bool:
    """Whether a piece's bytes hold no quote and no carriage return (the module docstring; a blank line is told by
    each caller from its lines: a search for two line ends took 6 ms of 8 MiB, four times both of these)."""
    return bool(piece) and b'"' not in piece and b"\r" not in piece


def _blank(column: pa.ChunkedArray) -> pa.ChunkedArray:
    return pc.equal(pc.utf8_trim_whitespace(column), "")


def plain_body(piece: bytes, width: int, first_line: int, max_cells: int = MAX_DETECTION_CELLS,
               max_rows: int = MAX_DETECTIONS) -> tuple[pd.DataFrame, list[int]] | None:
    """A plain piece's rows as text cells (columns ``0 … width-1``, pandas' ``str``, as
    :func:`~sblsim.orchestrator.readers.cells.text_table`'s body) and each row's line in the file; None where the
    piece is not plain (the module docstring).

    Parameters
    ----------
    piece : bytes
        Whole lines of the file, after its header.
    width : int
        The header's cells [1].
    first_line : int
        The file's line number of the piece's first line.
    max_cells, max_rows : int
        The most cells and rows of the piece [1] (the text reader's limits).
    """
    if not _plain_text(piece):
        return None
    rows = piece.count(b"\n") + (not piece.endswith(b"\n"))
    if rows * width > max_cells or rows > max_rows:
        return None
    names = [str(k) for k in range(width)]
    try:
        table = pcsv.read_csv(
            io.BytesIO(piece),
            read_options=pcsv.ReadOptions(column_names=names, block_size=1 << 22),
            parse_options=pcsv.ParseOptions(newlines_in_values=False, ignore_empty_lines=True),  # rows < lines
            convert_options=pcsv.ConvertOptions(column_types={n: pa.string() for n in names},
                                                strings_can_be_null=False, quoted_strings_can_be_null=False))
    except pa.ArrowException:  # a row of another width, a byte not UTF-8: the text reader's
        return None
    if table.num_rows != rows:  # a row of another width, or a blank line (Arrow skips it, the text reader too)
        return None
    if len(piece) > MAX_LINE_BYTES:  # the longest line, from the line ends' places
        ends = np.flatnonzero(np.frombuffer(piece, np.uint8) == ord("\n"))
        if not len(ends) or np.diff(ends, prepend=-1).max() - 1 > MAX_LINE_BYTES or \
                len(piece) - 1 - ends[-1] > MAX_LINE_BYTES:
            return None
    suspect = _blank(table.column(0))  # a row of blank cells, which the text reader drops: read by it
    if pc.any(suspect).as_py():
        inside = table.filter(suspect)
        blank = _blank(inside.column(0))
        for k in range(1, width):
            blank = pc.and_(blank, _blank(inside.column(k)))
        if pc.any(blank).as_py():
            return None
    body = table.to_pandas()
    body.columns = range(width)
    return body, (np.arange(rows, dtype=np.int64) + first_line).tolist()


def fathom_detections(piece: bytes, max_cells: int = MAX_DETECTION_CELLS) -> tuple[bytes, np.ndarray] | None:
    """A plain piece of a Fathom CSV's records (the module docstring) reduced to its ``DET`` lines, and each one's
    line in the piece (0 first); None where the piece is not plain, holds no ``DET`` line, or holds a line of a
    ``DET_…`` record (a ``DET_DESC`` or ``DET_SENS``: read by the text reader). Every line of the piece is checked as
    :func:`~sblsim.orchestrator.io.tables.check_cells` checks it (its length, its cells, the piece's cells), the
    lines of other records too.

    Parameters
    ----------
    piece : bytes
        Whole lines of the file, after its first line.
    max_cells : int
        The most cells of the piece [1].
    """
    if not _plain_text(piece):
        return None
    if not piece.endswith(b"\n"):
        piece += b"\n"
    data = np.frombuffer(piece, np.uint8)
    ends = np.flatnonzero(data == ord("\n"))
    starts = np.r_[0, ends[:-1] + 1]
    length = ends - starts
    if length.min() == 0 or length.max() > MAX_LINE_BYTES or piece.count(b",") + len(starts) > max_cells:
        return None  # a blank line, a line too long, too many cells
    # a line of more cells than allowed holds as many commas, so as many bytes: only such lines' commas counted
    for k in np.flatnonzero(length >= MAX_LINE_CELLS):
        if piece.count(b",", starts[k], ends[k]) + 1 > MAX_LINE_CELLS:
            return None

    def at(k: int) -> np.ndarray:  # each line's k-th byte (a line shorter: its line end's, or the piece's last)
        return data[np.minimum(starts + k, len(data) - 1)]

    record = at(0) == ord("D")
    for k, byte in enumerate(b"ET"):
        record &= at(k + 1) == byte
    if (record & (at(3) == ord("_"))).any():
        return None
    record &= at(3) == ord(",")
    if not record.any():
        return None
    # the runs of DET lines joined (a few hundred other records in a piece: as many slices, not a mask of its bytes)
    edges = np.flatnonzero(np.diff(np.r_[False, record, False].view(np.int8)))
    first, last = edges[::2], edges[1::2] - 1
    kept = b"".join(piece[a:b] for a, b in zip(starts[first].tolist(), (ends[last] + 1).tolist()))
    return kept, np.flatnonzero(record)


__all__ = ["fathom_detections", "plain_body"]
