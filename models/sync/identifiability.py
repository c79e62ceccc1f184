"""Whether the sync tags determine the receivers' positions: the identifiability test of the refinement
(:class:`sblsim.models.sync.clocks.Geometry`).

A receiver's horizontal position refined with the clocks is the survey's (the prior, σ₀ per axis) updated by the
sync tags' arrivals. Its posterior covariance (the fit's information with the prior's, inverted:
:attr:`~sblsim.models.sync.clock_fit.ClockFit.shift_covariance_all`) says how much the arrivals added. Two things are
left out before it is compared with the prior:

* **the gauge**: a translation or a rotation of the whole array changes no distance, so the arrivals never
  determine them and the prior alone fixes them (σ₀/√R per axis for R receivers). They are projected out of both
  covariances (the complement of the array's translations and rotation about its centroid, ``G = I − H(HᵀH)⁻¹Hᵀ``:
  the array's **shape**, what the arrivals can determine), else a small array's positions could never pass and a
  large one's would pass on the gauge alone;
* **the worst direction**: the ratio of a receiver's posterior σ to its prior σ is the square root of the largest
  generalised eigenvalue of its 2 × 2 blocks of ``G P G`` and ``G P₀ G``: a receiver determined along one line
  only (a single sync tag's range) keeps a ratio near 1 across it.

A receiver is **determined** where that ratio is below :data:`MAX_SIGMA_RATIO` both in the fit with every sync tag
and in each fit with one sync tag left out (its worst: :func:`identify`). The second condition is the redundancy a
position needs to be checked and not set by one tag: the leave-one-out of the sync tags compares each tag's fixes
with its receiver's position refined without that tag, so a position only that tag determines cannot be checked,
and one tag's bias (a tag hung off its receiver, its echoes) would move it unseen. It is what a count such as "four
sync tags around the array" says, read from the information matrix instead: three pseudoranges (two coordinates and
the receiver's clock) must remain with any one tag left out, and they must not lie on one line.

Sources: Tapley, Schutz & Born (2004) *Statistical Orbit Determination*, Elsevier, ch. 4.6 (a priori information
in least squares); Baarda (1968) *A testing procedure for use in geodetic networks*, Netherlands Geodetic
Commission (the free network's datum defect, the redundancy an estimate needs to be checked); Koch (1999)
*Parameter Estimation and Hypothesis Testing in Linear Models*, Springer, §3.4 (the free network's S-transformation,
the projector above).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.survey_root import gauge_modes

#: The largest posterior-over-prior σ [1] in a receiver's worst direction at which the arrivals determine its
#: position: a posterior variance at most a quarter of the prior's, i.e. the arrivals' information at least three
#: times the survey's (``1/σ² = 1/σ₀² + I``), so the refined position is at least three quarters the arrivals' and at
#: most a quarter the survey's, and its σ at most half the table's (a refinement that can halve the table's error).
#: On the boats array with its 11 sync tags heard the receivers pass at 0.05–0.4 (one hardly heard at 0.99); with 3
#: of them (every other tag's receiver row cleared) none passes with a tag left out.
MAX_SIGMA_RATIO = 0.5
#: The survey's horizontal σ per axis [m] by default (a handheld GPS's at the surface above a moored receiver), and
#: its allowed range: the prior of the receivers' positions refined (by the sync tags, or a moving tag's pings).
SURVEY_SIGMA = 3.0
SURVEY_SIGMA_RANGE = (0.01, 1000.0)


@dataclass(frozen=True)
class Identifiability:
    """Which receivers' positions the sync tags determine (:func:`identify`).

    Attributes
    ----------
    ratio : numpy.ndarray
        (R,) [1] each receiver's posterior σ of its place in the array's shape over the prior's, in its worst
        direction, in the fit with every sync tag (1 where it has no arrivals).
    ratio_without : numpy.ndarray
        (R,) [1] the largest of those ratios over the fits with one sync tag left out (NaN: no such fit).
    worst : numpy.ndarray
        (R,) int, the left-out tag (its index in ``without``) of ``ratio_without``; -1 where none.
    determined : numpy.ndarray
        (R,) bool, both ratios below ``threshold``.
    threshold : float
    tags : numpy.ndarray or None
        (T,) the caller's labels of the sync tags of ``without`` (``worst`` indexes them), where given.
    """

    ratio: np.ndarray
    ratio_without: np.ndarray
    worst: np.ndarray
    determined: np.ndarray
    threshold: float
    tags: np.ndarray | None = None


def shape_sigma_ratio(xy: np.ndarray, covariance: np.ndarray, sigma: float | np.ndarray,
                      members: np.ndarray, scale: bool = False) -> np.ndarray:
    """Each receiver's posterior σ over its prior σ in the array's shape, worst direction (the module docstring).

    Parameters
    ----------
    xy : numpy.ndarray
        (R, 2) [m] the receivers' table positions (the gauge's rotation is about their centroid).
    covariance : numpy.ndarray
        (2R, 2R) [m²] the shifts' posterior covariance, x then y per receiver.
    sigma : float or numpy.ndarray
        [m] the prior's σ per axis, one or (R,).
    members : numpy.ndarray
        (R,) bool, the receivers in the fit (synchronised); the others' ratio is 1 (nothing added to the prior).
    scale : bool
        The array's scale in the gauge too (where the sound speed is fitted with the positions: no time of arrival
        tells the two apart).

    Returns
    -------
    numpy.ndarray
        (R,) [1].

    Raises
    ------
    ModelError
        ``covariance`` not (2R, 2R).
    """
    xy = np.asarray(xy, float)[:, :2]
    n = len(xy)
    covariance = np.asarray(covariance, float)
    if covariance.shape != (2 * n, 2 * n):
        raise ModelError(f"identifiability: covariance of shape {covariance.shape}; allowed: ({2 * n}, {2 * n}) for "
                         f"{n} receivers")
    ratio = np.ones(n)
    inside = np.flatnonzero(members)
    if len(inside) < 3:  # two receivers' shape is one distance: neither position is determined
        return ratio
    prior_sigma = np.broadcast_to(np.asarray(sigma, float), (n,))[inside]
    index = np.ravel(np.c_[2 * inside, 2 * inside + 1])
    P = covariance[np.ix_(index, index)]
    m = len(inside)
    H = gauge_modes(xy[inside], scale)
    H /= np.maximum(np.linalg.norm(H, axis=0), 1e-300)
    Q, _ = np.linalg.qr(H)
    G = np.eye(2 * m) - Q @ Q.T
    posterior = G @ P @ G
    prior = G @ np.diag(np.repeat(prior_sigma ** 2, 2)) @ G
    for k, j in enumerate(inside):
        b = slice(2 * k, 2 * k + 2)
        try:
            # the generalised eigenvalues of (posterior, prior): those of L⁻¹ P L⁻ᵀ, L the prior's Cholesky factor
            lower = np.linalg.cholesky(prior[b, b])
            worst = np.linalg.eigvalsh(np.linalg.solve(lower, np.linalg.solve(lower, posterior[b, b]).T))[-1]
        except np.linalg.LinAlgError:  # the prior's shape variance singular there (collinear or coincident)
            continue
        ratio[j] = float(np.sqrt(max(worst, 0.0)))
    return ratio


def identify(xy: np.ndarray, covariance: np.ndarray, sigma: float | np.ndarray, members: np.ndarray,
             without: list[np.ndarray | None], threshold: float = MAX_SIGMA_RATIO) -> Identifiability:
    """The identifiability test of the refined positions (the module docstring).

    Parameters
    ----------
    xy, covariance, sigma, members
        As :func:`shape_sigma_ratio`: the fit with every sync tag.
    without : list of numpy.ndarray or None
        Per sync tag, the (2R, 2R) [m²] covariance of the fit with that tag left out (None: not fitted, e.g. the
        clocks cannot be fitted without it: its receivers count as not determined).
    threshold : float
        [1] the largest ratio of a determined receiver, in (0, 1).

    Returns
    -------
    Identifiability

    Raises
    ------
    ModelError
        ``threshold`` outside (0, 1), a covariance of the wrong shape.
    """
    if not 0.0 < threshold < 1.0:
        raise ModelError(f"identifiability: threshold {threshold!r} is outside the allowed range (0, 1)")
    members = np.asarray(members, bool)
    ratio = shape_sigma_ratio(xy, covariance, sigma, members)
    n = len(ratio)
    ratio_without = np.full(n, np.nan)
    worst = np.full(n, -1, np.int64)
    for i, cov in enumerate(without):
        r = np.ones(n) if cov is None else shape_sigma_ratio(xy, cov, sigma, members)
        higher = ~(r <= ratio_without)  # NaN so far, or higher
        ratio_without = np.where(higher, r, ratio_without)
        worst = np.where(higher, i, worst)
    determined = members & (ratio < threshold) & ~(ratio_without >= threshold)
    return Identifiability(ratio, ratio_without, worst, determined, threshold)


__all__ = ["Identifiability", "MAX_SIGMA_RATIO", "SURVEY_SIGMA", "SURVEY_SIGMA_RANGE", "identify", "shape_sigma_ratio"]
