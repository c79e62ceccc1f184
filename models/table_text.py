"""A table parameter as configuration text: rows separated by ``;``, values by blanks or commas.

:func:`parse_table` reads such a text into the rows of a :class:`~sblsim.models.declarations.Table` and checks it
(each value against its column: :func:`check_entry`; the first column strictly increasing where the table asks
for it: :func:`check_increasing`), refusing a bad value with a one-line
:class:`~sblsim.models.errors.ModelError`; :func:`format_table` writes rows back as text that reads back exactly.
"""

from __future__ import annotations

import math
import re
from typing import Sequence

import numpy as np

from sblsim.models.declarations import Column, Table
from sblsim.models.errors import ModelError

_ROW_SPLIT = re.compile(r"[\s,]+")


def parse_table(text: str, table: Table, where: str) -> np.ndarray:
    """Parse a table given as text ``"a b; a b; ..."`` and check it.

    Returns
    -------
    ndarray, shape (rows, len(table.columns))
        The values; 0 rows for a blank text.

    Raises
    ------
    ModelError
        On a non-numeric or non-finite value (naming the row and column), a
        wrong number of values in a row, more rows than the table holds, a
        value outside its column's range, or a first column that is not
        strictly increasing when it must be.
    """
    ncol = len(table.columns)
    rows = [r.strip() for r in text.split(";")]
    if rows and not rows[-1]:
        rows = rows[:-1]  # a trailing ';'
    if not any(rows):
        return np.zeros((0, ncol))
    if len(rows) > table.max_rows:
        raise ModelError(f"{where}: {len(rows)} rows; at most {table.max_rows}")
    values = np.empty((len(rows), ncol))
    for i, row in enumerate(rows, start=1):
        items = [s for s in _ROW_SPLIT.split(row) if s]
        if len(items) != ncol:
            raise ModelError(f"{where}: row {i} has {len(items)} values, expected {ncol} "
                             f"({' '.join(c.name for c in table.columns)})")
        for j, (item, col) in enumerate(zip(items, table.columns)):
            try:
                number = float(item)
            except ValueError:
                raise ModelError(f"{where}: row {i}, column {col.name}: {item!r} is not a number") from None
            check_entry(number, col, f"{where}: row {i}, column {col.name}")
            values[i - 1, j] = number
    check_increasing(values, table, where)
    return values


def check_entry(number: float, col: Column, label: str) -> None:
    """Check one table value against its column (finite, in range).

    Raises
    ------
    ModelError
        Naming ``label`` and the column's allowed range.
    """
    if not math.isfinite(number):
        raise ModelError(f"{label}: {number!r} is not finite; allowed {col.allowed()}")
    if (col.min is not None and number < col.min) or (col.max is not None and number > col.max):
        raise ModelError(f"{label}: {number:g} is outside the allowed range {col.allowed()}")


def check_increasing(values: np.ndarray, table: Table, where: str, lines: Sequence[int] | None = None,
                     unit: str = "row") -> None:
    """Check that the first column is strictly increasing where the table asks for it.

    Parameters
    ----------
    lines : sequence of int, optional
        The file line (or row) number of each row, for the message (default 1, 2, ...).
    unit : str
        What the numbers are called in the message (``row`` or ``line``).

    Raises
    ------
    ModelError
        Naming the first row that is not greater than the row before.
    """
    if table.increasing and values.shape[0] > 1 and np.any(np.diff(values[:, 0]) <= 0.0):
        k = int(np.flatnonzero(np.diff(values[:, 0]) <= 0.0)[0]) + 1
        number = lines[k] if lines is not None else k + 1
        raise ModelError(f"{where}: {unit} {number}, column {table.columns[0].name}: must be greater than the "
                         f"{unit} before")


def format_table(values: np.ndarray) -> str:
    """A table as text, every value with 17 significant digits (read back exactly)."""
    return "; ".join(" ".join(repr(float(v)) for v in row) for row in np.asarray(values, float))


__all__ = ["check_entry", "check_increasing", "format_table", "parse_table"]
