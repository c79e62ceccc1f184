"""Where the robust smoother starts: the single-ping fixes' own track, that track graduated, the RTS smoother's;
the lowest cost kept (the smoother's cost is not convex).

References
----------
Blake & Zisserman, *Visual Reconstruction*, MIT Press 1987 (graduated non-convexity).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.modes import with_modes
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.smoother import ROBUST_COARSE_ITERATIONS, ROBUST_COARSE_SCALE, RobustTrack, robust_smooth


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
    (:func:`robust_smooth`); with late arrivals modelled, its other local modes searched
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
    track = replace(robust_smooth(toa, receivers, settings, list(starts.values()), schedule=schedule, depth=depth),
                    start_names=tuple(starts))
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


__all__ = ["NEIGHBOURS", "anchored_start", "graduated_start", "robust_track"]
