"""Transmission loss along eigenrays (models/acoustics/rays.py: ``arrivals``, ``eigenray_paths``): the geometric
spreading of the ray tube and the path length of every family, against references nobody here wrote: the image
distances of isovelocity water, the circular arcs of a linear gradient (geometry of the circle), the ray equations
integrated numerically (scipy ``solve_ivp``, the tube by finite differences of the launch angle) and Bellhop's
incoherent transmission loss (M. Porter, through the ``pelagic`` package, a test-only extra).

``pytest -s -k bellhop tests/models/test_spreading.py`` prints the Bellhop comparison's numbers."""

from __future__ import annotations

import math
import os
import tempfile
from bisect import bisect_right

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sblsim.models.acoustics import rays, spreading_loss
from sblsim.models.acoustics.sound_speed import munk_table

#: The strongly refracting table of tests/models/test_rays.py: a surface duct over a sharp thermocline.
STRONG = np.array([[0.0, 1500.0], [80.0, 1501.5], [140.0, 1468.0], [600.0, 1478.0], [1500.0, 1486.0],
                   [4500.0, 1537.0]])
ISO = np.array([[0.0, 1493.0], [100.0, 1493.0], [5000.0, 1493.0]])


def paths(table, zs, zr, x, depth=0.0):
    nodes, speeds = rays.profile_arrays(table)
    return [np.asarray(v).ravel() for v in rays.eigenray_paths()(zs, zr, x, depth, nodes, speeds)]


def paths_at(table, zs, zr, x, depth, paths=None):
    """:func:`rays.eigenray_paths` at arrays of receiver depths and ranges: its outputs, each (3, n). ``paths``:
    that function as it is evaluated (e.g. compiled); default casadi's own evaluation."""
    nodes, speeds = rays.profile_arrays(table)
    zr, x = np.broadcast_arrays(np.asarray(zr, float).ravel(), np.asarray(x, float).ravel())
    f = (rays.eigenray_paths() if paths is None else paths).map(zr.size)
    return [np.asarray(v) for v in f(zs, zr[None], x[None], depth, nodes, speeds)]


# ------------------------------------------------------------------ closed forms


@pytest.mark.parametrize("zs, zr, x", [(10.0, 30.0, 100.0), (10.0, 10.0, 500.0), (30.0, 10.0, 0.0),
                                       (100.0, 3000.0, 4000.0), (2.0, 250.0, 0.3), (400.0, 20.0, 1500.0)])
def test_isovelocity_spreading_is_the_image_distance(zs, zr, x):
    """Isovelocity water: spherical spreading 20 log10 L of the straight line and of its images in the surface and
    the bottom, and the path length L, to round-off, through a table and through the constant-speed branch."""
    depth = 5000.0
    nodes, speeds = rays.profile_arrays(ISO)
    want = np.hypot(x, [zr - zs, zs + zr, 2 * depth - zs - zr])
    for use_table in (1.0, 0.0):
        tau, _launch, _arrival, valid, spreading, length = (
            np.asarray(v).ravel() for v in rays.arrivals(use_table, zs, zr, x, depth, 1493.0, nodes, speeds))
        assert valid[3] == 0.0  # no ray turns in water of one speed: no other eigenray of the direct family
        tau, valid, spreading, length = tau[:3], valid[:3], spreading[:3], length[:3]
        assert valid.all()
        np.testing.assert_allclose(spreading, 20 * np.log10(want), rtol=0, atol=1e-12)
        np.testing.assert_allclose(length, want, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(tau, want / 1493.0, rtol=4e-15)


def test_level_path_and_coincident_points():
    """A level path in isovelocity water (source and receiver at one depth, the family degenerate) is the straight
    line; within 1 m of the source the loss is floored at 0 dB (the source level is given at 1 m)."""
    out = paths(ISO, 40.0, 40.0, 700.0)
    assert out[3][0] == 1 and out[4][0] == pytest.approx(20 * np.log10(700.0), abs=1e-12)
    assert out[5][0] == pytest.approx(700.0, abs=1e-9)
    out = paths(ISO, 40.0, 40.3, 0.2)
    assert out[4][0] == 0.0 and out[5][0] == pytest.approx(np.hypot(0.3, 0.2), rel=1e-12)


#: c = C0 + G z: a linear gradient, every ray a circular arc centred at the depth where c would vanish.
C0, G = 1480.0, 0.05


def _arc(zs, zr, x):
    """The eigenray of the linear gradient from the geometry of its circle (not the layer formulas):
    ``(spreading [dB], arc length [m])``.

    The circle through both ends has its centre at depth ``z_c = −C0 / G`` and horizontal position ``x_c``; with
    ``a = z_s − z_c``, ``b = z_r − z_c`` and the launch angle θ (``x_c = a tan θ``, radius ``R = a / cos θ``) the
    range at depth ``z_r`` is ``r(θ) = a tan θ ± √(a² sec² θ − b²)`` (+ past the arc's lowest point), so
    ``∂r/∂θ = a sec² θ ± a² sec² θ tan θ / √(a² sec² θ − b²)``; the arrival's grazing angle has
    ``sin θ_r = |x − x_c| / R``; ``|p/p0|² = (c_r / c_s) cos θ / (x |∂r/∂θ| sin θ_r)`` (Jensen et al., ch. 3)."""
    zc = -C0 / G
    a, b = zs - zc, zr - zc
    cs, cr = C0 + G * zs, C0 + G * zr
    if x == 0.0:  # the vertical ray: the tube's limit c_s c_r / (∫ c dz)², ∫ c dz = (c_r² − c_s²) / (2 G)
        return 10 * np.log10(((cr * cr - cs * cs) / (2 * G)) ** 2 / (cs * cr)), abs(zr - zs)
    xc = (x * x + b * b - a * a) / (2 * x)
    radius = np.hypot(a, xc)
    theta = np.arctan2(xc, a)
    sec2 = 1.0 / np.cos(theta) ** 2
    dr = a * sec2 + np.sign(x - xc) * a * a * sec2 * np.tan(theta) / np.sqrt(a * a * sec2 - b * b)
    intensity = (cr / cs) * np.cos(theta) / (x * abs(dr) * abs(x - xc) / radius)
    return -10 * np.log10(intensity), radius * abs(np.arctan2(b, x - xc) - np.arctan2(a, -xc))


@pytest.mark.parametrize("zs, zr, x", [(100.0, 900.0, 2000.0), (1000.0, 1000.0, 3000.0), (2000.0, 100.0, 5000.0),
                                       (500.0, 600.0, 4000.0), (3000.0, 50.0, 1000.0), (40.0, 3900.0, 700.0),
                                       (40.0, 3900.0, 0.0), (2500.0, 20.0, 0.0)])
def test_linear_gradient_is_the_circular_arc_tube(zs, zr, x):
    """The direct eigenray's spreading within 1e-6 dB (the task asks 0.1 dB) of the circle's closed form, its length
    within 1 mm, the vertical ray included (x = 0: its limit, not a floor)."""
    table = np.array([[0.0, C0], [5000.0, C0 + 5000.0 * G]])
    want, arc = _arc(zs, zr, x)
    out = paths(table, zs, zr, x)
    assert out[3][0] == 1
    assert out[4][0] == pytest.approx(want, abs=1e-6)
    assert out[5][0] == pytest.approx(arc, abs=1e-3)


def test_the_vertical_limit_is_continuous():
    """Through the Munk table: at x = 0 the spreading is c_s c_r / (∫ c dz)² (the integral by the trapezoid rule on
    a fine grid), and 1 cm off the vertical it is the same within 1e-4 dB (the tube, not a floor)."""
    table = munk_table()
    zs, zr = 30.0, 3500.0
    z = np.linspace(zs, zr, 200001)
    c = np.interp(z, table[:, 0], table[:, 1])
    integral = np.sum(0.5 * (c[1:] + c[:-1]) * np.diff(z))
    want = 10 * np.log10(integral ** 2 / (c[0] * c[-1]))
    assert paths(table, zs, zr, 0.0)[4][0] == pytest.approx(want, abs=1e-6)
    assert paths(table, zs, zr, 0.01)[4][0] == pytest.approx(want, abs=1e-4)


# ------------------------------------------------------------------ the ray equations integrated


def _ivp(table, zs, x, theta0, depth):
    """Integrate dz/dr = tan θ, dθ/dr = −c'(z)/c in range from depth ``zs`` at launch angle ``theta0`` [rad],
    reflecting at 0 and ``depth``: (z, θ) at ``x`` and the boundaries hit (0 surface, 1 bottom)."""
    # the table as Python floats, and each layer's gradient: the right-hand side runs millions of times, on scalars
    zt, ct = [float(v) for v in table[:, 0]], [float(v) for v in table[:, 1]]
    slopes = [(ct[k + 1] - ct[k]) / (zt[k + 1] - zt[k]) for k in range(len(zt) - 1)]
    last = len(zt) - 2

    def rhs(r, y):
        z, th = float(y[0]), float(y[1])
        k = min(max(bisect_right(zt, z) - 1, 0), last)
        g = 0.0 if (z < zt[0] or z > zt[-1]) else slopes[k]
        return [math.tan(th), -g / (ct[k] + slopes[k] * (min(max(z, zt[0]), zt[-1]) - zt[k]))]

    def top(r, y):
        return y[0]

    def bottom(r, y):
        return y[0] - depth

    top.terminal = bottom.terminal = True
    top.direction, bottom.direction = -1, 1
    y, r0, hits = [zs, theta0], 0.0, []
    while True:
        sol = solve_ivp(rhs, (r0, x), y, method="DOP853", rtol=1e-10, atol=1e-10, events=[top, bottom],
                        max_step=50.0)
        if sol.status != 1:
            return sol.y[0, -1], sol.y[1, -1], hits
        which = 0 if len(sol.t_events[0]) else 1
        r0, y = sol.t_events[which][0], sol.y_events[which][0].copy()
        y[0], y[1] = (0.0, -y[1]) if which == 0 else (depth, -y[1])
        hits.append(which)


#: Launch-angle step [rad] of the finite differences of the integrated rays.
DELTA = 1e-4


def _ivp_spreading(table, zs, zr, x, theta, depth):
    """The integrated ray from our launch angle ``theta``: (its miss at the receiver [m], boundaries hit, the
    spreading [dB] of its tube ``|p/p0|² = (c_r / c_s) cos θ_s / (x |∂z/∂θ_s| cos θ_r)``, ``∂z/∂θ_s`` at fixed range
    by central differences of two more integrated rays — the same tube as ``r |∂r/∂θ_s| sin θ_r``, since
    ``∂r/∂θ_s = −∂z/∂θ_s / tan θ_r``)."""
    z, th, hits = _ivp(table, zs, x, theta, depth)
    up, down = _ivp(table, zs, x, theta + DELTA, depth)[0], _ivp(table, zs, x, theta - DELTA, depth)[0]
    dz = (up - down) / (2 * DELTA)
    cs, cr = np.interp(zs, table[:, 0], table[:, 1]), np.interp(zr, table[:, 0], table[:, 1])
    intensity = (cr / cs) * np.cos(theta) / (x * abs(dz) * np.cos(th))
    return z - zr, hits, -10 * np.log10(intensity)


#: (profile, source depth, receiver depth, range): Munk's deep sound channel, and the strong table's surface duct,
#: thermocline and deep increase (turning rays above and below, surface and bottom paths).
IVP_CASES = [("munk", 1000.0, 1000.0, 4700.0), ("munk", 1300.0, 1300.0, 5000.0), ("munk", 115.0, 3015.0, 2783.0),
             ("munk", 3800.0, 1250.0, 2232.0), ("strong", 20.0, 60.0, 1500.0), ("strong", 100.0, 1200.0, 3000.0),
             ("strong", 3000.0, 300.0, 4500.0), ("strong", 700.0, 700.0, 2500.0), ("strong", 2050.0, 3800.0, 892.0)]


@pytest.mark.slow
@pytest.mark.parametrize("name, zs, zr, x", IVP_CASES)
def test_spreading_against_solve_ivp(name, zs, zr, x):
    """Every family's spreading within 0.5 dB of the integrated rays' tube (finite differences of the launch angle),
    away from caustics: a ray whose integrated tube gains more than CAUSTIC_GAIN − 1 dB over the spherical spreading
    of its image is left out (none of these is)."""
    table = munk_table() if name == "munk" else STRONG
    depth = float(table[-1, 0])
    out = paths(table, zs, zr, x, depth)
    checked = 0
    for k in range(3):
        if not out[3][k]:
            continue
        miss, hits, want = _ivp_spreading(table, zs, zr, x, out[1][k], depth)
        assert abs(miss) < 0.05 and hits == [[], [0], [1]][k]  # the integration follows the same eigenray
        image = np.hypot(x, [zr - zs, zs + zr, 2 * depth - zs - zr][k])
        if 20 * np.log10(image) - want > spreading_loss.CAUSTIC_GAIN - 1.0:
            continue
        print(f"{name} {zs} {zr} {x} family {k + 1}: ours {out[4][k]:.4f} dB, integrated {want:.4f} dB")
        assert out[4][k] == pytest.approx(want, abs=0.5)
        checked += 1
    assert checked >= 2


@pytest.mark.parametrize("zs, zr, x", [(20.0, 60.0, 5000.0), (60.0, 20.0, 5000.0), (10.0, 70.0, 4500.0),
                                       (30.0, 50.0, 6000.0)])
def test_surface_duct_spreading_against_solve_ivp(zs, zr, x):
    """The surface-reflected eigenray that also turns below the deeper end (the strong table's surface duct): its
    spreading within 0.01 dB of the integrated rays' tube, the integration following it (one surface reflection,
    within 5 cm of the receiver) and no caustic cap; its length longer than the image path's and within 2 m of it
    (a nearly level ray)."""
    depth = float(STRONG[-1, 0])
    out = paths(STRONG, zs, zr, x, depth)
    assert out[3][1] and np.sign(out[1][1]) == np.sign(out[2][1])  # leaving and arriving the same way: it turns
    miss, hits, want = _ivp_spreading(STRONG, zs, zr, x, out[1][1], depth)
    assert abs(miss) < 0.05 and hits == [0]
    image = np.hypot(x, zs + zr)
    assert 20 * np.log10(image) - want < spreading_loss.CAUSTIC_GAIN - 1.0
    assert out[4][1] == pytest.approx(want, abs=0.01)
    assert image < out[5][1] < image + 2.0


# ------------------------------------------------------------------ Bellhop's incoherent transmission loss

#: Bellhop's fan [deg] and its number of beams (geometric beams, run type 'I': incoherent TL).
BELLHOP_FAN, BELLHOP_BEAMS = 89.0, 4001
#: A point is left out where Bellhop's TL differs by more than this [dB] from one of its four neighbours on the grid
#: (a caustic or a shadow edge, where ray theory and beams differ by construction).
JUMP = 3.0
#: The sites: (profile, water depth [m], bottom, source depth [m], receiver depths, ranges [m]). ``absorbing``: an
#: acousto-elastic half-space matching the water (sound speed and density), which reflects nothing (the bottom
#: family then carries nothing); ``rigid``: |R| = 1. The surface is a vacuum (|R| = 1) at both. The isovelocity site
#: stops at 300 m range: beyond about 450 m the paths reflected twice or more (surface and bottom, which the
#: families do not hold) add more than 2 dB there (the image sum of a pressure-release surface and a rigid bottom).
BELLHOP_SITES = {
    "munk": (munk_table(), 5000.0, "absorbing", 1000.0, np.arange(50.0, 4001.0, 100.0),
             np.arange(200.0, 5001.0, 200.0)),
    "isovelocity": (np.array([[0.0, 1500.0], [300.0, 1500.0]]), 300.0, "rigid", 20.0, np.arange(5.0, 296.0, 10.0),
                    np.arange(10.0, 301.0, 10.0)),
}
_BELLHOP: dict[str, tuple] = {}


def _bellhop_tl(table, source, depths, ranges, depth, bottom, frequency=1000.0, volume=None):
    """Bellhop's incoherent TL [dB] on the grid (depths × ranges) at ``frequency`` [Hz], below a vacuum surface.

    ``bottom``: ``"rigid"``, ``"absorbing"`` (an acousto-elastic half-space matching the water) or
    ``(density ratio, compressional speed [m/s], attenuation [dB/λ])`` of an acousto-elastic half-space without
    shear. ``volume``: None (no volume attenuation), ``(temperature [°C], salinity [PSU], pH, depth [m])`` of
    Bellhop's Francois-Garrison attenuation (option 'F', one depth for the whole water column), or a volume
    attenuation [dB/m] given at every point of the profile (as dB/λ, ``α λ = α c / f``)."""
    pg = pytest.importorskip("pelagic")  # the test extra installs it: this skips only outside it
    tab = table[table[:, 0] < depth]
    tab = np.vstack([tab, [depth, np.interp(depth, table[:, 0], table[:, 1])]])
    lines = ["'sblsim tl'", f"{frequency:.6f}", "1"]
    if volume is None or np.isscalar(volume):
        lines += ["'CVW'"]
    else:
        lines += ["'CVWF'", " ".join(f"{v:.6f}" for v in volume) + " /"]
    lines += [f"0 0.0 {depth:.4f}"]
    if np.isscalar(volume):  # z, c_p, c_s, density, α_p [dB/λ], α_s
        lines += [f"{z:.6f} {c:.6f} 0.0 1.0 {volume * c / frequency:.9f} 0.0 /" for z, c in tab]
    else:
        lines += [f"{z:.6f} {c:.6f} /" for z, c in tab]
    if bottom == "rigid":
        lines += ["'R' 0.0"]
    elif bottom == "absorbing":
        lines += ["'A' 0.0", f"{depth:.4f} {tab[-1, 1]:.6f} 0.0 1.0 0.0 /"]
    else:
        density, speed, attenuation = bottom
        lines += ["'A' 0.0", f"{depth:.4f} {speed:.6f} 0.0 {density:.6f} {attenuation:.6f} 0.0 /"]
    lines += ["1", f"{source:.6f} /", f"{len(depths)}", " ".join(f"{z:.6f}" for z in depths) + " /",
              f"{len(ranges)}", " ".join(f"{r / 1000:.9f}" for r in ranges) + " /", "'I'", f"{BELLHOP_BEAMS}",
              f"{-BELLHOP_FAN} {BELLHOP_FAN} /", f"0.0 {depth + 100:.1f} {max(ranges) / 1000 + 0.2:.3f}"]
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "case.env")
        with open(path, "w") as handle:
            handle.write("\n".join(lines) + "\n")
        result = pg.bellhop.load(path).run()
    return np.asarray(result.field.transmission_loss()[0], dtype=float)


def _site(name):
    """Bellhop's TL and our families' outputs at the site ``name`` (computed once per session).

    Ours are the families as the channel evaluates them, compiled in the local engine's library
    (:func:`~sblsim.fmus.compiled_functions.compiled_family_points`: casadi's own evaluation takes over a minute for the
    grid), checked equal to :func:`rays.eigenray_paths` evaluated by casadi itself at every 97th point of the grid."""
    if name not in _BELLHOP:
        from sblsim.fmus.compiled_functions import compiled_family_points

        table, depth, bottom, source, depths, ranges = BELLHOP_SITES[name]
        theirs = _bellhop_tl(table, source, depths, ranges, depth, bottom)
        zr, x = (a.ravel() for a in np.meshgrid(depths, ranges, indexing="ij"))
        compiled = compiled_family_points()
        ours = paths_at(table, source, zr, x, depth, compiled)
        if compiled is not None:
            sample = slice(0, zr.size, 97)
            for got, want in zip(ours, paths_at(table, source, zr[sample], x[sample], depth)):
                np.testing.assert_array_equal(got[:, sample], want)
        _BELLHOP[name] = (theirs, ours, zr, x)
    return _BELLHOP[name]


def _jumps(theirs):
    """The largest |ΔTL| [dB] between each point of a (depths × ranges) TL grid and its four neighbours (the grid's
    edge repeated): more than :data:`JUMP` marks a caustic or a shadow edge."""
    padded = np.pad(theirs, 1, mode="edge")
    return np.max([np.abs(padded[1 + i:1 + i + theirs.shape[0], 1 + j:1 + j + theirs.shape[1]] - theirs)
                   for i, j in ((-1, 0), (1, 0), (0, -1), (0, 1))], axis=0)


def _compare_with_bellhop(name, offset=0.0):
    """Our incoherent TL (the families' intensities 10^(−spreading/10) summed; the bottom family only where the
    bottom reflects) against Bellhop's outside the mask: (points compared, points masked, max |ΔTL| [dB], median)."""
    table, depth, bottom, source, depths, ranges = BELLHOP_SITES[name]
    theirs, out, zr, x = _site(name)
    _tau, _launch, _arrival, valid, spreading, _length = out
    # the families the images bound: direct, surface, bottom (the fourth row, a ray turning in the water, is the
    # first arrival's, not a family of its own in the loss)
    valid, spreading = valid[:3], spreading[:3] + offset
    families = 3 if bottom == "rigid" else 2
    intensity = np.sum(np.where(valid[:families] > 0, 10.0 ** (-spreading[:families] / 10.0), 0.0), axis=0)
    ours = (-10.0 * np.log10(intensity)).reshape(theirs.shape)
    # the mask: Bellhop's TL jumping between neighbours, and our tube capped at a caustic
    jumps = _jumps(theirs)
    image = np.hypot(x, np.array([zr - source, zr + source, 2 * depth - source - zr]))
    cap = 20 * np.log10(image) - spreading_loss.CAUSTIC_GAIN
    capped = np.any((valid > 0) & (np.abs(spreading - offset - cap) < 1e-9), axis=0).reshape(theirs.shape)
    keep = (jumps <= JUMP) & ~capped & np.isfinite(theirs)
    error = np.abs(ours - theirs)[keep]
    return int(keep.sum()), int((~keep).sum()), float(error.max()), float(np.median(error))


@pytest.mark.slow
@pytest.mark.parametrize("name", list(BELLHOP_SITES))
def test_bellhop_incoherent_tl(name):
    """The families' summed intensities within 3 dB of Bellhop's incoherent TL at ≥ 200 receiver points outside the
    mask (:data:`JUMP`, and our caustic cap): Munk with the source 1000 m deep, receivers to 4 km depth and 5 km
    range (1000 points, a bottom that reflects nothing), and isovelocity water with a rigid bottom at 300 m (900
    points, out to 300 m range). ``pytest -s`` prints the numbers."""
    compared, masked, worst, median = _compare_with_bellhop(name)
    print(f"{name}: {compared} points compared, {masked} masked, max |ΔTL| {worst:.3f} dB, median {median:.4f} dB")
    assert compared >= 200
    assert worst <= 3.0


@pytest.mark.slow
def test_bellhop_comparison_can_fail():
    """The comparison fails for a loss 3.5 dB off everywhere (Munk)."""
    compared, _masked, worst, _median = _compare_with_bellhop("munk", offset=3.5)
    assert compared >= 200 and worst > 3.0


# ------------------------------------------------------------------ the channel's function


def test_arrivals_in_an_sx_expression_agree_with_first_arrival():
    """``arrivals`` called with SX symbols (as the channel's event handlers call ``first_arrival_grid``) gives the
    families of ``eigenray_paths``; its earliest valid row is ``first_arrival``'s eigenray, through the table and
    through the constant speed."""
    table = munk_table()
    nodes, speeds = rays.profile_arrays(table)
    sym = [ca.SX.sym(n) for n in ("use", "zs", "zr", "x", "depth", "c")]
    nd, sp = ca.SX.sym("nodes", nodes.size), ca.SX.sym("speeds", speeds.size)
    f = ca.Function("f", [*sym, nd, sp], list(rays.arrivals(*sym, nd, sp)))
    for use, zs, zr, x, depth in [(1.0, 30.0, 900.0, 1200.0, 1000.0), (1.0, 500.0, 40.0, 3000.0, 0.0),
                                  (0.0, 30.0, 900.0, 1200.0, 1000.0), (1.0, 5.0, 60.0, 150.0, 80.0)]:
        got = [np.asarray(v).ravel() for v in f(use, zs, zr, x, depth, 1500.0, nodes, speeds)]
        if use:
            want = paths(table, zs, zr, x, depth)
            for k in range(3 if depth > 0 else 1):
                for g, w in zip(got, want):
                    assert g[k] == w[k]
            if depth == 0:
                assert not got[3][1:].any()
        tau, launch, arrival, kind = (float(v) for v in rays.first_arrival(use, zs, zr, x, depth, 1500.0, nodes,
                                                                            speeds))
        times = np.where(got[3] > 0, got[0], np.inf)
        assert int(np.argmin(times)) + 1 == kind and times.min() == tau
        assert got[1][int(kind) - 1] == launch and got[2][int(kind) - 1] == arrival
