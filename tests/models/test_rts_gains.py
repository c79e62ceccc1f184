"""The RTS smoother's gains solved for every row at once are the gains solved one row at a time, to the last bit
(the smoother's and its sensitivity's records depend on it), and a record of one row or none has none."""

from __future__ import annotations

import numpy as np

from sblsim.models.tracking.ekf import rts_gains


def test_the_gains_at_once_are_the_gains_one_at_a_time():
    rng = np.random.default_rng(7)
    m, s = 300, 6
    A = rng.normal(size=(m, s, s))
    P_filtered = A @ np.swapaxes(A, 1, 2) + 1e-3 * np.eye(s)
    B = rng.normal(size=(m, s, s))
    P_predicted = B @ np.swapaxes(B, 1, 2) + np.eye(s)
    F = np.eye(s) + 0.1 * rng.normal(size=(m, s, s))
    gains = rts_gains(P_filtered, P_predicted, F)
    assert gains.shape == (m - 1, s, s)
    for k in range(m - 1):
        one = np.linalg.solve(P_predicted[k + 1], F[k + 1] @ P_filtered[k]).T
        assert np.array_equal(gains[k], one)
        # and the definition, C P_{k+1|k} = P_k|k F_{k+1}ᵀ
        assert np.allclose(gains[k] @ P_predicted[k + 1], P_filtered[k] @ F[k + 1].T, rtol=1e-9, atol=1e-9)
    assert rts_gains(P_filtered[:1], P_predicted[:1], F[:1]).shape == (0, s, s)
    assert rts_gains(P_filtered[:0], P_predicted[:0], F[:0]).shape == (0, s, s)
