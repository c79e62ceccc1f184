"""The replay's tracker model: the timing noise and depth noise it assumes (the timing noise given, each receiver's
from a synchronisation's residuals, else :data:`~sblsim.models.tracking.timing.SIGMA_TOA`: :func:`toa_noise`), its
settings (:class:`~sblsim.models.tracking.ekf.TrackerSettings`), the steps between the pings (:func:`ping_schedule`:
the ping type given or inferred) and the motion model's noise (:func:`motion_model`: given, or estimated by EM)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.motion_noise import estimate_acceleration_psd
from sblsim.models.tracking.ping_type import infer_ping_type
from sblsim.models.tracking.strays import SET_ASIDE_REASON, check_strays, stable_interval, stray_rows
from sblsim.models.tracking.timing import SIGMA_TOA

#: Consecutive mutually consistent single-ping fixes of dim + 2 receivers, all outside the prediction, that restart
#: a lost EKF (:class:`~sblsim.models.tracking.ekf.TrackerSettings` ``agree_after``).
AGREE_AFTER = 4


#: The standard deviation of a tag's depth reading the tracker assumes by default [m]
#: (:class:`~sblsim.models.tracking.ekf.TrackerSettings` ``depth_sigma``).
DEPTH_SIGMA = 0.3


def toa_noise(given: float | None, per_receiver: np.ndarray | None, names: list[str]
              ) -> tuple[float | np.ndarray, dict[str, Any]]:
    """The timing noise the tracker takes [s], and what was done (``summary.json``'s ``toa_noise``): ``given``
    (``--toa-sigma``, one for every receiver) where given; else each receiver's own, ``per_receiver`` (len(names),)
    [s] (a receivers file's ``toa_sigma_s``: what a synchronisation measured, NaN where a receiver has none, which
    takes the others' median, said); else :data:`~sblsim.models.tracking.timing.SIGMA_TOA`, assumed (said)."""
    if given is not None:
        return given, {"source": "given", "sigma_s": given}
    known = None if per_receiver is None else np.asarray(per_receiver, float)
    if known is None or not np.isfinite(known).any():
        return SIGMA_TOA, {"source": "assumed", "sigma_s": SIGMA_TOA}
    missing = [n for n, v in zip(names, known) if not np.isfinite(v)]
    sigma = np.where(np.isfinite(known), known, np.nanmedian(known))
    return sigma, {"source": "synchronisation", "sigma_s": float(np.median(sigma)),
                   "per_receiver_s": {n: float(v) for n, v in zip(names, sigma)},
                   "median_s": float(np.median(sigma)), "min_s": float(sigma.min()), "max_s": float(sigma.max()),
                   "min_receiver": names[int(np.argmin(sigma))], "max_receiver": names[int(np.argmax(sigma))],
                   "without": missing}


def noise_line(info: dict[str, Any], option: str = "--toa-sigma") -> str:
    """The console's line on the timing noise taken (:func:`toa_noise`'s ``info``; ``option`` how the caller spells
    the option that gives it)."""
    if info["source"] == "given":
        return f"TOA noise: {info['sigma_s'] * 1e3:.4g} ms (given, {option})"
    if info["source"] == "assumed":
        return (f"TOA noise: {info['sigma_s'] * 1e3:.4g} ms assumed (no synchronisation residuals); give "
                f"{option}")
    line = (f"TOA noise per receiver from the synchronisation's residuals: median {info['median_s'] * 1e3:.3g} ms, "
            f"{info['min_s'] * 1e3:.3g} ms ({info['min_receiver']}) to {info['max_s'] * 1e3:.3g} ms "
            f"({info['max_receiver']}), {len(info['per_receiver_s'])} receivers")
    if info["without"]:
        line += f"; the others' median for {', '.join(info['without'][:10])} (none measured)"
    return line


def tracker_settings(sound_speed: float, emissions: np.ndarray, sigma_toa: float | np.ndarray = SIGMA_TOA):
    """The replay's tracker (:class:`~sblsim.models.tracking.ekf.TrackerSettings`) at ``sound_speed``
    [m/s]: the timing noise ``sigma_toa`` [s] (one, or each receiver's (n,); default
    :data:`~sblsim.models.tracking.timing.SIGMA_TOA`), the ping
    interval the median step of the single-ping fixes' emission
    times ``emissions`` (m,) [s] (NaN where no fix; 2 s when no two consecutive pings have one), and a lost filter
    restarted on :data:`AGREE_AFTER` consecutive consistent fixes of dim + 2 receivers too (an array of few
    receivers rarely gives the dim + 3 of the disagreement rule, docs/tracking.md)."""
    from sblsim.models.receiver.toa_tracking import TrackerSettings

    steps = np.diff(emissions)
    interval = float(np.nanmedian(steps)) if np.isfinite(steps).any() else 2.0
    return TrackerSettings(sound_speed=sound_speed, sigma_toa=sigma_toa, interval=interval, agree_after=AGREE_AFTER)


def ping_schedule(toa: np.ndarray, positions: np.ndarray, settings, ping_type: str | None = None,
                  burst_interval: tuple[float, float] | None = None, burst_sequence: np.ndarray | None = None):
    """The steps between the rows of ``toa`` (m, n) [s] (:class:`~sblsim.models.tracking.schedule.PingSchedule`)
    for the tracker's ``settings`` at the receivers ``positions`` (n, dim) [m]: the ping type given (``sbi``,
    ``rbi``, ``pbi``), else the one the first arrivals' spacing shows (``rbi`` when ``burst_interval`` (min, max)
    [s] is given, ``pbi`` when ``burst_sequence`` (the intervals [s]) is), and what was seen of the spacing."""
    crossing = ps.crossing_time(positions, settings.sound_speed)
    seen = infer_ping_type(toa, crossing)
    kind = ping_type or ("pbi" if burst_sequence is not None else "rbi" if burst_interval is not None else seen.kind)
    source = "given" if (ping_type or burst_interval is not None or burst_sequence is not None) else "inferred"
    interval = settings.interval if kind == "sbi" else float(np.mean(burst_interval)) if burst_interval else \
        seen.interval
    bounds = burst_interval if burst_interval is not None else (seen.bounds if kind == "rbi" else None)
    schedule = ps.build_schedule(toa, kind, interval, settings.jitter, settings.interval_drift, crossing,
                                 burst_interval, burst_sequence, source)
    return replace(schedule, bounds=bounds), seen


def set_aside(toa: np.ndarray, positions: np.ndarray, fastest: float, burst_interval: tuple[float, float] | None = None,
              burst_sequence: np.ndarray | None = None, force: bool = False, option: str = "--force-interval",
              stable: bool = False, slowest: float | None = None
              ) -> tuple[np.ndarray, np.ndarray, dict[str, Any], str | None]:
    """The rows of ``toa`` (m, n) [s] that cannot be pings of the stated schedule, set aside
    (:func:`~sblsim.models.tracking.strays.stray_rows`): a random interval's min (``burst_interval`` (min, max)
    [s]), a pseudo-random sequence's least (``burst_sequence`` [s]) or, for a stable interval stated (``stable``:
    ``--ping-type sbi``), the interval its steps fit (:func:`~sblsim.models.tracking.strays.stable_interval` at the
    crossing time of ``slowest`` [m/s], the slowest sound speed allowed: it refuses one they contradict at any speed)
    less its tolerance, at the crossing time of the receivers
    ``positions`` (n, dim) [m] at ``fastest`` [m/s], the fastest sound speed allowed (the shortest crossing: a row
    kept here is kept by the schedule at any speed). A stated interval the rows contradict as a whole is refused
    (:func:`~sblsim.models.tracking.strays.check_strays`), or with ``force`` taken and said.

    Returns
    -------
    toa : ndarray, (m, n)
        The matrix with the rows set aside blanked (NaN): heard by nobody, no ping.
    stray : ndarray of bool, (m,)
    info : dict
        ``summary.json``'s ``set_aside``: the shortest interval [s], the rows set aside (0-based) and their count.
    warning : str or None
        With ``force``, where the rows contradict the interval: the line that says so.

    Raises
    ------
    ModelError
        A stated interval the rows contradict as a whole, without ``force``.
    """
    stray = np.zeros(len(toa), bool)
    crossing = ps.crossing_time(positions, fastest)
    # the stable interval the steps fit, checked as leniently as any speed allows (the schedule's check, at the
    # tracker's speed, is the one that refuses)
    interval = stable_interval(toa, crossing * fastest / (slowest or fastest))[0] \
        if stable and burst_interval is None and burst_sequence is None else None
    if interval is not None:  # the shortest first-arrival step of two pings: the interval less its tolerance
        shortest = interval - max(ps.SBI_CROSSINGS * crossing, ps.SBI_SHARE * interval) + crossing
        stated = f"a stable interval of {interval:.4g} s (its pings' steps)"
    elif burst_interval is not None:
        shortest, stated = float(burst_interval[0]), f"{burst_interval[0]:g}:{burst_interval[1]:g} s"
    elif burst_sequence is not None and len(burst_sequence):
        shortest = float(np.min(burst_sequence))
        stated = f"the burst sequence's {shortest:g} s least"
    else:
        return toa, stray, {"shortest_s": None, "rows": [], "count": 0, "forced": False}, None
    stray = stray_rows(toa, shortest, crossing)
    warning = check_strays(toa, stray, stated, shortest, force, option)
    out = toa.copy()
    out[stray] = np.nan
    rows = np.flatnonzero(stray)
    return out, stray, {"shortest_s": shortest, "rows": [int(k) for k in rows], "count": int(len(rows)),
                        "forced": warning is not None, "reason": SET_ASIDE_REASON}, warning


def motion_model(toa: np.ndarray, positions: np.ndarray, settings, schedule, fixes, acceleration_psd: float | None):
    """The tracker's settings with the motion model's ``q`` [m²/s³]: ``acceleration_psd`` where given, else
    estimated by EM (:func:`~sblsim.models.tracking.motion_noise.estimate_acceleration_psd`) from the single-ping
    fixes' own track (``fixes``: positions, emission times and the arrivals used, as
    :func:`~sblsim.models.receiver.toa_tracking.fix_pings` gives them), the default kept where they give no track;
    and what was done (``summary.json``'s ``motion``; ``windows``, the rows [first, end) EM smoothed, where a long
    record's E-steps took windows of it)."""
    from sblsim.models.receiver.toa_tracking import anchored_start

    if acceleration_psd is not None:
        return replace(settings, acceleration_psd=acceleration_psd), {
            "acceleration_psd_m2_s3": acceleration_psd, "source": "given"}
    dim = positions.shape[1]
    start = anchored_start(fixes, np.isfinite(toa).sum(axis=1), settings, dim, schedule.times())
    if start is None:
        return settings, {"acceleration_psd_m2_s3": settings.acceleration_psd,
                          "source": "default (too few fixes to estimate it)"}
    found = estimate_acceleration_psd(toa, positions, settings, start, schedule)
    said = {"acceleration_psd_m2_s3": found.q, "source": "estimated (EM)", "iterations": found.iterations,
            "converged": found.converged, "history": list(found.history)}
    if len(found.windows) > 1:  # a long record's E-steps over windows of it: which rows
        said["windows"] = [list(w) for w in found.windows]
    return replace(settings, acceleration_psd=found.q), said


__all__ = ["AGREE_AFTER", "DEPTH_SIGMA", "motion_model",
           "noise_line", "ping_schedule", "set_aside", "toa_noise", "tracker_settings"]
