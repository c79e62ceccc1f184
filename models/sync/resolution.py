"""The resolution of detection times against what positioning needs of them.

A receiver's export may round its times (a whole second, a tenth): the rounding is an error uniform over one
quantum q, of standard deviation q / √12 (Widrow & Kollár, *Quantization Noise*, Cambridge University Press 2008,
§ 4.1). Positioning from times of arrival needs that error well below the travel time across the array; where it is
not, every position is poor whatever the solver, and the user can only fix it at the export.

Two checks weigh it by its size:

* **before a synchronisation** (:func:`check_resolution`): a rounding whose σ is not below :data:`RESOLVABLE` of the
  largest travel time across the array leaves the travel times the sync fits inside the rounding (whole seconds
  on an array sound crosses in half a second: the boats' clocks come out 0.17 s off, median, against the same
  file's to the millisecond); refused before the work, naming the rounding as the cause
  (:func:`resolution_warning` says the same of a matrix or a study's detections, where nothing is fitted);
* **after it** (:func:`residual_warning`): the sync's own residuals say what it reaches on this array; where a
  receiver's rounding σ is the larger part of them (``σ_q² ≥ r² / 2``, ``r`` its residuals' robust scale: the
  noise without the rounding, ``√(r² − σ_q²)``, not above the rounding's), the rounding is what limits its clock
  and every position from it: said in one line.
"""

from __future__ import annotations

import numpy as np

from sblsim.models.declarations import ModelError

#: The quanta looked for, coarsest first [s]: the decimal steps of 1, 2 and 5 (and quarters) from a minute to a
#: millisecond, each a whole number of milliseconds. Not a chain (0.05 s is no multiple of 0.02 s): batches' quanta
#: combine by their greatest common divisor (:func:`common_quantum`). A grid the decimal steps alone would miss (times
#: floored to 0.05 s taken as hundredths) gives its rounding σ five times too small.
QUANTA = (60.0, 30.0, 10.0, 5.0, 2.0, 1.0, 0.5, 0.25, 0.2, 0.1, 0.05, 0.025, 0.02, 0.01, 0.005, 0.002, 0.001)
#: The first times each quantum is tried on before all of them.
SCREEN = 1000
#: The share of the largest travel time across the array a rounding's σ must stay below (:func:`check_resolution`,
#: :func:`resolution_warning`).
RESOLVABLE = 0.1
#: How the quanta are named in a line.
QUANTUM_NAMES = {60.0: "whole minutes", 30.0: "half minutes", 10.0: "tens of seconds", 5.0: "fives of seconds",
                 2.0: "even seconds", 1.0: "whole seconds", 0.5: "half seconds", 0.25: "quarter seconds",
                 0.2: "fifths of a second", 0.1: "tenths of a second", 0.05: "twentieths of a second",
                 0.025: "fortieths of a second", 0.02: "fiftieths of a second", 0.01: "hundredths of a second",
                 0.005: "two-hundredths of a second", 0.002: "five-hundredths of a second", 0.001: "milliseconds"}


def rounding_sigma(quantum: float) -> float:
    """[s] the standard deviation of a rounding to ``quantum`` [s]: ``q / √12`` (uniform over one quantum)."""
    return float(quantum) / np.sqrt(12.0)


#: The rounding σ a receivers file may give [s] (``rounding_sigma_s``): none to the coarsest of :data:`QUANTA`'s.
ROUNDING_SIGMA_RANGE = (0.0, rounding_sigma(max(QUANTA)))


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
    tolerance = max(1e-6, 4 * float(np.spacing(np.abs(t).max())))
    head = t[:SCREEN]  # (a quantum the first times refuse is not tried on a season's)
    for q in QUANTA:
        if all((np.abs(part / q - np.round(part / q)) * q <= tolerance).all() for part in (head, t)):
            return q
    return 0.0


def common_quantum(quanta) -> float:
    """[s] the rounding of batches' times together: the coarsest of :data:`QUANTA` dividing each batch's quantum
    (their greatest common divisor: 0.05 s and 0.02 s give 0.01 s), 0 where any is 0 (finer than a millisecond) or
    none is given."""
    ms = [int(round(float(q) * 1000)) for q in quanta]
    if not ms or min(ms) <= 0:
        return 0.0
    common = int(np.gcd.reduce(ms))
    return next(q for q in QUANTA if common % int(round(q * 1000)) == 0)


def resolution_warning(times: np.ndarray | None, travel_time: float, sound_speed: float, what: str,
                       quantum: float | None = None) -> str | None:
    """One line where the times' rounding (:func:`time_quantum`) is not well below the travel time across the array.

    Parameters
    ----------
    times : ndarray, (n,) or None
        Detection times [s] (None: ``quantum`` given).
    travel_time : float
        The largest travel time between two receivers [s] (0 for one receiver: any rounding said).
    sound_speed : float
        [m/s], to state the rounding's error in metres.
    what : str
        The source named in the line (a file).
    quantum : float, optional
        [s] the times' rounding where known already (batches' :func:`time_quantum` together:
        :func:`common_quantum`).

    Returns
    -------
    str or None
        The line, or None where the rounding's standard deviation is below a tenth of ``travel_time``.
    """
    q = time_quantum(times) if quantum is None else float(quantum)
    if q == 0.0:
        return None
    sigma = rounding_sigma(q)
    if sigma < RESOLVABLE * travel_time:
        return None
    where = (f"where the largest travel time across the array is {1000 * travel_time:.3g} ms" if travel_time > 0 else
             "one receiver: no travel time across an array to weigh it against")
    return (f"{what}: every time is a whole multiple of {q:g} s (a rounding error of {1000 * sigma:.3g} ms, "
            f"{sigma * sound_speed:.3g} m of range, {where}): positions from these times are poor whatever the "
            "solver; export the detections with their sub-second times")


class RoundingError(ModelError):
    """Times rounded too coarsely to synchronise clocks from (:func:`check_resolution`): a refusal of the
    synchronisation that a study may take as clocks not synchronised, each tag then saying what that allows."""


def check_resolution(times: np.ndarray, travel_time: float, sound_speed: float, what: str) -> float:
    """Refuse times rounded too coarsely to synchronise clocks from (module docstring): the rounding's σ not below
    :data:`RESOLVABLE` of the largest travel time across the array.

    Parameters
    ----------
    times : ndarray, (n,)
        The sync tags' times of arrival [s] (epoch seconds).
    travel_time : float
        [s] the largest travel time between two receivers (0 for one receiver: no check).
    sound_speed : float
        [m/s], to state the rounding's error in metres.
    what : str
        The source named in the line (the detections file).

    Returns
    -------
    float
        The times' quantum [s] (:func:`time_quantum`; 0 where finer than a millisecond).

    Raises
    ------
    RoundingError
        One line naming ``what``, the rounding (whole seconds, tenths, ...) as the cause, its σ in milliseconds and
        metres against the travel time across the array, and the rounding allowed.
    """
    q = time_quantum(times)
    sigma = rounding_sigma(q)
    if q == 0.0 or travel_time <= 0 or sigma < RESOLVABLE * travel_time:
        return q
    name = QUANTUM_NAMES.get(q, f"multiples of {q:g} s")
    finest = RESOLVABLE * travel_time * np.sqrt(12.0)
    raise RoundingError(f"{what}: every time is a whole multiple of {q:g} s ({name}: a rounding error of "
                     f"{1000 * sigma:.3g} ms, {sigma * sound_speed:.3g} m of range, where sound crosses the array in "
                     f"{1000 * travel_time:.3g} ms): the clocks cannot be synchronised from these times (the "
                     "rounding is the cause, not the receivers' positions); allowed: detections with their sub-second "
                     f"times (rounded to less than {finest:.2g} s on this array)")


def residual_warning(quanta: np.ndarray, residuals: np.ndarray, receivers: list[str], sound_speed: float,
                     what: str) -> str | None:
    """One line where the times' rounding is the larger part of a synchronisation's residuals (module docstring).

    Parameters
    ----------
    quanta : ndarray, (R,)
        [s] each receiver's rounding (:func:`time_quantum` of its times; 0: finer than a millisecond).
    residuals : ndarray, (R,)
        [s] each receiver's residuals' robust scale (NaN: not measured).
    receivers : list of str
        Their names.
    sound_speed : float
        [m/s], to state the rounding in metres.
    what : str
        The source named in the line (the detections file).

    Returns
    -------
    str or None
        The line, naming the rounding (its coarsest among the receivers it limits), the receivers (all, or which),
        the residuals and the noise left without the rounding; None where no receiver's rounding is that large.
    """
    q = np.asarray(quanta, float)
    r = np.asarray(residuals, float)
    sigma = q / np.sqrt(12.0)
    limited = (q > 0) & np.isfinite(r) & (2 * sigma ** 2 >= r ** 2)
    if not limited.any():
        return None
    coarse = float(q[limited].max())
    mine = limited & (q == coarse)
    s = rounding_sigma(coarse)
    rest = float(np.median(np.sqrt(np.maximum(r[mine] ** 2 - s ** 2, 0.0))))
    measured = np.isfinite(r)
    names = [receivers[j] for j in np.flatnonzero(mine)]
    who = ("every receiver's" if mine.sum() == measured.sum() else
           f"{mine.sum()} of {measured.sum()} receivers' ({', '.join(names[:8])}{', ...' if len(names) > 8 else ''})")
    name = QUANTUM_NAMES.get(coarse, f"multiples of {coarse:g} s")
    left = "all of them the rounding's" if rest == 0.0 else f"about {1000 * rest:.2g} ms without the rounding"
    return (f"{what}: {who} times are whole multiples of {coarse:g} s ({name}: a rounding error of {1000 * s:.3g} "
            f"ms, {s * sound_speed:.3g} m of range), the larger part of the synchronisation's residuals there "
            f"(median {1000 * float(np.median(r[mine])):.3g} ms, {left}): the rounding limits the clocks and every "
            "position from them; export the detections with their sub-second times")


__all__ = ["QUANTA", "QUANTUM_NAMES", "RESOLVABLE", "RoundingError", "check_resolution", "common_quantum",
           "resolution_warning", "residual_warning", "rounding_sigma", "time_quantum"]
