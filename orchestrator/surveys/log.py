"""The calibration survey log: sblsim's own format of a GNSS-Acoustic (box-in) survey, and its reader.

One row per reply (CSV with a header row and ``#`` comment lines, or Parquet), SI units in the column names
(:data:`COLUMNS`; docs/calibration.md). Every reader of another format (:mod:`sblsim.orchestrator.surveys.xie`,
the GNATSS reader) produces this table. :func:`read_survey_log` reads a file with the hostile-safe table reading of
``sblsim replay`` (:mod:`sblsim.orchestrator.io.log_tables`: a regular file only, read in pieces whatever its length,
each line's bytes and cells bounded before it is parsed, line numbers in every error) and refuses any flaw with one
line naming the line and the column: a log never runs code and never makes us read or write a path it names.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.calibration import Replies
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.limits import MEMORY_SHARE, available_memory
from sblsim.orchestrator.io.log_tables import TextTable, check_fits, columns, table_chunks, table_length
from sblsim.orchestrator.io.output import write_atomic
from sblsim.orchestrator.io.tables import NUMBER, number

#: POSIX times accepted [s] (1970 to 2100).
TIME_RANGE = (0.0, 4_102_444_800.0)
#: Local ENU coordinates accepted [m] (a survey's frame spans at most 100 km).
POSITION_RANGE = (-1e5, 1e5)
#: Transducer 1-sigma accepted [m] (> 0).
SIGMA_RANGE = (1e-9, 100.0)
#: Two-way travel times accepted [s] (> 0; 60 s is 45 km of water).
TWTT_RANGE = (1e-9, 60.0)
#: The largest ping index.
MAX_PING = 2**53
#: A transponder id: 1 to 32 letters, digits, ``_``, ``-`` or ``.``.
TRANSPONDER_ID = re.compile(r"[A-Za-z0-9_.\-]{1,32}")

#: The log's columns, declared once: name -> (kind, unit, allowed range, meaning).
COLUMNS: dict[str, tuple[str, str, tuple[float, float] | None, str]] = {
    "ping": ("int", "1", (0, MAX_PING), "the interrogation's index; every reply to one transmission has the same ping"),
    "transponder": ("str", "", None, "the replying transponder's id (replies are paired with transponders by this "
                    "id, never by arrival order)"),
    "t_tx_s": ("float", "s", TIME_RANGE, "transmit time, POSIX seconds (UTC, since 1970-01-01T00:00:00)"),
    "tx_e_m": ("float", "m", POSITION_RANGE, "the surface transducer at transmit, local East of the survey's origin"),
    "tx_n_m": ("float", "m", POSITION_RANGE, "the surface transducer at transmit, local North"),
    "tx_u_m": ("float", "m", POSITION_RANGE, "the surface transducer at transmit, local Up"),
    "tx_sigma_e_m": ("float", "m", SIGMA_RANGE, "1-sigma of tx_e_m (> 0)"),
    "tx_sigma_n_m": ("float", "m", SIGMA_RANGE, "1-sigma of tx_n_m (> 0)"),
    "tx_sigma_u_m": ("float", "m", SIGMA_RANGE, "1-sigma of tx_u_m (> 0)"),
    "t_rx_s": ("float", "s", TIME_RANGE, "the reply's receive time, POSIX seconds (not before t_tx_s)"),
    "rx_e_m": ("float", "m", POSITION_RANGE, "the transducer at the reply's receive time, local East"),
    "rx_n_m": ("float", "m", POSITION_RANGE, "the transducer at the reply's receive time, local North"),
    "rx_u_m": ("float", "m", POSITION_RANGE, "the transducer at the reply's receive time, local Up"),
    "rx_sigma_e_m": ("float", "m", SIGMA_RANGE, "1-sigma of rx_e_m (> 0)"),
    "rx_sigma_n_m": ("float", "m", SIGMA_RANGE, "1-sigma of rx_n_m (> 0)"),
    "rx_sigma_u_m": ("float", "m", SIGMA_RANGE, "1-sigma of rx_u_m (> 0)"),
    "twtt_s": ("float", "s", TWTT_RANGE, "two-way travel time, the transponder's turnaround (and any transducer "
               "delay) removed (> 0)"),
}
#: The column names in their documented order.
LOG_COLUMNS = tuple(COLUMNS)
#: The log's columns of numbers that are not whole (all but ``ping`` and ``transponder``), in their order.
_FLOATS = tuple(name for name, (kind, *_) in COLUMNS.items() if kind == "float")
#: The memory a reply takes while its log is read and checked [bytes] (its numbers and id as read, the frame made of
#: them, the checks' copies and sorted frame, its place in the file; measured on a log of 10**6 replies).
ROW_BYTES = 700
#: Title line a written CSV log starts with.
TITLE = "sblsim calibration survey log, format 1"


@dataclass
class SurveyLog:
    """A calibration survey log read and checked.

    Attributes
    ----------
    frame : pandas.DataFrame
        One row per reply, the columns :data:`LOG_COLUMNS` (``ping`` int64, ``transponder`` str, the rest float64),
        sorted by ``t_tx_s``, ``ping`` and ``transponder``.
    source : str
        The file it came from (for messages).
    where : list of str
        Each row's place in the file (``line 12``, ``row 3``), in the frame's order.
    counts : dict
        What the reader found: ``rows``, ``pings``, ``transponders`` (replies per id), ``ignored_columns``.
    """

    frame: pd.DataFrame
    source: str
    where: list[str] = field(default_factory=list)
    counts: dict = field(default_factory=dict)

    def replies(self, ids: list[str], rows: np.ndarray | None = None) -> Replies:
        """The replies (all, or ``rows``) as arrays for :func:`sblsim.models.calibration.solve`.

        Parameters
        ----------
        ids : list of str
            The transponders, in the order of the a-priori positions; every row's id must be one of them.
        rows : numpy.ndarray or None
            Positions of the rows to take (default all).
        """
        f = self.frame if rows is None else self.frame.iloc[rows]
        index = {name: k for k, name in enumerate(ids)}
        unknown = sorted(set(f["transponder"]) - set(index))
        if unknown:
            raise ModelError(f"transponder: {unknown[0]!r} in {self.source!r} is not a transponder of the site "
                             f"({', '.join(ids)})")

        def block(prefix: str) -> np.ndarray:
            return f[[f"{prefix}_e_m", f"{prefix}_n_m", f"{prefix}_u_m"]].to_numpy(float)

        return Replies(block("tx"), block("tx_sigma"), block("rx"), block("rx_sigma"), f["twtt_s"].to_numpy(float),
                       f["transponder"].map(index).to_numpy(int), f["t_tx_s"].to_numpy(float),
                       f["t_rx_s"].to_numpy(float))


def check_frame(frame: pd.DataFrame, where: list[str], source: str) -> SurveyLog:
    """Check a table of replies in the log format and return it sorted (the readers' common end).

    Every value is checked against :data:`COLUMNS`' ranges; two replies of one ping from one transponder, a
    ping whose replies disagree on the transmit time or a reply received before its transmission are refused.

    Parameters
    ----------
    frame : pandas.DataFrame
        The columns :data:`LOG_COLUMNS` (already numbers and strings).
    where : list of str
        Each row's place in its file (for messages).
    source : str
        The file's name (for messages).

    Raises
    ------
    ModelError
        Naming the row's place, the column and the allowed range.
    """
    frame = frame.reset_index(drop=True)
    frame["transponder"] = frame["transponder"].astype(object)
    for name, (kind, _, bounds, _) in COLUMNS.items():
        if kind != "float":
            continue
        values = frame[name].to_numpy(float)
        bad = ~(np.isfinite(values) & (values >= bounds[0]) & (values <= bounds[1]))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ModelError(f"{source!r} {where[k]}: {name}: {values[k]!r} is outside the allowed range "
                             f"[{bounds[0]:g}, {bounds[1]:g}]")
    late = frame["t_rx_s"].to_numpy() < frame["t_tx_s"].to_numpy()
    if late.any():
        k = int(np.flatnonzero(late)[0])
        raise ModelError(f"{source!r} {where[k]}: t_rx_s is before t_tx_s (a reply is received after its "
                         "transmission)")
    twice = frame.duplicated(["ping", "transponder"], keep=False).to_numpy()
    if twice.any():
        k = np.flatnonzero(twice)
        first = int(k[0])
        other = int(next(j for j in k[1:] if frame.at[j, "ping"] == frame.at[first, "ping"]
                         and frame.at[j, "transponder"] == frame.at[first, "transponder"]))
        raise ModelError(f"{source!r} {where[other]}: ping {frame.at[first, 'ping']} has a second reply from "
                         f"transponder {frame.at[first, 'transponder']!r} (the first: {where[first]})")
    by_ping = frame.groupby("ping")["t_tx_s"]
    spread = by_ping.max() - by_ping.min()
    if (spread > 1e-6).any():
        ping = spread.index[int(np.argmax((spread > 1e-6).to_numpy()))]
        k = int(np.flatnonzero(frame["ping"].to_numpy() == ping)[-1])
        raise ModelError(f"{source!r} {where[k]}: the replies of ping {ping} have different t_tx_s (one "
                         "transmission has one transmit time)")
    order = np.lexsort((frame["transponder"].to_numpy(str), frame["ping"].to_numpy(), frame["t_tx_s"].to_numpy()))
    if np.any(order != np.arange(len(order))):  # a log in order (as recorded, as written) is not copied
        frame = frame.iloc[order].reset_index(drop=True)
        where = [where[k] for k in order]
    counts = {"rows": len(frame), "pings": int(frame["ping"].nunique()),
              "transponders": {str(k): int(v) for k, v in frame["transponder"].value_counts().sort_index().items()}}
    return SurveyLog(frame, source, where, counts)


def read_survey_log(path: Path | str) -> SurveyLog:
    """Read a calibration survey log (CSV or Parquet, :data:`COLUMNS`).

    Read in pieces (:func:`~sblsim.orchestrator.io.log_tables.table_chunks`), each piece's cells checked and kept as
    numbers, so that a log of any length is read in the memory its numbers take (about :data:`ROW_BYTES` a reply);
    one whose replies would not fit in the memory available here is refused before it is read
    (:func:`~sblsim.orchestrator.io.log_tables.check_fits`). Columns beyond :data:`LOG_COLUMNS` are ignored
    (counted in ``counts["ignored_columns"]``).

    Parameters
    ----------
    path : pathlib.Path or str
        A ``.csv`` or ``.parquet`` file.

    Returns
    -------
    SurveyLog

    Raises
    ------
    ModelError
        One line naming the file, the line (or row) and the column: a missing file, one that is not a regular
        file, one too large for the memory here, a line too long or of too many cells, not UTF-8, a missing column,
        a cell that is not a number or outside its range, a transponder id that is not 1-32 letters, digits,
        ``_``, ``-`` or ``.``, or the flaws of :func:`check_frame`; or a log without rows.
    """
    path = Path(path)
    what = "log"
    rows = table_length(path, what)
    check_fits(path, what, rows, ROW_BYTES, MEMORY_SHARE * available_memory())
    header: list[str] = []
    index: dict[str, int] = {}
    floats = np.empty((rows, len(_FLOATS)))  # filled piece by piece: the numbers are held once, not joined
    pings, ids = np.empty(rows, np.int64), np.empty(rows, object)
    where: list[str] = []
    for table in table_chunks(path, what):
        if not header:
            header, index = table.header, columns(table, what)
            missing = [name for name in LOG_COLUMNS if name not in index]
            if missing:
                raise ModelError(f"{what}: {str(path)!r} lacks the column{'s' if len(missing) > 1 else ''} "
                                 f"{', '.join(missing)} (the calibration log's columns: {', '.join(LOG_COLUMNS)})")
        if not table.rows:
            continue
        data = _columns(table, index)
        if data is None:  # a cell that is not what its column takes: found and named, cell by cell
            _refuse_cell(table, index, what)
        done = slice(len(where), len(where) + len(table.rows))
        pings[done], ids[done] = data["ping"], data["transponder"]
        for j, name in enumerate(_FLOATS):
            floats[done, j] = data[name]
        where += [place for place, _ in table.rows]
    if not where:
        raise ModelError(f"{what}: {str(path)!r} holds no reply (only a header)")
    n = len(where)
    frame = pd.DataFrame(floats[:n], columns=list(_FLOATS), copy=False)
    frame.insert(0, "ping", pings[:n])
    frame.insert(1, "transponder", ids[:n])
    log = check_frame(frame, where, str(path))
    log.counts["ignored_columns"] = [name for name in header if name not in COLUMNS]
    return log


def _refuse_cell(table: TextTable, index: dict[str, int], what: str) -> None:
    """Refuse the first cell of a piece of a log that is not what its column takes (its line and column named)."""
    for place, cells in table.rows:
        here = f"{what}: {str(table.path)!r} {place}"
        for name, (kind, _, bounds, _) in COLUMNS.items():
            text = cells[index[name]]
            if kind == "str":
                if not TRANSPONDER_ID.fullmatch(text):
                    raise ModelError(f"{here}: {name}: {text[:40]!r} is not an id (1-32 letters, digits, _, - or .)")
                continue
            value = number(text, here, name, *bounds)
            if kind == "int" and value != int(value):
                raise ModelError(f"{here}: {name}: {text[:40]!r} is not a whole number")
    raise AssertionError("a piece refused as a whole has no bad cell")  # pragma: no cover


def _columns(table: TextTable, index: dict[str, int]) -> dict[str, np.ndarray] | None:
    """The log's columns of a piece's text cells as arrays, a column at a time, or None when a cell is not what its
    column takes (:func:`_refuse_cell` then finds and names it). The ids are shared strings (one object per id, not
    per reply)."""
    data = {}
    for name, (kind, _, bounds, _) in COLUMNS.items():
        texts = [cells[index[name]] for _, cells in table.rows]
        if kind == "str":
            if not all(map(TRANSPONDER_ID.fullmatch, texts)):
                return None
            ids = pd.Categorical(texts)
            data[name] = np.asarray(ids.categories, dtype=object)[ids.codes]
            continue
        if not all(map(NUMBER.fullmatch, texts)):
            return None
        values = np.array(texts, dtype=float)
        if not np.all(np.isfinite(values) & (values >= bounds[0]) & (values <= bounds[1])):
            return None
        if kind == "int":
            if not np.all(values == np.floor(values)):
                return None
            values = values.astype(np.int64)
        data[name] = values
    return data


def write_log(log: SurveyLog, path: Path | str) -> Path:
    """Write a log as CSV (with :data:`TITLE`) or Parquet, by the suffix, atomically.

    Raises
    ------
    ModelError
        A suffix other than .csv or .parquet.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise ModelError(f"log: {str(path)!r} must be a .csv or .parquet file")
    frame = log.frame[list(LOG_COLUMNS)]

    def write(tmp: Path) -> None:
        if suffix == ".parquet":
            frame.to_parquet(tmp, index=False)
        else:
            tmp.write_text(f"# {TITLE}\n" + frame.to_csv(index=False, float_format=None))

    write_atomic(path, write)
    return path


__all__ = ["COLUMNS", "LOG_COLUMNS", "POSITION_RANGE", "ROW_BYTES", "SIGMA_RANGE", "SurveyLog", "TIME_RANGE", "TITLE",
           "TWTT_RANGE", "check_frame", "read_survey_log", "write_log"]
