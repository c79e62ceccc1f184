"""Kalman-filter arithmetic as casadi expressions: predict, joint and scalar updates, the NIS gate, sigma points.

State ``x = [posX, velX, posY, velY, posZ, velZ]`` (NED) [m, m/s] with the
constant-velocity transition ``Φ = blockdiag([[1, Δt], [0, 1]] × 3)`` and
white-noise-acceleration process noise
``Q = q · [[Δt³/3, Δt²/2], [Δt²/2, Δt]]`` per axis (q_h for North and East,
q_v for Down) [m²/s³]. The measurement model comes from
:mod:`sblsim.models.receiver.measurement`. A scalar update (:func:`scalar_update`)
processes one measurement with independent noise, its covariance in Joseph
form; the update with several independent measurements (:func:`update`) is
the sequence of them at the joint update's linearization point, equal to the
joint update with ``S = H P Hᵀ + R`` without factoring S. The NIS gate
(:func:`gate_threshold`) rejects a scalar innovation whose NIS exceeds the
χ²(1) quantile of the gate probability. The unscented transform
(:func:`sigma_points`, :func:`unscented_weights`) uses the scaled sigma points
of van der Merwe (α, β, κ).

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Sections 5.2 (Joseph form), 6.2 (white-noise
acceleration model), 5.4 (NIS), 3.6 (sequential processing of independent
measurements). Julier, Uhlmann, "Unscented filtering and nonlinear
estimation", Proc. IEEE 92(3), 2004; van der Merwe, Sigma-point Kalman
filters for probabilistic inference in dynamic state-space models, PhD
thesis, OGI 2004 (scaled sigma points).
"""

from __future__ import annotations

import math

import casadi as ca

from sblsim.models.receiver.measurement import STATE_SIZE


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
    """``x ← Φx``, ``P ← ΦPΦᵀ + Q`` for a step ``dt`` [s] (P's upper triangle computed, mirrored: exactly
    symmetric)."""
    phi = transition(dt)
    return ca.mtimes(phi, x), symmetric(ca.mtimes([phi, P, phi.T]) + process_noise(dt, q_horizontal, q_vertical))


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


def symmetric(P: ca.SX) -> ca.SX:
    """P with its lower triangle taken from the upper one: exactly symmetric, the upper triangle's values."""
    n = P.shape[0]
    return ca.vertcat(*[ca.horzcat(*[P[min(i, j), max(i, j)] for j in range(n)]) for i in range(n)])


def update(x: ca.SX, P: ca.SX, y: ca.SX, H: ca.SX, variances: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Kalman update with m independent measurements: innovation ``y`` (m, 1), Jacobian ``H`` (m, n) and noise
    variances ``variances`` (m, 1) (a diagonal R).

    The rows are processed one after the other by :func:`scalar_update`, each
    at the linearization point of the joint update (row k's innovation less
    ``H_k δ``, δ the correction the earlier rows made): in exact arithmetic
    this is the joint update with ``S = H P Hᵀ + R``, and the NIS ``yᵀ S⁻¹ y``
    is the sum of the rows' ``ỹ_k² / s_k`` (Bar-Shalom et al., Section 3.6).
    It needs no m × m factorization: about two thirds of the joint update's
    arithmetic for five rows. A zero row with a zero innovation changes
    nothing, bit for bit.

    Returns
    -------
    x, P : casadi.SX
        (n, 1) and (n, n), P exactly symmetric (computed from the upper triangle of ``P``).
    nis : casadi.SX
        ``yᵀ S⁻¹ y`` [1].
    """
    dx, P_k, nis = ca.SX.zeros(x.shape[0]), P, 0.0  # dx: the correction so far (each row reads P symmetric)
    for k in range(H.shape[0]):
        row = H[k, :]
        dx, P_k, nis_k = scalar_update(dx, P_k, y[k] - ca.mtimes(row, dx), row, variances[k])
        nis = nis + nis_k
    return x + dx, P_k, nis


def scalar_update(x: ca.SX, P: ca.SX, innovation, H: ca.SX, variance, use=1.0) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Update with one scalar measurement of noise variance ``variance`` (Joseph form).

    The Joseph form ``(I − k h) P (I − k h)ᵀ + k r kᵀ`` of a rank-one update
    is evaluated as ``P − k uᵀ + (r k − w) kᵀ`` with ``u = P hᵀ`` and
    ``w = (I − k h) P hᵀ = u − k h u``, on the upper triangle, mirrored (P is
    taken as symmetric, its upper triangle read): the same algebra, about a
    third of the arithmetic of the matrix products, and like them first-order
    insensitive to round-off in the gain.

    Parameters
    ----------
    x : casadi.SX, (n, 1)
    P : casadi.SX, (n, n)
        Symmetric.
    innovation : casadi.SX
        ``z − h(x)``.
    H : casadi.SX, (1, n)
        ``∂h/∂x``.
    variance : casadi.SX
        Noise variance of the measurement.
    use : casadi.SX
        1 to apply the update, 0 to leave x and P as they are (a gated or missing measurement).

    Returns
    -------
    x, P : casadi.SX
        P exactly symmetric.
    nis : casadi.SX
        ``y² / S`` of the innovation (whether it is used or not).
    """
    n = x.shape[0]
    P = symmetric(P)
    u = ca.mtimes(P, H.T)
    hu = ca.mtimes(H, u)
    S = hu + variance
    K = u / S
    nis = innovation * innovation / S
    x_new = x + K * innovation
    v = variance * K - (u - K * hu)
    P_new = symmetric(ca.vertcat(*[ca.horzcat(*[P[i, j] - K[i] * u[j] + v[i] * K[j] for j in range(n)])
                                   for i in range(n)]))
    keep = use > 0.5
    return ca.if_else(keep, x_new, x), ca.if_else(keep, P_new, P), nis


def erfinv(y) -> ca.SX:
    """Inverse error function for 0 ≤ y < 1 as a plain expression (the generated C has no ``erfinv``).

    Winitzki's closed-form approximation (relative error about 2·10⁻³) refined
    by three Newton steps on ``erf``: about 10⁻¹⁴ relative for y ≤ 1 − 10⁻⁴.
    """
    a = 0.147
    log_term = ca.log(1.0 - y * y)
    t = 2.0 / (math.pi * a) + 0.5 * log_term
    x = ca.sqrt(ca.sqrt(t * t - log_term / a) - t)
    for _ in range(3):
        x = x - (ca.erf(x) - y) * (0.5 * math.sqrt(math.pi)) * ca.exp(x * x)
    return x


def gate_threshold(probability) -> ca.SX:
    """χ²(1) quantile of ``probability``: ``2 erfinv(probability)²``; infinite (no gate) for probability ≥ 1."""
    q = 2.0 * erfinv(ca.fmin(probability, 1.0 - 1e-12)) ** 2
    return ca.if_else(probability >= 1.0, ca.inf, q)


def unscented_weights(n: int, alpha, beta, kappa) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Scaled unscented weights: λ = α²(n + κ) − n; mean and covariance weights, each (2n + 1, 1)."""
    lam = alpha**2 * (n + kappa) - n
    rest = 0.5 / (n + lam)
    wm = ca.vertcat(lam / (n + lam), *([rest] * (2 * n)))
    wc = ca.vertcat(lam / (n + lam) + (1.0 - alpha**2 + beta), *([rest] * (2 * n)))
    return wm, wc, lam


def sigma_points(x: ca.SX, P: ca.SX, lam) -> list[ca.SX]:
    """The 2n + 1 scaled sigma points ``x, x ± col_i(chol((n + λ) P))`` (lower Cholesky factor's columns)."""
    n = x.shape[0]
    L = cholesky((n + lam) * P)
    return [x] + [x + L[:, i] for i in range(n)] + [x - L[:, i] for i in range(n)]


__all__ = ["cholesky", "erfinv", "gate_threshold", "predict", "process_noise", "scalar_update", "sigma_points",
           "solve_spd", "symmetric", "transition", "unscented_weights", "update"]
