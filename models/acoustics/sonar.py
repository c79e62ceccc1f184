"""The site's acoustics: the terms of the sonar equation (casadi expressions).

Each function takes Python floats or casadi symbols (``SX``/``MX``) and
returns a float for float input, an expression otherwise, so that the
channel model writes each term once and the FMUs generate it:

* :func:`absorption`: volume absorption of sea water, Francois & Garrison
  (1982);
* :func:`noise_spectrum_level`, :func:`noise_level`: ambient noise, the Wenz
  (1962) curves in the parametric form of Coates (1990) given by Stojanovic
  (2007);
* :data:`BOTTOMS`, :func:`bottom_parameters`, :func:`half_space_loss`,
  :func:`bottom_loss`: the Rayleigh reflection loss of a lossy fluid
  half-space (Jensen et al. 2011, ch. 1 and its Table 1.3);
* :func:`surface_loss`: the coherent (Kirchhoff) roughness loss of the
  pressure-release sea surface;
* :func:`snr`: the passive form of the sonar equation SL − TL − (NL − DI);
* :func:`detection_probability`: a log-normal fluctuation of the received
  level about the detection threshold (Urick 1983, ch. 12);
* :func:`accuracy_scale`: the Cramér–Rao scaling of timing and phase noise
  with SNR;
* :func:`detection_range`: the range at which SNR falls to the detection
  threshold for spherical spreading in constant sound speed (a documentation
  helper, plain numpy).

docs/model.md ("Signal-to-noise: the sonar equation") writes each term out
with a hand-worked detection range.

References
----------
Francois, Garrison, "Sound absorption based on ocean measurements. Part II:
Boric acid contribution and equation for total absorption", J. Acoust. Soc.
Am. 72(6):1879-1890, 1982. Wenz, "Acoustic ambient noise in the ocean:
spectra and sources", J. Acoust. Soc. Am. 34(12):1936-1956, 1962. Coates,
Underwater Acoustic Systems, Wiley 1990. Stojanovic, "On the relationship
between capacity and distance in an underwater acoustic communication
channel", ACM SIGMOBILE Mob. Comput. Commun. Rev. 11(4):34-43, 2007.
Jensen, Kuperman, Porter, Schmidt, Computational Ocean Acoustics, 2nd ed.,
Springer 2011, ch. 1. Brekhovskikh, Lysanov, Fundamentals of Ocean
Acoustics, 3rd ed., Springer 2003, ch. 4 and 13. Urick, Principles of
Underwater Sound, 3rd ed., McGraw-Hill 1983. Carter, "Time delay estimation
for passive sonar signal processing", IEEE Trans. ASSP 29(3):463-470, 1981.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from sblsim.models.acoustics.sound_speed import temperature_from_speed
from sblsim.models.errors import ModelError
from sblsim.models.expressions import lookup
from sblsim.models.platform.waves import WAVE_HEIGHT, WIND_SPEED

#: 20 log10(e): decibels per neper of amplitude.
DB_PER_NEPER = 20.0 / math.log(10.0)
#: The reference SNR at which a system's configured timing and angle noise hold [dB] (Kongsberg HiPAP 101).
REFERENCE_SNR = 20.0


def _value(x: Any) -> Any:
    """A float for a 1×1 numeric casadi result (``ca.if_else`` of floats gives a ``DM``), else ``x``."""
    if isinstance(x, ca.DM) and x.numel() == 1:
        return float(x)
    return x


# ------------------------------------------------------------------ absorption


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


# ------------------------------------------------------------------ ambient noise


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


# ------------------------------------------------------------------ boundaries


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


# ------------------------------------------------------------------ sonar equation, detection, accuracy


def snr(source_level, transmission_loss, noise_level, directivity_index):
    """Signal-to-noise ratio of the passive sonar equation: ``SNR = SL − TL − (NL − DI)``.

    Parameters
    ----------
    source_level : float or casadi.SX
        SL [dB re 1 µPa at 1 m].
    transmission_loss : float or casadi.SX
        TL along the path [dB re 1 m] (spreading + absorption + boundary losses).
    noise_level : float or casadi.SX
        NL in the receiver's band [dB re 1 µPa] (:func:`noise_level`).
    directivity_index : float or casadi.SX
        DI of the receiving transducer [dB].

    Returns
    -------
    float or casadi.SX
        SNR [dB].

    References
    ----------
    Urick, Principles of Underwater Sound, 3rd ed., 1983, ch. 2 (the passive sonar equation).
    """
    return _value(source_level - transmission_loss - (noise_level - directivity_index))


def detection_probability(snr, threshold, fluctuation):
    """Probability of detecting an arrival: ``P_d = Φ((SNR − DT)/σ_f)``.

    The received level fluctuates about its mean log-normally (Gaussian in
    dB) with standard deviation σ_f [dB]; the detection threshold DT is the
    SNR detected half of the time (Urick's definition: DT at the 50 %
    point), so ``P_d = ½ (1 + erf((SNR − DT)/(σ_f √2)))``. With σ_f = 0 it is
    a step: 1 when SNR ≥ DT, else 0 (no division by zero).

    Parameters
    ----------
    snr : float or casadi.SX
        Mean SNR of the arrival [dB].
    threshold : float or casadi.SX
        Detection threshold DT [dB].
    fluctuation : float or casadi.SX
        σ_f, standard deviation of the received level [dB], ≥ 0.

    Returns
    -------
    float or casadi.SX
        P_d, 0 to 1.

    References
    ----------
    Urick, Principles of Underwater Sound, 3rd ed., 1983, §12.1-12.3 (detection threshold, the 50 % point;
    log-normal fluctuation of the received level).
    """
    excess = snr - threshold
    scale = ca.fmax(fluctuation, 1e-300) * math.sqrt(2.0)
    smooth = 0.5 * (1.0 + ca.erf(excess / scale))
    return _value(ca.if_else(fluctuation > 0, smooth, ca.if_else(excess >= 0, 1.0, 0.0)))


def accuracy_scale(snr, reference_snr=REFERENCE_SNR):
    """Factor on a configured timing or angle standard deviation at an SNR: ``max(1, 10^((SNR_ref − SNR)/20))``.

    The Cramér–Rao bound of a time delay, ``σ_τ ≥ 1/(2π β √(2 E/N0))``
    (β the rms bandwidth), and of the phase difference of a USBL pair,
    ``σ_φ ∝ 1/√SNR``, both scale as ``SNR^(−1/2) = 10^(−SNR_dB/20)``: 6.02 dB
    less SNR doubles them. The configured σ holds at the reference SNR (20 dB,
    the level at which vendors state accuracy, e.g. Kongsberg HiPAP 101) and
    is the floor above it: there other errors (sound speed, calibration,
    quantization) dominate, which the bound does not model.

    Parameters
    ----------
    snr : float or casadi.SX
        SNR [dB].
    reference_snr : float or casadi.SX, optional
        SNR at which the configured σ holds [dB] (20).

    Returns
    -------
    float or casadi.SX
        Scale factor, ≥ 1.

    References
    ----------
    Carter, IEEE Trans. ASSP 29(3):463-470, 1981 (time-delay CRLB); Van Trees, Detection, Estimation, and
    Modulation Theory, Part I, Wiley 1968, §2.4 and ch. 4 (Cramér–Rao bound, phase estimation).
    """
    return _value(ca.fmax(1.0, 10.0 ** ((reference_snr - snr) / 20.0)))


# ------------------------------------------------------------------ documentation helper


def detection_range(frequency, bandwidth, source_level, directivity_index, detection_threshold, wind_speed,
                    shipping, temperature, salinity, depth, ph=8.0, shortest=1.0, longest=1e6) -> float:
    """The range at which SNR falls to the detection threshold: spherical spreading, constant sound speed.

    Solves ``SL − (20 log10 r + α r) − (NL − DI) = DT`` for r by bisection
    on log r (SNR falls strictly with r), α from :func:`absorption` and NL
    from :func:`noise_level`. A documentation helper (plain floats, not a
    channel expression): docs/model.md works one out by hand.

    Parameters
    ----------
    frequency, bandwidth : float
        Centre frequency and bandwidth [Hz].
    source_level : float
        SL [dB re 1 µPa at 1 m].
    directivity_index : float
        DI [dB].
    detection_threshold : float
        DT [dB].
    wind_speed : float
        Wind speed [m/s].
    shipping : float
        Shipping activity, 0 to 1.
    temperature, salinity, depth : float
        Water temperature [°C], salinity [PSU], depth [m] for the absorption.
    ph : float, optional
        pH (8.0).
    shortest, longest : float, optional
        The bracket searched [m] (1 m to 1000 km).

    Returns
    -------
    float
        Detection range r [m] (to 1e-9 relative).

    Raises
    ------
    ModelError
        SNR below DT already at ``shortest``, or above DT still at ``longest``.
    """
    alpha = float(absorption(frequency, temperature, salinity, depth, ph))
    noise = float(noise_level(frequency, bandwidth, wind_speed, shipping))

    def excess(r: float) -> float:
        return source_level - (20.0 * math.log10(r) + alpha * r) - (noise - directivity_index) - detection_threshold

    if excess(shortest) < 0:
        raise ModelError(f"detection_range: SNR at {shortest:g} m is below the detection threshold "
                         f"{detection_threshold:g} dB (nothing is heard)")
    if excess(longest) >= 0:
        raise ModelError(f"detection_range: SNR at {longest:g} m is still above the detection threshold "
                         f"{detection_threshold:g} dB (raise longest)")
    low, high = math.log(shortest), math.log(longest)
    while high - low > 1e-10:
        mid = 0.5 * (low + high)
        if excess(math.exp(mid)) >= 0:
            low = mid
        else:
            high = mid
    return math.exp(0.5 * (low + high))



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

__all__ = ["absorption", "accuracy_scale", "Bottom", "bottom_loss", "bottom_parameters", "BOTTOMS", "DB_PER_NEPER",
           "detection_probability", "detection_range", "half_space_loss", "noise_components", "noise_level",
           "noise_spectrum_level", "REFERENCE_SNR", "snr", "surface_loss", "water_column_absorption", "wave_height",
           "wind_speed"]
