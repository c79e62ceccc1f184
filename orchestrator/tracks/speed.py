"""The sound speed the replay takes: given (and checked against the pings' own calibration), a measured series
(each ping's arrivals rescaled to its median) or a temperature series made one by TEOS-10, or calibrated from the
pings (with a fallback's prior where the array determines it weakly, the fallback alone where the pings cannot be
fitted or where the calibration lies outside the speeds the stated water can have); and what was done, for
``summary.json``'s ``sound_speed``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking import sound_speed as ss
from sblsim.models.tracking.timing import SIGMA_TOA
from sblsim.orchestrator.tracks.tracker import DEPTH_SIGMA

#: A given sound speed is said to disagree with the pings where their own calibration, determined to
#: :data:`~sblsim.models.tracking.calibration.MAX_SIGMA` or better, lies more than this many of its standard errors
#: from it (the speed is still the one given: a user may know the water better than a thin array does).
SPEED_CHECK_SIGMAS = 3.0
#: ``summary.json``'s ``sound_speed`` ``source`` where a temperature series gives the speed, and where the stated
#: water's speed replaces a calibration it cannot have.
TEMPERATURE_SOURCE = "temperature series (TEOS-10)"
REPLACED_SOURCE = "fallback (the calibration is outside the stated water's speeds)"


@dataclass(frozen=True)
class Water:
    """Where the water's TEOS-10 speed is taken: the ``depth`` of the pings' paths [m, positive down] (the receivers'
    mean depth; 0 in 2-D), the shallowest and deepest depths they cross (``depths`` [m]: the surface to the bottom
    where the water's depth is given, else the shallowest receiver's to the deepest's), and the array's ``latitude``
    and ``longitude`` [°, WGS 84] where the receivers have a CRS
    (:func:`~sblsim.models.tracking.sound_speed.water_speed`)."""

    depth: float = 0.0
    depths: tuple[float, float] = (0.0, 0.0)
    latitude: float | None = None
    longitude: float | None = None

    @classmethod
    def of_array(cls, positions: np.ndarray, frame: Any = None, water_depth: float | None = None) -> Water:
        """The water of an array: its receivers' positions (n, dim) [m] (z up where dim is 3), its metric ``frame``
        (:class:`~sblsim.orchestrator.io.frames.Frame` or None) and the ``water_depth`` [m] where given."""
        depths = -positions[:, 2] if positions.shape[1] == 3 else np.zeros(1)
        low = 0.0 if water_depth is not None else float(depths.min())
        high = float(water_depth) if water_depth is not None else float(depths.max())
        latitude = longitude = None
        if frame is not None:
            lat, lon = frame.to_latlon(np.array([positions[:, 0].mean()]), np.array([positions[:, 1].mean()]))
            latitude, longitude = float(np.asarray(lat)[0]), float(np.asarray(lon)[0])
        return cls(float(depths.mean()), (low, high), latitude, longitude)

    def info(self) -> dict[str, Any]:
        """``summary.json``'s words on where the water's speed was taken."""
        return {"pressure_depth_m": self.depth, "depths_m": list(self.depths), "latitude": self.latitude,
                "longitude": self.longitude,
                "absolute_salinity": "gsw.SA_from_SP at the array's position" if self.latitude is not None else
                "gsw.SR_from_SP (the Reference Salinity: the array's position is not known)"}


def _plausible(speed: dict[str, Any], temperature: float | None, salinity: float | None,
               water: Water) -> dict[str, Any]:
    """A speed calibrated from the pings (``speed``: ``summary.json``'s ``sound_speed``) against the speeds the stated
    water can have (:func:`~sblsim.models.tracking.sound_speed.plausible_speeds`): outside them, replaced by the
    water's own TEOS-10 speed and its spread (:func:`~sblsim.models.tracking.sound_speed.fallback_prior`), the
    calibration kept beside (``source`` :data:`REPLACED_SOURCE`); inside, ``plausible_m_s`` added."""
    if temperature is None:
        return speed
    low, high, _ = ss.plausible_speeds(temperature, salinity, water.depths, water.latitude, water.longitude)
    c = speed["sound_speed_m_s"]
    out = speed | {"plausible_m_s": [low, high]}
    if low <= c <= high:
        return out
    prior, sigma, words = ss.fallback_prior(temperature, salinity, water.depth, water.latitude, water.longitude)
    return out | {"sound_speed_m_s": prior, "source": REPLACED_SOURCE, "method": words, "sigma_m_s": sigma,
                  "calibrated_m_s": c, "calibrated_sigma_m_s": speed.get("sigma_m_s"),
                  "calibrated_source": speed["source"], "water": water.info()}


def replaced_line(speed: dict[str, Any]) -> str | None:
    """The console's warning on a calibration the stated water cannot have (``summary.json``'s ``sound_speed``),
    after ``sblsim: warning:``; None where the calibration was kept."""
    if speed.get("source") != REPLACED_SOURCE:
        return None
    low, high = speed["plausible_m_s"]
    return (f"the pings' calibration, {speed['calibrated_m_s']:.1f} m/s, is outside the speeds the stated water can "
            f"have ({low:.1f} to {high:.1f} m/s: 3 σ of 1 °C and 1 in salinity); taken instead: {speed['method']}, "
            f"{speed['sound_speed_m_s']:.1f} m/s (every range scales with it)")


def speed_check(toa: np.ndarray, positions: np.ndarray, given: float, depth: np.ndarray | None,
                depth_sigma: float, sigma_toa: float | np.ndarray = SIGMA_TOA) -> dict[str, Any]:
    """A given sound speed [m/s] against the pings' own calibration
    (:func:`~sblsim.models.tracking.calibration.calibrate_sound_speed`): ``calibrated_m_s``, its
    ``calibrated_sigma_m_s`` and the two's ``disagreement_sigmas`` where the pings determine the speed (to
    :data:`~sblsim.models.tracking.calibration.MAX_SIGMA`), ``disagrees`` where that is above
    :data:`SPEED_CHECK_SIGMAS`; nothing where they do not. ``sigma_toa`` [s]: the timing noise (one, or each
    receiver's)."""
    from sblsim.models.tracking.calibration import MAX_SIGMA, calibrate_sound_speed

    try:
        calibration = calibrate_sound_speed(toa, positions, sigma_toa, strict=False, depth=depth,
                                            depth_sigma=depth_sigma)
    except ModelError:
        return {}
    if not calibration.sigma <= MAX_SIGMA:
        return {}
    sigmas = abs(given - calibration.c) / calibration.sigma if calibration.sigma > 0 else float("inf")
    return {"calibrated_m_s": calibration.c, "calibrated_sigma_m_s": calibration.sigma,
            "disagreement_sigmas": sigmas, "disagrees": bool(sigmas > SPEED_CHECK_SIGMAS)}


#: The fallback's words where it is the study's own speed (``study_speed``).
STUDY_SPEED = ("the study's speed, fitted with its clocks (from its sync tags, or from its moving tags' pings where "
               "none is heard)")


def sound_speed_stage(toa: np.ndarray, positions: np.ndarray, sound_speed: float | None = None,
                      series_path: Path | None = None, temperature: float | None = None,
                      salinity: float | None = None, depth: np.ndarray | None = None,
                      depth_sigma: float = DEPTH_SIGMA, time_origin: float | None = None,
                      sigma_toa: float | np.ndarray = SIGMA_TOA, temperature_path: Path | None = None,
                      water: Water | None = None, still: bool = False,
                      study_speed: tuple[float, float] | None = None) -> tuple[np.ndarray, float, dict[str, Any]]:
    """The sound speed the estimators take, and the times of arrival they take at it: ``sound_speed`` [m/s] where
    given; else a measured series (``series_path``,
    :func:`~sblsim.orchestrator.readers.time_series.read_sound_speed_series`) whose median is the reference speed and
    to which each ping's arrivals are rescaled (:func:`~sblsim.models.tracking.sound_speed.rescale_to_reference`);
    else calibrated from the pings (:func:`~sblsim.models.tracking.calibration.calibrate_sound_speed`); where its
    standard error is above
    :data:`~sblsim.models.tracking.calibration.MAX_SIGMA` (the array determines it only weakly), combined by inverse
    variance with the fallback and its spread (:func:`~sblsim.models.tracking.sound_speed.fallback_prior`:
    ``temperature`` [°C] and ``salinity`` (practical), else the stated default; a calibration 5.6 m/s uncertain is far
    better than a default 51 m/s uncertain), and where the pings cannot be fitted at all, the fallback alone. The
    calibration takes the tag's depth per ping (``depth`` [m], NaN where none) with ``depth_sigma`` [m] where known.
    A given speed is checked against the pings' own calibration (:func:`speed_check`: said, not replaced). A series
    in absolute times is taken to the times of arrival's base by ``time_origin`` [s since 1970 UTC]. ``sigma_toa``
    [s]: the arrivals' timing noise in the fits (one, or each receiver's (n,)). A temperature series
    (``temperature_path``, :func:`~sblsim.orchestrator.readers.water.read_temperature_series`) is made a measured
    series by TEOS-10 at ``salinity`` (practical) in the ``water`` (:class:`Water`: the depth and position of the
    pressure and the absolute salinity), which also places the fallback and the speeds the stated water can have: a
    calibration outside them is replaced by the water's own speed (:data:`REPLACED_SOURCE`). A ``still`` tag's pings
    that cannot be fitted one by one (an array of four) are calibrated as one place
    (:func:`~sblsim.models.tracking.still_speed.calibrate_still_sound_speed`) before the fallback is taken; where that
    fails too, the fallback says why (``still_calibration``). ``study_speed`` (the speed [m/s] and its σ [m/s]: a
    study's own, fitted with its clocks from its sync tags or its moving tags' pings) is the fallback where no
    ``temperature`` is given, in place of the default's 51 m/s.
    Returns ``toa`` (m, n) [s], the speed [m/s] and what was done (``summary.json``'s ``sound_speed``)."""
    from sblsim.models.tracking.calibration import calibrate_sound_speed

    water = Water() if water is None else water
    if temperature_path is not None:
        from sblsim.orchestrator.readers.water import read_temperature_series

        if salinity is None:
            raise ModelError("temperature file: needs the water's salinity (practical: 0 for fresh water, about 35 "
                             "for the open sea)")
        ss.check_water(0.0, salinity)
        temperatures = read_temperature_series(temperature_path, time_origin)
        series = np.column_stack([temperatures[:, 0], ss.water_speed(temperatures[:, 1], salinity, water.depth,
                                                                     water.latitude, water.longitude)])
        scaled, c, speed = _series_speed(toa, positions, series, temperature_path, "temperature file", sigma_toa)
        return scaled, c, speed | {"source": TEMPERATURE_SOURCE, "salinity": salinity,
                                   "temperature_range_c": [float(temperatures[:, 1].min()),
                                                           float(temperatures[:, 1].max())], "water": water.info()}
    prior, prior_sigma, words = ss.fallback_prior(temperature, salinity, water.depth, water.latitude,
                                                  water.longitude)  # refuses a bad temperature or salinity
    if study_speed is not None and temperature is None:  # the study's own speed, not a default's
        prior, prior_sigma, words = float(study_speed[0]), float(study_speed[1]), STUDY_SPEED
    if sound_speed is not None:
        return toa, sound_speed, {"sound_speed_m_s": sound_speed, "source": "given"} | speed_check(
            toa, positions, sound_speed, depth, depth_sigma, sigma_toa)
    if series_path is not None:
        from sblsim.orchestrator.readers.time_series import read_sound_speed_series

        return _series_speed(toa, positions, read_sound_speed_series(series_path, time_origin), series_path,
                             "sound speed file", sigma_toa)
    try:
        calibration = calibrate_sound_speed(toa, positions, sigma_toa, strict=False, depth=depth,
                                            depth_sigma=depth_sigma)
    except ModelError as exc:
        fallback = {"sound_speed_m_s": prior, "source": "fallback", "method": words, "sigma_m_s": prior_sigma,
                    "calibration": str(exc)}
        if not still:
            return toa, prior, fallback
        from sblsim.models.tracking.still_speed import calibrate_still_sound_speed

        try:
            calibration = calibrate_still_sound_speed(toa, positions, sigma_toa)
        except ModelError as why:
            return toa, prior, fallback | {"still_calibration": str(why)}
        method = (f"median of {len(calibration.batches)} stretches' joint soft-L1 fits of the tag as one place (its "
                  f"pings one by one could not: {exc})")
    else:
        method = f"median of {len(calibration.batches)} stretches' joint soft-L1 fits" if calibration.batches else \
            "one joint soft-L1 fit (a record too short for stretches)"
    speed = _calibrated(calibration, method, (prior, prior_sigma, words), temperature, salinity, water)
    return toa, speed["sound_speed_m_s"], speed


def _calibrated(calibration, method: str, fallback: tuple[float, float, str], temperature: float | None,
                salinity: float | None, water: Water) -> dict[str, Any]:
    """What a calibration (:class:`~sblsim.models.tracking.calibration.Calibration`, made by ``method``) gives:
    combined with the ``fallback``'s prior (its speed [m/s], σ [m/s] and words) where weakly determined, replaced
    where the stated water cannot have it."""
    from sblsim.models.tracking.calibration import MAX_SIGMA

    prior, prior_sigma, words = fallback
    speed = {"sound_speed_m_s": calibration.c, "source": "calibrated", "method": method,
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
    return _plausible(speed, temperature, salinity, water)


def _series_speed(toa: np.ndarray, positions: np.ndarray, series: np.ndarray, path: Path, what: str,
                  sigma_toa: float | np.ndarray) -> tuple[np.ndarray, float, dict[str, Any]]:
    """A measured series ``series`` (k, 2) [s, m/s] (read from ``path``, named ``what`` in a refusal) taken: each
    ping's arrivals rescaled to the series' median over the pings (:func:`sound_speed_stage`).

    Raises
    ------
    ModelError
        The series' times do not overlap the pings' first arrivals (one line).
    """
    first = ps.first_arrivals(toa)
    span = (np.nanmin(first), np.nanmax(first)) if np.isfinite(first).any() else (np.nan, np.nan)
    inside = (series[:, 0] >= span[0]) & (series[:, 0] <= span[1])
    if np.isfinite(span[0]) and (series[-1, 0] < span[0] or series[0, 0] > span[1]):
        raise ModelError(f"{what}: {str(path)!r}: its times [{series[0, 0]:.10g}, "
                         f"{series[-1, 0]:.10g}] s do not overlap the pings' first arrivals [{span[0]:.10g}, "
                         f"{span[1]:.10g}] s; allowed: a series on the times of arrival's time base (toa.txt "
                         "from sblsim toa: seconds since its origin_epoch_s)")
    c = float(np.median(series[inside, 1] if inside.any() else series[:, 1]))
    scaled, speeds, outside = _rescaled(toa, positions, series, c, sigma_toa)
    return scaled, c, {"sound_speed_m_s": c, "source": "measured series", "file": str(path),
                       "method": "each ping's arrivals rescaled from the series' speed at its emission to the "
                                 "series' median over the record",
                       "range_m_s": [float(np.nanmin(speeds)), float(np.nanmax(speeds))]
                       if np.isfinite(speeds).any() else None,
                       "pings_outside_series": int(outside.sum()),
                       "series_time_s": [float(series[0, 0]), float(series[-1, 0])]}


def _rescaled(toa: np.ndarray, positions: np.ndarray, series: np.ndarray, c: float, sigma_toa: float | np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each ping's arrivals rescaled from ``series``' speed (k, 2) [s, m/s] at its emission (its single-ping fix's
    at ``c``, :func:`~sblsim.models.tracking.sound_speed.emission_estimates`) to ``c`` [m/s]
    (:func:`~sblsim.models.tracking.sound_speed.rescale_to_reference`): the times, each ping's speed and whether it
    lies outside the series."""
    from sblsim.models.receiver import toa_tracking as tt

    emissions = ss.emission_estimates(toa, tt.fix_pings(toa, positions, c, sigma_toa)[1])
    return ss.rescale_to_reference(toa, emissions, series, c)


def season_rescaled(toa: np.ndarray, positions: np.ndarray, windows: Sequence[Sequence[float]], time_origin: float,
                    c: float, sigma_toa: float | np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """A tag's arrivals rescaled from the water's speed at each ping, as a season's synchronisation found it window by
    window (``windows``: each window's middle [s since 1970 UTC] and speed [m/s], in time order:
    :func:`~sblsim.orchestrator.sync.estimated_speed.estimated_speed`; linear between the middles, held beyond), to
    the season's ``c`` [m/s], which the tag's calibration or fallback then takes: one speed for a season whose water
    changed by more than its windows' σ would scale every range by the change. ``time_origin`` [s since 1970 UTC] the
    times of arrival's zero; ``sigma_toa`` [s] their timing noise in the pings' fixes. Returns the times (m, n) [s]
    and what was done (``summary.json``'s ``sound_speed.season_windows``)."""
    series = np.asarray(windows, float) - np.array([time_origin, 0.0])
    scaled, speeds, _ = _rescaled(toa, positions, series, c, sigma_toa)
    heard = np.isfinite(speeds)
    return scaled, {"windows": len(series), "season_m_s": c,
                    "range_m_s": [float(speeds[heard].min()), float(speeds[heard].max())] if heard.any() else None,
                    "method": "each ping's arrivals rescaled from the synchronisation's windows' speed at its "
                              "emission (linear between the windows' middles) to the season's"}


__all__ = ["REPLACED_SOURCE", "SPEED_CHECK_SIGMAS", "TEMPERATURE_SOURCE", "Water", "replaced_line",
           "season_rescaled", "sound_speed_stage", "speed_check"]
