"""Raw instrumentation fix: per-step multilateration from the latest ranges and depth.

Weighted Gauss-Newton least squares on
``Σ_i ((r_i − ‖p − b_i‖) / σ_r)² + ((d − p_z) / σ_d)²``, batched over
replicates, with the same casadi range Jacobian as the EKF. The depth term
resolves the mirror ambiguity of a surface array. No filtering and no memory
beyond the starting guess.

References
----------
Foy, "Position-location solutions by Taylor-series estimation", IEEE Trans.
Aerospace and Electronic Systems AES-12(2), 1976.
"""

from __future__ import annotations

import numpy as np

from models.receiver.jacobian import POSITION_INDEX, STATE_SIZE, range_and_jacobian


def multilaterate(ranges: np.ndarray, beacons: np.ndarray, depth: np.ndarray, guess: np.ndarray,
                  sigma_range: float, sigma_depth: float, iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares position from ranges and depth.

    Parameters
    ----------
    ranges : ndarray, shape (B, n)
        Ranges [m]; NaN where missing.
    beacons : ndarray, shape (B, n, 3)
        Beacon positions [m].
    depth : ndarray, shape (B,)
        Depth reading [m].
    guess : ndarray, shape (B, 3)
        Starting point [m].
    sigma_range, sigma_depth : float
        Weights [m]; zero values are floored at 1 mm.

    Returns
    -------
    position : ndarray, shape (B, 3)
        Fix [m]; NaN where fewer than 3 ranges are available.
    valid : ndarray of bool, shape (B,)
    """
    have = np.isfinite(ranges)
    valid = (have.sum(axis=1) >= 3) & np.isfinite(depth)
    w_r = 1.0 / max(sigma_range, 1e-3)
    w_d = 1.0 / max(sigma_depth, 1e-3)
    b = np.where(np.isfinite(beacons), beacons, 0.0)
    r = np.where(have, ranges, 0.0)
    p = np.where(np.isfinite(guess), guess, 0.0).astype(float)
    state = np.zeros((p.shape[0], STATE_SIZE))
    for _ in range(iterations):
        state[:, POSITION_INDEX] = p
        h, H = range_and_jacobian(state, b)
        J = np.where(have[:, :, None], H[:, :, POSITION_INDEX] * w_r, 0.0)
        res = np.where(have, (r - h) * w_r, 0.0)
        J = np.concatenate([J, np.broadcast_to([0.0, 0.0, w_d], (p.shape[0], 1, 3))], axis=1)
        res = np.concatenate([res, ((depth - p[:, 2]) * w_d)[:, None]], axis=1)
        JtJ = np.swapaxes(J, 1, 2) @ J + 1e-9 * np.eye(3)
        p = p + np.linalg.solve(JtJ, np.einsum("bki,bk->bi", J, res)[:, :, None])[:, :, 0]
    return np.where(valid[:, None], p, np.nan), valid
