"""A pseudo-random tag's burst sequence: its intervals [s] in the tag's order, one per row, read as hostile input
(:mod:`.input_rows`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.input_rows import _is_cell, _numbers, _rows, _stripped

#: The shortest and longest interval of a burst sequence [s].
BURST_RANGE = (0.1, 86400.0)


def read_burst_sequence(path: Path | str) -> np.ndarray:
    """Read a pseudo-random tag's burst sequence: its intervals [s] in the tag's order, one per row, under an optional
    header (a column ``interval_s`` or ``interval`` where there are several; else the only column).

    Raises
    ------
    ModelError
        One line naming the file, the line and column, and the allowed range (each interval in
        :data:`BURST_RANGE`).
    """
    path, what = Path(path), "burst sequence"
    name = str(path)
    parsed = _rows(path, what)
    if not parsed:
        raise ModelError(f"{what}: {name!r} holds no rows; allowed: the tag's intervals [s], one per row")
    first = _stripped(parsed[0][1])
    headed = not all(_is_cell(c) for c in first)
    header = [h.lower() for h in first] if headed else ["interval_s"] + [str(k + 2) for k in range(len(first) - 1)]
    rows = parsed[1:] if headed else parsed
    if not rows:
        raise ModelError(f"{what}: {name!r} holds no intervals; allowed: the tag's intervals [s], one per row")
    found = [k for k, h in enumerate(header) if h in ("interval_s", "interval")]
    if len(header) > 1 and not found:
        raise ModelError(f"{what}: {name!r}: {len(header)} columns and none named interval_s; allowed: one column, "
                         "or a header naming interval_s")
    values = _numbers(rows, name, what, header, *BURST_RANGE, False, headed)
    return values[:, found[0] if found else 0]


__all__ = ["BURST_RANGE", "read_burst_sequence"]
