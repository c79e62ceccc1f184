"""One tag's synchronised detections grouped into pings: the times-of-arrival matrix (pings × receivers) the
tracker reads (``sblsim toa``).

Once the receivers' clocks are synchronised (:mod:`sblsim.models.sync.clocks`), the arrivals of one transmission
at two receivers ``j`` and ``k`` differ by at most the travel time between them, ``d_jk / c`` (the triangle
inequality, wherever the tag is), so by at most the array's **largest travel time** ``D / c`` (``D`` the largest
distance between two receivers). Successive transmissions are at least the tag's **shortest burst interval** apart.
So, with a **window** of ``D / c`` plus the synchronisation's tolerance, and the shortest interval longer than two
windows:

1. **multipath echoes**: at one receiver, an arrival less than the echo limit (the shortest interval less one
   window: the most the tag's own travel time to that receiver can shorten the step between two pings) after the
   receiver's previous arrival of the tag is a late copy of that transmission (a reflected path; or a false
   detection), dropped: only the first, the direct path's, is kept (:func:`multipath_echoes`);
2. **pings**: the kept arrivals of all receivers in time order, a new ping where the gap to the previous arrival
   exceeds the window; a group that spans more than one window or holds one receiver twice (false detections
   chained between two pings) is split greedily from its first arrival (:func:`group_pings`);
3. **the matrix**: one row per ping, one column per receiver, NaN where not heard (:func:`toa_matrix`).

This is how YAPS's users build the matrix from synchronised detections (Baktoft, Gjelland, Økland & Thygesen 2017,
Sci. Rep. 7:14294; the ``yaps`` package's ``getToaYaps``), with the window taken from the array instead of a
fixed number. Units: seconds [s], metres [m]. No orchestrator import.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError

#: The largest share of a receiver's successive arrival steps (those longer than two windows: no echo of the same
#: transmission) that may fall below a stated shortest interval less one window before the detections contradict it
#: as a whole (:func:`interval_seen`): a few stray codes and collisions make a few per cent.
CONTRADICTED_SHARE = 0.10


def largest_travel_time(positions: np.ndarray, sound_speed: float) -> float:
    """[s] the largest distance between two receivers ``positions`` (n, dim) [m] over ``sound_speed`` [m/s]."""
    p = np.asarray(positions, float)
    if len(p) < 2:
        return 0.0
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
    return float(d.max() / sound_speed)


def multipath_echoes(receiver: np.ndarray, time: np.ndarray, limit: float) -> np.ndarray:
    """(n,) bool: an arrival less than ``limit`` [s] after the same receiver's previous arrival of the tag (a
    multipath echo or a false detection; the first of a run is the direct path's and kept).

    Parameters
    ----------
    receiver : numpy.ndarray
        (n,) int, each arrival's receiver.
    time : numpy.ndarray
        (n,) [s] the synchronised arrival times.
    limit : float
        [s] the echo limit: the shortest burst interval less the window.
    """
    order = np.lexsort((time, receiver))
    r, t = receiver[order], time[order]
    echo = np.zeros(len(t), bool)
    if len(t) > 1:
        close = (r[1:] == r[:-1]) & (np.diff(t) < limit)  # arrival k + 1 within limit of arrival k
        for k in np.flatnonzero(close):  # in time order: each against the last arrival kept before it
            j = k
            while echo[j]:  # the first arrival of a receiver is never an echo: the walk stays on its receiver
                j -= 1
            echo[k + 1] = t[k + 1] - t[j] < limit
    out = np.zeros(len(t), bool)
    out[order] = echo
    return out


def group_pings(receiver: np.ndarray, time: np.ndarray, window: float) -> np.ndarray:
    """(n,) int: each arrival's ping, numbered in time order (the module docstring's step 2).

    Parameters
    ----------
    receiver : numpy.ndarray
        (n,) int, each arrival's receiver (echoes already dropped).
    time : numpy.ndarray
        (n,) [s] the synchronised arrival times.
    window : float
        [s] the largest spread of one ping's arrivals.
    """
    n = len(time)
    ping = np.zeros(n, np.int64)
    if not n:
        return ping
    order = np.argsort(time, kind="stable")
    t, r = time[order], receiver[order]
    new = np.ones(n, bool)
    new[1:] = np.diff(t) > window
    group = np.cumsum(new) - 1
    starts = np.flatnonzero(new)
    ends = np.r_[starts[1:], n]
    spread = t[ends - 1] - t[starts]
    label = group.copy()
    count = 0
    for g, (a, b) in enumerate(zip(starts, ends)):
        members = r[a:b]
        if spread[g] <= window and len(np.unique(members)) == len(members):
            label[a:b] = count
            count += 1
            continue
        first, seen = t[a], set()
        for k in range(a, b):  # split from the first arrival: a new ping beyond one window or at a receiver seen
            if t[k] - first > window or int(r[k]) in seen:
                count += 1
                first, seen = t[k], set()
            seen.add(int(r[k]))
            label[k] = count
        count += 1
    ping[order] = label
    return ping


def toa_matrix(receiver: np.ndarray, time: np.ndarray, ping: np.ndarray, n_receivers: int) -> np.ndarray:
    """(pings, n_receivers) [s]: each ping's arrival at each receiver, NaN where not heard."""
    n_pings = int(ping.max()) + 1 if len(ping) else 0
    toa = np.full((n_pings, n_receivers), np.nan)
    toa[ping, receiver] = time
    return toa


@dataclass
class Pings:
    """One tag's detections grouped (:func:`build_pings`).

    Attributes
    ----------
    toa : numpy.ndarray
        (P, R) [s] the synchronised times of arrival, NaN where not heard; rows in time order.
    ping : numpy.ndarray
        (n,) int, each detection's ping (-1 for an echo).
    echo : numpy.ndarray
        (n,) bool, a multipath echo dropped.
    window, echo_limit : float
        [s] the window of one ping and the echo limit used.
    """

    toa: np.ndarray
    ping: np.ndarray
    echo: np.ndarray
    window: float
    echo_limit: float


def build_pings(receiver: np.ndarray, time: np.ndarray, n_receivers: int, window: float, shortest: float) -> Pings:
    """The module docstring's three steps.

    Parameters
    ----------
    receiver : numpy.ndarray
        (n,) int in [0, n_receivers), each detection's receiver.
    time : numpy.ndarray
        (n,) [s] the synchronised times.
    n_receivers : int
        The matrix's columns.
    window : float
        [s] the largest spread of one ping's arrivals (the array's largest travel time and the tolerance).
    shortest : float
        [s] the tag's shortest burst interval.

    Returns
    -------
    Pings

    Raises
    ------
    ModelError
        A shortest interval not longer than two windows (pings could not be told apart).
    """
    if not shortest > 2 * window:
        raise ModelError(f"burst interval: the shortest, {shortest:.4g} s, is not longer than twice the array's "
                         f"largest travel time and tolerance ({window:.4g} s): pings cannot be told apart; allowed: "
                         "a shortest interval above twice that")
    receiver = np.asarray(receiver, np.int64)
    time = np.asarray(time, float)
    limit = shortest - window
    echo = multipath_echoes(receiver, time, limit)
    ping = np.full(len(time), -1, np.int64)
    keep = ~echo
    ping[keep] = group_pings(receiver[keep], time[keep], window)
    toa = toa_matrix(receiver[keep], time[keep], ping[keep], n_receivers)
    return Pings(toa, ping, echo, window, limit)


def receiver_steps(receiver: np.ndarray, time: np.ndarray, window: float) -> np.ndarray:
    """[s] the steps between each receiver's successive arrivals longer than two windows ``window`` [s] (a receiver
    misses pings, so they run from the interval up; echoes are shorter)."""
    order = np.lexsort((time, receiver))
    r, t = np.asarray(receiver)[order], np.asarray(time, float)[order]
    steps = np.diff(t)[r[1:] == r[:-1]]
    return steps[steps > 2 * window]


def inferred_shortest(receiver: np.ndarray, time: np.ndarray, window: float) -> float | None:
    """[s] the shortest burst interval as the detections show it: 0.9 times the 5th percentile of the steps
    between a receiver's successive arrivals longer than two windows (:func:`receiver_steps`); None with fewer than
    20 such steps."""
    steps = receiver_steps(receiver, time, window)
    if len(steps) < 20:
        return None
    return float(0.9 * np.percentile(steps, 5))


@dataclass(frozen=True)
class IntervalSeen:
    """A stated shortest interval against the steps at each receiver (:func:`interval_seen`): ``below`` of
    ``steps`` fall below it less one window; ``low`` and ``high`` [s] the interval the steps show (the 5th
    percentile, and the 98th of those under twice it: the single steps where the longest interval is under twice
    the shortest); ``contradicted`` more than :data:`CONTRADICTED_SHARE` below (of 20 steps at least)."""

    below: int
    steps: int
    low: float
    high: float
    contradicted: bool


def interval_seen(receiver: np.ndarray, time: np.ndarray, window: float, shortest: float) -> IntervalSeen:
    """A stated shortest burst interval ``shortest`` [s] against the detections' steps at each receiver
    (:func:`receiver_steps`): contradicted as a whole where more than :data:`CONTRADICTED_SHARE` of them fall below
    it less one window ``window`` [s], the echo limit, which would drop them.

    Parameters
    ----------
    receiver : numpy.ndarray
        (n,) int, each detection's receiver.
    time : numpy.ndarray
        (n,) [s] the synchronised times.
    window : float
        [s] the largest spread of one ping's arrivals.
    shortest : float
        [s] the stated shortest interval.

    Returns
    -------
    IntervalSeen
    """
    steps = receiver_steps(receiver, time, window)
    if not len(steps):
        return IntervalSeen(0, 0, float("nan"), float("nan"), False)
    below = int((steps < shortest - window).sum())
    low = float(np.percentile(steps, 5))
    high = float(np.percentile(steps[steps < 2 * low], 98))
    return IntervalSeen(below, len(steps), low, high, len(steps) >= 20 and below > CONTRADICTED_SHARE * len(steps))


__all__ = ["CONTRADICTED_SHARE", "IntervalSeen", "Pings", "build_pings", "group_pings", "inferred_shortest",
           "interval_seen", "largest_travel_time", "multipath_echoes", "receiver_steps", "toa_matrix"]
