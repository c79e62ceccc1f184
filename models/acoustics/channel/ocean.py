"""The moving ocean: the sound speed's smooth change in time, the same on every path, as the nadir total delay
(NTD) of GNSS-Acoustic seafloor geodesy models it (docs/calibration.md): every travel time of a leg is multiplied by
``1 + ε(t)`` (:func:`ocean_perturbation`; :func:`~sblsim.models.acoustics.channel.legs._leg` applies it at the leg's
start). A steady ocean (``ntd_sigma_ppm = 0``, the default) changes nothing.
"""

from __future__ import annotations

import math

import casadi as ca

from sblsim.models.declarations import Variable

#: Random Fourier features of the moving ocean's travel-time perturbation (:func:`ocean_perturbation`).
OCEAN_FEATURES = 16
#: The moving ocean (declared after every other variable of the channel: their value references stay): the
#: sound speed's smooth change in time, the same on every path, as the nadir total delay (NTD) of GNSS-Acoustic
#: seafloor geodesy models it (docs/calibration.md).
OCEAN_VARIABLES: tuple[Variable, ...] = (
    Variable("ntd_sigma_ppm", "parameter", "Real", 0.0, "ppm",
             "Moving ocean: std of the travel times' relative change in time (the nadir total delay over the nadir "
             "travel time; 0: a steady ocean)", min=0.0, max=1e4),
    Variable("ntd_time_scale", "parameter", "Real", 1800.0, "s",
             "Moving ocean: time scale of the change (a Gaussian correlation exp(-dt^2 / (2 scale^2)))",
             min=1.0, max=1e7),
)


def ocean_perturbation(t, sigma, frequency, phase) -> ca.SX:
    """The moving ocean's relative travel-time change ε(t) at the epoch ``t`` [s]: a stationary Gaussian process of
    standard deviation ``sigma`` [1] and Gaussian correlation ``exp(−Δt² / (2 ℓ²))``, drawn as random Fourier
    features, ``ε(t) = σ √(2/M) Σ_m cos(ω_m t + φ_m)``, with ``ω_m ~ N(0, 1/ℓ²)`` (``frequency`` (M, 1) [rad/s])
    and ``φ_m ~ U(0, 2π)`` (``phase`` (M, 1) [rad]) drawn once per run; a path's travel time is multiplied by
    ``1 + ε``.

    References
    ----------
    Rahimi, Recht, "Random features for large-scale kernel machines", NIPS 2007. Tomita, Kido, "SeaGap", 2022
    (the nadir total delay of GNSS-A); Watanabe et al., Front. Earth Sci. 8:597532, 2020 (GARPOS).
    """
    m = frequency.shape[0]
    return sigma * math.sqrt(2.0 / m) * ca.sum1(ca.cos(frequency * t + phase))


__all__ = ["OCEAN_FEATURES", "ocean_perturbation", "OCEAN_VARIABLES"]
