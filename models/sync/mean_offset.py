"""The error of a receiver's clock offset averaged over a record's times: what a still tag's pooled place takes of it.

A synchronised clock is its offsets at the bins' edges, linear between them (:class:`~sblsim.models.sync.clock_fit.
ClockFit`); their errors, each edge's ``σ_k`` and each bin's drift's ``σ_d,k``, are the fit's. A still tag's pooled
place takes each receiver's arrivals' clock error as a bias (:func:`~sblsim.models.tracking.still_tag.
stationary_consider`), but over a record that spans several bins that bias is the offsets' error **averaged over the
record's arrivals**, ``ē = Σ_k a_k e_k`` (``a_k`` the arrivals' mean interpolation weight on edge k), not one edge's:
the edges' errors are estimated from different bins' arrivals and partly average out. Its variance is ``aᵀ C a``.

The edges' covariance C: the variances ``σ_k²``, and between neighbours ``(σ_k² + σ_{k+1}² − (w_k σ_d,k)²) / 2``
(the drift ``(e_{k+1} − e_k) / w_k`` over a bin of width w_k); farther apart, the product of the neighbours'
correlations, as for a Gauss-Markov chain, whose precision is tridiagonal as a clock's edges' are (each bin's
arrivals tie its two edges alone; the emission times shared between receivers tie the receivers, which this leaves
out: the receivers' errors are taken as independent, as each receiver's ``clock_sigma`` is). Rue & Held, *Gaussian
Markov Random Fields*, Chapman & Hall 2005, § 2.3 (a first-order Markov chain's covariance); Tapley, Schutz & Born,
*Statistical Orbit Determination*, Elsevier 2004, § 6.3 (the consider covariance).

Units: seconds [s].
"""

from __future__ import annotations

import numpy as np


def edge_weights(times: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(K + 1,) [1] the mean over ``times`` (n,) [s] of each edge's weight in the linear interpolation between the
    bins' ``edges`` (K + 1,) [s] (a time outside them on the end bin's edge); they sum to 1 (0 where no time)."""
    times, edges = np.asarray(times, float), np.asarray(edges, float)
    width = len(edges) - 1
    if not len(times) or width < 1:
        return np.zeros(len(edges))
    k = np.clip(np.searchsorted(edges, times, side="right") - 1, 0, width - 1)
    f = np.clip((times - edges[k]) / (edges[k + 1] - edges[k]), 0.0, 1.0)
    weights = np.bincount(k, 1.0 - f, minlength=width + 1) + np.bincount(k + 1, f, minlength=width + 1)
    return weights / len(times)


def mean_offset_sigma(knot_sigma: np.ndarray, drift_sigma: np.ndarray, edges: np.ndarray,
                      times: np.ndarray) -> float:
    """σ [s] of a receiver's offset error averaged over its arrivals' ``times`` (n,) [s] (the module docstring), from
    its offsets' σ at the ``edges`` (K + 1,) [s] and its drifts' σ per bin (K,) [s/s]. NaN where an edge the times
    lean on has no σ (NaN: not computed, nothing to average); an edge without one they do not lean on, and a bin
    without a drift σ, tie nothing (correlation 0); no time: 0."""
    a = edge_weights(times, edges)
    used = np.flatnonzero(a > 0)
    if not len(used):
        return 0.0
    if not np.isfinite(np.asarray(knot_sigma, float)[used]).all():
        return float("nan")
    s = np.nan_to_num(np.asarray(knot_sigma, float))
    lo, hi = int(used[0]), int(used[-1]) + 1
    s, a = s[lo:hi], a[lo:hi]
    width = np.diff(np.asarray(edges, float))[lo:hi - 1]
    drift = np.asarray(drift_sigma, float)[lo:hi - 1]
    lag = (s[:-1] ** 2 + s[1:] ** 2 - (width * drift) ** 2) / 2.0
    known = np.isfinite(lag) & (s[:-1] > 0) & (s[1:] > 0)
    rho = np.clip(np.where(known, lag, 0.0) / np.maximum(s[:-1] * s[1:], 1e-300), -1.0, 1.0)
    # the chain e_{k+1} = φ_k e_k + ν_k (φ_k = ρ_k σ_{k+1} / σ_k, Var ν_k = σ_{k+1}² (1 − ρ_k²)): Σ a_k e_k is
    # B_0 e_0 + Σ_k B_{k+1} ν_k with B_k = a_k + φ_k B_{k+1} from the last edge back (linear in the edges)
    phi = np.where(known, rho * s[1:] / np.maximum(s[:-1], 1e-300), 0.0)
    B = np.array(a, float)
    for k in range(len(s) - 2, -1, -1):
        B[k] += phi[k] * B[k + 1]
    variance = (B[0] * s[0]) ** 2 + float(np.sum((B[1:] * s[1:]) ** 2 * (1.0 - rho**2)))
    return float(np.sqrt(max(variance, 0.0)))


__all__ = ["edge_weights", "mean_offset_sigma"]
