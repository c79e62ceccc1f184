"""The ping type a tag's rows show: ``sbi`` (a stable burst interval) where the steps of the rows' first arrivals
lie within the array's crossing time of a whole number of the typical step, else ``rbi`` (a random burst interval);
the ping types of :mod:`sblsim.models.tracking.schedule`. Units: seconds [s].

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017,
doi:10.1038/s41598-017-14278-z (the ping types).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.schedule import first_arrival_steps


@dataclass(frozen=True)
class InferredType:
    """What :func:`infer_ping_type` saw: the type, the typical step Δ [s], the spacing's bounds (2nd and 98th
    percentiles of the single steps) [s] and the residual spread (the 90th percentile of the steps' distance to a
    whole number of Δ) [s]."""

    kind: str
    interval: float
    bounds: tuple[float, float]
    spread: float


def infer_ping_type(toa: np.ndarray, crossing: float) -> InferredType:
    """The ping type the rows' first arrivals show: ``sbi`` when their steps lie within the array's crossing time
    (the first arrival's travel time changes by less) of a whole number of the typical step, else ``rbi``.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    crossing : float
        The array's crossing time [s] (:func:`~sblsim.models.tracking.schedule.crossing_time`).

    Returns
    -------
    InferredType

    Raises
    ------
    ModelError
        As :func:`~sblsim.models.tracking.schedule.first_arrival_steps`, or if no two rows are apart in time.
    """
    d = first_arrival_steps(toa)
    positive = d[d > 0]
    if not len(positive):
        raise ModelError("toa: no two pings are apart in time; allowed: rows of successive pings")
    delta = float(np.median(positive))
    n = np.maximum(np.round(d / delta), 1.0)
    residual = np.abs(d - n * delta)
    spread = float(np.percentile(residual, 90))
    single = d[n == 1]
    bounds = (float(np.percentile(single, 2)), float(np.percentile(single, 98))) if len(single) else (delta, delta)
    kind = "sbi" if spread <= 2.0 * crossing else "rbi"
    return InferredType(kind, delta, bounds, spread)


__all__ = ["InferredType", "infer_ping_type"]
