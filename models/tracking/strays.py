"""Stray rows: the rows of a TOA matrix that cannot be pings of a tag whose pings are at least a given interval
apart (a stray code, a collision, an echo beyond the grouping's window), set aside; and a stated interval refused
where it would set aside too many of the rows (the detections contradict it as a whole). Units: seconds [s].
"""

from __future__ import annotations

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.schedule import first_arrivals

#: The largest share of a record's heard rows a stated interval may set aside as strays (:func:`stray_rows`): more,
#: and the detections contradict the interval as a whole (:func:`check_strays`). A raw recording's stray codes and
#: collisions are a few per cent of its rows.
STRAY_SHARE = 0.10
#: The reason a row set aside carries (``quality_reason``, ``set_aside.csv``).
SET_ASIDE_REASON = "set_aside_not_a_ping"


def stray_rows(toa: np.ndarray, shortest: float, crossing: float) -> np.ndarray:
    """The rows that cannot be pings of a tag whose pings are at least ``shortest`` [s] apart: a stray code, a
    collision, an echo beyond the grouping's window.

    The heard rows are walked in time order against the last row kept: a row whose first arrival is less than
    ``shortest − crossing`` after it (the first arrival's travel time changes by at most the crossing time) conflicts
    with it, and of the two the row heard by more receivers is kept (a tie: the earlier), the other set aside. A row
    heard by nobody is no ping (its time is unknown) and takes no part.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard; rows in time order.
    shortest : float
        The shortest interval between two pings [s] (``rbi``: its min; ``pbi``: the sequence's least).
    crossing : float
        The array's crossing time [s] (:func:`~sblsim.models.tracking.schedule.crossing_time`).

    Returns
    -------
    ndarray of bool, (m,)
        True where a row is set aside.
    """
    toa = np.asarray(toa, float)
    first = first_arrivals(toa)
    count = np.isfinite(toa).sum(axis=1)
    heard = np.flatnonzero(np.isfinite(first))
    stray = np.zeros(len(first), bool)
    limit = shortest - crossing
    if len(heard) < 2 or not (np.diff(first[heard]) < limit).any():
        return stray
    last = int(heard[0])
    for k in heard[1:]:
        if first[k] - first[last] >= limit:
            last = int(k)
        elif count[k] > count[last]:  # the row heard by more receivers is the ping
            stray[last], last = True, int(k)
        else:
            stray[k] = True
    return stray


def check_strays(toa: np.ndarray, stray: np.ndarray, stated: str, shortest: float, force: bool = False,
                 option: str = "--force-interval") -> str | None:
    """Refuse a stated interval the rows contradict as a whole: more than :data:`STRAY_SHARE` of the heard rows set
    aside by it (:func:`stray_rows`), where a few stray codes and collisions would be a few per cent.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard (before any row is set aside).
    stray : ndarray of bool, (m,)
        The rows :func:`stray_rows` sets aside.
    stated : str
        The interval as stated, for the message (e.g. ``"150:300 s"``).
    shortest : float
        Its shortest interval [s].
    force : bool
        Take the stated interval whatever the rows show: the message is returned, a warning, not raised.
    option : str
        How the caller spells the override.

    Returns
    -------
    str or None
        With ``force``, the line that says how much the stated interval sets aside where it is contradicted; else
        None.

    Raises
    ------
    ModelError
        One line naming the stated interval, the steps the rows show and how many rows it would set aside.
    """
    first = first_arrivals(toa)
    heard = np.flatnonzero(np.isfinite(first))
    n_stray = int(np.asarray(stray, bool).sum())
    if len(heard) < 3 or n_stray <= STRAY_SHARE * len(heard):
        return None
    steps = np.diff(first[heard])
    low, high = np.percentile(steps, [5, 50])
    seen = (f"the rows' first arrivals are {low:.4g} s apart or more (5th percentile; median {high:.4g} s, "
            f"{int((steps < shortest).sum())} of {len(steps)} steps below {shortest:g} s)")
    if force:
        return (f"burst interval: {stated} stated ({option}) against {seen}: {n_stray} of {len(heard)} heard rows "
                "set aside as no pings of it")
    raise ModelError(f"burst interval: {stated} stated, but {seen}: it would set aside {n_stray} of {len(heard)} "
                     f"heard rows (more than {STRAY_SHARE:.0%}); allowed: the tag's interval, or {option} to use it "
                     "anyway")


__all__ = ["SET_ASIDE_REASON", "STRAY_SHARE", "check_strays", "stray_rows"]
