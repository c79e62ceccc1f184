"""The replay's tracker model: the timing noise and depth noise it assumes, its settings
(:class:`~sblsim.models.tracking.ekf.TrackerSettings`), the steps between the pings (:func:`ping_schedule`: the ping
type given or inferred) and the motion model's noise (:func:`motion_model`: given, or estimated by EM)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.motion_noise import estimate_acceleration_psd

#: The standard deviation of a time of arrival the tracker assumes [s] (Lake Hald's single-ping residuals: 0.13 ms
#: by their median absolute deviation, 0.15 ms by their standard deviation).
SIGMA_TOA = 1.5e-4


#: Consecutive mutually consistent single-ping fixes of dim + 2 receivers, all outside the prediction, that restart
#: a lost EKF (:class:`~sblsim.models.tracking.ekf.TrackerSettings` ``agree_after``).
AGREE_AFTER = 4


#: The standard deviation of a tag's depth reading the tracker assumes by default [m]
#: (:class:`~sblsim.models.tracking.ekf.TrackerSettings` ``depth_sigma``).
DEPTH_SIGMA = 0.3


def tracker_settings(sound_speed: float, emissions: np.ndarray):
    """The replay's tracker (:class:`~sblsim.models.tracking.ekf.TrackerSettings`) at ``sound_speed``
    [m/s]: the timing noise :data:`SIGMA_TOA`, the ping interval the median step of the single-ping fixes' emission
    times ``emissions`` (m,) [s] (NaN where no fix; 2 s when no two consecutive pings have one), and a lost filter
    restarted on :data:`AGREE_AFTER` consecutive consistent fixes of dim + 2 receivers too (an array of few
    receivers rarely gives the dim + 3 of the disagreement rule, docs/tracking.md)."""
    from sblsim.models.receiver.toa_tracking import TrackerSettings

    steps = np.diff(emissions)
    interval = float(np.nanmedian(steps)) if np.isfinite(steps).any() else 2.0
    return TrackerSettings(sound_speed=sound_speed, sigma_toa=SIGMA_TOA, interval=interval, agree_after=AGREE_AFTER)


def ping_schedule(toa: np.ndarray, positions: np.ndarray, settings, ping_type: str | None = None,
                  burst_interval: tuple[float, float] | None = None, burst_sequence: np.ndarray | None = None):
    """The steps between the rows of ``toa`` (m, n) [s] (:class:`~sblsim.models.tracking.schedule.PingSchedule`)
    for the tracker's ``settings`` at the receivers ``positions`` (n, dim) [m]: the ping type given (``sbi``,
    ``rbi``, ``pbi``), else the one the first arrivals' spacing shows (``rbi`` when ``burst_interval`` (min, max)
    [s] is given, ``pbi`` when ``burst_sequence`` (the intervals [s]) is), and what was seen of the spacing."""
    crossing = ps.crossing_time(positions, settings.sound_speed)
    seen = ps.infer_ping_type(toa, crossing)
    kind = ping_type or ("pbi" if burst_sequence is not None else "rbi" if burst_interval is not None else seen.kind)
    source = "given" if (ping_type or burst_interval is not None or burst_sequence is not None) else "inferred"
    interval = settings.interval if kind == "sbi" else float(np.mean(burst_interval)) if burst_interval else \
        seen.interval
    bounds = burst_interval if burst_interval is not None else (seen.bounds if kind == "rbi" else None)
    schedule = ps.build_schedule(toa, kind, interval, settings.jitter, settings.interval_drift, crossing,
                                 burst_interval, burst_sequence, source)
    return replace(schedule, bounds=bounds), seen


def motion_model(toa: np.ndarray, positions: np.ndarray, settings, schedule, fixes, acceleration_psd: float | None):
    """The tracker's settings with the motion model's ``q`` [m²/s³]: ``acceleration_psd`` where given, else
    estimated by EM (:func:`~sblsim.models.tracking.motion_noise.estimate_acceleration_psd`) from the single-ping
    fixes' own track (``fixes``: positions, emission times and the arrivals used, as
    :func:`~sblsim.models.receiver.toa_tracking.fix_pings` gives them), the default kept where they give no track;
    and what was done (``summary.json``'s ``motion``)."""
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
    return replace(settings, acceleration_psd=found.q), {
        "acceleration_psd_m2_s3": found.q, "source": "estimated (EM)", "iterations": found.iterations,
        "converged": found.converged, "history": list(found.history)}


__all__ = ["AGREE_AFTER", "DEPTH_SIGMA", "SIGMA_TOA", "motion_model", "ping_schedule", "tracker_settings"]
