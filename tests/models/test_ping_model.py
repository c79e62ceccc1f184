"""``PingModel``: the TOA model evaluated one ping at a time through casadi's buffers gives the casadi function's own
numbers (every bit) and the closed form's, in 2-D and 3-D, for one receiver and several, and each call's arrays are
its own."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.tracking.toa import PingModel, toa_function


@pytest.mark.parametrize("n, dim", [(1, 2), (5, 2), (8, 3)])
def test_the_buffers_give_the_casadi_call_s_numbers_and_the_closed_form(n, dim):
    rng = np.random.default_rng(n + dim)
    receivers = rng.uniform(-300.0, 300.0, (n, dim))
    c = 1483.5
    model = PingModel(receivers, c)
    function = toa_function(n, dim)
    for _ in range(20):
        p, te = rng.uniform(-250.0, 250.0, dim), float(rng.uniform(0.0, 1e5))
        toa, J = model(p, te)
        want_toa, want_J = function(p, te, receivers.T, c)
        assert toa.shape == (n,) and J.shape == (n, dim + 1)
        assert np.array_equal(toa, np.asarray(want_toa).ravel()) and np.array_equal(J, np.asarray(want_J))
        d = p - receivers
        r = np.sqrt((d**2).sum(axis=1))
        assert np.allclose(toa, te + r / c, rtol=0.0, atol=1e-9)
        assert np.allclose(J[:, :dim], d / r[:, None] / c, rtol=1e-12, atol=0.0) and np.all(J[:, dim] == 1.0)


def test_each_call_returns_arrays_of_its_own():
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    model = PingModel(receivers, 1500.0)
    first = model(np.array([10.0, 20.0]), 1.0)
    kept = [a.copy() for a in first]
    model(np.array([-50.0, 70.0]), 9.0)
    assert all(np.array_equal(a, b) for a, b in zip(first, kept))
    receivers[0] = 1e3  # the array the model was made from changed afterwards: the model keeps its own copy
    assert np.array_equal(model(np.array([10.0, 20.0]), 1.0)[0], kept[0])
