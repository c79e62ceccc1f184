"""Each tag of a study counted before any schedule is asked of it (``sblsim track``): the true reason a tag cannot be
positioned, found first, with its counts.

A position from times of arrival needs one transmission heard by ``dim + 1`` receivers at once (3 in 2-D, 4 in
3-D), on clocks that agree to a fraction of the travel time between them. So before its burst interval is checked,
each tag is counted (:func:`count`): its detections per receiver (deployment), which of those receivers have a
synchronised clock, its pings (its synchronised detections grouped within the travel time between the receivers
that heard it, :func:`~sblsim.models.sync.at_once.heard_at_once`) and how many receivers heard each at once, the
times' resolution (:func:`~sblsim.models.sync.resolution.time_quantum`) and whether the clocks were synchronised.
:func:`verdict` then says, in this order, the first reason it cannot be positioned, with a code a user can filter
``tags.csv`` by (:data:`REASON_CODES`): heard by one receiver; by fewer receivers than a position needs; by enough
receivers, too few of them synchronised; too few pings heard by enough receivers at once (a track needs
:data:`MIN_AT_ONCE`, and a moving tag's tracker starts from a ping heard by ``dim + 2``); times rounded to whole
seconds on clocks nobody synchronised. Only a tag none of these hold for has its schedule checked and is tracked;
what the later steps refuse is coded by :func:`code_of`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import pandas as pd

from sblsim.models.sync.at_once import heard_at_once
from sblsim.models.sync.resolution import resolution_warning, time_quantum
from sblsim.orchestrator.sync.clocks import Clocks
from sblsim.orchestrator.sync.declared import NOMINAL_SOUND_SPEED
from sblsim.orchestrator.sync.toa import SLOWEST_SOUND_SPEED, TOLERANCE, on_the_clocks

#: The fewest pings heard by ``dim + 1`` receivers at once a track is offered from: two fixes to start from and one
#: to check them (fewer leave every other row of the track to the motion model alone).
MIN_AT_ONCE = 3
#: How ``sblsim track`` takes a tag's interval and a contradicted one anyway, as a tag's refusal names them
#: (:func:`~sblsim.orchestrator.sync.toa.build_toa`'s ``options``).
TRACK_OPTIONS = {"interval": "the tag sheet's ping_type with min_delay and max_delay, interval or burst_sequence "
                             "(--tags)", "force_interval": "--force-interval"}
#: Each ``reason_code`` of ``tags.csv``, with what it means (docs/telemetry.md's table).
REASON_CODES = {
    "never_detected": "the tag is not detected inside a deployment",
    "one_receiver": "heard by one receiver only",
    "too_few_receivers": "heard by fewer receivers than a position needs (3 in 2-D, 4 in 3-D)",
    "receivers_not_synchronised": "heard by enough receivers, too few of them on a synchronised clock",
    "too_few_receivers_at_once": "too few pings heard by enough receivers at once",
    "whole_seconds_unsynchronised": "times rounded to whole seconds on clocks nobody synchronised",
    "interval_contradicted": "the tag sheet's interval contradicted by the pings heard at once",
    "interval_unknown": "no interval on the tag sheet and too few steps to see it",
    "pings_not_told_apart": "the interval shorter than twice the travel time across the array",
    "receivers_on_one_line": "the receivers that heard it lie on one line (a mirror image for every position)",
    "receivers_misplaced": "the arrivals spread wider than the receivers' positions allow",
    "two_tags": "two tags under one code",
    "no_position": "the tracker positioned none of its pings",
    "tracked_twice": "the same tag asked for twice",
    "refused": "another refusal: the reason says which",
    "internal_error": "a fault of ours: please report it",
}
#: The refusals of the steps after the census (the matrix, the tracker), by their line's text, and their codes.
_LATER = ((r"^tag: .* is never detected", "never_detected"),
          (r"^tag: .* is tracked twice", "tracked_twice"),
          (r"^tag: .* is detected only at receivers that are not synchronised", "receivers_not_synchronised"),
          (r"^burst interval: .* stated, but ", "interval_contradicted"),
          (r"^ping type \w+: the pings' first arrivals are ", "interval_contradicted"),
          (r"too few successive detections", "interval_unknown"),
          (r"^burst interval: the shortest, .* pings cannot be told apart", "pings_not_told_apart"),
          (r"^receivers: .* lie on one line", "receivers_on_one_line"),
          (r"^receivers: (the \d+ receivers lie within|a typical ping's arrivals spread)", "receivers_misplaced"),
          (r"^(receivers: \d+ receivers with a position heard|stationary tag: \d+ receivers heard)",
           "too_few_receivers"),
          (r"looks like two tags", "two_tags"),
          (r"^internal error", "internal_error"))


@dataclass(frozen=True)
class Census:
    """One tag counted (:func:`count`).

    Attributes
    ----------
    per_receiver : dict
        Its detections at each receiver (deployment) that heard it, most first.
    synchronised : list of str
        Those receivers whose clocks the study has (synchronised, or taken as logged).
    pings, at_once, to_start, most : int
        Its pings (its detections on synchronised clocks, grouped), those heard by ``need`` receivers or more at
        once and by ``need + 1``, and the most receivers that heard one at once.
    need : int
        ``dim + 1``: the receivers one position needs at once.
    quantum : float
        [s] the resolution of its times (0: finer than a millisecond).
    logged : bool
        Whether the clocks were taken as logged (no synchronisation).
    crossing : float
        [s] the sound's crossing time of the receivers that hear one of its pings at once: the median over its
        pings heard by ``need`` receivers or more of their extent (the diagonal of their bounding box), at the
        nominal sound speed (the travel times a position is made of; a network's whole extent is not).
    """

    per_receiver: dict[str, int]
    synchronised: list[str]
    pings: int
    at_once: int
    to_start: int
    most: int
    need: int
    quantum: float
    logged: bool
    crossing: float

    @property
    def detections(self) -> int:
        """Its detections inside a deployment."""
        return sum(self.per_receiver.values())


def count(mine: pd.DataFrame, table: pd.DataFrame, clocks: Clocks, logged: bool) -> Census:
    """One tag counted (the module docstring).

    Parameters
    ----------
    mine : pandas.DataFrame
        The tag's detections, each at its deployment (``receiver``, ``time`` [s since 1970 UTC on its receiver's
        clock], ``clock_part`` where a receiver's time went back in the file's order).
    table : pandas.DataFrame
        The receivers (``receiver``, ``x``, ``y``, ``z`` [m]; the geometry 3-D where every ``z`` is given).
    clocks : Clocks
        The study's clocks (synchronised, or taken as logged).
    logged : bool
        The clocks taken as logged.

    Returns
    -------
    Census
    """
    per_receiver = {str(k): int(v) for k, v in mine["receiver"].value_counts().items()}
    xyz = table[["x", "y", "z"]].to_numpy(float)
    dim = 3 if np.isfinite(xyz[:, 2]).all() else 2
    row = {n: k for k, n in enumerate(table["receiver"])}
    synced = {n: k for k, n in enumerate(clocks.receivers)}
    usable = [n for n in per_receiver if n in row and n in synced]
    quantum = time_quantum(mine["time"].to_numpy(float))
    use = mine[mine["receiver"].isin(usable)]
    pings = at_once = to_start = most = 0
    crossing = 0.0
    if len(use):
        _, inside, times = on_the_clocks(use, clocks, synced)
        receiver = use["receiver"].map(row).to_numpy(np.int64)[inside]
        grouped = heard_at_once(receiver, times[inside], xyz[:, :dim], SLOWEST_SOUND_SPEED, TOLERANCE + quantum)
        pings, most = len(grouped.receivers), int(grouped.receivers.max(initial=0))
        at_once, to_start = grouped.heard_by(dim + 1), grouped.heard_by(dim + 2)
        crossing = _crossing(grouped.ping, receiver, grouped.detections_heard_by(dim + 1), xyz[:, :dim])
    return Census(per_receiver, usable, pings, at_once, to_start, most, dim + 1, quantum, logged, crossing)


def _crossing(ping: np.ndarray, receiver: np.ndarray, rich: np.ndarray, positions: np.ndarray) -> float:
    """[s] the median over the pings heard at once (``rich``: their detections) of the extent of the receivers that
    heard each (the diagonal of their bounding box [m]) at the nominal sound speed; 0 where there is none."""
    if not rich.any():
        return 0.0
    order = np.argsort(ping[rich], kind="stable")
    p, where = ping[rich][order], positions[receiver[rich][order]]
    starts = np.flatnonzero(np.r_[True, p[1:] != p[:-1]])
    extent = np.maximum.reduceat(where, starts, axis=0) - np.minimum.reduceat(where, starts, axis=0)
    return float(np.median(np.linalg.norm(extent, axis=1))) / NOMINAL_SOUND_SPEED


def _listed(counts: dict[str, int], limit: int = 6) -> str:
    """Receivers and their detections, most first: ``A: 1,204, B: 56`` (and how many more)."""
    shown = [f"{name}: {n:,}" for name, n in list(counts.items())[:limit]]
    more = len(counts) - limit
    return ", ".join(shown) + (f" and {more} more" if more > 0 else "")


def verdict(census: Census, times: np.ndarray, stationary: bool = False, unsynchronisable: bool = False
            ) -> tuple[str, str] | None:
    """The first reason (the module docstring's order) a tag cannot be positioned: its ``reason_code`` and its one
    line, with the counts; None where it can be tried.

    Parameters
    ----------
    census : Census
    times : numpy.ndarray
        (n,) [s] its detections' times as logged (their rounding).
    stationary : bool
        A still tag (a reference tag): one position from all its pings, no tracker to start.
    unsynchronisable : bool
        The study's sync tags could not synchronise the clocks from times rounded so coarsely (the clocks taken as
        logged): the rounding is the reason once enough receivers heard the tag, before its pings are judged (their
        arrivals, on clocks seconds apart, are no pings' then).
    """
    need, heard = census.need, census.per_receiver
    at_once = f"positioning needs {need} at once"
    if len(heard) == 1:
        name, n = next(iter(heard.items()))
        return "one_receiver", f"heard by 1 receiver ({name}, {n:,} detection{'s' * (n != 1)}): {at_once}"
    if len(heard) < need:
        return "too_few_receivers", f"heard by {len(heard)} receivers (detections {_listed(heard)}): {at_once}"
    if len(census.synchronised) < need:
        alone = {n: c for n, c in heard.items() if n not in census.synchronised}
        return "receivers_not_synchronised", (
            f"heard by {len(heard)} receivers, {len(census.synchronised)} of them on a synchronised clock "
            f"({', '.join(census.synchronised) or 'none'}; not synchronised, detections {_listed(alone)}): {at_once}; "
            "allowed: their sync tags heard by the others (the deployments' transmitter column), or --sync DIR")
    if unsynchronisable:
        return "whole_seconds_unsynchronised", _rounded(census, "the sync tags could not set the clocks from them")
    if census.at_once < MIN_AT_ONCE:
        most = f"never more than {census.most} at once" if census.most < need else f"at most {census.most} at once"
        return "too_few_receivers_at_once", (
            f"{census.at_once:,} of {census.pings:,} pings heard by {need} receivers or more at once ({most}; "
            f"heard by {len(heard)} receivers, detections {_listed(heard)}): {at_once}, and a track at least "
            f"{MIN_AT_ONCE} such pings")
    if not stationary and not census.to_start:
        return "too_few_receivers_at_once", (
            f"{census.at_once:,} of {census.pings:,} pings heard by {need} receivers at once and none by {need + 1}: "
            f"the tracker starts from a ping heard by {need + 1} (a position with an arrival to check it)")
    if census.logged and census.quantum >= 1.0 and resolution_warning(times, census.crossing, NOMINAL_SOUND_SPEED,
                                                                       "") is not None:
        return "whole_seconds_unsynchronised", _rounded(census, "no sync tag set their clocks",
                                                        ", or the deployments' sync tags (transmitter column)")
    return None


def _rounded(census: Census, clocks: str, also: str = "") -> str:
    """The whole-seconds reason's line: the rounding in range, against the array's crossing time, why the clocks are
    not synchronised (``clocks``) and what else would allow positions (``also``)."""
    q = census.quantum
    whole = "whole-second" if q == 1.0 else f"whole-{q:g}-second"
    crossing = (f", where sound crosses the receivers that hear one of its pings at once in "
                f"{1000 * census.crossing:,.0f} ms (the median)" if np.isfinite(census.crossing) and census.crossing > 0
                else "")
    return (f"{whole}, unsynchronised times: {q:g} s is {q * NOMINAL_SOUND_SPEED:,.0f} m of range at "
            f"{NOMINAL_SOUND_SPEED:,.0f} m/s (the rounding alone {q / np.sqrt(12.0):.2g} s, "
            f"{q / np.sqrt(12.0) * NOMINAL_SOUND_SPEED:,.0f} m, one standard deviation){crossing}, and {clocks}; "
            f"allowed: the detections exported with their sub-second times{also}")


def code_of(reason: str) -> str:
    """The ``reason_code`` of a refusal said after the census (:data:`_LATER`'s patterns; else ``refused``)."""
    return next((code for pattern, code in _LATER if re.search(pattern, reason)), "refused")


__all__ = ["MIN_AT_ONCE", "REASON_CODES", "TRACK_OPTIONS", "Census", "code_of", "count", "verdict"]
