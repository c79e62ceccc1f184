"""Times as a study's files give them, read to seconds since 1970-01-01 UTC, and written back as ISO 8601 UTC.

A column of times is either **ISO 8601** text (``2023-08-31T21:15:42.123456Z``, ``2023-08-31 21:15:42.1``, a
date alone ``2023-08-31`` for midnight, a zone ``+02:00`` / ``-0500`` / ``Z`` / ``UTC``; without a zone the time is
UTC, as every export this project reads states: VUE's ``Date and Time (UTC)``, Fathom's ``Device Time (UTC)``,
GLATOS's ``detection_timestamp_utc``, OTN's ``dateCollectedUTC``) or **epoch seconds** (a number of seconds since
1970-01-01 UTC, a fraction kept), never both in one column. The fraction of a second is kept to the nanosecond
the text gives (pandas' ``datetime64[ns]``), returned as float seconds (a microsecond resolves at 1e-7 s near
2030, below a millimetre of sound's travel).

Every cell is matched against its pattern before pandas parses it (:data:`ISO_TIME`: no free text reaches the
parser) and the first bad one is refused in one line naming the file, its line and column and the allowed forms.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Sequence

import numpy as np

from sblsim.models.declarations import ModelError

if TYPE_CHECKING:  # pandas is imported when a function runs (the commands' modules load without it)
    import pandas as pd

#: An ISO 8601 date and time: a date, optionally a time (``T`` or a space, seconds optional, a fraction of up to
#: nine digits after ``.`` or ``,``) and optionally a zone (``Z``, ``UTC``, ``±hh``, ``±hh:mm``, ``±hhmm``).
ISO_TIME = re.compile(r"[0-9]{4}-[0-9]{2}-[0-9]{2}"
                      r"(?:[T ][0-9]{2}:[0-9]{2}(?::[0-9]{2}(?:[.,][0-9]{1,9})?)?)?"
                      r"(?: ?(?:Z|UTC|[+-][0-9]{2}(?::?[0-9]{2})?))?")
#: The ISO 8601 times pandas parses as they are (:data:`ISO_TIME` without a decimal comma, ``UTC`` or a space before
#: the zone, which are normalised first).
PLAIN_TIME = re.compile(r"[0-9]{4}-[0-9]{2}-[0-9]{2}"
                        r"(?:[T ][0-9]{2}:[0-9]{2}(?::[0-9]{2}(?:\.[0-9]{1,9})?)?)?"
                        r"(?:Z|[+-][0-9]{2}(?::?[0-9]{2})?)?")
#: Epoch seconds: a plain decimal number (no exponent, no sign: 1970 onwards).
EPOCH = re.compile(r"[0-9]{1,11}(?:\.[0-9]{0,9})?")
#: The latest time allowed [s since 1970-01-01 UTC]: 2262-04-11T23:47:16Z, the latest whole second pandas' timestamps
#: (nanoseconds in 64 bits) hold, which every time read and written passes through.
MAX_EPOCH = 9_223_372_036
#: The times allowed, as a refusal says them.
TIME_SPAN = "a time from 1970-01-01 to 2262-04-11T23:47:16 (UTC: the latest a 64-bit nanosecond timestamp holds)"
#: What a refusal names as allowed.
ALLOWED = ("an ISO 8601 time (2023-08-31T21:15:42.123Z; UTC unless a zone is given) or epoch seconds "
           "(1693516542.123)")

#: A spreadsheet's date as a locale shows it (``6/3/2024 0:01``, ``03.06.2024 00:01:07``): day and month in the
#: locale's order, the seconds' fraction (often the seconds) dropped when the file was opened and saved again.
SPREADSHEET_DATE = re.compile(r"[0-9]{1,2}[/.][0-9]{1,2}[/.][0-9]{2,4}(?: [0-9]{1,2}:[0-9]{2}(?::[0-9]{2})?"
                              r"(?: ?[AaPp][Mm])?)?")
#: What a refusal of such a date adds.
SPREADSHEET_SAID = ("; this is a spreadsheet's date (the file opened and saved again: its day and month in the "
                    "locale's order, its seconds' fraction dropped): give the file as exported")


def _refuse(where: str, line: int, column: str, text: str, allowed: str = ALLOWED) -> ModelError:
    shown = text if len(text) <= 40 else text[:40] + "..."
    return ModelError(f"{where} line {line} column {column}: {shown!r} is not allowed; allowed: {allowed}")


def _exists(date: str) -> bool:
    """Whether an ISO 8601 date (``YYYY-MM-DD``) exists, whatever its year (numpy's days reach far beyond pandas')."""
    try:
        np.datetime64(date, "D")
    except ValueError:
        return False
    return True


def is_epoch(cells: pd.Series) -> bool:
    """Whether a column's non-empty cells are all epoch seconds (else they must all be ISO 8601)."""
    text = cells.astype(str).str.strip()
    text = text[text != ""]
    if not len(text) or not EPOCH.fullmatch(text.iloc[0]):  # the first not epoch seconds: the column is not
        return False
    return bool(text.str.fullmatch(EPOCH.pattern).all())


def _zoneless_nanoseconds(cells: pd.Series) -> np.ndarray | None:
    """Cells of :data:`PLAIN_TIME` parsed by Arrow's ISO 8601 cast to a timestamp without a zone (C++: 0.07 s for
    2.7 M cells of a VUE export, where pandas' parse took 0.76 s) as nanoseconds since 1970-01-01 UTC (a time
    without a zone is UTC: the module docstring); None where Arrow refuses any cell: a zone (``Z``, ``+02:00``),
    a date or time that does not exist, a time beyond a 64-bit nanosecond timestamp. pandas' parse then reads
    those cells or names the first bad one, as it did every cell before; where Arrow reads them, both give the
    same nanoseconds (``tests/orchestrator/test_time_span.py``)."""
    import pyarrow as pa

    try:
        stamps = pa.array(cells).cast(pa.timestamp("ns"))
    except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
        return None
    if stamps.null_count:
        return None
    return stamps.cast(pa.int64()).to_numpy()


def utc_seconds(cells: pd.Series | Sequence[str], where: str, lines: Sequence[int], column: str,
                missing: bool = False) -> np.ndarray:
    """A column of times (module docstring) as seconds since 1970-01-01 UTC.

    Parameters
    ----------
    cells : pandas.Series or sequence of str
        The column's text cells.
    where : str
        The file, as a refusal names it (``"detections: 'x.csv'"``).
    lines : sequence of int
        Each cell's line in the file.
    column : str
        The column's name in the file.
    missing : bool
        Empty cells allowed (NaN).

    Returns
    -------
    numpy.ndarray
        (n,) [s since 1970-01-01 UTC], float; NaN for an empty cell where ``missing``.

    Raises
    ------
    ModelError
        One line naming the file, the line and the column: a cell neither form, an ISO time that does not exist
        (``2023-02-30``), a column mixing the forms, a time outside :data:`TIME_SPAN`.
    """
    import pandas as pd

    plain = False  # every cell a PLAIN_TIME as it is: none to strip, none empty
    if isinstance(cells, pd.Series) and pd.api.types.is_string_dtype(cells) and not cells.isna().any():
        text = cells.reset_index(drop=True)  # a table's text cells
        plain = len(text) > 0 and bool(text.str.fullmatch(PLAIN_TIME.pattern).all())
        text = text if plain else text.str.strip()
    else:
        text = pd.Series(cells, dtype=object).astype(str).str.strip().reset_index(drop=True)
    empty = np.zeros(len(text), bool) if plain else (text == "").to_numpy(bool)
    if empty.any() and not missing:
        k = int(np.flatnonzero(empty)[0])
        raise _refuse(where, lines[k], column, "", ALLOWED)
    given = text[~empty] if empty.any() else text
    seconds = np.full(len(text), np.nan)
    if not len(given):
        return seconds
    if not plain and is_epoch(given):
        values = pd.to_numeric(given, errors="coerce").to_numpy(float)
    else:
        normal = given
        if not plain and not given.str.fullmatch(PLAIN_TIME.pattern).all():  # else ISO 8601 as pandas parses it
            iso = given.str.fullmatch(ISO_TIME.pattern).to_numpy(bool)
            if not iso.all():
                k = int(given.index[np.flatnonzero(~iso)[0]])
                allowed = ALLOWED + (" (one form per column)" if given.str.fullmatch(EPOCH.pattern).any() else "")
                allowed += SPREADSHEET_SAID if SPREADSHEET_DATE.fullmatch(text[k]) else ""
                raise _refuse(where, lines[k], column, text[k], allowed)
            normal = given.str.replace(",", ".", regex=False).str.replace(r" ?UTC$", "Z", regex=True)
            normal = normal.str.replace(r"(?<=[0-9]) (?=[Z+-])", "", regex=True)
        nanoseconds = _zoneless_nanoseconds(normal) if normal is given else None
        if nanoseconds is None:
            stamps = pd.to_datetime(normal, format="ISO8601", utc=True, errors="coerce")
            bad = stamps.isna().to_numpy(bool)
            if bad.any():
                k = int(given.index[np.flatnonzero(bad)[0]])
                late = int(text[k][:4]) >= 2262 and _exists(text[k][:10])  # a real date beyond the span
                raise _refuse(where, lines[k], column, text[k],
                              TIME_SPAN if late else "a date and time that exists (ISO 8601)")
            nanoseconds = stamps.to_numpy(dtype="datetime64[ns]").astype(np.int64)
        whole, rest = np.divmod(nanoseconds, 1_000_000_000)
        values = whole.astype(float) + rest / 1e9
    outside = (values < 0) | (values > MAX_EPOCH) | ~np.isfinite(values)
    if outside.any():
        k = int(given.index[np.flatnonzero(outside)[0]])
        raise _refuse(where, lines[k], column, text[k], TIME_SPAN)
    seconds[~empty] = values
    return seconds


def iso_utc(seconds: np.ndarray | Sequence[float]) -> list[str]:
    """Seconds since 1970-01-01 UTC as ISO 8601 UTC texts to the microsecond (``2023-08-31T21:15:42.123456Z``),
    ``""`` where NaN."""
    import pandas as pd

    values = np.asarray(seconds, float)
    out = [""] * len(values)
    ok = np.isfinite(values)
    if ok.any():
        whole = np.floor(values[ok])
        micro = np.round((values[ok] - whole) * 1e6).astype(np.int64)
        stamps = pd.to_datetime(whole.astype(np.int64), unit="s", utc=True) + pd.to_timedelta(micro, unit="us")
        for k, text in zip(np.flatnonzero(ok), stamps.strftime("%Y-%m-%dT%H:%M:%S.%fZ")):
            out[k] = text
    return out


def parse_instant(value: str | float | int, where: str) -> float:
    """One time given on the command line or to a function (ISO 8601 or epoch seconds) as seconds since
    1970-01-01 UTC.

    Raises
    ------
    ModelError
        One line naming ``where`` and the allowed forms.
    """
    text = str(value).strip() if isinstance(value, str) else repr(float(value)) if isinstance(
        value, (int, float, np.floating, np.integer)) and not isinstance(value, bool) else None
    if text is None or len(text) > 64:
        raise ModelError(f"{where}: {str(value)[:40]!r} is not allowed; allowed: {ALLOWED}")
    try:
        return float(utc_seconds([text], where, [1], "value")[0])
    except ModelError:
        raise ModelError(f"{where}: {text[:40]!r} is not allowed; allowed: {ALLOWED}") from None


__all__ = ["ALLOWED", "EPOCH", "ISO_TIME", "MAX_EPOCH", "PLAIN_TIME", "SPREADSHEET_DATE", "SPREADSHEET_SAID",
           "TIME_SPAN", "is_epoch", "iso_utc", "parse_instant", "utc_seconds"]
