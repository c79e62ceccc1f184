"""How well a calibration's unknowns are determined: the condition of its normal matrix, the correlations of the
positions with the other unknowns (a sound-speed scale, the perturbation's bases and gradients), and the refusal of
a solve whose unknowns the survey's geometry cannot separate, or that did not converge.

:func:`determination` computes the diagnostics from the normal matrix :math:`N = A^\\top W A` of the last
Gauss-Newton step and its inverse :math:`Q = N^{-1}`:

- the condition number of :math:`N` equilibrated to a unit diagonal, :math:`\\kappa(D^{-1/2} N D^{-1/2})`,
  :math:`D = \\mathrm{diag}(N)` (the scaling makes it independent of the unknowns' units, metres against seconds;
  Björck 1996, *Numerical Methods for Least Squares Problems*, SIAM, sections 1.4 and 2.6, and van der Sluis's
  theorem that this scaling is within a factor of the number of unknowns of the best diagonal one);
- the correlation :math:`\\rho_{ij} = Q_{ij}/\\sqrt{Q_{ii} Q_{jj}}` of each position unknown with each other unknown
  (the formal correlation of the estimates; SeaGap, Tomita & Kido 2022, and GARPOS, Watanabe et al. 2020, report
  the positions' covariance, of which these are the normalised off-diagonal terms);
- the multiple correlation :math:`R_i^2` of each position unknown with all the other unknowns (those that are not
  positions) together: the share of the position's information that they take,

  .. math:: R_i^2 = 1 - \\frac{(N_{pp} - N_{pr} N_{rr}^{-1} N_{rp})_{ii}}{(N_{pp})_{ii}},

  :math:`p` the positions, :math:`r` the other unknowns (the Schur complement of :math:`N_{rr}`; computed on the
  equilibrated matrix, where the denominator is 1). It is the :math:`R^2` of the weighted regression of the
  position's column of the design on the other unknowns' columns, and :math:`1/(1-R_i^2)` the variance inflation
  factor (VIF) of the position by them (Belsley, Kuh & Welsch 1980, *Regression Diagnostics*, Wiley, chapter 3;
  Björck 1996, section 1.1.5, the Schur complement of a partitioned normal matrix). A degeneracy that several
  unknowns make together shows here where no pairwise correlation is large;
- when a perturbation's gradients are solved, the share of a position's information that they take beyond its
  background (the NTD's or GARPOS's bases): the partial :math:`R^2`,
  :math:`1 - (1 - R_i^2)/(1 - R_{i,b}^2)`, :math:`R_{i,b}^2` the multiple correlation with the background alone
  (the incremental :math:`R^2` of a block of regressors, e.g. Cohen et al. 2003, *Applied Multiple
  Regression/Correlation Analysis*, 3rd ed., section 5.5).

:func:`check_determination` refuses, in one line naming what cannot be separated and which survey would separate
it:

- a normal matrix numerically rank deficient (its equilibrated condition above :data:`MAX_CONDITION`, or a
  non-positive variance on the diagonal of :math:`Q`: a negative variance is never square-rooted);
- a position correlated beyond :data:`MAX_CORRELATION` with a perturbation's or a speed's unknown;
- a position of which the gradients take more than :data:`MAX_GRADIENT_R2` of what the background leaves (the
  multiple correlation with all the others is reported, not judged: a position and the NTD's bases that trade
  one for the other are judged by the pairwise correlation and bounded by the bases a survey determines);
- a solve that did not converge (checked last, so that a cause above is named first:
  :data:`~sblsim.models.calibration.measurement.MAX_ITERATIONS` iterations without a step below
  :data:`~sblsim.models.calibration.measurement.POSITION_TOLERANCE`).

Sources: Belsley, D. A., Kuh, E. & Welsch, R. E. (1980) *Regression Diagnostics*, Wiley; Cohen, J., Cohen, P.,
West, S. G. & Aiken, L. S. (2003) *Applied Multiple Regression/Correlation Analysis*, 3rd ed., Erlbaum;
Björck, Å. (1996) *Numerical Methods for Least Squares Problems*, SIAM; Tomita, F. & Kido, M. (2022)
SeaGap, Zenodo, doi:10.5281/zenodo.6370613; Watanabe, S. et al. (2020) GARPOS, Front. Earth Sci. 8:597532.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError

#: The largest absolute correlation [1] of a position unknown with a perturbation's (or a speed scale's) unknown
#: that a solution keeps. Above it the two trade one for the other within the data's noise (a correlation of
#: 0.9999 inflates a sigma by a factor 71 over the one of a separable survey, :math:`1/\sqrt{1-\rho^2}`), as for a
#: circle at one radius, whose replies at each transponder share a few elevations, so that its Up and a constant
#: nadir delay are one unknown. Every survey of the package's examples and docs stays below it (NCL1's NTD 0.17,
#: SeaGap's example 0.45; the simulated box-in's single circle in a moving ocean 0.99978, whose sigmas still cover
#: its errors).
MAX_CORRELATION = 0.9999
#: The largest condition number [1] of the normal matrix equilibrated to a unit diagonal that a solution keeps:
#: above it the matrix is numerically rank deficient (1e12 leaves 4 significant digits of double precision to the
#: solution's variances, Björck 1996, section 1.4); the package's examples stay below 1e8.
MAX_CONDITION = 1e12
#: The largest share [1] of a position's information that a perturbation's gradients take beyond its background
#: (the partial :math:`R^2`, :func:`determination`) that a solution keeps: above it the gradients inflate the
#: position's variance more than 100 times (its sigma 10 times) over what the background alone leaves. Chosen between
#: the package's surveys (docs/calibration.md, "How well a solve is determined"): SeaGap's example with its deep
#: gradient (77 bases) keeps 0.976 (inflation 42, 2.4 times below), the box-in's figure-eight with a deep gradient
#: 0.83; the box-in with a deep gradient on one circle, whose slant directions turn with the vessel as a horizontal
#: shift's effect does, has 0.998 (inflation 537, 5.4 times above) and is refused. The multiple correlation with all
#: the others is not judged: the NTD's bases alone take 1 - 1e-7 of a position's information in surveys the package
#: keeps (the Up on one circle, the horizontal of a figure-eight with a knot every 15 s).
MAX_GRADIENT_R2 = 0.99


@dataclass(frozen=True)
class Determination:
    """The diagnostics of a solution's normal matrix (:func:`determination`).

    Attributes
    ----------
    condition : float
        The condition number of the normal matrix equilibrated to a unit diagonal [1] (inf: singular).
    max_correlation : float or None
        The largest absolute correlation of a position unknown with another kind of unknown [1] (None: the
        positions are the only unknowns; 1 when the normal matrix is numerically singular, its pair then the
        largest position and other components of the eigenvector of its smallest eigenvalue).
    position : str or None
        The position unknown of ``max_correlation`` (e.g. ``"Up of transponder 2"``, 1-based).
    parameter : str or None
        The other unknown of ``max_correlation`` (e.g. ``"NTD basis 3"``, ``"deep gradient East"``).
    converged : bool
        Whether Gauss-Newton met its tolerance.
    iterations : int
        Its iterations.
    max_r2 : float or None
        The largest multiple correlation :math:`R^2` of a position unknown with all the other unknowns together [1]
        (None: the positions are the only unknowns; 1 when the normal matrix is numerically singular).
    r2_position : str or None
        The position unknown of ``max_r2``.
    r2_group : str or None
        The kinds of the other unknowns, e.g. ``"the deep gradient and the NTD"``.
    gradient_r2 : float or None
        The largest share of a position's information that the gradients take beyond the background [1] (None: no
        gradient solved).
    gradient_position : str or None
        The position unknown of ``gradient_r2``.
    """

    condition: float
    max_correlation: float | None
    position: str | None
    parameter: str | None
    converged: bool
    iterations: int
    max_r2: float | None = None
    r2_position: str | None = None
    r2_group: str | None = None
    gradient_r2: float | None = None
    gradient_position: str | None = None

    @property
    def variance_inflation(self) -> float | None:
        """The variance inflation factor :math:`1/(1-R^2)` of ``max_r2`` [1] (None: no other unknowns or a singular
        matrix)."""
        return _inflation(self.max_r2)

    @property
    def gradient_inflation(self) -> float | None:
        """The variance inflation of ``gradient_r2``, :math:`1/(1-R^2)` [1]: the factor by which the gradients
        multiply the position's variance that the background leaves (None: no gradient)."""
        return _inflation(self.gradient_r2)

    def as_dict(self) -> dict:
        """The keys of ``solution.json``'s ``determination``."""
        return {"condition": self.condition if np.isfinite(self.condition) else None,
                "max_correlation": self.max_correlation, "position": self.position, "parameter": self.parameter,
                "converged": self.converged, "iterations": self.iterations, "multiple_r2": self.max_r2,
                "variance_inflation": self.variance_inflation, "multiple_position": self.r2_position,
                "multiple_group": self.r2_group, "gradient_r2": self.gradient_r2,
                "gradient_inflation": self.gradient_inflation, "gradient_position": self.gradient_position}


def _inflation(r2: float | None) -> float | None:
    return None if r2 is None or r2 >= 1.0 else 1.0 / (1.0 - r2)


def _position_name(i: int, rigid: bool) -> str:
    axis = ("East", "North", "Up")[i % 3]
    return f"{axis} of the array's common shift" if rigid else f"{axis} of transponder {i // 3 + 1}"


def _group(name: str) -> str:
    """The kind of an unknown (``"NTD basis 3"`` -> ``"NTD"``, ``"deep gradient East basis 2"`` ->
    ``"deep gradient"``)."""
    name = re.sub(r" basis \d+$", "", name)
    return re.sub(r" (East|North)$", "", name)


def _join(groups: list[str]) -> str:
    """``"the deep gradient and the NTD"``: the kinds named, the last first (the gradients before the background
    they add to)."""
    named = [f"the {g}" for g in reversed(groups)]
    return named[0] if len(named) == 1 else ", ".join(named[:-1]) + " and " + named[-1]


def multiple_r2(scaled: np.ndarray, q: int, columns: np.ndarray | None = None) -> np.ndarray:
    """The multiple correlation :math:`R_i^2` of each of the first ``q`` unknowns with the others together.

    Parameters
    ----------
    scaled : numpy.ndarray, shape (p, p)
        A normal matrix equilibrated to a unit diagonal, positive definite.
    q : int
        The position unknowns, first.
    columns : numpy.ndarray of int, optional
        The other unknowns to regress on (indices from ``q``; all of them if None).

    Returns
    -------
    numpy.ndarray, shape (q,)
        :math:`R_i^2 = S_{ir} S_{rr}^{-1} S_{ri}` in [0, 1] (1 minus the Schur complement's diagonal).
    """
    rest = np.arange(q, len(scaled)) if columns is None else np.asarray(columns)
    cross = scaled[:q][:, rest]
    with np.errstate(all="ignore"):
        x = np.linalg.solve(scaled[np.ix_(rest, rest)], cross.T)
    return np.clip(np.sum(cross * x.T, axis=1), 0.0, 1.0)


def determination(normal: np.ndarray, q: int, names: list[str], rigid: bool, converged: bool,
                  iterations: int) -> Determination:
    """The condition and the correlations of a normal matrix whose first ``q`` unknowns are positions.

    Parameters
    ----------
    normal : numpy.ndarray, shape (p, p)
        The normal matrix :math:`A^\\top W A` (with a prior, if any) of the last step [units of the unknowns⁻²].
    q : int
        The position unknowns, first (3 per transponder, or 3 for a rigid shift).
    names : list of str
        The names of the other ``p - q`` unknowns.
    rigid : bool
        Whether the positions are one common shift.
    converged, iterations
        Gauss-Newton's end.

    Returns
    -------
    Determination
    """
    d = np.diag(normal)
    if not np.all(np.isfinite(normal)) or np.any(d <= 0.0):
        return Determination(float("inf"), None, None, None, converged, iterations)
    s = 1.0 / np.sqrt(d)
    scaled = normal * s[:, None] * s[None, :]
    with np.errstate(all="ignore"):
        eigen, vectors = np.linalg.eigh(scaled)
    condition = float(eigen[-1] / eigen[0]) if eigen[0] > 0.0 else float("inf")
    if len(normal) == q:
        return Determination(condition, None, None, None, converged, iterations)
    if condition <= MAX_CONDITION:
        inverse = (vectors / eigen) @ vectors.T
        v = np.diag(inverse)
        r = np.abs(inverse[:q, q:] / np.sqrt(np.outer(v[:q], v[q:])))
        i, j = np.unravel_index(int(np.argmax(r)), r.shape)
        r2 = multiple_r2(scaled, q)
        k = int(np.argmax(r2))
        kinds = list(dict.fromkeys(_group(n) for n in names))
        gradient = np.array([m for m, n in enumerate(names) if "gradient" in _group(n)], dtype=int)
        partial, g = None, None
        if 0 < len(gradient) < len(names):  # the share the gradients take of what the background leaves
            background = np.setdiff1d(np.arange(len(names)), gradient)
            left = 1.0 - multiple_r2(scaled, q, q + background)
            with np.errstate(all="ignore"):
                share = np.where(left > 0.0, 1.0 - (1.0 - r2) / left, 0.0)
            share = np.clip(share, 0.0, 1.0)
            g = int(np.argmax(share))
            partial = float(share[g])
        return Determination(condition, float(r[i, j]), _position_name(int(i), rigid), names[int(j)], converged,
                             iterations, float(r2[k]), _position_name(k, rigid), _join(kinds), partial,
                             None if g is None else _position_name(g, rigid))
    # numerically singular: the direction of the smallest eigenvalue is the combination the data do not see;
    # its largest position and other components are what trade one for the other (a correlation of 1)
    null = np.abs(vectors[:, 0])
    i, j = int(np.argmax(null[:q])), int(np.argmax(null[q:]))
    groups = list(dict.fromkeys(_group(names[m]) for m in np.flatnonzero(null[q:] > 1e-3 * null[q:].max())))
    return Determination(condition, 1.0, _position_name(i, rigid), names[j], converged, iterations, 1.0,
                         _position_name(i, rigid), _join(groups))


def check_determination(det: Determination, what: str, separate: str) -> None:
    """Refuse a solution that did not converge, whose normal matrix is numerically rank deficient, or whose position
    is correlated beyond :data:`MAX_CORRELATION` with another unknown.

    Parameters
    ----------
    det : Determination
    what : str
        What the error names (e.g. the segment).
    separate : str
        The survey that would separate the unknowns (e.g. "a second circle radius or a cross track").

    Raises
    ------
    ModelError
        One line naming what cannot be separated and what would separate it.
    """
    pair = det.max_correlation is not None and det.max_correlation > MAX_CORRELATION
    if not det.condition <= MAX_CONDITION:
        which = f"the {det.position} from the {det.parameter}" if pair else "the unknowns"
        raise ModelError(f"{what}: the survey cannot separate {which} (the normal matrix is numerically rank "
                         f"deficient: its equilibrated condition {det.condition:.3g} is above {MAX_CONDITION:g}); "
                         + separate)
    if pair:
        raise ModelError(f"{what}: the survey cannot separate the {det.position} from the {det.parameter} "
                         f"(correlation {det.max_correlation:.6f}, above {MAX_CORRELATION:g}); {separate}")
    if det.gradient_r2 is not None and det.gradient_r2 > MAX_GRADIENT_R2:
        raise ModelError(f"{what}: the survey cannot separate the {det.gradient_position} from {det.r2_group} "
                         f"together (beyond the background the gradients take {det.gradient_r2:.2%} of its "
                         f"information, above {MAX_GRADIENT_R2:.0%}: variance inflation {det.gradient_inflation:.3g}; "
                         f"multiple correlation with all of them R² {det.max_r2:.7f}); " + separate)
    if not det.converged:
        raise ModelError(f"{what}: the solve did not converge in {det.iterations} iterations (no step below "
                         f"the tolerance; largest position correlation {det.max_correlation or 0.0:.4f}); "
                         + separate)

__all__ = ["MAX_CONDITION", "MAX_CORRELATION", "MAX_GRADIENT_R2", "Determination", "check_determination",
           "determination", "multiple_r2"]
