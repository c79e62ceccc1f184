"""A clock offset's error averaged over a record's times (sblsim.models.sync.mean_offset): against the exact
covariance of a piecewise-linear clock fitted here by least squares (its edges' precision tridiagonal, so the chain's
correlations are exact), the interpolation weights against their definition, and the edge cases."""

from __future__ import annotations

import numpy as np

from sblsim.models.sync.mean_offset import edge_weights, mean_offset_sigma


def _fitted_clock(rng: np.random.Generator, bins: int = 7):
    """A receiver's offsets at the edges of ``bins`` bins fitted to noisy arrivals (each an offset interpolated
    linearly between its bin's edges, a few per bin, 0.1 ms noise): the edges, the fit's exact covariance (the
    normal matrix inverted), each edge's σ and each bin's drift's σ from it."""
    edges = np.cumsum(np.r_[0.0, rng.uniform(3000.0, 4000.0, bins)])
    times = np.sort(rng.uniform(edges[0], edges[-1], 12 * bins))
    k = np.clip(np.searchsorted(edges, times, side="right") - 1, 0, bins - 1)
    f = (times - edges[k]) / np.diff(edges)[k]
    design = np.zeros((len(times), bins + 1))
    design[np.arange(len(times)), k] = 1.0 - f
    design[np.arange(len(times)), k + 1] = f
    covariance = np.linalg.inv(design.T @ design / 1e-8)
    sigma = np.sqrt(np.diag(covariance))
    step = np.diag(covariance)[:-1] + np.diag(covariance)[1:] - 2.0 * np.diag(covariance, 1)
    return edges, covariance, sigma, np.sqrt(step) / np.diff(edges)


def test_the_averaged_error_is_the_fitted_clocks_own():
    """Three fitted clocks and three records (one bin's times, a few bins', every bin's): the σ of the mean offset
    error over the record's times is ``√(aᵀ C a)`` with C the fit's exact covariance, a the times' mean weights
    (each time's two edges' weights written out here), to 1e-9; and far below one edge's σ over many bins."""
    rng = np.random.default_rng(3)
    for _ in range(3):
        edges, covariance, sigma, drift = _fitted_clock(rng)
        for lo, hi in ((2, 3), (1, 4), (0, 7)):
            times = rng.uniform(edges[lo], edges[hi], 40)
            a = np.zeros(len(edges))
            for t in times:
                k = min(int(np.searchsorted(edges, t, side="right")) - 1, len(edges) - 2)
                f = (t - edges[k]) / (edges[k + 1] - edges[k])
                a[k] += (1.0 - f) / len(times)
                a[k + 1] += f / len(times)
            exact = float(np.sqrt(a @ covariance @ a))
            assert np.isclose(mean_offset_sigma(sigma, drift, edges, times), exact, rtol=1e-9), (lo, hi)
        whole = mean_offset_sigma(sigma, drift, edges, rng.uniform(edges[0], edges[-1], 200))
        assert whole < 0.6 * np.median(sigma), (whole, sigma)


def test_the_weights_and_the_edge_cases():
    """The weights sum to 1 and a time on an edge is all its; a time before the first edge is the first's; no time:
    no weight and a σ of 0; an edge without a σ ties nothing (its neighbours' errors independent), and where the
    times lean on it the σ is not known (NaN: the caller keeps one edge's)."""
    edges = np.array([0.0, 10.0, 30.0])
    assert np.allclose(edge_weights(np.array([10.0]), edges), [0.0, 1.0, 0.0])
    assert np.allclose(edge_weights(np.array([-5.0]), edges), [1.0, 0.0, 0.0])
    assert np.isclose(edge_weights(np.array([2.5, 20.0, 29.0]), edges).sum(), 1.0)
    assert not edge_weights(np.array([]), edges).any()
    assert mean_offset_sigma(np.ones(3), np.ones(2), edges, np.array([])) == 0.0
    # the middle edge without a σ: the two ends independent, each half the weight
    got = mean_offset_sigma(np.array([1.0, np.nan, 1.0]), np.array([0.1, 0.1]), edges, np.array([0.0, 30.0]))
    assert np.isclose(got, np.sqrt(0.5))
    assert np.isnan(mean_offset_sigma(np.array([1.0, np.nan, 1.0]), np.array([0.1, 0.1]), edges, np.array([5.0])))
