"""Sea state (Beaufort scale) to platform wave motion.

The SPEC fixes the probable wave height per Beaufort level; the rest is
sblsim's documented choice:

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
from dataclasses import dataclass

G = 9.80665  # standard gravity [m/s^2]

#: Probable wave height [m] per Beaufort level 0..8 (SPEC.md).
WAVE_HEIGHT = (0.0, 0.1, 0.2, 0.6, 1.0, 2.0, 3.0, 4.0, 5.5)
#: Mid-range 10 m wind speed [m/s] per Beaufort level 0..8 (WMO).
WIND_SPEED = (0.1, 0.9, 2.5, 4.4, 6.7, 9.35, 12.3, 15.5, 18.95)


@dataclass(frozen=True)
class WaveMotion:
    """Sinusoidal platform motion for one sea state.

    Attributes
    ----------
    tilt_amplitude : float
        Roll and pitch amplitude [rad].
    yaw_amplitude : float
        Yaw amplitude [rad].
    heave_amplitude : float
        Heave amplitude [m].
    frequency : float
        Roll, pitch and heave frequency [Hz]; yaw at half of it.
    """

    tilt_amplitude: float
    yaw_amplitude: float
    heave_amplitude: float
    frequency: float


def wave_motion(beaufort: int, hull_length: float) -> WaveMotion:
    """Wave-motion amplitudes and frequency for a Beaufort level.

    Parameters
    ----------
    beaufort : int
        Beaufort level, 0 (calm) to 8.
    hull_length : float
        Platform hull length ℓ [m].

    Returns
    -------
    WaveMotion
    """
    height = WAVE_HEIGHT[beaufort]
    period = 2.0 * math.pi * WIND_SPEED[beaufort] / (0.877 * G)
    wavelength = G * period**2 / (2.0 * math.pi)
    tilt = min(math.pi * height / wavelength, math.atan(height / hull_length))
    return WaveMotion(tilt_amplitude=tilt, yaw_amplitude=0.5 * tilt,
                      heave_amplitude=0.5 * height, frequency=1.0 / period)
