"""Raw instrumentation fix: per-step multilateration from the latest ranges and depth.

Weighted least squares (Levenberg-Marquardt) on
``Σ_i ((r_i − ‖p − b_i‖) / σ_r)² + ((d − p_z) / σ_d)²``, batched over
replicates, with the casadi-derived range Jacobian (position part). The depth term
resolves the mirror ambiguity of a surface array. No filtering and no memory
beyond the starting guess.

References
----------
Foy, "Position-location solutions by Taylor-series estimation", IEEE Trans.
Aerospace and Electronic Systems AES-12(2), 1976.
"""

from __future__ import annotations

import numpy as np

from models.receiver.jacobian import position_range_numpy


def multilaterate(ranges: np.ndarray, beacons: np.ndarray, depth: np.ndarray, guess: np.ndarray,
                  sigma_range, sigma_depth, iterations: int = 8,
                  tolerance: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares position from ranges and depth (Levenberg-Marquardt).

    Minimizes ``F(p) = Σ_i w_r (r_i − h_i(p))² + w_d (d − p_z)²`` with
    ``h_i = ‖p − b_i‖`` and its casadi-derived gradient ``J_i = ∇h_i``. Each
    iteration solves the damped normal equations
    ``(JᵀWJ + μ diag(JᵀWJ)) δ = JᵀW res`` and keeps the step only if it
    lowers F (μ ÷ 10), else raises μ × 10, so a fix never runs away when the
    geometry is poor (short baseline, large range noise). The start is the
    guess or the closed-form :func:`linear_fix`, whichever fits better. A
    replicate stops when its step is statistically negligible,
    ``δᵀ JᵀWJ δ ≤ tolerance²`` (below ``tolerance`` standard deviations of
    the fix in every direction), or after ``iterations``. Only the replicates
    still moving are evaluated, and a replicate's result does not depend on
    the others of the batch.

    With a short baseline and noisy ranges the cost has a ring-shaped valley
    around the array and the least-squares fix is poorly determined; the
    iteration cap then leaves the fix part-way along the valley. That fix is
    poor either way (the instrumentation is the unfiltered reference the EKF
    is compared with), and the cap keeps its cost bounded.

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
        Weights ``w = 1/σ²`` [m]; values below 1 mm are floored at 1 mm.
    iterations : int
        Maximum number of steps tried.
    tolerance : float
        Convergence threshold on a step, in standard deviations of the fix [1].

    Returns
    -------
    position : ndarray, shape (B, 3)
        Fix [m]; NaN where fewer than 3 ranges are available.
    valid : ndarray of bool, shape (B,)

    References
    ----------
    Marquardt, "An algorithm for least-squares estimation of nonlinear
    parameters", J. SIAM 11(2), 1963. Foy (1976), see the module.
    """
    batch = ranges.shape[0]
    have = np.isfinite(ranges)
    valid = (have.sum(axis=1) >= 3) & np.isfinite(depth)
    w_r = 1.0 / np.maximum(np.broadcast_to(np.asarray(sigma_range, dtype=float), (batch,)), 1e-3) ** 2
    w_d = 1.0 / np.maximum(np.broadcast_to(np.asarray(sigma_depth, dtype=float), (batch,)), 1e-3) ** 2
    weights = np.where(have, w_r[:, None], 0.0)  # (B, n): 1/σ_r² for the ranges available
    b = np.moveaxis(np.where(np.isfinite(beacons), beacons, 0.0), -1, 0)  # (3, B, n), components first
    r = np.where(have, ranges, 0.0)
    d = np.where(np.isfinite(depth), depth, 0.0)
    p = np.where(np.isfinite(guess), guess, 0.0).T.astype(float)  # (3, B)
    model = position_range_numpy()

    def evaluate(points, rows):
        """Normal matrix JᵀWJ (k, 3, 3), gradient JᵀW res (k, 3) and cost (k,) at ``points`` (3, k)."""
        (h,), J = model(points[:, :, None], b[:, rows])  # (k, n), (3, k, n)
        # a missing beacon sits at the origin: its gradient is 0/0 at a point there, so mask it
        J = np.where(have[rows][:, None, :], np.moveaxis(J, 0, 1), 0.0)  # (k, 3, n)
        w = weights[rows]
        res = r[rows] - h
        dres = d[rows] - points[2]
        wJ = w[:, None, :] * J
        A = wJ @ np.swapaxes(J, 1, 2)
        A[:, 2, 2] += w_d[rows]
        g = (wJ @ res[:, :, None])[:, :, 0]
        g[:, 2] += w_d[rows] * dres
        return A, g, np.sum(w * res * res, axis=-1) + w_d[rows] * dres * dres

    def keep(better, new, old):
        return tuple(np.where(better.reshape((-1,) + (1,) * (n.ndim - 1)), n, o) for n, o in zip(new, old))

    active = np.flatnonzero(valid)
    state = evaluate(p[:, active], active)
    start = linear_fix(r, b, d, have).T
    alternative = evaluate(start[:, active], active)
    better = alternative[2] < state[2]
    p[:, active[better]] = start[:, active[better]]
    state = keep(better, alternative, state)
    mu = np.full(active.size, 1e-3)
    for _ in range(iterations):
        if active.size == 0:
            break
        A, g, cost = state
        step = _solve_damped3(A, g, mu)
        trial = p[:, active] + step
        candidate = evaluate(trial, active)
        better = candidate[2] < cost
        p[:, active[better]] = trial[:, better]
        size = np.sum(step.T * (A @ step.T[:, :, None])[:, :, 0], axis=1)  # δᵀ JᵀWJ δ
        state = keep(better, candidate, state)
        mu = np.where(better, mu * 0.1, mu * 10.0)
        moving = (size > tolerance**2) & np.isfinite(state[2])
        active, mu, state = active[moving], mu[moving], tuple(x[moving] for x in state)
    return np.where(valid[:, None], p.T, np.nan), valid


def linear_fix(ranges: np.ndarray, beacons: np.ndarray, depth: np.ndarray, have: np.ndarray) -> np.ndarray:
    """Closed-form horizontal fix at the measured depth (differenced squared ranges).

    Subtracting the mean over the available beacons from
    ``‖p − b_i‖² = r_i²`` gives equations linear in p,
    ``2 (b_i − b̄) · p = |b_i|² − mean|b|² − (r_i² − mean r²)``; with
    ``p_z = d`` they are solved for (p_x, p_y) by least squares. Used as a
    starting point: it lands in the right basin when the iterative fix would
    have to travel around the ring valley of a short baseline.

    Parameters
    ----------
    ranges : ndarray, shape (B, n)
        Ranges [m] (any value where ``have`` is False).
    beacons : ndarray, shape (3, B, n)
        Beacon positions, components first [m].
    depth : ndarray, shape (B,)
        Depth [m].
    have : ndarray of bool, shape (B, n)
        Available ranges.

    Returns
    -------
    ndarray, shape (B, 3)
        Fix [m]; ``(0, 0, d)`` where the horizontal geometry is degenerate.

    References
    ----------
    Smith, Abel, "Closed-form least-squares source location estimation from
    range-difference measurements", IEEE Trans. ASSP 35(12), 1987.
    """
    count = np.maximum(have.sum(axis=1), 1)
    m = have.astype(float)

    def centred(values):
        return np.where(have, values - (np.sum(values * m, axis=-1) / count)[:, None], 0.0)

    bx, by, bz = centred(beacons[0]), centred(beacons[1]), centred(beacons[2])
    norm2 = np.sum(beacons * beacons, axis=0)
    rhs = 0.5 * (centred(norm2) - centred(ranges * ranges)) - bz * depth[:, None]
    sxx, sxy, syy = np.sum(bx * bx, axis=-1), np.sum(bx * by, axis=-1), np.sum(by * by, axis=-1)
    tx, ty = np.sum(bx * rhs, axis=-1), np.sum(by * rhs, axis=-1)
    det = sxx * syy - sxy * sxy
    ok = det > 1e-12 * np.maximum(sxx + syy, 1e-300) ** 2
    safe = np.where(ok, det, 1.0)
    x = np.where(ok, (syy * tx - sxy * ty) / safe, 0.0)
    y = np.where(ok, (sxx * ty - sxy * tx) / safe, 0.0)
    return np.column_stack([x, y, depth])


_EPS = 1e-9  # Tikhonov term of the normal equations [1/m²]


def _solve_damped3(A: np.ndarray, g: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Solve ``(A + μ diag(A) + εI) x = g`` for symmetric 3 × 3 ``A`` by the adjugate.

    Parameters
    ----------
    A : ndarray, shape (k, 3, 3)
    g : ndarray, shape (k, 3)
    mu : ndarray, shape (k,)

    Returns
    -------
    ndarray, shape (3, k)
    """
    scale = 1.0 + mu
    a00, a01, a02 = A[:, 0, 0] * scale + _EPS, A[:, 0, 1], A[:, 0, 2]
    a11, a12, a22 = A[:, 1, 1] * scale + _EPS, A[:, 1, 2], A[:, 2, 2] * scale + _EPS
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    g0, g1, g2 = g[:, 0], g[:, 1], g[:, 2]
    return np.stack([c00 * g0 + c01 * g1 + c02 * g2,
                     c01 * g0 + c11 * g1 + c12 * g2,
                     c02 * g0 + c12 * g1 + c22 * g2]) / det
