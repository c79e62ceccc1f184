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
                  sigma_range, sigma_depth, iterations: int = 8,
                  tolerance: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares position from ranges and depth.

    Each replicate iterates until its own Gauss-Newton step is below
    ``tolerance`` (or ``iterations`` steps); the replicates still moving are
    the only ones evaluated, and a replicate's result does not depend on the
    others of the batch.

    Parameters
    ----------
    ranges : ndarray, shape (B, n)
        Ranges [m]; NaN where missing.
    beacons : ndarray, shape (B, n, 3)
        Beacon positions [m].
    depth : ndarray, shape (B,)
        Depth reading [m].
    guess : ndarray, shape (B, 3)
        Starting point [m] (e.g. the previous fix).
    sigma_range, sigma_depth : float or ndarray, shape (B,)
        Weights [m]; values below 1 mm are floored at 1 mm.
    iterations : int
        Maximum Gauss-Newton steps.
    tolerance : float
        Convergence threshold on the largest coordinate of a step [m].

    Returns
    -------
    position : ndarray, shape (B, 3)
        Fix [m]; NaN where fewer than 3 ranges are available.
    valid : ndarray of bool, shape (B,)
    """
    batch = ranges.shape[0]
    have = np.isfinite(ranges)
    valid = (have.sum(axis=1) >= 3) & np.isfinite(depth)
    w_r = 1.0 / np.maximum(np.broadcast_to(np.asarray(sigma_range, dtype=float), (batch,)), 1e-3)
    w_d = 1.0 / np.maximum(np.broadcast_to(np.asarray(sigma_depth, dtype=float), (batch,)), 1e-3)
    b = np.where(np.isfinite(beacons), beacons, 0.0)
    r = np.where(have, ranges, 0.0)
    p = np.where(np.isfinite(guess), guess, 0.0).astype(float)
    active = np.flatnonzero(valid)
    for _ in range(iterations):
        if active.size == 0:
            break
        pa, ha, wa, da = p[active], have[active], w_r[active, None], w_d[active]
        state = np.zeros((active.size, STATE_SIZE))
        state[:, POSITION_INDEX] = pa
        h, H = range_and_jacobian(state, b[active])
        J = np.where(ha[:, :, None], H[:, :, POSITION_INDEX] * wa[:, :, None], 0.0)
        res = np.where(ha, (r[active] - h) * wa, 0.0)
        depth_row = np.zeros((active.size, 1, 3))
        depth_row[:, 0, 2] = da
        J = np.concatenate([J, depth_row], axis=1)
        res = np.concatenate([res, ((depth[active] - pa[:, 2]) * da)[:, None]], axis=1)
        JtJ = np.swapaxes(J, 1, 2) @ J + 1e-9 * np.eye(3)
        step = np.linalg.solve(JtJ, np.einsum("bki,bk->bi", J, res)[:, :, None])[:, :, 0]
        p[active] = pa + step
        active = active[np.max(np.abs(step), axis=1) > tolerance]
    return np.where(valid[:, None], p, np.nan), valid
