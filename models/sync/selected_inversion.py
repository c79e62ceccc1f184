"""The selected inverse of block-tridiagonal normal equations with a border: the solution and the entries of the
inverse a fit reports (each unknown's variance, its covariance with the next block's), without the dense inverse.

The block form of Takahashi, Fagan & Chin 1973's selected inverse (the RTS smoother's covariance recursion). The
clocks' fit (:func:`sblsim.models.sync.clocks.fit_clocks`) takes it beyond its dense limit, where the knots in time
order make the normal equations block tridiagonal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from sblsim.models.declarations import ModelError


@dataclass
class SelectedCovariance:
    """The entries of the knots' covariance a fit reports: ``variance`` (knots,) [s²] each knot's, ``following``
    (pairs,) [s²] the covariance of each pair asked for (a knot and the next edge's), ``border`` (b, b) the
    unknowns after the knots' (slowness, shifts) among themselves."""

    variance: np.ndarray
    following: np.ndarray
    border: np.ndarray


def selected_inverse(S: sp.spmatrix, n_band: int, order: np.ndarray, rhs: np.ndarray, pairs: np.ndarray | None
                     ) -> tuple[np.ndarray, SelectedCovariance]:
    """Solve ``S x = rhs`` and the entries of ``S⁻¹`` a fit reports, without the dense inverse.

    The first ``n_band`` unknowns (the knots), put in ``order`` (time order), make a block-tridiagonal matrix ``A``
    (its blocks as wide as its bandwidth); the rest (a border ``b``: the slowness, the shifts) couple to all. ``A``
    is factored block by block (``A = Uᵀ diag(Sᵢ) U``, ``U`` unit upper with ``U_{i,i+1} = Xᵢ = Sᵢ⁻¹ A_{i,i+1}``),
    the border by its Schur complement ``G − Cᵀ A⁻¹ C``, and the inverse's diagonal blocks and first off-diagonal
    blocks by the backward recursion ``Σ_{i,i+1} = −Xᵢ Σ_{i+1,i+1}``, ``Σ_{ii} = Sᵢ⁻¹ + Xᵢ Σ_{i+1,i+1} Xᵢᵀ`` (the
    block form of Takahashi, Fagan & Chin 1973's selected inverse; the RTS smoother's covariance recursion), plus
    ``Z Σ_bb Zᵀ`` for the border (``Z = A⁻¹ C``). Cost: blocks × block³ and memory two blocks per block, where the
    dense inverse is unknowns³ and unknowns².

    Parameters
    ----------
    S : scipy.sparse.spmatrix
        (p, p) symmetric positive definite.
    n_band : int
        The banded unknowns (the first ``n_band``).
    order : numpy.ndarray
        (n_band,) int, the banded unknowns in the order that makes ``A`` banded (``order[new] = old``).
    rhs : numpy.ndarray
        (p,) the right-hand side.
    pairs : numpy.ndarray or None
        (P, 2) int, the pairs of banded unknowns (original indices) whose covariance is wanted; each pair within the
        bandwidth in ``order``. None: the solution and the border's covariance only (no backward recursion; the
        variances and pairs' covariances empty).

    Returns
    -------
    (numpy.ndarray, SelectedCovariance)
        The solution (p,) and the selected entries.
    """
    p = S.shape[0]
    perm = np.r_[np.asarray(order, np.int64), np.arange(n_band, p)]
    P = sp.csr_matrix(S)[perm][:, perm].tocsr()
    A = P[:n_band, :n_band].tocoo()
    m = max(int(np.max(np.abs(A.row - A.col), initial=0)), 1)
    A = A.tocsr()
    nb = -(-n_band // m)
    edge = np.minimum(np.arange(nb + 1) * m, n_band)
    blk = [slice(edge[i], edge[i + 1]) for i in range(nb)]
    C = P[:n_band, n_band:].toarray()
    G = P[n_band:, n_band:].toarray()
    r = np.asarray(rhs, float)[perm]
    factors, X = [], []
    Si = A[blk[0], blk[0]].toarray()
    for i in range(nb):
        factor = scipy.linalg.cho_factor(Si, lower=True, check_finite=False)
        factors.append(factor)
        if i + 1 < nb:
            upper = A[blk[i], blk[i + 1]].toarray()
            X.append(scipy.linalg.cho_solve(factor, upper, check_finite=False))
            Si = A[blk[i + 1], blk[i + 1]].toarray() - upper.T @ X[i]

    def solve_band(R: np.ndarray) -> np.ndarray:
        z = [R[b].copy() for b in blk]
        for i in range(nb - 1):
            z[i + 1] -= X[i].T @ z[i]
        out = np.empty_like(R)
        out[blk[-1]] = scipy.linalg.cho_solve(factors[-1], z[-1], check_finite=False)
        for i in range(nb - 2, -1, -1):
            out[blk[i]] = scipy.linalg.cho_solve(factors[i], z[i], check_finite=False) - X[i] @ out[blk[i + 1]]
        return out

    Z = solve_band(C)
    border = np.linalg.inv(G - C.T @ Z) if p > n_band else np.zeros((0, 0))
    ya = solve_band(r[:n_band])
    xb = border @ (r[n_band:] - C.T @ ya)
    x = np.empty(p)
    x[perm] = np.r_[ya - Z @ xb, xb]
    if pairs is None:
        return x, SelectedCovariance(np.zeros(0), np.zeros(0), border)
    # the selected inverse: where each original knot sits, and each pair's blocks
    where = np.empty(n_band, np.int64)
    where[perm[:n_band]] = np.arange(n_band)
    a, b = where[pairs[:, 0]], where[pairs[:, 1]]
    a, b = np.minimum(a, b), np.maximum(a, b)
    if np.any(b // m - a // m > 1):
        raise ModelError("sync: a covariance asked for outside the normal equations' band")
    variance = np.empty(n_band)
    following = np.empty(len(pairs))
    by_block = np.argsort(a // m, kind="stable")
    starts = np.searchsorted(a[by_block] // m, np.arange(nb + 1))
    sigma_next = None
    for i in range(nb - 1, -1, -1):
        inverse = scipy.linalg.cho_solve(factors[i], np.eye(edge[i + 1] - edge[i]), check_finite=False)
        if i + 1 < nb:
            M = X[i] @ sigma_next
            sigma_ii = inverse + M @ X[i].T
            sigma_up = -M  # Σ_{i,i+1}
        else:
            sigma_ii, sigma_up = inverse, None
        variance[blk[i]] = np.diag(sigma_ii)
        mine = by_block[starts[i]:starts[i + 1]]
        same = b[mine] // m == i
        following[mine[same]] = sigma_ii[a[mine[same]] - edge[i], b[mine[same]] - edge[i]]
        if (~same).any():
            following[mine[~same]] = sigma_up[a[mine[~same]] - edge[i], b[mine[~same]] - edge[i + 1]]
        sigma_next = sigma_ii
    if p > n_band:  # the border's share: Z Σ_bb Zᵀ
        ZS = Z @ border
        variance += np.einsum("ij,ij->i", ZS, Z)
        following += np.einsum("ij,ij->i", ZS[a], Z[b])
    back = np.empty(n_band)
    back[perm[:n_band]] = variance
    return x, SelectedCovariance(back, following, border)


__all__ = ["SelectedCovariance", "selected_inverse"]
