"""The normal equations of a refinement of the receivers' positions (models/tracking/refinement_terms.py): the range
biases' knots and each time's bin against ``numpy.interp``; with biases at knots and anchored emissions, the reduced
system's covariance against the inverse of the whole problem built here by finite differences; the selected
inverse's path (a season's knots) against the dense one."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.tracking import refinement_terms
from sblsim.models.tracking.receiver_positions import refine_receivers
from sblsim.models.tracking.refinement_terms import Unknowns

C, SIGMA, SURVEY, DOF = 1480.0, 2e-4, 3.0, 3.0


def test_each_times_bin_and_bias_are_the_knots_interpolated():
    edges = np.array([0.0, 10.0, 30.0])
    layout = Unknowns.of(2, True, edges, free=False)
    times = np.array([-5.0, 0.0, 5.0, 10.0, 20.0, 30.0, 40.0])
    k, f = layout.bins(times, len(times))
    assert k.tolist() == [0, 0, 0, 1, 1, 1, 1] and np.allclose(f, [0, 0, 0.5, 0, 0.5, 1, 1])
    theta = np.zeros(layout.size)
    knots = np.array([[1.0, -2.0], [3.0, 0.5], [-1.0, 4.0]])  # (knot, receiver): time order, an edge's together
    theta[:6] = knots.ravel()
    expected = np.stack([np.interp(times, edges, knots[:, r]) for r in range(2)], axis=1)
    assert np.allclose(layout.bias(theta, k, f), expected)
    assert layout.band == 6 and layout.size == 10 and Unknowns.of(2, True, None, True).size == 7
    assert Unknowns.of(2, False, edges, free=False).size == 4
    with pytest.raises(ModelError, match="edges"):
        Unknowns.of(2, True, np.array([0.0, 0.0, 1.0]), free=False)
    with pytest.raises(ModelError, match="1 not finite"):
        layout.bins(np.array([1.0, np.nan]), 2)


def _problem(rng):
    """Five receivers, a tag's 30 pings over 3000 s and four sync tags' 12 emissions, without noise."""
    receivers = rng.uniform(0.0, 300.0, (5, 2))
    t = np.arange(30) * 100.0 + 7.0
    path = np.c_[150 + 100 * np.sin(t / 700), 150 + 100 * np.cos(t / 900)]
    toa = t[:, None] + np.linalg.norm(path[:, None] - receivers[None], axis=2) / C
    toa[rng.random(toa.shape) < 0.1] = np.nan
    toa[np.isfinite(toa).sum(axis=1) < 4] = np.nan
    source = np.arange(12) % 4
    emitted = np.sort(rng.uniform(0.0, 3000.0, 12))
    sync = emitted[:, None] + np.linalg.norm(receivers[source][:, None] - receivers[None], axis=2) / C
    sync[np.arange(12), source] = np.nan
    return receivers, t, path, toa, source, emitted, sync


def _dense_covariance(receivers, t, path, toa, source, emitted, sync, edges, sigma):
    """The whole problem (pings' x, y, t; emissions' t; biases' knots; shifts) by central finite differences of the
    model, weights 1/σ², the survey's prior on the knots and the shifts: the inverse's blocks of the shifts and
    the knots' variances."""
    rows = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= 4)
    heard = [(j, i) for j in rows for i in range(len(receivers)) if np.isfinite(toa[j, i])]
    arrivals = [(q, i) for q in range(len(sync)) for i in range(len(receivers)) if np.isfinite(sync[q, i])]
    p, e, n, K = len(rows), len(sync), len(receivers), len(edges)
    at = {j: k for k, j in enumerate(rows)}

    def bias(knots, i, time):
        return np.interp(time, edges, knots[:, i])

    def model(theta):
        xy = theta[:2 * p].reshape(p, 2)
        tp = theta[2 * p:3 * p]
        te = theta[3 * p:3 * p + e]
        knots = theta[3 * p + e:3 * p + e + n * K].reshape(K, n)
        d = theta[3 * p + e + n * K:].reshape(n, 2)
        out = [tp[at[j]] + (np.linalg.norm(xy[at[j]] - receivers[i] - d[i]) + bias(knots, i, t[j])) / C
               for j, i in heard]
        out += [te[q] + (np.linalg.norm(receivers[source[q]] + d[source[q]] - receivers[i] - d[i])
                         + bias(knots, i, emitted[q])) / C for q, i in arrivals]
        return np.array(out)

    theta = np.concatenate([path[rows].ravel(), t[rows], emitted, np.zeros(n * K + 2 * n)])
    J = np.empty((len(heard) + len(arrivals), len(theta)))
    for k in range(len(theta)):
        step = np.zeros_like(theta)
        step[k] = 1e-7 if 2 * p <= k < 3 * p + e else 1e-4
        J[:, k] = (model(theta + step) - model(theta - step)) / (2 * step[k])
    normal = J.T @ J / sigma**2
    first = 3 * p + e
    normal[first:, first:] += np.eye(n * K + 2 * n) / SURVEY**2
    whole = np.linalg.inv(normal)
    return whole[first + n * K:, first + n * K:], np.diag(whole)[first:first + n * K].reshape(K, n).T


def test_the_covariance_with_knots_and_sync_tags_is_the_whole_problems():
    """Without noise every residual is 0, where an arrival's Student-t observed information is (ν + 1) / ν times the
    Gaussian's: the shifts' covariance and each knot's variance equal the dense problem's with σ / √((ν + 1) / ν)."""
    rng = np.random.default_rng(8)
    receivers, t, path, toa, source, emitted, sync = _problem(rng)
    edges = np.array([0.0, 1000.0, 2000.0, 3000.0])
    fit = refine_receivers(toa, receivers, path, C, SIGMA, SURVEY, biases=True, anchored=(sync, source, emitted),
                           times=t, edges=edges)
    assert np.abs(fit.fitted).max() < 1e-6 and np.abs(fit.bias).max() < 1e-6 and fit.bias.shape == (5, 4)
    shifts, knots = _dense_covariance(receivers, t, path, toa, source, emitted, sync, edges,
                                      SIGMA / np.sqrt((DOF + 1) / DOF))
    # to the finite differences' precision (1e-5 m² of a 9 m² prior), where the Gaussian σ's differ by a third
    assert np.abs(fit.covariance - shifts).max() < 1e-5 * SURVEY**2, np.abs(fit.covariance - shifts).max()
    assert np.abs(fit.bias_sigma**2 - knots).max() < 1e-5 * SURVEY**2, np.abs(fit.bias_sigma**2 - knots).max()
    gaussian, _ = _dense_covariance(receivers, t, path, toa, source, emitted, sync, edges, SIGMA)
    assert np.abs(fit.covariance - gaussian).max() > 1e-2 * SURVEY**2


def test_a_seasons_knots_by_the_selected_inverse_are_the_dense_solves(monkeypatch):
    """Clocks off by 1 ms σ at each of 11 knots: refined with every solve dense, then with the selected inverse of the
    block-tridiagonal knots (the dense limit set to 0): the same shifts, biases and sigmas."""
    rng = np.random.default_rng(2)
    receivers, t, path, toa, source, emitted, sync = _problem(rng)
    edges = np.linspace(0.0, 3000.0, 11)
    clock = rng.normal(0.0, 1e-3, (len(edges), 5))
    toa = toa + np.stack([np.interp(t, edges, clock[:, i]) for i in range(5)], axis=1)
    sync = sync + np.stack([np.interp(emitted, edges, clock[:, i]) for i in range(5)], axis=1)
    places = path + rng.normal(0.0, 2.0, path.shape)
    table = receivers + rng.normal(0.0, 1.0, receivers.shape)
    args = (toa, table, places, C, SIGMA, SURVEY)
    kwargs = {"biases": True, "anchored": (sync, source, emitted), "times": t, "edges": edges}
    dense = refine_receivers(*args, **kwargs)
    monkeypatch.setattr(refinement_terms, "DENSE_LIMIT", 0)
    banded = refine_receivers(*args, **kwargs)
    assert banded.iterations == dense.iterations and np.abs(dense.fitted).max() > 0.1
    for a, b in ((dense.fitted, banded.fitted), (dense.bias, banded.bias), (dense.covariance, banded.covariance),
                 (dense.bias_sigma, banded.bias_sigma)):
        assert np.allclose(a, b, rtol=1e-7, atol=1e-9)
