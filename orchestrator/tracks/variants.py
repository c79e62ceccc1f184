"""A recorded TOA matrix changed the way real studies differ: other ping intervals, gaps, thinner arrays.

One recording is one sample. To see whether a tracker holds beyond it, the same pings are kept or removed so that
the matrix looks as another study's would (docs/tracking.md, "Beyond one recording"):

* :func:`random_interval_pings`: the pings kept so that successive kept pings are a random burst interval
  ``U(low, high)`` apart (a fish tag's random delay, as Innovasea/Vemco, Thelma Biotel and Lotek tags transmit),
  chosen by their first arrivals;
* :func:`cut_gap`: the pings whose first arrival falls in a window removed (rows absent, as a matrix built from
  detections has them when the tag is out of range);
* :func:`write_toa`: a matrix written in the replay's format (``NA`` where not heard, a header of receiver names).

Every draw is seeded (``numpy.random.default_rng(seed)``); a variant is a function of the recording, its arguments
and the seed alone.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.schedule import first_arrivals


def random_interval_pings(toa: np.ndarray, low: float, high: float, seed: int) -> np.ndarray:
    """The rows of ``toa`` (m, n) [s] kept so that successive kept pings are ``U(low, high)`` seconds apart.

    From the first heard ping, the next target time is the last kept ping's first arrival plus a draw of
    ``U(low, high)``; the heard ping whose first arrival is nearest to it is kept (never the same ping twice).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    low, high : float
        The random burst interval's bounds [s], 0 < low ≤ high.
    seed : int
        Of ``numpy.random.default_rng``.

    Returns
    -------
    ndarray of int
        The rows kept, increasing.

    Raises
    ------
    ModelError
        Bounds out of order or not positive.
    """
    if not 0 < low <= high:
        raise ModelError(f"burst interval: [{low}, {high}] s; allowed: 0 < min <= max")
    first = first_arrivals(toa)
    rows = np.flatnonzero(np.isfinite(first))
    if not len(rows):
        return rows
    times = first[rows]
    rng = np.random.default_rng(seed)
    kept = [0]
    while True:
        target = times[kept[-1]] + rng.uniform(low, high)
        j = int(np.searchsorted(times, target))
        if j >= len(times):
            break
        if j > 0 and abs(times[j - 1] - target) < abs(times[j] - target) and j - 1 > kept[-1]:
            j -= 1
        kept.append(j)
    return rows[np.array(kept)]


def cut_gap(toa: np.ndarray, start: float, duration: float) -> np.ndarray:
    """The rows of ``toa`` (m, n) [s] whose first arrival is outside ``[start, start + duration)`` [s] (a ping nobody
    heard is kept): the rows left when the tag is out of range for ``duration`` seconds."""
    first = first_arrivals(toa)
    inside = (first >= start) & (first < start + duration)
    return np.flatnonzero(~inside)


def write_toa(path: str | Path, toa: np.ndarray, names: Sequence[str]) -> None:
    """Write a TOA matrix (m, n) [s] in the replay's format: a header of the receivers' names, one row per ping,
    ``NA`` where not heard, times to the nanosecond."""
    import pandas as pd

    frame = pd.DataFrame(np.asarray(toa, float), columns=list(names))
    frame.to_csv(path, sep=" ", na_rep="NA", index=False, float_format="%.9f")


__all__ = ["cut_gap", "random_interval_pings", "write_toa"]
