"""The identifiability test of the receivers' positions refined with the clocks
(:mod:`sblsim.models.sync.identifiability`): against covariances of a known ratio, and on simulated dense and
sparse sync arrays whose table is off by a known survey error."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.sync.clocks import Geometry, fit_clocks
from sblsim.models.sync.emissions import connected, group_emissions, later_duplicates
from sblsim.models.sync.identifiability import MAX_SIGMA_RATIO, identify, shape_sigma_ratio
from sblsim.models.sync.simulate import simulate_sync


def _gauge(xy: np.ndarray) -> np.ndarray:
    """(2R, 3) an orthonormal basis of the array's translations and rotation about its centroid."""
    c = xy - xy.mean(axis=0)
    H = np.zeros((2 * len(xy), 3))
    H[0::2, 0] = H[1::2, 1] = 1.0
    H[0::2, 2], H[1::2, 2] = -c[:, 1], c[:, 0]
    return np.linalg.qr(H)[0]


def test_the_ratio_of_a_constructed_covariance():
    """A covariance with the gauge at the prior's sigma and the shape at tau has the ratio tau / sigma at every
    receiver (the gauge never counts), the prior alone 1; a receiver not in the fit 1."""
    xy = np.random.default_rng(1).uniform(0, 500, (7, 2))
    Q = _gauge(xy)
    G = np.eye(14) - Q @ Q.T
    sigma, tau = 3.0, 0.6
    P = sigma ** 2 * Q @ Q.T + tau ** 2 * G
    members = np.ones(7, bool)
    np.testing.assert_allclose(shape_sigma_ratio(xy, P, sigma, members), tau / sigma, rtol=1e-9)
    np.testing.assert_allclose(shape_sigma_ratio(xy, sigma ** 2 * np.eye(14), sigma, members), 1.0, rtol=1e-9)
    # one receiver's x known better only: its ratio is its worst direction's (y), still about 1
    Px = sigma ** 2 * np.eye(14)
    Px[0, 0] = 0.01
    assert shape_sigma_ratio(xy, Px, sigma, members)[0] > 0.9
    members[3] = False
    assert shape_sigma_ratio(xy, P, sigma, members)[3] == 1.0
    # the fits without each tag: a receiver determined with all, not with one of them left out, is not determined
    out = identify(xy, P, sigma, np.ones(7, bool), [P, sigma ** 2 * np.eye(14)])
    assert not out.determined.any() and (out.worst == 1).all()
    assert identify(xy, P, sigma, np.ones(7, bool), [P, P]).determined.all()
    with pytest.raises(ModelError, match="covariance of shape"):
        shape_sigma_ratio(xy, P[:4, :4], sigma, members)


@pytest.fixture(scope="module")
def array():
    """12 receivers over 6 h whose table is the truth plus 2 m per axis."""
    sim = simulate_sync(n_receivers=12, hours=6.0, seed=2)
    table = sim.positions + np.random.default_rng(7).normal(0, 2.0, sim.positions.shape)
    return sim, np.floor(sim.time.min()), table


def _refined(sim, origin, table, tags):
    """The fit with the sync tags ``tags`` alone (the others' arrivals dropped) and its identifiability."""
    sel = np.isin(sim.tag, tags)
    rec, tag, t = sim.receiver[sel], sim.tag[sel], sim.time[sel] - origin
    emission = group_emissions(tag, t, np.full(12, 180.0))
    used = ~later_duplicates(emission, rec, t)
    d = np.linalg.norm(table[tag] - table[rec], axis=1)
    s = np.full(len(t), 1 / sim.sound_speed)
    linked = connected(rec[used], emission[used], 12, 0)
    fit = fit_clocks(rec, emission, t, d, s, used, linked, 0, 3600.0, geometry=Geometry(tag, table, 2.0))
    without = []
    for i in tags:
        w = used & (tag != i)
        still = connected(rec[w], emission[w], 12, 0)
        loo = fit_clocks(rec, emission, t, d, s, w, still, 0, 3600.0, keep=fit.kept, scale=fit.scale, sigmas=False,
                         geometry=Geometry(tag, table, 2.0, fit.shift))
        without.append(loo.shift_covariance_all)
    return fit, identify(table, fit.shift_covariance_all, 2.0, linked, without)


def test_a_dense_sync_array_determines_every_receiver(array):
    """A sync tag at each of the 12 receivers: every position determined, the refined positions nearer the truth
    than the table."""
    sim, origin, table = array
    fit, out = _refined(sim, origin, table, list(range(12)))
    assert out.determined.all() and out.ratio.max() < MAX_SIGMA_RATIO
    error = np.linalg.norm(table + fit.shift - sim.positions, axis=1)
    before = np.linalg.norm(table - sim.positions, axis=1)
    assert np.sqrt(np.mean(error ** 2)) < 0.75 * np.sqrt(np.mean(before ** 2))


def test_a_sparse_sync_array_determines_none(array):
    """3 sync tags among the 12 receivers: with one left out two remain, which fix no receiver (3 pseudoranges
    needed: two coordinates and its clock), so none is determined, though the fit with all 3 reads below the
    threshold at some (no redundancy to check them); 4 tags determine some, not all."""
    sim, origin, table = array
    _, sparse = _refined(sim, origin, table, [0, 5, 9])
    assert not sparse.determined.any() and (sparse.ratio < MAX_SIGMA_RATIO).any()
    _, four = _refined(sim, origin, table, [0, 3, 6, 9])
    assert 0 < four.determined.sum() < 12
