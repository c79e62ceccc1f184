"""The telemetry design's confirmation by the tracker: a simulated tag's pings along its path tracked as
``sblsim replay --format toa`` tracks a recorded tag (the single-ping fixes, the ping type's schedule, the motion
noise by EM, the robust smoother; :mod:`sblsim.orchestrator.tracks.track`), its 2-D error against the path beside
the tracker's smoothing bound at the path's true positions and velocities (the PCRB of the same motion model and
schedule, :func:`~sblsim.models.receiver.toa_bound.pcrb`; Tichavský, Muravchik & Nehorai, IEEE Trans. Signal
Process. 46(5), 1998, and its smoothing form, Šimandl, Královec & Tichavský, Automatica 37, 2001), and the track's
NEES against its own covariance.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from sblsim.models.receiver import toa_bound as tb
from sblsim.models.receiver import toa_tracking as tt
from sblsim.orchestrator.tracks.track import motion_model, ping_schedule, tracker_settings


def track_path(receivers: np.ndarray, toa: np.ndarray, positions: np.ndarray, emissions: np.ndarray,
               sound_speed: float, sigma_toa: float, burst_interval: tuple[float, float]) -> dict:
    """Track a simulated tag's pings and score the track against its path.

    Parameters
    ----------
    receivers : ndarray, shape (n, 2)
        [m].
    toa : ndarray, shape (K, n)
        Times of arrival [s], NaN where not heard.
    positions : ndarray, shape (K, 2)
        The tag's true position at each emission [m].
    emissions : ndarray, shape (K,)
        The true emission times [s], increasing.
    sound_speed : float
        [m/s], given to the tracker (the design's).
    sigma_toa : float
        The timing σ [s].
    burst_interval : tuple of float
        The tag's random burst interval (min, max) [s] (``--ping-type rbi --burst-interval MIN:MAX``).

    Returns
    -------
    dict
        ``tracked_pings`` (the pings from the first heard by three receivers to the last heard by one: the rows
        the tracker positions and the bound starts from), ``tracked_rms_m`` (the robust smoother's 2-D RMS error
        over them), ``tracked_bound_m`` (the smoothing bound's RMS DRMS over the same pings), ``tracked_ratio``
        (their ratio), ``tracked_nees`` (the mean 2-D NEES against the track's covariance; 2 when consistent),
        ``tracked_p95_m`` and ``acceleration_psd_m2_s3`` (the EM's motion noise). NaN figures where fewer than
        ten pings can be tracked.
    """
    nothing = {"tracked_pings": 0, "tracked_rms_m": math.nan, "tracked_bound_m": math.nan,
               "tracked_ratio": math.nan, "tracked_nees": math.nan, "tracked_p95_m": math.nan,
               "acceleration_psd_m2_s3": math.nan}
    heard = np.isfinite(toa).sum(axis=1)
    starts, ends = np.flatnonzero(heard >= 3), np.flatnonzero(heard >= 1)
    if not len(starts) or ends[-1] - starts[0] + 1 < 10:
        return nothing
    rows = slice(starts[0], ends[-1] + 1)
    toa, positions, emissions = toa[rows], positions[rows], emissions[rows]
    fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, sound_speed, sigma_toa)
    settings = replace(tracker_settings(sound_speed, fe), sigma_toa=sigma_toa)
    schedule, _ = ping_schedule(toa, receivers, settings, "rbi", burst_interval)
    settings = replace(settings, interval=schedule.interval)
    settings, motion = motion_model(toa, receivers, settings, schedule, (fx, fe, fused), None)
    robust = tt.robust_track(toa, receivers, settings, (fx, fe, fused), None, schedule)
    error = robust.x[:, :2] - positions
    squared = np.sum(error**2, axis=1)
    nees = np.einsum("ki,kij,kj->k", error, np.linalg.inv(robust.P[:, :2, :2]), error)
    velocities = np.gradient(positions, emissions, axis=0)
    bound = tb.pcrb(positions, velocities, emissions, np.isfinite(toa), receivers, sound_speed, sigma_toa,
                    tb.MotionModel.of(settings), schedule).smoothed
    rms, limit = float(np.sqrt(np.mean(squared))), float(np.sqrt(np.mean(np.square(bound))))
    return {"tracked_pings": int(len(toa)), "tracked_rms_m": rms, "tracked_bound_m": limit,
            "tracked_ratio": rms / limit if limit > 0.0 else math.nan, "tracked_nees": float(np.mean(nees)),
            "tracked_p95_m": float(np.percentile(np.sqrt(squared), 95)),
            "acceleration_psd_m2_s3": float(motion["acceleration_psd_m2_s3"])}


__all__ = ["track_path"]
