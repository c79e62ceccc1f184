"""Geometric spreading and arc length of a solved eigenray: the ray-tube loss, capped at caustics.

The ray-tube intensity relative to 1 m (Jensen, Kuperman, Porter, Schmidt, *Computational Ocean Acoustics*, 2nd
ed., Springer 2011, ch. 3.3, eq. 3.65 with the tube's Jacobian) in a family's parameter ``q``, from the layer sums
of :func:`~sblsim.models.acoustics.ray_integrals._tube` (:func:`_tube_loss`); the loss at most :data:`CAUSTIC_GAIN`
below the spherical spreading of the path's isovelocity image (:func:`spherical_spreading`) and at least 0 dB.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.acoustics.ray_integrals import _TINY, _speed, _tube

#: The most a ray tube may gain over the spherical spreading of the path's isovelocity image [dB]: the cap of the
#: ray-tube intensity at and near a caustic (``dX/dq → 0``), where geometric acoustics predicts an infinite one.
CAUSTIC_GAIN = 10.0


def spherical_spreading(length):
    """``20 log10 L`` [dB] of a distance ``L`` [m], floored at 0 dB (within 1 m of the source: its source level)."""
    return ca.fmax(20.0 * ca.log10(ca.fmax(length, _TINY)), 0.0)


def _tube_loss(zs, zr, x, ray, nodes, speeds):
    """Geometric spreading [dB re 1 m] and arc length [m] of a solved eigenray ``ray`` (:func:`_direct`).

    The ray-tube intensity relative to 1 m (Jensen et al. 2011, ch. 3.3, eq. 3.65 with the tube's Jacobian) is
    ``|p/p0|² = (c_r / c_s) cos θ_s / (r |∂r/∂θ_s| sin θ_r)``; in the family's parameter ``q`` (``cos θ_s = ξ c_s``,
    ``ξ = √(1 − q²) / c_ref``: ``cos θ_s |dθ_s/dq| = c_s² |q| / (c_ref² sin θ_s)``) and with ``X = √(1 − q²) F``
    (so that ``X |dX/dq| = |q F² − (1 − q²) F F'|``, finite at the vertical ray), it is
    ``c_s c_r / (c_ref² · X |dX/dq| · sin θ_s sin θ_r / |q|)``. ``sin θ / |q|`` is taken at the faster end (1 where
    the speed is ``c_ref``: a ray horizontal at that end, ``q → 0``, keeps a finite tube) and ``sin θ`` at the other.
    A level path in water of constant speed around it (the family degenerate: ``X ≡ 0``) is the straight line. The
    loss is capped at :data:`CAUSTIC_GAIN` below the spherical spreading of the isovelocity image, and floored at
    0 dB."""
    q, fold, cref, u1, v1, u2, v2, image, level = ray[:9]
    f, df, arc = _tube()(q, fold, cref, u1, v1, u2, v2, nodes, speeds)
    if len(ray) > 9:  # a second interval covered twice (:func:`_surface_turning`)
        f2, df2, arc2 = _tube()(q, 1.0, cref, ray[9], ray[9], ray[9], ray[10], nodes, speeds)
        f, df, arc = f + f2, df + df2, arc + arc2
    speed = _speed()
    c_s, c_r = speed(zs, nodes, speeds), speed(zr, nodes, speeds)
    qq = q * q
    area = ca.fabs(q * f * f - (1.0 - qq) * f * df)  # X |dX/dq| [m²]

    def sine(c):
        return ca.sqrt(ca.fmax((cref - c) * (cref + c) + qq * c * c, 0.0)) / cref

    def ratio(c):  # sin θ / |q|
        return ca.sqrt(ca.fmax((cref - c) * (cref + c), 0.0) / ca.fmax(qq, _TINY) + c * c) / cref

    ends = ca.if_else(c_s >= c_r, ratio(c_s) * sine(c_r), sine(c_s) * ratio(c_r))
    tube = 10.0 * ca.log10(ca.fmax(cref * cref * area * ends / (c_s * c_r), _TINY))
    straight = ca.sqrt(x * x + image * image)
    spreading = ca.fmax(ca.fmax(tube, spherical_spreading(straight) - CAUSTIC_GAIN), 0.0)
    return ca.if_else(level, spherical_spreading(x), spreading), ca.if_else(level, x, arc)


__all__ = ["CAUSTIC_GAIN", "spherical_spreading"]
