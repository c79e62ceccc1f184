"""Clock breaks: a receiver whose clock jumps (a reset, a download, a battery change) or goes back, found from its
sync-tag arrivals and split into **clock segments**, each with its own offsets and drifts.

The clock model of :mod:`sblsim.models.sync.clocks` is continuous: a jump of a receiver's clock cannot be fitted,
and the robust fit spreads it over the record (a jump of 0.5 s became a ramp of ±0.1 s, most of its arrivals
rejected). So, after the fit (:func:`fit_with_breaks`):

1. each arrival's **offset sample** (:func:`~sblsim.models.sync.change_points.offset_samples`): its time less its
   travel time less the emission's time estimated from the *other* receivers' kept arrivals on their fitted clocks,
   less its receiver's fitted offset (a smooth curve). The receiver itself is left out of the emission's time, so
   that a broken clock cannot hide its own step there, and a break of the reference receiver shows at the reference
   (the others agree among themselves), not at every other;
2. each clock's samples in its own time order are a change-point problem (a mean shift in a series with a smooth
   trend: Bai & Perron 1998, *Econometrica* 66:47). A sample off both the line through the same sync tag's two
   previous samples and the line through its two next ones, on the same side, by more than
   :data:`~sblsim.models.sync.change_points.SPIKE` robust sigmas is set aside (a late arrival; a step has one of the
   two lines through it); the rest are fitted by weighted least squares with the clock model (the knots over the
   bins, the drift prior) plus a constant per sync tag (a position error of the table is a constant per pair: metres
   on the boats array) and, for every gap between two successive samples, a **jump** from that gap on
   (:func:`~sblsim.models.sync.change_points.scan`). The jump's estimate and the drop in chi-square it brings come
   for every gap at once from the residual-maker's quadratic forms by suffix sums (the knots' part bin by bin), in
   O(samples × tags² + bins³);
3. the best gap's statistic is the square root of its F ratio (the chi-square drop over the variance of the
   residuals of the model with that jump): a break where it exceeds :data:`THRESHOLD`, with at least
   :data:`~sblsim.models.sync.change_points.MIN_SIDE` samples on each side. A jump below the sync's resolution (a
   few of its sigmas) is none and stays absorbed by the drifts. A clock's last (or first) run of arrivals the fit
   rejected that :func:`~sblsim.models.sync.end_breaks.end_runs` takes for a break too near its end, of fewer than
   ``MIN_SIDE`` (where no gap may be), is left out of the search (cut afterwards by
   :func:`~sblsim.models.sync.end_breaks.cut_ends`): in it, it pulls the best gap to ``MIN_SIDE`` from the end, the
   jump there fitted with the last bin's knots bent to it (on the boats data, +0.5 s with 5 arrivals beyond it made
   a split 40 min before it, of 1 ms once refitted);
4. the clock with the largest statistic is split at that gap (the arrivals after it a new clock row of the same
   receiver: :attr:`~sblsim.models.sync.clock_fit.ClockFit.site`) and the clocks refitted; the arrivals about the
   break are then put in the segment against whose refitted clock they fit (where the time went back, the two
   segments read the same times), the clocks refitted again if one moved, and all again until no break is left.
   The two segments' drifts in the break's bin are tied by the drift prior (the crystal runs on at its rate:
   ``ties`` in :func:`~sblsim.models.sync.clocks.fit_clocks`), and a later segment of the reference receiver keeps
   its drift (the time base stays its crystal's: ``steady``).

A receiver whose time went back in the file's order (a reset kept in its logging order: its **clock parts**,
``part`` of :func:`fit_with_breaks`) is split at each part before the search, the break's place certain and its
size fitted like any other's (no arrival set aside there: two parts may read the same times, each arrival's part
says which clock read it); its drifts are tied only where the last arrival before and the first after fall in one
bin. Such a part's arrivals are first aligned to the others' for the emissions' grouping by
:func:`~sblsim.models.sync.clock_parts.part_shifts` (a reset of a day puts them a day from their emissions).

A segment's offsets hold for the times of its receiver's own clock it read
(:attr:`~sblsim.models.sync.clock_fit.ClockFit.span`, within its part); between the last arrival before a found break
and the first after it (widened by the jump where the time went back: the readings both segments make) a time is in
neither, and a detection there belongs to no synchronised clock (set aside); where the arrivals put in the two
segments interleave in time beyond the jump, the stretch is the whole interleave (never inverted). Units: seconds
[s] throughout.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from time import perf_counter

import numpy as np

from sblsim.models.sync.change_points import MIN_SIDE, _best, offset_samples
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clocks import Geometry, fit_clocks
from sblsim.models.sync.emissions import connected
from sblsim.models.sync.end_breaks import end_runs

#: The statistic (√F of the best jump) above which a clock break is taken.
THRESHOLD = 12.0
#: The most breaks found in one fit.
MAX_BREAKS = 20


@dataclass
class ClockBreak:
    """A break found in a receiver's clock.

    Attributes
    ----------
    receiver : int
        The receiver (the clock rows' :attr:`~sblsim.models.sync.clock_fit.ClockFit.site`).
    before, after : int
        The clock rows of the segments before and after it.
    last, first : float
        [s] the receiver's own times of its last arrival before the break and its first after it.
    size, size_sigma : float
        [s] the jump (the clock after less the clock before at the same instant: > 0 it jumped ahead, < 0 its time
        went back) and its sigma.
    time, time_within : float
        [s] the break's instant on the reference clock (the middle of the two arrivals, each synchronised by its
        segment) and half their interval (the instant is within it).
    statistic : float
        √F of the jump when it was found (:data:`THRESHOLD`); NaN for a reset from the file's order.
    part : int or None
        The clock part the break starts where it is a reset from the file's order (``part`` of
        :func:`fit_with_breaks`: its place known, not searched for), else None.
    """

    receiver: int
    before: int
    after: int
    last: float
    first: float
    size: float
    size_sigma: float
    time: float
    time_within: float
    statistic: float
    part: int | None = None


def fit_with_breaks(receiver: np.ndarray, emission: np.ndarray, time: np.ndarray, distance: np.ndarray,
                    slowness: np.ndarray | None, used: np.ndarray, synchronised: np.ndarray, reference: int,
                    bin_width: float, tag: np.ndarray, drift_change: float = 1e-6, geometry: Geometry | None = None,
                    threshold: float = THRESHOLD, max_breaks: int = MAX_BREAKS, timings: dict | None = None,
                    part: np.ndarray | None = None) -> ClockFit:
    """The clocks fitted (:func:`~sblsim.models.sync.clocks.fit_clocks`), their breaks found and each broken clock
    split into segments (the module docstring).

    Parameters
    ----------
    receiver, emission, time, distance, slowness, used, synchronised, reference, bin_width, drift_change, geometry
        As :func:`~sblsim.models.sync.clocks.fit_clocks` takes them (``receiver``, ``synchronised`` and
        ``reference`` the receivers').
    tag : numpy.ndarray
        (n,) int, each arrival's sync tag.
    threshold : float
        The statistic above which a break is taken (:data:`THRESHOLD`); ``inf``: none looked for.
    max_breaks : int
        The most breaks taken.
    timings : dict, optional
        As :func:`~sblsim.models.sync.clocks.fit_clocks` fills it (its last fit's), with ``breaks`` [s] the search.
    part : numpy.ndarray, optional
        (n,) int, each arrival's clock part (1 first; a later one after its receiver's time went back in the
        file's order): each later part a clock segment of its own from the start, its break's place known (the
        module docstring). None: one part.

    Returns
    -------
    ClockFit
        Where no break was found the fit of :func:`~sblsim.models.sync.clocks.fit_clocks` itself; else one row per
        clock segment, with :attr:`~sblsim.models.sync.clock_fit.ClockFit.site`, ``span``, ``clock`` and ``breaks``.

    Raises
    ------
    ModelError
        As :func:`~sblsim.models.sync.clocks.fit_clocks`.
    """
    timings = {} if timings is None else timings
    n_receivers = len(synchronised)
    rows = np.asarray(receiver, np.int64).copy()
    site = list(range(n_receivers))
    span = [[-np.inf, np.inf] for _ in range(n_receivers)]
    linked = np.asarray(synchronised, bool).copy()
    arrival_part = np.ones(len(rows), np.int64) if part is None else np.asarray(part, np.int64)
    row_part = [1] * n_receivers
    found: list[dict] = []
    for j, p in sorted({(int(a), int(b)) for a, b in zip(receiver, arrival_part) if b > 1}):
        # a reset from the file's order: the part its own clock segment, the break between it and the part before
        mine = (receiver == j) & (arrival_part == p)
        earlier = (receiver == j) & (arrival_part < p)
        new = len(site)
        before = max((r for r in range(len(site)) if site[r] == j and row_part[r] < p), key=lambda r: row_part[r])
        site.append(j)
        span.append([-np.inf, np.inf])
        row_part.append(p)
        rows[mine] = new
        last = time[earlier & (arrival_part == row_part[before])]
        found.append({"receiver": j, "before": before, "after": new, "statistic": np.nan, "size": np.nan,
                      "last": float(last.max()) if len(last) else np.nan, "first": float(time[mine].min()),
                      "part": p})

    def refit():
        nonlocal linked
        if len(site) > n_receivers:  # a segment no other clock is tied to is not synchronised
            heard = connected(rows[used & (rows >= 0)], emission[used & (rows >= 0)], len(site), reference)
            linked = heard & np.asarray(synchronised, bool)[np.array(site)]
        geo = None if geometry is None else replace(geometry, site=np.array(site))
        steady = None if len(site) == n_receivers else np.array(site) == reference
        return fit_clocks(np.maximum(rows, 0), emission, time, distance, slowness, used & (rows >= 0), linked,
                          reference, bin_width, drift_change=drift_change, geometry=geo, timings=timings,
                          steady=steady, ties=tied(fit_edges))

    def tied(edges: np.ndarray | None) -> np.ndarray | None:
        """Each break's two segments' drifts tied in the bin of its last arrival before it (a reset's only where
        its first arrival after it is in that bin too: its two parts read different times)."""
        if not found or edges is None:
            return None
        width = edges[1] - edges[0]

        def bin_of(t: float) -> int:
            return int(np.clip((t - edges[0]) // width, 0, len(edges) - 2)) if np.isfinite(t) else -1

        out = [(e["before"], e["after"], bin_of(e["last"])) for e in found
               if "part" not in e or (bin_of(e["last"]) == bin_of(e["first"]) >= 0)]
        return np.array(out, np.int64) if out else None

    fit_edges = None
    fit = refit()
    fit_edges = fit.edges  # the same for every refit: the arrivals' span, whatever their clocks
    searched = 0.0
    while np.isfinite(threshold) and len(found) < max_breaks:
        tick = perf_counter()
        # a run of rejected arrivals beyond a break too near a clock's end to split there (fewer than MIN_SIDE: cut by
        # end_breaks.cut_ends afterwards) left out of the search: in it, it pulls the best gap to MIN_SIDE from the end
        searched_used = used & (rows >= 0)
        z = offset_samples(fit, rows, emission, time, distance, slowness, searched_used)
        for _, _, run, _, _ in end_runs(fit, rows, z, time, tag):
            if len(run) < MIN_SIDE:
                searched_used[run] = False  # (rejected by the fit: no other arrival's sample moves)
        jump = _best(fit, rows, emission, time, distance, slowness, searched_used, tag, drift_change * bin_width,
                     threshold)
        searched += perf_counter() - tick
        if jump is None:
            break
        new = len(site)
        site.append(site[jump.row])
        span.append([np.nan, span[jump.row][1]])
        row_part.append(row_part[jump.row])
        rows[jump.after] = new
        for other in found:  # an earlier break after this one now follows the new segment
            if other["before"] == jump.row and other["last"] >= jump.first:
                other["before"] = new
        entry = {"receiver": site[jump.row], "before": jump.row, "after": new, "statistic": jump.statistic,
                 "size": jump.size}
        found.append(entry)
        classified = np.zeros(len(rows), bool)
        classified[jump.after] = classified[jump.before] = True
        same = arrival_part == row_part[jump.row]  # its part's arrivals alone (another part may read these times)
        _bounds(entry, rows, receiver, time, classified, jump.size, span, same)
        fit = refit()
        # the arrivals about the break put where the refitted clocks say they belong (where the time went back, the
        # ones the first cut misplaced), and the clocks refitted if one moved
        size = _measured(fit, entry).size
        size = jump.size if not np.isfinite(size) else size
        wide = 2 * abs(size) + 60.0
        settled, moved = _settle(fit, rows, receiver, used & same, entry, emission, time, distance, slowness,
                                 min(entry["last"], entry["first"]) - wide, max(entry["last"], entry["first"]) + wide)
        if moved:
            _bounds(entry, rows, receiver, time, classified | settled, size, span, same)
            fit = refit()
    timings["breaks"] = searched
    if not found:
        return fit
    return replace(fit, site=np.array(site), span=np.array(span), clock=rows,
                   breaks=[_measured(fit, b) for b in found], part=None if part is None else np.array(row_part))


def _bounds(entry: dict, rows: np.ndarray, receiver: np.ndarray, time: np.ndarray, classified: np.ndarray,
            size: float, span: list, same: np.ndarray) -> None:
    """A break's bracket (``entry``'s ``last`` and ``first``: the last arrival ``classified`` before it, the first
    after it), its two segments' spans (the stretch between them widened by the jump where the time went back:
    the readings both may hold; where the bracket's two arrivals are in the wrong order beyond that, from the first
    after to the last before: never an inverted stretch) and the receiver's other arrivals there by their times (-1
    in the stretch), of its clock part (``same``) alone."""
    before, after = entry["before"], entry["after"]
    mine = (receiver == entry["receiver"]) & np.isin(rows, (before, after, -1)) & same
    mine &= (time >= span[before][0]) & (time <= span[after][1])
    fixed = mine & classified
    entry["last"] = float(time[fixed & (rows == before)].max())
    entry["first"] = float(time[fixed & (rows == after)].min())
    # the readings either segment may make, never inverted: where the arrivals the fit put in the two segments
    # interleave in time by more than the jump (the last before after the first after), the whole interleave
    low = min(entry["last"] + min(0.0, size), entry["first"])
    high = max(entry["first"] + max(0.0, -size), entry["last"])
    rest = mine & ~classified
    rows[rest & (time <= low)] = before
    rows[rest & (time >= high)] = after
    rows[rest & (time > low) & (time < high)] = -1
    span[before][1], span[after][0] = low, high


def _settle(fit: ClockFit, rows: np.ndarray, receiver: np.ndarray, used: np.ndarray, entry: dict,
            emission: np.ndarray,
            time: np.ndarray, distance: np.ndarray, slowness: np.ndarray | None, low: float, high: float
            ) -> tuple[np.ndarray, bool]:
    """The break's receiver's ``used`` arrivals with times in [``low``, ``high``] put in the segment (``before``
    or ``after``) against whose refitted clock their emission's time fits them best; the mask of those it could
    compare (the emission fitted) and whether one moved."""
    before, after = entry["before"], entry["after"]
    k = np.flatnonzero(used & (receiver == entry["receiver"]) & np.isin(rows, (before, after, -1)) & (time >= low)
                       & (time <= high))
    out = np.zeros(len(rows), bool)
    if not len(k) or not (np.isfinite(fit.knots[before, 0]) and np.isfinite(fit.knots[after, 0])):
        return out, False
    emitted = fit.emission_time[emission[k]]
    d = distance[k] if fit.distance is None else np.where(np.isfinite(fit.distance[k]), fit.distance[k], distance[k])
    travel = d * (fit.slowness if slowness is None else slowness[k])
    miss_before = np.abs(time[k] - fit.offset(np.full(len(k), before), time[k]) - travel - emitted)
    miss_after = np.abs(time[k] - fit.offset(np.full(len(k), after), time[k]) - travel - emitted)
    ok = np.isfinite(miss_before) & np.isfinite(miss_after)
    choice = np.where(miss_after < miss_before, after, before)
    moved = ok & (choice != rows[k])
    rows[k[ok]] = choice[ok]
    out[k[ok]] = True
    return out, bool(moved.any())


def _reading(fit: ClockFit, row: int, instant: float) -> float:
    """[s] clock ``row``'s reading at the reference clock's ``instant`` (its offset's fixed point)."""
    r = instant
    for _ in range(4):
        r = instant + float(fit.offset(np.array([row]), np.array([r]))[0])
    return r


def _sigma(fit: ClockFit, row: int, time: float) -> float:
    """[s] clock ``row``'s offset sigma at its ``time`` (its knots' interpolated)."""
    width = fit.edges[1] - fit.edges[0]
    k = int(np.clip(np.floor((time - fit.edges[0]) / width), 0, len(fit.edges) - 2))
    f = (time - fit.edges[k]) / width
    return float(fit.knot_sigma[row, k] * (1 - f) + fit.knot_sigma[row, k + 1] * f)


def _measured(fit: ClockFit, found: dict) -> ClockBreak:
    """A break's size and instant from the refitted clocks of its two segments (the scan's where one of them is not
    synchronised)."""
    before, after = found["before"], found["after"]
    if not (np.isfinite(fit.knots[before, 0]) and np.isfinite(fit.knots[after, 0]) and np.isfinite(found["last"])):
        return ClockBreak(found["receiver"], before, after, found["last"], found["first"], found["size"], np.nan,
                          np.nan, np.nan, found["statistic"], found.get("part"))
    t0 = found["last"] - float(fit.offset(np.array([before]), np.array([found["last"]]))[0])
    t1 = found["first"] - float(fit.offset(np.array([after]), np.array([found["first"]]))[0])
    instant = 0.5 * (t0 + t1)
    r0, r1 = _reading(fit, before, instant), _reading(fit, after, instant)
    sigma = np.hypot(_sigma(fit, before, r0), _sigma(fit, after, r1))
    return ClockBreak(found["receiver"], before, after, found["last"], found["first"], r1 - r0, float(sigma),
                      instant, 0.5 * abs(t1 - t0), found["statistic"], found.get("part"))


__all__ = ["ClockBreak", "MAX_BREAKS", "THRESHOLD", "fit_with_breaks"]
