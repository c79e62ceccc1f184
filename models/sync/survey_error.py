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

Before the moments, pairs far beyond a robust fit are set aside (a reflection lengthening one pair's path for the
season, which the moments would count as the positions' error): the variance at which the median of the pairs'
projected squares over their variances is χ²(1)'s median, each pair beyond :data:`GROSS` of its variance there set
aside, the rest fitted again, up to :data:`MAX_ROUNDS` times. On simulated arrays (tests/models/test_survey_error.py)
σ holds to a few per cent with up to one pair in ten so lengthened, not with one in five.

The array's translation and rotation change no range, and its scale is the sound speed's: neither is seen, and
neither is counted (their part of ``A`` is in ``M``'s null space or takes no share of ``tr(Aᵀ M A)``). The speed the
synchronisation estimates takes that scale: its relative error from the positions' is ``σ ‖e X⁺ A‖`` (``e`` picking
the distance's coefficient of the least squares ``X β = A δ``: the same pairs, each weighed alike), ``scale_sigma``
per metre of ``σ``, NaN where the pairs do not determine the scale. A reflection
that lengthens many pairs' paths for the whole season is counted as the positions' error: where most paths reflect,
``σ`` is an upper bound of the survey's.

Units: metres [m].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import orth
from scipy.optimize import brentq
from scipy.stats import chi2

#: The fewest arrivals of one sync tag at one receiver whose median residual is a pair.
MIN_PAIR_ARRIVALS = 10
#: A pair whose projected median residual squared passes this many times its variance under the robust fit is set
#: aside before the moments (χ²(1)'s 99.9 % quantile: a reflection lengthening one pair's path, not a position).
GROSS = float(chi2.ppf(0.999, 1))
#: The most rounds of setting gross pairs aside (each round the rest fitted again: a long path's share spread over the
#: pairs it shares a receiver or a tag with shrinks as the longest are set aside).
MAX_ROUNDS = 10
#: The excess over the noise, in standard deviations of the quadratic form without survey error, beyond which a
#: survey error is said to be seen.
Z_SEEN = 3.0


@dataclass(frozen=True)
class SurveyError:
    """The survey error a synchronisation's residuals show: ``sigma`` [m per horizontal axis] (0 where not seen),
    its standard error ``sigma_se`` [m], ``z`` the excess over the noise in standard deviations, ``seen``, ``pairs``,
    ``degrees`` (the pairs kept less what the fit absorbs), the pairs ``set_aside`` as gross, and ``scale_sigma``
    [1/m] the estimated sound speed's relative error per metre of survey error (σ per axis) on the pairs kept (NaN
    where they do not determine it)."""

    sigma: float
    sigma_se: float
    z: float
    seen: bool
    pairs: int
    degrees: int
    set_aside: int
    scale_sigma: float = float("nan")

    def summary(self) -> dict:
        """``sync.json``'s ``survey_error``."""
        def number(x: float) -> float | None:  # (JSON: None where not finite)
            return float(x) if np.isfinite(x) else None

        return {"survey_sigma_m": number(self.sigma), "survey_sigma_se_m": number(self.sigma_se),
                "excess_z": number(self.z), "seen": self.seen, "pairs": self.pairs, "degrees": self.degrees,
                "pairs_set_aside": self.set_aside, "z_seen": Z_SEEN,
                "speed_scale_sigma_per_m": number(self.scale_sigma)}


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
    X = np.zeros((P, R + (tag.max() + 1 if P else 0) + 1))
    X[rows, listener] = 1.0
    X[rows, R + tag] = 1.0
    X[:, -1] = distance
    noise = np.pi / 2.0 * scale**2 / np.maximum(count, 1.0)
    A = A.reshape(P, 2 * R)
    gross = np.zeros(P, bool)
    fit = _moments(median, A, X, noise)
    for _ in range(MAX_ROUNDS):  # the pairs far beyond the robust fit set aside, the rest fitted again
        if fit is None or fit.parts is None:
            break
        far = fit.square > GROSS * (_robust_variance(fit.square, fit.parts, fit.own) * fit.parts + fit.own)
        if not far.any():
            break
        gross[np.flatnonzero(~gross)[far]] = True
        fit = _moments(median[~gross], A[~gross], X[~gross], noise[~gross])
    scale = _scale_sigma(A[~gross], X[~gross])
    if fit is None or fit.parts is None:
        return SurveyError(float("nan"), float("nan"), float("nan"), False, P, 0, int(gross.sum()), scale)
    seen = bool(fit.z >= Z_SEEN)
    sigma = float(np.sqrt(fit.variance)) if seen else 0.0
    se = float(fit.se_variance / (2.0 * np.sqrt(fit.variance))) if fit.variance > 0 else float(
        np.sqrt(fit.se_variance))
    return SurveyError(sigma, se, fit.z, seen, P, fit.degrees, int(gross.sum()), scale)


def _scale_sigma(A: np.ndarray, X: np.ndarray) -> float:
    """The distance's coefficient's standard deviation per unit survey error, ``‖e X⁺ A‖`` [1/m] (the module
    docstring); NaN where the other columns span the distance's (the scale not determined) or there is no pair."""
    if not len(X) or np.linalg.matrix_rank(X) == np.linalg.matrix_rank(X[:, :-1]):
        return float("nan")
    return float(np.linalg.norm((np.linalg.pinv(X) @ A)[-1]))


@dataclass(frozen=True)
class _Moments:
    """One moment fit: σ² (``variance``) and its standard error, the excess's ``z``, the degrees of freedom, and per
    pair its projected median squared, its part of the positions' term and of the noise (None without degrees)."""

    variance: float
    se_variance: float
    z: float
    degrees: int
    square: np.ndarray | None
    parts: np.ndarray | None
    own: np.ndarray | None


def _moments(median: np.ndarray, A: np.ndarray, X: np.ndarray, noise: np.ndarray) -> _Moments | None:
    """The method of moments on these pairs (the module docstring); None where the fit absorbs every pair."""
    Q = orth(X) if len(median) else np.zeros((0, 0))
    degrees = len(median) - Q.shape[1]
    if degrees <= 0:
        return None
    Mm = median - Q @ (Q.T @ median)
    MA = A - Q @ (Q.T @ A)
    signal = float((MA**2).sum())  # tr(Aᵀ M A)
    lever = (Q**2).sum(axis=1)
    QN = Q.T @ (noise[:, None] * Q)
    trace_noise = float(noise.sum() - (noise * lever).sum())  # tr(M N)
    noise_square = float((noise**2).sum() - 2.0 * (noise**2 * lever).sum() + (QN**2).sum())  # tr((M N)²)
    form = float(Mm @ Mm)
    z = (form - trace_noise) / np.sqrt(2.0 * noise_square) if noise_square > 0 else float("inf")
    if signal <= 0:
        return _Moments(float("nan"), float("nan"), float(z), degrees, None, None, None)
    variance = max(form - trace_noise, 0.0) / signal
    AMA = MA.T @ MA
    spread = 2.0 * (variance**2 * float((AMA**2).sum()) + 2.0 * variance * float((noise[:, None] * MA**2).sum())
                    + noise_square)  # Var(mᵀ M m) = 2 tr((M V)²), V = σ² A Aᵀ + N
    own = noise - 2.0 * noise * lever + np.einsum("pi,ij,pj->p", Q, QN, Q)  # (M N M)_pp
    return _Moments(variance, float(np.sqrt(spread) / signal), float(z), degrees, Mm**2, (MA**2).sum(axis=1), own)


def _robust_variance(square: np.ndarray, parts: np.ndarray, own: np.ndarray) -> float:
    """The variance ``v`` [m²] at which the median of ``square / (v parts + own)`` is χ²(1)'s median: each pair's
    projected median residual squared over its variance, robust to the pairs a reflection lengthens (up to half
    of them); 0 where the noise alone explains more than half the pairs. Pairs the fit absorbs whole (no part of
    the positions' error left) say nothing and are left out."""
    keep = parts > 1e-12 * parts.max()
    square, parts, own = square[keep], parts[keep], own[keep]
    half = float(chi2.ppf(0.5, 1))

    def excess(v: float) -> float:  # a pair of no noise at v = 0: infinite where its residual is not 0
        variance = v * parts + own
        ratio = np.divide(square, variance, out=np.where(square > 0, np.inf, 0.0), where=variance > 0)
        return float(np.median(ratio)) - half

    if not len(square) or excess(0.0) <= 0:
        return 0.0
    high = float(np.max(square / parts)) / half + 1e-12
    return float(brentq(excess, 0.0, high, xtol=1e-12 * high, rtol=1e-10))


__all__ = ["MIN_PAIR_ARRIVALS", "SurveyError", "Z_SEEN", "survey_error"]
