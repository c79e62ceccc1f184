"""A synchronisation's clock segments, where a receiver's clock broke (:mod:`sblsim.models.sync.breaks`): the clock
row of each arrival, each segment's number and span for ``offsets.csv``, the breaks for ``sync.json``
(``clock_breaks``) and the line that names each.

A receiver whose clock never broke has one clock row, its own; one whose clock broke has one per segment, numbered
1, 2, … in its own clock's time order. A segment's offsets hold for the times of the receiver's own clock from
``clock_from`` to ``clock_to`` [s since 1970 UTC on that clock; open where empty]; a time between two segments (the
stretch between the last sync-tag arrival before the break and the first after it, widened by the jump where the
time went back) is in neither: a detection there is set aside.

Where a receiver's time went back in the file's order (a reset kept in its logging order: the reader's clock parts,
:attr:`~sblsim.orchestrator.readers.detections.Detections.clock_resets`), each part's segments are numbered after the
part before's, ``offsets.csv`` says each segment's part (``clock_part``), and a detection takes the segment of its
own part (the detections' ``clock_part`` column) that holds its time: two parts may read the same times, nothing is
set aside at such a break.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.end_breaks import EndBreak
from sblsim.models.sync.noise import undetermined
from sblsim.models.tracking.timing import CLOCK_SIGMA_RANGE
from sblsim.orchestrator.io.times import iso_utc


def clock_rows(fit: ClockFit, receiver: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) each arrival's clock row (its receiver where no clock broke; -1 set aside at a break) and (rows,) each
    row's receiver."""
    if fit.site is None:
        return receiver, np.arange(len(fit.knots))
    return fit.clock, fit.site


#: How a synchronisation's notes of the receivers it could not synchronise begin (a study takes them among its own).
NOT_SYNCHRONISED = "receivers that cannot be synchronised"


def without_undetermined(fit: ClockFit, receiver: np.ndarray, time: np.ndarray, used: np.ndarray,
                         names: list[str]) -> tuple[ClockFit, np.ndarray, str | None]:
    """The fit with each clock row its sync-tag arrivals do not determine not synchronised
    (:func:`~sblsim.models.sync.noise.undetermined`: its offset's sigma at its ``used`` arrivals above
    :data:`~sblsim.models.tracking.timing.CLOCK_SIGMA_RANGE`'s largest, the most ``clock_sigma_s`` may say; e.g. one
    arrival ties it to the others and its drift is free), the receivers (R,) bool none of whose rows is left
    synchronised, and a note naming them (None where every clock is determined)."""
    rows, site = clock_rows(fit, receiver)
    rows = np.where(used, rows, -1)  # each used arrival's row (−1: not used, or set aside at a break)
    lost = undetermined(rows, time, fit.knot_sigma, fit.edges, CLOCK_SIGMA_RANGE[1])
    if not lost.any():
        return fit, np.zeros(len(names), bool), None
    kept = np.bincount(site[~lost], minlength=len(names)) > 0
    gone = np.bincount(site[lost], minlength=len(names)) > 0
    count = np.bincount(rows[rows >= 0], minlength=len(lost))
    said = [f"{names[site[r]]} ({count[r]} arrival{'s' if count[r] != 1 else ''})" for r in np.flatnonzero(lost)]
    note = (f"{NOT_SYNCHRONISED} (the sync-tag arrivals do not determine their clock: its offset's sigma at them "
            f"above {CLOCK_SIGMA_RANGE[1]:g} s, its drift free), their detections set aside: " + ", ".join(said))
    return fit.without(lost), gone & ~kept, note


def segment_numbers(fit: ClockFit) -> np.ndarray:
    """(rows,) int, each clock row's segment among its receiver's, 1 first (1 everywhere where no clock broke)."""
    if fit.site is None:
        return np.ones(len(fit.knots), np.int64)
    out = np.ones(len(fit.site), np.int64)
    part = np.ones(len(fit.site), np.int64) if fit.part is None else fit.part
    for j in np.unique(fit.site):
        mine = np.flatnonzero(fit.site == j)
        out[mine[np.lexsort((fit.span[mine, 0], part[mine]))]] = np.arange(1, len(mine) + 1)
    return out


def segment_columns(fit: ClockFit, origin: float) -> dict[str, np.ndarray] | None:
    """``offsets.csv``'s columns of the clock rows where a clock broke: ``segment`` (:func:`segment_numbers`),
    ``clock_from`` and ``clock_to`` [s since 1970 UTC on the receiver's own clock; NaN: open], and where a
    receiver's time went back in the file's order ``clock_part`` (the part of its rows each holds for); None where
    none broke."""
    if fit.site is None:
        return None
    span = np.where(np.isfinite(fit.span), fit.span + origin, np.nan)
    out = {"segment": segment_numbers(fit), "clock_from": span[:, 0], "clock_to": span[:, 1]}
    if fit.part is not None:
        out["clock_part"] = fit.part
    return out


def receiver_sigmas(fit: ClockFit, n_receivers: int) -> np.ndarray:
    """(R, K+1) [s] each receiver's offset sigmas at the bins' edges: its own row's, or where its clock broke at each
    edge the sigma of the segment that holds it (the smallest of its segments' in a stretch set aside; where its time
    went back in the file's order, of those of its clock parts that hold it and read arrivals beside it, NaN where
    none does)."""
    if fit.site is None:
        return fit.knot_sigma
    out = np.full((n_receivers, fit.knot_sigma.shape[1]), np.nan)
    for j in range(n_receivers):
        mine = np.flatnonzero(fit.site == j)
        if len(mine) == 1:
            out[j] = fit.knot_sigma[mine[0]]
            continue
        row = fit.rows_at(np.full(len(fit.edges), j), fit.edges)
        least = np.nanmin(np.where(np.isfinite(fit.knot_sigma[mine]), fit.knot_sigma[mine], np.inf), axis=0)
        out[j] = np.where(row >= 0, fit.knot_sigma[np.maximum(row, 0), np.arange(len(fit.edges))], least)
        if fit.part is not None:  # its clock parts read the same times: the least of the segments that hold an edge
            # and read arrivals in a bin beside it (NaN where none: a stretch its clock never read)
            counts = np.pad(fit.counts[mine], ((0, 0), (1, 1)))
            read = (counts[:, :-1] + counts[:, 1:]) > 0
            held = (fit.edges >= fit.span[mine, :1]) & (fit.edges <= fit.span[mine, 1:]) & read
            sigma = np.where(held & np.isfinite(fit.knot_sigma[mine]), fit.knot_sigma[mine], np.inf)
            out[j] = np.where(held.any(axis=0), sigma.min(axis=0), np.nan)
        out[j] = np.where(np.isfinite(out[j]), out[j], np.nan)
    return out


def receiver_values(values: np.ndarray, fit: ClockFit, n_receivers: int) -> np.ndarray:
    """(R,) a value per clock row (a noise scale [s]) per receiver: the largest of its segments'."""
    if fit.site is None:
        return values
    out = np.full(n_receivers, np.nan)
    for j in range(n_receivers):
        mine = values[fit.site == j]
        if np.isfinite(mine).any():
            out[j] = np.nanmax(mine)
    return out


def breaks_summary(fit: ClockFit, names: list[str], origin: float,
                   resets: dict[tuple[str, int], dict] | None = None) -> list[dict[str, Any]]:
    """``sync.json``'s ``clock_breaks``: per break its receiver, segments, instant (s since 1970 and UTC, on the
    reference clock, within ``within_s``), size and its sigma [s], the receiver's own times of its last sync-tag
    arrival before and its first after, the stretch of its own clock set aside, its statistic, and whether both
    segments are synchronised; a reset from the file's order (its place known: ``statistic`` and the stretch set
    aside None) with ``clock_part`` and ``reset``, the reader's entry (``resets`` by receiver and clock part: its
    line and step)."""
    if not fit.breaks:
        return []
    number = segment_numbers(fit)
    out = []
    for b in fit.breaks:
        linked = bool(np.isfinite(fit.knots[b.before, 0]) and np.isfinite(fit.knots[b.after, 0]))
        instant = b.time + origin if np.isfinite(b.time) else np.nan
        known = b.part is not None
        out.append({
            "receiver": names[b.receiver], "segment_before": int(number[b.before]),
            "segment_after": int(number[b.after]), "time_s": instant, "time_utc": iso_utc([instant])[0] or None,
            "within_s": b.time_within, "size_s": b.size, "size_sigma_s": b.size_sigma,
            "last_before_s": b.last + origin if np.isfinite(b.last) else None, "first_after_s": b.first + origin,
            "set_aside_from_s": None if known else fit.span[b.before, 1] + origin,
            "set_aside_to_s": None if known else fit.span[b.after, 0] + origin,
            "statistic": None if known else b.statistic, "synchronised": linked})
        if known:
            out[-1]["clock_part"] = int(b.part)
            out[-1]["reset"] = (resets or {}).get((names[b.receiver], int(b.part)))
    return out


def break_line(entry: dict[str, Any]) -> str:
    """One console line naming a break (an entry of :func:`breaks_summary`)."""
    size = entry["size_s"]
    jump = _jump(size, entry["size_sigma_s"])
    when = (f"at {entry['time_utc'][:19]}Z (within {entry['within_s']:.0f} s)" if entry["time_utc"] else
            f"after its time {entry['last_before_s'] or np.nan:.3f} s")
    split = (f"its clock split there (segments {entry['segment_before']} and {entry['segment_after']})"
             if entry["synchronised"] else "the segment not synchronised, its detections set aside")
    if "clock_part" in entry:  # a reset from the file's order: its place known, nothing set aside
        reset = entry.get("reset")
        said = (f"its time goes back {-reset['step_s']:.6g} s at line {reset['line']} (its clock from "
                f"{iso_utc([reset['before_s']])[0][:23]} to {iso_utc([reset['after_s']])[0][:23]} UTC)" if reset else
                f"its time goes back in the file's order (clock part {entry['clock_part']})")
        fitted = f"; fitted: it {jump} {when}" if np.isfinite(size) and entry["time_utc"] else ""
        return (f"clock break: receiver {entry['receiver']}: {said}: a new clock segment{fitted}; {split}, each "
                "detection in its part's segment by the file's order")
    aside = iso_utc([entry["set_aside_from_s"], entry["set_aside_to_s"]])
    return (f"clock break: receiver {entry['receiver']} {jump} {when}; {split}, "
            f"its own times from {aside[0][11:23]} to {aside[1][11:23]} set aside")


def end_line(end: EndBreak, names: list[str], origin: float) -> str:
    """One console line naming a break too near a clock's end (or start) to fit a segment
    (:func:`~sblsim.models.sync.end_breaks.cut_ends`): the receiver, the break's instant (UTC, on the reference
    clock), the jump and its sigma, the arrivals beyond it and the receiver's own times set aside."""
    where, side = ("start", "before") if end.at_start else ("end", "after")
    when = iso_utc([end.time + origin])[0][:19]
    bound = iso_utc([(end.aside_to if end.at_start else end.aside_from) + origin])[0][:23]
    aside = f"up to {bound} set aside" if end.at_start else f"from {bound} on set aside"
    return (f"clock break: receiver {names[end.receiver]} {_jump(end.size, end.size_sigma)} at {when}Z (within "
            f"{end.time_within:.0f} s), {end.arrivals} sync-tag arrivals {side} it: too near its "
            f"clock's {where} to fit a segment; its own times {aside}")


def _jump(size: float, sigma: float | None) -> str:
    """A break's jump as its lines say it: ``jumped ahead`` or ``went back``, its size [s] and its sigma (in ms,
    where known)."""
    how = "jumped ahead" if size >= 0 else "went back"
    said = f" ± {sigma * 1e3:.2g} ms" if sigma is not None and np.isfinite(sigma) else ""
    return f"{how} {abs(size):.6g} s{said}"


__all__ = ["break_line", "breaks_summary", "clock_rows", "end_line", "receiver_sigmas", "receiver_values",
           "segment_columns", "segment_numbers"]
