"""Sea state (Beaufort scale) to platform wave motion (casadi expressions).

The probable wave height per Beaufort level is the WMO table (docs/model.md);
the rest is sblsim's documented choice:

* dominant wave period from the Pierson-Moskowitz spectrum of a fully
  developed sea, ``T_p = 2π U / (0.877 g)``, with U the mid-range wind speed
  of the Beaufort level (WMO Beaufort scale);
* deep-water wavelength ``λ = g T_p² / (2π)``;
* roll and pitch amplitude: the platform follows the dominant wave slope
  ``π H / λ``, but a hull of length ℓ cannot tilt more than ``atan(H / ℓ)``
  (short waves are averaged over the hull);
* yaw amplitude half the tilt at half the wave frequency (a moored platform
  swings slowly); heave amplitude ``H / 2`` at the wave frequency.

References
----------
Pierson, Moskowitz, "A proposed spectral form for fully developed wind seas",
J. Geophys. Res. 69(24), 1964. WMO, Manual on Marine Meteorological Services,
WMO-No. 558 (Beaufort scale).
"""

from __future__ import annotations

import math

import casadi as ca

from sblsim.models.expressions import lookup

G = 9.80665  # standard gravity [m/s^2]

#: Probable wave height [m] per Beaufort level 0..8.
WAVE_HEIGHT = (0.0, 0.1, 0.2, 0.6, 1.0, 2.0, 3.0, 4.0, 5.5)
#: Mid-range 10 m wind speed [m/s] per Beaufort level 0..8 (WMO).
WIND_SPEED = (0.1, 0.9, 2.5, 4.4, 6.7, 9.35, 12.3, 15.5, 18.95)


def wave_motion(beaufort, hull_length) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """Wave-motion amplitudes and frequency for a Beaufort level.

    Parameters
    ----------
    beaufort : casadi.SX or int
        Beaufort level, 0 (calm) to 8.
    hull_length : casadi.SX or float
        Platform hull length ℓ [m].

    Returns
    -------
    tilt_amplitude : casadi.SX
        Roll and pitch amplitude [rad].
    yaw_amplitude : casadi.SX
        Yaw amplitude [rad].
    heave_amplitude : casadi.SX
        Heave amplitude [m].
    frequency : casadi.SX
        Roll, pitch and heave frequency [Hz]; yaw at half of it.
    """
    height = lookup(beaufort, WAVE_HEIGHT)
    period = 2.0 * math.pi * lookup(beaufort, WIND_SPEED) / (0.877 * G)
    wavelength = G * period**2 / (2.0 * math.pi)
    tilt = ca.fmin(math.pi * height / wavelength, ca.atan(height / hull_length))
    return tilt, 0.5 * tilt, 0.5 * height, 1.0 / period


__all__ = ["G", "WAVE_HEIGHT", "WIND_SPEED", "wave_motion"]
