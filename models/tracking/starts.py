"""Where the robust smoother starts: the single-ping fixes' own track, that track graduated, the RTS smoother's;
the lowest cost kept (the smoother's cost is not convex); then the fixes the track disagrees with spliced in as
starts again (:func:`with_fixes_spliced`).

References
----------
Blake & Zisserman, *Visual Reconstruction*, MIT Press 1987 (graduated non-convexity).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.modes import MODE_BETTER, with_modes
from sblsim.models.tracking.quality import FIX_SLACK, explained
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.smoother import (
    ROBUST_COARSE_ITERATIONS,
    ROBUST_COARSE_SCALE,
    RobustTrack,
    robust_smooth,
    with_covariance,
)
from sblsim.models.tracking.smoother_windows import Resolved, resolved_windows


def graduated_start(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, start: np.ndarray,
                    schedule: PingSchedule | None = None, depth: np.ndarray | None = None) -> np.ndarray:
    """A start for :func:`robust_smooth` by graduated non-convexity (Blake & Zisserman, *Visual Reconstruction*,
    MIT Press 1987): the robust smoother with the timing noise's scale :data:`ROBUST_COARSE_SCALE` times larger
    (the arrivals' Student-t cost flatter over the residuals seen, the motion model weighing more: fewer local
    minima), :data:`ROBUST_COARSE_ITERATIONS` steps from ``start`` (m, 2 dim + 2); its states (m, 2 dim + 2).

    Raises
    ------
    ModelError
        As :func:`robust_smooth`.
    """
    coarse = replace(settings, sigma_toa=settings.sigma_toa * ROBUST_COARSE_SCALE)
    return robust_smooth(toa, receivers, coarse, [start], iterations=ROBUST_COARSE_ITERATIONS, covariance=False,
                         schedule=schedule, depth=depth).x


def robust_track(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings,
                 fixes: tuple[np.ndarray, np.ndarray, np.ndarray], rts: np.ndarray | None,
                 schedule: PingSchedule | None = None, depth: np.ndarray | None = None,
                 modes: bool = True) -> RobustTrack:
    """The robust smoother of a record from its starts: the single-ping fixes' own track (:func:`anchored_start`),
    that track graduated (:func:`graduated_start`) and the RTS smoother's states ``rts`` (m, 2 dim + 2; None: the
    fixes' two starts alone, e.g. a record too long for the EKF's ping-by-ping loop); the lowest cost kept
    (:func:`robust_smooth`), then re-solved from the fixes it disagrees with (:func:`with_fixes_spliced`), its
    covariance made once, for the track kept (:func:`~sblsim.models.tracking.smoother.with_covariance`); with late
    arrivals modelled, its other local modes searched
    (:func:`~sblsim.models.tracking.modes.with_modes`). ``fixes``: positions (m, dim), emission times (m,) and the
    arrivals used (m, n) of :func:`fix_pings` for the same pings as ``toa`` (m, n); ``schedule`` the steps between them
    (:class:`~sblsim.models.tracking.schedule.PingSchedule`, default one stable interval each); ``depth`` (m,) the
    tag's depth readings [m] (:func:`robust_smooth`); ``modes`` False: the smoother alone, its other modes not
    searched (e.g. to time the search apart: benchmarks/bench_modes.py).

    Raises
    ------
    ModelError
        As :func:`robust_smooth` (no start: ``rts`` None and too few fixes).
    """
    if schedule is None:
        schedule = PingSchedule.stable(len(toa), settings.interval, settings.jitter, settings.interval_drift)
    starts = {} if rts is None else {"rts": rts}
    anchored = anchored_start(fixes, np.isfinite(toa).sum(axis=1), settings, receivers.shape[1], schedule.times())
    if anchored is not None:
        starts = {"fixes": anchored,
                  "graduated": graduated_start(toa, receivers, settings, anchored, schedule, depth), **starts}
    names = tuple(starts)
    del anchored  # each start's states (m, 2 dim + 2) held by the solve alone, released once it has copied them
    # the first track handed on unnamed, held by the splices alone (released once a round improves on it), and the
    # covariance made once, for the track kept: of 10⁶ pings each of these arrays is tens of MB
    track = with_fixes_spliced(
        replace(robust_smooth(toa, receivers, settings, [starts.pop(name) for name in names], covariance=False,
                              schedule=schedule, depth=depth), start_names=names),
        toa, receivers, settings, fixes, schedule, depth)
    track = with_covariance(track, toa, receivers, settings, schedule, depth)
    return with_modes(track, toa, receivers, settings, schedule, depth) if modes else track


def anchored_start(fixes: tuple[np.ndarray, np.ndarray, np.ndarray], heard: np.ndarray, settings: TrackerSettings,
                   dim: int, times: np.ndarray | None = None) -> np.ndarray | None:
    """A starting track for :func:`robust_smooth` from the single-ping fixes alone: the fixes of dim + 2 receivers or
    more that kept every arrival of their ping (each within ``fix_speed`` × elapsed time + 5 m of the median of its
    six neighbours among them), interpolated linearly in time (the velocity their differences, the emission
    time advanced by the time elapsed since the nearest such fix before); None when fewer than 2 remain.

    Parameters
    ----------
    fixes : tuple
        Positions (m, dim) [m], emission times (m,) [s] and the arrivals used (m, n), as :func:`fix_pings` gives.
    heard : ndarray, (m,)
        The arrivals of each ping.
    settings : TrackerSettings
    dim : int
    times : ndarray, (m,), optional
        Each ping's time from the first [s] (:meth:`~sblsim.models.tracking.schedule.PingSchedule.times`; default
        the nominal interval per ping).
    """
    position, emission, used = fixes
    m = len(position)
    times = np.arange(m) * settings.interval if times is None else np.asarray(times, float)
    good = np.flatnonzero(np.isfinite(emission) & (used.sum(axis=1) >= dim + 2) & (used.sum(axis=1) == heard))
    keep = _near_the_neighbours(position[good], times[good], settings.fix_speed)
    good = good[keep]
    if len(good) < 2:
        return None
    pings = np.arange(m)
    X = np.empty((m, 2 * dim + 2))
    for a in range(dim):
        X[:, a] = np.interp(times, times[good], position[good, a])
        X[:, dim + a] = np.gradient(X[:, a], times) if m > 1 else 0.0
    before = good[np.clip(np.searchsorted(good, pings, side="right") - 1, 0, len(good) - 1)]
    X[:, -2] = emission[before] + (times - times[before])
    X[:, -1] = settings.interval
    return X


#: The neighbours of a fix :func:`anchored_start` checks it against: up to three on each side.
NEIGHBOURS = 3


def _near_the_neighbours(position: np.ndarray, times: np.ndarray, fix_speed: float) -> np.ndarray:
    """Whether each fix (g, dim) [m] at ``times`` (g,) [s] lies within ``fix_speed`` × the time elapsed to the
    farthest of its (up to) six neighbours + 5 m of their median (per axis, :func:`numpy.median`'s value: the middle
    one, or the mean of the two middle ones), all fixes at once: (g,) bool; True for a fix without neighbours."""
    g = len(position)
    offsets = np.r_[-NEIGHBOURS:0, 1:NEIGHBOURS + 1]
    index = np.arange(g)[:, None] + offsets[None, :]  # (g, 6)
    inside = (index >= 0) & (index < g)
    index = np.clip(index, 0, max(g - 1, 0))
    count = inside.sum(axis=1)
    ordered = np.sort(np.where(inside[:, :, None], position[index], np.nan), axis=1)  # NaN last
    rows = np.arange(g)
    upper, lower = ordered[rows, count // 2], ordered[rows, np.maximum(count - 1, 0) // 2]
    median = np.where((count % 2 == 1)[:, None], upper, (lower + upper) / 2)
    elapsed = np.where(inside, np.abs(times[index] - times[:, None]), -np.inf).max(axis=1, initial=-np.inf)
    with np.errstate(invalid="ignore"):
        near = np.sqrt(np.square(position - median).sum(axis=1)) <= fix_speed * elapsed + 5.0
    return near | (count == 0)


#: Pings each side of a fix that :func:`spliced` moves with it (the move tapering linearly to none beyond them).
SPLICE_WINDOW = 3

#: Rounds of :func:`with_fixes_spliced` at most (each a re-solve of the windows about the fixes to splice).
SPLICE_ROUNDS = 3

#: Pings each side of a fix to splice that its window re-solves at first (:func:`with_fixes_spliced`; beyond
#: :data:`SPLICE_WINDOW`, the splice's own reach).
SPLICE_MARGIN = 16

#: A window's solve from the splice counts as the whole record's where its rows beside the held ones lie within this
#: [m] of the same window's solve from the track (the position, or the emission time times the sound speed): the
#: splice's reach ends inside it. Else its margins are doubled and it is solved again.
SPLICE_EDGE = 1e-7


def splice_pings(X: np.ndarray, toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings,
                 fixes: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """The pings whose single-ping fix explains more of the ping's arrivals than the track does
    (:func:`~sblsim.models.tracking.quality.explained`), dim + 1 at least (enough to place the tag and its emission
    time), and lies more than :data:`~sblsim.models.tracking.quality.FIX_SLACK` from the track: where the track may
    sit in another local minimum than the ping's own data point to.

    Parameters
    ----------
    X : ndarray, (m, 2 dim + 2)
        The track's states.
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    settings : TrackerSettings
        ``sound_speed`` and ``sigma_toa``.
    fixes : tuple
        Positions (m, dim) [m], emission times (m,) [s] and the arrivals used (m, n), as :func:`fix_pings` gives.

    Returns
    -------
    ndarray of int
        The pings, increasing.
    """
    position = np.asarray(fixes[0], float)
    dim = receivers.shape[1]
    with np.errstate(invalid="ignore"):
        far = np.linalg.norm(X[:, :2] - position[:, :2], axis=1) > FIX_SLACK  # False where no fix
    far &= np.isfinite(position).all(axis=1) & np.isfinite(fixes[1])
    rows = np.flatnonzero(far)  # each ping's count its own arrivals' (explained): those of these pings alone
    theirs = explained(toa[rows], receivers, position[rows], settings.sound_speed, settings.sigma_toa)
    ours = explained(toa[rows], receivers, X[rows, :dim], settings.sound_speed, settings.sigma_toa)
    return rows[(theirs >= dim + 1) & (theirs > ours)]


def spliced(X: np.ndarray, fixes: tuple[np.ndarray, np.ndarray, np.ndarray], pings: np.ndarray) -> np.ndarray:
    """A start: the track ``X`` (m, 2 dim + 2) with each of ``pings`` moved onto its fix (position and emission
    time) and the :data:`SPLICE_WINDOW` pings each side moved with it by a share falling linearly to none (a ping
    in two windows takes the nearer fix's); states (m, 2 dim + 2)."""
    position, emission = np.asarray(fixes[0], float), np.asarray(fixes[1], float)
    m, dim = len(X), position.shape[1]
    out = np.array(X, float)
    share = np.zeros(m)
    for k in pings:
        rows = np.arange(max(k - SPLICE_WINDOW, 0), min(k + SPLICE_WINDOW, m - 1) + 1)
        w = 1.0 - np.abs(rows - k) / (SPLICE_WINDOW + 1)
        nearer = w > share[rows]
        rows, w = rows[nearer], w[nearer]
        out[rows, :dim] = X[rows, :dim] + w[:, None] * (position[k] - X[k, :dim])
        share[rows] = w
    out[pings, -2] = emission[pings]
    return out


def with_fixes_spliced(track: RobustTrack, toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings,
                       fixes: tuple[np.ndarray, np.ndarray, np.ndarray], schedule: PingSchedule,
                       depth: np.ndarray | None = None) -> RobustTrack:
    """The robust smoother re-solved from the track with the fixes it disagrees with spliced in (:func:`splice_pings`,
    :func:`spliced`), kept where the whole cost is lower by more than
    :data:`~sblsim.models.tracking.modes.MODE_BETTER`; up to :data:`SPLICE_ROUNDS` rounds while any such fix
    remains.

    The smoother's cost is not convex: on a thin array with random burst intervals (each ping's emission time free,
    so a ping of dim + 1 arrivals places itself exactly) a track can settle where it weighs down most arrivals of a
    stretch of pings, each ping's own fix there explaining more of them; its starts (:func:`robust_track`) are all
    of the whole record and do not leave that minimum. Each fix's splice is a local restart; the whole cost decides
    (on the 8 hydrophones of Lake Hald at U(20, 40) s, seed 1: the cost from 1,127 to 772, the RMS against the GPS
    from 17.9 to 5.15 m, docs/tracking.md).

    The cost is a sum of local terms, so a round re-solves the splice's windows alone, the rest of the track held
    (:func:`splice_windows`), as the whole record's re-solve from the track and from its splice would: the splice
    kept where it is lower than the track after the smoother's screening steps
    (:data:`~sblsim.models.tracking.smoother.ROBUST_SCREEN`) and, at the end, lower by more than ``MODE_BETTER``
    (all its windows together); the rest of the track, at its minimum already, moves by no more than the smoother's
    own stop leaves (micrometres). A track its solve left unconverged (stopped at its iterations allowed) has no
    minimum to hold: its rounds re-solve the whole record from the track and from its splice.

    Parameters
    ----------
    track : RobustTrack
        :func:`~sblsim.models.tracking.smoother.robust_smooth`'s answer (m pings).
    toa, receivers, settings, schedule, depth
        As the track was solved with.
    fixes : tuple
        As :func:`splice_pings`.

    Returns
    -------
    RobustTrack
        The track of the lowest cost found (``start`` and ``start_names`` the given track's; the windows' weights
        their solve's and the cost lowered by their gain, or a whole re-solve's answer), with its covariance where
        the given track has one (made once, for the track kept: a round's re-solve makes none); the given track
        itself where no round was kept.
    """
    given, covariance = track, track.P is not None
    for _ in range(SPLICE_ROUNDS):
        pings = splice_pings(track.x, toa, receivers, settings, fixes)
        if not len(pings):
            break
        start = spliced(track.x, fixes, pings)
        if not track.converged:
            again = robust_smooth(toa, receivers, settings, [track.x, start], schedule=schedule, depth=depth,
                                  covariance=False, student_start=False)
            if not again.cost < track.cost - MODE_BETTER:
                break
            track = replace(again, start=given.start, start_names=given.start_names)
            continue
        found = splice_windows(track.x, start, pings, toa, receivers, settings, schedule, depth)
        del start
        if not (found.screened.sum() > 0.0 and found.gain.sum() > MODE_BETTER):
            break
        X, weights = track.x.copy(), track.weights.copy()
        for b in range(len(found.lo)):
            X[found.lo[b]:found.hi[b]] = found.x[b]
            weights[found.lo[b]:found.hi[b]] = found.weights[b]
        track = replace(track, x=X, weights=weights, cost=track.cost - float(found.gain.sum()), P=None, P_lag=None)
    if track is given:
        return given
    return with_covariance(track, toa, receivers, settings, schedule, depth) if covariance else track


def splice_windows(X: np.ndarray, start: np.ndarray, pings: np.ndarray, toa: np.ndarray, receivers: np.ndarray,
                   settings: TrackerSettings, schedule: PingSchedule, depth: np.ndarray | None = None) -> Resolved:
    """The windows of the fixes to splice re-solved from their splice, the rest of the track held
    (:func:`~sblsim.models.tracking.smoother_windows.resolved_windows`): :data:`SPLICE_MARGIN` pings each side of
    each of ``pings`` (windows that would overlap or touch joined), each window's margins doubled and it solved
    again from the splice while its solve moves its rows beside the held ones by :data:`SPLICE_EDGE` or more from
    where the track's own states go in the same window (up to the record's ends: the whole record's re-solve from
    the splice); the windows not solved on where the splice loses the screening (its windows' cost after
    :data:`~sblsim.models.tracking.smoother.ROBUST_SCREEN` steps not below the track's there, as a whole record's
    re-solve drops a start), nor widened where their gain together is not above
    :data:`~sblsim.models.tracking.modes.MODE_BETTER` (the splice not kept).

    Parameters
    ----------
    X : ndarray, (m, 2 dim + 2)
        The track's states.
    start : ndarray, (m, 2 dim + 2)
        The track with the fixes spliced in (:func:`spliced`).
    pings : ndarray of int
        The fixes spliced (:func:`splice_pings`), increasing.
    toa, receivers, settings, schedule, depth
        As the track was solved with.

    Returns
    -------
    Resolved
        The windows, each with its gain (the whole cost's fall were its states put in); where the splice lost its
        screening, the screening's (:attr:`~sblsim.models.tracking.smoother_windows.Resolved.screened`, its sum
        not above 0), and the edges NaN where not measured.
    """
    m = len(X)
    margin = np.full(len(pings), SPLICE_MARGIN)
    done: dict[tuple[int, int], tuple] = {}  # each window solved: its states, weights, gains, edge
    first = True  # the first windows decide whether the splice is screened out, or not kept and not widened
    while True:
        lo, hi, owner = _joined(pings, margin, m)
        new = [b for b in range(len(lo)) if (lo[b], hi[b]) not in done]
        found = resolved_windows(X, start, lo[new], hi[new], toa, receivers, settings, schedule, depth,
                                 lost=(lambda screened: not screened.sum() > 0.0) if first else None,
                                 keep=(lambda gain: gain.sum() > MODE_BETTER) if first else None)
        first = False
        wide = set()
        for a, b in enumerate(new):
            done[lo[b], hi[b]] = (found.x[a], found.weights[a], found.gain[a], found.screened[a], found.edge[a])
            if found.edge[a] >= SPLICE_EDGE:  # not where the windows are not kept (NaN)
                wide.add(b)
        if not wide:
            parts = [done[key] for key in zip(lo, hi)]
            return Resolved(lo, hi, [p[0] for p in parts], [p[1] for p in parts],
                            *(np.array([p[c] for p in parts]) for c in (2, 3, 4)))
        margin[np.isin(owner, list(wide))] *= 2


def _joined(pings: np.ndarray, margin: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The windows ``lo:hi`` (B,) of ``margin`` (p,) pings each side of ``pings`` (p,), increasing, within ``0:m``,
    those that overlap or touch (one window's held rows ``lo − 1`` and ``hi`` another's rows) joined; and each
    ping's window (p,)."""
    lo, hi = np.maximum(pings - margin, 0), np.minimum(pings + margin + 1, m)
    order = np.argsort(lo, kind="stable")
    reach = np.maximum.accumulate(hi[order])
    starts = np.r_[True, lo[order][1:] > reach[:-1]]  # a new window where a ping's rows begin past the last's reach
    group = np.empty(len(pings), int)
    group[order] = np.cumsum(starts) - 1
    first = np.flatnonzero(starts)
    return lo[order][first], np.maximum.reduceat(hi[order], first), group


__all__ = ["NEIGHBOURS", "SPLICE_EDGE", "SPLICE_MARGIN", "SPLICE_ROUNDS", "SPLICE_WINDOW", "anchored_start",
           "graduated_start", "robust_track", "splice_pings", "splice_windows", "spliced", "with_fixes_spliced"]
