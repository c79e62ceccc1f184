"""Stray rows: the rows of a TOA matrix that cannot be pings of a tag whose pings are at least a given interval
apart (a stray code, a collision, an echo beyond the grouping's window), set aside; a stated interval refused where
the rows it would set aside look like pings, too many of them (the detections contradict it as a whole); and a
stable interval found and checked with its strays set aside. Units: seconds [s].

A stray code is one receiver's false decode: a row heard by that receiver alone, where an array's pings are heard by
several. A raw recording's stray detections are a few per cent of its detections, but each is a row of its own: with
pings heard by five receivers, 3 % of the detections are 15 % of the rows. Where most rows are heard by two
receivers or more (a dense array), only the rows set aside that were heard by two or more count against the
interval: a wrong interval sets aside pings, heard as the others are; stray codes are heard once.
"""

from __future__ import annotations

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.schedule import first_arrivals

#: The largest share of a record's heard rows a stated interval may set aside as strays (:func:`stray_rows`): more,
#: and the detections contradict the interval as a whole (:func:`check_strays`). A raw recording's stray codes and
#: collisions are a few per cent of its rows.
STRAY_SHARE = 0.10
#: The reason a row set aside carries (``quality_reason``, ``set_aside.csv``).
SET_ASIDE_REASON = "set_aside_not_a_ping"
#: A dense record: at least this share of the rows kept heard by two receivers or more (:func:`check_strays`).
DENSE_SHARE = 0.5
#: The stable intervals tried with their strays set aside (:func:`stable_interval`): the best-scoring few.
STABLE_CANDIDATES = 6
#: The most steps scored for the candidates (evenly over the sorted steps: the search stays linear in the rows).
STABLE_SAMPLE = 300


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


def pinglike(toa: np.ndarray, stray: np.ndarray) -> tuple[int, int, bool]:
    """How many of the rows set aside look like pings, out of how many rows (module docstring): in a dense record
    (:data:`DENSE_SHARE`) those heard by two receivers or more, out of the rows so heard; else all of them, out of
    the rows heard. ``toa`` (m, n) [s], ``stray`` (m,) bool. Returns (count, out of, dense)."""
    count = np.isfinite(np.asarray(toa, float)).sum(axis=1)
    stray = np.asarray(stray, bool)
    kept = (count > 0) & ~stray
    dense = bool(kept.any() and (count[kept] >= 2).mean() >= DENSE_SHARE)
    if dense:
        return int((stray & (count >= 2)).sum()), int((count >= 2).sum()), True
    return int(stray.sum()), int((count > 0).sum()), False


def check_strays(toa: np.ndarray, stray: np.ndarray, stated: str, shortest: float, force: bool = False,
                 option: str = "--force-interval") -> str | None:
    """Refuse a stated interval the rows contradict as a whole: more than :data:`STRAY_SHARE` of the heard rows set
    aside by it (:func:`stray_rows`) looking like pings (:func:`pinglike`: in a dense record, heard by two receivers
    or more), where stray codes are heard once and collisions are a few per cent.

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
    like, out_of, dense = pinglike(toa, stray)
    if len(heard) < 3 or like <= STRAY_SHARE * out_of:
        return None
    steps = np.diff(first[heard])
    low, high = np.percentile(steps, [5, 50])
    seen = (f"the rows' first arrivals are {low:.4g} s apart or more (5th percentile; median {high:.4g} s, "
            f"{int((steps < shortest).sum())} of {len(steps)} steps below {shortest:g} s)")
    share = (f"{like} of them heard by two receivers or more, as pings are (more than {STRAY_SHARE:.0%} of the "
             f"{out_of} rows so heard)" if dense else f"more than {STRAY_SHARE:.0%}")
    if force:
        return (f"burst interval: {stated} stated ({option}) against {seen}: {n_stray} of {len(heard)} heard rows "
                "set aside as no pings of it")
    raise ModelError(f"burst interval: {stated} stated, but {seen}: it would set aside {n_stray} of {len(heard)} "
                     f"heard rows ({share}); allowed: the tag's interval, or {option} to use it anyway")


def stable_interval(toa: np.ndarray, crossing: float) -> tuple[float | None, np.ndarray]:
    """A stable burst interval (``sbi``) the rows show, with the rows that cannot be its pings set aside: where the
    steps of all rows contradict one (:func:`~sblsim.models.tracking.schedule.check_stable`), the intervals that
    the most steps fit as whole multiples (:func:`_stable_candidates`) are tried, the largest first, each with the
    rows closer to a kept row than the interval less its tolerance set aside (:func:`stray_rows`), until the rows
    left fit one and those set aside do not look like pings (:func:`pinglike`: at most :data:`STRAY_SHARE`).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard; rows in time order.
    crossing : float
        The array's crossing time [s] (:func:`~sblsim.models.tracking.schedule.crossing_time`).

    Returns
    -------
    interval : float or None
        [s] as :func:`~sblsim.models.tracking.schedule.check_stable` returns it, on the rows kept.
    stray : ndarray of bool, (m,)
        The rows set aside to find it (none where all rows fit).

    Raises
    ------
    ModelError
        :func:`~sblsim.models.tracking.schedule.check_stable`'s line on all rows, where no candidate fits either.
    """
    toa = np.asarray(toa, float)
    none = np.zeros(len(toa), bool)
    try:
        return ps.check_stable(toa, crossing), none
    except ModelError as error:
        refusal = error
    for delta in _stable_candidates(toa, crossing):
        tolerance = max(ps.SBI_CROSSINGS * crossing, ps.SBI_SHARE * delta)
        stray = stray_rows(toa, delta - tolerance + crossing, crossing)
        like, out_of, _ = pinglike(toa, stray)
        if not stray.any() or like > STRAY_SHARE * out_of:
            continue
        try:
            return ps.check_stable(np.where(stray[:, None], np.nan, toa), crossing), stray
        except ModelError:
            continue
    raise refusal


def _stable_candidates(toa: np.ndarray, crossing: float) -> list[float]:
    """The stable intervals [s] most steps of the rows' first arrivals fit as whole multiples (within
    :func:`~sblsim.models.tracking.schedule.check_stable`'s tolerance ``t``), beyond the share ``2 t / Δ`` any steps
    would fit by chance, from the steps and their halves, thirds and
    quarters (:data:`~sblsim.models.tracking.schedule.SBI_DIVISORS`); a stray's part-step fits none. The best of
    each tolerance's width, at most :data:`STABLE_CANDIDATES` of them within a tenth of the best score, the largest
    first (a half of the interval fits as many steps)."""
    first = first_arrivals(toa)
    d = np.diff(first[np.isfinite(first)])
    d = np.sort(d[d > 0])
    if len(d) < 3:
        return []
    sample = d[np.unique(np.linspace(0, len(d) - 1, min(len(d), STABLE_SAMPLE)).round().astype(int))]
    delta = np.unique(np.concatenate([sample / k for k in ps.SBI_DIVISORS]))
    delta = delta[delta > 4 * crossing]
    if not len(delta):
        return []
    tolerance = np.maximum(ps.SBI_CROSSINGS * crossing, ps.SBI_SHARE * delta)
    score = np.empty(len(delta))
    for k in range(0, len(delta), 256):  # (candidates, steps) in blocks: bounded memory
        part = slice(k, k + 256)
        n = np.maximum(np.round(sample[None] / delta[part, None]), 1.0)
        score[part] = (np.abs(sample[None] - n * delta[part, None]) <= tolerance[part, None]).mean(axis=1)
    score -= np.minimum(2 * tolerance / delta, 1.0)  # beyond chance: any step is that near a multiple of a short one
    chosen: list[float] = []
    for k in np.lexsort((-delta, -score)):  # the best first; of the intervals within one tolerance, the best only
        if score[k] < score.max() - 0.1 or len(chosen) == STABLE_CANDIDATES:
            break
        if all(abs(delta[k] - c) > tolerance[k] for c in chosen):
            chosen.append(float(delta[k]))
    return sorted(chosen, reverse=True)


__all__ = ["DENSE_SHARE", "SET_ASIDE_REASON", "STABLE_CANDIDATES", "STABLE_SAMPLE", "STRAY_SHARE", "check_strays",
           "pinglike", "stable_interval", "stray_rows"]
