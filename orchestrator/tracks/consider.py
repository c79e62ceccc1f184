"""The pieces of a track's consider terms (the errors its estimators do not estimate, added to the covariances
reported): each used receiver's survey error, and two terms of a covariance summed where either may be absent.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np


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


__all__ = ["survey_sigmas"]
