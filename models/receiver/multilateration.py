"""Least-squares multilateration from the latest ranges and depth (casadi expressions).

Weighted least squares (Levenberg-Marquardt) on
``F(p) = Σ_i w_r (r_i − ‖p − b_i‖)² + w_d (d − p_z)²`` with the
casadi-derived range gradient (:mod:`sblsim.models.receiver.measurement`). The
depth term resolves the mirror ambiguity of a surface array. The iteration
is a state machine the generated code steps as an event (one iteration per
call, :data:`LM_STATE`), so each replicate stops on its own.

* Start: the guess or the closed-form :func:`linear_fix`, whichever fits better.
* Iteration: solve the damped normal equations
  ``(JᵀWJ + μ diag(JᵀWJ) + εI) δ = JᵀW res``; keep the step only if it
  lowers F (μ ÷ 10), else raise μ × 10, so a fix never runs away when the
  geometry is poor (short baseline, large range noise).
* Stop when the step is statistically negligible, ``δᵀ JᵀWJ δ ≤ tol²`` (below
  ``tol`` standard deviations of the fix in every direction), or after the
  iteration cap.

With a short baseline and noisy ranges the cost has a ring-shaped valley
around the array and the fix is poorly determined; the cap then leaves the
fix part-way along the valley. That fix is poor either way.

References
----------
Foy, "Position-location solutions by Taylor-series estimation", IEEE Trans.
Aerospace and Electronic Systems AES-12(2), 1976. Marquardt, "An algorithm
for least-squares estimation of nonlinear parameters", J. SIAM 11(2), 1963.
Smith, Abel, "Closed-form least-squares source location estimation from
range-difference measurements", IEEE Trans. ASSP 35(12), 1987. Kay,
Fundamentals of Statistical Signal Processing, Vol. 1, Prentice Hall 1993,
Chapters 3 and 8.
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.receiver.measurement import position_range_function

#: Smallest standard deviation used in the weights [m].
SIGMA_FLOOR = 1e-3
#: Tikhonov term of the normal equations [1/m²].
EPS = 1e-9
#: State blocks of an iteration in progress: point, cost, damping, iteration count, still moving.
LM_STATE = (("lm_point", 3), ("lm_cost", 1), ("lm_mu", 1), ("lm_iter", 1), ("lm_active", 1))


def weights(sigma_range, sigma_depth) -> tuple[ca.SX, ca.SX]:
    """``w = 1 / max(σ, 1 mm)²`` for ranges and depth [1/m²]."""
    return 1.0 / ca.fmax(sigma_range, SIGMA_FLOOR) ** 2, 1.0 / ca.fmax(sigma_depth, SIGMA_FLOOR) ** 2


def law_weight(law, distance) -> ca.SX:
    """A range's weight ``1 / max(σ₀ + k d, 1 mm)²`` [1/m²] of the range law ``law = (σ₀, k)`` at the predicted
    range ``distance`` [m] (:func:`~sblsim.models.acoustics.range_law.range_noise_sigma`)."""
    return 1.0 / ca.fmax(range_noise_sigma({"sigma_range": law[0], "range_k": law[1]}, distance), SIGMA_FLOOR) ** 2


def normal_equations(point, ranges, beacons, heard, depth, w_r, w_d, common=None,
                     law=None) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Normal matrix ``JᵀWJ`` (3, 3), gradient ``JᵀW res`` (3, 1) and cost F at ``point``.

    Where ``law = (σ₀, k)`` is given (the range law, :mod:`sblsim.models.acoustics.range_law`), each range's
    weight is :func:`law_weight` at its predicted range ``‖point − b_i‖`` in place of ``w_r`` (the weights taken
    at ``point``: iteratively reweighted least squares).

    Where ``common`` (None: never) holds, the ranges share an unknown offset (an inverted LBL's ping: the
    emission's), which the fix eliminates: ``F(p) = min_o Σ_i w_r (r_i − ‖p − b_i‖ − o)² + w_d (d − p_z)²``,
    whose optimal ``o`` is the mean residual, so the residuals and their Jacobian rows are taken about their means
    over the heard ranges
    (variable projection: Golub, Pereyra, "The differentiation of pseudo-inverses and nonlinear least squares
    problems whose variables separate", SIAM J. Numer. Anal. 10(2), 1973).

    Parameters
    ----------
    point : casadi.SX, (3, 1)
        Position [m].
    ranges : casadi.SX, (n, 1)
        Ranges [m].
    beacons : casadi.SX, (3 n, 1)
        Beacon positions [m], beacon after beacon.
    heard : casadi.SX, (n, 1)
        1 where a range is available (the others have zero weight).
    depth : casadi.SX
        Depth reading [m].
    w_r, w_d : casadi.SX
        Weights [1/m²] (``w_r`` a list: one per range).
    common : casadi.SX, optional
        The ranges share an unknown offset (1) or not (0).
    law : tuple of 2 casadi.SX, optional
        ``(σ₀ [m], k [m/m])`` of the range law; None: ``w_r`` for every range.
    """
    upper = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    a = [0] * len(upper)  # the upper triangle of A (it is symmetric)
    g = ca.SX.zeros(3, 1)
    cost = 0
    rows, range_weights = [], []
    for i in range(ranges.numel()):
        h, J = position_range_function()(point, beacons[3 * i:3 * i + 3])
        range_weights.append(law_weight(law, h) if law is not None else w_r[i] if isinstance(w_r, list) else w_r)
        J = ca.if_else(heard[i], J, ca.SX.zeros(3))  # an unheard beacon may give 0/0 at its placeholder
        rows.append((J, ca.if_else(heard[i], ranges[i] - h, 0.0)))
    if common is not None:  # the offset common to the ranges eliminated: residuals and rows about their means
        share = common / ca.fmax(ca.sum1(heard), 1.0)  # 0 where nothing is common: the rows as they are
        mean_J = share * sum(J for J, _ in rows)
        mean_res = share * sum(res for _, res in rows)
        rows = [((J - mean_J) * heard[i], (res - mean_res) * heard[i]) for i, (J, res) in enumerate(rows)]
    for i, (J, res) in enumerate(rows):
        w = range_weights[i] * heard[i]
        wJ = w * J
        a = [a[k] + wJ[r] * J[c] for k, (r, c) in enumerate(upper)]
        g = g + wJ * res
        cost = cost + w * res * res
    dres = depth - point[2]
    a[-1] = a[-1] + w_d
    g[2] = g[2] + w_d * dres
    A = ca.SX.zeros(3, 3)
    for value, (r, c) in zip(a, upper):
        A[r, c] = A[c, r] = value
    return A, g, cost + w_d * dres * dres


def linear_fix(ranges, beacons, heard, depth) -> ca.SX:
    """Closed-form horizontal fix at the measured depth (differenced squared ranges).

    Subtracting the mean over the available beacons from
    ``‖p − b_i‖² = r_i²`` gives equations linear in p,
    ``2 (b_i − b̄) · p = |b_i|² − mean|b|² − (r_i² − mean r²)``; with
    ``p_z = d`` they are solved for (p_x, p_y) by least squares. Used as a
    starting point: it lands in the right basin when the iterative fix would
    have to travel around the ring valley of a short baseline.

    Returns
    -------
    casadi.SX, (3, 1)
        Fix [m]; ``(0, 0, d)`` where the horizontal geometry is degenerate.
    """
    n = ranges.numel()
    count = ca.fmax(ca.sum1(heard), 1.0)

    def centred(values):
        mean = sum(values[i] * heard[i] for i in range(n)) / count
        return [ca.if_else(heard[i], values[i] - mean, 0.0) for i in range(n)]

    b = [beacons[3 * i:3 * i + 3] for i in range(n)]
    bx, by, bz = (centred([b[i][a] for i in range(n)]) for a in range(3))
    norm2 = centred([ca.dot(b[i], b[i]) for i in range(n)])
    r2 = centred([ranges[i] * ranges[i] for i in range(n)])
    rhs = [0.5 * (norm2[i] - r2[i]) - bz[i] * depth for i in range(n)]
    sxx = sum(bx[i] * bx[i] for i in range(n))
    sxy = sum(bx[i] * by[i] for i in range(n))
    syy = sum(by[i] * by[i] for i in range(n))
    tx = sum(bx[i] * rhs[i] for i in range(n))
    ty = sum(by[i] * rhs[i] for i in range(n))
    det = sxx * syy - sxy * sxy
    ok = det > 1e-12 * ca.fmax(sxx + syy, 1e-300) ** 2
    safe = ca.if_else(ok, det, 1.0)
    return ca.vertcat(ca.if_else(ok, (syy * tx - sxy * ty) / safe, 0.0),
                      ca.if_else(ok, (sxx * ty - sxy * tx) / safe, 0.0), depth)


def solve_damped3(A, g, mu) -> ca.SX:
    """Solve ``(A + μ diag(A) + εI) δ = g`` for a symmetric 3 × 3 A by the adjugate."""
    scale = 1.0 + mu
    a00, a01, a02 = A[0, 0] * scale + EPS, A[0, 1], A[0, 2]
    a11, a12, a22 = A[1, 1] * scale + EPS, A[1, 2], A[2, 2] * scale + EPS
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    return ca.vertcat(c00 * g[0] + c01 * g[1] + c02 * g[2],
                      c01 * g[0] + c11 * g[1] + c12 * g[2],
                      c02 * g[0] + c12 * g[1] + c22 * g[2]) / det


def _finite(value) -> ca.SX:
    return ca.logic_and(value == value, ca.fabs(value) < 1e308)


def lm_start(guess, ranges, beacons, heard, depth, w_r, w_d, valid, common=None, law=None) -> dict[str, ca.SX]:
    """The iteration state at the start: the guess or the linear fix, whichever costs less.

    ``valid`` (enough ranges) decides whether iterations follow; ``common``: the ranges share an unknown offset,
    ``law``: the range law's weights (:func:`normal_equations`).
    """
    cost_guess = normal_equations(guess, ranges, beacons, heard, depth, w_r, w_d, common, law)[2]
    alternative = linear_fix(ranges, beacons, heard, depth)
    cost_alt = normal_equations(alternative, ranges, beacons, heard, depth, w_r, w_d, common, law)[2]
    better = cost_alt < cost_guess
    return {"lm_point": ca.if_else(better, alternative, guess), "lm_cost": ca.if_else(better, cost_alt, cost_guess),
            "lm_mu": 1e-3, "lm_iter": 0, "lm_active": valid}


def lm_iteration(x, ranges, beacons, heard, depth, w_r, w_d, iterations: int, tolerance: float,
                 common=None, law=None) -> dict[str, ca.SX]:
    """One Levenberg-Marquardt iteration of the state in ``x`` (blocks :data:`LM_STATE`; ``common``: the ranges
    share an unknown offset, :func:`normal_equations`). With the range ``law`` and ``k > 0`` the weights are those
    at the iteration's point, the trial's cost compared with the point's at the same weights (iteratively
    reweighted)."""
    point, cost, mu = x["lm_point"], x["lm_cost"], x["lm_mu"]
    A, g, here = normal_equations(point, ranges, beacons, heard, depth, w_r, w_d, common, law)
    step = solve_damped3(A, g, mu)
    trial = point + step
    frozen = w_r
    if law is not None:  # the trial's cost at the point's weights
        cost = ca.if_else(law[1] > 0.0, here, cost)
        frozen = [law_weight(law, position_range_function()(point, beacons[3 * i:3 * i + 3])[0])
                  for i in range(ranges.numel())]
    trial_cost = normal_equations(trial, ranges, beacons, heard, depth, frozen, w_d, common)[2]
    better = trial_cost < cost
    size = ca.dot(step, ca.mtimes(A, step))  # δᵀ JᵀWJ δ
    new_cost = ca.if_else(better, trial_cost, cost)
    moving = ca.logic_and(size > tolerance**2, _finite(new_cost))
    return {"lm_point": ca.if_else(better, trial, point), "lm_cost": new_cost,
            "lm_mu": ca.if_else(better, mu * 0.1, mu * 10.0), "lm_iter": x["lm_iter"] + 1,
            "lm_active": ca.logic_and(moving, x["lm_iter"] + 1 < iterations)}


def fix_covariance(point, ranges, beacons, heard, depth, w_r, w_d, law=None) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Gauss-Newton covariance ``(JᵀWJ)⁻¹`` of a fix (by the adjugate), with the fit's cost (``law``: the range
    law's weights at the fix, :func:`normal_equations`).

    Returns
    -------
    rss : casadi.SX
        F at the fix [1] (chi-square with n + 1 − 3 degrees of freedom for correct weights).
    covariance : casadi.SX, (3, 3)
        [m²]; zeros where ``JᵀWJ`` is singular.
    positive : casadi.SX
        ``JᵀWJ`` is positive-definite.
    """
    A, _, rss = normal_equations(point, ranges, beacons, heard, depth, w_r, w_d, law=law)
    c = ca.SX.zeros(3, 3)
    c[0, 0] = A[1, 1] * A[2, 2] - A[1, 2] * A[1, 2]
    c[1, 1] = A[0, 0] * A[2, 2] - A[0, 2] * A[0, 2]
    c[2, 2] = A[0, 0] * A[1, 1] - A[0, 1] * A[0, 1]
    c[0, 1] = c[1, 0] = A[0, 2] * A[1, 2] - A[0, 1] * A[2, 2]
    c[0, 2] = c[2, 0] = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
    c[1, 2] = c[2, 1] = A[0, 1] * A[0, 2] - A[0, 0] * A[1, 2]
    det = A[0, 0] * c[0, 0] + A[0, 1] * c[0, 1] + A[0, 2] * c[0, 2]
    positive = det > 0.0
    return rss, ca.if_else(positive, c / ca.if_else(positive, det, 1.0), ca.SX.zeros(3, 3)), positive


def fit_statistics(point, ranges, beacons, heard, depth, w_r, w_d) -> tuple[ca.SX, ca.SX]:
    """Weighted residual sum of squares F and Gauss-Newton spread ``sqrt(trace((JᵀWJ)⁻¹))`` at a fix.

    Returns
    -------
    rss : casadi.SX
        F at the fix [1].
    spread : casadi.SX
        [m]; 0 where ``JᵀWJ`` is singular.
    """
    rss, covariance, _ = fix_covariance(point, ranges, beacons, heard, depth, w_r, w_d)
    return rss, ca.sqrt(ca.fmax(ca.trace(covariance), 0.0))


__all__ = ["EPS", "LM_STATE", "SIGMA_FLOOR", "fit_statistics", "fix_covariance", "law_weight", "linear_fix",
           "lm_iteration", "lm_start", "normal_equations", "solve_damped3", "weights"]
