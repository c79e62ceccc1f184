"""The reflected families' eigenrays: surface-reflected (with a surface duct's turning ray) and bottom-reflected.

In the ray integrals of :mod:`~sblsim.models.acoustics.ray_integrals`:

* **surface-reflected** (``arrival`` 2): ``[0, z_a]`` twice (the path unfolded at the surface), ``c_ref`` the
  fastest speed over ``[0, z_b]``, ``q ≥ 0`` (no turning before the surface). In a **surface duct** (the speed below
  ``z_b`` climbing above ``c_ref``) also the ray reflected at the surface that **turns** below ``z_b``: it covers
  ``[0, z_a]`` twice, ``[z_a, z_b]`` once and ``[z_b, z_t]`` twice (``z_t`` where ``c = 1/ξ``, inside the region
  below ``z_b`` where the speed keeps increasing, bounded by the water depth; its bottom's speed ``c_peak``), the
  same ``c_ref`` and ``q ∈ [0, √(1 − (c_ref / c_peak)²)]``: from the plain family's flattest ray to the ray
  grazing the region's bottom. It leaves the shallower end upward and the deeper end downward. The family's
  eigenray is the earliest valid of the two; where no duct exists only the plain one is solved;
* **bottom-reflected** (3): ``[z_b, D]`` twice, ``D`` the water depth, ``c_ref`` the fastest over
  ``[z_a, D]``.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca

from sblsim.models.acoustics.ray_integrals import (
    NEWTON_ITERATIONS,
    _angle,
    _interval_max,
    _layers,
    _peak_down,
    _solve,
    _speed,
)
from sblsim.models.acoustics.sound_speed import NODES
from sblsim.models.acoustics.spreading_loss import _tube_loss
from sblsim.models.expressions import switch


def _reflected(zs, zr, target, depth, nodes, speeds, bottom: bool):
    """The surface- (``bottom`` false) or bottom-reflected eigenray: ``(τ, launch, arrival, valid, ray)`` (as
    :func:`_direct`)."""
    za, zb = ca.fmin(zs, zr), ca.fmax(zs, zr)
    if bottom:
        u2, v2, span_lo, span_hi = zb, depth, za, depth
        fits = depth >= zb
        image = 2.0 * depth - zs - zr
    else:
        u2, v2, span_lo, span_hi = 0.0, za, 0.0, zb
        fits = za >= 0
        image = zs + zr
    cref = _interval_max(span_lo, span_hi, nodes, speeds)
    q0 = image / ca.fmax(ca.sqrt(image * image + target * target), 1e-300)
    tau, q, valid = _solve(target, 0.0, q0, 1.0, cref, za, zb, u2, v2, nodes, speeds)
    ts, tr = _angle(zs, q, cref, nodes, speeds), _angle(zr, q, cref, nodes, speeds)
    sign = 1.0 if bottom else -1.0
    return (tau, sign * ts, -sign * tr, ca.logic_and(valid, ca.logic_and(fits, depth > 0)),
            (q, 1.0, cref, za, zb, u2, v2, image, 0.0))


def _surface_turning(zs, zr, target, depth, nodes, speeds):
    """The surface-reflected eigenray that also turns below the deeper end (a surface duct): ``(τ, launch, arrival,
    valid, ray)`` (as :func:`_direct`; ``ray`` has two more items, the interval it covers twice beyond the deeper
    end).

    Unfolded at the surface, the ray covers ``[0, z_a]`` twice, ``[z_a, z_b]`` once and ``[z_b, z_t]`` twice, ``z_t``
    its turning depth (``c = 1/ξ``) inside the region below ``z_b`` where the speed keeps increasing
    (:func:`_peak_down`, bounded by the water depth). ``c_ref`` is the fastest speed over ``[0, z_b]`` (as for the
    plain surface-reflected ray) and ``q ∈ [0, q_hi]``: from the ray horizontal at ``c_ref`` (``q = 0``, where the
    plain surface family ends) to the ray turning at the bottom of that region, ``c_peak``
    (``q_hi = √(1 − (c_ref / c_peak)²)``); none where ``c_peak ≤ c_ref``. The eigenray exists when ``X(0)`` and
    ``X(q_hi)`` bracket the target; it is found by the bracketed Newton iteration of :func:`_solve` in whichever
    direction ``X`` runs over the bracket. It leaves the shallower end upward and the deeper end downward."""
    c = _speed()
    za, zb = ca.fmin(zs, zr), ca.fmax(zs, zr)
    cref = _interval_max(0.0, zb, nodes, speeds)
    peak = _peak_down(zb, depth, nodes, speeds)
    c_peak = c(peak, nodes, speeds)
    q_hi = ca.sqrt(ca.fmax(1.0 - (cref / c_peak) ** 2, 0.0))
    sums = _layers()

    def total(q):
        x1, t1, d1 = sums(q, 1.0, cref, za, zb, 0.0, za, nodes, speeds)
        x2, t2, d2 = sums(q, 1.0, cref, zb, zb, zb, peak, nodes, speeds)
        return x1 + x2, t1 + t2, d1 + d2

    x_lo, x_hi = total(0.0)[0], total(q_hi)[0]
    rising = x_hi > x_lo
    bracket = ca.logic_and(ca.fmin(x_lo, x_hi) <= target, ca.fmax(x_lo, x_hi) >= target)  # false for NaN
    valid = ca.logic_and(ca.logic_and(bracket, q_hi > 0),
                         ca.logic_and(ca.logic_and(za >= 0, depth >= zb), depth > 0))
    lo, hi = 0.0, q_hi
    span = x_hi - x_lo
    q = ca.fmin(ca.fmax(q_hi * (target - x_lo) / ca.if_else(span == 0, 1.0, span), lo), hi)
    for _ in range(NEWTON_ITERATIONS):
        x, _t, dx = total(q)
        r = x - target
        past = ca.if_else(rising, r > 0, r < 0)  # the eigenray lies between lo and q
        lo, hi = ca.if_else(past, lo, q), ca.if_else(past, q, hi)
        step = ca.if_else(r == 0, q, q - r / dx)
        ok = ca.logic_and(step >= lo, step <= hi)  # false for NaN
        q = ca.if_else(ok, step, 0.5 * (lo + hi))
    x, t, _dx = total(q)
    xi = ca.sqrt(1.0 - q * q) / cref
    tau = t + xi * (target - x)
    ts, tr = _angle(zs, q, cref, nodes, speeds), _angle(zr, q, cref, nodes, speeds)
    # up from the shallower end, down from the deeper one (at equal depths: the ray leaving upward)
    up_first = zs <= zr
    launch = ca.if_else(up_first, -ts, ts)
    arrival = ca.if_else(up_first, -tr, tr)
    return tau, launch, arrival, valid, (q, 1.0, cref, za, zb, 0.0, za, zs + zr, 0.0, zb, peak)


def _duct(zs, zr, depth, nodes, speeds):
    """True where a surface-reflected ray can also turn below the deeper end: a water depth is set and the speed
    below the deeper end climbs above the fastest over ``[0, z_b]`` (:func:`_surface_turning`)."""
    zb = ca.fmax(zs, zr)
    c_peak = _speed()(_peak_down(zb, depth, nodes, speeds), nodes, speeds)
    return ca.logic_and(depth > 0, c_peak > _interval_max(0.0, zb, nodes, speeds))


def _earliest(plain, turning):
    """The earliest valid of two eigenrays of one family, each ``(τ, launch, arrival, valid, ...)``: the row of the
    chosen one, valid if either is."""
    better = ca.logic_and(turning[3], ca.logic_or(ca.logic_not(plain[3]), turning[0] < plain[0]))
    out = [ca.if_else(better, b, a) for a, b in zip(plain, turning)]
    out[3] = ca.logic_or(plain[3], turning[3])
    return out


@lru_cache(maxsize=2)
def _surface_family(paths: bool) -> ca.Function:
    """``(zs, zr, x, depth, nodes, speeds) -> (tau, launch, arrival, valid[, spreading, length])``: the surface family's
    eigenray, the earliest valid of the plain surface-reflected one (:func:`_reflected`) and the one that also turns
    (:func:`_surface_turning`); the latter solved only where a surface duct exists (:func:`_duct`, a switch: elsewhere
    the plain one alone is evaluated, in the generated C too). With ``paths``, its spreading and length
    (:func:`_tube_loss`)."""
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    args = [zs, zr, x, depth, nodes, speeds]
    names = ["tau", "launch", "arrival", "valid"] + (["spreading", "length"] if paths else [])

    def row(r):
        return list(r[:4]) + (list(_tube_loss(zs, zr, x, r[4], nodes, speeds)) if paths else [])

    plain = row(_reflected(zs, zr, x, depth, nodes, speeds, False))
    turning = row(_surface_turning(zs, zr, x, depth, nodes, speeds))
    tag = "paths" if paths else "families"
    alone = ca.Function(f"sblsim_ray_surface_{tag}_plain", args, plain)
    both = ca.Function(f"sblsim_ray_surface_{tag}_duct", args, _earliest(plain, turning))
    chosen = switch(f"sblsim_ray_surface_{tag}", [alone, both])
    out = chosen(_duct(zs, zr, depth, nodes, speeds), *args)
    return ca.Function(f"sblsim_ray_surface_{tag}", args, out, ["zs", "zr", "x", "depth", "nodes", "speeds"], names,
                       {"never_inline": True})
