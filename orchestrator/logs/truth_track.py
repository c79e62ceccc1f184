"""A truth track (``time_s, n_m, e_m, d_m``, docs/log-format.md) read and checked: the diver's true position on the
log's clock that a replay's errors are measured against (``sblsim replay LOG --truth FILE``; ``sblsim run
--export-log`` writes one beside the log, :mod:`sblsim.orchestrator.logs.log_export`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sblsim.models.declarations import SIGNAL_RANGES, ModelError
from sblsim.orchestrator.cosim.limits import MEMORY_SHARE, available_memory
from sblsim.orchestrator.io.log_tables import check_fits, table_chunks, table_length
from sblsim.orchestrator.io.log_tables import columns as _columns
from sblsim.orchestrator.io.tables import number as _number

#: The truth track's columns (time_s on the log's clock; N, E, D in the log's frame) [s, m, m, m].
TRUTH_COLUMNS = ("time_s", "n_m", "e_m", "d_m")
#: The memory a row of a truth track takes while it is read [bytes] (its four numbers, their pieces joined, the
#: arrays returned).
TRUTH_ROW_BYTES = 128


def read_truth(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Read a truth track: ``time_s, n_m, e_m, d_m`` (CSV or Parquet), times strictly increasing; read in pieces
    (:func:`~sblsim.orchestrator.io.log_tables.table_chunks`), refused before it is read where its rows would not
    fit in the memory available here (:data:`TRUTH_ROW_BYTES` each).

    Returns
    -------
    time : ndarray, shape (M,)
        [s], M ≥ 2.
    ned : ndarray, shape (M, 3)
        [m].

    Raises
    ------
    ModelError
        ``--truth: ...`` naming the line: a missing column, a value that is not a finite number, a time
        that does not increase, fewer than two rows; a line too long or of too many cells, a track too long for
        the memory here.
    """
    path = Path(path)
    name = str(path)
    check_fits(path, "--truth", table_length(path, "--truth"), TRUTH_ROW_BYTES, MEMORY_SHARE * available_memory())
    index: dict[str, int] = {}
    parts: list[np.ndarray] = []
    p_lo, p_hi = SIGNAL_RANGES["position"]
    last = -np.inf
    for table in table_chunks(path, "--truth"):  # in pieces: a track of any length in the memory its numbers take
        if not index:
            index = _columns(table, "--truth")
            missing = [c for c in TRUTH_COLUMNS if c not in index]
            if missing:
                raise ModelError(f"--truth: {name!r} has no column {missing[0]}; its columns: "
                                 f"{','.join(table.header)}; a truth track has the columns {','.join(TRUTH_COLUMNS)} "
                                 "(docs/log-format.md)")
        values = np.empty((len(table.rows), 4))
        for k, (where_short, cells) in enumerate(table.rows):
            where = f"--truth: {name!r} {where_short}"
            for j, column in enumerate(TRUTH_COLUMNS):
                low, high = (-1e12, 1e12) if j == 0 else (p_lo, p_hi)
                values[k, j] = _number(cells[index[column]], where, column, low, high)
            if values[k, 0] <= last:
                raise ModelError(f"{where}: time_s {values[k, 0]:.10g} s does not come after the row before "
                                 f"({last:.10g} s): a truth track's times must increase")
            last = values[k, 0]
        parts.append(values)
    values = np.concatenate(parts)
    if len(values) < 2:
        raise ModelError(f"--truth: {name!r} has {len(values)} row(s); a track needs at least two")
    return values[:, 0], values[:, 1:]


__all__ = ["TRUTH_COLUMNS", "TRUTH_ROW_BYTES", "read_truth"]
