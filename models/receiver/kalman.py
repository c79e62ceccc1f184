"""Kalman-filter arithmetic as casadi expressions: linear prediction, joint and scalar updates, the EKF update.

Nothing here knows the state layout or the measurement: the motion model
(:mod:`sblsim.models.receiver.motion`) gives Φ and Q to
:func:`linear_predict`, a measurement model
(:mod:`sblsim.models.receiver.measurement`) gives ``h``, its Jacobian, R and
the residual to :func:`ekf_update`. A scalar update (:func:`scalar_update`)
processes one measurement with independent noise, its covariance in Joseph
form; the update with several independent measurements (:func:`update`) is
the sequence of them at the joint update's linearization point, equal to the
joint update with ``S = H P Hᵀ + R`` without factoring S. The NIS gate is in
:mod:`sblsim.models.receiver.gate`, the sigma points of the unscented
transform in :mod:`sblsim.models.receiver.sigma_points`.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Sections 5.2 (Joseph form), 3.6 (sequential
processing of independent measurements), 10.3 (extended Kalman filter).
"""

from __future__ import annotations

import casadi as ca


def linear_predict(x: ca.SX, P: ca.SX, phi: ca.SX, Q: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Prediction of a linear motion model: ``x ← Φx``, ``P ← ΦPΦᵀ + Q`` (P's upper triangle computed, mirrored:
    exactly symmetric).

    Parameters
    ----------
    x : casadi.SX, (n, 1)
    P : casadi.SX, (n, n)
    phi, Q : casadi.SX, (n, n)
        Transition matrix and process noise of the step (e.g. from
        :class:`~sblsim.models.receiver.motion.ConstantVelocity`).

    Returns
    -------
    x, P : casadi.SX
        (n, 1) and (n, n).
    """
    return ca.mtimes(phi, x), symmetric(ca.mtimes([phi, P, phi.T]) + Q)


def cholesky(S: ca.SX) -> ca.SX:
    """Lower-triangular L with ``S = L Lᵀ`` for a symmetric positive-(semi)definite S (Cholesky-Banachiewicz).

    A zero pivot (a state that is known exactly: an error state a receiver does not use) gives a zero column
    instead of a division by zero; a positive-definite S gets the plain factor."""
    m = S.shape[0]
    L = ca.SX.zeros(m, m)
    for i in range(m):
        for j in range(i + 1):
            total = S[i, j]
            for k in range(j):
                total = total - L[i, k] * L[j, k]
            L[i, j] = ca.sqrt(ca.fmax(total, 0.0)) if i == j else ca.if_else(L[j, j] > 0.0, total / L[j, j], 0.0)
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


def solve_lower(L: ca.SX, B: ca.SX) -> ca.SX:
    """``L⁻¹ B`` for a lower-triangular L (m, m) and B (m, k), by forward substitution."""
    rows = []
    for i in range(L.shape[0]):
        total = B[i, :]
        for k in range(i):
            total = total - L[i, k] * rows[k]
        rows.append(total / L[i, i])
    return ca.vertcat(*rows)


def whiten(y: ca.SX, H: ca.SX, R: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Rows of unit variance from a measurement of full covariance: ``(L⁻¹ y, L⁻¹ H)`` with ``R = L Lᵀ``
    (:func:`cholesky`, L lower). Their sequential scalar updates of variance 1 (:func:`update`) are the joint
    update with R (Bar-Shalom et al. 2001, Section 3.6: decorrelating the measurements first); the first row is
    the first measurement over ``sqrt(R_00)``, so that its own NIS is unchanged.

    Parameters
    ----------
    y : casadi.SX, (m, 1)
        Innovation.
    H : casadi.SX, (m, n)
        Jacobian.
    R : casadi.SX, (m, m)
        Symmetric positive-definite covariance.

    Returns
    -------
    y, H : casadi.SX
        (m, 1) and (m, n).
    """
    L = cholesky(R)
    return solve_lower(L, y), solve_lower(L, H)


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


def ekf_update(x: ca.SX, P: ca.SX, z: ca.SX, model, context, variances: ca.SX,
               available=None) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Extended Kalman update with a measurement model: ``z`` against ``model.h(x, context)``.

    The model linearizes at ``x`` (``h`` and its casadi Jacobian ``H``), its
    ``residual`` gives the innovation (angles wrapped), and :func:`update`
    applies the rows with independent noises of variances ``variances``.

    Parameters
    ----------
    x : casadi.SX, (n, 1)
        Predicted state.
    P : casadi.SX, (n, n)
        Predicted covariance, symmetric.
    z : casadi.SX, (m, 1)
        Measurement.
    model : MeasurementModel
        A :class:`~sblsim.models.receiver.measurement.MeasurementModel`.
    context
        What ``model.h`` needs besides the state (the beacons, a transceiver position, ...).
    variances : casadi.SX, (m, 1)
        Diagonal of R (e.g. ``model.variances(x, context, p)``).
    available : sequence of casadi.SX or None, optional
        Per row, a flag (1: use the row; 0: the row becomes a zero row with a
        zero innovation, an exact no-op) or None (always used). Default: every
        row is used.

    Returns
    -------
    x, P : casadi.SX
        (n, 1) and (n, n), P exactly symmetric.
    nis : casadi.SX
        ``yᵀ S⁻¹ y`` of the rows used [1].

    References
    ----------
    Bar-Shalom, Li, Kirubarajan 2001, Section 10.3 (the extended Kalman filter).
    """
    h, H = model.linearize(x, context)
    y = model.residual(z, h)
    if available is not None:
        n = x.shape[0]
        rows = [H[k, :] if a is None else ca.if_else(a, H[k, :], ca.SX.zeros(1, n)) for k, a in enumerate(available)]
        y = ca.vertcat(*[y[k] if a is None else ca.if_else(a, y[k], 0.0) for k, a in enumerate(available)])
        H = ca.vertcat(*rows)
    return update(x, P, y, H, variances)


__all__ = ["cholesky", "ekf_update", "linear_predict", "scalar_update", "solve_lower", "solve_spd", "symmetric",
           "update", "whiten"]
