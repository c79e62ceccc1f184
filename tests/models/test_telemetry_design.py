"""The telemetry array's criteria (:mod:`sblsim.models.design.telemetry`), its detection range curve
(:mod:`sblsim.models.design.detection_curve`) and study areas (:mod:`sblsim.models.design.area`), against
computations written here independently:

* the DRMS of a fix against the full Fisher information of ``(p, t_e)`` in seconds, inverted whole and its
  position block taken (no Schur complement written), for several layouts, patterns and a range-dependent σ; the
  averaged information against the accuracy map's casadi function (``layout_values`` with ``emission``);
* the closed form ``2σ/√N`` of a regular ring at its centre, and its growth off the centre;
* the positioning yield against a sum over every detection pattern and against a binomial Monte Carlo of 10⁴ pings;
* the RMS over fixed pings against a loop over the patterns with the tracker's own fix DRMS;
* the sync graph on layouts drawn by hand; polygon containment against shapely's ``contains`` per point, a ray
  casting written here and an L-shaped lake whose answers are known.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from sblsim.models.design import area as ar
from sblsim.models.design import information
from sblsim.models.design import sync_graph as sg
from sblsim.models.design import telemetry as tm
from sblsim.models.design.detection_curve import DetectionCurve
from sblsim.models.errors import ModelError
from sblsim.models.receiver import toa_bound

C = 1470.0  # sound speed [m/s]


# --- the detection range curve ---------------------------------------------------------------------------------

def test_the_logistic_curve_is_the_formula_and_its_ranges_invert_it():
    curve = DetectionCurve.logistic(200.0, 0.025)
    d = np.array([0.0, 50.0, 200.0, 350.0, 5e3])
    np.testing.assert_allclose(curve.probability(d), [1.0 / (1.0 + math.exp(0.025 * (x - 200.0))) for x in d],
                               rtol=1e-14, atol=1e-300)
    assert curve.probability(200.0) == 0.5 and curve.probability(1e7) == 0.0 and curve.probability(-1e7) == 1.0
    for p in (0.1, 0.5, 0.9):
        assert curve.probability(curve.range_at(p)) == pytest.approx(p, abs=1e-12)
    assert curve.range_at(0.1) - curve.range_at(0.9) == pytest.approx(2 * math.log(9) / 0.025)


def test_a_table_is_interpolated_and_held_at_its_ends():
    curve = DetectionCurve.from_mapping({"table": [[50, 1.0], [150, 0.8], [250, 0.2], [400, 0.0]]})
    np.testing.assert_allclose(curve.probability([0, 50, 100, 200, 325, 1000]), [1.0, 1.0, 0.9, 0.5, 0.1, 0.0])
    assert curve.range_at(0.5) == pytest.approx(200.0)
    assert DetectionCurve.from_mapping({"range_50_m": 100, "slope": 0.1}) == DetectionCurve.logistic(100, 0.1)


@pytest.mark.parametrize("values, key", [
    ({"range_50_m": -5, "slope": 0.1}, "detection.range_50_m"),
    ({"range_50_m": 100, "slope": 0.0}, "detection.slope"),
    ({"range_50_m": 100, "slope": "steep"}, "detection.slope"),
    ({"range_50_m": 100}, "detection.slope"),
    ({"range_50_m": 100, "slope": 0.1, "table": [[0, 1], [10, 0]]}, "detection.range_50_m"),
    ({"table": [[0, 0.5], [100, 0.9]]}, "detection.table"),
    ({"table": [[0, 1.0], [0, 0.5]]}, "detection.table"),
    ({"table": [[0, 1.5], [10, 0.5]]}, "detection.table"),
    ({"table": [[0, 1.0]]}, "detection.table"),
    ({"range_m": 100}, "detection.range_m"),
])
def test_a_bad_curve_is_one_line_naming_its_key_and_the_allowed_values(values, key):
    with pytest.raises(ModelError) as error:
        DetectionCurve.from_mapping(values)
    message = str(error.value)
    assert message.startswith(key + ":") and "allowed" in message and "\n" not in message


# --- the DRMS of a fix -----------------------------------------------------------------------------------------

def _fisher_drms(point, receivers, heard, sigma_toa):
    """The DRMS from the full information of (p [m], t_e [s]) in seconds, inverted whole."""
    rows = []
    for r, h, s in zip(receivers, heard, sigma_toa):
        if h:
            u = (point - r) / np.linalg.norm(point - r)
            rows.append(np.r_[u / C, 1.0] / s)
    if len(rows) < len(point) + 1:
        return np.inf
    H = np.array(rows)
    cov = np.linalg.inv(H.T @ H)
    return math.sqrt(cov[0, 0] + cov[1, 1])


@pytest.mark.parametrize("dim", [2, 3])
def test_the_fix_drms_is_the_inverse_of_the_full_fisher_information_with_the_emission_unknown(dim):
    rng = np.random.default_rng(11)
    layouts = rng.uniform(-300, 300, (3, 7, dim))
    points = rng.uniform(-250, 250, (20, dim))
    heard = rng.random((3, 20, 7)) < 0.6
    sigma0, per_m = C * 2e-4, 1e-3  # σ = σ₀ + k·range [m]
    sigma_m = tm.range_sigma(tm.distances(points, layouts), sigma0, per_m)
    got = tm.fix_drms(points, layouts, sigma_m, heard)
    want = np.array([[_fisher_drms(p, layouts[k], heard[k, j], sigma_m[k, j] / C) for j, p in enumerate(points)]
                     for k in range(3)])
    assert np.isinf(want).any() and np.isfinite(want).sum() > 30
    np.testing.assert_array_equal(np.isinf(got), np.isinf(want))
    # 1e-9 where the geometry is not near-singular (a DRMS below 100 σ₀); there both lose digits to the conditioning
    ok = np.isfinite(want) & (want < 100 * sigma0)
    assert ok.sum() > 30
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9)
    np.testing.assert_allclose(got[np.isfinite(want)], want[np.isfinite(want)], rtol=1e-5)
    # the tracker's own fix DRMS (one σ) agrees where every receiver heard
    np.testing.assert_allclose(tm.fix_drms(points, layouts[0], sigma0, horizontal=False),
                               toa_bound.fix_drms(points, np.ones((20, 7), bool), layouts[0], C, sigma0 / C),
                               rtol=1e-9)


def test_the_averaged_information_is_the_accuracy_maps_with_the_emission_removed():
    rng = np.random.default_rng(5)
    receivers = np.c_[rng.uniform(-200, 200, (6, 2)), rng.uniform(20, 30, 6)]
    points = np.c_[rng.uniform(-150, 150, (25, 2)), rng.uniform(0, 15, 25)]
    q = rng.uniform(0, 1, (25, 6))
    sigma_m = rng.uniform(0.2, 0.6, (25, 6))
    got = tm.expected_information_drms(points, receivers, sigma_m, q, depth_sigma_m=0.5)
    want = information.layout_values(points, receivers, receivers, q, sigma_m ** 2, 0.0, 0.25, emission=True)
    np.testing.assert_allclose(got, want["drms"], rtol=1e-9)


@pytest.mark.parametrize("n", [3, 4, 5, 8, 12])
def test_a_regular_ring_gives_two_sigma_over_root_n_at_its_centre_and_more_off_it(n):
    sigma_toa = 1.5e-4
    theta = 2 * np.pi * np.arange(n) / n + 0.3
    receivers = 120.0 * np.c_[np.cos(theta), np.sin(theta)]
    centre = tm.fix_drms(np.zeros((1, 2)), receivers, C * sigma_toa)[0]
    assert centre == pytest.approx(tm.ring_fix_drms(n, C * sigma_toa), rel=1e-12)
    assert centre == pytest.approx(2 * C * sigma_toa / math.sqrt(n), rel=1e-12)
    for bearing in (0.0, 1.0, 2.5):
        ray = np.outer(np.linspace(0.0, 90.0, 10), [math.cos(bearing), math.sin(bearing)])
        along = tm.fix_drms(ray, receivers, C * sigma_toa)
        assert np.all(along[1:] > centre * (1 + 1e-9))


# --- the positioning yield -------------------------------------------------------------------------------------

def test_the_yield_is_the_sum_over_every_detection_pattern():
    rng = np.random.default_rng(2)
    q = rng.uniform(0, 1, (4, 6))
    for needed in (0, 3, 4, 6):
        want = [sum(np.prod(np.where(bits, row, 1 - row)) for bits in itertools.product((0, 1), repeat=6)
                    if sum(bits) >= needed) for row in q]
        np.testing.assert_allclose(tm.positioning_yield(q, needed), want, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(tm.count_distribution(q).sum(axis=-1), 1.0, rtol=1e-14)


def test_the_yield_is_what_a_monte_carlo_of_ten_thousand_pings_hears():
    rng = np.random.default_rng(3)
    curve = DetectionCurve.logistic(150.0, 0.03)
    receivers = rng.uniform(-200, 200, (10, 2))
    points = rng.uniform(-250, 250, (12, 2))
    q = curve.probability(tm.distances(points, receivers))
    predicted = tm.positioning_yield(q, 3)
    heard = rng.binomial(1, q[:, None, :], size=(12, 10_000, 10)).sum(axis=-1)
    simulated = (heard >= 3).mean(axis=1)
    assert predicted.min() < 0.5 < predicted.max()
    np.testing.assert_allclose(simulated, predicted, atol=0.02)


def test_the_rms_over_fixed_pings_is_the_loop_over_patterns_and_its_monte_carlo_agrees():
    rng = np.random.default_rng(8)
    receivers = rng.uniform(-150, 150, (6, 2))
    points = rng.uniform(-100, 100, (4, 2))
    q = rng.uniform(0.3, 0.95, (4, 6))
    q[0, 2] = 1.0  # a receiver that always hears
    sigma_toa = 2e-4
    rms, fixable = tm.fixed_ping_drms(points, receivers, C * sigma_toa, q)
    for j, p in enumerate(points):
        total = weight = 0.0
        for bits in itertools.product((False, True), repeat=6):
            w = np.prod(np.where(bits, q[j], 1 - q[j]))
            value = toa_bound.fix_drms(p[None], np.array([bits]), receivers, C, sigma_toa)[0]
            if np.isfinite(value) and w > 0:
                total, weight = total + w * value ** 2, weight + w
        assert fixable[j] == pytest.approx(weight, rel=1e-12)
        assert rms[j] == pytest.approx(math.sqrt(total / weight), rel=1e-9)
    assert np.all(fixable <= tm.positioning_yield(q, 3) + 1e-15)
    # the Monte Carlo of the patterns, the enumeration turned off
    sampled, sampled_fixable = _monte_carlo(points, receivers, C * sigma_toa, q)
    np.testing.assert_allclose(sampled_fixable, fixable, atol=0.02)
    np.testing.assert_allclose(sampled, rms, rtol=0.1)
    # every receiver heard: the fix of them all
    all_heard, one = tm.fixed_ping_drms(points, receivers, C * sigma_toa, 1.0)
    np.testing.assert_allclose(all_heard, tm.fix_drms(points, receivers, C * sigma_toa), rtol=1e-12)
    np.testing.assert_array_equal(one, 1.0)


def _monte_carlo(points, receivers, sigma_m, q):
    old = tm.ENUMERATE_MAX
    tm.ENUMERATE_MAX = -1
    try:
        return tm.fixed_ping_drms(points, receivers, sigma_m, q, np.random.default_rng(1), samples=20_000)
    finally:
        tm.ENUMERATE_MAX = old


# --- the sync graph --------------------------------------------------------------------------------------------

CURVE = DetectionCurve.logistic(150.0, 0.05)  # 0.92 at 100 m, 0.08 at 200 m


def _sync(receivers, p=0.8):
    return sg.sync_coverage(sg.sync_probabilities(np.asarray(receivers, float), CURVE.probability), p)


def test_a_square_whose_receivers_all_hear_each_other_is_synchronised():
    s = _sync([[0, 0], [80, 0], [80, 80], [0, 80]])
    np.testing.assert_array_equal(s.heard, [3, 3, 3, 3])
    assert s.connected and s.met and s.share == 1.0


def test_a_line_is_connected_but_its_ends_hear_one_sync_tag():
    s = _sync([[0, 0], [100, 0], [200, 0], [300, 0]])
    np.testing.assert_array_equal(s.heard, [1, 2, 2, 1])
    assert s.connected and not s.met and s.share == 0.5


def test_two_clusters_out_of_range_are_two_components():
    cluster = np.array([[0, 0], [60, 0], [30, 50]])
    s = _sync(np.r_[cluster, cluster + [1000, 0]])
    assert int(s.components) == 2 and not s.connected and not s.met and s.share == 1.0
    np.testing.assert_array_equal(s.labels[:3], s.labels[0])
    assert s.labels[3] != s.labels[0]
    # a bridge of receivers joins them
    bridge = np.c_[np.arange(130, 1000, 90), np.zeros(10)]
    assert bool(_sync(np.r_[cluster, cluster + [1000, 0], bridge]).connected)


def test_layouts_are_judged_at_once_and_one_way_hearing_links_two_clocks():
    layouts = np.array([[[0, 0], [80, 0], [40, 60]], [[0, 0], [80, 0], [900, 0]]], float)
    s = sg.sync_coverage(sg.sync_probabilities(layouts, CURVE.probability), 0.8)
    np.testing.assert_array_equal(s.connected, [True, False])
    q = np.array([[0, 0.9, 0], [0, 0, 0.9], [0, 0, 0]])  # 0 hears 1, 1 hears 2: a chain one way
    assert bool(sg.sync_coverage(q, 0.8).connected)


# --- study areas -----------------------------------------------------------------------------------------------

L_LAKE = [[0, 0], [300, 0], [300, 100], [100, 100], [100, 300], [0, 300]]  # an L: the notch x, y > 100 is land


def _ray_casting(vertices, x, y):
    """Even-odd rule: a horizontal ray from (x, y) crosses the outline an odd number of times inside."""
    v = np.asarray(vertices, float)
    inside = False
    for (x1, y1), (x2, y2) in zip(v, np.roll(v, -1, axis=0)):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def test_containment_is_shapelys_contains_and_a_ray_casting_and_the_hand_made_l():
    lake = ar.polygon(L_LAKE)
    rng = np.random.default_rng(4)
    points = rng.uniform(-50, 350, (2000, 2))
    got = ar.inside(lake, points)
    np.testing.assert_array_equal(got, [Polygon(L_LAKE).contains(Point(p)) for p in points])
    np.testing.assert_array_equal(got, [_ray_casting(L_LAKE, *p) for p in points])
    hand = np.array([[50, 50], [250, 50], [50, 250], [200, 200], [150, 150], [-10, 50], [350, 50]])
    np.testing.assert_array_equal(ar.inside(lake, hand), [True, True, True, False, False, False, False])
    # 3 receivers of 2 layouts at once
    np.testing.assert_array_equal(ar.inside(lake, hand[:6].reshape(2, 3, 2)), [[True, True, True],
                                                                               [False, False, False]])


def test_the_shore_distance_limits_where_receivers_go():
    lake = ar.polygon(L_LAKE)
    points = np.array([[50, 50], [10, 150], [290, 50], [150, 90], [95, 95]])
    np.testing.assert_allclose(ar.shore_distance(lake, points), [50, 10, 10, 10, math.sqrt(50)])
    np.testing.assert_array_equal(ar.inside(lake, points, min_shore_m=8), [True, True, True, True, False])
    np.testing.assert_array_equal(ar.inside(lake, points, max_shore_m=20), [False, True, True, True, True])
    grid = ar.grid(lake, 10.0, min_shore_m=5.0)
    assert len(grid) == 500  # the L's 50,000 m² in 10 m cells, their centres 5 m off every shore and kept
    assert ar.inside(lake, grid).all() and ar.shore_distance(lake, grid).min() == 5.0
    # 6 m: the cells along the 1,200 m of shore gone (120, the 5 convex corners' counted twice); the one in the
    # reflex corner, 7.07 m from it, kept
    assert len(ar.grid(lake, 10.0, min_shore_m=6.0)) == 500 - 120 + 5


def test_areas_from_geojson_and_bad_outlines_name_the_key():
    ring = [[0, 0], [300, 0], [300, 300], [0, 300], [0, 0]]
    island = [[100, 100], [200, 100], [200, 200], [100, 200], [100, 100]]
    lake = ar.polygon({"type": "Feature", "properties": {}, "geometry": {"type": "Polygon",
                                                                          "coordinates": [ring, island]}})
    np.testing.assert_array_equal(ar.inside(lake, np.array([[50, 50], [150, 150]])), [True, False])
    assert ar.shore_distance(lake, np.array([[150, 90]]))[0] == pytest.approx(10.0)
    for bad in ([[0, 0], [1, 1]], [[0, 0], [10, 10], [10, 0], [0, 10]], [[0, 0], [1, 1], [2, 2]],
                {"type": "Point", "coordinates": [0, 0]}, [[0, 0], [np.nan, 1], [1, 0]]):
        with pytest.raises(ModelError, match=r"^site\.area: "):
            ar.polygon(bad)


# --- Lake Hald's layout evaluated ------------------------------------------------------------------------------

def _hydrophones():
    from pathlib import Path
    path = Path(__file__).resolve().parents[2] / "data" / "lake-hald" / "hydrophones.csv"
    xy = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=(1, 2))
    return xy[np.isfinite(xy).all(axis=1)]


def test_lake_halds_layout_is_evaluated_inside_the_drawn_area():
    from sblsim.models.design import lake_hald as lh
    hydrophones = _hydrophones()
    assert len(hydrophones) == 27
    lake = ar.polygon(lh.LAKE_HALD_AREA)
    assert ar.shore_distance(lake, hydrophones).min() > 20.0 and lake.area == pytest.approx(41_562.5)
    evaluation = lh.lake_hald_evaluation(hydrophones, spacing_m=40.0, samples=50)
    rows = np.asarray(lh.LAKE_HALD_DETECTION)
    q = np.interp(tm.distances(evaluation.points, hydrophones), rows[:, 0], rows[:, 1])
    np.testing.assert_allclose(evaluation.positioning_yield, tm.positioning_yield(q, 3), rtol=1e-12)
    assert np.all(np.isfinite(evaluation.drms_expected)) and evaluation.drms_expected.max() < 2.0
    assert bool(evaluation.sync.met) and len(evaluation.lines()) == 6
    with pytest.raises(ModelError, match=r"^receivers: 1 outside the study area"):
        lh.evaluate_layout(np.r_[hydrophones, [[500.0, 0.0]]], lh.LAKE_HALD_AREA,
                           DetectionCurve.logistic(150, 0.03), 0.2)
