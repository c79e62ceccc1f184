"""Reading recorded times of arrival at a fixed array (an inverted LBL), as hostile input (:mod:`.input_rows`): the
TOA matrix, one row per ping, one column per receiver, comma-separated (if its first row holds a comma) or
whitespace-separated, an optional header of receiver names; ``NA`` or an empty cell where the ping was not heard
(Lake Hald's ``toa.txt``); read a piece at a time (:func:`~.input_rows.row_pieces`: a season's tag of millions of
pings in its numbers' memory). A pseudo-random tag's burst sequence: :mod:`.burst_sequence`.

The files read beside them: the receivers' positions (:mod:`.receivers_file`), a track and a measured sound-speed
series (:mod:`.time_series`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.input_rows import (
    MAX_MATRIX_PINGS,
    MAX_RECEIVERS,
    MAX_TIME,
    _is_cell,
    _numbers,
    _stripped,
    row_pieces,
)


@dataclass
class ToaMatrix:
    """Times of arrival: ``toa`` (pings, receivers) [s], NaN where not heard; ``names`` the columns' receiver names
    (None: no header, the columns in the receivers file's order); ``depth`` the tag's depth-sensor reading per ping
    [m] (a ``depth_m`` column of the header: positive down, NaN where none; None without one)."""

    toa: np.ndarray
    names: list[str] | None
    depth: np.ndarray | None = None


#: The column of a TOA matrix's header that holds the tag's depth reading per ping, not a receiver's times.
DEPTH_COLUMN = "depth_m"
#: The depth readings allowed [m] (a pressure sensor reads a little above the surface; the deepest trench).
DEPTH_RANGE = (-10.0, 11000.0)


def read_toa(path: Path | str) -> ToaMatrix:
    """Read a TOA matrix (module docstring); times in [0, :data:`~sblsim.orchestrator.readers.input_rows.MAX_TIME`] s.

    Raises
    ------
    ModelError
        One line naming the file, the line and column, and the allowed range; more than
        :data:`~.input_rows.MAX_MATRIX_PINGS` pings or :data:`~.input_rows.MAX_MATRIX_CELLS` cells.
    """
    path, what = Path(path), "toa"
    names, header, parts, pings = None, None, [], 0
    for rows in row_pieces(path, what):  # a piece at a time: 8 bytes a cell kept, not its text
        if header is None and rows:
            first = _stripped(rows[0][1])
            if not all(_is_cell(c) for c in first):
                names, rows = first, rows[1:]
                if len(set(names)) != len(names):
                    raise ModelError(f"{what}: {str(path)!r}: a receiver name is given twice in the header")
            header = names or [f"{k + 1}" for k in range(len(first))]
            if not 1 <= len(header) <= MAX_RECEIVERS:
                raise ModelError(f"{what}: {str(path)!r} has {len(header)} columns; allowed 1 to {MAX_RECEIVERS}")
        if not rows:
            continue
        pings += len(rows)
        if pings > MAX_MATRIX_PINGS:
            raise ModelError(f"{what}: {str(path)!r} holds more than {MAX_MATRIX_PINGS:,} pings; allowed at most "
                             f"{MAX_MATRIX_PINGS:,} (split it in time)")
        depth = names is not None and DEPTH_COLUMN in names
        parts.append((_numbers(rows, str(path), what, header, -MAX_TIME if depth else 0.0, MAX_TIME, True,
                               names is not None), [k for k, _ in rows] if depth else []))  # lines: the depth's checks
    if header is None:
        raise ModelError(f"{what}: {str(path)!r} holds no rows; allowed: a matrix of times of arrival [s]")
    if not parts:
        raise ModelError(f"{what}: {str(path)!r} holds a header and no rows")
    values = parts[0][0] if len(parts) == 1 else np.concatenate([v for v, _ in parts])
    if names is None or DEPTH_COLUMN not in names:
        return ToaMatrix(values, names)
    lines = [k for _, numbers in parts for k in numbers]
    at = names.index(DEPTH_COLUMN)
    depth, toa = values[:, at], np.delete(values, at, axis=1)
    receivers = [n for n in names if n != DEPTH_COLUMN]
    for cells, low, high, columns in ((depth[:, None], *DEPTH_RANGE, [DEPTH_COLUMN]), (toa, 0.0, MAX_TIME, receivers)):
        bad = np.argwhere((cells < low) | (cells > high))
        if len(bad):
            i, j = map(int, bad[0])
            raise ModelError(f"{what}: {str(path)!r} line {lines[i]} column {columns[j]}: {cells[i, j]:.10g} is not "
                             f"allowed; allowed: a finite number in [{low:g}, {high:g}] or NA/empty")
    if not receivers:
        raise ModelError(f"{what}: {str(path)!r} holds a depth column and no receiver's")
    return ToaMatrix(toa, receivers, depth)


__all__ = ["DEPTH_COLUMN", "DEPTH_RANGE", "ToaMatrix", "read_toa"]
