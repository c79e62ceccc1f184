"""A ray's integrals through the c-linear layers of a sound-speed profile, and the solve of a family's eigenray.

The profile is the channel's sound-speed table (:data:`~sblsim.models.acoustics.sound_speed.PROFILE`) as
:func:`~sblsim.models.acoustics.sound_speed.profile_nodes` pads it: the speed is **linear in depth** between
the nodes (Bellhop's ``'C'``, c-linear, interpolation) and constant above the first row and below the last
(the end speeds extended). Snell's invariant ``ξ = cos θ / c(z)`` (θ the grazing angle) is constant along a
ray; in a layer where ``c = c_0 + g (z − z_0)`` the ray is a circular arc of radius ``1 / (ξ |g|)`` and, with
``s = sin θ = √(1 − ξ² c²)``, its horizontal distance and travel time between speeds ``c_a`` and ``c_b`` are

    x = (s_a − s_b) / (ξ g) = ξ Δz (c_a + c_b) / (s_a + s_b),
    t = ln[c_b (1 + s_a) / (c_a (1 + s_b))] / g = Δz [φ(u) / c_a + φ(v) ξ² (c_a + c_b) / ((s_a + s_b)(1 + s_b))],

with ``u = (c_b − c_a) / c_a``, ``v = (s_a − s_b) / (1 + s_b)`` and ``φ(v) = ln(1 + v) / v`` (→ 1): the second
forms hold for every gradient, zero included (Jensen, Kuperman, Porter, Schmidt, *Computational Ocean
Acoustics*, 2nd ed., Springer 2011, ch. 3.3-3.4).

A family of rays between depths ``z_a ≤ z_b`` is parametrized by ``q``, the signed sine of the grazing angle
at the reference speed ``c_ref`` (``ξ = √(1 − q²) / c_ref``); its horizontal range ``X(q)`` is the sum of the
layers' arcs over ``[z_a, z_b]`` once and over a second interval twice (the families:
:mod:`~sblsim.models.acoustics.direct_family`, :mod:`~sblsim.models.acoustics.reflected_families`). The layer
sums (:func:`_layers`: range, time and the range's derivative; :func:`_tube`: the ray tube's terms and the arc
length) evaluate a layer only where the ray crosses it.

``X`` decreases from its largest value at the family's flattest ray ``q_lo`` to 0 at ``q = 1`` (vertical) (the
surface duct's turning ray: over its own bracket, in whichever direction ``X`` runs). The eigenray solves
``X(q) = X_target`` by a bracketed Newton iteration (a Newton step that leaves the bracket is replaced by
bisection) with a fixed number of iterations (:data:`NEWTON_ITERATIONS`), so the solve is one casadi
expression for the local engine and the generated C alike. A target beyond ``X(q_lo)`` has no eigenray of that
family (``valid`` false). The travel time is taken at the stationary point, ``τ = T(q) + ξ (X_target − X(q))``
(``dT/dX = ξ`` along the family, Fermat), so that a residual error in ``q`` enters the time only to second
order; isovelocity water gives the straight line to round-off.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca

from sblsim.models.acoustics.sound_speed import NODES
from sblsim.models.expressions import switch

#: Bracketed-Newton iterations of every eigenray solve (fixed: the solve is a closed casadi expression).
NEWTON_ITERATIONS = 24
_BIG = 1e7
#: Floor of a square root's argument: finite derivatives at a grazing point.
_TINY = 1e-300


def _phi(v):
    """``ln(1 + v) / v``, 1 at v = 0 (a series near 0)."""
    small = ca.fabs(v) < 1e-5
    safe = ca.if_else(small, 1.0, v)
    return ca.if_else(small, 1.0 - v / 2.0 + v * v / 3.0, ca.log1p(safe) / safe)


def _psi(w):
    """``asin(w) / w``, 1 at w = 0 (a series near 0)."""
    small = ca.fabs(w) < 1e-4
    safe = ca.if_else(small, 1.0, w)
    return ca.if_else(small, 1.0 + w * w / 6.0, ca.asin(safe) / safe)


def _sine(c, cref, k):
    """``sin θ = √(1 − ξ² c²)`` at speed ``c`` with ``ξ² c_ref² = k`` (floored at 0 beyond a turning point)."""
    return ca.sqrt(ca.fmax((cref - c) * (cref + c) + (1.0 - k) * c * c, _TINY)) / cref


def _piece(q, cref, u, v, z0, z1, c0, c1):
    """Horizontal distance [m], travel time [s], the distance over ``√(1 − q²)`` [m] and the arc length [m] of a
    ray ``(q, c_ref)`` over ``[u, v] ∩ [z0, z1]`` of a c-linear layer, cut where the ray turns (``c = 1/ξ``)."""
    k = 1.0 - q * q
    g = (c1 - c0) / (z1 - z0)
    a = ca.fmax(z0, u)
    b = ca.fmax(a, ca.fmin(z1, v))
    ca_, cb_ = c0 + g * (a - z0), c0 + g * (b - z0)
    blocked_a, blocked_b = k * ca_ * ca_ > cref * cref, k * cb_ * cb_ > cref * cref
    turn_c = cref / ca.sqrt(ca.fmax(k, 1e-300))
    turn_z = ca.fmin(ca.fmax(z0 + (turn_c - c0) / ca.if_else(g == 0, 1.0, g), a), b)
    a2 = ca.if_else(blocked_a, ca.if_else(blocked_b, b, turn_z), a)
    b2 = ca.if_else(blocked_b, ca.if_else(blocked_a, b, turn_z), b)
    ca2 = ca.if_else(blocked_a, turn_c, ca_)
    cb2 = ca.if_else(blocked_b, turn_c, cb_)
    dz = b2 - a2
    ca2 = ca.if_else(dz > 0, ca2, c0)  # an empty piece: finite values, zero length
    cb2 = ca.if_else(dz > 0, cb2, c0)
    # exactly 0 where the ray turns (the square root of a rounded zero would be ~1e-8, a noise of mm in X)
    sa = ca.if_else(ca.logic_and(blocked_a, dz > 0), 0.0, _sine(ca2, cref, k))
    sb = ca.if_else(ca.logic_and(blocked_b, dz > 0), 0.0, _sine(cb2, cref, k))
    xi = ca.sqrt(ca.fmax(k, _TINY)) / cref
    ssum = ca.fmax(sa + sb, 1e-12)
    x = xi * dz * (ca2 + cb2) / ssum
    t = dz * (_phi((cb2 - ca2) / ca2) / ca2
              + _phi((sa - sb) / (1.0 + sb)) * xi * xi * (ca2 + cb2) / (ssum * (1.0 + sb)))
    # the range over ξ c_ref = √(1 − q²): smooth up to the vertical ray (q = 1), where x itself has an infinite slope
    reduced = dz * (ca2 + cb2) / (cref * ssum)
    # the arc length ∫ dz / sin θ = (θ_a − θ_b) / (ξ g) = ψ(w) Δz (c_a + c_b) / (c_b s_a + c_a s_b), with
    # w = ξ (c_b s_a − c_a s_b) = sin(θ_a − θ_b) and ψ(w) = asin(w) / w (every gradient, zero included)
    w = ca.fmin(ca.fmax(xi * (cb2 * sa - ca2 * sb), -1.0), 1.0)
    length = _psi(w) * dz * (ca2 + cb2) / ca.fmax(cb2 * sa + ca2 * sb, _TINY)
    return x, t, reduced, length


def _summed_over_layers(name: str, layer: ca.Function) -> ca.Function:
    """``(q, fold, cref, u1, v1, u2, v2, nodes, speeds) -> sums``: each output of ``layer`` (a layer's terms,
    ``(q, fold, cref, u1, v1, u2, v2, z0, z1, c0, c1) -> terms``) summed over the NODES − 1 layers of the padded
    profile, a layer's terms evaluated only where the ray crosses it.

    :func:`_piece` clips ``[u, v]`` to ``[z0, z1]``; where ``min(z1, v) ≤ max(z0, u)`` for both pieces the clipped
    thickness is exactly 0 and every term is a product with it, a zero, which leaves each sum as it is. Most of the
    layers are such: a short table's padding, and every layer above or below the ray's depths; the generated C
    skips them (:func:`~sblsim.models.expressions.switch`).
    """
    terms = [ca.MX.sym(layer.name_in(k)) for k in range(layer.n_in())]
    _q, _fold, _cref, u1, v1, u2, v2, z0, z1, _c0, _c1 = terms
    crossed = ca.logic_or(ca.fmin(z1, v1) > ca.fmax(z0, u1), ca.fmin(z1, v2) > ca.fmax(z0, u2))
    outside = ca.Function(f"{layer.name()}_outside", terms, [ca.MX.zeros(layer.sparsity_out(k))
                                                            for k in range(layer.n_out())])
    chosen = switch(f"{layer.name()}_where", [outside, layer])
    crossed_only = ca.Function(f"{layer.name()}_crossed", terms, chosen.call([crossed, *terms]))
    mapped = crossed_only.map(NODES - 1, "serial")
    args = [ca.MX.sym(n) for n in ("q", "fold", "cref", "u1", "v1", "u2", "v2")]
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    out = mapped(*args, nodes[:-1].T, nodes[1:].T, speeds[:-1].T, speeds[1:].T)
    return ca.Function(name, args + [nodes, speeds], [ca.sum2(o) for o in out], {"never_inline": True})


@lru_cache(maxsize=1)
def _layers() -> ca.Function:
    """``(q, fold, cref, u1, v1, u2, v2, nodes, speeds) -> (X, T, dX/dq)``: a ray's range [m] and time [s]
    over ``[u1, v1]`` once and ``[u2, v2]`` twice (when ``fold`` or ``q < 0``), summed over the layers."""
    q, fold, cref = ca.SX.sym("q"), ca.SX.sym("fold"), ca.SX.sym("cref")
    u1, v1, u2, v2 = ca.SX.sym("u1"), ca.SX.sym("v1"), ca.SX.sym("u2"), ca.SX.sym("v2")
    z0, z1, c0, c1 = ca.SX.sym("z0"), ca.SX.sym("z1"), ca.SX.sym("c0"), ca.SX.sym("c1")
    x1, t1, _f1, _l1 = _piece(q, cref, u1, v1, z0, z1, c0, c1)
    x2, t2, _f2, _l2 = _piece(q, cref, u2, v2, z0, z1, c0, c1)
    w2 = ca.if_else(ca.logic_or(fold > 0.5, q < 0), 2.0, 0.0)
    x, t = x1 + w2 * x2, t1 + w2 * t2
    layer = ca.Function("sblsim_ray_layer", [q, fold, cref, u1, v1, u2, v2, z0, z1, c0, c1],
                        [x, t, ca.jacobian(x, q)])
    return _summed_over_layers("sblsim_ray_sums", layer)


@lru_cache(maxsize=1)
def _tube() -> ca.Function:
    """``(q, fold, cref, u1, v1, u2, v2, nodes, speeds) -> (F, dF/dq, S)``: a ray's range over ``√(1 − q²)``
    (``X = √(1 − q²) F``) [m], its derivative in ``q`` [m] and its arc length [m], summed over the layers as
    :func:`_layers` sums the range."""
    q, fold, cref = ca.SX.sym("q"), ca.SX.sym("fold"), ca.SX.sym("cref")
    u1, v1, u2, v2 = ca.SX.sym("u1"), ca.SX.sym("v1"), ca.SX.sym("u2"), ca.SX.sym("v2")
    z0, z1, c0, c1 = ca.SX.sym("z0"), ca.SX.sym("z1"), ca.SX.sym("c0"), ca.SX.sym("c1")
    _x1, _t1, f1, s1 = _piece(q, cref, u1, v1, z0, z1, c0, c1)
    _x2, _t2, f2, s2 = _piece(q, cref, u2, v2, z0, z1, c0, c1)
    w2 = ca.if_else(ca.logic_or(fold > 0.5, q < 0), 2.0, 0.0)
    f, arc = f1 + w2 * f2, s1 + w2 * s2
    layer = ca.Function("sblsim_ray_tube_layer", [q, fold, cref, u1, v1, u2, v2, z0, z1, c0, c1],
                        [f, ca.jacobian(f, q), arc])
    return _summed_over_layers("sblsim_ray_tube", layer)


@lru_cache(maxsize=1)
def _speed() -> ca.Function:
    """``(z, nodes, speeds) -> c``: the c-linear profile (constant beyond the end nodes)."""
    f = ca.interpolant("sblsim_ray_speed_table", "linear", [NODES], 1)
    z, nodes, speeds = ca.MX.sym("z"), ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    inside = ca.fmin(ca.fmax(z, nodes[0]), nodes[NODES - 1])
    return ca.Function("sblsim_ray_speed", [z, nodes, speeds], [f(inside, nodes, speeds)])


def sound_speed_at(z, nodes, speeds):
    """The c-linear profile's speed [m/s] at depth ``z`` [m] (constant beyond the end nodes): ``nodes``, ``speeds``
    (NODES, 1) as :func:`~sblsim.models.acoustics.sound_speed.node_speeds` pads them."""
    return _speed()(z, nodes, speeds)


def _interval_max(u, v, nodes, speeds):
    """The fastest speed over ``[u, v]`` [m/s] (its ends and the nodes inside)."""
    c = _speed()
    inside = ca.logic_and(nodes > u, nodes < v)
    return ca.fmax(ca.fmax(c(u, nodes, speeds), c(v, nodes, speeds)), ca.mmax(inside * speeds))


def _solve(target, q_lo, q0, fold, cref, u1, v1, u2, v2, nodes, speeds):
    """The eigenray of a family: ``(τ, q, valid)`` by bracketed Newton on ``q ∈ [q_lo, 1]``."""
    sums = _layers()
    x_lo = sums(q_lo, fold, cref, u1, v1, u2, v2, nodes, speeds)[0]
    valid = ca.logic_not(x_lo < target)  # NaN or infinite: the family reaches every range
    lo, hi = q_lo, 1.0
    q = ca.fmin(ca.fmax(q0, lo), hi)
    for _ in range(NEWTON_ITERATIONS):
        x, _t, dx = sums(q, fold, cref, u1, v1, u2, v2, nodes, speeds)
        r = x - target
        lo, hi = ca.if_else(r > 0, q, lo), ca.if_else(r > 0, hi, q)
        step = ca.if_else(r == 0, q, q - r / dx)
        ok = ca.logic_and(step >= lo, step <= hi)  # false for NaN
        q = ca.if_else(ok, step, 0.5 * (lo + hi))
    x, t, _dx = sums(q, fold, cref, u1, v1, u2, v2, nodes, speeds)
    xi = ca.sqrt(1.0 - q * q) / cref
    return t + xi * (target - x), q, valid


def _angle(z, q, cref, nodes, speeds):
    """Grazing angle [rad] (unsigned) of the ray ``(q, c_ref)`` at depth ``z``."""
    c = _speed()(z, nodes, speeds)
    k = 1.0 - q * q
    return ca.atan2(ca.sqrt(ca.fmax((cref - c) * (cref + c) + (1.0 - k) * c * c, 0.0)), ca.sqrt(k) * c)


def _peak_down(zb, depth, nodes, speeds):
    """The bottom [m] of the region below ``zb`` over which the speed keeps increasing downward (from the first node
    below ``zb``): the first node below ``zb`` with no faster node under it, at most the water depth ``depth`` (when
    it is set, > 0)."""
    down_flag = ca.vertcat(speeds[1:] <= speeds[:-1], 1.0)  # the next node down is not faster
    below = nodes > zb
    peak_down = -ca.mmax(ca.if_else(ca.logic_and(below, down_flag), -nodes, -_BIG))
    return ca.if_else(depth > 0, ca.fmin(peak_down, ca.fmax(depth, zb)), peak_down)



__all__ = ["NEWTON_ITERATIONS", "sound_speed_at"]
