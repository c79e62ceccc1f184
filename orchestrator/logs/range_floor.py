"""The lowest range a configuration's channel measures (docs/log-format.md, "A range is a measurement"): a log's
range below it is refused (:func:`sblsim.orchestrator.logs.receiver_log.read_log`).
"""

from __future__ import annotations

from typing import Any, Mapping

from sblsim.models.declarations import SIGNAL_RANGES

#: How far below its distance a range's noise reaches, in its standard deviations (a Gaussian draw beyond 8 σ: one
#: in 8e14): the margin of :func:`range_floor` [1].
NOISE_SIGMAS = 8.0


def range_floor(acoustics: Mapping[str, Any] | None) -> tuple[float, float, str]:
    """The lowest range a configuration's channel measures (docs/log-format.md, "A range is a measurement").

    A range is ``c`` times a measured time plus its noise: below 0 only by the noise (:data:`NOISE_SIGMAS` of
    ``acoustics.sigma_range``, grown by ``range_k`` and, with detection by signal-to-noise, to its accuracy at an SNR
    3 fluctuations below the detection threshold), by a two-way turnaround that jitters short (``turnaround_sigma``
    > 0: down to ``c · turnaround / 2``) and by a one-way clock's drift (``clock_drift_ppm``, growing with the time
    since the log's first row). An inverted LBL's pseudo-range (``ranging = "toa"``) has no such floor.

    Parameters
    ----------
    acoustics : mapping or None
        The configuration's ``[acoustics]`` (None: not known; the receiver's input range is taken).

    Returns
    -------
    floor : float
        The lowest range at the log's first row [m].
    fall : float
        How much lower it goes per second after the log's first row [m/s] (a one-way clock's drift).
    reason : str
        What makes the floor, for a refusal.
    """
    lowest = SIGNAL_RANGES["range"][0]
    if acoustics is None or acoustics.get("ranging") == "toa":
        return lowest, 0.0, "the receiver's input range"
    c = float(acoustics.get("sound_speed_assumed", 1500.0))
    sigma = float(acoustics.get("sigma_range", 0.0))
    jitter = 0.0
    two_way = acoustics.get("ranging") == "twtt"
    if two_way and float(acoustics.get("turnaround_sigma", 0.0)) > 0.0:
        jitter = c * float(acoustics.get("turnaround", 0.0)) / 2.0
        sigma += float(acoustics.get("range_k", 0.0)) * jitter  # the noise where the jitter makes a range negative
    if acoustics.get("detection") == "snr":
        weakest = float(acoustics["detection_threshold"]) - 3.0 * float(acoustics["fluctuation"])
        sigma *= max(1.0, 10.0 ** ((float(acoustics["reference_snr"]) - weakest) / 20.0))
    margin = NOISE_SIGMAS * sigma
    fall = abs(float(acoustics.get("clock_drift_ppm", 0.0))) * 1e-6 * c if not two_way else 0.0
    parts = [f"{NOISE_SIGMAS:g} σ_r = {margin:.4g} m of range noise (acoustics.sigma_range = "
             f"{float(acoustics.get('sigma_range', 0.0)):g} m)"]
    if jitter:
        parts.append(f"c · acoustics.turnaround / 2 = {jitter:.4g} m of turnaround jitter")
    if fall:
        parts.append(f"{fall:.3g} m per second of the log of clock drift (acoustics.clock_drift_ppm)")
    ranging = "two-way" if two_way else "one-way"
    return max(-(jitter + margin), lowest), fall, f"{ranging} ranging: " + " and ".join(parts)


__all__ = ["NOISE_SIGMAS", "range_floor"]
