"""A clock break too near a clock's end (or its start) to fit a segment: the few arrivals beyond it set aside.

The change-point search of :mod:`sblsim.models.sync.breaks` needs
:data:`~sblsim.models.sync.change_points.MIN_SIDE` samples on each side of a break; a jump with fewer arrivals
after it (or before it, at the start) is not found, and the robust fit of
:func:`~sblsim.models.sync.clocks.fit_clocks` rejects those arrivals as outliers, silently, while the receiver's
detections there stay wrong by the jump. So, after the breaks are found (:func:`cut_ends`), each clock row's
arrivals with an offset sample (:func:`~sblsim.models.sync.change_points.offset_samples`: its time less its
travel time less the emission's time from the *other* receivers, less its clock's fitted offset) are taken in its
own time order, and its last (and first) run of consecutive arrivals the fit rejected is looked at: where at least
:data:`MIN_END` of them, heard from at least two sync tags (a shift of one tag alone is its path, not the clock),
agree on one shift (each within :data:`AGREE` sigmas of their median) that is at least :data:`LEVEL` sigmas from 0
(the sigma: the robust sigma of the row's kept samples), that is a break too near the clock's end to fit a
segment. Where the time went back, the two clocks read the same times, so good arrivals within the jump of the
run's first are passed over. The row's :attr:`~sblsim.models.sync.clock_fit.ClockFit.span` then ends at its last
good arrival (widened by the shift where the time went back: the readings the jumped clock may make there; and by
:data:`AGREE` sigmas), so that a time beyond it is in no segment (set aside, as between two segments at a break),
and the run's arrivals are put on no clock row (``clock`` -1). The fit itself is unchanged: those arrivals were
rejected. The same runs (:func:`end_runs`) of fewer than :data:`~sblsim.models.sync.change_points.MIN_SIDE` are left
out of the change-point search before it (:func:`~sblsim.models.sync.breaks.fit_with_breaks`). Units: seconds [s]
throughout.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sblsim.models.sync.change_points import MIN_SIDE, offset_samples
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clocks import MIN_SCALE
from sblsim.models.sync.noise import MAD_FACTOR

#: The fewest consecutive rejected arrivals at a clock's end taken as a break there.
MIN_END = 3
#: [sigmas] each of them within this of their median shift.
AGREE = 6.0
#: [sigmas] their median shift at least this far from 0.
LEVEL = 12.0


@dataclass
class EndBreak:
    """A break too near a clock row's end (or start) to fit a segment (the module docstring).

    Attributes
    ----------
    receiver, row : int
        The receiver and its clock row (:attr:`~sblsim.models.sync.clock_fit.ClockFit.site`).
    at_start : bool
        The break is near the row's start (its first arrivals set aside), else near its end.
    arrivals : int
        The arrivals beyond it, set aside.
    size, size_sigma : float
        [s] the jump (the clock after it less the clock before at the same instant: > 0 it jumped ahead, < 0 its
        time went back) and its sigma (the samples' robust sigma over the square root of the sync tags among them:
        a tag's position error, a constant of its samples, averages out over the tags only).
    sigma : float
        [s] the row's samples' robust sigma.
    time, time_within : float
        [s] the break's instant on the reference clock (the middle of the last arrival before it and the first
        after, each synchronised) and half their interval.
    aside_from, aside_to : float
        [s] the receiver's own times set aside (±inf open).
    """

    receiver: int
    row: int
    at_start: bool
    arrivals: int
    size: float
    size_sigma: float
    sigma: float
    time: float
    time_within: float
    aside_from: float
    aside_to: float


def cut_ends(fit: ClockFit, receiver: np.ndarray, emission: np.ndarray, time: np.ndarray, distance: np.ndarray,
             slowness: np.ndarray | None, used: np.ndarray, tag: np.ndarray) -> tuple[ClockFit, list[EndBreak]]:
    """The clock rows' breaks too near their ends to fit a segment found and the times beyond them set aside (the
    module docstring).

    Parameters
    ----------
    fit : ClockFit
        The clocks fitted with their breaks (:func:`~sblsim.models.sync.breaks.fit_with_breaks`).
    receiver, emission, tag : numpy.ndarray
        (n,) int, each arrival's receiver, emission and sync tag.
    time, distance : numpy.ndarray
        (n,) [s] each arrival on its receiver's clock and [m] its distance.
    slowness : numpy.ndarray or None
        (n,) [s/m]; None: the fit's estimate.
    used : numpy.ndarray
        (n,) bool, the arrivals fitted.

    Returns
    -------
    ClockFit
        ``fit`` itself where none was found; else with :attr:`~sblsim.models.sync.clock_fit.ClockFit.site`,
        ``span`` and ``clock`` (one row per receiver where no clock broke before, ``breaks`` then empty), each cut
        row's span ending (or starting) at its last (first) good arrival and the arrivals beyond it on no row (-1).
    list of EndBreak
        The breaks found, by row.
    """
    receiver = np.asarray(receiver, np.int64)
    rows = receiver if fit.clock is None else fit.clock
    z = offset_samples(fit, rows, emission, time, distance, slowness, used)
    found = [(_described(fit, row, at_start, run, good, z, time, tag, sigma), run)
             for row, at_start, run, good, sigma in end_runs(fit, rows, z, time, tag)]
    if not found:
        return fit, []
    found, runs = [b for b, _ in found], [r for _, r in found]
    n_rows = len(fit.knots)
    site = np.arange(n_rows) if fit.site is None else fit.site.copy()
    span = np.tile([-np.inf, np.inf], (n_rows, 1)) if fit.span is None else fit.span.copy()
    clock = receiver.copy() if fit.clock is None else fit.clock.copy()
    for b, run in zip(found, runs):
        span[b.row] = [max(span[b.row, 0], b.aside_to) if b.at_start else span[b.row, 0],
                       span[b.row, 1] if b.at_start else min(span[b.row, 1], b.aside_from)]
        clock[run] = -1
        outside = (time < span[b.row, 0]) | (time > span[b.row, 1])
        clock[(clock == b.row) & outside & ~fit.kept] = -1  # (a kept one there: fitted, where the time went back)
    return replace(fit, site=site, span=span, clock=clock, breaks=[] if fit.breaks is None else fit.breaks), found


def end_runs(fit: ClockFit, rows: np.ndarray, z: np.ndarray, time: np.ndarray, tag: np.ndarray
             ) -> list[tuple[int, bool, np.ndarray, int, float]]:
    """Each clock row's runs of arrivals beyond a break near its end (or start) (the module docstring's check).

    Parameters
    ----------
    fit : ClockFit
        The clocks fitted (its ``kept`` and ``knots``).
    rows, tag : numpy.ndarray
        (n,) int, each arrival's clock row (-1 on none) and sync tag.
    z, time : numpy.ndarray
        (n,) [s] each arrival's offset sample (:func:`~sblsim.models.sync.change_points.offset_samples`, NaN where
        it has none) and its time on its receiver's clock.

    Returns
    -------
    list of (int, bool, numpy.ndarray, int, float)
        Per run: its clock row, whether it is at the row's start, its arrivals (indices), the good arrival next to
        them and [s] the row's samples' robust sigma.
    """
    out = []
    for row in np.flatnonzero(np.isfinite(fit.knots[:, 0])):
        idx = np.flatnonzero((rows == row) & np.isfinite(z))
        idx = idx[np.argsort(time[idx], kind="stable")]
        kept = fit.kept[idx]
        if kept.sum() < MIN_SIDE:
            continue
        sigma = max(MAD_FACTOR * float(np.median(np.abs(z[idx[kept]] - np.median(z[idx[kept]])))), MIN_SCALE)
        for at_start in (False, True):
            order = idx[::-1] if not at_start else idx
            run = _run(order, fit.kept, z, time, tag, sigma, at_start)
            if run is not None:
                out.append((int(row), at_start, run[0], run[1], sigma))
    return out


def _run(order: np.ndarray, kept: np.ndarray, z: np.ndarray, time: np.ndarray, tag: np.ndarray, sigma: float,
         at_start: bool) -> tuple[np.ndarray, int] | None:
    """The arrivals beyond a break near the end ``order`` starts from (a row's arrivals from its end or its start)
    and the good arrival next to them, or None where there is none: the rejected arrivals that agree with the shift
    of the rejected ones there, taken from that end inward while every other arrival among them is within the
    jump of the farthest in (where the time went back the two clocks read the same times: the readings
    interleave), at least :data:`MIN_END` of them, heard from two sync tags or more, their shift far from 0; the
    good arrival: the kept one nearest that end."""
    bad = ~kept[order]
    k0 = int(np.argmin(bad)) if not bad.all() else len(order)
    if k0 == 0 or k0 == len(order):
        return None
    member = bad & (np.abs(z[order] - float(np.median(z[order[:k0]]))) <= AGREE * sigma)
    u = time[order] * (-1.0 if at_start else 1.0)  # decreasing along ``order``
    width = max(0.0, (1.0 if at_start else -1.0) * float(np.median(z[order[:k0]])))  # the readings both make
    c = 0
    for q in np.flatnonzero(member):  # the run up to member q: every other arrival before it within the width
        if (u[:q][~member[:q]] > u[q] + width + AGREE * sigma).any():
            break
        c = q + 1
    run = order[:c][member[:c]]
    if len(run) < MIN_END or len(np.unique(tag[run])) < 2 or abs(np.median(z[run])) < LEVEL * sigma:
        return None
    return run, int(order[np.argmax(kept[order])])


def _described(fit: ClockFit, row: int, at_start: bool, run: np.ndarray, good: int, z: np.ndarray,
               time: np.ndarray, tag: np.ndarray, sigma: float) -> EndBreak:
    """The break before the arrivals ``run`` near the row's end (start), ``good`` the good arrival next to them."""
    k = len(run)
    at = np.full(k, row)
    # each sample against the row's offset at the reading its clock would have made without the jump (a drift of
    # 20 ppm over a jump of 20 s: 0.4 ms), so that the shift is the two clocks' difference at one instant
    shift = float(np.median(z[run] + fit.offset(at, time[run]) - fit.offset(at, time[run] - z[run])))
    beyond = time[run].min() if not at_start else time[run].max()  # the run's arrival next to the good ones
    good = time[good]

    def instant(t: float) -> float:
        return t - float(fit.offset(np.array([row]), np.array([t]))[0])

    edge = [instant(good), instant(beyond - shift)]
    size = -shift if at_start else shift  # the clock after the break less the clock before
    if at_start:  # the jumped clock reads up to the first good arrival's time plus the shift (and its noise)
        aside = (-np.inf, good + max(0.0, shift) + AGREE * sigma)
    else:  # it reads from the last good arrival's time plus the shift on
        aside = (good + min(0.0, shift) - AGREE * sigma, np.inf)
    site = row if fit.site is None else int(fit.site[row])
    tags = len(np.unique(tag[run]))
    return EndBreak(site, row, at_start, k, size, sigma / np.sqrt(tags), sigma, 0.5 * (edge[0] + edge[1]),
                    0.5 * abs(edge[1] - edge[0]), *aside)


__all__ = ["AGREE", "EndBreak", "LEVEL", "MIN_END", "cut_ends", "end_runs"]
