"""Ambient noise: the Wenz (1962) curves in the parametric form of Coates (1990) given by Stojanovic (2007).

:func:`noise_components` gives the four sources' spectrum levels (turbulence, shipping, wind, thermal),
:func:`noise_spectrum_level` their sum as powers and :func:`noise_level` the level over the receiver's band;
:func:`wind_speed` is the wind of a Beaufort level, which drives the wind (surface-wave) term. Each takes floats
(and returns a float) or casadi symbols (and returns an expression).

References
----------
Wenz, "Acoustic ambient noise in the ocean: spectra and sources", J. Acoust.
Soc. Am. 34(12):1936-1956, 1962. Coates, Underwater Acoustic Systems, Wiley
1990. Stojanovic, "On the relationship between capacity and distance in an
underwater acoustic communication channel", ACM SIGMOBILE Mob. Comput. Commun.
Rev. 11(4):34-43, 2007.
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.expressions import _value, lookup
from sblsim.models.platform.waves import WIND_SPEED


def wind_speed(beaufort):
    """The mid-range 10 m wind speed of a Beaufort level [m/s] (WMO; :data:`~sblsim.models.platform.waves.WIND_SPEED`).

    Parameters
    ----------
    beaufort : int or casadi.SX
        Beaufort level 0..8 (0 outside).

    Returns
    -------
    float or casadi.SX
        Wind speed w [m/s].
    """
    return _value(lookup(beaufort, WIND_SPEED))


def noise_components(frequency, wind_speed, shipping):
    """The four Wenz noise sources' spectrum levels, Coates' parametric form (Stojanovic 2007, eqs. 6-7).

    With f in kHz, w the wind speed [m/s] and s the shipping activity (0 to 1):

    * turbulence ``17 − 30 log f``;
    * shipping ``40 + 20 (s − 0.5) + 26 log f − 60 log (f + 0.03)``;
    * wind (surface waves) ``50 + 7.5 √w + 20 log f − 40 log (f + 0.4)``;
    * thermal ``−15 + 20 log f``.

    Parameters
    ----------
    frequency : float or casadi.SX
        Frequency f [Hz], > 0.
    wind_speed : float or casadi.SX
        Wind speed w [m/s], ≥ 0.
    shipping : float or casadi.SX
        Shipping activity s, 0 (none) to 1 (heavy).

    Returns
    -------
    turbulence, shipping, wind, thermal : float or casadi.SX
        Spectrum levels [dB re 1 µPa²/Hz].

    References
    ----------
    Wenz, J. Acoust. Soc. Am. 34(12):1936-1956, 1962; Coates, Underwater
    Acoustic Systems, Wiley 1990; Stojanovic, ACM SIGMOBILE MC2R 11(4):34-43,
    2007, eqs. (6)-(7).
    """
    f = frequency / 1000.0
    log_f = ca.log10(f)
    turbulence = 17.0 - 30.0 * log_f
    ships = 40.0 + 20.0 * (shipping - 0.5) + 26.0 * log_f - 60.0 * ca.log10(f + 0.03)
    wind = 50.0 + 7.5 * ca.sqrt(wind_speed) + 20.0 * log_f - 40.0 * ca.log10(f + 0.4)
    thermal = -15.0 + 20.0 * log_f
    return _value(turbulence), _value(ships), _value(wind), _value(thermal)


def noise_spectrum_level(frequency, wind_speed, shipping):
    """Ambient-noise spectrum level NL_f: the four Wenz sources summed as powers.

    ``NL_f = 10 log10 Σ 10^(N_i/10)`` over the terms of
    :func:`noise_components` (turbulence, shipping, wind, thermal).

    Parameters
    ----------
    frequency : float or casadi.SX
        Frequency f [Hz], > 0.
    wind_speed : float or casadi.SX
        Wind speed w [m/s], ≥ 0 (:func:`wind_speed` of a Beaufort level).
    shipping : float or casadi.SX
        Shipping activity s, 0 (none) to 1 (heavy).

    Returns
    -------
    float or casadi.SX
        NL_f [dB re 1 µPa²/Hz].

    References
    ----------
    Stojanovic, ACM SIGMOBILE MC2R 11(4):34-43, 2007, eqs. (6)-(7), after
    Coates (1990) and Wenz (1962).
    """
    levels = noise_components(frequency, wind_speed, shipping)
    top = ca.fmax(ca.fmax(levels[0], levels[1]), ca.fmax(levels[2], levels[3]))
    power = sum(10.0 ** ((level - top) / 10.0) for level in levels)  # relative to the largest: no overflow
    return _value(top + 10.0 * ca.log10(power))


def noise_level(frequency, bandwidth, wind_speed, shipping):
    """Ambient-noise level over the receiver's band: ``NL = NL_f(f_c) + 10 log10 B``.

    The spectrum level at the centre frequency stands for the whole band (a
    flat spectrum across it). The spectrum falls by about 17 dB per decade at
    the frequencies of positioning systems (10-50 kHz), so for a band of
    B/f_c = 0.2 the band's true power differs from this by less than 0.05 dB.

    Parameters
    ----------
    frequency : float or casadi.SX
        Centre frequency f_c [Hz], > 0.
    bandwidth : float or casadi.SX
        Bandwidth B [Hz], > 0.
    wind_speed : float or casadi.SX
        Wind speed w [m/s], ≥ 0.
    shipping : float or casadi.SX
        Shipping activity s, 0 to 1.

    Returns
    -------
    float or casadi.SX
        NL [dB re 1 µPa].
    """
    return _value(noise_spectrum_level(frequency, wind_speed, shipping) + 10.0 * ca.log10(bandwidth))


__all__ = ["noise_components", "noise_level", "noise_spectrum_level", "wind_speed"]
