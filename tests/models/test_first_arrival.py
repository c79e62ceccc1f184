"""The channel's first arrival is the earliest eigenray heard (models/acoustics/rays.py, detection.py): where the
direct family holds several eigenrays (a ray that turns beyond the faster end as well as the straight one), against
the closed form of rays through linear-gradient layers and Bellhop's arrivals (M. Porter, through the ``pelagic``
package) at the ``lbl-field`` site."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from sblsim.models.acoustics import detection, rays
from sblsim.orchestrator.cosim.plan import load_plan

#: lbl-field's profile (orchestrator/scenarios/lbl-field.toml), its water depth, a transponder and the vehicle.
LBL_FIELD = np.array([[0.0, 1510.0], [30.0, 1508.0], [60.0, 1495.0], [100.0, 1489.0], [300.0, 1487.0]])
DEPTH, ZS, ZR = 300.0, 299.0, 150.0
DISTANCES = (3500.0, 4000.0, 4500.0, 5000.0, 6000.0)


def _families(table, zs, zr, x, depth):
    nodes, speeds = rays.profile_arrays(table)
    return [np.asarray(v).ravel() for v in rays.eigenray_families()(zs, zr, x, depth, nodes, speeds)]


# ------------------------------------------------------------------ closed form: arcs of linear-gradient layers


def _arcs(table, zs, zr, turn_layer, xi):
    """Range [m], time [s] and launch grazing angle [rad] (unsigned) of the ray of Snell's invariant ``xi`` from
    ``zs`` up to its turning point in the layer ``turn_layer`` (rows k, k + 1 of ``table``, the speed falling with
    depth above ``zs``) and down to ``zr``. In a layer ``c = c_a + g (z − z_a)`` the ray is a circular arc of radius
    ``1 / (ξ |g|)``: between grazing angles θ_a and θ_b it covers ``|sin θ_a − sin θ_b| / (ξ |g|)`` in range and
    ``|ln tan(π/4 + θ_b/2) − ln tan(π/4 + θ_a/2)| / |g|`` in time (``dt = dθ / (|g| cos θ)``; Jensen, Kuperman,
    Porter, Schmidt, *Computational Ocean Acoustics*, 2nd ed., 2011, § 3.3; Medwin & Clay, *Fundamentals of
    Acoustical Oceanography*, 1998, § 2.6)."""
    z, c = table[:, 0], table[:, 1]

    def theta(speed):
        return math.acos(min(1.0, xi * speed))

    def leg(z_end):  # from z_end up to the turning point: the layers crossed whole, then the turning one
        x = t = 0.0
        for k in range(len(z) - 2, turn_layer, -1):
            top, bottom = z[k], min(z[k + 1], z_end)
            if bottom <= top:
                continue
            g = (c[k + 1] - c[k]) / (z[k + 1] - z[k])
            ca_, cb_ = np.interp(top, z, c), np.interp(bottom, z, c)
            ta, tb = theta(ca_), theta(cb_)
            x += abs(math.sin(ta) - math.sin(tb)) / (xi * abs(g))
            t += abs(math.log(math.tan(math.pi / 4 + tb / 2)) - math.log(math.tan(math.pi / 4 + ta / 2))) / abs(g)
        k = turn_layer
        g = (c[k + 1] - c[k]) / (z[k + 1] - z[k])
        t0 = theta(c[k + 1])  # at the layer's bottom; 0 where it turns
        x += math.sin(t0) / (xi * abs(g))
        t += math.log(math.tan(math.pi / 4 + t0 / 2)) / abs(g)
        return x, t

    xs, ts = leg(zs)
    xr, tr = leg(zr)
    return xs + xr, ts + tr, theta(np.interp(zs, z, c))


def test_a_turning_ray_through_linear_layers_is_the_earliest_arrival_and_its_closed_form():
    """At lbl-field, 4.5 km from a transponder at 299 m to a vehicle at 150 m: the ray that leaves upward, turns
    in the top layer (0–30 m, at 11.6 m) and comes back, its Snell invariant solved from the closed-form range, is
    the first arrival (kind OTHER) within 1e-9 s of its closed-form time and 1e-8 rad of its launch angle, 4 ms
    before the straight ray, which stays the direct row."""
    x = 4500.0
    z, c = LBL_FIELD[:, 0], LBL_FIELD[:, 1]
    # Snell's invariant of the rays turning inside the top layer: from grazing the surface to turning at 30 m
    lo, hi = 1.0 / c[0], 1.0 / c[1]
    xi = brentq(lambda v: _arcs(LBL_FIELD, ZS, ZR, 0, v)[0] - x, lo * (1 + 1e-15), hi * (1 - 1e-15), xtol=1e-22,
                rtol=1e-15)
    _x, want, launch = _arcs(LBL_FIELD, ZS, ZR, 0, xi)
    turning_depth = (1.0 / xi - c[0]) / ((c[1] - c[0]) / z[1])
    assert 5.0 < turning_depth < 25.0  # 11.6 m
    tau, angles, arrival, valid = _families(LBL_FIELD, ZS, ZR, x, DEPTH)
    assert valid[3] and tau[3] == pytest.approx(want, abs=1e-9)
    assert angles[3] == pytest.approx(-launch, abs=1e-8)  # leaving upward
    first = [float(v) for v in rays.first_arrival(1.0, ZS, ZR, x, DEPTH, 1500.0, *rays.profile_arrays(LBL_FIELD))]
    assert first[3] == rays.OTHER and first[0] == tau[3]
    assert tau[0] - tau[3] > 3e-3 and valid[0]
    # without boundaries too (the family alone)
    bare = [float(v) for v in rays.first_arrival(1.0, ZS, ZR, x, 0.0, 1500.0, *rays.profile_arrays(LBL_FIELD))]
    assert bare[3] == rays.OTHER and bare[0] == tau[3]


@pytest.mark.parametrize("zs, zr, x", [(1000.0, 1000.0, 3000.0), (500.0, 600.0, 4000.0), (250.0, 200.0, 8000.0),
                                       (300.0, 300.0, 9000.0)])
def test_a_linear_gradient_has_one_eigenray_and_its_turning_time_is_the_closed_form(zs, zr, x):
    """c = c0 + g z (speed growing with depth): every ray is an arc of a circle centred where c would vanish, so one
    eigenray joins two points; here it turns below the deeper end. Its time is the closed form
    ``(ln tan(π/4 + θ_s/2) + ln tan(π/4 + θ_r/2)) / g`` (θ the grazing angles at the ends, through the turning
    point, θ = 0), its range ``(sin θ_s + sin θ_r) / (ξ g)`` solved for Snell's invariant ξ; the first arrival is
    that ray (kind DIRECT, within 1e-10 s) and the direct family holds no other."""
    c0, g = 1480.0, 0.05
    table = np.array([[0.0, c0], [12000.0, c0 + 12000.0 * g]])
    cs, cr = c0 + g * zs, c0 + g * zr

    def span(xi):
        return (math.sqrt(1 - (xi * cs) ** 2) + math.sqrt(1 - (xi * cr) ** 2)) / (xi * g)

    xi = brentq(lambda v: span(v) - x, 1e-9, 1.0 / max(cs, cr) * (1 - 1e-15), xtol=1e-22, rtol=1e-15)
    ts, tr = math.acos(xi * cs), math.acos(xi * cr)
    want = (math.log(math.tan(math.pi / 4 + ts / 2)) + math.log(math.tan(math.pi / 4 + tr / 2))) / g
    bottom = (1.0 / xi - c0) / g  # the turning depth: below both ends
    assert bottom > max(zs, zr)
    tau, launch, arrival, valid = _families(table, zs, zr, x, 0.0)
    assert valid[0] and not valid[3]
    assert tau[0] == pytest.approx(want, abs=1e-10)
    assert launch[0] == pytest.approx(ts, abs=1e-10) and arrival[0] == pytest.approx(-tr, abs=1e-10)
    first = [float(v) for v in rays.first_arrival(1.0, zs, zr, x, 0.0, 1500.0, *rays.profile_arrays(table))]
    assert first[3] == rays.DIRECT and first[0] == pytest.approx(want, abs=1e-10)


# ------------------------------------------------------------------ the earliest heard, against Bellhop


def _site():
    plan = load_plan("lbl-field")
    params = plan.component_parameters("acoustics")
    from sblsim.models.acoustics.channel.site_levels import _site as site_of

    return params, dict(zip(detection.SITE, site_of(params)[1]))


def _ours(x):
    """Our eigenrays at ``x`` with their SNR and detection probability (the channel's site function)."""
    from sblsim.models.acoustics.channel.site_levels import site_levels

    params, _site_numbers = _site()
    levels = site_levels(params, [[0.0, 0.0, ZS]], [[x, 0.0, ZR]])
    return {k: v[0] for k, v in levels.items()}


def test_the_first_heard_arrival_is_the_earliest_eigenray_above_the_threshold():
    """At 4.5 km the direct family's other eigenray (turning at 11.6 m, SNR 18.7 dB, 8 dB below the straight ray)
    arrives first when it is detected; the channel's draw decides it with the low bits of the direct ray's uniform
    (:func:`~sblsim.models.acoustics.detection.other_draw`), and where it is missed the straight ray is first."""
    import casadi as ca

    lv = _ours(4500.0)
    assert lv["valid"][3] and lv["tau"][3] < lv["tau"][0] and lv["snr"][3] > 12.0
    nodes, speeds = rays.profile_arrays(LBL_FIELD)
    params, site = _site()
    fam = detection.family_levels()(ZS, ZR, 4500.0, DEPTH, 1.0, 1500.0, nodes, speeds,
                                    [site[k] for k in detection.SITE])
    pd_other = float(fam[5][3])

    def first(draws):
        return [float(v) for v in detection.first_detected(*fam, ca.DM(draws))]

    heard_all = first([0.0, 0.0, 0.0])
    assert heard_all[3] == rays.OTHER and heard_all[0] == pytest.approx(float(fam[0][3]), abs=0)
    # a direct-ray uniform whose low bits miss the other ray: the straight one is first
    u = 0.25 + (pd_other + (1 - pd_other) / 2) / detection.OTHER_DRAW_SCALE
    assert float(detection.other_draw(u)) > pd_other and u < float(fam[5][0])
    missed = first([u, 0.99, 0.0])
    assert missed[3] == rays.DIRECT and missed[0] == pytest.approx(float(fam[0][0]), abs=0)


BELLHOP_BEAMS, BELLHOP_FAN, BELLHOP_STEP = 4001, 86.0, 5.0
#: Bellhop's arrivals per range [m], run once per session for every distance.
_BELLHOP: dict = {}


def _bellhop(ranges):
    pg = pytest.importorskip("pelagic")  # the test extra installs it
    import os
    import tempfile

    tab = LBL_FIELD
    lines = ["'sblsim'", "12000.0", "1", "'CVW'", f"0 0.0 {DEPTH:.4f}"]
    lines += [f"{z:.6f} {c:.6f} /" for z, c in tab]
    lines += ["'A' 0.0", f"{DEPTH:.4f} 1650.00 0.0 1.9 0.8 /", "1", f"{ZS:.6f} /", "1", f"{ZR:.6f} /",
              f"{len(ranges)}", " ".join(f"{r / 1000:.9f}" for r in ranges) + " /", "'A'", f"{BELLHOP_BEAMS}",
              f"{-BELLHOP_FAN} {BELLHOP_FAN} /", f"{BELLHOP_STEP} {DEPTH + 100:.1f} {max(ranges) / 1000 + 1:.3f}"]
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "case.env")
        with open(path, "w") as handle:
            handle.write("\n".join(lines) + "\n")
        return pg.bellhop.load(path).run().arrivals.to_pandas()


@pytest.mark.parametrize("x", DISTANCES)
def test_the_first_arrival_at_lbl_field_is_bellhops_earliest_above_the_threshold(x):
    """Bellhop's arrivals (c-linear, 4001 beams over ±86°, a vacuum surface, the site's sand half-space) between a
    transponder at 299 m and the vehicle at 150 m: the earliest whose SNR (the site's source level, ambient noise and
    directivity, Bellhop's amplitude for the spreading and the bottom, the site's absorption over the path) reaches
    the detection threshold arrives within 1 µs of ours: the earliest of our eigenrays whose SNR reaches it. From
    4.5 km that is a ray turning near 20 m, 4 ms before the straight ray (the channel used to report a surface
    reflection 78 µs later there, and at 5 and 6 km no direct ray at all); at 5 km Bellhop's beam grazing the
    surface (no ray: the ray grazing it lands at 4.92 km) arrives 8.8 ms earlier, 8.7 dB below the threshold."""
    if not _BELLHOP:
        _BELLHOP.update(dict(tuple(_bellhop(list(DISTANCES)).groupby("range_m"))))
    arrivals = _BELLHOP[min(_BELLHOP, key=lambda r: abs(r - x))]
    _params, site = _site()
    amplitude = np.abs(arrivals.amplitude.values)
    loss = -20.0 * np.log10(np.maximum(amplitude, 1e-300)) \
        + site["absorption"] * 1490.0 * arrivals.travel_time_s.values
    snr = site["source_level"] - loss - site["noise"] + site["directivity_index"]
    heard = arrivals[snr >= site["detection_threshold"]]
    theirs = float(heard.travel_time_s.min())
    lv = _ours(x)
    ours_heard = (lv["valid"] > 0.5) & (lv["snr"] >= site["detection_threshold"])
    ours = float(np.min(np.where(ours_heard, lv["tau"], np.inf)))
    assert abs(ours - theirs) <= 1e-6, (x, ours, theirs)
    kind = int(np.argmin(np.where(ours_heard, lv["tau"], np.inf))) + 1
    assert kind == (rays.OTHER if x == 4500.0 else rays.DIRECT), kind
