"""Eigenrays in a range-independent sound-speed profile: direct, surface- and bottom-reflected.

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
layers' arcs over ``[z_a, z_b]`` once and over a second interval twice:

* **direct** (``arrival`` 1): ``c_ref`` is the faster end. ``q ≥ 0``: the ray runs monotonically from one
  end to the other; ``q < 0``: it leaves the faster end away from the other, **turns** where ``c = 1/ξ``
  (inside the region beyond that end where the speed keeps increasing, bounded by the surface and the
  water depth) and comes back. If the speed between the ends exceeds both, rays flatter than the one
  grazing that maximum cannot pass: beyond that ray's range lies a **shadow zone** (no direct eigenray);
* **surface-reflected** (2): ``[0, z_a]`` twice (the path unfolded at the surface), ``c_ref`` the fastest
  speed over ``[0, z_b]``, ``q ≥ 0`` (no turning before the surface). In a **surface duct** (the speed below
  ``z_b`` climbing above ``c_ref``) also the ray reflected at the surface that **turns** below ``z_b``: it covers
  ``[0, z_a]`` twice, ``[z_a, z_b]`` once and ``[z_b, z_t]`` twice (``z_t`` where ``c = 1/ξ``, inside the region
  below ``z_b`` where the speed keeps increasing, bounded by the water depth; its bottom's speed ``c_peak``), the
  same ``c_ref`` and ``q ∈ [0, √(1 − (c_ref / c_peak)²)]``: from the plain family's flattest ray to the ray
  grazing the region's bottom. It leaves the shallower end upward and the deeper end downward. The family's
  eigenray is the earliest valid of the two; where no duct exists only the plain one is solved;
* **bottom-reflected** (3): ``[z_b, D]`` twice, ``D`` the water depth, ``c_ref`` the fastest over
  ``[z_a, D]``.

``X`` decreases from its largest value at the family's flattest ray ``q_lo`` to 0 at ``q = 1`` (vertical) (the
surface duct's turning ray: over its own bracket, in whichever direction ``X`` runs). The eigenray solves
``X(q) = X_target`` by a bracketed Newton iteration (a Newton step that leaves the bracket is replaced by
bisection) with a fixed number of iterations (:data:`NEWTON_ITERATIONS`), so the solve is one casadi
expression for the local engine and the generated C alike. A target beyond ``X(q_lo)`` has no eigenray of that
family (``valid`` false). The travel time is taken at the stationary point, ``τ = T(q) + ξ (X_target − X(q))``
(``dT/dX = ξ`` along the family, Fermat), so that a residual error in ``q`` enters the time only to second
order; isovelocity water gives the straight line to round-off.

Angles are grazing angles [rad], positive when the ray travels downward (toward greater depth): the launch
angle at the source, the arrival angle at the receiver, in the direction of travel (Bellhop's sign).

What is not modelled: rays that turn more than once, or that pass over a local maximum of the speed beyond
the faster end and turn further away (they come back only after long excursions; not within the few km of
a positioning system in the profiles sblsim ships), reflected rays that turn otherwise than the surface duct's
above (a surface-reflected ray leaving the shallower end downward, crossing ``[z_a, z_b]`` three times, or
turning before it reaches the surface; a bottom-reflected ray that turns), range-dependent profiles and
bathymetry. Where ``X(q)`` is not monotonic (several eigenrays of one family) the solve returns one of
them.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS, NODES, node_speeds
from sblsim.models.expressions import switch

#: Bracketed-Newton iterations of every eigenray solve (fixed: the solve is a closed casadi expression).
NEWTON_ITERATIONS = 24
#: Eigenray families: the ``arrival`` codes of the channel's time series (0: none); ``OTHER``: the earliest other
#: eigenray of the direct family (a ray turning beyond the faster end, or the straight one where the solve's own is
#: a turning ray), no boundary met.
DIRECT, SURFACE, BOTTOM, OTHER = 1, 2, 3, 4
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


def _direct(zs, zr, target, depth, nodes, speeds, found: bool = True, others: bool = False):
    """The direct eigenray: ``(τ, launch, arrival, valid, ray)``, ``ray`` the solved ray for :func:`_tube_loss`
    (``q, fold, c_ref, u1, v1, u2, v2``, the isovelocity image's vertical extent and whether the path is level).

    With ``found`` it is valid also where the solve ends on a root although the flattest ray falls short of the
    target (``X(q)`` not monotonic); without it, only where ``X(q_lo)`` reaches the target (the receivers'
    inversion, :func:`slant_range`, as it was). With ``others``, a pair: that eigenray and the earliest other
    eigenray of the family (:func:`_other_function`), each ``(τ, launch, arrival, valid, ray)``."""
    c = _speed()
    za, zb = ca.fmin(zs, zr), ca.fmax(zs, zr)
    c_a, c_b = c(za, nodes, speeds), c(zb, nodes, speeds)
    inside = ca.logic_and(nodes > za, nodes < zb)
    c_int = ca.mmax(inside * speeds)
    # the regions beyond each end over which the speed keeps increasing away from it (bounded by the
    # surface above and the water depth below): a ray leaving that end outward turns there
    up_flag = ca.vertcat(1.0, speeds[:-1] <= speeds[1:])  # the next node up is not faster
    above, below = nodes < za, nodes > zb
    near_up = ca.mmax(ca.if_else(above, nodes, -_BIG))
    near_down = -ca.mmax(ca.if_else(below, -nodes, -_BIG))
    peak_up = ca.fmax(ca.mmax(ca.if_else(ca.logic_and(above, up_flag), nodes, -_BIG)), ca.fmin(0.0, za))
    peak_down = _peak_down(zb, depth, nodes, speeds)
    grows_up = c(near_up, nodes, speeds) > c_a
    grows_down = c(near_down, nodes, speeds) > c_b
    c_up = ca.if_else(grows_up, c(peak_up, nodes, speeds), c_a)
    c_down = ca.if_else(grows_down, c(peak_down, nodes, speeds), c_b)
    use_up = ca.logic_or(c_a > c_b, ca.logic_and(c_a == c_b, c_up > c_a))
    cref = ca.if_else(use_up, c_a, c_b)
    c_peak = ca.if_else(use_up, c_up, c_down)
    blocked = c_int > cref  # a faster layer between the ends: flatter rays cannot pass
    q_lo = ca.if_else(blocked, ca.sqrt(ca.fmax(1.0 - (cref / c_int) ** 2, 0.0)),
                      -ca.sqrt(ca.fmax(1.0 - (cref / c_peak) ** 2, 0.0)))
    u2 = ca.if_else(use_up, peak_up, zb)
    v2 = ca.if_else(use_up, za, peak_down)
    dz = zb - za
    q0 = dz / ca.fmax(ca.sqrt(dz * dz + target * target), 1e-300)
    tau, q, valid = _solve(target, q_lo, q0, 0.0, cref, za, zb, u2, v2, nodes, speeds)
    if found:
        # X(q) need not decrease over the turning rays: where X(q_lo) falls short of the target the iteration may
        # still end on a root (e.g. the straight ray when the surface-grazing ray lands short of it)
        valid = ca.logic_or(valid, _lands(target, q, cref, za, zb, u2, v2, nodes, speeds))
    # a level path in water of constant speed around it: the horizontal ray (X(q) = 0 for every q ≥ 0)
    flat = ca.logic_or(c(za - 1e-3, nodes, speeds) == c_a, c(za + 1e-3, nodes, speeds) == c_a)
    valid = ca.logic_or(valid, ca.logic_and(zb - za == 0, ca.logic_and(flat, q_lo == 0)))
    launch, arrival = _direct_angles(zs, zr, q, cref, use_up, nodes, speeds)
    level = ca.logic_and(zb - za == 0, ca.logic_and(flat, q_lo == 0))
    ray = (q, 0.0, cref, za, zb, u2, v2, dz, level)
    if not others:
        return tau, launch, arrival, valid, ray
    o_tau, o_q, o_valid = _other_function()(target, cref, q_lo, use_up, za, zb, u2, v2, q, valid, nodes, speeds)
    o_launch, o_arrival = _direct_angles(zs, zr, o_q, cref, use_up, nodes, speeds)
    other = (o_tau, o_launch, o_arrival, o_valid, (o_q, 0.0, cref, za, zb, u2, v2, dz, 0.0))
    return (tau, launch, arrival, valid, ray), other


def _direct_angles(zs, zr, q, cref, use_up, nodes, speeds):
    """Launch and arrival grazing angles [rad] of the direct family's ray ``(q, c_ref)`` (positive downward)."""
    ts, tr = _angle(zs, q, cref, nodes, speeds), _angle(zr, q, cref, nodes, speeds)
    d = ca.sign(zr - zs)
    turning = q < 0
    # a turning ray leaves downward and arrives upward when it turns below, the reverse when above
    launch = ca.if_else(turning, ca.if_else(use_up, -ts, ts), d * ts)
    arrival = ca.if_else(turning, ca.if_else(use_up, tr, -tr), d * tr)
    return launch, arrival


#: A direct-family ray whose range is within this of the target [m] is an eigenray (the bracketed iteration ends
#: within nanometres of a root; a ray that turns short of the target misses it by metres or more).
LANDING = 1e-6


def _lands(target, q, cref, za, zb, u2, v2, nodes, speeds):
    """True where the direct-family ray ``q`` reaches the horizontal distance ``target`` within :data:`LANDING`."""
    x = _layers()(q, 0.0, cref, za, zb, u2, v2, nodes, speeds)[0]
    return ca.fabs(x - target) <= LANDING * ca.fmax(target, 1.0)


@lru_cache(maxsize=1)
def _other_function() -> ca.Function:
    """``(target, cref, q_lo, use_up, za, zb, u2, v2, q1, valid1, nodes, speeds) -> (τ, q, valid)``: the earliest
    eigenray of the direct family other than the one at ``q1`` (:func:`_direct`'s, when ``valid1``).

    ``X(q)`` is sampled at the rays turning at each end of the region beyond the faster end (``[u2, v2]``: the ray
    horizontal at the faster end, ``q = 0``, and the flattest, ``q_lo``) and at every node inside it; between two
    consecutive samples the ray turns inside one c-linear layer. Each interval between consecutive samples, and the
    rays that do not turn (``[max(q_lo, 0), 1]``, where ``X`` decreases to 0), is a bracket where ``X − target``
    changes sign; the one that holds ``q1`` is left out. Of the others the one whose time, interpolated linearly in
    ``X`` between its ends, is the earliest is solved by the bracketed Newton iteration of :func:`_solve`
    (:data:`NEWTON_ITERATIONS`, in whichever direction ``X`` runs over it), and its time taken at the stationary
    point as there. ``valid`` is false where no such bracket exists (a root pair inside one layer's interval, a
    caustic of that layer, is not resolved)."""
    names = ("target", "cref", "q_lo", "use_up", "za", "zb", "u2", "v2", "q1", "valid1")
    target, cref, q_lo, use_up, za, zb, u2, v2, q1, valid1 = (ca.MX.sym(n) for n in names)
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    sums = _layers()
    turns = q_lo < 0  # not blocked: rays leaving the faster end away from the other turn in [u2, v2]

    def q_at(cz):  # the ray turning where the speed is cz (0 at or below c_ref)
        return -ca.sqrt(ca.fmax(1.0 - (cref / ca.fmax(cz, cref)) ** 2, 0.0))

    # the samples at the nodes strictly inside the region (NaN elsewhere: no bracket; the generated C skips them)
    qs, inside = ca.MX.sym("qs"), ca.MX.sym("inside")
    rest = [cref, za, zb, u2, v2, nodes, speeds]
    rest_sym = [ca.MX.sym(f"r{k}", r.sparsity()) for k, r in enumerate(rest)]
    r_cref, r_za, r_zb, r_u2, r_v2, r_nodes, r_speeds = rest_sym
    at = ca.Function("sblsim_ray_other_sample", [qs, inside, *rest_sym],
                     list(sums(qs, 0.0, r_cref, r_za, r_zb, r_u2, r_v2, r_nodes, r_speeds)[:2]))
    nan = ca.Function("sblsim_ray_other_none", [qs, inside, *rest_sym], [ca.MX(np.nan), ca.MX(np.nan)])
    sample = switch("sblsim_ray_other_at", [nan, at])
    within = ca.logic_and(ca.logic_and(nodes > u2, nodes < v2), turns)
    q_nodes = ca.vertcat(*[q_at(speeds[k]) for k in range(NODES)])
    out = sample.map(NODES, "serial")(within.T, q_nodes.T, within.T, *rest)
    x_n, t_n = out[0].T, out[1].T
    # the region's ends: the upper one (u2) and the lower one (v2), each the faster end or the turning limit
    q_u, q_v = ca.if_else(use_up, q_lo, 0.0), ca.if_else(use_up, 0.0, q_lo)
    x_u, t_u = sums(q_u, 0.0, cref, za, zb, u2, v2, nodes, speeds)[:2]
    x_v, t_v = sums(q_v, 0.0, cref, za, zb, u2, v2, nodes, speeds)[:2]
    # intervals ending at each inside node (from the previous inside node, or from the upper end), then the last
    before = ca.vertcat(0.0, within[:-1])
    after = ca.vertcat(within[1:], 0.0)
    xa = ca.if_else(before, ca.vertcat(x_u, x_n[:-1]), x_u)
    ta = ca.if_else(before, ca.vertcat(t_u, t_n[:-1]), t_u)
    qa = ca.if_else(before, ca.vertcat(q_u, q_nodes[:-1]), q_u)
    last = ca.logic_and(within, ca.logic_not(after))
    any_inside = ca.mmax(within)
    x_last = ca.if_else(any_inside, ca.mmax(ca.if_else(last, x_n, -_BIG)), x_u)
    t_last = ca.if_else(any_inside, ca.mmax(ca.if_else(last, t_n, -_BIG)), t_u)
    q_last = ca.if_else(any_inside, ca.mmax(ca.if_else(last, q_nodes, -_BIG)), q_u)
    q_top = ca.fmax(q_lo, 0.0)
    x_top, t_top = sums(q_top, 0.0, cref, za, zb, u2, v2, nodes, speeds)[:2]
    x_end, t_end = sums(1.0, 0.0, cref, za, zb, u2, v2, nodes, speeds)[:2]
    xa = ca.vertcat(ca.if_else(within, xa, np.nan), x_last, x_top)
    ta = ca.vertcat(ta, t_last, t_top)
    qa = ca.vertcat(qa, q_last, q_top)
    xb = ca.vertcat(x_n, x_v, x_end)
    tb = ca.vertcat(t_n, t_v, t_end)
    qb = ca.vertcat(q_nodes, q_v, ca.DM(1.0))
    usable = ca.vertcat(within, turns, 1.0)
    bracket = ca.logic_and(ca.fmin(xa, xb) <= target, ca.fmax(xa, xb) >= target)  # false for NaN
    holds_q1 = ca.logic_and(valid1 > 0.5, ca.logic_and(ca.fmin(qa, qb) <= q1, ca.fmax(qa, qb) >= q1))
    span = xb - xa
    share = ca.if_else(span == 0, 0.0, (target - xa) / ca.if_else(span == 0, 1.0, span))
    estimate = ta + (tb - ta) * share
    candidate = ca.logic_and(ca.logic_and(usable, bracket), ca.logic_not(holds_q1))
    score = ca.if_else(candidate, estimate, _BIG)
    best = ca.mmin(score)
    valid = best < _BIG
    # the chosen bracket (the first of equal estimates)
    chosen = ca.logic_and(candidate, score == best)
    first = ca.logic_and(chosen, ca.cumsum(chosen) == 1)
    pick = [ca.dot(first, v) for v in (qa, qb, ca.if_else(candidate, xa, 0.0), ca.if_else(candidate, xb, 0.0))]
    lo, hi, x_lo, x_hi = (ca.if_else(valid, v, d) for v, d in zip(pick, (0.0, 1.0, 1.0, 0.0)))
    rising = x_hi > x_lo
    gap = x_hi - x_lo
    q = ca.fmin(ca.fmax(lo + (hi - lo) * (target - x_lo) / ca.if_else(gap == 0, 1.0, gap), ca.fmin(lo, hi)),
                ca.fmax(lo, hi))
    for _ in range(NEWTON_ITERATIONS):
        x, _t, dx = sums(q, 0.0, cref, za, zb, u2, v2, nodes, speeds)
        r = x - target
        past = ca.if_else(rising, r > 0, r < 0)  # the eigenray lies between lo and q
        lo, hi = ca.if_else(past, lo, q), ca.if_else(past, q, hi)
        step = ca.if_else(r == 0, q, q - r / dx)
        ok = ca.logic_and(step >= ca.fmin(lo, hi), step <= ca.fmax(lo, hi))  # false for NaN
        q = ca.if_else(ok, step, 0.5 * (lo + hi))
    x, t, _dx = sums(q, 0.0, cref, za, zb, u2, v2, nodes, speeds)
    xi = ca.sqrt(1.0 - q * q) / cref
    tau = t + xi * (target - x)
    valid = ca.logic_and(valid, ca.fabs(x - target) <= LANDING * ca.fmax(target, 1.0))
    return ca.Function("sblsim_ray_other", [target, cref, q_lo, use_up, za, zb, u2, v2, q1, valid1, nodes, speeds],
                       [tau, q, valid], [*names, "nodes", "speeds"], ["tau", "q", "valid"], {"never_inline": True})


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


@lru_cache(maxsize=1)
def eigenray_paths() -> ca.Function:
    """``(zs, zr, x, depth, nodes, speeds) -> (tau, launch, arrival, valid, spreading, length)``, each (3, 1): the
    eigenrays of :func:`eigenray_families` (the same first four outputs) with their geometric spreading and their
    length along the ray.

    Parameters (of the function)
    ----------------------------
    zs, zr, x, depth, nodes, speeds : as :func:`eigenray_families`.

    Returns (of the function)
    -------------------------
    tau, launch, arrival, valid : as :func:`eigenray_families`.
    spreading : the ray-tube geometric spreading loss [dB re 1 m] of each eigenray, ``−10 log10 |p/p0|²``
        (:func:`_tube_loss`: Jensen et al. 2011, ch. 3), capped at caustics (:data:`CAUSTIC_GAIN`), ≥ 0.
    length : its arc length along the ray [m] (closed form per c-linear layer).
    """
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    rows = [*_direct(zs, zr, x, depth, nodes, speeds, others=True), _reflected(zs, zr, x, depth, nodes, speeds, True)]
    rows = [r[:4] + _tube_loss(zs, zr, x, r[4], nodes, speeds) for r in rows]
    rows.insert(2, _surface_family(True)(zs, zr, x, depth, nodes, speeds))
    rows = [rows[0], rows[2], rows[3], rows[1]]
    out = [ca.vertcat(*[r[j] for r in rows]) for j in range(6)]
    return ca.Function("sblsim_eigenray_paths", [zs, zr, x, depth, nodes, speeds], out,
                       ["zs", "zr", "x", "depth", "nodes", "speeds"],
                       ["tau", "launch", "arrival", "valid", "spreading", "length"], {"never_inline": True})


@lru_cache(maxsize=1)
def eigenray_families() -> ca.Function:
    """``(zs, zr, x, depth, nodes, speeds) -> (tau, launch, arrival, valid)``, each (3, 1): the direct, the
    surface-reflected and the bottom-reflected eigenray (rows in that order).

    Parameters (of the function)
    ----------------------------
    zs, zr : depth of the source and of the receiver [m] (positive down).
    x : horizontal distance between them [m].
    depth : water depth [m]; 0: no boundary (the reflected rows are invalid).
    nodes, speeds : (NODES, 1) the padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).

    Returns (of the function)
    -------------------------
    tau [s], launch and arrival grazing angles [rad] (positive downward, in the direction of travel),
    valid (1: the eigenray exists; 0: shadow zone, or no boundary, and the other values are meaningless).
    """
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    direct, other = _direct(zs, zr, x, depth, nodes, speeds, others=True)
    rows = [direct, _surface_family(False)(zs, zr, x, depth, nodes, speeds),
            _reflected(zs, zr, x, depth, nodes, speeds, True), other]
    out = [ca.vertcat(*[r[j] for r in rows]) for j in range(4)]
    return ca.Function("sblsim_eigenray_families", [zs, zr, x, depth, nodes, speeds], out,
                       ["zs", "zr", "x", "depth", "nodes", "speeds"], ["tau", "launch", "arrival", "valid"],
                       {"never_inline": True})


def _first(tau, launch, arrival, valid):
    """The earliest valid arrival of (3, 1) families: ``(τ, launch, arrival, kind)``, kind 0 when none."""
    best_t, best_l, best_a, kind = ca.inf, 0.0, 0.0, 0.0
    for j in range(int(tau.numel())):
        better = ca.logic_and(valid[j] > 0.5, tau[j] < best_t)
        best_t = ca.if_else(better, tau[j], best_t)
        best_l = ca.if_else(better, launch[j], best_l)
        best_a = ca.if_else(better, arrival[j], best_a)
        kind = ca.if_else(better, j + 1.0, kind)
    return ca.if_else(kind > 0, best_t, 0.0), best_l, best_a, kind


@lru_cache(maxsize=1)
def _first_arrival_table() -> ca.Function:
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    direct, other = _direct(zs, zr, x, depth, nodes, speeds, others=True)
    # without boundaries: the direct family's two eigenrays (rows 1 and 4: the kinds DIRECT and OTHER)
    no_row = (0.0, 0.0, 0.0, 0.0)
    pair = [ca.vertcat(*v) for v in zip(direct[:4], no_row, no_row, other[:4])]
    direct_only = ca.Function("sblsim_ray_direct_only", [zs, zr, x, depth, nodes, speeds], list(_first(*pair)))
    families = eigenray_families()(zs, zr, x, depth, nodes, speeds)
    with_boundaries = ca.Function("sblsim_ray_bounded", [zs, zr, x, depth, nodes, speeds], list(_first(*families)))
    return switch("sblsim_ray_first", [direct_only, with_boundaries])


def _constant_rows(zs, zr, x, depth, c):
    """Isovelocity: the straight line and its images in the surface and the bottom, each ``(τ, launch, arrival,
    valid, L)`` with ``L`` the (image) path's length [m]."""
    rows = []
    for image, kind in ((zr - zs, DIRECT), (zs + zr, SURFACE), (2.0 * depth - zs - zr, BOTTOM)):
        length = ca.sqrt(x * x + image * image)
        angle = ca.atan2(image, x)
        # reflected: launched toward the boundary, arriving from it
        launch, arrival = (angle, angle) if kind == DIRECT else ((-angle, angle) if kind == SURFACE else
                                                                  (angle, -angle))
        valid = 1.0 if kind == DIRECT else ca.logic_and(depth > 0, ca.logic_and(
            zs >= 0, zr >= 0) if kind == SURFACE else ca.logic_and(depth >= zs, depth >= zr))
        rows.append((length / c, launch, arrival, valid, length))
    return rows


@lru_cache(maxsize=1)
def _first_arrival_constant() -> ca.Function:
    """Isovelocity: the straight line and its images in the surface and the bottom."""
    zs, zr, x, depth, c = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "c"))
    rows = _constant_rows(zs, zr, x, depth, c)
    out = _first(*[ca.vertcat(*[r[j] for r in rows]) for j in range(4)])
    return ca.Function("sblsim_ray_constant", [zs, zr, x, depth, c], list(out))


@lru_cache(maxsize=1)
def first_arrival_function() -> ca.Function:
    zs, zr, x, depth, c = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "c"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    args = [zs, zr, x, depth, c, nodes, speeds]
    const = ca.Function("sblsim_ray_isovelocity", args, _first_arrival_constant()(zs, zr, x, depth, c))
    table = ca.Function("sblsim_ray_table", args,
                        _first_arrival_table()(depth > 0, zs, zr, x, depth, nodes, speeds))
    return switch("sblsim_first_arrival", [const, table])


def first_arrival(use_table, zs, zr, x, depth, constant, nodes, speeds):
    """The earliest eigenray between two depths: ``(τ, launch, arrival, kind)``.

    Parameters
    ----------
    use_table : casadi.SX
        True (non-zero) for the table, false for the constant ``constant``.
    zs, zr : casadi.SX
        Depth of the source and of the receiver [m].
    x : casadi.SX
        Horizontal distance [m].
    depth : casadi.SX
        Water depth [m]; 0: no boundary, the direct eigenray only.
    constant : casadi.SX
        The sound speed of an empty table [m/s].
    nodes, speeds : casadi.SX, shape (NODES, 1)
        The padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).

    Returns
    -------
    tau : casadi.SX
        Travel time [s] of the earliest arrival (0 when none).
    launch, arrival : casadi.SX
        Its grazing angles [rad] at the source and at the receiver, positive downward.
    kind : casadi.SX
        1 direct, 2 surface-reflected, 3 bottom-reflected, 0 none (a shadow zone without boundaries).
    """
    return first_arrival_function()(use_table, zs, zr, x, depth, constant, nodes, speeds)


@lru_cache(maxsize=1)
def _arrivals() -> ca.Function:
    """``(use_table, zs, zr, x, depth, constant, nodes, speeds) -> (tau, launch, arrival, valid, spreading,
    length)``: see :func:`arrivals`."""
    zs, zr, x, depth, c = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "c"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    args = [zs, zr, x, depth, c, nodes, speeds]
    names = ["tau", "launch", "arrival", "valid", "spreading", "length"]
    rows = _constant_rows(zs, zr, x, depth, c)
    # isovelocity: one direct eigenray (the OTHER row invalid, zero)
    const = ca.Function("sblsim_arrivals_isovelocity", args,
                        [ca.vertcat(*[r[j] for r in rows], 0.0) for j in range(4)]
                        + [ca.vertcat(*[spherical_spreading(r[4]) for r in rows], 0.0),
                           ca.vertcat(*[r[4] for r in rows], 0.0)])
    # without a water depth the direct family alone is solved (the reflected rows: invalid, zero)
    direct, other = (list(r[:4]) + list(_tube_loss(zs, zr, x, r[4], nodes, speeds))
                     for r in _direct(zs, zr, x, depth, nodes, speeds, others=True))
    inner = [zs, zr, x, depth, nodes, speeds]
    direct_only = ca.Function("sblsim_arrivals_direct", inner, [ca.vertcat(v, 0.0, 0.0, w)
                                                                for v, w in zip(direct, other)])
    bounded = ca.Function("sblsim_arrivals_bounded", inner, eigenray_paths()(*inner))
    table = ca.Function("sblsim_arrivals_table", args,
                        switch("sblsim_arrivals_boundary", [direct_only, bounded])(depth > 0, *inner))
    chosen = switch("sblsim_arrivals_choice", [const, table])
    use = ca.MX.sym("use_table")
    return ca.Function("sblsim_arrivals", [use, *args], chosen(use, *args),
                       ["use_table", "zs", "zr", "x", "depth", "constant", "nodes", "speeds"], names,
                       {"never_inline": True})


def arrivals(use_table, zs, zr, x, depth, constant, nodes, speeds):
    """Every eigenray family between two depths with its geometric spreading and its length, for the sonar
    equation: ``(tau, launch, arrival, valid, spreading, length)``, each (4, 1), rows direct, surface-reflected,
    bottom-reflected and the direct family's earliest other eigenray (a ray turning in the water; the ``arrival``
    codes 1 to 4 less one; the fourth never valid in water of one speed).

    Through the profile table (``use_table``) the eigenrays of :func:`eigenray_paths` (only the direct one solved
    without a water depth); in water of the constant speed ``constant`` the straight line and its images in the
    surface and the bottom, spreading ``20 log10 L`` and length ``L`` (``L`` the image path's length), as
    :func:`first_arrival`'s isovelocity branch. Only the chosen branch runs in the generated C.

    Parameters
    ----------
    use_table : casadi.SX
        True (non-zero) for the table, false for the constant ``constant``.
    zs, zr : casadi.SX
        Depth of the source and of the receiver [m] (positive down).
    x : casadi.SX
        Horizontal distance [m].
    depth : casadi.SX
        Water depth [m]; 0: no boundary (the reflected rows invalid).
    constant : casadi.SX
        The sound speed of an empty table [m/s].
    nodes, speeds : casadi.SX, shape (NODES, 1)
        The padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).

    Returns
    -------
    tau : casadi.SX, shape (4, 1)
        Travel times [s].
    launch, arrival : casadi.SX, shape (4, 1)
        Grazing angles [rad] at the source and at the receiver, positive downward, in the direction of travel.
    valid : casadi.SX, shape (4, 1)
        1 where the eigenray exists (0: shadow zone or no boundary; the row's other values are then meaningless).
    spreading : casadi.SX, shape (4, 1)
        Geometric spreading loss [dB re 1 m], ``−10 log10 |p/p0|²`` of the ray tube (Jensen, Kuperman, Porter,
        Schmidt, *Computational Ocean Acoustics*, 2nd ed., 2011, ch. 3), at most :data:`CAUSTIC_GAIN` below the
        spherical spreading ``20 log10`` of the isovelocity image's length (caustics), and at least 0 dB.
    length : casadi.SX, shape (4, 1)
        Path length along the ray [m] (for absorption): per c-linear layer ``(θ_a − θ_b) / (ξ g)`` in a form that
        holds for a zero gradient too.
    """
    return _arrivals()(use_table, zs, zr, x, depth, constant, nodes, speeds)


def profile_arrays(table) -> tuple[np.ndarray, np.ndarray]:
    """The padded nodes and speeds of a numeric sound-speed table, as the channel builds them.

    Parameters
    ----------
    table : array_like, shape (rows, 2)
        Depth [m], sound speed [m/s], 1 ≤ rows ≤ MAX_PROFILE_ROWS, depths increasing.

    Returns
    -------
    nodes, speeds : ndarray, each (NODES,)
    """
    table = np.asarray(table, dtype=float)
    n = table.shape[0]
    depth, speed = np.zeros(MAX_PROFILE_ROWS), np.zeros(MAX_PROFILE_ROWS)
    depth[:n], speed[:n] = table[:, 0], table[:, 1]
    count, d, c = ca.MX.sym("n"), ca.MX.sym("d", MAX_PROFILE_ROWS), ca.MX.sym("c", MAX_PROFILE_ROWS)
    nodes, speeds = ca.Function("sblsim_ray_nodes", [count, d, c], list(node_speeds(count, d, c)))(n, depth, speed)
    return np.asarray(nodes).ravel(), np.asarray(speeds).ravel()


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


__all__ = ["BOTTOM", "CAUSTIC_GAIN", "DIRECT", "NEWTON_ITERATIONS", "RANGE_ITERATIONS", "SURFACE", "arrivals",
           "eigenray_families", "eigenray_paths", "first_arrival", "first_arrival_function", "profile_arrays",
           "ray_bending", "slant_range", "sound_speed_at", "spherical_spreading"]
