"""How many receivers heard each of a tag's pings at once: what positioning from times of arrival needs.

A position from times of arrival at fixed receivers needs one transmission heard by ``dim + 1`` receivers at once
(``dim`` coordinates and the emission time unknown; 3 in 2-D, 4 in 3-D), and a tracker that checks its fixes one
arrival more (:func:`~sblsim.models.tracking.starts.anchored_start` starts from fixes of ``dim + 2``). Before any
schedule is known, a tag's synchronised detections are grouped as :mod:`.pings` groups them (a new ping where the gap
to the previous arrival exceeds the window, a group split where it spans more than one window or holds one receiver
twice), the window the largest travel time between the receivers that heard the tag; then a ping's arrivals count
as heard at once only where every two of them lie no further apart in time than the travel time between their two
receivers allows (the triangle inequality, wherever the tag is: ``|t_j - t_k| <= d_jk / c + tolerance``), which a
window as wide as a whole network's does not check. Units: seconds [s], metres [m]. No orchestrator import.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.sync.pings import group_pings, largest_travel_time


@dataclass(frozen=True)
class AtOnce:
    """A tag's detections grouped into pings (:func:`heard_at_once`).

    Attributes
    ----------
    ping : numpy.ndarray
        (n,) int, each detection's ping, numbered in time order.
    receivers : numpy.ndarray
        (pings,) int, the most receivers of each ping whose arrivals every two agree with the travel time between
        them (its detections heard at once).
    window : float
        [s] the window the pings were grouped in.
    """

    ping: np.ndarray
    receivers: np.ndarray
    window: float

    def heard_by(self, count: int) -> int:
        """The pings heard by ``count`` receivers or more at once."""
        return int((self.receivers >= count).sum())

    def detections_heard_by(self, count: int) -> np.ndarray:
        """(n,) bool: the detections of the pings heard by ``count`` receivers or more at once."""
        return self.receivers[self.ping] >= count if len(self.ping) else np.zeros(0, bool)


def heard_at_once(receiver: np.ndarray, time: np.ndarray, positions: np.ndarray, sound_speed: float,
                  tolerance: float) -> AtOnce:
    """A tag's detections grouped into pings, and each ping's receivers heard at once (the module docstring).

    Parameters
    ----------
    receiver : numpy.ndarray
        (n,) int, each detection's receiver: a row of ``positions``.
    time : numpy.ndarray
        (n,) [s] the synchronised detection times.
    positions : numpy.ndarray
        (R, dim) [m] the receivers' positions.
    sound_speed : float
        [m/s] the slowest sound speed allowed (the travel times' longest).
    tolerance : float
        [s] added to every travel time: the synchronisation's tolerance and the times' rounding.

    Returns
    -------
    AtOnce
    """
    receiver = np.asarray(receiver, np.int64)
    time = np.asarray(time, float)
    positions = np.asarray(positions, float)
    heard = np.unique(receiver)
    window = largest_travel_time(positions[heard], sound_speed) + tolerance
    ping = group_pings(receiver, time, window)
    n_pings = int(ping.max()) + 1 if len(ping) else 0
    order = np.lexsort((time, ping))
    p, r, t = ping[order], receiver[order], time[order]
    size = np.bincount(p, minlength=n_pings)
    bad = np.zeros(n_pings, bool)  # a ping two of whose arrivals the travel time between them cannot hold
    for k in range(1, int(size.max()) if len(size) else 0):  # every two arrivals of one ping, k apart in order
        same = p[k:] == p[:-k]
        a, b = np.flatnonzero(same), np.flatnonzero(same) + k
        apart = np.linalg.norm(positions[r[a]] - positions[r[b]], axis=1) / sound_speed + tolerance
        bad[p[a][np.abs(t[b] - t[a]) > apart]] = True
    counts = size.copy()
    starts = np.r_[0, np.cumsum(size)]
    for g in np.flatnonzero(bad):
        counts[g] = _agreeing(r[starts[g]:starts[g + 1]], t[starts[g]:starts[g + 1]], positions, sound_speed,
                              tolerance)
    return AtOnce(ping, counts, window)


def _agreeing(receiver: np.ndarray, time: np.ndarray, positions: np.ndarray, sound_speed: float,
              tolerance: float) -> int:
    """The arrivals of one ping left when the one that disagrees with the most others is dropped, in turn, until
    every two agree with the travel time between their receivers: their count (at least 1)."""
    d = np.linalg.norm(positions[receiver][:, None] - positions[receiver][None], axis=2) / sound_speed + tolerance
    clash = np.abs(time[:, None] - time[None]) > d
    keep = np.ones(len(time), bool)
    while True:
        counts = (clash & keep[None] & keep[:, None]).sum(axis=1)
        if not counts.any():
            return int(keep.sum())
        keep[int(np.argmax(counts))] = False


__all__ = ["AtOnce", "heard_at_once"]
