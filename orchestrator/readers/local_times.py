"""Times a study's people write in their own local time (actel's deployments and release dates, in the study's time
zone: actel's ``tz``), read to seconds since 1970-01-01 UTC.

A time that carries its offset (``2021-03-20 09:30:00+01:00``, ``…Z``, ``… UTC``) is read as it says
(:func:`~sblsim.orchestrator.io.times.utc_seconds`); one that does not is a wall-clock time in the study's time zone,
an IANA name (``Europe/Copenhagen``: :func:`study_zone`, the tz database through :mod:`zoneinfo`), its offset that of
that date (summer time where the zone keeps it). Without a zone such a time is refused, never taken as UTC. A wall
time the zone skips (the hour the clocks go forward) or passes twice (the hour they go back) is refused in one line:
written with its offset it is read.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Sequence
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import ISO_TIME, utc_seconds

if TYPE_CHECKING:  # pandas is imported when a function runs (the commands' modules load without it)
    import pandas as pd

#: An IANA time zone's name: one to three parts of letters, digits, ``_ + -`` (``Europe/Copenhagen``,
#: ``America/Argentina/Buenos_Aires``, ``UTC``, ``Etc/GMT-1``).
ZONE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_+-]{0,29}(?:/[A-Za-z0-9_+-]{1,30}){0,2}")
#: An offset at the end of a time (after its date): ``Z``, ``UTC``, ``±hh``, ``±hh:mm``, ``±hhmm``.
OFFSET = re.compile(r"(?:Z|UTC|[+-][0-9]{2}(?::?[0-9]{2})?)$")
#: What a refusal for a time without an offset asks for.
ASK = "the study's time zone given (--tz, an IANA name such as Europe/Copenhagen), or each time with its offset"


def study_zone(name: str, where: str = "tz") -> ZoneInfo:
    """The study's time zone by its IANA name (``Europe/Copenhagen``).

    Raises
    ------
    ModelError
        A name that is not one (one line naming ``where``, the name and an example).
    """
    text = name if isinstance(name, str) else ""
    if not ZONE_NAME.fullmatch(text):
        raise ModelError(f"{where}: {str(name)[:40]!r} is not allowed; allowed: an IANA time zone's name such as "
                         "Europe/Copenhagen or UTC")
    try:
        return ZoneInfo(text)
    except (ZoneInfoNotFoundError, ValueError):
        raise ModelError(f"{where}: {text!r} is not a time zone of the tz database; allowed: an IANA name such as "
                         "Europe/Copenhagen, America/Halifax or UTC") from None


def local_seconds(cells: pd.Series | Sequence[str], zone: str | None, where: str, lines: Sequence[int],
                  column: str, missing: bool = False) -> np.ndarray:
    """A column of times (ISO 8601), each with its offset or in the study's time zone ``zone`` (module docstring),
    as seconds since 1970-01-01 UTC.

    Parameters
    ----------
    cells : pandas.Series or sequence of str
        The column's text cells.
    zone : str or None
        The study's IANA time zone; None: every time must carry its offset.
    where : str
        The file, as a refusal names it (``"receivers: 'deployments.csv'"``).
    lines : sequence of int
        Each cell's line in the file.
    column : str
        The column's name in the file.
    missing : bool
        Empty cells allowed (NaN).

    Returns
    -------
    numpy.ndarray
        (n,) [s since 1970-01-01 UTC]; NaN for an empty cell where ``missing``.

    Raises
    ------
    ModelError
        One line naming the file, the line and the column: a time neither ISO 8601 nor epoch seconds, one without
        an offset where no zone is given, a wall time the zone skips or passes twice, a zone that is not one.
    """
    import pandas as pd

    text = pd.Series(cells, dtype=object).astype(str).str.strip().reset_index(drop=True)
    seconds = utc_seconds(text, where, lines, column, missing=missing)  # every cell checked: its form, its range
    iso = text.str.fullmatch(ISO_TIME.pattern).to_numpy(bool)
    naive = iso & ~text.str.slice(10).str.contains(OFFSET.pattern, regex=True).to_numpy(bool)
    if not naive.any():
        return seconds
    if zone is None:
        k = int(np.flatnonzero(naive)[0])
        raise ModelError(f"{where} line {lines[k]} column {column}: {text[k][:40]!r} carries no UTC offset, and these "
                         f"times are the study's local time (never taken as UTC); allowed: {ASK} (+01:00)")
    tz = study_zone(zone)
    wall = seconds[naive]
    whole = np.floor(wall)
    stamps = pd.Series(pd.to_datetime(whole.astype(np.int64), unit="s"))
    local = stamps.dt.tz_localize(tz, ambiguous="NaT", nonexistent="NaT")
    bad = local.isna().to_numpy(bool)
    if bad.any():
        k = int(np.flatnonzero(naive)[np.flatnonzero(bad)[0]])
        skipped = stamps.iloc[[int(np.flatnonzero(bad)[0])]].dt.tz_localize(
            tz, ambiguous=np.array([True]), nonexistent="NaT").isna().iloc[0]
        happens = "skips (the clocks go forward)" if skipped else "passes twice (the clocks go back)"
        raise ModelError(f"{where} line {lines[k]} column {column}: {text[k][:40]!r} is a wall time {zone} "
                         f"{happens}; allowed: the time written with its UTC offset (e.g. +01:00)")
    utc = local.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(dtype="datetime64[s]").astype(np.int64)
    seconds[naive] = utc.astype(float) + (wall - whole)
    return seconds


__all__ = ["ASK", "OFFSET", "ZONE_NAME", "local_seconds", "study_zone"]
