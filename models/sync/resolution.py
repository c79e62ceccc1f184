"""The resolution of detection times against what positioning needs of them.

A receiver's export may round its times (a whole second, a tenth): the rounding is an error uniform over one
quantum q, of standard deviation q / √12 (Widrow & Kollár, *Quantization Noise*, Cambridge University Press 2008,
§ 4.1). Positioning from times of arrival needs that error well below the travel time across the array; where it is
not, every position is poor whatever the solver, and the user can only fix it at the export.
"""

from __future__ import annotations

import numpy as np

#: The quanta looked for, coarsest first [s].
QUANTA = (60.0, 10.0, 1.0, 0.1, 0.01, 0.001)


def time_quantum(times: np.ndarray) -> float:
    """The coarsest of :data:`QUANTA` every time is a whole multiple of, 0 where none is (sub-millisecond).

    Parameters
    ----------
    times : ndarray, (n,)
        Detection times [s] (epoch seconds: float64 keeps them to about 0.2 µs, well below the finest quantum).

    Returns
    -------
    float
        The quantum [s], or 0.0 where the times are finer than a millisecond or there are none.
    """
    t = np.asarray(times, float)
    t = t[np.isfinite(t)]
    if len(t) < 2:
        return 0.0
    for q in QUANTA:
        remainder = np.abs(t / q - np.round(t / q)) * q
        if (remainder <= max(1e-6, 4 * np.spacing(np.abs(t).max()))).all():
            return q
    return 0.0


def resolution_warning(times: np.ndarray, travel_time: float, sound_speed: float, what: str) -> str | None:
    """One line where the times' rounding (:func:`time_quantum`) is not well below the travel time across the array.

    Parameters
    ----------
    times : ndarray, (n,)
        Detection times [s].
    travel_time : float
        The largest travel time between two receivers [s] (0 for one receiver: any rounding said).
    sound_speed : float
        [m/s], to state the rounding's error in metres.
    what : str
        The source named in the line (a file).

    Returns
    -------
    str or None
        The line, or None where the rounding's standard deviation is below a tenth of ``travel_time``.
    """
    q = time_quantum(times)
    if q == 0.0:
        return None
    sigma = q / np.sqrt(12.0)
    if sigma < 0.1 * travel_time:
        return None
    return (f"{what}: every time is a whole multiple of {q:g} s (a rounding error of {1000 * sigma:.3g} ms, "
            f"{sigma * sound_speed:.3g} m of range, where the largest travel time across the array is "
            f"{1000 * travel_time:.3g} ms): positions from these times are poor whatever the solver; export the "
            "detections with their sub-second times")


__all__ = ["QUANTA", "resolution_warning", "time_quantum"]
