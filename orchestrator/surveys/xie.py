"""Reader of survey A's text format (Xie et al. 2023, repository suruixie/sfg_gnssa_sw, ``gnssa_data_*.txt``)
into the calibration survey log (:mod:`sblsim.orchestrator.surveys.log`).

The format, from the files' own header lines: ``#`` comment lines, then one line per ping of 15
whitespace-separated numbers: transmit time [s after 2020-01-01T00:00:00 UTC], the transducer's local North,
East, Up [m] and their 1-sigma [m] at transmit, the receive time [s, same clock], North, East, Up and 1-sigma
at the reply's receive time, and the two-way travel time with the transponder's 0.2 s turnaround already
removed [s]. There is one transponder: every row is a reply of transponder ``"1"``, ``ping`` is the row's index
(from 0). The origin of the local frame is in a header line (``Lat0=... deg., Lon0=... deg., H0=... m``);
:func:`origin` reads it.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.limits import MEMORY_SHARE, available_memory
from sblsim.orchestrator.io.log_tables import check_fits, line_chunks, line_count
from sblsim.orchestrator.io.tables import csv_cells, number
from sblsim.orchestrator.surveys.log import COLUMNS, LOG_COLUMNS, ROW_BYTES, SurveyLog, check_frame

#: The files' clock: seconds after this instant (UTC) [s since 1970-01-01].
EPOCH = datetime(2020, 1, 1, tzinfo=timezone.utc).timestamp()
#: The fields of a line, in order (N before E, as the authors write them).
FIELDS = ("t_tx", "tx_n_m", "tx_e_m", "tx_u_m", "tx_sigma_n_m", "tx_sigma_e_m", "tx_sigma_u_m",
          "t_rx", "rx_n_m", "rx_e_m", "rx_u_m", "rx_sigma_n_m", "rx_sigma_e_m", "rx_sigma_u_m", "twtt_s")
#: The one transponder's id.
TRANSPONDER = "1"
#: The file clock's range accepted [s after 2020-01-01] (to 2100).
CLOCK_RANGE = (0.0, 2_524_608_000.0)
_ORIGIN = re.compile(r"Lat0\s*=\s*([-+0-9.eE]+)\s*deg\.?,\s*Lon0\s*=\s*([-+0-9.eE]+)\s*deg\.?,\s*H0\s*=\s*"
                     r"([-+0-9.eE]+)\s*m")


def origin(path: Path | str) -> tuple[float, float, float] | None:
    """The local frame's origin from the file's header (latitude [deg], longitude [deg], height [m]), or None.

    Raises
    ------
    ModelError
        As :func:`read_xie` for a file that cannot be read.
    """
    for _, line in next(line_chunks(Path(path), "log", delimiter=" ", comments=True), []):  # the header: first lines
        if not line.lstrip().startswith("#"):
            break
        found = _ORIGIN.search(line)
        if found:
            here = f"log: {str(path)!r} header"
            return (number(found.group(1), here, "Lat0", -90, 90), number(found.group(2), here, "Lon0", -180, 360),
                    number(found.group(3), here, "H0", -1e4, 1e4))
    return None


def read_xie(path: Path | str) -> SurveyLog:
    """Read a ``gnssa_data_*.txt`` file of survey A into the calibration log.

    Parameters
    ----------
    path : pathlib.Path or str
        The text file.

    Returns
    -------
    SurveyLog
        One row per line: ``ping`` the line's index among the data lines, ``transponder`` ``"1"``, times as POSIX
        seconds, E/N/U in the log's column order.

    Raises
    ------
    ModelError
        One line naming the file, the line and the field: a missing or not regular file, one too large for the
        memory here (read in pieces, :func:`~sblsim.orchestrator.io.log_tables.line_chunks`), a line too long or of
        too many fields, not UTF-8, a line without 15 fields, a field that is not a number or outside its range
        (those of :data:`sblsim.orchestrator.surveys.log.COLUMNS`), no data line.
    """
    path = Path(path)
    what = "log"
    check_fits(path, what, line_count(path, what), ROW_BYTES, MEMORY_SHARE * available_memory())
    parts: list[np.ndarray] = []
    where: list[str] = []
    for piece in line_chunks(path, what, delimiter=" ", comments=True):  # in pieces: any length, bounded memory
        lines = [(k, line) for k, line in piece if line.strip() and not line.lstrip().startswith("#")]
        values = np.empty((len(lines), len(FIELDS)))
        for j, (k, cells) in enumerate(csv_cells(lines, f"{what}: {str(path)!r}", " ")):  # by the csv module
            here = f"{what}: {str(path)!r} line {k}"
            if len(cells) != len(FIELDS):
                raise ModelError(f"{here} has {len(cells)} fields, the format {len(FIELDS)} ({' '.join(FIELDS)})")
            for i, (name, text) in enumerate(zip(FIELDS, cells)):
                bounds = CLOCK_RANGE if name in ("t_tx", "t_rx") else COLUMNS[name][2]
                values[j, i] = number(text, here, name, *bounds)
            where.append(f"line {k}")
        parts.append(values)
    if not where:
        raise ModelError(f"{what}: {str(path)!r} holds no data line")
    raw = pd.DataFrame(np.concatenate(parts), columns=list(FIELDS))
    frame = raw.drop(columns=["t_tx", "t_rx"]).assign(
        ping=range(len(raw)), transponder=TRANSPONDER, t_tx_s=raw["t_tx"] + EPOCH, t_rx_s=raw["t_rx"] + EPOCH)
    log = check_frame(frame[list(LOG_COLUMNS)], where, str(path))
    log.counts["ignored_columns"] = []
    return log


__all__ = ["EPOCH", "FIELDS", "TRANSPONDER", "origin", "read_xie"]
