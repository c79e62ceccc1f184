"""The range-dependent noise law of a range: ``σ = σ₀ + k · d`` (``acoustics.range_k``), written once for the
channel that draws the noise and the receivers and bounds that weigh it.

The source of the law: the Cramér-Rao bound of a time delay's estimate is proportional to ``1 / √SNR`` (Quazi,
"An overview on the time delay estimate in active and passive systems for target localization", IEEE Trans.
Acoustics, Speech and Signal Processing 29(3):527–533, 1981), and with spherical spreading the SNR falls as
``1 / d²``: the noise of an arrival that is not at its floor grows in proportion to the distance, as the ranging
accuracy that acoustic positioning equipment states as a share of the range (0.1 % of the range: ``k = 0.001``);
``σ₀`` is the floor. The telemetry design's :func:`~sblsim.models.design.telemetry.range_sigma` is the same law in
numbers.
"""

from __future__ import annotations

#: The scenario key of the law's growth (a channel parameter, tied to the receivers' ``range_k``).
RANGE_K = "range_k"


def range_noise_sigma(p, distance):
    """The standard deviation of a range [m] at the length ``distance`` [m]: ``σ₀ + k d``.

    Parameters
    ----------
    p : mapping
        Parameters (numbers or casadi expressions): ``sigma_range`` (σ₀ [m]) and, where declared, ``range_k``
        (k [m/m]); a mapping without ``range_k`` gives ``σ₀`` itself (a receiver that does not declare the law).
    distance : float, ndarray or casadi.SX
        The range's length [m]: the true one where the noise is drawn, the predicted ``‖p̂ − b‖`` where it is
        weighed.

    Returns
    -------
    float, ndarray or casadi.SX
        σ [m], the shape of ``distance`` (``σ₀`` unchanged where ``range_k`` is not declared).

    References
    ----------
    Quazi, IEEE Trans. ASSP 29(3):527–533, 1981 (the time delay's bound ∝ 1/√SNR; with spherical spreading,
    σ ∝ d).
    """
    if RANGE_K not in p:
        return p["sigma_range"]
    return p["sigma_range"] + p[RANGE_K] * distance


__all__ = ["RANGE_K", "range_noise_sigma"]
