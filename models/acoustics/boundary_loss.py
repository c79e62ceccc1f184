"""Reflection loss at the channel's boundaries: the sea floor as a lossy fluid half-space, and the rough sea surface.

* :data:`BOTTOMS`, :func:`bottom_parameters`, :func:`half_space_loss`, :func:`bottom_loss`: the Rayleigh
  reflection loss of a lossy fluid half-space (Jensen et al. 2011, ch. 1 and its Table 1.3);
* :func:`surface_loss`: the coherent (Kirchhoff) roughness loss of the pressure-release sea surface, its rms
  elevation from the probable wave height of a Beaufort level (:func:`wave_height`).

Each takes floats (and returns a float) or casadi symbols (and returns an expression).

References
----------
Jensen, Kuperman, Porter, Schmidt, Computational Ocean Acoustics, 2nd ed.,
Springer 2011, ch. 1. Brekhovskikh, Lysanov, Fundamentals of Ocean
Acoustics, 3rd ed., Springer 2003, ch. 4 and 13.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import casadi as ca

from sblsim.models.errors import ModelError
from sblsim.models.expressions import _value, lookup
from sblsim.models.platform.waves import WAVE_HEIGHT

#: 20 log10(e): decibels per neper of amplitude.
DB_PER_NEPER = 20.0 / math.log(10.0)


def wave_height(beaufort):
    """The probable wave height of a Beaufort level [m] (WMO; :data:`~sblsim.models.platform.waves.WAVE_HEIGHT`).

    Parameters
    ----------
    beaufort : int or casadi.SX
        Beaufort level 0..8 (0 outside).

    Returns
    -------
    float or casadi.SX
        Probable (significant) wave height H [m].
    """
    return _value(lookup(beaufort, WAVE_HEIGHT))


class Bottom(NamedTuple):
    """A fluid half-space's geoacoustic parameters (one row of Jensen et al. 2011, Table 1.3)."""

    #: Density over the water's density ρ_b/ρ_w.
    density_ratio: float
    #: Compressional sound speed c_p [m/s] (Jensen's c_p/c_w times c_w = 1500 m/s).
    speed: float
    #: Compressional attenuation α_p [dB/λ].
    attenuation: float


#: Geoacoustic properties of sea-floor sediments and rocks (Jensen, Kuperman, Porter, Schmidt, Computational
#: Ocean Acoustics, 2nd ed., Springer 2011, Table 1.3; shear ignored: a fluid half-space). ``mud`` is the clay
#: row (soft, lossy, no critical angle), ``rock`` the limestone row.
BOTTOMS: dict[str, Bottom] = {
    "clay": Bottom(1.5, 1500.0, 0.2),
    "silt": Bottom(1.7, 1575.0, 1.0),
    "sand": Bottom(1.9, 1650.0, 0.8),
    "gravel": Bottom(2.0, 1800.0, 0.6),
    "moraine": Bottom(2.1, 1950.0, 0.4),
    "chalk": Bottom(2.2, 2400.0, 0.2),
    "limestone": Bottom(2.4, 3000.0, 0.1),
    "basalt": Bottom(2.7, 5250.0, 0.1),
}
BOTTOMS["mud"] = BOTTOMS["clay"]
BOTTOMS["rock"] = BOTTOMS["limestone"]


def bottom_parameters(bottom, water_speed=1500.0) -> tuple[Any, Any, Any]:
    """The three numbers of :func:`half_space_loss` for a bottom of :data:`BOTTOMS` or given parameters.

    Parameters
    ----------
    bottom : str or Bottom or tuple of 3 floats
        A name of :data:`BOTTOMS`, or ``(density_ratio, speed [m/s], attenuation [dB/λ])``.
    water_speed : float or casadi.SX, optional
        Sound speed of the water at the sea floor [m/s] (1500).

    Returns
    -------
    density_ratio : float
        ρ_b/ρ_w.
    speed_ratio : float or casadi.SX
        c_b/c_w: the bottom's compressional speed over ``water_speed``.
    attenuation : float
        α_p [dB/λ].

    Raises
    ------
    ModelError
        An unknown name, or parameters outside density ratio (0, 10], speed (0, 10000] m/s,
        attenuation [0, 10] dB/λ.
    """
    if isinstance(bottom, str):
        if bottom not in BOTTOMS:
            raise ModelError(f"acoustics.bottom: unknown bottom {bottom!r} (allowed: {', '.join(BOTTOMS)})")
        row = BOTTOMS[bottom]
    else:
        try:
            row = Bottom(*(float(v) for v in bottom))
        except (TypeError, ValueError):
            raise ModelError("acoustics.bottom: a name of BOTTOMS or (density ratio, speed [m/s], "
                             "attenuation [dB/λ])") from None
        bounds = (("density ratio", row.density_ratio, 0.0, 10.0, False),
                  ("speed [m/s]", row.speed, 0.0, 10000.0, False),
                  ("attenuation [dB/λ]", row.attenuation, 0.0, 10.0, True))
        for name, v, lo, hi, closed in bounds:
            if not (math.isfinite(v) and (v >= lo if closed else v > lo) and v <= hi):
                raise ModelError(f"acoustics.bottom: {name} {v} outside {'[' if closed else '('}{lo:g}, {hi:g}]")
    return row.density_ratio, _value(row.speed / water_speed), row.attenuation


def half_space_loss(grazing, density_ratio, speed_ratio, attenuation):
    """Bottom loss BL = −20 log10 |R| of a lossy fluid half-space (Rayleigh reflection coefficient).

    With m = ρ_b/ρ_w, the complex index ``n = (c_w/c_b)(1 + iδ)``,
    ``δ = α_p / (40 π log10 e)`` (α_p in dB/λ: the wave loses α_p dB per
    wavelength) and θ the grazing angle::

        R = (m sin θ − √(n² − cos² θ)) / (m sin θ + √(n² − cos² θ)),

    the root with non-negative imaginary part (the transmitted wave decays
    into the bottom). Without attenuation and below the critical angle
    θ_c = arccos(c_w/c_b) |R| = 1 (0 dB); at normal incidence
    R = (m ν − 1)/(m ν + 1), ν = c_b/c_w. The complex arithmetic is written
    out in real and imaginary parts (casadi has no complex numbers).

    Parameters
    ----------
    grazing : float or casadi.SX
        Grazing angle θ [rad], 0 to π/2.
    density_ratio : float or casadi.SX
        ρ_b/ρ_w, > 0.
    speed_ratio : float or casadi.SX
        ν = c_b/c_w, > 0.
    attenuation : float or casadi.SX
        Compressional attenuation α_p [dB/λ], ≥ 0.

    Returns
    -------
    float or casadi.SX
        BL [dB], ≥ 0.

    References
    ----------
    Jensen, Kuperman, Porter, Schmidt, Computational Ocean Acoustics, 2nd ed., 2011, ch. 1 (the Rayleigh
    reflection coefficient of two fluid half-spaces; attenuation in dB/λ and the loss tangent δ; Table 1.3);
    Brekhovskikh, Lysanov, Fundamentals of Ocean Acoustics, 2003, ch. 4.
    """
    delta = attenuation / (40.0 * math.pi * math.log10(math.e))
    sin_g, cos_g = ca.sin(grazing), ca.cos(grazing)
    # n² = (1/ν²)(1 + iδ)² ; z = n² − cos²θ = a + i b with b ≥ 0
    inv_sq = 1.0 / (speed_ratio * speed_ratio)
    a = inv_sq * (1.0 - delta * delta) - cos_g * cos_g
    b = inv_sq * 2.0 * delta
    modulus = ca.sqrt(a * a + b * b)
    # principal square root p + i q (q ≥ 0), each part from the stable side
    tiny = 1e-300
    root_pos = ca.sqrt(ca.fmax(0.5 * (modulus + a), 0.0))
    root_neg = ca.sqrt(ca.fmax(0.5 * (modulus - a), 0.0))
    p = ca.if_else(a >= 0, root_pos, b / (2.0 * ca.fmax(root_neg, tiny)))
    q = ca.if_else(a >= 0, b / (2.0 * ca.fmax(root_pos, tiny)), root_neg)
    ms = density_ratio * sin_g
    numerator = (ms - p) ** 2 + q * q
    denominator = (ms + p) ** 2 + q * q
    ratio = ca.if_else(denominator > 0, numerator / ca.fmax(denominator, tiny), 1.0)
    return _value(ca.fmax(-10.0 * ca.log10(ca.fmax(ratio, tiny)), 0.0))


def bottom_loss(grazing, bottom, water_speed=1500.0):
    """Bottom loss [dB] of a named bottom (or given parameters) at a grazing angle.

    :func:`half_space_loss` with :func:`bottom_parameters`.

    Parameters
    ----------
    grazing : float or casadi.SX
        Grazing angle θ [rad], 0 to π/2.
    bottom : str or tuple of 3 floats
        A name of :data:`BOTTOMS` or ``(density_ratio, speed [m/s], attenuation [dB/λ])``.
    water_speed : float or casadi.SX, optional
        Sound speed of the water at the sea floor [m/s] (1500).

    Returns
    -------
    float or casadi.SX
        BL [dB], ≥ 0.

    Raises
    ------
    ModelError
        An unknown bottom or parameters out of range (:func:`bottom_parameters`).
    """
    return half_space_loss(grazing, *bottom_parameters(bottom, water_speed))


def surface_loss(grazing, frequency, wave_height, sound_speed=1500.0, limit=None):
    """Coherent reflection loss of the rough, pressure-release sea surface.

    The flat surface reflects with R = −1 (no loss); its roughness scatters
    energy out of the specular (coherent) path, whose amplitude falls by the
    Rayleigh (Kirchhoff) factor ``exp(−2 (k σ sin θ)²)``, k = 2π f / c, so
    ``loss = −20 log10 exp(−2 (k σ sin θ)²) = 40 log10(e) (k σ sin θ)²`` [dB],
    σ the rms surface elevation: a quarter of the probable (significant)
    wave height H (σ = H/4 for a Gaussian sea). The loss grows without bound
    with kσ sin θ (the incoherent scatter it leaves out arrives spread in
    time and direction); ``limit`` caps it where a caller wants a finite
    value.

    Parameters
    ----------
    grazing : float or casadi.SX
        Grazing angle θ [rad], 0 to π/2.
    frequency : float or casadi.SX
        Frequency f [Hz].
    wave_height : float or casadi.SX
        Probable (significant) wave height H [m] (:func:`wave_height` of a Beaufort level).
    sound_speed : float or casadi.SX, optional
        Sound speed at the surface c [m/s] (1500).
    limit : float or casadi.SX, optional
        Largest loss returned [dB] (None: no cap).

    Returns
    -------
    float or casadi.SX
        Loss [dB], ≥ 0.

    References
    ----------
    Jensen, Kuperman, Porter, Schmidt, Computational Ocean Acoustics, 2nd ed., 2011, ch. 1 (the Kirchhoff
    coherent reflection coefficient of a rough surface); Brekhovskikh, Lysanov, 2003, ch. 13;
    σ = H_s/4: e.g. Holthuijsen, Waves in Oceanic and Coastal Waters, Cambridge 2007, §4.2.
    """
    k = 2.0 * math.pi * frequency / sound_speed
    rayleigh = k * (wave_height / 4.0) * ca.sin(grazing)
    loss = 2.0 * DB_PER_NEPER * rayleigh * rayleigh
    if limit is not None:
        loss = ca.fmin(loss, limit)
    return _value(loss)


__all__ = ["Bottom", "BOTTOMS", "bottom_loss", "bottom_parameters", "DB_PER_NEPER", "half_space_loss", "surface_loss",
           "wave_height"]
