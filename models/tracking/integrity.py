"""The integrity of a single-ping fix: how far one faulty arrival (a reflection, a late multipath arrival) could move
it while its own χ² test still passes, the fix's horizontal **protection level** (receiver autonomous integrity
monitoring, RAIM: Brown & Chin, "GPS RAIM: calculation of threshold and protection radius using chi-square
methods — a geometric approach", *Global Positioning System* vol. V, ION 1998, pp. 155–178; Parkinson & Axelrad,
*Navigation* 35(2), 1988).

A fix solves a ping's ``k`` arrivals for its position and emission time (``p = dim + 1`` unknowns) by weighted
least squares. With the arrivals' normalised design ``H`` (k × p: row ``i`` the time of arrival's gradient,
``((x − r_i) / (c |x − r_i|), 1)``, over its timing noise ``σ_i``), the estimator ``K = (Hᵀ H)⁻¹ Hᵀ`` and the
residual-maker ``S = I − H K``, a bias ``b`` on arrival ``i`` (in its sigmas) moves the horizontal position by
``b |K_xy,i|`` and raises the test statistic (the sum of squared normalised residuals) by ``b² S_ii``. Its
**slope** ``|K_xy,i| / √S_ii`` is the position error per unit of the statistic's root; at the test's threshold
``T`` (χ² with ``k − p`` degrees of freedom at the probability the fix's own test takes) the largest error a single
fault leaves undetected is ``HPL = max_i slope_i √T``. An arrival with no redundancy (``S_ii = 0``: the others
cannot check it) has an infinite slope: a fix of ``dim + 2`` arrivals in a weak geometry can absorb a reflection
by tens of metres with a χ² that passes and a covariance of decimetres. Units: metres [m], seconds [s].
"""

from __future__ import annotations

import numpy as np

#: The probability of the fix's own χ² test (:func:`~sblsim.models.tracking.quality.trusted_fixes`'s).
TEST_PROBABILITY = 0.999


def protection_levels(receivers: np.ndarray, positions: np.ndarray, used: np.ndarray, c: float,
                      sigma_toa: float | np.ndarray, probability: float = TEST_PROBABILITY) -> np.ndarray:
    """Each fix's horizontal protection level against one faulty arrival (module docstring).

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        [m].
    positions : ndarray, (m, dim)
        The fixes [m], NaN where none.
    used : ndarray of bool, (m, n)
        The arrivals each fix kept.
    c : float
        Sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        The arrivals' timing noise [s]: one, or each receiver's.
    probability : float
        The χ² test's probability (its threshold the quantile at ``k − dim − 1`` degrees of freedom).

    Returns
    -------
    ndarray, (m,)
        [m]; NaN where there is no fix, inf where an arrival the fix kept has no redundancy (fewer than
        ``dim + 2`` arrivals, or one the others cannot check).
    """
    from scipy.stats import chi2 as chi2_dist

    r = np.asarray(receivers, float)
    x = np.asarray(positions, float)
    used = np.asarray(used, bool)
    m, n = used.shape
    dim = r.shape[1]
    out = np.full(m, np.nan)
    rows = np.isfinite(x).all(axis=1) & used.any(axis=1)
    if not rows.any():
        return out
    sigma = np.broadcast_to(np.asarray(sigma_toa, float), (n,))
    delta = x[rows, None, :] - r[None]
    d = np.linalg.norm(delta, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        gradient = np.where(d[..., None] > 0, delta / (c * d[..., None]), 0.0)
    H = np.concatenate([gradient, np.ones(gradient.shape[:2] + (1,))], axis=2) / sigma[None, :, None]
    H = np.where(used[rows][..., None], H, 0.0)  # an arrival the fix did not keep: no row
    k = used[rows].sum(axis=1)
    dof = k - (dim + 1)
    normal = np.einsum("mij,mik->mjk", H, H)
    level = np.full(rows.sum(), np.inf)
    solvable = (dof >= 1) & (np.linalg.matrix_rank(normal) == dim + 1)
    if solvable.any():
        K = np.linalg.solve(normal[solvable], np.swapaxes(H[solvable], 1, 2))  # (s, p, n)
        S = 1.0 - np.einsum("mip,mpi->mi", H[solvable], K)  # the residual-maker's diagonal
        horizontal = np.linalg.norm(K[:, :2, :], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.where(used[rows][solvable], horizontal / np.sqrt(np.maximum(S, 0.0)), 0.0)
        slope = np.where(np.isnan(slope), np.inf, slope)
        level[solvable] = slope.max(axis=1) * np.sqrt(chi2_dist.ppf(probability, dof[solvable]))
    out[rows] = level
    return out


__all__ = ["TEST_PROBABILITY", "protection_levels"]
