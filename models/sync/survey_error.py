"""The receivers' survey error that a synchronisation's residuals show.

The synchronisation fits each receiver's clock and each sync-tag emission's time on the table's positions. Where a
position is off by ``δ_i`` (horizontal), a sync tag's range to another receiver is off by ``u · (δ_k − δ_h)`` at every
emission of the season (``u`` the unit vector from the tag's own receiver ``h`` to the listening receiver ``k``): an
error its noise does not average and the clocks only partly absorb. The median residual of each pair (a sync tag at
one receiver, heard at another) keeps it. With the positions' errors independent, of variance ``σ²`` per axis:

    m = A δ + ε,    E[mᵀ M m] = σ² tr(Aᵀ M A) + tr(M N)

``M = I − X X⁺`` takes out what the fit absorbs (a constant per listening receiver: its clock; per sync tag: its
emissions' times; along the distance: the sound speed), ``N`` the pairs' medians' own variance (``π s² / (2 n)``, a
median's of ``n`` arrivals of robust scale ``s``). ``σ²`` is the quadratic form's excess over its noise, divided by
its expectation per unit variance (the method of moments of variance components: Searle, Casella & McCulloch,
*Variance Components*, Wiley 1992, on the expectations of quadratic forms); its standard error from the form's
variance ``2 tr((M V)²)`` under normal errors, ``V = σ² A Aᵀ + N``. The excess is said to be seen where it passes
:data:`Z_SEEN` standard deviations of the form under no survey error.

The array's translation and rotation change no range, and its scale is the sound speed's: neither is seen, and
neither is counted (their part of ``A`` is in ``M``'s null space or takes no share of ``tr(Aᵀ M A)``). A reflection
that lengthens one pair's path for the whole season is counted as a position's error: where paths reflect, ``σ`` is
an upper bound of the survey's.

Units: metres [m].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import orth

#: The fewest kept arrivals of one sync tag at one receiver whose median residual is a pair.
MIN_PAIR_ARRIVALS = 10
#: The excess over the noise, in standard deviations of the quadratic form without survey error, beyond which a
#: survey error is said to be seen.
Z_SEEN = 3.0


@dataclass(frozen=True)
class SurveyError:
    """The survey error a synchronisation's residuals show: ``sigma`` [m per horizontal axis] (0 where not seen),
    its standard error ``sigma_se`` [m], ``z`` the excess over the noise in standard deviations, ``seen``, ``pairs``
    and ``degrees`` (the pairs less what the fit absorbs)."""

    sigma: float
    sigma_se: float
    z: float
    seen: bool
    pairs: int
    degrees: int

    def summary(self) -> dict:
        """``sync.json``'s ``survey_error``."""
        return {"survey_sigma_m": self.sigma, "survey_sigma_se_m": self.sigma_se, "excess_z": self.z,
                "seen": self.seen, "pairs": self.pairs, "degrees": self.degrees, "z_seen": Z_SEEN}


def survey_error(median: np.ndarray, count: np.ndarray, scale: np.ndarray, listener: np.ndarray, home: np.ndarray,
                 tag: np.ndarray, positions: np.ndarray) -> SurveyError:
    """The survey error of the receivers' positions the pairs' median residuals show (the module docstring).

    Parameters
    ----------
    median : ndarray, (P,)
        Each pair's median residual [m] (a sync tag heard at a receiver not its own).
    count : ndarray, (P,)
        Its arrivals.
    scale : ndarray, (P,)
        Its residuals' robust scale [m] (1.4826 × their median absolute deviation).
    listener, home : ndarray of int, (P,)
        The receiver that heard it and the tag's own receiver (rows of ``positions``).
    tag : ndarray of int, (P,)
        The sync tag.
    positions : ndarray, (R, ≥ 2)
        The receivers' positions as the table gives them [m].

    Returns
    -------
    SurveyError

    Raises
    ------
    ValueError
        Arrays of different lengths, or a pair at no distance.
    """
    median, count, scale = (np.asarray(a, float) for a in (median, count, scale))
    listener, home, tag = (np.asarray(a, int) for a in (listener, home, tag))
    if not len(median) == len(count) == len(scale) == len(listener) == len(home) == len(tag):
        raise ValueError("survey_error: the pairs' arrays differ in length")
    P, R = len(median), len(positions)
    xy = np.asarray(positions, float)[:, :2]
    d = xy[listener] - xy[home]
    distance = np.linalg.norm(d, axis=1)
    if P and not (distance > 0).all():
        raise ValueError("survey_error: a pair at no distance (a tag's own receiver)")
    unit = d / np.maximum(distance, 1e-12)[:, None]
    rows = np.arange(P)
    A = np.zeros((P, R, 2))
    A[rows, listener] += unit
    A[rows, home] -= unit
    A = A.reshape(P, 2 * R)
    X = np.zeros((P, R + (tag.max() + 1 if P else 0) + 1))
    X[rows, listener] = 1.0
    X[rows, R + tag] = 1.0
    X[:, -1] = distance
    Q = orth(X) if P else np.zeros((0, 0))
    degrees = P - Q.shape[1]
    noise = np.pi / 2.0 * scale**2 / np.maximum(count, 1.0)
    if degrees <= 0:
        return SurveyError(float("nan"), float("nan"), float("nan"), False, P, max(degrees, 0))
    Mm = median - Q @ (Q.T @ median)
    MA = A - Q @ (Q.T @ A)
    form = float(Mm @ Mm)
    signal = float((MA**2).sum())  # tr(Aᵀ M A)
    lever = (Q**2).sum(axis=1)
    QN = Q.T @ (noise[:, None] * Q)
    trace_noise = float(noise.sum() - (noise * lever).sum())  # tr(M N)
    noise_square = float((noise**2).sum() - 2.0 * (noise**2 * lever).sum() + (QN**2).sum())  # tr((M N)²)
    z = (form - trace_noise) / np.sqrt(2.0 * noise_square) if noise_square > 0 else float("inf")
    if signal <= 0:
        return SurveyError(float("nan"), float("nan"), float(z), False, P, degrees)
    variance = max(form - trace_noise, 0.0) / signal
    seen = bool(z >= Z_SEEN)
    AMA = MA.T @ MA
    spread = 2.0 * (variance**2 * float((AMA**2).sum()) + 2.0 * variance * float((noise[:, None] * MA**2).sum())
                    + noise_square)  # Var(mᵀ M m) = 2 tr((M V)²), V = σ² A Aᵀ + N
    se_variance = np.sqrt(spread) / signal
    sigma = float(np.sqrt(variance)) if seen else 0.0
    se = float(se_variance / (2.0 * np.sqrt(variance))) if variance > 0 else float(np.sqrt(se_variance))
    return SurveyError(sigma, se, float(z), seen, P, degrees)


__all__ = ["MIN_PAIR_ARRIVALS", "SurveyError", "Z_SEEN", "survey_error"]
