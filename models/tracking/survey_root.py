"""The receivers' position errors as a consider term's square root: one σ per receiver, or a covariance whose
receivers' errors are correlated (positions refined together from one fit).

A consider term of a track (:mod:`~sblsim.models.tracking.filter_consider`,
:mod:`~sblsim.models.tracking.smoother_covariance`, :func:`~sblsim.models.tracking.fix.fix_pings`) follows the
receivers' position errors δr (n dim,), receiver-major (receiver i's axis a at ``i dim + a``), whitened: ``δr = L θ``,
``θ ~ N(0, I)``. Surveyed receivers' errors are independent, ``L = diag(σ_i)`` per axis (each consider module's own
path, a σ per receiver (n,)); positions refined together are not (their errors share the fit's: receivers heard in
the same pings move together), and a σ per receiver drops those correlations. Given as a square root ``L`` (n dim,
p), the same modules take ``δr = L θ`` with p columns.

The refinement's gauge (the array's translation, rotation and, with the sound speed fitted, scale, which no time of
arrival tells) is the survey's, the prior's mean: :func:`frame_conditioned` gives the refined positions' errors in the
survey's frame, the covariance conditioned on the whole array's gauge error being none (a Gaussian's conditional
covariance, ``P − P H (Hᵀ P H)⁻¹ Hᵀ P``). It keeps what the receivers the pings determine share with those they do
not (a receiver no ping heard keeps the survey's σ, and the gauge of the determined ones follows it), which a
projection on the determined receivers' own shape drops.

Sources: Tapley, Schutz & Born, *Statistical Orbit Determination*, Elsevier 2004, § 6.3 (the consider covariance);
Koch, *Parameter Estimation and Hypothesis Testing in Linear Models*, Springer 1999, § 3.4 (the free network's
datum); Rasmussen & Williams, *Gaussian Processes for Machine Learning*, MIT Press 2006, eq. A.6 (a Gaussian
conditioned on a linear function of it).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from sblsim.models.declarations import ModelError

#: Eigenvalues of a covariance below this share of its largest are dropped from its square root (round-off).
RELATIVE_FLOOR = 1e-12


def gauge_modes(xy: np.ndarray, scale: bool = False) -> np.ndarray:
    """The array's gauge (2R, 3 or 4): its translation in x and y, its rotation about the centroid and, with
    ``scale``, its dilation about it, for receivers at ``xy`` (R, 2) [m]; shifts x then y per receiver."""
    xy = np.asarray(xy, float)[:, :2]
    centred = xy - xy.mean(axis=0)
    H = np.zeros((2 * len(xy), 4 if scale else 3))
    H[0::2, 0] = H[1::2, 1] = 1.0
    H[0::2, 2], H[1::2, 2] = -centred[:, 1], centred[:, 0]
    if scale:
        H[0::2, 3], H[1::2, 3] = centred[:, 0], centred[:, 1]
    return H


def frame_conditioned(xy: np.ndarray, covariance: np.ndarray, scale: bool = False) -> np.ndarray:
    """A refinement's posterior covariance of the receivers' shifts (2R, 2R) [m²] conditioned on the whole array's
    gauge error being none (the module docstring): ``P − P H (Hᵀ P H)⁻¹ Hᵀ P``, H :func:`gauge_modes` of the table
    positions ``xy`` (R, 2) [m] (``scale``: the array's scale a gauge too, where the sound speed was fitted).

    Raises
    ------
    ModelError
        ``covariance`` not (2R, 2R), or the gauge's variance singular (fewer than two receivers, or all at one
        place).
    """
    P = np.asarray(covariance, float)
    H = gauge_modes(xy, scale)
    if P.shape != (len(H), len(H)):
        raise ModelError(f"survey frame: covariance of shape {P.shape}; allowed: ({len(H)}, {len(H)}) for "
                         f"{len(H) // 2} receivers")
    PH = P @ H
    try:
        out = P - PH @ np.linalg.solve(H.T @ PH, PH.T)
    except np.linalg.LinAlgError:
        raise ModelError("survey frame: the array's gauge has no variance (fewer than two receivers, or all at one "
                         "place); allowed: receivers at two places or more") from None
    return (out + out.T) / 2.0


def survey_root(sigma: np.ndarray, dim: int, horizontal: np.ndarray | None = None) -> np.ndarray:
    """The square root L (n dim, p) of the receivers' position errors' covariance (the module docstring): each
    receiver's σ (n,) [m] on every axis, independent, and where ``horizontal`` (2n, 2n) [m²] (x then y per receiver)
    is given, its x and y from it instead (a row of it with NaN: that receiver's σ kept); its z (``dim`` 3) the σ.
    ``L Lᵀ`` is the covariance, less eigenvalues below :data:`RELATIVE_FLOOR` of the largest.

    Raises
    ------
    ModelError
        Shapes that do not agree, or a σ negative.
    """
    sigma = np.asarray(sigma, float)
    n = len(sigma)
    if (sigma < 0).any():
        raise ModelError("survey root: a receiver's σ below 0; allowed: 0 or more [m]")
    cov = np.diag(np.repeat(sigma**2, dim))
    if horizontal is not None:
        horizontal = np.asarray(horizontal, float)
        if horizontal.shape != (2 * n, 2 * n):
            raise ModelError(f"survey root: horizontal covariance of shape {horizontal.shape}; allowed: "
                             f"({2 * n}, {2 * n}) for {n} receivers")
        diagonal = np.isfinite(np.diag(horizontal))
        given = diagonal[0::2] & diagonal[1::2]
        index = np.array([i * dim + a for i in np.flatnonzero(given) for a in (0, 1)], int)
        rows = np.ravel(np.c_[2 * np.flatnonzero(given), 2 * np.flatnonzero(given) + 1])
        cov[np.ix_(index, index)] = horizontal[np.ix_(rows, rows)]
    values, vectors = np.linalg.eigh((cov + cov.T) / 2.0)
    keep = values > RELATIVE_FLOOR * max(float(values[-1]), 0.0)
    if not keep.any():
        return np.zeros((n * dim, 1))
    return vectors[:, keep] * np.sqrt(values[keep])


def taken_for(names: Sequence[str], sigma: np.ndarray, dim: int,
              covariance: tuple[Sequence[str], np.ndarray] | None) -> np.ndarray | None:
    """The square root (:func:`survey_root`) of receivers ``names`` (n,) whose σ are ``sigma`` (n,) [m], their
    horizontal errors from ``covariance`` (the names it covers and their (2N, 2N) [m²], x then y per receiver) where
    it names them; None where it is None or names none of them."""
    if covariance is None:
        return None
    covered, matrix = [str(v) for v in covariance[0]], np.asarray(covariance[1], float)
    at = {name: k for k, name in enumerate(covered)}
    found = [at.get(str(name), -1) for name in names]
    if all(k < 0 for k in found):
        return None
    n = len(names)
    horizontal = np.full((2 * n, 2 * n), np.nan)
    mine = np.array([i for i, k in enumerate(found) if k >= 0], int)
    source = np.array([found[i] for i in mine], int)
    ours = np.ravel(np.c_[2 * mine, 2 * mine + 1])
    theirs = np.ravel(np.c_[2 * source, 2 * source + 1])
    horizontal[np.ix_(ours, ours)] = matrix[np.ix_(theirs, theirs)]
    return survey_root(sigma, dim, horizontal)


__all__ = ["RELATIVE_FLOOR", "frame_conditioned", "gauge_modes", "survey_root", "taken_for"]
