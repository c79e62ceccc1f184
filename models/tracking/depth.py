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

Receivers **in one plane** (:func:`in_plane`: their heights span less than :data:`PLANAR_SHARE` of their horizontal
aperture, e.g. moored 1.1-1.8 m deep in a bay hundreds of metres across) do not determine the depth whatever the fixes
say: a fix's depth there trades against the sound speed (a range ``√(h² + Δz²)`` lengthened by a depth as by a speed
too slow), so the fixes and the calibration find a depth the water does not have and a speed it cannot have. The depth
is then held at a default (:func:`plane_prior`): the middle of the water column where its depth is known, with the
σ of a uniform over it, else the receivers' mean depth with their span as σ (the tag taken in the receivers' plane,
as a 2-D solver takes it). A **water depth** bounds the depth of any array (:func:`water_column`): the uniform over
``[0, water_depth]`` as a Gaussian of its mean and σ (moment matched), a pseudo-reading per ping as the fix and the
robust smoother take a sensor's (a soft bound: both solve least squares, in which a Gaussian term is one more row).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sblsim.models.declarations import ModelError

#: Above this ratio of the fixes' median depth σ to the receivers' vertical extent, the arrivals do not determine the
#: depth among the receivers' heights (mirror images about them within 2 σ of each other).
UNDETERMINED_RATIO = 0.5
#: The fewest fixes of dim + 1 receivers or more the decision takes (fewer: the depth is estimated).
MIN_FIXES = 10
#: How many of the fixes' median depth σ (and a given depth's σ) widen the band of depths their 5th to 95th
#: percentiles span before a depth given outside it is refused (:func:`check_given_depth`).
DEPTH_WIDEN = 1.0
#: Receivers whose heights span less than this share of their horizontal aperture (the largest horizontal distance
#: between two of them) lie in one plane: for a tag among them the depth's σ is about 0.4 / share times a range's
#: (the fixes' Jacobian on the arrays of tests/models/test_tracking_depth.py: 25 at a share of 0.016, 6 at 0.072), 8
#: times at this share; and the depth trades against the sound speed.
PLANAR_SHARE = 0.05
#: The bases of a prior (:class:`DepthPrior`): the fixes' depth σ, the receivers in one plane, the water column.
BASES = ("fixes", "plane", "water column")


@dataclass(frozen=True)
class DepthPrior:
    """The prior on an undetermined depth: ``depth`` [m] (positive down, the receivers' mean height negated),
    ``sigma`` [m], and the ``ratio`` of the fixes' median depth σ to the receivers' vertical extent it was decided
    on, over ``fixes`` fixes (NaN and 0 where the fixes did not decide); its ``basis`` (:data:`BASES`), and whether
    the depth reported is known no better than it (``floor``: :func:`at_least`; not where the prior only bounds a
    depth the arrivals determine)."""

    depth: float
    sigma: float
    ratio: float
    fixes: int
    basis: str = "fixes"
    floor: bool = True


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


def plane_span(receivers: np.ndarray) -> tuple[float, float]:
    """The receivers' heights' span and their horizontal aperture (the largest horizontal distance between two) [m].

    Parameters
    ----------
    receivers : ndarray, (n, 3)
        The receivers' positions [m], z up.
    """
    r = np.asarray(receivers, float)
    flat = r[:, :2]
    aperture = float(np.sqrt(((flat[:, None, :] - flat[None, :, :]) ** 2).sum(axis=2).max())) if len(r) else 0.0
    return float(np.ptp(r[:, 2])) if len(r) else 0.0, aperture


def in_plane(receivers: np.ndarray) -> bool:
    """Whether receivers in 3-D lie in one plane (their heights' span below :data:`PLANAR_SHARE` of their horizontal
    aperture, :func:`plane_span`): the depth of a tag among them is not determined by its arrivals."""
    receivers = np.asarray(receivers, float)
    if receivers.ndim != 2 or receivers.shape[1] != 3 or len(receivers) < 2:
        return False
    span, aperture = plane_span(receivers)
    return aperture > 0 and span < PLANAR_SHARE * aperture


def water_column(water_depth: float) -> tuple[float, float]:
    """The uniform over a water column ``[0, water_depth]`` [m] as a Gaussian: its mean and σ (``D / 2``,
    ``D / √12``) [m]."""
    return 0.5 * float(water_depth), float(water_depth) / np.sqrt(12.0)


def plane_prior(receivers: np.ndarray, water_depth: float | None = None, sigma: float = 0.0) -> DepthPrior | None:
    """The depth held for a tag among receivers in one plane (:func:`in_plane`; module docstring), else None: the
    middle of the water column with the σ of a uniform over it (:func:`water_column`) where ``water_depth`` [m] is
    given, else the receivers' mean depth with their heights' span, or ``sigma`` [m] (a depth reading's) if larger,
    as its σ.

    Parameters
    ----------
    receivers : ndarray, (n, 3)
        The receivers' positions [m], z up.
    water_depth : float, optional
        The water's depth [m], positive down.
    sigma : float
        The least σ of the receivers' depth taken as the tag's [m].
    """
    if not in_plane(receivers):
        return None
    heights = np.asarray(receivers, float)[:, 2]
    if water_depth is not None:
        depth, spread = water_column(water_depth)
    else:
        depth, spread = float(-heights.mean()), max(float(np.ptp(heights)), float(sigma))
    return DepthPrior(depth=depth, sigma=spread, ratio=np.nan, fixes=0, basis="plane")


def bounded_prior(prior: DepthPrior | None, water_depth: float | None, fixes: int = 0) -> DepthPrior | None:
    """A prior bounded by the water column ``[0, water_depth]`` [m] (:func:`water_column`): where none was taken (the
    arrivals determine the depth), the column's, which bounds it without flooring the depth reported; where one was
    and the column's σ is the smaller, the column's (floored as the prior was); else the prior, its depth within the
    column.

    Parameters
    ----------
    prior : DepthPrior or None
        The prior taken without the water depth (:func:`depth_prior`, :func:`plane_prior`).
    water_depth : float, optional
        [m], positive down.
    fixes : int
        The fixes the decision took (kept in a column prior that replaces none).

    Returns
    -------
    DepthPrior or None
        ``prior`` as it is without a water depth.
    """
    if water_depth is None:
        return prior
    depth, sigma = water_column(water_depth)
    if prior is None:
        return DepthPrior(depth=depth, sigma=sigma, ratio=np.nan, fixes=fixes, basis="water column", floor=False)
    if sigma < prior.sigma:
        return DepthPrior(depth=depth, sigma=sigma, ratio=prior.ratio, fixes=prior.fixes, basis="water column",
                          floor=prior.floor)
    return replace(prior, depth=float(np.clip(prior.depth, 0.0, water_depth)))


def check_given_depth(given: float, sigma: float, fixes: np.ndarray, covariances: np.ndarray, used: np.ndarray,
                      receivers: np.ndarray, where: str = "tag_depth") -> None:
    """Refuse one depth given for a tag that its arrivals place elsewhere.

    The single-ping fixes made with the depth free (four receivers or more, as :func:`fixes_depth` takes them) show
    where the tag was: the depths between their 5th and 95th percentiles (their own noise and the tag's motion in
    depth), widened by :data:`DEPTH_WIDEN` times their median depth σ and the given depth's ``sigma`` combined, and
    the same band mirrored about the receivers' mean height (where the receivers lie near one plane a range cannot
    tell above from below it). A given depth outside both bands is one the arrivals refute; with fewer than
    :data:`MIN_FIXES` fixes nothing is checked.

    Parameters
    ----------
    given : float
        [m] the depth given, positive down.
    sigma : float
        [m] its standard deviation (the tracker's depth σ).
    fixes : ndarray, (m, 3)
        The single-ping fixes made without a depth [m], z up; NaN where a ping has no fix.
    covariances : ndarray, (m, 4, 4)
        Their covariances [m², m·s, s²].
    used : ndarray, (m,)
        The receivers each fix used.
    receivers : ndarray, (n, 3)
        The receivers' positions [m], z up.
    where : str
        How the caller names the given depth (the message's first word).

    Raises
    ------
    ModelError
        One line naming ``where``, the depth given, the depths the arrivals show and the depths allowed.
    """
    C = np.asarray(covariances, float)
    z = np.asarray(fixes, float)[:, 2]
    with np.errstate(invalid="ignore"):
        good = (np.asarray(used) >= 4) & np.isfinite(C[:, 2, 2]) & (C[:, 2, 2] > 0) & np.isfinite(z)
    if good.sum() < MIN_FIXES:
        return
    low, high = np.percentile(z[good], [5, 95])
    wide = DEPTH_WIDEN * float(np.hypot(np.median(np.sqrt(C[good, 2, 2])), sigma))
    height = -float(given)
    mean = float(np.mean(np.asarray(receivers, float)[:, 2]))
    if low - wide <= height <= high + wide or 2 * mean - high - wide <= height <= 2 * mean - low + wide:
        return
    raise ModelError(f"{where}: {given:g} m given, but the arrivals with the depth free put the tag at {-high:.3g} to "
                     f"{-low:.3g} m (5th to 95th percentile of {int(good.sum())} single-ping fixes, median "
                     f"{-float(np.median(z[good])):.3g} m); allowed: a depth within {-high - wide:.3g} to "
                     f"{-low + wide:.3g} m, or none (the depth estimated with the position)")


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


__all__ = ["BASES", "MIN_FIXES", "PLANAR_SHARE", "UNDETERMINED_RATIO", "DepthPrior", "at_least", "bounded_prior",
           "checked_depth", "depth_prior", "fixes_depth", "in_plane", "plane_prior", "plane_span", "water_column"]
