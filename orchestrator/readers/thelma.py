"""Thelma Biomedical's TBR receivers' detection exports, in the two layouts actel reads (actel's
``processThelmaOldFile`` and ``processThelmaNewFile``; Flávio & Baktoft 2021, Methods Ecol. Evol. 12:196), each told
from its header (:data:`OLD_FINGERPRINT`, :data:`NEW_FINGERPRINT`, as actel tells them):

* the **old** layout: ``Date and Time (UTC)``, ``TBR Serial Number`` (the receiver), ``Unix Timestamp (UTC)`` (whole
  seconds since 1970), ``Millisecond`` (the millisecond of that second, 0 to 999), ``CodeType`` (the code space:
  ``R64K``, ``S256``, …), ``Id`` (the transmitter's id), ``Data`` (a sensor tag's raw value), ``Signal to Noise
  Ratio``;
* the **new** layout: ``Date and Time (UTC)``, ``Unix Timestamp (UTC)``, ``ID``, ``Data``, ``Protocol`` (the code
  space and the frequency: ``R64K-69kHz``, the code space before the dash), ``SNR``, ``Receiver``.

A detection's time is its whole second (``Unix Timestamp (UTC)`` where given, else ``Date and Time (UTC)``: ISO
8601, UTC) and its millisecond (``Millisecond`` where given; actel reads the date alone, whole seconds, a second of
sound's travel: about 1,500 m). Where both the date and the Unix timestamp are given they must name the same
second, else the row is refused. A Unix timestamp of 12 or 13 digits is in milliseconds (a count of seconds that
large is past the year 5000); one of seconds may carry a fraction, kept where no ``Millisecond`` is given. ``-`` (or
``NA``, or empty) is a missing cell; ``Data`` is kept as a raw sensor value (unit ``raw``: a tag sheet's slope and
intercept convert it). A transmitter is its full ID, the code space and the id (``R64K-610``); the receiver is its
serial (``TBR700-1234`` keeps ``1234``).
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import column, numbers, pattern, refuse, shown_header
from sblsim.orchestrator.readers.network import RECEIVER
from sblsim.orchestrator.readers.sensors import sensor_columns
from sblsim.orchestrator.readers.transmitters import CODE_SPACE, TAG_ID, full_ids

#: The columns (lower case) that tell each layout, as actel's ``header_formats`` lists them.
OLD_FINGERPRINT = ("codetype", "tbr serial number", "id")
NEW_FINGERPRINT = ("protocol", "receiver", "id")
#: The cells that stand for a missing value.
MISSING = ("-", "NA", "")
#: A Unix timestamp: whole seconds (a fraction allowed), or milliseconds (12 or 13 digits, whole).
UNIX = re.compile(r"[0-9]{1,11}(?:\.[0-9]{1,9})?|[0-9]{12,13}")


def is_thelma(names: set[str]) -> bool:
    """Whether a header's names (lower case, stripped) are one of Thelma's layouts."""
    return set(OLD_FINGERPRINT) <= names or set(NEW_FINGERPRINT) <= names


def _blanked(cells: pd.Series) -> pd.Series:
    """A column's cells stripped, the missing ones (:data:`MISSING`) empty."""
    cells = cells.astype(str).str.strip()
    return cells.where(~cells.isin(MISSING), "")


def _unix(cells: pd.Series, what: str, name: str, lines: list[int], column_name: str) -> np.ndarray:
    """A ``Unix Timestamp (UTC)`` column as seconds since 1970 (NaN where missing): seconds, or milliseconds."""
    given = (cells != "").to_numpy(bool)
    out = np.full(len(cells), np.nan)
    if not given.any():
        return out
    at = np.flatnonzero(given)
    text = pattern(cells[given], UNIX, what, name, [lines[k] for k in at], column_name,
                   "whole seconds since 1970-01-01 UTC (a fraction allowed) or milliseconds (12 or 13 digits)")
    values = text.astype(float).to_numpy()
    out[at] = np.where(text.str.fullmatch(r"[0-9]{12,13}").to_numpy(bool), values / 1000.0, values)
    return out


def _times(body: pd.DataFrame, index: dict[str, int | None], header: list[str], lines: list[int], name: str,
           what: str) -> np.ndarray:
    """Each row's time [s since 1970 UTC]: its second from the Unix timestamp (else the date), its millisecond."""
    date = utc_seconds(_blanked(body[index["date"]]), f"{what}: {name!r}", lines, header[index["date"]],
                       missing=index["unix"] is not None) if index["date"] is not None else np.full(len(body), np.nan)
    unix = _unix(_blanked(body[index["unix"]]), what, name, lines, header[index["unix"]]) \
        if index["unix"] is not None else np.full(len(body), np.nan)
    both = np.isfinite(date) & np.isfinite(unix)
    apart = np.flatnonzero(both & (np.floor(date) != np.floor(unix)))
    if len(apart):
        k = int(apart[0])
        raise ModelError(f"{what}: {name!r} line {lines[k]}: {header[index['date']]} and {header[index['unix']]} name "
                         f"different seconds ({date[k]:.3f} and {unix[k]:.3f} s since 1970); allowed: the same time "
                         "in both")
    neither = np.flatnonzero(~np.isfinite(date) & ~np.isfinite(unix))
    if len(neither):
        k = int(neither[0])
        raise refuse(what, name, lines[k], header[index["unix"]], "", "a time (this column or "
                     f"{header[index['date']] if index['date'] is not None else 'Date and Time (UTC)'})")
    time = np.where(np.isfinite(unix), unix, date)
    if index["ms"] is not None:
        ms = numbers(_blanked(body[index["ms"]]), what, name, lines, header[index["ms"]], 0.0, 1000.0,
                     high_open=True, missing=True, unit="ms")
        time = np.where(np.isfinite(ms), np.floor(time) + ms / 1000.0, time)
    return time


def thelma(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
           ) -> tuple[pd.DataFrame, set[int]]:
    """A Thelma TBR export in either layout (the module docstring) as detections, in the file's order.

    Parameters
    ----------
    header : list of str
        The file's header.
    body : pandas.DataFrame
        (n, columns) its rows as text cells.
    lines : list of int
        (n,) each row's line in the file.
    name, what : str
        The file and what it is, as a refusal names them.

    Returns
    -------
    frame : pandas.DataFrame
        ``receiver``, ``tag`` (the full ID), ``code_space``, ``time`` [s since 1970 UTC on the receiver's clock],
        ``sensor_value`` (the raw ``Data``; NaN where missing), ``sensor_unit`` (``raw`` where given, else ``""``).
    used : set of int
        The columns read.

    Raises
    ------
    ModelError
        One line naming the file, its line and column and what is allowed: a layout's column missing, a cell
        outside its pattern or range, the date and the Unix timestamp naming different seconds.
    """
    old = column(header, ("tbr serial number",)) is not None
    index = {"date": column(header, ("date and time (utc)",)), "unix": column(header, ("unix timestamp (utc)",)),
             "ms": column(header, ("millisecond",)),
             "receiver": column(header, ("tbr serial number",) if old else ("receiver",)),
             "space": column(header, ("codetype",) if old else ("protocol",)),
             "id": column(header, ("id",)), "data": column(header, ("data",))}
    needed = {"receiver": "TBR Serial Number" if old else "Receiver", "space": "CodeType" if old else "Protocol",
              "id": "Id" if old else "ID"}
    missing = [shown for key, shown in needed.items() if index[key] is None] + \
        (["Date and Time (UTC) or Unix Timestamp (UTC)"] if index["date"] is None and index["unix"] is None else [])
    if missing:
        raise ModelError(f"{what}: {name!r}: a Thelma export ({'old' if old else 'new'} layout) needs the columns "
                         f"Date and Time (UTC) (or Unix Timestamp (UTC)), {', '.join(needed.values())}; "
                         f"{', '.join(missing)} missing, got {shown_header(header)}")
    time = _times(body, index, header, lines, name, what)
    receiver = pattern(body[index["receiver"]], RECEIVER, what, name, lines, header[index["receiver"]],
                       "a receiver's serial (or MODEL-SERIAL)").str.rpartition("-")[2]
    space = body[index["space"]].astype(str).str.strip()
    if not old:  # R64K-69kHz: the code space, then the frequency
        space = space.str.partition("-")[0]
    space = pattern(space, CODE_SPACE, what, name, lines, header[index["space"]],
                    "a code space (R64K, S256; a protocol R64K-69kHz)")
    ident = pattern(body[index["id"]], TAG_ID, what, name, lines, header[index["id"]],
                    "a transmitter's id of 1 to 40 letters, digits, '.' or '_'")
    frame = pd.DataFrame({"receiver": receiver.to_numpy(), "tag": full_ids(space, ident).to_numpy(),
                          "code_space": space.to_numpy(), "time": time})
    if index["data"] is not None:
        data = body[[index["data"]]].copy()
        data[index["data"]] = _blanked(data[index["data"]])
        value, _ = sensor_columns(data, index["data"], None, header, lines, name, what)
    else:
        value = np.full(len(body), np.nan)
    frame["sensor_value"] = value
    frame["sensor_unit"] = np.where(np.isfinite(value), "raw", "")
    return frame, {k for k in index.values() if k is not None}


__all__ = ["MISSING", "NEW_FINGERPRINT", "OLD_FINGERPRINT", "UNIX", "is_thelma", "thelma"]
