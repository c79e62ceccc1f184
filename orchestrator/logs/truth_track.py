"""A truth track (``time_s, n_m, e_m, d_m``, docs/log-format.md) read and checked: the diver's true position on the
log's clock that a replay's errors are measured against (``sblsim replay LOG --truth FILE``; ``sblsim run
--export-log`` writes one beside the log, :mod:`sblsim.orchestrator.logs.log_export`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sblsim.models.declarations import SIGNAL_RANGES, ModelError
from sblsim.orchestrator.io.tables import columns as _columns
from sblsim.orchestrator.io.tables import number as _number
from sblsim.orchestrator.io.tables import read_table as _read_table

#: The truth track's columns (time_s on the log's clock; N, E, D in the log's frame) [s, m, m, m].
TRUTH_COLUMNS = ("time_s", "n_m", "e_m", "d_m")


def read_truth(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Read a truth track: ``time_s, n_m, e_m, d_m`` (CSV or Parquet), times strictly increasing.

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
        that does not increase, fewer than two rows.
    """
    path = Path(path)
    table = _read_table(path, "--truth")
    index = _columns(table, "--truth")
    name = str(path)
    missing = [c for c in TRUTH_COLUMNS if c not in index]
    if missing:
        raise ModelError(f"--truth: {name!r} has no column {missing[0]}; its columns: {','.join(table.header)}; "
                         f"a truth track has the columns {','.join(TRUTH_COLUMNS)} (docs/log-format.md)")
    values = np.empty((len(table.rows), 4))
    p_lo, p_hi = SIGNAL_RANGES["position"]
    for k, (where_short, cells) in enumerate(table.rows):
        where = f"--truth: {name!r} {where_short}"
        for j, column in enumerate(TRUTH_COLUMNS):
            low, high = (-1e12, 1e12) if j == 0 else (p_lo, p_hi)
            values[k, j] = _number(cells[index[column]], where, column, low, high)
        if k and values[k, 0] <= values[k - 1, 0]:
            raise ModelError(f"{where}: time_s {values[k, 0]:.10g} s does not come after the row before "
                             f"({values[k - 1, 0]:.10g} s): a truth track's times must increase")
    if len(values) < 2:
        raise ModelError(f"--truth: {name!r} has {len(values)} row(s); a track needs at least two")
    return values[:, 0], values[:, 1:]


__all__ = ["TRUTH_COLUMNS", "read_truth"]
