"""The receivers' inversion of the direct eigenray: a travel time to a slant range, a range to the ray's bending.

LBL and USBL processing with a measured profile turns a one-way travel time into the straight chord's length
(:func:`slant_range`, Newton's iteration on the direct eigenray's time) and a direction of arrival into the chord's
(:func:`ray_bending`, the chord's elevation less the eigenray's grazing angle at the transceiver), each through the
direct eigenray the solve finds from the chord's angle without boundaries (:func:`_direct_first`).

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca

from sblsim.models.acoustics.direct_family import _direct
from sblsim.models.acoustics.ray_integrals import _speed
from sblsim.models.acoustics.rays import _first
from sblsim.models.acoustics.sound_speed import NODES


@lru_cache(maxsize=1)
def _direct_first() -> ca.Function:
    """``(zs, zr, x, nodes, speeds) -> (τ, launch, arrival, kind)``: the direct eigenray the solve finds from the
    chord's angle (no boundaries, kind 1 or 0), valid where the flattest ray reaches ``x``: the eigenray the
    receivers' profile processing inverts (:func:`slant_range`, :func:`ray_bending`)."""
    zs, zr, x = (ca.MX.sym(n) for n in ("zs", "zr", "x"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    direct = _direct(zs, zr, x, 0.0, nodes, speeds, found=False)[:4]
    return ca.Function("sblsim_ray_direct_first", [zs, zr, x, nodes, speeds],
                       list(_first(*[ca.vertcat(v) for v in direct])), {"never_inline": True})


#: Newton iterations of :func:`slant_range` (from the straight line at the harmonic-mean speed; the error falls
#: quadratically: metres, millimetres, then round-off at a 1 km slant range).
RANGE_ITERATIONS = 3


@lru_cache(maxsize=1)
def _slant_range() -> ca.Function:
    """``(zs, zr, tau, start, nodes, speeds) -> (range, valid)``: see :func:`slant_range`."""
    zs, zr, tau, start = (ca.MX.sym(n) for n in ("zs", "zr", "tau", "start"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    dz = zr - zs
    rho = ca.fmax(start, 0.0)
    valid = 1.0
    for _ in range(RANGE_ITERATIONS):
        x = ca.sqrt(ca.fmax(rho * rho - dz * dz, 0.0))
        t, launch, _arrival, kind = _direct_first()(zs, zr, x, nodes, speeds)
        # dT/dρ = ξ dX/dρ = ξ ρ / X (ξ = cos θ / c, Snell's invariant); at or below the vertical (ρ ≤ |Δz|,
        # X = 0) the vertical path's time scaled with ρ, T(ρ) = T_0 ρ / |Δz|: the next step lands on
        # τ |Δz| / T_0, the vertical path's range at its mean speed
        xi = ca.cos(launch) / _speed()(zs, nodes, speeds)
        vertical = x <= 1e-9 * ca.fmax(rho, 1.0)
        slowness = t / ca.fmax(ca.fabs(dz), 1e-9)
        slope = ca.if_else(vertical, slowness, xi * rho / ca.if_else(vertical, 1.0, x))
        t = ca.if_else(vertical, slowness * rho, t)
        found = kind > 0
        valid = ca.logic_and(valid, found)
        rho = ca.if_else(found, ca.fmax(rho + (tau - t) / slope, 0.0), rho)
    return ca.Function("sblsim_ray_slant_range", [zs, zr, tau, start, nodes, speeds], [rho, valid],
                       ["zs", "zr", "tau", "start", "nodes", "speeds"], ["range", "valid"], {"never_inline": True})


def slant_range(zs, zr, tau, start, nodes, speeds):
    """The straight-line slant range of the direct eigenray whose travel time is ``tau``: the inverse of the
    direct eigenray's time, as LBL and USBL processing turns a travel time into a range with a measured profile.

    Newton's iteration on the slant range ``ρ`` (the horizontal distance ``X = √(ρ² − Δz²)``), each step the
    direct eigenray of :func:`first_arrival` (no boundaries) at ``X``, with ``dτ/dρ = ξ ρ / X`` (``dτ/dX = ξ``
    along the family, Fermat; ``ξ = cos θ_launch / c(z_s)``) and, for a vertical path (``X = 0``), the mean
    slowness ``τ / ρ``; a fixed :data:`RANGE_ITERATIONS` steps from ``start``. A travel time shorter than the
    vertical one gives the vertical path's range scaled by its mean speed.

    Parameters
    ----------
    zs, zr : casadi.SX
        Depth of the two transducers [m] (positive down); the direct eigenray is reciprocal.
    tau : casadi.SX
        One-way travel time [s].
    start : casadi.SX
        The first guess [m] (e.g. the assumed speed times ``tau``).
    nodes, speeds : casadi.SX, shape (NODES, 1)
        The padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`, a table of at least one row).

    Returns
    -------
    range : casadi.SX
        ``√(X² + Δz²)`` [m] of the direct eigenray of time ``tau``.
    valid : casadi.SX
        1 when every step found a direct eigenray (0: a shadow zone; the range stops where it was).
    """
    return _slant_range()(zs, zr, tau, start, nodes, speeds)


@lru_cache(maxsize=1)
def _ray_bending() -> ca.Function:
    """``(zt, zr, range, nodes, speeds) -> (bending, valid)``: see :func:`ray_bending`."""
    zt, zr, rho = ca.MX.sym("zt"), ca.MX.sym("zr"), ca.MX.sym("range")
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    dz = zr - zt
    x = ca.sqrt(ca.fmax(rho * rho - dz * dz, 0.0))
    _t, launch, _arrival, kind = _direct_first()(zt, zr, x, nodes, speeds)
    found = kind > 0
    bending = ca.if_else(found, ca.atan2(dz, x) - launch, 0.0)
    return ca.Function("sblsim_ray_bending", [zt, zr, rho, nodes, speeds], [bending, found],
                       ["zt", "zr", "range", "nodes", "speeds"], ["bending", "valid"], {"never_inline": True})


def ray_bending(zt, zr, rho, nodes, speeds):
    """The bending of the direct eigenray between a transceiver at depth ``zt`` and a target at depth ``zr`` at the
    slant range ``rho``: the chord's elevation minus the eigenray's grazing angle at the transceiver, the angle by
    which USBL processing with a measured profile turns a direction of arrival in its vertical plane to the chord
    (a range-independent profile keeps the eigenray in that plane). It is computed from the range and the depth,
    which the packet carries to centimetres, not from the measured elevation: a ray traced from a noisy shallow
    elevation would amplify its noise near the turning angles.

    Parameters
    ----------
    zt, zr : casadi.SX
        Depth of the transceiver and of the target [m] (positive down).
    rho : casadi.SX
        Slant range [m] (the straight chord's length, :func:`slant_range`).
    nodes, speeds : casadi.SX, shape (NODES, 1)
        The padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).

    Returns
    -------
    bending : casadi.SX
        ``atan2(zr − zt, X) − θ_launch`` [rad] (``X = √(ρ² − Δz²)``, θ_launch the direct eigenray's grazing angle
        at the transceiver, positive down, :func:`first_arrival`); 0 where no direct eigenray exists.
    valid : casadi.SX
        1 when the direct eigenray exists (0: a shadow zone).
    """
    return _ray_bending()(zt, zr, rho, nodes, speeds)


__all__ = ["RANGE_ITERATIONS", "ray_bending", "slant_range"]
