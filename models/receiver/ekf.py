"""The paper's Extended Kalman Filter as casadi expressions.

State ``x = [posX, velX, posY, velY, posZ, velZ]`` (NED) [m, m/s] with the
constant-velocity transition ``Φ = blockdiag([[1, Δt], [0, 1]] × 3)`` and
white-noise-acceleration process noise
``Q = q · [[Δt³/3, Δt²/2], [Δt²/2, Δt]]`` per axis (q_h for North and East,
q_v for Down) [m²/s³]. Measurements: the latest range of each beacon and the
depth, ``z = [r_1 … r_n, d]``, with ``h_i(x) = ‖p − b̃_i‖`` (casadi Jacobian,
:mod:`models.receiver.measurement`) and the depth row ``[0 0 0 0 1 0]``;
``R = diag(σ_r², …, σ_r², σ_d²)``. A beacon not heard yet gets a zero
Jacobian row and a zero innovation, which leaves the update exact for the
others. The innovation covariance is factored by Cholesky (it is symmetric
positive-definite); the covariance update uses the Joseph form.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Sections 5.2 (Joseph form), 6.2 (white-noise
acceleration model), 5.4 (NIS).
"""

from __future__ import annotations

import casadi as ca

from models.receiver.measurement import STATE_SIZE, range_function

DEPTH_ROW = (0.0, 0.0, 0.0, 0.0, 1.0, 0.0)


def transition(dt) -> ca.SX:
    """Constant-velocity transition matrix Φ, (6, 6), for a step ``dt`` [s]."""
    phi = ca.SX.eye(STATE_SIZE)
    for k in (0, 2, 4):
        phi[k, k + 1] = dt
    return phi


def process_noise(dt, q_horizontal, q_vertical) -> ca.SX:
    """White-noise-acceleration process noise Q, (6, 6) [m², m²/s, m²/s²], densities in [m²/s³]."""
    q = ca.SX.zeros(STATE_SIZE, STATE_SIZE)
    block = ca.vertcat(ca.horzcat(dt**3 / 3.0, dt**2 / 2.0), ca.horzcat(dt**2 / 2.0, dt))
    for axis, density in enumerate((q_horizontal, q_horizontal, q_vertical)):
        q[2 * axis:2 * axis + 2, 2 * axis:2 * axis + 2] = density * block
    return q


def predict(x: ca.SX, P: ca.SX, dt, q_horizontal, q_vertical) -> tuple[ca.SX, ca.SX]:
    """``x ← Φx``, ``P ← ΦPΦᵀ + Q`` for a step ``dt`` [s]."""
    phi = transition(dt)
    return ca.mtimes(phi, x), ca.mtimes([phi, P, phi.T]) + process_noise(dt, q_horizontal, q_vertical)


def cholesky(S: ca.SX) -> ca.SX:
    """Lower-triangular L with ``S = L Lᵀ`` for a symmetric positive-definite S (Cholesky-Banachiewicz)."""
    m = S.shape[0]
    L = ca.SX.zeros(m, m)
    for i in range(m):
        for j in range(i + 1):
            total = S[i, j]
            for k in range(j):
                total = total - L[i, k] * L[j, k]
            L[i, j] = ca.sqrt(total) if i == j else total / L[j, j]
    return L


def solve_spd(S: ca.SX, B: ca.SX) -> ca.SX:
    """``S⁻¹ B`` for a symmetric positive-definite S, by Cholesky and two triangular solves."""
    L = cholesky(S)
    m = S.shape[0]
    cols = []
    for c in range(B.shape[1]):
        y = [None] * m
        for i in range(m):
            total = B[i, c]
            for k in range(i):
                total = total - L[i, k] * y[k]
            y[i] = total / L[i, i]
        z = [None] * m
        for i in reversed(range(m)):
            total = y[i]
            for k in range(i + 1, m):
                total = total - L[k, i] * z[k]
            z[i] = total / L[i, i]
        cols.append(ca.vertcat(*z))
    return ca.horzcat(*cols)


def update(x: ca.SX, P: ca.SX, ranges: ca.SX, beacons: ca.SX, heard: ca.SX, depth, sigma_range,
           sigma_depth) -> tuple[ca.SX, ca.SX, ca.SX]:
    """EKF update with the latest range of each beacon heard so far and the depth.

    Parameters
    ----------
    x : casadi.SX, (6, 1)
        Predicted state [m, m/s].
    P : casadi.SX, (6, 6)
        Predicted covariance.
    ranges : casadi.SX, (n, 1)
        Latest range of each beacon [m].
    beacons : casadi.SX, (3 n, 1)
        Broadcast position carried with each range [m], beacon after beacon.
    heard : casadi.SX, (n, 1)
        1 for a beacon heard so far, else 0 (its row is left out exactly).
    depth : casadi.SX
        Depth reading [m].
    sigma_range, sigma_depth : casadi.SX
        Standard deviations in R [m].

    Returns
    -------
    x, P : casadi.SX
        Updated state and covariance.
    nis : casadi.SX
        Normalized innovation squared ``yᵀ S⁻¹ y`` [1].
    """
    n = ranges.numel()
    h_rows, y = [], []
    for i in range(n):
        h, H = range_function()(x, beacons[3 * i:3 * i + 3])
        h_rows.append(ca.if_else(heard[i], H.T, ca.SX.zeros(1, STATE_SIZE)))
        y.append(ca.if_else(heard[i], ranges[i] - h, 0.0))
    H = ca.vertcat(*h_rows, ca.horzcat(*DEPTH_ROW))
    y = ca.vertcat(*y, depth - x[4])
    R = ca.diag(ca.vertcat(*([sigma_range**2] * n), sigma_depth**2))
    PHt = ca.mtimes(P, H.T)
    S = ca.mtimes(H, PHt) + R
    solved = solve_spd(S, ca.horzcat(PHt.T, y))  # one factorization of S: S⁻¹ [H P, y]
    K = solved[:, :STATE_SIZE].T
    x_new = x + ca.mtimes(K, y)
    I_KH = ca.SX.eye(STATE_SIZE) - ca.mtimes(K, H)
    P_new = ca.mtimes([I_KH, P, I_KH.T]) + ca.mtimes([K, R, K.T])
    nis = ca.dot(y, solved[:, STATE_SIZE])
    return x_new, P_new, nis


__all__ = ["DEPTH_ROW", "cholesky", "predict", "process_noise", "solve_spd", "transition", "update"]
