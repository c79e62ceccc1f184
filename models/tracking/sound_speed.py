"""The tracker's sound speed where it is not calibrated from the pings: a measured series, and the fallback where the
array cannot determine it.

* A **measured series** ``c(t)`` (a temperature logger's record converted, a CTD's time series): the estimators take
  one sound speed, so each ping's travel times are rescaled to a reference speed ``c_ref``,
  ``toa'_ki = t_k + (toa_ki − t_k) c(t_k) / c_ref`` about the ping's emission time ``t_k``; then
  ``(toa'_ki − t_k) c_ref = (toa_ki − t_k) c(t_k)``, the range at the ping's own speed, exactly where ``t_k`` is
  exact. ``t_k`` is the single-ping fix's emission time where the ping has one, else the ping's first arrival less
  the median delay of first arrival after emission over the fixed pings (:func:`emission_estimates`): an error
  ``δ`` in ``t_k`` moves each arrival by ``δ (c(t_k) / c_ref − 1)``, 1.4 µs (2 mm) for ``δ`` = 1 ms and a speed 0.1 %
  from the reference.
* The **fallback** where the calibration finds the array cannot determine the speed: the TEOS-10 speed of sound
  (IOC, SCOR and IAPSO, *The international thermodynamic equation of seawater – 2010*, Manual and Guides 56,
  UNESCO 2010; via ``gsw``) of a given temperature and salinity (:func:`water_speed`), else
  :data:`DEFAULT_SOUND_SPEED`; with its standard deviation (:func:`fallback_prior`), so that a calibration the array
  determines only weakly is combined with it rather than thrown away (:func:`combine_speeds`), and one the stated
  water cannot have (outside :func:`plausible_speeds`) is replaced by it.
* A **temperature series** (a logger's record) is a measured series once each temperature is a speed
  (:func:`water_speed` at the stated salinity).

The water's speed (:func:`water_speed`): the practical salinity (PSS-78, what a CTD or a salinometer reports) made
absolute salinity by ``gsw.SA_from_SP`` where the array's latitude and longitude are known (the composition anomaly
of TEOS-10's atlas; in the Baltic's area its own formula, which puts 0.087 g/kg in water of practical salinity 0:
0.1 m/s), else by ``gsw.SR_from_SP`` (the Reference Salinity, standard sea water's composition); the pressure from
the depth by ``gsw.p_from_z``; the Conservative Temperature from the in-situ one by ``gsw.CT_from_t``; the speed by
``gsw.sound_speed``.

Units: seconds [s], metres per second [m/s], degrees Celsius [°C], practical salinity [1] (PSS-78), metres [m].
"""

from __future__ import annotations

from functools import cache

import gsw
import numpy as np

from sblsim.models.declarations import ModelError

#: The speed taken where the array cannot determine it and nothing else is given [m/s]: the conventional nominal
#: speed of sound in water of underwater acoustics (TEOS-10: sea water of 35 g/kg near 13 °C, fresh water near
#: 27 °C): a stated assumption, every range scaling with it.
DEFAULT_SOUND_SPEED = 1500.0
#: The water temperatures [°C] and practical salinities [1] (PSS-78) the fallback and a temperature series take.
TEMPERATURE_RANGE = (-2.0, 40.0)
SALINITY_RANGE = (0.0, 42.0)
#: The standard deviations [°C], [1] taken for a given temperature and salinity in the fallback's spread
#: (:func:`fallback_prior`): a surface reading or a season's mean stands for the water the pings crossed to about
#: this (a stated assumption).
FALLBACK_TEMPERATURE_SIGMA = 1.0
FALLBACK_SALINITY_SIGMA = 1.0
#: A speed calibrated from the pings is one the stated water can have where it lies within this many of the water's
#: standard deviations (:func:`plausible_speeds`) of the water's TEOS-10 speed: 3 σ of 1 °C and 1 in salinity (and
#: of the depths the pings cross) is 9.9 m/s in fresh water at 20 °C and 6.9 m/s in sea water of salinity 35 at 30 °C.
PLAUSIBLE_SIGMAS = 3.0
#: The latitude [°] of the depth-to-pressure conversion where the array's position is not known (the pressure at
#: 100 m differs by 0.5 dbar from the equator to a pole: 0.01 m/s).
DEFAULT_LATITUDE = 45.0


def emission_estimates(toa: np.ndarray, fix_emissions: np.ndarray) -> np.ndarray:
    """Each ping's emission time: its single-ping fix's where it has one, else its first arrival less the median
    delay of the first arrival after the emission over the fixed pings (0 where no ping has a fix).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    fix_emissions : ndarray, (m,)
        The single-ping fixes' emission times [s], NaN where none.

    Returns
    -------
    ndarray, (m,)
        [s], NaN for a ping nobody heard.
    """
    toa = np.asarray(toa, float)
    fixed = np.asarray(fix_emissions, float)
    heard = np.isfinite(toa).any(axis=1)
    first = np.full(len(toa), np.nan)
    first[heard] = np.nanmin(toa[heard], axis=1)
    both = np.isfinite(fixed) & heard
    delay = float(np.median(first[both] - fixed[both])) if both.any() else 0.0
    return np.where(np.isfinite(fixed), fixed, first - delay)


def rescale_to_reference(toa: np.ndarray, emissions: np.ndarray, series: np.ndarray,
                         c_ref: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times of arrival rescaled from a measured sound-speed series to one reference speed (module docstring).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    emissions : ndarray, (m,)
        Each ping's emission time [s] (:func:`emission_estimates`).
    series : ndarray, (k, 2)
        Time [s] (increasing) and sound speed [m/s]; linearly interpolated, held at its ends.
    c_ref : float
        The reference speed [m/s] the estimators then take.

    Returns
    -------
    toa : ndarray, (m, n)
        The rescaled times of arrival [s].
    speeds : ndarray, (m,)
        The series' speed at each ping's emission [m/s] (NaN for a ping nobody heard).
    outside : ndarray of bool, (m,)
        Pings emitted before the series' first time or after its last (the end value held).

    Raises
    ------
    ModelError
        ``c_ref`` not positive, or the series empty.
    """
    series = np.asarray(series, float)
    if not (np.isfinite(c_ref) and c_ref > 0) or series.ndim != 2 or len(series) == 0:
        raise ModelError("sound speed file: no series to rescale the times of arrival by; allowed: at least one row")
    t = np.asarray(emissions, float)
    speeds = np.interp(t, series[:, 0], series[:, 1])
    speeds[~np.isfinite(t)] = np.nan
    outside = np.isfinite(t) & ((t < series[0, 0]) | (t > series[-1, 0]))
    toa = np.asarray(toa, float)
    scaled = t[:, None] + (toa - t[:, None]) * (speeds / c_ref)[:, None]
    return np.where(np.isfinite(toa), scaled, np.nan), speeds, outside


def water_speed(temperature: np.ndarray | float, salinity: np.ndarray | float, depth: np.ndarray | float = 0.0,
                latitude: float | None = None, longitude: float | None = None) -> np.ndarray:
    """TEOS-10's speed of sound in water of in-situ ``temperature`` and practical ``salinity`` at ``depth`` (the
    module docstring).

    Parameters
    ----------
    temperature : array_like
        In-situ temperature [°C] (ITS-90).
    salinity : array_like
        Practical salinity [1] (PSS-78; 0 for fresh water, about 35 for the open sea).
    depth : array_like
        Depth [m], positive down (the pressure ``gsw.p_from_z(−depth, latitude)``).
    latitude, longitude : float, optional
        The water's position [°, WGS 84]: the absolute salinity from TEOS-10's atlas where both are given (else the
        Reference Salinity) and the pressure's gravity (else :data:`DEFAULT_LATITUDE`).

    Returns
    -------
    ndarray
        The speed of sound [m/s], broadcast over the three.
    """
    t, sp = np.asarray(temperature, float), np.asarray(salinity, float)
    lat = DEFAULT_LATITUDE if latitude is None else float(latitude)
    pressure = gsw.p_from_z(-np.asarray(depth, float), lat)
    absolute = gsw.SR_from_SP(sp)
    if latitude is not None and longitude is not None:
        atlas = np.asarray(gsw.SA_from_SP(sp, pressure, float(longitude), lat), float)
        absolute = np.where(np.isfinite(atlas), atlas, absolute)  # off the atlas: the Reference Salinity
    return np.asarray(gsw.sound_speed(absolute, gsw.CT_from_t(absolute, t, pressure), pressure), float)


def check_water(temperature: float | None, salinity: float | None) -> None:
    """A stated water: both or neither of ``temperature`` [°C] and ``salinity`` [1], each within its range.

    Raises
    ------
    ModelError
        Only one of the two given, or one outside :data:`TEMPERATURE_RANGE` / :data:`SALINITY_RANGE` (one line).
    """
    if temperature is None and salinity is None:
        return
    if temperature is None or salinity is None:
        raise ModelError(f"{'temperature' if temperature is None else 'salinity'}: needed with the "
                         f"{'salinity' if temperature is None else 'temperature'} (practical salinity: 0 for fresh "
                         "water, about 35 for the open sea)")
    for name, value, (low, high), unit in (("temperature", temperature, TEMPERATURE_RANGE, " °C"),
                                           ("salinity", salinity, SALINITY_RANGE, " (practical salinity)")):
        if not (np.isfinite(value) and low <= value <= high):
            raise ModelError(f"{name}: {value!r}{unit} is not allowed; allowed: [{low:g}, {high:g}]{unit}")


def fallback_sound_speed(temperature: float | None = None, salinity: float | None = None, depth: float = 0.0,
                         latitude: float | None = None, longitude: float | None = None) -> tuple[float, str]:
    """The speed taken where the array cannot determine it: TEOS-10's at ``temperature`` [°C] and practical
    ``salinity`` [1] at ``depth`` [m] (:func:`water_speed`, at ``latitude``, ``longitude`` [°] where known) where
    both are given, else :data:`DEFAULT_SOUND_SPEED`; and its source in words.

    Raises
    ------
    ModelError
        As :func:`check_water`.
    """
    check_water(temperature, salinity)
    if temperature is None:
        return DEFAULT_SOUND_SPEED, f"the default {DEFAULT_SOUND_SPEED:g} m/s"
    at = f" at {depth:.3g} m" if depth else ""
    return (float(water_speed(temperature, salinity, depth, latitude, longitude)),
            f"TEOS-10 at {temperature:g} °C and salinity {salinity:g}{at}")


def _teos10(temperature: np.ndarray, salinity: np.ndarray) -> np.ndarray:
    """TEOS-10's speed of sound [m/s] at the surface at in-situ ``temperature`` [°C] and practical ``salinity``
    (:func:`water_speed`)."""
    return water_speed(temperature, salinity)


@cache
def _natural_spread() -> float:
    """The spread of TEOS-10's surface speeds over :data:`TEMPERATURE_RANGE` × :data:`SALINITY_RANGE` as a
    uniform's, (max − min) / √12 [m/s] (:func:`fallback_prior`; computed once)."""
    t = np.linspace(*TEMPERATURE_RANGE, 43)
    speeds = _teos10(*np.meshgrid(t, np.linspace(*SALINITY_RANGE, 43)))
    return float((speeds.max() - speeds.min()) / np.sqrt(12.0))


def fallback_prior(temperature: float | None = None, salinity: float | None = None, depth: float = 0.0,
                   latitude: float | None = None, longitude: float | None = None) -> tuple[float, float, str]:
    """The fallback speed (:func:`fallback_sound_speed`) with its standard deviation: where a temperature and a
    salinity are given, TEOS-10's change over ±:data:`FALLBACK_TEMPERATURE_SIGMA` and
    ±:data:`FALLBACK_SALINITY_SIGMA` (central differences, in quadrature; at ``depth`` [m], ``latitude``,
    ``longitude`` [°] as :func:`water_speed`); else the spread of the speeds TEOS-10 gives at the surface over
    :data:`TEMPERATURE_RANGE` × :data:`SALINITY_RANGE` taken as a uniform's, (max − min) / √12 (51 m/s: nothing is
    known of the water but that it is water).

    Returns
    -------
    tuple
        The speed [m/s], its standard deviation [m/s] and its source in words.

    Raises
    ------
    ModelError
        As :func:`fallback_sound_speed`.
    """
    c, words = fallback_sound_speed(temperature, salinity, depth, latitude, longitude)
    if temperature is None:
        return c, _natural_spread(), words
    dt, ds = FALLBACK_TEMPERATURE_SIGMA, FALLBACK_SALINITY_SIGMA
    t, s = np.array([temperature + dt, temperature - dt]), np.array([salinity + ds, max(salinity - ds, 0.0)])
    along_t = np.diff(water_speed(t, salinity, depth, latitude, longitude))[0] / (t[1] - t[0]) * dt
    along_s = np.diff(water_speed(temperature, s, depth, latitude, longitude))[0] / (s[1] - s[0]) * ds
    return c, float(np.hypot(along_t, along_s)), words


def plausible_speeds(temperature: float, salinity: float, depths: tuple[float, float] = (0.0, 0.0),
                     latitude: float | None = None, longitude: float | None = None) -> tuple[float, float, float]:
    """The speeds the stated water can have: TEOS-10's at ``temperature`` [°C] and practical ``salinity`` [1] at the
    middle of ``depths`` (the shallowest and deepest the pings cross [m], positive down), ± :data:`PLAUSIBLE_SIGMAS`
    of its spread: the change over ±1 °C and ±1 in salinity (:func:`fallback_prior`: a surface reading or a season's
    mean stands for the water the pings crossed to about that) and half its change over ``depths``, in quadrature.

    Returns
    -------
    low, high, centre : float
        [m/s].

    Raises
    ------
    ModelError
        As :func:`check_water`, or without a temperature.
    """
    if temperature is None:
        raise ModelError("temperature: the speeds the water can have need its temperature and salinity")
    top, bottom = float(min(depths)), float(max(depths))
    centre, sigma, _ = fallback_prior(temperature, salinity, 0.5 * (top + bottom), latitude, longitude)
    ends = water_speed(temperature, salinity, np.array([top, bottom]), latitude, longitude)
    spread = float(np.hypot(sigma, 0.5 * abs(ends[1] - ends[0])))
    return centre - PLAUSIBLE_SIGMAS * spread, centre + PLAUSIBLE_SIGMAS * spread, centre


def combine_speeds(c: float, sigma: float, prior: float, prior_sigma: float) -> tuple[float, float]:
    """Two independent estimates of one sound speed, each with its standard deviation [m/s], combined by inverse
    variance: the posterior mean and standard deviation of a Gaussian prior (``prior``, ``prior_sigma``) updated by
    a Gaussian estimate (``c``, ``sigma``; Gelman et al., *Bayesian Data Analysis*, 3rd ed., CRC 2013, § 2.5).

    Returns
    -------
    tuple of float
        The speed [m/s] and its standard deviation [m/s].
    """
    w, w0 = 1.0 / sigma**2, 1.0 / prior_sigma**2
    return float((w * c + w0 * prior) / (w + w0)), float(1.0 / np.sqrt(w + w0))


__all__ = ["DEFAULT_LATITUDE", "DEFAULT_SOUND_SPEED", "FALLBACK_SALINITY_SIGMA", "FALLBACK_TEMPERATURE_SIGMA",
           "PLAUSIBLE_SIGMAS", "SALINITY_RANGE", "TEMPERATURE_RANGE", "check_water", "combine_speeds",
           "emission_estimates", "fallback_prior", "fallback_sound_speed", "plausible_speeds", "rescale_to_reference",
           "water_speed"]
