"""The direct family's eigenrays: the rays between two depths that meet no boundary.

The **direct** family (``arrival`` 1) in the ray integrals of :mod:`~sblsim.models.acoustics.ray_integrals`:
``c_ref`` is the faster end. ``q ≥ 0``: the ray runs monotonically from one end to the other; ``q < 0``: it leaves
the faster end away from the other, **turns** where ``c = 1/ξ`` (inside the region beyond that end where the speed
keeps increasing, bounded by the surface and the water depth) and comes back. If the speed between the ends exceeds
both, rays flatter than the one grazing that maximum cannot pass: beyond that ray's range lies a **shadow zone** (no
direct eigenray).

Where ``X(q)`` is not monotonic over the turning rays the family has several eigenrays: :func:`_direct` returns the
one its solve ends on (valid also where the flattest ray falls short of the target when the solve lands on a root
within :data:`LANDING`), and :func:`_other_function` the earliest other (the ``arrival`` code 4,
:data:`~sblsim.models.acoustics.rays.OTHER`).

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.ray_integrals import _BIG, NEWTON_ITERATIONS, _angle, _layers, _peak_down, _solve, _speed
from sblsim.models.acoustics.sound_speed import NODES
from sblsim.models.expressions import switch


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



__all__ = ["LANDING"]
