"""The sonar equation and what follows from it: an arrival's SNR, its detection probability, the accuracy there.

Each function takes Python floats or casadi symbols (``SX``/``MX``) and
returns a float for float input, an expression otherwise, so that the
channel model writes each term once and the FMUs generate it. The terms
the equation combines are modules of their own: volume absorption
(:mod:`~sblsim.models.acoustics.volume_absorption`), ambient noise
(:mod:`~sblsim.models.acoustics.ambient_noise`) and the boundaries'
reflection loss (:mod:`~sblsim.models.acoustics.boundary_loss`).

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
Urick, Principles of Underwater Sound, 3rd ed., McGraw-Hill 1983. Carter,
"Time delay estimation for passive sonar signal processing", IEEE Trans. ASSP
29(3):463-470, 1981.
"""

from __future__ import annotations

import math

import casadi as ca

from sblsim.models.acoustics.ambient_noise import noise_level
from sblsim.models.acoustics.volume_absorption import absorption
from sblsim.models.errors import ModelError
from sblsim.models.expressions import _value

#: The reference SNR at which a system's configured timing and angle noise hold [dB] (Kongsberg HiPAP 101).
REFERENCE_SNR = 20.0


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


__all__ = ["accuracy_scale", "detection_probability", "detection_range", "REFERENCE_SNR", "snr"]
