"""The tag's depth where no reading gives it: whether the array's arrivals determine it, and the prior where not.

Receivers in 3-D determine a tag's depth through the vertical part of each range, ``(z − z_i) / r_i`` times a depth
error: where the tag is among the receivers' heights and far from them compared with their vertical extent
(receivers moored a few metres below the surface of a lake hundreds of metres across, a fish near them), that part is
small, the depth poorly determined, with mirror images about the receivers' heights that the horizontal position
follows (a track that settles on one is metres off, with a covariance of decimetres). Such an array is what
positioning studies without depth sensors solve in the horizontal plane (Lake Hald's authors' model is 2-D:
``data/lake-hald/README.md``). Here the single-ping fixes of four receivers or more decide: where their median
height lies among the receivers' heights (within their median depth σ of the highest and the lowest) and their
median depth σ is above :data:`UNDETERMINED_RATIO` of the receivers' vertical extent, the fixes cannot tell where
among those heights the tag is, and the depth is taken with a prior: one pseudo-reading per ping at the receivers'
mean height, with a σ of the fixes' median depth σ or the receivers' vertical extent, the larger, which the fix and
the robust smoother take as they take a pressure sensor's reading; the depth reported is never more certain than the
prior (:func:`at_least`). Lake Hald with its receivers at 1-5 m depths (a 2-D truth; the fixes' median depth σ
against the extent): 0.67 over the full array, 2.2 over the authors' 8 hydrophones; simulated arrays 200 m across,
1-5 m deep with tags at 2 m: 0.93 (a prior), with tags at 13 m: 0.18 (and below the receivers' heights); 2-20 m
deep: 0.05 (``tests/models/test_tracking_depth.py``, docs/tracking.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError

#: Above this ratio of the fixes' median depth σ to the receivers' vertical extent, the arrivals do not determine the
#: depth among the receivers' heights (mirror images about them within 2 σ of each other).
UNDETERMINED_RATIO = 0.5
#: The fewest fixes of dim + 1 receivers or more the decision takes (fewer: the depth is estimated).
MIN_FIXES = 10


@dataclass(frozen=True)
class DepthPrior:
    """The prior on an undetermined depth: ``depth`` [m] (positive down, the receivers' mean height negated),
    ``sigma`` [m], and the ``ratio`` of the fixes' median depth σ to the receivers' vertical extent it was decided
    on, over ``fixes`` fixes."""

    depth: float
    sigma: float
    ratio: float
    fixes: int


def fixes_depth(fixes: np.ndarray, covariances: np.ndarray, used: np.ndarray) -> tuple[float, float, int]:
    """The median depth σ [m] and the median height [m] of the single-ping fixes of four receivers or more (dim + 1
    in 3-D), and their count.

    Parameters
    ----------
    fixes : ndarray, (m, 3)
        The fixes' positions [m], z up; NaN where a ping has no fix.
    covariances : ndarray, (m, 4, 4)
        Their covariances of ``(x, y, z, t_e)`` [m², m·s, s²].
    used : ndarray, (m,)
        The receivers each fix used.

    Returns
    -------
    sigma, height, count : float, float, int
        NaN and NaN where no fix counts.
    """
    C = np.asarray(covariances, float)
    z = np.asarray(fixes, float)[:, 2]
    with np.errstate(invalid="ignore"):
        good = (np.asarray(used) >= 4) & np.isfinite(C[:, 2, 2]) & (C[:, 2, 2] > 0) & np.isfinite(z)
    if not good.any():
        return np.nan, np.nan, 0
    return float(np.median(np.sqrt(C[good, 2, 2]))), float(np.median(z[good])), int(good.sum())


def depth_prior(fixes: np.ndarray, covariances: np.ndarray, used: np.ndarray,
                receivers: np.ndarray) -> DepthPrior | None:
    """The prior on the tag's depth where the array's arrivals do not determine it (module docstring), else None.

    Parameters
    ----------
    fixes : ndarray, (m, 3)
        The single-ping fixes' positions, made without depth readings [m], z up.
    covariances : ndarray, (m, 4, 4)
        Their covariances [m², m·s, s²].
    used : ndarray, (m,)
        The receivers each fix used.
    receivers : ndarray, (n, 3)
        The receivers' positions [m], z up.

    Returns
    -------
    DepthPrior or None
        None where fewer than :data:`MIN_FIXES` fixes count, their median height lies outside the receivers'
        heights by more than their median depth σ, or that σ is at most :data:`UNDETERMINED_RATIO` of the
        receivers' vertical extent.
    """
    sigma, height, count = fixes_depth(fixes, covariances, used)
    heights = np.asarray(receivers, float)[:, 2]
    extent = float(np.ptp(heights))
    if count < MIN_FIXES or not heights.min() - sigma <= height <= heights.max() + sigma:
        return None
    ratio = sigma / extent if extent > 0 else np.inf
    if not ratio > UNDETERMINED_RATIO:
        return None
    return DepthPrior(depth=float(-heights.mean()), sigma=max(sigma, extent), ratio=ratio, fixes=count)


def at_least(covariances: np.ndarray, sigma: float) -> np.ndarray:
    """The term that raises each covariance's depth variance to at least ``sigma``² (a depth held by a prior is
    known no better than the prior, however many pings' pseudo-readings a smoother combined).

    Parameters
    ----------
    covariances : ndarray, (m, 3, 3)
        Covariances of ``(x, y, z)`` [m²].
    sigma : float
        The prior's σ [m].

    Returns
    -------
    ndarray, (m, 3, 3)
        Zero but at ``[2, 2]``: ``max(sigma² − P_zz, 0)`` (a positive semi-definite addition).
    """
    P = np.asarray(covariances, float)
    term = np.zeros_like(P)
    with np.errstate(invalid="ignore"):
        term[:, 2, 2] = np.where(np.isfinite(P[:, 2, 2]), np.maximum(sigma ** 2 - P[:, 2, 2], 0.0), 0.0)
    return term


def checked_depth(depth: np.ndarray | None, m: int, dim: int) -> np.ndarray | None:
    """The tag's depth per ping as the fix, the calibration and the robust smoother take it: ``depth`` as floats
    (m,) [m], positive down, NaN where none; None where none is given.

    Raises
    ------
    ModelError
        A depth given with receivers in 2-D (``dim`` not 3), or not one per ping (not ``m`` of them).
    """
    if depth is None:
        return None
    depth = np.asarray(depth, float)
    if dim != 3 or depth.shape != (m,):
        raise ModelError(f"depth_m: {depth.shape} readings for {m} pings at receivers in {dim}-D; allowed: one per "
                         "ping (NaN where none), with the receivers' depths (z_m)")
    return depth


__all__ = ["MIN_FIXES", "UNDETERMINED_RATIO", "DepthPrior", "at_least", "checked_depth", "depth_prior",
           "fixes_depth"]
