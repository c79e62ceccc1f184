"""The sound speed the replay takes: given (and checked against the pings' own calibration), a measured series
(each ping's arrivals rescaled to its median), or calibrated from the pings (with a fallback's prior where the array
determines it weakly, the fallback alone where the pings cannot be fitted); and what was done, for
``summary.json``'s ``sound_speed``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking import sound_speed as ss
from sblsim.orchestrator.tracks.tracker import DEPTH_SIGMA, SIGMA_TOA

#: A given sound speed is said to disagree with the pings where their own calibration, determined to
#: :data:`~sblsim.models.tracking.calibration.MAX_SIGMA` or better, lies more than this many of its standard errors
#: from it (the speed is still the one given: a user may know the water better than a thin array does).
SPEED_CHECK_SIGMAS = 3.0


def speed_check(toa: np.ndarray, positions: np.ndarray, given: float, depth: np.ndarray | None,
                depth_sigma: float) -> dict[str, Any]:
    """A given sound speed [m/s] against the pings' own calibration
    (:func:`~sblsim.models.tracking.calibration.calibrate_sound_speed`): ``calibrated_m_s``, its
    ``calibrated_sigma_m_s`` and the two's ``disagreement_sigmas`` where the pings determine the speed (to
    :data:`~sblsim.models.tracking.calibration.MAX_SIGMA`), ``disagrees`` where that is above
    :data:`SPEED_CHECK_SIGMAS`; nothing where they do not."""
    from sblsim.models.tracking.calibration import MAX_SIGMA, calibrate_sound_speed

    try:
        calibration = calibrate_sound_speed(toa, positions, SIGMA_TOA, strict=False, depth=depth,
                                            depth_sigma=depth_sigma)
    except ModelError:
        return {}
    if not calibration.sigma <= MAX_SIGMA:
        return {}
    sigmas = abs(given - calibration.c) / calibration.sigma if calibration.sigma > 0 else float("inf")
    return {"calibrated_m_s": calibration.c, "calibrated_sigma_m_s": calibration.sigma,
            "disagreement_sigmas": sigmas, "disagrees": bool(sigmas > SPEED_CHECK_SIGMAS)}


def sound_speed_stage(toa: np.ndarray, positions: np.ndarray, sound_speed: float | None = None,
                      series_path: Path | None = None, temperature: float | None = None,
                      salinity: float | None = None, depth: np.ndarray | None = None,
                      depth_sigma: float = DEPTH_SIGMA, time_origin: float | None = None
                      ) -> tuple[np.ndarray, float, dict[str, Any]]:
    """The sound speed the estimators take, and the times of arrival they take at it: ``sound_speed`` [m/s] where
    given; else a measured series (``series_path``, :func:`~sblsim.orchestrator.tracks.toa.read_sound_speed_series`)
    whose median is the reference speed and to which each ping's arrivals are rescaled
    (:func:`~sblsim.models.tracking.sound_speed.rescale_to_reference`); else calibrated from the pings
    (:func:`~sblsim.models.tracking.calibration.calibrate_sound_speed`); where its standard error is above
    :data:`~sblsim.models.tracking.calibration.MAX_SIGMA` (the array determines it only weakly), combined by inverse
    variance with the fallback and its spread (:func:`~sblsim.models.tracking.sound_speed.fallback_prior`:
    ``temperature`` [°C] and ``salinity`` [g/kg], else the stated default; a calibration 5.6 m/s uncertain is far
    better than a default 51 m/s uncertain), and where the pings cannot be fitted at all, the fallback alone. The
    calibration takes the tag's depth per ping (``depth`` [m], NaN where none) with ``depth_sigma`` [m] where known.
    A given speed is checked against the pings' own calibration (:func:`speed_check`: said, not replaced). A series
    in absolute times is taken to the times of arrival's base by ``time_origin`` [s since 1970 UTC].
    Returns ``toa`` (m, n) [s], the speed [m/s] and what was done (``summary.json``'s ``sound_speed``)."""
    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.models.tracking.calibration import MAX_SIGMA, calibrate_sound_speed

    prior, prior_sigma, words = ss.fallback_prior(temperature, salinity)  # refuses a bad temperature or salinity
    if sound_speed is not None:
        return toa, sound_speed, {"sound_speed_m_s": sound_speed, "source": "given"} | speed_check(
            toa, positions, sound_speed, depth, depth_sigma)
    if series_path is not None:
        from sblsim.orchestrator.tracks.toa import read_sound_speed_series

        series = read_sound_speed_series(series_path, time_origin)
        first = ps.first_arrivals(toa)
        span = (np.nanmin(first), np.nanmax(first)) if np.isfinite(first).any() else (np.nan, np.nan)
        inside = (series[:, 0] >= span[0]) & (series[:, 0] <= span[1])
        if np.isfinite(span[0]) and (series[-1, 0] < span[0] or series[0, 0] > span[1]):
            raise ModelError(f"sound speed file: {str(series_path)!r}: its times [{series[0, 0]:.10g}, "
                             f"{series[-1, 0]:.10g}] s do not overlap the pings' first arrivals [{span[0]:.10g}, "
                             f"{span[1]:.10g}] s; allowed: a series on the times of arrival's time base (toa.txt "
                             "from sblsim toa: seconds since its origin_epoch_s)")
        c = float(np.median(series[inside, 1] if inside.any() else series[:, 1]))
        emissions = ss.emission_estimates(toa, tt.fix_pings(toa, positions, c, SIGMA_TOA)[1])
        scaled, speeds, outside = ss.rescale_to_reference(toa, emissions, series, c)
        return scaled, c, {"sound_speed_m_s": c, "source": "measured series", "file": str(series_path),
                           "method": "each ping's arrivals rescaled from the series' speed at its emission to the "
                                     "series' median over the record",
                           "range_m_s": [float(np.nanmin(speeds)), float(np.nanmax(speeds))]
                           if np.isfinite(speeds).any() else None,
                           "pings_outside_series": int(outside.sum()),
                           "series_time_s": [float(series[0, 0]), float(series[-1, 0])]}
    try:
        calibration = calibrate_sound_speed(toa, positions, SIGMA_TOA, strict=False, depth=depth,
                                            depth_sigma=depth_sigma)
    except ModelError as exc:
        return toa, prior, {"sound_speed_m_s": prior, "source": "fallback", "method": words,
                            "sigma_m_s": prior_sigma, "calibration": str(exc)}
    speed = {"sound_speed_m_s": calibration.c, "source": "calibrated",
             "method": f"median of {len(calibration.batches)} stretches' joint soft-L1 fits"
             if calibration.batches else "one joint soft-L1 fit (a record too short for stretches)",
             "sigma_m_s": calibration.sigma, "pings": calibration.pings,
             "stretches_m_s": [None if not np.isfinite(v) else v for v in calibration.batches]}
    if temperature is not None:  # both given (fallback_prior refuses one alone)
        speed["fallback_m_s"], speed["fallback"] = prior, words
    if calibration.sigma > MAX_SIGMA:  # weakly determined: the fallback's prior weighs in
        c, sigma = ss.combine_speeds(calibration.c, calibration.sigma, prior, prior_sigma)
        speed |= {"sound_speed_m_s": c, "source": "calibrated with the fallback's prior", "sigma_m_s": sigma,
                  "calibrated_m_s": calibration.c, "calibrated_sigma_m_s": calibration.sigma, "prior_m_s": prior,
                  "prior_sigma_m_s": prior_sigma, "prior": words,
                  "disagreement_sigmas": abs(calibration.c - prior) / float(np.hypot(calibration.sigma, prior_sigma))}
    return toa, speed["sound_speed_m_s"], speed


__all__ = ["SPEED_CHECK_SIGMAS", "sound_speed_stage", "speed_check"]
