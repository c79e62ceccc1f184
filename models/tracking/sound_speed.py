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
  UNESCO 2010; via ``gsw``) of a given temperature and salinity at the surface, else :data:`DEFAULT_SOUND_SPEED`;
  with its standard deviation (:func:`fallback_prior`), so that a calibration the array determines only weakly is
  combined with it rather than thrown away (:func:`combine_speeds`).

Units: seconds [s], metres per second [m/s], degrees Celsius [°C], grams per kilogram [g/kg].
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
#: The water temperatures [°C] and salinities [g/kg] the fallback takes.
TEMPERATURE_RANGE = (-2.0, 40.0)
SALINITY_RANGE = (0.0, 42.0)
#: The standard deviations [°C], [g/kg] taken for a given temperature and salinity in the fallback's spread
#: (:func:`fallback_prior`): a surface reading or a season's mean stands for the water the pings crossed to about
#: this (a stated assumption).
FALLBACK_TEMPERATURE_SIGMA = 1.0
FALLBACK_SALINITY_SIGMA = 1.0


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


def fallback_sound_speed(temperature: float | None = None, salinity: float | None = None) -> tuple[float, str]:
    """The speed taken where the array cannot determine it: TEOS-10's at ``temperature`` [°C] and ``salinity``
    [g/kg] (absolute salinity) at the surface (0 dbar) where both are given, else :data:`DEFAULT_SOUND_SPEED`;
    and its source in words.

    Raises
    ------
    ModelError
        Only one of the two given, or one outside :data:`TEMPERATURE_RANGE` / :data:`SALINITY_RANGE`.
    """
    if temperature is None and salinity is None:
        return DEFAULT_SOUND_SPEED, f"the default {DEFAULT_SOUND_SPEED:g} m/s"
    if temperature is None or salinity is None:
        raise ModelError(f"{'temperature' if temperature is None else 'salinity'}: needed with the "
                         f"{'salinity' if temperature is None else 'temperature'} (0 g/kg for fresh water, about 35 "
                         "for the open sea)")
    for name, value, (low, high), unit in (("temperature", temperature, TEMPERATURE_RANGE, "°C"),
                                           ("salinity", salinity, SALINITY_RANGE, "g/kg")):
        if not (np.isfinite(value) and low <= value <= high):
            raise ModelError(f"{name}: {value!r} {unit} is not allowed; allowed: [{low:g}, {high:g}] {unit}")
    return float(_teos10(temperature, salinity)), f"TEOS-10 at {temperature:g} °C and {salinity:g} g/kg"


def _teos10(temperature: np.ndarray, salinity: np.ndarray) -> np.ndarray:
    """TEOS-10's speed of sound [m/s] at the surface (0 dbar) at in-situ ``temperature`` [°C] and absolute
    ``salinity`` [g/kg]."""
    return np.asarray(gsw.sound_speed(salinity, gsw.CT_from_t(salinity, temperature, 0.0), 0.0), float)


@cache
def _natural_spread() -> float:
    """The spread of TEOS-10's surface speeds over :data:`TEMPERATURE_RANGE` × :data:`SALINITY_RANGE` as a
    uniform's, (max − min) / √12 [m/s] (:func:`fallback_prior`; computed once)."""
    t = np.linspace(*TEMPERATURE_RANGE, 43)
    speeds = _teos10(*np.meshgrid(t, np.linspace(*SALINITY_RANGE, 43)))
    return float((speeds.max() - speeds.min()) / np.sqrt(12.0))


def fallback_prior(temperature: float | None = None, salinity: float | None = None) -> tuple[float, float, str]:
    """The fallback speed (:func:`fallback_sound_speed`) with its standard deviation: where a temperature and a
    salinity are given, TEOS-10's change over ±:data:`FALLBACK_TEMPERATURE_SIGMA` and
    ±:data:`FALLBACK_SALINITY_SIGMA` (central differences, in quadrature); else the spread of the speeds TEOS-10
    gives at the surface over :data:`TEMPERATURE_RANGE` × :data:`SALINITY_RANGE` taken as a uniform's,
    (max − min) / √12 (51 m/s: nothing is known of the water but that it is water).

    Returns
    -------
    tuple
        The speed [m/s], its standard deviation [m/s] and its source in words.

    Raises
    ------
    ModelError
        As :func:`fallback_sound_speed`.
    """
    c, words = fallback_sound_speed(temperature, salinity)
    if temperature is None:
        return c, _natural_spread(), words
    dt, ds = FALLBACK_TEMPERATURE_SIGMA, FALLBACK_SALINITY_SIGMA
    t, s = np.array([temperature + dt, temperature - dt]), np.array([salinity + ds, max(salinity - ds, 0.0)])
    along_t = np.diff(_teos10(t, np.full(2, salinity)))[0] / (t[1] - t[0]) * dt
    along_s = np.diff(_teos10(np.full(2, temperature), s))[0] / (s[1] - s[0]) * ds
    return c, float(np.hypot(along_t, along_s)), words


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


__all__ = ["DEFAULT_SOUND_SPEED", "FALLBACK_SALINITY_SIGMA", "FALLBACK_TEMPERATURE_SIGMA", "SALINITY_RANGE",
           "TEMPERATURE_RANGE", "combine_speeds", "emission_estimates", "fallback_prior", "fallback_sound_speed",
           "rescale_to_reference"]
