"""The synchronisation's fits of a season in windows (:mod:`sblsim.models.sync.windows`): the clocks with their
breaks (:func:`breaks_in_windows`, as :func:`~sblsim.models.sync.breaks.fit_with_breaks` fits one span) and the
clocks refitted with some arrivals left out (:func:`clocks_in_windows`, as
:func:`~sblsim.models.sync.clocks.fit_clocks` with an earlier fit's rejections and scales: a sync tag's
leave-one-out). In each window the receivers tied to the reference receiver are those its own emissions tie; a
window the reference receiver does not hear (recovered, its clock gone) is fitted against the receiver of its most
arrivals, the season's time base carried to it (:mod:`sblsim.models.sync.windows`).
"""

from __future__ import annotations

import numpy as np

from sblsim.models.sync.breaks import fit_with_breaks
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clocks import fit_clocks
from sblsim.models.sync.emissions import connected
from sblsim.models.sync.windows import Windows, fit_in_windows


def breaks_in_windows(windows: Windows, receiver: np.ndarray, emission: np.ndarray, time: np.ndarray,
                      distance: np.ndarray, slowness: np.ndarray | None, used: np.ndarray, synchronised: np.ndarray,
                      reference: int, bin_width: float, tag: np.ndarray, timings: dict | None = None,
                      part: np.ndarray | None = None) -> ClockFit:
    """:func:`~sblsim.models.sync.breaks.fit_with_breaks` (its parameters) in ``windows`` (:func:`fit_in_windows`):
    in each, the receivers of ``synchronised`` tied to ``reference`` by the window's own emissions; ``timings``
    filled with each stage's seconds summed over the windows."""
    timings = {} if timings is None else timings

    def one(rows: np.ndarray) -> ClockFit:
        u = used[rows]
        linked, here = _tied(receiver[rows][u], emission[rows][u], synchronised, reference)
        own: dict = {}
        fit = fit_with_breaks(receiver[rows], emission[rows], time[rows], distance[rows],
                              None if slowness is None else slowness[rows], u, linked, here, bin_width,
                              tag[rows], timings=own, part=None if part is None else part[rows])
        for stage, seconds in own.items():  # each stage's seconds summed over the windows
            timings[stage] = timings.get(stage, 0.0) + seconds
        return fit

    return fit_in_windows(one, windows, receiver, time, emission, len(synchronised), reference)


def clocks_in_windows(windows: Windows, receiver: np.ndarray, emission: np.ndarray, time: np.ndarray,
                      distance: np.ndarray, slowness: np.ndarray | None, used: np.ndarray, synchronised: np.ndarray,
                      reference: int, bin_width: float, keep: np.ndarray, scale: np.ndarray,
                      steady: np.ndarray | None = None, arrivals: bool = True) -> ClockFit:
    """:func:`~sblsim.models.sync.clocks.fit_clocks` with the arrivals ``keep`` (n,) and the clock rows' noise
    ``scale`` (rows,) [s] of an earlier fit (no reweighting: e.g. a sync tag's arrivals left out), no sigmas, in
    ``windows`` (:func:`fit_in_windows`; ``arrivals`` False: the clocks alone, no arrival's residual kept);
    ``receiver`` the arrivals' clock rows."""

    def one(rows: np.ndarray) -> ClockFit:
        u = used[rows]
        linked, here = _tied(receiver[rows][u], emission[rows][u], synchronised, reference)
        return fit_clocks(receiver[rows], emission[rows], time[rows], distance[rows],
                          None if slowness is None else slowness[rows], u, linked, here, bin_width,
                          keep=keep[rows], scale=scale, sigmas=False, steady=steady)

    return fit_in_windows(one, windows, receiver, time, emission, len(synchronised), reference, arrivals)


def _tied(receiver: np.ndarray, emission: np.ndarray, synchronised: np.ndarray, reference: int
          ) -> tuple[np.ndarray, int]:
    """(R,) bool, a window's receivers of ``synchronised`` tied to ``reference`` by its arrivals (``receiver``,
    ``emission``), and the window's reference: ``reference``, or where it ties no other receiver (recovered, its
    clock gone) the receiver of the most arrivals there (the windows carry the season's time base to it:
    :mod:`sblsim.models.sync.windows`)."""
    n = len(synchronised)
    linked = connected(receiver, emission, n, reference) & synchronised
    if linked.sum() >= 2 or not len(receiver):
        return linked, reference
    here = int(np.argmax(np.bincount(receiver, minlength=n)[:n] * synchronised))
    return connected(receiver, emission, n, here) & synchronised, here


__all__ = ["breaks_in_windows", "clocks_in_windows"]
