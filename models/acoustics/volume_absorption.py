"""Volume absorption of sound in sea water: Francois & Garrison (1982), at one depth and over the site's water column.

:func:`absorption` is the formula (a float for floats, a casadi expression for symbols, so that the channel model
writes it once and the FMUs generate it); :func:`water_column_absorption` its average over the site's water column,
each depth at the cast's own temperature (TEOS-10).

References
----------
Francois, Garrison, "Sound absorption based on ocean measurements. Part II:
Boric acid contribution and equation for total absorption", J. Acoust. Soc.
Am. 72(6):1879-1890, 1982. IOC, SCOR, IAPSO, The international thermodynamic
equation of seawater - 2010 (TEOS-10), 2010.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.sound_speed import temperature_from_speed
from sblsim.models.expressions import _value


def absorption(frequency, temperature, salinity, depth, ph=8.0):
    """Volume absorption of sound in sea water, Francois & Garrison (1982).

    ``α = A1 P1 f1 f²/(f1² + f²) + A2 P2 f2 f²/(f2² + f²) + A3 P3 f²`` [dB/km],
    f in kHz: boric acid (A1, P1 = 1, f1), magnesium sulphate (A2, P2, f2)
    and pure water (A3, P3), with ``c = 1412 + 3.21 T + 1.19 S + 0.0167 D``
    [m/s], ``θ = 273 + T`` [K]:

    * ``A1 = 8.86/c · 10^(0.78 pH − 5)`` [dB/(km kHz)],
      ``f1 = 2.8 √(S/35) · 10^(4 − 1245/θ)`` [kHz];
    * ``A2 = 21.44 S/c · (1 + 0.025 T)`` [dB/(km kHz)],
      ``P2 = 1 − 1.37e-4 D + 6.2e-9 D²``,
      ``f2 = 8.17 · 10^(8 − 1990/θ) / (1 + 0.0018 (S − 35))`` [kHz];
    * ``A3 = 4.937e-4 − 2.59e-5 T + 9.11e-7 T² − 1.50e-8 T³`` for T ≤ 20 °C,
      ``3.964e-4 − 1.146e-5 T + 1.45e-7 T² − 6.5e-10 T³`` above
      [dB/(km kHz²)], ``P3 = 1 − 3.83e-5 D + 4.9e-10 D²``.

    Francois & Garrison state it for −2 to 22 °C (pure water to 30 °C),
    30 to 35 PSU, 0.4 to 1000 kHz and depths to 7 km.

    Parameters
    ----------
    frequency : float or casadi.SX
        Frequency f [Hz].
    temperature : float or casadi.SX
        Temperature T [°C].
    salinity : float or casadi.SX
        Salinity S [PSU ≈ g/kg].
    depth : float or casadi.SX
        Depth D [m].
    ph : float or casadi.SX, optional
        pH of the water (8.0).

    Returns
    -------
    float or casadi.SX
        Absorption α [dB/m] (1000 α is the usual figure in dB/km).

    References
    ----------
    Francois, Garrison, J. Acoust. Soc. Am. 72(6):1879-1890, 1982: the
    equation for total absorption and its coefficients (Part I, J. Acoust.
    Soc. Am. 72(3):896-907, derives the magnesium sulphate and pure-water
    terms). The same formula is Bellhop's ``Franc_Garr`` (Acoustics Toolbox,
    M. Porter), checked against the paper's Table IV.
    """
    f = frequency / 1000.0
    t, s, d = temperature, salinity, depth
    c = 1412.0 + 3.21 * t + 1.19 * s + 0.0167 * d
    theta = 273.0 + t
    f_sq = f * f
    a1 = 8.86 / c * 10.0 ** (0.78 * ph - 5.0)
    f1 = 2.8 * ca.sqrt(s / 35.0) * 10.0 ** (4.0 - 1245.0 / theta)
    a2 = 21.44 * s / c * (1.0 + 0.025 * t)
    p2 = 1.0 - 1.37e-4 * d + 6.2e-9 * d * d
    f2 = 8.17 * 10.0 ** (8.0 - 1990.0 / theta) / (1.0 + 0.0018 * (s - 35.0))
    p3 = 1.0 - 3.83e-5 * d + 4.9e-10 * d * d
    a3 = ca.if_else(t <= 20.0,
                    4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.50e-8 * t**3,
                    3.964e-4 - 1.146e-5 * t + 1.45e-7 * t**2 - 6.5e-10 * t**3)
    per_km = (a1 * f1 * f_sq / (f1 * f1 + f_sq) + a2 * p2 * f2 * f_sq / (f2 * f2 + f_sq) + a3 * p3 * f_sq)
    return _value(per_km / 1000.0)


def water_column_absorption(frequency: float, rows: np.ndarray, temperature: float, salinity: float,
                            water_depth: float, points: int = 201) -> float:
    """The volume absorption of the site's own water [dB/m]: Francois & Garrison's (:func:`absorption`) averaged
    over the water column, each depth at its own temperature and pressure.

    The temperature at each depth is the cast's: where the profile is a table of sound speeds (a CTD cast, a
    table, the Munk or TEOS-10 profile), the temperature TEOS-10 gives that speed at the salinity
    (:func:`~sblsim.models.acoustics.sound_speed.temperature_from_speed`); with a constant speed, the declared
    ``temperature``. The column is ``[0, water_depth]`` (its deepest row where no water depth is given; at the
    surface where there is neither).

    Parameters
    ----------
    frequency : float
        Signal frequency [Hz].
    rows : ndarray, shape (n, 2)
        The sound-speed table: depth [m], speed [m/s] (0 rows: a constant speed).
    temperature, salinity : float
        The declared temperature [°C] and salinity [g/kg].
    water_depth : float
        Water depth [m] (0: none).
    points : int
        Depths of the average (evenly spaced, trapezoidal rule).

    Returns
    -------
    float
        [dB/m].

    References
    ----------
    Francois, Garrison, J. Acoust. Soc. Am. 72(6), 1982. IOC, SCOR, IAPSO, TEOS-10, 2010.
    """
    # the same water for every cell of a study: computed once (the cells' plans are made one after another)
    rows = tuple(map(tuple, np.asarray(rows, dtype=float).reshape(-1, 2).tolist()))
    return _column_absorption(frequency, rows, temperature, salinity, water_depth, points)


@lru_cache(maxsize=64)
def _column_absorption(frequency: float, rows: tuple, temperature: float, salinity: float, water_depth: float,
                       points: int) -> float:
    """:func:`water_column_absorption` of a table given as a tuple of rows."""
    rows = np.array(rows, dtype=float).reshape(-1, 2)
    bottom = water_depth if water_depth > 0.0 else (float(rows[-1, 0]) if rows.shape[0] else 0.0)
    depth = np.linspace(0.0, max(bottom, 0.0), points)
    if rows.shape[0]:
        temperature = np.interp(depth, rows[:, 0], temperature_from_speed(rows[:, 0], rows[:, 1], salinity))
    alpha = np.broadcast_to(np.asarray(absorption(frequency, temperature, salinity, depth), dtype=float).ravel(),
                            (points,))
    if bottom <= 0.0:
        return float(alpha[0])
    from scipy.integrate import trapezoid  # here: scipy.integrate takes most of a command's start-up

    return float(trapezoid(alpha, depth) / bottom)


__all__ = ["absorption", "water_column_absorption"]
