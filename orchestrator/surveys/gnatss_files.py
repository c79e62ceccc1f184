"""GNATSS's two survey files, read as hostile: ``pxp_tt`` (per ping, the transmit time and the two-way travel
times, :func:`read_pxp_tt`) and ``POS_FREED_TRANS_TWTT`` (the transducer's ECEF position and covariance at each
epoch, :func:`read_posfilter`), as GNATSS's ``docs/input.md`` and ``gnatss/loaders.py`` (commit 44ca5389) give
them; :mod:`sblsim.orchestrator.surveys.gnatss` describes both and joins them into the calibration log.

Every file is read with the helpers every log reader shares (:mod:`sblsim.orchestrator.io.tables`): a regular
file of ASCII text only, within the logs' documented size, every number checked with its file, line and column
named (:class:`~sblsim.models.errors.ModelError`, one line).

References
----------
GNATSS, GNSS-Acoustic Seafloor Positioning Software, https://github.com/seafloor-geodesy/gnatss (BSD-3).
"""

from __future__ import annotations

import calendar
import re
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.errors import ModelError
from sblsim.orchestrator.io.tables import NUMBER, csv_cells, read_lines
from sblsim.orchestrator.io.tables import number as table_number

#: POSIX time of J2000 (2000-01-01T12:00:00 UTC) [s]: GNATSS's J2000 seconds are POSIX seconds less this.
J2000_POSIX = 946728000
#: Range of a two-way travel time in pxp_tt [us] (0: no reply).
MAX_TWTT_US = 60e6
#: Range of an ECEF coordinate [m] and of a covariance entry [m^2].
MAX_ECEF_M, MAX_COV_M2 = 1e7, 1e4
#: Range of a J2000 time in POS_FREED_TRANS_TWTT [s] (1970 to 2100).
J2000_RANGE = (-float(J2000_POSIX), 3.2e9)
#: Columns of a POS_FREED_TRANS_TWTT line.
POS_FIELDS = 13
_MONTHS = {m.upper(): k for k, m in enumerate(calendar.month_abbr) if m}
_DATE = re.compile(r"([0-9]{2})-([A-Za-z]{3})-([0-9]{2})")
_TIME = re.compile(r"([0-9]{2}):([0-9]{2}):([0-9]{2}(?:\.[0-9]{1,6})?)")


def _utc(date: str, clock: str, where: str) -> float:
    """POSIX seconds of a ``pxp_tt`` date and time (``27-JUL-22``, ``17:37:45.00``; years 2000-2099)."""
    d, t = _DATE.fullmatch(date), _TIME.fullmatch(clock)
    if d is None or d.group(2).upper() not in _MONTHS:
        raise ModelError(f"{where}: column 1 (date): {date[:40]!r} is not a date DD-MON-YY")
    if t is None:
        raise ModelError(f"{where}: column 2 (time): {clock[:40]!r} is not a time HH:MM:SS.ss")
    year, month, day = 2000 + int(d.group(3)), _MONTHS[d.group(2).upper()], int(d.group(1))
    hour, minute, second = int(t.group(1)), int(t.group(2)), float(t.group(3))
    if not (1 <= day <= calendar.monthrange(year, month)[1]):
        raise ModelError(f"{where}: column 1 (date): {date!r} has no day {day} in that month")
    if hour > 23 or minute > 59 or second >= 60.0:
        raise ModelError(f"{where}: column 2 (time): {clock!r} is outside 00:00:00 to 23:59:59.999999")
    return calendar.timegm((year, month, day, hour, minute, 0, 0, 0, 0)) + second


def read_pxp_tt(path: Path | str, columns: int) -> pd.DataFrame:
    """Read a ``pxp_tt`` file: per ping, the transmit time and the two-way travel times.

    Parameters
    ----------
    path : path
        The file.
    columns : int
        Travel-time columns to read (the site's transponders); further columns are not read.

    Returns
    -------
    pandas.DataFrame
        Columns ``line`` (the line number), ``t_tx_s`` (POSIX, UTC) and ``twtt_us_1`` ... ``twtt_us_N``
        [us] (0 for no reply), one row per ping, in the file's order.

    Raises
    ------
    ModelError
        Naming file, line and column: a line with too few fields, a date or time that is not one, a travel
        time not a number within [0, :data:`MAX_TWTT_US`] us; a file that is missing, not a regular file,
        too large or not text; no pings.
    """
    path = Path(path)
    what = "pxp_tt"
    rows = []
    lines = [(number, line) for number, line in enumerate(read_lines(path, what, "ascii", delimiter=" "), start=1)
             if line.strip()]
    for number, fields in csv_cells(lines, f"{what}: {str(path)!r}", " "):  # whitespace-separated, by the csv module
        where = f"{what}: {str(path)!r} line {number}"
        if len(fields) < 2 + columns:
            raise ModelError(f"{where} has {len(fields)} fields; date, time and {columns} travel times [us] needed "
                             "(a truncated file?)")
        t_tx = _utc(fields[0], fields[1], where)
        twtt = [table_number(fields[2 + k], where, f"column {3 + k} (two-way travel time [us])", 0.0, MAX_TWTT_US)
                for k in range(columns)]
        rows.append([number, t_tx, *twtt])
    if not rows:
        raise ModelError(f"{what}: {str(path)!r} holds no pings")
    return pd.DataFrame(rows, columns=["line", "t_tx_s", *[f"twtt_us_{k + 1}" for k in range(columns)]])


def read_posfilter(path: Path | str) -> pd.DataFrame:
    """Read a ``POS_FREED_TRANS_TWTT`` file: the transducer's ECEF position and covariance at each epoch.

    Returns
    -------
    pandas.DataFrame
        Columns ``line``, ``t_j2000_s`` [s since J2000], ``x_m``, ``y_m``, ``z_m`` [m] and ``c0`` ... ``c8``,
        the covariance row by row [m^2], in the file's order.

    Raises
    ------
    ModelError
        Naming file, line and column: a line without :data:`POS_FIELDS` fields, a number that is not one or
        outside its range, a covariance that is not symmetric or not positive definite (its Cholesky
        factorisation by numpy fails).
    """
    path = Path(path)
    what = "POS_FREED_TRANS_TWTT"
    names = ["time [s since J2000]", "x [m]", "y [m]", "z [m]", *[f"covariance {a}{b} [m^2]" for a in "xyz"
                                                                  for b in "xyz"]]
    ranges = [J2000_RANGE] + [(-MAX_ECEF_M, MAX_ECEF_M)] * 3 + [(-MAX_COV_M2, MAX_COV_M2)] * 9
    lines = csv_cells([(number, line) for number, line in enumerate(read_lines(path, what, "ascii", delimiter=" "),
                                                                    start=1)
                       if line.strip()], f"{what}: {str(path)!r}", " ")  # whitespace-separated, by the csv module
    if not lines:
        raise ModelError(f"{what}: {str(path)!r} holds no positions")
    low, high = np.array(ranges).T
    values = None
    if all(len(fields) == POS_FIELDS and all(NUMBER.fullmatch(f) for f in fields) for _, fields in lines):
        values = np.array([fields for _, fields in lines], dtype=float)  # every line at once (a file of 10^6 lines)
        cov = values[:, 4:].reshape(-1, 3, 3)
        diagonal = np.diagonal(cov, axis1=1, axis2=2)
        asymmetry = np.max(np.abs(cov - cov.transpose(0, 2, 1)), axis=(1, 2))
        if not (np.all(np.isfinite(values) & (values >= low) & (values <= high)) and np.all(diagonal > 0.0)
                and np.all(asymmetry <= 1e-9 + 1e-6 * np.max(np.abs(cov), axis=(1, 2)))):
            values = None
    if values is None:  # a flaw: found and named, line by line
        for number, fields in lines:
            where = f"{what}: {str(path)!r} line {number}"
            if len(fields) != POS_FIELDS:
                raise ModelError(f"{where} has {len(fields)} fields, {POS_FIELDS} expected (time, x, y, z and 9 "
                                 "covariance entries; a truncated file?)")
            one = [table_number(f, where, f"column {k + 1} ({name})", lo, hi)
                   for k, (f, name, lo, hi) in enumerate(zip(fields, names, low, high))]
            cov = np.array(one[4:]).reshape(3, 3)
            if np.any(np.diag(cov) <= 0.0):
                raise ModelError(f"{where}: the covariance's diagonal (columns 5, 9, 13) must be > 0 m^2")
            if np.max(np.abs(cov - cov.T)) > 1e-9 + 1e-6 * np.max(np.abs(cov)):
                raise ModelError(f"{where}: the covariance (columns 5-13) is not symmetric")
    frame = pd.DataFrame(values, columns=["t_j2000_s", "x_m", "y_m", "z_m", *[f"c{k}" for k in range(9)]])
    frame.insert(0, "line", np.array([number for number, _ in lines], dtype=np.int64))
    cov = frame[[f"c{k}" for k in range(9)]].to_numpy().reshape(-1, 3, 3)
    try:
        np.linalg.cholesky(0.5 * (cov + cov.transpose(0, 2, 1)))
    except np.linalg.LinAlgError:  # which line: one at a time, only now
        for line, one in zip(frame["line"], cov):
            try:
                np.linalg.cholesky(0.5 * (one + one.T))
            except np.linalg.LinAlgError:
                raise ModelError(f"{what}: {str(path)!r} line {line}: the covariance (columns 5-13) is not positive "
                                 "definite (a covariance has positive variances and correlations within ±1)") \
                    from None
    return frame


__all__ = ["J2000_POSIX", "J2000_RANGE", "MAX_COV_M2", "MAX_ECEF_M", "MAX_TWTT_US", "POS_FIELDS", "read_posfilter",
           "read_pxp_tt"]
