"""What a map's site lets through: each packet's probability of being received and its accuracy scale
(:func:`packet_probabilities`), the probability of a fix (:func:`fix_probability`) and a range's
variance grown by its SNR (:func:`grown_noise`).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from sblsim.fmus.compiled_functions import compiled_family_levels
from sblsim.models.acoustics.channel.site_levels import site_levels
from sblsim.models.acoustics.detection import direct_first, packet_probability
from sblsim.models.acoustics.sonar import accuracy_scale
from sblsim.orchestrator.cosim.plan import RunPlan


def grown_noise(noise_variance, range_variance, probability: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Each range's variance where the site decides what is heard [m²]: the range noise ``range_variance`` (σ_r²,
    or the range law's per point and transducer; part of ``noise_variance``, which holds the transducer position's
    error too) grown by the square of the
    accuracy scale of the packet's SNR; a packet never heard keeps ``noise_variance`` (its weight is 0)."""
    return np.where(probability > 0.0, noise_variance + range_variance * (scale ** 2 - 1.0), noise_variance)


def packet_probabilities(plan: RunPlan, points: np.ndarray, arms: np.ndarray | None = None,
                         echo: bool = False) -> tuple[np.ndarray, ...]:
    """Per point and transducer: the probability that one packet is received, and the accuracy scale.

    With fixed detection a packet is received with ``1 − loss_pct`` per draw (USBL: the reply and the
    downlink, two draws) and the scale is 1. With detection by signal-to-noise (``acoustics.detection = "snr"``)
    each leg of the exchange is the eigenrays between the point and the transducer (a leg and its reverse
    are the same path: reciprocity), the legs' fluctuations independent: every leg before the last must be
    heard (``1 − Π (1 − P_j)``: TWTT's interrogation; USBL's interrogation and reply), the last one's first
    detected arrival decoded (:func:`~sblsim.models.acoustics.detection.packet_probability`); the scale is
    :func:`~sblsim.models.acoustics.sonar.accuracy_scale` at the SNR of the earliest eigenray.

    With ``echo``, a third array: the probability that a received packet's range is not the direct rays' (a leg
    of the range, TWTT's and USBL's interrogation and reply, or OWTT's one, had a reflection as its first detected
    arrival: :func:`~sblsim.models.acoustics.detection.direct_first`), where the map's geometry of the direct ray
    does not describe the range (0 with fixed detection).

    Parameters
    ----------
    plan : RunPlan
    points : ndarray, shape (M, 3)
        NED [m].
    arms : ndarray, shape (n, 3), optional
        The transducers' positions when the platform is at the origin, NED [m] (default the plan's,
        :attr:`RunPlan.lever_arms`; a design's candidate layout).
    echo : bool
        Return the probability of a range of reflections too.

    Returns
    -------
    probability, scale[, echo] : ndarray, each (M, n)
        n the system's transducers.
    """
    acoustics, system = plan["acoustics"], plan.system
    arms = np.asarray(plan.lever_arms if arms is None else arms, dtype=float)
    m, n = points.shape[0], arms.shape[0]
    if acoustics["detection"] != "snr":
        keep = (1.0 - acoustics["loss_pct"] / 100.0) ** (2 if system.measures_direction else 1)
        return (np.full((m, n), keep), np.ones((m, n))) + ((np.zeros((m, n)),) if echo else ())
    legs = 3 if system.measures_direction else (2 if acoustics["ranging"] == "twtt" else 1)
    levels = site_levels(plan.component_parameters("acoustics"), np.repeat(arms, m, axis=0), np.tile(points, (n, 1)),
                         compiled_family_levels())
    pd, snr, tau = levels["pd"], levels["snr"], np.where(levels["valid"] > 0.5, levels["tau"], np.inf)
    heard = 1.0 - np.prod(1.0 - pd, axis=1)
    data = packet_probability(tau, pd, snr, acoustics["detection_threshold"], acoustics["decoding_margin"],
                              acoustics["fluctuation"])
    first = np.take_along_axis(snr, np.argmin(tau, axis=1)[:, None], 1)[:, 0]
    scale = np.asarray(accuracy_scale(ca.DM(first), acoustics["reference_snr"])).ravel()  # the channel's form
    out = (heard ** (legs - 1) * data).reshape(n, m).T, scale.reshape(n, m).T
    if not echo:
        return out
    direct_heard = np.where(heard > 0.0, direct_first(tau, pd) / np.where(heard > 0.0, heard, 1.0), 1.0)
    decoded = direct_first(tau, pd, snr, acoustics["detection_threshold"], acoustics["decoding_margin"],
                           acoustics["fluctuation"])
    direct_data = np.where(data > 0.0, decoded / np.where(data > 0.0, data, 1.0), 1.0)
    direct = direct_heard ** 2 if system.measures_direction else direct_heard ** (legs - 1) * direct_data
    return out + (np.clip(1.0 - direct, 0.0, 1.0).reshape(n, m).T,)


def fix_probability(probability: np.ndarray, needed: int) -> np.ndarray:
    """The probability that at least ``needed`` of a cycle's packets are received (independent packets).

    Parameters
    ----------
    probability : ndarray, shape (M, n)
        Each packet's probability of being received.
    needed : int
        The packets a fix needs (:attr:`~sblsim.models.systems.System.fix_packets`).

    Returns
    -------
    ndarray, shape (M,)
        The upper tail of the Poisson-binomial distribution (the count's distribution, one packet at a time).
    """
    count = np.zeros((probability.shape[0], probability.shape[1] + 1))
    count[:, 0] = 1.0
    for j in range(probability.shape[1]):
        p = probability[:, j:j + 1]
        count[:, 1:] = count[:, 1:] * (1.0 - p) + count[:, :-1] * p
        count[:, 0] *= 1.0 - p[:, 0]
    return count[:, needed:].sum(axis=1)
