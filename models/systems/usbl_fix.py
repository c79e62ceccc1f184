"""The least-squares fix of one USBL packet and the depth reading, and the Fisher information of the two.

Gauss-Newton on ``[r, a_x, a_y, d]`` weighted by the receivers' R, from the packet's polar fix
(:func:`packet_fix`, :func:`gauss_newton`), with its covariance ``(Hᵀ R⁻¹ H + e_z e_zᵀ / σ_d²)⁻¹``
(:func:`position_information`): the instrumentation fix and the ``lsq`` receiver's estimate of a USBL packet.

References
----------
Kay, Fundamentals of Statistical Signal Processing: Estimation Theory, Prentice Hall 1993, Sections 3.7 and 8.9
(Gauss-Newton).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.receiver import kalman
from sblsim.models.systems.usbl_packet import POSITION_MODEL, context, covariance, measurement, polar_fix

#: Gauss-Newton iterations of the packet's least-squares fix from its polar fix (:func:`packet_fix`).
FIX_ITERATIONS = 5


def _depth_row(n: int, index: int) -> ca.SX:
    row = ca.SX.zeros(1, n)
    row[index] = 1.0
    return row


def position_information(position, ctx, R, depth_variance) -> ca.SX:
    """Fisher information (3, 3) [1/m²] of one packet of covariance ``R`` (3, 3) and a depth reading of variance
    ``depth_variance`` [m²] about a diver at ``position`` (3, 1) [m]: ``Hᵀ R⁻¹ H + e_z e_zᵀ / σ_d²``, H of
    :data:`POSITION_MODEL` (Kay 1993, Section 3.7)."""
    H = POSITION_MODEL.jacobian(position, ctx)
    _, Hw = kalman.whiten(ca.SX.zeros(3), H, R)
    e_z = _depth_row(3, 2)
    return ca.mtimes(Hw.T, Hw) + ca.mtimes(e_z.T, e_z) / depth_variance


def packet_fix(u: dict, p: dict, depth) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The least-squares fix of one packet and the depth reading ``depth`` [m], its covariance and its residual.

    Gauss-Newton (:data:`FIX_ITERATIONS` steps) on ``[r, a_x, a_y, d]`` weighted by the receivers' R
    (:func:`covariance` at the polar fix) and ``σ_d² = sigma_depth²``, from the polar fix ``b + r n(α, ε)``;
    the covariance is ``(Hᵀ R⁻¹ H + e_z e_zᵀ / σ_d²)⁻¹`` at the fix (Kay 1993, Section 8.9).

    Returns
    -------
    point : casadi.SX, (3, 1)
        The fix [m].
    covariance : casadi.SX, (3, 3)
        Its covariance [m²].
    rss : casadi.SX
        The weighted sum of squared residuals at the fix [1] (chi-square with 1 degree of freedom: four
        measurements, three unknowns).
    """
    ctx, z = context(u), measurement(u)
    point = polar_fix(u)
    depth_variance = p["sigma_depth"] ** 2
    point, rss = gauss_newton(z, depth, ctx, point, covariance(point, ctx, p, POSITION_MODEL, states=False),
                              depth_variance)
    J = position_information(point, ctx, covariance(point, ctx, p, POSITION_MODEL, states=False), depth_variance)
    return point, kalman.symmetric(kalman.solve_spd(J, ca.SX.eye(3))), rss


def gauss_newton(z, depth, ctx, point, R, depth_variance) -> tuple[ca.SX, ca.SX]:
    """The least-squares position of a packet ``z = [r, a_x, a_y]`` (3, 1) of covariance ``R`` (3, 3) and a depth
    reading ``depth`` [m] of variance ``depth_variance`` [m²]: :data:`FIX_ITERATIONS` Gauss-Newton steps from
    ``point`` (3, 1) [m] (Kay 1993, Section 8.9); the position and its weighted sum of squared residuals."""
    e_z = _depth_row(3, 2)

    def normal(point):
        h, H = POSITION_MODEL.linearize(point, ctx)
        yw, Hw = kalman.whiten(z - h, H, R)
        J = ca.mtimes(Hw.T, Hw) + ca.mtimes(e_z.T, e_z) / depth_variance
        g = ca.mtimes(Hw.T, yw) + e_z.T * (depth - point[2]) / depth_variance
        return J, g, ca.dot(yw, yw) + (depth - point[2]) ** 2 / depth_variance

    for _ in range(FIX_ITERATIONS):
        J, g, _ = normal(point)
        point = point + kalman.solve_spd(J, g)
    _, _, rss = normal(point)
    return point, rss


__all__ = ["FIX_ITERATIONS", "gauss_newton", "packet_fix", "position_information"]
