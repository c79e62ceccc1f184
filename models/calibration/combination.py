"""Segment solutions combined as Xie et al. (2023) combine them (:func:`combine`): a weighted mean per axis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from sblsim.models.calibration.replies import Solution
from sblsim.models.declarations import ModelError


@dataclass(frozen=True)
class Combined:
    """Segment solutions combined (:func:`combine`), per transponder, local ENU [m].

    Attributes
    ----------
    position, sigma : numpy.ndarray, shape (k, 3)
        The weighted mean and its 1-sigma propagated from the segments' covariances (taken as independent) [m].
    scatter : numpy.ndarray, shape (k, 3)
        The weighted standard deviation of the segment solutions about the mean [m] (Xie et al.'s "std"); NaN
        with one segment.
    """

    position: np.ndarray
    sigma: np.ndarray
    scatter: np.ndarray


def combine(solutions: Sequence[Solution]) -> Combined:
    """Combine segment solutions as Xie et al. (2023) do: a weighted mean per axis, weights
    :math:`1/s_k^2` with :math:`s_k` the segment's projected residual RMS (:attr:`Solution.scatter`).

    Parameters
    ----------
    solutions : sequence of Solution
        The segments' solutions of the same transponders (at least one).

    Returns
    -------
    Combined

    Raises
    ------
    ModelError
        No solution.
    """
    if not solutions:
        raise ModelError("segments: no segment to combine")
    x = np.stack([s.position for s in solutions])  # (m, k, 3)
    sd = np.stack([s.sigma for s in solutions])
    w = 1.0 / np.stack([s.scatter for s in solutions]) ** 2
    total = np.sum(w, axis=0)
    mean = np.sum(w * x, axis=0) / total
    sigma = np.sqrt(np.sum(w**2 * sd**2, axis=0)) / total
    m = len(solutions)
    if m > 1:
        scatter = np.sqrt(np.sum(w * (x - mean) ** 2, axis=0) / ((m - 1) * total / m))
    else:
        scatter = np.full_like(mean, np.nan)
    return Combined(mean, sigma, scatter)


__all__ = ["Combined", "combine"]
