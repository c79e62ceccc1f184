"""Eigenrays through the sound-speed profile (models/acoustics/rays.py) against references nobody here wrote:
the straight line of isovelocity water, the circular arc of a linear gradient, a numerical integration of the
ray equations (scipy ``solve_ivp``) and Bellhop (M. Porter) through the ``pelagic`` package."""

from __future__ import annotations

import math
import os
import tempfile
from bisect import bisect_right

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from sblsim.models.acoustics import ray_integrals, ray_tables, rays
from sblsim.models.acoustics.sound_speed import munk_speed, munk_table, profile_table

#: A strongly refracting table: a surface duct over a sharp thermocline, then the deep increase.
STRONG = np.array([[0.0, 1500.0], [80.0, 1501.5], [140.0, 1468.0], [600.0, 1478.0], [1500.0, 1486.0],
                   [4500.0, 1537.0]])


def families(table, zs, zr, x, depth=0.0):
    nodes, speeds = rays.profile_arrays(table)
    return [np.asarray(v).ravel() for v in rays.eigenray_families()(zs, zr, x, depth, nodes, speeds)]


# ------------------------------------------------------------------ closed forms


@pytest.mark.parametrize("zs, zr, x", [(10.0, 30.0, 100.0), (10.0, 10.0, 500.0), (30.0, 10.0, 0.0),
                                       (100.0, 3000.0, 4000.0), (5.0, 5.0, 0.0), (2.0, 250.0, 0.3)])
def test_isovelocity_is_the_straight_line(zs, zr, x):
    table = np.array([[0.0, 1493.0], [100.0, 1493.0], [5000.0, 1493.0]])
    depth = 5000.0
    tau, launch, arrival, valid = families(table, zs, zr, x, depth)
    assert valid[:3].all() and valid[3] == 0  # one straight line: no other eigenray of the direct family
    for k, image in enumerate((zr - zs, zs + zr, 2 * depth - zs - zr)):
        length = np.hypot(x, image)
        assert tau[k] == pytest.approx(length / 1493.0, rel=4e-15, abs=1e-17)
        angle = np.arctan2(abs(image), x)
        assert abs(launch[k]) == pytest.approx(angle, abs=1e-9)
    # the constant-speed branch of the channel: the same straight line
    out = [float(v) for v in rays.first_arrival(0.0, zs, zr, x, depth, 1493.0, *rays.profile_arrays(table))]
    assert out[0] == pytest.approx(np.hypot(x, zr - zs) / 1493.0, rel=4e-15, abs=1e-17) and out[3] == rays.DIRECT


@pytest.mark.parametrize("zs, zr, x", [(100.0, 900.0, 2000.0), (1000.0, 1000.0, 3000.0), (2000.0, 100.0, 5000.0),
                                       (500.0, 600.0, 4000.0), (3000.0, 50.0, 1000.0), (40.0, 3900.0, 700.0)])
def test_linear_gradient_is_a_circular_arc(zs, zr, x):
    """c = c0 + g z: the ray is a circle centred at the depth where c would vanish; t = ln tan(φ/2) / g
    between the polar angles φ of the two ends (geometry of the circle, not the layer formulas)."""
    c0, g = 1480.0, 0.05
    table = np.array([[0.0, c0], [5000.0, c0 + 5000.0 * g]])
    zc = -c0 / g
    a, b = zs - zc, zr - zc
    xc = (x * x + b * b - a * a) / (2 * x)
    phi_s, phi_r = np.arctan2(a, -xc), np.arctan2(b, x - xc)
    want = abs(np.log(np.tan(phi_r / 2)) - np.log(np.tan(phi_s / 2))) / g
    tau, launch, arrival, valid = families(table, zs, zr, x)
    assert valid[0]
    assert tau[0] == pytest.approx(want, abs=1e-12)
    # grazing angle |π/2 − φ|; the arc descends until it passes under the centre (x = xc), then rises
    assert launch[0] == pytest.approx(np.sign(xc) * abs(np.pi / 2 - phi_s), abs=1e-11)
    assert arrival[0] == pytest.approx(np.sign(xc - x) * abs(np.pi / 2 - phi_r), abs=1e-11)


def test_a_faster_layer_between_the_ends_casts_a_shadow():
    """A speed maximum between source and receiver: beyond the range of the ray grazing it, no direct
    eigenray (and the channel reports no arrival without boundaries)."""
    table = np.array([[0.0, 1480.0], [100.0, 1500.0], [200.0, 1480.0], [1000.0, 1480.0]])
    near, far = families(table, 50.0, 150.0, 200.0), families(table, 50.0, 150.0, 5000.0)
    assert near[3][0] == 1 and far[3][0] == 0
    out = rays.first_arrival(1.0, 50.0, 150.0, 5000.0, 0.0, 1500.0, *rays.profile_arrays(table))
    assert float(out[3]) == 0


@pytest.mark.slow
def test_the_layers_a_ray_does_not_cross_change_no_sum():
    """The solve's layer sums (range, time, dX/dq; the tube's range over √(1 − q²), its derivative, the arc
    length), which skip the layers a ray does not cross, equal bit for bit the sums of every layer's terms (each
    layer evaluated) at random rays through a short table (most layers padding) and the NCL1 cast, with both pieces
    and with fold on and off, ends on nodes included."""
    import casadi as ca

    rng = np.random.default_rng(5)
    sym = [ca.SX.sym(n) for n in ("q", "fold", "cref", "u1", "v1", "u2", "v2", "z0", "z1", "c0", "c1")]
    q, fold, cref, u1, v1, u2, v2, z0, z1, c0, c1 = sym
    p1 = ray_integrals._piece(q, cref, u1, v1, z0, z1, c0, c1)
    p2 = ray_integrals._piece(q, cref, u2, v2, z0, z1, c0, c1)
    w2 = ca.if_else(ca.logic_or(fold > 0.5, q < 0), 2.0, 0.0)
    x, t, f, arc = (a + w2 * b for a, b in zip(p1, p2))
    every = {ray_integrals._layers(): ca.Function("every", sym, [x, t, ca.jacobian(x, q)]),
             ray_integrals._tube(): ca.Function("every_tube", sym, [f, ca.jacobian(f, q), arc])}
    for table in (np.array([[0, 1510], [30, 1508], [60, 1495], [100, 1489], [300, 1487.0]]),
                  profile_table("ctd:NCL1", "", 15.0, 35.0)):
        nodes, speeds = rays.profile_arrays(table)
        n = 200
        ends = np.sort(rng.uniform(-5.0, table[-1, 0] + 5.0, (n, 4)), axis=1)
        ends[:20, 0] = table[rng.integers(0, len(table), 20), 0]  # on a node
        ends[20:30, 1] = ends[20:30, 0]  # an empty first piece
        cols = [rng.uniform(-0.9, 1.0, n), (np.arange(n) % 2).astype(float), rng.uniform(1480.0, 1520.0, n),
                ends[:, 0], ends[:, 1], ends[:, 2], ends[:, 3]]
        for sums, layer in every.items():
            skipping = [np.asarray(v).ravel() for v in sums.map(n)(*[c[None] for c in cols], nodes, speeds)]
            terms = layer.map(nodes.size - 1)
            summed = [np.zeros(n) for _ in skipping]
            for k in range(n):
                out = terms(*[c[k] for c in cols], nodes[:-1].T, nodes[1:].T, speeds[:-1].T, speeds[1:].T)
                for j, o in enumerate(out):
                    summed[j][k] = float(ca.sum2(o))
            for got, want in zip(skipping, summed):
                np.testing.assert_array_equal(got, want)


# ------------------------------------------------------------------ numerical integration of the ray equations


def _ivp_ray(table, zs, x, theta0, depth, end_angle=False):
    """Integrate dz/dr = tan θ, dθ/dr = −c'(z)/c, dτ/dr = 1/(c cos θ) in range, reflecting at 0 and ``depth``.
    Returns (z at x, τ at x, boundaries hit), and with ``end_angle`` θ at x [rad]."""
    # the table as Python floats, and each layer's gradient: the right-hand side runs millions of times, on scalars
    zt, ct = [float(v) for v in table[:, 0]], [float(v) for v in table[:, 1]]
    slopes = [(ct[k + 1] - ct[k]) / (zt[k + 1] - zt[k]) for k in range(len(zt) - 1)]
    last = len(zt) - 2

    def rhs(r, y):
        z, th = float(y[0]), float(y[1])
        k = min(max(bisect_right(zt, z) - 1, 0), last)
        if z < zt[0] or z > zt[-1]:  # the speed is constant beyond the table (as np.interp holds it)
            c, g = (ct[0] if z < zt[0] else ct[-1]), 0.0
        else:
            c, g = ct[k] + slopes[k] * (z - zt[k]), slopes[k]
        return [math.tan(th), -g / c, 1.0 / (c * math.cos(th))]

    def top(r, y):
        return y[0]

    def bottom(r, y):
        return y[0] - depth

    top.terminal = bottom.terminal = True
    top.direction, bottom.direction = -1, 1
    y, r0, hits = [zs, theta0, 0.0], 0.0, []
    while True:
        sol = solve_ivp(rhs, (r0, x), y, method="DOP853", rtol=1e-10, atol=1e-10, events=[top, bottom],
                        max_step=20.0)
        if sol.status != 1:
            return (sol.y[0, -1], sol.y[2, -1], hits) + ((sol.y[1, -1],) if end_angle else ())
        which = 0 if len(sol.t_events[0]) else 1
        r0, y = sol.t_events[which][0], sol.y_events[which][0].copy()
        y[0], y[1] = (0.0, -y[1]) if which == 0 else (depth, -y[1])
        hits.append(which)


#: How near [m] to the receiver the integrated ray launched at our angle must reach its range for
#: :func:`_shoot` to take its time without shooting.
LANDED = 0.01


def _shoot(table, zs, zr, x, theta, depth):
    """The integrated ray equations' eigenray near the launch angle ``theta`` [rad]: :func:`_ivp_ray`'s (z at x,
    τ at (x, ``zr``), boundaries hit).

    The ray launched at ``theta`` itself where it reaches ``x`` within :data:`LANDED` of ``zr`` (near a separatrix
    the depth reached moves metres per µrad: landing there places the angle), its time moved along the wavefront
    to ``zr``: τ(x, zr) = τ(x, z) − (z − zr) sin θ / c(z), θ its angle at x (Fermat: the time is stationary along
    the ray; the rest, second order in z − zr, is below 1e-9 s here); else the ray of the launch angle found by
    Brent's method within 1e-5 of ``theta`` (to 1e-11 rad)."""
    z, tau, hits, angle = _ivp_ray(table, zs, x, theta, depth, end_angle=True)
    if abs(z - zr) <= LANDED:
        return z, tau - (z - zr) * math.sin(angle) / np.interp(z, table[:, 0], table[:, 1]), hits
    root = brentq(lambda a: _ivp_ray(table, zs, x, a, depth)[0] - zr, theta - 1e-5, theta + 1e-5, xtol=1e-11)
    return _ivp_ray(table, zs, x, root, depth)


def _brent(table, zs, zr, x, theta, depth):
    """The launch angle within 1e-5 of ``theta`` [rad] whose integrated ray reaches ``zr`` at ``x`` (Brent's method,
    to 1e-13 rad), and that ray (:func:`_ivp_ray`: z at x, τ at x, boundaries hit), kept from the last integration
    of Brent's method (the angle it returns is one it integrated), not integrated again."""
    shots = {}

    def miss(a):
        shots[a] = _ivp_ray(table, zs, x, a, depth)
        return shots[a][0] - zr

    root = brentq(miss, theta - 1e-5, theta + 1e-5, xtol=1e-13)
    return root, shots[root] if root in shots else _ivp_ray(table, zs, x, root, depth)


IVP_CASES = [("munk", 1300.0, 1300.0, 5000.0),
             ("strong", 20.0, 60.0, 1500.0), ("strong", 100.0, 1200.0, 3000.0), ("strong", 3000.0, 300.0, 4500.0),
             ("strong", 700.0, 700.0, 2500.0)]


def _table(name):
    return {"munk": munk_table(), "NCL1": profile_table("ctd:NCL1", "", 15.0, 35.0), "strong": STRONG}[name]


@pytest.mark.slow
@pytest.mark.parametrize("name, zs, zr, x", IVP_CASES)
def test_against_solve_ivp(name, zs, zr, x):
    """Within 1 µs of the ray equations integrated numerically (DOP853, relative and absolute tolerances 1e-10),
    shooting the launch angle (Brent) inside a small window around ours: the same eigenray, found by the
    integration itself, its launch angle within 1e-6 rad (the shooting itself is no finer where the depth reached
    barely changes with the angle: along the Munk axis 8e-8 rad apart)."""
    table = _table(name)
    depth = float(table[-1, 0])
    tau, launch, arrival, valid = families(table, zs, zr, x, depth)
    checked = 0
    for k in range(3):
        if not valid[k]:
            continue
        root, (z_end, t_end, hits) = _brent(table, zs, zr, x, launch[k], depth)
        assert hits == [[], [0], [1]][k]
        assert tau[k] == pytest.approx(t_end, abs=1e-6)
        assert launch[k] == pytest.approx(root, abs=1e-6)  # the launch angle (a USBL measures it): 0.1 mm at 100 m
        checked += 1
    assert checked >= 2


#: Geometries of the strong table's surface duct (source depth, receiver depth, range [m]) where the surface-reflected
#: eigenray also turns below the deeper end: beyond the range of the flattest plain surface-reflected ray (the one
#: horizontal at the fastest speed above the deeper end), short of the ray grazing the duct's bottom at 80 m. The
#: first is the case of 3.332 s (no direct eigenray there: the thermocline's shadow).
DUCT_CASES = [(20.0, 60.0, 5000.0), (60.0, 20.0, 5000.0), (5.0, 60.0, 4000.0), (10.0, 70.0, 4500.0),
              (30.0, 50.0, 6000.0), (20.0, 60.0, 3800.0)]
#: The case the fast tier solves (1 s); the others, 1.5 to 2.5 s each, in the slow tier.
DUCT_FAST = (10.0, 70.0, 4500.0)


@pytest.mark.parametrize("zs, zr, x", [case if case == DUCT_FAST else pytest.param(*case, marks=pytest.mark.slow)
                                       for case in DUCT_CASES])
def test_surface_duct_eigenray_against_solve_ivp(zs, zr, x):
    """The surface family's eigenray that also turns (leaving the shallower end upward and the deeper end downward,
    arriving likewise) within 1 µs of the integrated ray equations shot around our launch angle, its launch angle
    within 1e-6 rad, one surface reflection and no bottom. Where the direct path is shadowed it is the first arrival,
    not the bottom bounce (6.8 s at the first geometry)."""
    table, depth = STRONG, float(STRONG[-1, 0])
    tau, launch, arrival, valid = families(table, zs, zr, x, depth)
    assert valid[1] and np.sign(launch[1]) == np.sign(arrival[1]) == (1.0 if zs > zr else -1.0)
    th = launch[1]
    root = brentq(lambda a: _ivp_ray(table, zs, x, a, depth)[0] - zr, th - 1e-5, th + 1e-5, xtol=1e-13)
    _z, t_end, hits = _ivp_ray(table, zs, x, root, depth)
    assert hits == [0]
    assert tau[1] == pytest.approx(t_end, abs=1e-6)
    assert launch[1] == pytest.approx(root, abs=1e-6)
    if not valid[0]:
        out = rays.first_arrival(1.0, zs, zr, x, depth, 1500.0, *rays.profile_arrays(table))
        assert int(out[3]) == rays.SURFACE and float(out[0]) == pytest.approx(t_end, abs=1e-6)


# ------------------------------------------------------------------ Bellhop (pelagic)

#: Bellhop's fan of launch angles [deg], its step [m] and its number of beams.
FAN, STEP, BEAMS = 86.0, 5.0, 4001
#: Arrivals are compared where the eigenray leaves within this angle of the horizontal [deg] (the fan's last
#: degrees hold too few beams for Bellhop's interpolation to the receiver).
STEEPEST = 80.0


def _bellhop(table, source, depths, ranges, depth, fan=(-FAN, FAN), beams=BEAMS):
    pg = pytest.importorskip("pelagic")  # the test extra installs it: this skips only outside it
    tab = table[table[:, 0] < depth]
    tab = np.vstack([tab, [depth, np.interp(depth, table[:, 0], table[:, 1])]])
    if tab[0, 0] > 0:
        tab = np.vstack([[0.0, tab[0, 1]], tab])
    lines = ["'sblsim'", "1000.0", "1", "'CVW'", f"0 0.0 {depth:.4f}"]
    lines += [f"{z:.6f} {c:.6f} /" for z, c in tab]
    lines += ["'A' 0.0", f"{depth:.4f} 1600.00 0.0 1.8 0.8 /", "1", f"{source:.6f} /",
              f"{len(depths)}", " ".join(f"{z:.6f}" for z in depths) + " /", f"{len(ranges)}",
              " ".join(f"{r / 1000:.9f}" for r in ranges) + " /", "'A'", f"{beams}", f"{fan[0]} {fan[1]} /",
              f"{STEP} {depth + 100:.1f} {max(ranges) / 1000 + 1:.3f}"]
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "case.env")
        with open(path, "w") as handle:
            handle.write("\n".join(lines) + "\n")
        return pg.bellhop.load(path).run().arrivals.to_pandas()


BELLHOP_SITES = {
    "munk": ([25.0, 400.0, 1300.0, 2500.0], [10.0, 150.0, 800.0, 1300.0, 2200.0, 4000.0],
             [800.0, 1500.0, 2200.0, 3000.0, 3700.0, 4300.0, 5000.0], 5000.0),
    "NCL1": ([5.0, 300.0, 900.0, 1150.0], [2.0, 50.0, 250.0, 600.0, 1000.0, 1200.0],
             [800.0, 1500.0, 2200.0, 3000.0, 3700.0, 4300.0, 5000.0], 1220.0),
    "strong": ([20.0, 110.0, 700.0, 3000.0], [5.0, 60.0, 200.0, 1000.0, 2500.0, 4000.0],
               [800.0, 1500.0, 2200.0, 3000.0, 3700.0, 4300.0, 5000.0], 4500.0),
}


#: Bellhop's fan samples launch angles 2 FAN / (BEAMS − 1) = 0.043° apart. Within this angle [deg] (about two beams)
#: of a separatrix — a ray horizontal at a local maximum of the speed, where the range reached is infinitely
#: sensitive to the launch angle — the fan cannot place an eigenray: its beams land metres to hundreds of metres
#: from the receiver and their interpolated times miss by tens of µs, or they miss or invent the arrival.
SEPARATRIX = 0.1
#: Half-width [deg] of the narrow fan run there around our launch angle.
NARROW = 0.05
#: The integrated eigenray and the narrow fan's arrivals per geometry (a perturbed solve reuses them).
_SHOOTING: dict[tuple, tuple] = {}


def _separatrices(table, zs):
    """Launch angles [deg] (unsigned) at depth ``zs`` of the rays horizontal at a local maximum of the table's speed
    (a row not slower than its neighbours; the ends count, the speed being constant beyond them)."""
    c = table[:, 1]
    peaks = c[np.r_[True, c[1:] >= c[:-1]] & np.r_[c[:-1] >= c[1:], True]]
    here = np.interp(zs, table[:, 0], c)
    return np.degrees(np.arccos(here / peaks[peaks > here]))


def _turns(k, zs, zr, source_angle, receiver_angle):
    """Bellhop's reflected arrivals whose ray turns as no path of the families does.

    Bottom: leaving away from the bottom (upward) or arriving toward it. Surface: the plain surface-reflected ray
    leaves upward and arrives downward; the one that also turns below the deeper end (a surface duct) leaves the
    shallower end upward and the deeper end downward, and arrives likewise (at equal depths either way); every other
    surface arrival (leaving the shallower end downward: turning below, it crosses ``[z_a, z_b]`` three times, or
    turning above the source before it reaches the surface) is not modelled (docs/model.md)."""
    if k == 2:
        return (source_angle < 0) | (receiver_angle > 0)
    plain = (source_angle < 0) & (receiver_angle > 0)
    up = (source_angle < 0) & (receiver_angle < 0) & (zs <= zr)
    down = (source_angle > 0) & (receiver_angle > 0) & (zs >= zr)
    return ~(plain | up | down)


_ARRIVALS: dict[str, dict] = {}
#: Our eigenrays per geometry of a site (the comparison asks for them again: perturbed, in the can-fail test).
_SOLVED: dict[tuple, tuple] = {}


def _eigenrays(name):
    """:func:`rays.eigenray_families` at the site ``name``, each geometry solved once per test session: as the
    channel evaluates them, compiled in the local engine's library (the first four outputs of
    :func:`~sblsim.fmus.compiled_functions.compiled_family_points`: casadi's own evaluation took 15 s of Munk's and
    of the strong table's 25 s), checked equal to casadi's evaluation of :func:`rays.eigenray_families` at every
    16th geometry."""
    from sblsim.fmus.compiled_functions import compiled_family_points

    model = rays.eigenray_families()
    compiled = compiled_family_points()
    solve = model if compiled is None else compiled

    def solved(zs, zr, x, depth, nodes, speeds):
        key = (name, float(zs), float(zr), float(x), float(depth))
        if key not in _SOLVED:
            out = tuple(np.asarray(v).ravel() for v in solve(zs, zr, x, depth, nodes, speeds)[:4])
            if compiled is not None and len(_SOLVED) % 16 == 0:
                for got, want in zip(out, model(zs, zr, x, depth, nodes, speeds)):
                    np.testing.assert_array_equal(got, np.asarray(want).ravel())
            _SOLVED[key] = out
        return _SOLVED[key]

    return solved


def _bellhop_arrivals(name):
    """Bellhop's arrivals at the site ``name``, per source depth (run once per test session)."""
    if name not in _ARRIVALS:
        table = _table(name)
        sources, depths, ranges, depth = BELLHOP_SITES[name]
        _ARRIVALS[name] = {zs: _bellhop(table, zs, depths, ranges, depth) for zs in sources}
    return _ARRIVALS[name]


def _compare_with_bellhop(name, solve):
    """The comparison of :func:`test_against_bellhop` of the eigenrays ``solve`` gives (the signature of
    :func:`rays.eigenray_families`); raises AssertionError naming the check that fails."""
    table = _table(name)
    sources, depths, ranges, depth = BELLHOP_SITES[name]
    nodes, speeds = rays.profile_arrays(table)
    compared, worst = [0, 0, 0], [0.0, 0.0, 0.0]
    ducted, ducted_worst = 0, 0.0  # surface-reflected eigenrays that also turn (leaving and arriving the same way)
    mismatched, other_ray, separatrix = [], [], []
    speed = ray_integrals._speed()
    for zs in sources:
        arrivals = _bellhop_arrivals(name)[zs]
        seps = _separatrices(table, zs)
        for zr in depths:
            for x in ranges:
                tau, launch, arrival, valid = (np.asarray(v).ravel() for v in solve(zs, zr, x, depth, nodes, speeds))
                edge = [np.asarray(solve(zs, zr, x * f, depth, nodes, speeds)[3]).ravel() for f in (0.99, 1.01)]
                here = arrivals[(arrivals.depth_m == np.float32(zr)) & (np.isclose(arrivals.range_m, x))]
                for k, (top, bottom) in enumerate(((0, 0), (1, 0), (0, 1))):
                    theirs = here[(here.top_bounces == top) & (here.bottom_bounces == bottom)]
                    if k > 0:
                        theirs = theirs[~_turns(k, zs, zr, theirs.source_angle_degrees.values,
                                                theirs.receiver_angle_degrees.values)]
                    if edge[0][k] != edge[1][k]:
                        continue  # at a shadow boundary
                    if k > 0 and len(theirs):  # Bellhop's beam grazing the boundary: reflected or not, by sampling
                        boundary = 0.0 if k == 1 else depth
                        lo, hi = min(zs, boundary), max(zs, boundary)
                        inside = table[(table[:, 0] > lo) & (table[:, 0] < hi), 1]
                        fastest = max([float(speed(lo, nodes, speeds)), float(speed(hi, nodes, speeds)), *inside])
                        graze = np.degrees(np.arccos(min(1.0, float(speed(zs, nodes, speeds)) / fastest)))
                        if np.any(np.abs(np.abs(theirs.source_angle_degrees.values) - graze) < 0.1):
                            continue
                    angles = list(np.abs(theirs.source_angle_degrees.values))
                    if valid[k]:
                        angles.append(abs(np.degrees(launch[k])))
                    if len(seps) and np.min(np.abs(np.subtract.outer(angles, seps)), initial=np.inf) < SEPARATRIX:
                        if valid[k] and abs(np.degrees(launch[k])) <= STEEPEST:
                            separatrix.append((k, zs, zr, x, float(launch[k]), float(tau[k])))
                        continue
                    if bool(valid[k]) != (len(theirs) > 0):
                        mismatched.append((k + 1, zs, zr, x, bool(valid[k])))
                        continue
                    if not valid[k] or abs(np.degrees(launch[k])) > STEEPEST:
                        continue
                    nearest = np.argmin(np.abs(theirs.source_angle_degrees.values - np.degrees(launch[k])))
                    if abs(theirs.source_angle_degrees.values[nearest] - np.degrees(launch[k])) > 0.5:
                        other_ray.append((k + 1, zs, zr, x, np.degrees(launch[k]), theirs.source_angle_degrees.values))
                        continue
                    error = abs(tau[k] - theirs.travel_time_s.values[nearest])
                    worst[k] = max(worst[k], error)
                    compared[k] += 1
                    if k == 1 and np.sign(launch[k]) == np.sign(arrival[k]):
                        ducted, ducted_worst = ducted + 1, max(ducted_worst, error)
    # near a separatrix: the eigenray against the ray equations integrated (the shooting of test_against_solve_ivp),
    # and against Bellhop with a fan of 1001 beams over ±0.05° around ours (beams 1e-4° apart)
    ivp_worst, narrow_worst, narrow_missed = 0.0, [0.0, 0.0, 0.0], []
    for k, zs, zr, x, theta, t in separatrix:
        key = (name, k, zs, zr, x, theta)
        if key not in _SHOOTING:
            narrow = _bellhop(table, zs, [zr], [x], depth, (np.degrees(theta) - NARROW, np.degrees(theta) + NARROW),
                              1001)
            _SHOOTING[key] = (_shoot(table, zs, zr, x, theta, depth), narrow)
        (_z, t_end, hits), narrow = _SHOOTING[key]
        assert hits == [[], [0], [1]][k], ("separatrix: other path", k + 1, zs, zr, x, hits)
        ivp_worst = max(ivp_worst, abs(t - t_end))
        top, bottom = ((0, 0), (1, 0), (0, 1))[k]
        theirs = narrow[(narrow.top_bounces == top) & (narrow.bottom_bounces == bottom)]
        gap = np.abs(theirs.source_angle_degrees.values - np.degrees(theta))
        if not len(theirs) or gap.min() > 0.01:
            narrow_missed.append((k + 1, zs, zr, x))
            continue
        narrow_worst[k] = max(narrow_worst[k], abs(t - theirs.travel_time_s.values[np.argmin(gap)]))
    print(f"{name}: compared {compared} (direct, surface, bottom), worst {worst} s; near a separatrix "
          f"{len(separatrix)} against solve_ivp, worst {ivp_worst} s, and Bellhop's narrow fan, worst {narrow_worst} "
          f"s; surface-reflected and turning {ducted}, worst {ducted_worst} s")
    assert not mismatched, ("shadowed sets", mismatched)
    assert not other_ray, ("other eigenray", other_ray)
    assert compared[0] >= 60 and compared[1] + compared[2] >= 60, ("compared", compared)
    assert worst[0] <= 10e-6 and worst[1] <= 20e-6 and worst[2] <= 20e-6, ("Bellhop's times", worst)
    assert ivp_worst <= 1e-6, ("solve_ivp's times near a separatrix", ivp_worst)
    assert not narrow_missed, ("the narrow fan's eigenrays near a separatrix", narrow_missed)
    assert narrow_worst[0] <= 10e-6 and max(narrow_worst[1:]) <= 20e-6, ("the narrow fan's times", narrow_worst)
    return compared, len(separatrix), ducted


@pytest.mark.slow
@pytest.mark.parametrize("name", ["munk", "NCL1", "strong"])
def test_against_bellhop(name):
    """Direct eigenray times within 10 µs of Bellhop's, surface- and bottom-reflected within 20 µs, over 168
    geometries per profile (504 in all, out to 5 km and 4 km deep), the same shadowed geometries.

    Bellhop's arrival of the same eigenray is the one with the same bounces whose launch angle is nearest to
    ours (within 0.5°). Left out: eigenrays steeper than :data:`STEEPEST`, and, for the sets, geometries within
    1 % in range of a family's shadow boundary, and reflected families where Bellhop has an arrival within 0.1°
    of the ray grazing the boundary: there a fan of beams decides by its sampling whether a ray is reflected.
    Bellhop's surface-reflected arrivals that also turn below the deeper end (the strong table's surface duct) are
    compared with the surface family (at least 5 of them there); its reflected arrivals that turn otherwise (in the
    duct: down, up to the surface and back down) are no path of the families (:func:`_turns`; not modelled,
    docs/model.md).

    Near a separatrix (ours or Bellhop's arrival leaving within :data:`SEPARATRIX` of a ray horizontal at a local
    maximum of the speed: the top of a duct, the cast's first sample, which the receiver 2 m deep lies 1.6 cm
    under) Bellhop's fan cannot resolve the eigenray: its nearest beams land up to hundreds of metres from the
    receiver (the integration shows it), so that it misses the arrival, reports one the rays do not make or
    times it tens of µs off. There our eigenray is checked against the ray equations integrated from our launch
    angle (solve_ivp, :func:`_shoot`: the ray lands within 1 cm of the receiver after the same boundaries, its time
    moved to the receiver's depth within 1 µs of ours) and against Bellhop with a fan 1e-4° fine around it (an
    arrival with the same bounces within 0.01° of ours, within 10 µs, 20 µs reflected) instead; the NCL1 cast and
    the strong table have such geometries."""
    compared, near, ducted = _compare_with_bellhop(name, _eigenrays(name))
    if name != "munk":
        assert near > 0
    if name == "strong":  # its surface duct: surface-reflected eigenrays that also turn, compared
        assert ducted >= 5, ducted


@pytest.mark.parametrize("name, family, offset, check", [
    pytest.param("strong", 0, 2e-6, "separatrix", marks=pytest.mark.slow),
    # the deep Munk profile's eigenrays take about 20 s: with the comparison they guard (slow, above)
    pytest.param("munk", 0, 12e-6, "Bellhop's times", marks=pytest.mark.slow),
    pytest.param("munk", 1, 25e-6, "Bellhop's times", marks=pytest.mark.slow)])
def test_against_bellhop_can_fail(name, family, offset, check):
    """The comparison fails for eigenray times off by a little more than its tolerances: 2 µs near a separatrix
    (solve_ivp), 12 µs direct and 25 µs reflected elsewhere (Bellhop)."""
    solve = _eigenrays(name)
    shift = np.zeros(4)
    shift[family] = offset

    def perturbed(*args):
        tau, launch, arrival, valid = solve(*args)
        return np.asarray(tau).ravel() + shift, launch, arrival, valid

    with pytest.raises(AssertionError, match=check):
        _compare_with_bellhop(name, perturbed)


def test_munk_table_samples_the_canonical_profile():
    table = munk_table()
    assert table.shape == (256, 2) and table[0, 0] == 0.0 and table[-1, 0] == 5000.0
    assert munk_speed(1300.0) == pytest.approx(1500.0, abs=1e-9)  # the axis: c_1
    np.testing.assert_allclose(table[:, 1], munk_speed(table[:, 0]), rtol=0, atol=0)
    z = np.linspace(0.0, 5000.0, 20001)
    assert np.max(np.abs(np.interp(z, table[:, 0], table[:, 1]) - munk_speed(z))) < 0.01  # c-linear sampling


def test_ncl1_cast_is_the_published_file_resampled():
    data = np.loadtxt(os.path.join(os.path.dirname(rays.__file__), "data", "CTD_NCL1_Ch_Mi"))
    assert data.shape == (985, 2)
    kept = data[data[:, 1] > 0]
    table = profile_table("ctd:NCL1", "", 15.0, 35.0)
    assert table.shape == (256, 2)
    assert table[0, 0] == pytest.approx(-kept[0, 0]) and table[-1, 0] == pytest.approx(-kept[-1, 0])
    np.testing.assert_allclose(table[:, 1], np.interp(table[:, 0], -kept[:, 0], kept[:, 1]), atol=1e-9)


# ------------------------------------------------------------------ the eigenray table of a run


def _grid_function(table, depth, bounds, columns):
    """The channel's table lookup (:func:`ray_tables.first_arrival_grid`) at arrays of points, with ``columns`` the
    table (None: no table, every eigenray solved)."""
    import casadi as ca

    nodes, speeds = rays.profile_arrays(table)
    bounds = np.asarray(bounds, dtype=float)
    use = columns is not None
    cols = [columns[c.name] for c in ray_tables.RAY_TABLE.columns] if use else [np.zeros(ray_tables.RAY_TABLE_ROWS)] * 5
    values = np.asarray(ray_tables.ray_values([ca.DM(c) for c in cols])).ravel()
    grid = ray_tables.ray_grid(bounds if use else np.arange(6.0))

    def f(zs, zr, x):
        n = zs.size
        out = ray_tables._first_arrival_grid().map(n)(float(use), zs[None], zr[None], x[None], depth, 1.0, 1500.0,
                                                      nodes, speeds, bounds, grid, values)
        return [np.asarray(o).ravel() for o in out]
    return f


def _exact_points(table, depth, zs, zr, x, exact=None):
    """The exact solve (``exact``: casadi's own :func:`~sblsim.models.acoustics.ray_tables.exact_points` unless a
    compiled one is given) at the points: (τ, launch, arrival, kind), each (n,)."""
    nodes, speeds = rays.profile_arrays(table)
    exact = ray_tables.exact_points() if exact is None else exact
    return [np.asarray(o).ravel() for o in exact.map(zs.size)(zs[None], zr[None], x[None], depth, nodes, speeds)]


def _tabulated(columns, bounds, zs, zr, x, flag="ray_exact"):
    """Which points a table answers: inside the box, every corner of their cell ``flag = 0`` (its exact-solve
    column: ``ray_exact`` of the eigenray table, ``ray_family_exact`` of the family table)."""
    axes = np.split(ray_tables.ray_grid(np.asarray(bounds, float)), np.cumsum(ray_tables.RAY_GRID)[:-1])
    flags = columns[flag].reshape(ray_tables.RAY_GRID, order="F")
    index = [np.clip(np.searchsorted(a, v, side="right") - 1, 0, len(a) - 2) for a, v in zip(axes, (zs, zr, x))]
    ok = np.ones(zs.size, bool)
    for i in (0, 1):
        for j in (0, 1):
            for k in (0, 1):
                ok &= flags[index[0] + i, index[1] + j, index[2] + k] == 0
    return ok


#: (profile, water depth, box, the least share of points the table answers): the benchmark's SBL geometry through
#: Munk, an LBL-like one with surface and bottom, a diver 1000 m deep within 220 m through the NCL1 cast, the
#: strongly refracting table's surface duct, and boxes far too coarse for the table's nodes (it answers nothing: the
#: exact solve everywhere), across Munk's channel axis and across the strong table's thermocline.
TABLE_CASES = [("munk", 0.0, (0.0, 2.5, 4.0, 6.0, 2.0, 28.0), 0.8),
               ("munk", 60.0, (45.0, 55.0, 0.0, 10.0, 0.0, 120.0), 0.8),
               ("NCL1", 0.0, (0.0, 5.0, 990.0, 1010.0, 0.0, 220.0), 0.8),
               ("strong", 0.0, (60.0, 70.0, 60.0, 70.0, 0.0, 100.0), 0.8),
               ("munk", 0.0, (0.0, 50.0, 900.0, 1400.0, 0.0, 2500.0), 0.0),
               ("strong", 0.0, (20.0, 40.0, 100.0, 120.0, 0.0, 800.0), 0.0)]


@pytest.mark.slow
@pytest.mark.parametrize("name, depth, bounds, share", TABLE_CASES)
def test_the_eigenray_table_holds_the_exact_solve(name, depth, bounds, share):
    """Inside the box, the channel's lookup equals the exact solve within 1 µs and 1e-5 rad with the same path,
    at 60 random geometries (the table answers a share of them; the exact solve the rest)."""
    from sblsim.fmus.compiled_functions import compiled_exact_points

    table = _table(name)
    columns = ray_tables.eigenray_table(table, depth, bounds, compiled_exact_points())
    rng = np.random.default_rng(7)
    n = 60
    zs, zr, x = (rng.uniform(bounds[2 * j], bounds[2 * j + 1], n) for j in range(3))
    want = _exact_points(table, depth, zs, zr, x)
    got = _grid_function(table, depth, bounds, columns)(zs, zr, x)
    np.testing.assert_array_equal(got[3], want[3])
    found = want[3] > 0
    assert np.max(np.abs(got[0] - want[0])[found]) <= 1e-6
    assert np.max(np.abs(got[1] - want[1])[found]) <= 1e-5 and np.max(np.abs(got[2] - want[2])[found]) <= 1e-5
    answered = _tabulated(columns, bounds, zs, zr, x)
    if share == 0.0:
        assert not answered.any()
        for g, w in zip(got, want):
            np.testing.assert_array_equal(g, w)
        return
    assert answered.mean() > share, answered.mean()
    # the answered points are interpolated, not solved: they differ from the exact solve (by far less than 1 µs)
    assert np.any(got[0][answered] != want[0][answered])
    # the others are the exact solve itself
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g[~answered], w[~answered])


@pytest.mark.slow
def test_without_a_table_the_lookup_is_the_exact_solve():
    table = munk_table()
    rng = np.random.default_rng(3)
    zs, zr, x = rng.uniform(0, 100, 20), rng.uniform(0, 100, 20), rng.uniform(0, 500, 20)
    got = _grid_function(table, 0.0, (0, 0, 0, 0, 0, 0), None)(zs, zr, x)
    for g, w in zip(got, _exact_points(table, 0.0, zs, zr, x)):
        np.testing.assert_array_equal(g, w)


#: The isovelocity table of :func:`test_an_isovelocity_table_is_the_straight_line` and its box.
ISO, ISO_BOUNDS = np.array([[0.0, 1493.0], [100.0, 1493.0], [5000.0, 1493.0]]), (0.0, 30.0, 10.0, 200.0, 0.0, 500.0)


@pytest.mark.slow
def test_an_isovelocity_table_is_the_straight_line():
    """Built as the local engine builds it (the exact solve compiled: :func:`test_the_compiled_builder_is_the_model`
    checks that solve against casadi's own at this table's nodes; casadi's evaluation of the whole table takes 40 s),
    the table answers every cell, with the straight line."""
    from sblsim.fmus.compiled_functions import compiled_exact_points

    table, bounds = ISO, ISO_BOUNDS
    columns = ray_tables.eigenray_table(table, 0.0, bounds, compiled_exact_points())
    assert not columns["ray_exact"].any()
    rng = np.random.default_rng(5)
    zs, zr, x = (rng.uniform(bounds[2 * j], bounds[2 * j + 1], 100) for j in range(3))
    tau, launch, arrival, kind = _grid_function(table, 0.0, bounds, columns)(zs, zr, x)
    np.testing.assert_allclose(tau, np.hypot(x, zr - zs) / 1493.0, rtol=1e-14, atol=0)
    np.testing.assert_allclose(launch, np.arctan2(zr - zs, x), rtol=0, atol=1e-13)
    np.testing.assert_array_equal(kind, rays.DIRECT)


#: Every how many of a table's nodes and of its cells' centres (the points its builder solves) the compiled exact
#: solve is checked against casadi's own (7: prime to the grid's sides, every row of each axis sampled).
BUILDER_STRIDE = 7


@pytest.mark.slow
@pytest.mark.parametrize("name, depth, bounds", [("munk", 8.0, (0.0, 2.5, 4.0, 6.0, 2.0, 28.0)),
                                                 ("isovelocity", 0.0, ISO_BOUNDS)])
def test_the_compiled_builder_is_the_model(name, depth, bounds):
    """The exact solve compiled in the local engine's library, with which the table is built, equals bit for bit
    casadi's own evaluation of it at every :data:`BUILDER_STRIDE`-th of the points the table's builder solves (its
    nodes and its cells' centres: 113 of 791; casadi's evaluation of them all takes 80 s through Munk), for the
    benchmark's box through Munk and for the isovelocity table of
    :func:`test_an_isovelocity_table_is_the_straight_line` (built with it)."""
    from sblsim.fmus.compiled_functions import compiled_exact_points

    compiled = compiled_exact_points()
    if compiled is None:
        pytest.skip("no C compiler")
    table = munk_table() if name == "munk" else ISO
    points = [np.r_[a, b] for a, b in zip(ray_tables.node_points(bounds), ray_tables.cell_centres(bounds))]
    zs, zr, x = (p[::BUILDER_STRIDE] for p in points)
    for g, w in zip(_exact_points(table, depth, zs, zr, x, compiled), _exact_points(table, depth, zs, zr, x)):
        np.testing.assert_array_equal(g, w)
