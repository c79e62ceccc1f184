"""The pieces of a track's consider terms (the errors its estimators do not estimate, added to the covariances
reported): each used receiver's survey error, and two terms of a covariance summed where either may be absent.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from sblsim.models.tracking.survey_root import taken_for


def _plus(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """Two terms of a reported covariance summed, either None (absent)."""
    return b if a is None else a if b is None else a + b


def survey_sigmas(receivers, names: Sequence[str], one: float | None) -> np.ndarray | None:
    """Each used receiver's survey error [m] (len(names),): its ``sigma_m`` in the receivers file, else ``one``
    (one value for the receivers without), else 0; None where none is given (the positions taken as exact)."""
    given = np.full(len(names), np.nan) if receivers.sigma is None else \
        receivers.sigma[[receivers.names.index(n) for n in names]]
    if one is not None:
        given = np.where(np.isfinite(given), given, one)
    return None if not np.isfinite(given).any() else np.nan_to_num(given)


def survey_considered(survey: np.ndarray | None, names: Sequence[str], dim: int,
                      covariance: tuple[Sequence[str], np.ndarray] | None) -> np.ndarray | None:
    """What the consider terms take of the used receivers' (``names``) survey errors: their σ ``survey`` (n,) [m], or
    where ``covariance`` (names and their horizontal covariance (2N, 2N) [m²]: positions refined together) covers any,
    the square root of their errors' covariance (n dim, p) [m]
    (:func:`~sblsim.models.tracking.survey_root.taken_for`)."""
    if covariance is None:
        return survey
    root = taken_for(names, np.zeros(len(names)) if survey is None else survey, dim, covariance)
    return survey if root is None else root


__all__ = ["survey_considered", "survey_sigmas"]
