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
  UNESCO 2010; via ``gsw``) of a given temperature and salinity at the surface, else :data:`DEFAULT_SOUND_SPEED`.

Units: seconds [s], metres per second [m/s], degrees Celsius [°C], grams per kilogram [g/kg].
"""

from __future__ import annotations

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
    conservative = gsw.CT_from_t(salinity, temperature, 0.0)
    c = float(gsw.sound_speed(salinity, conservative, 0.0))
    return c, f"TEOS-10 at {temperature:g} °C and {salinity:g} g/kg"


__all__ = ["DEFAULT_SOUND_SPEED", "SALINITY_RANGE", "TEMPERATURE_RANGE", "emission_estimates", "fallback_sound_speed",
           "rescale_to_reference"]
