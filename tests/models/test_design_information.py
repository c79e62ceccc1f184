"""The design's information of a layout and its criteria (:mod:`sblsim.models.design`), against computations written
here in numpy from the textbook formulas, and the closed forms of the optimal geometries against the layouts
themselves.

* ``layout_information``: ``J = Σ_i q_i g_i g_iᵀ / σ_i² + e_z e_zᵀ / σ_d²`` with ``g_i = (p − b_i)/‖p − b_i‖`` and
  ``σ_i² = σ_noise,i² + σ_att² ‖a_i × g_i‖²`` (a small rotation δθ moves a transducer at lever arm a by δθ × a),
  the DRMS, its 3-D form and ``log det J``, for random layouts, weights and noises; with every weight 1 it is the
  map's function of one round of ranges (:func:`sblsim.models.fisher.fix_information`) bit for bit; a transducer of
  weight 0 adds nothing, and padding a layout to more slots changes no bit.
* The closed forms (Bishop et al., Automatica 46(3), 2010): a regular polygon of N range sensors in the plane and a
  regular ring of N transponders at √2 h below a point give the determinants and traces the formulas give, and the
  criteria rank layouts as numpy's percentile, mean and max do.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sblsim.models.design import (
    RING_ELEVATION_DEG,
    RING_RADIUS_RATIO,
    bishop_2d_crb_trace,
    bishop_2d_determinant,
    coverage,
    criterion,
    layout_values,
    padded,
    ring_crb_trace,
    ring_determinant,
)
from sblsim.models.fisher import horizontal_std


def _numpy_information(points, beacons, arms, heard, noise, attitude, depth_variance):
    """J (M, 3, 3) from the formula in the module docstring, in numpy."""
    d = points[:, None, :] - beacons[None, :, :]
    g = d / np.linalg.norm(d, axis=-1, keepdims=True)
    variance = noise + attitude * np.sum(np.cross(arms[None, :, :], g) ** 2, axis=-1)
    J = np.einsum("mn,mni,mnj->mij", heard / variance, g, g)
    J[:, 2, 2] += 1.0 / depth_variance
    return J


def test_the_layout_information_is_the_textbook_sum_of_weighted_range_rows():
    rng = np.random.default_rng(7)
    points = rng.uniform(-300, 300, (40, 3))
    points[:, 2] = rng.uniform(5, 80, 40)
    beacons = rng.uniform(-400, 400, (6, 3))
    beacons[:, 2] = rng.uniform(0, 120, 6)
    arms = rng.uniform(-5, 5, (6, 3))
    heard = rng.uniform(0, 1, (40, 6))
    heard[:, 2] = 0.0  # never heard
    noise = rng.uniform(0.005, 0.05, (40, 6))
    attitude, depth_variance = math.radians(1.5) ** 2, 0.02
    values = layout_values(points, beacons, arms, heard, noise, attitude, depth_variance)
    J = _numpy_information(points, beacons, arms, heard, noise, attitude, depth_variance)
    np.testing.assert_allclose(values["J"], J, rtol=1e-12, atol=1e-12)
    C = np.linalg.inv(J)
    np.testing.assert_allclose(values["drms"], np.sqrt(C[:, 0, 0] + C[:, 1, 1]), rtol=1e-10)
    np.testing.assert_allclose(values["drms_3d"], np.sqrt(np.trace(C, axis1=1, axis2=2)), rtol=1e-10)
    np.testing.assert_allclose(values["log_det"], np.linalg.slogdet(J)[1], rtol=1e-10)
    # the never-heard transducer adds nothing: the layout without it
    without = layout_values(points, np.delete(beacons, 2, 0), np.delete(arms, 2, 0), np.delete(heard, 2, 1),
                            np.delete(noise, 2, 1), attitude, depth_variance)
    np.testing.assert_allclose(without["drms"], values["drms"], rtol=1e-13)
    # and the same transducer heard half the time does add
    heard[:, 2] = 0.5
    assert np.all(layout_values(points, beacons, arms, heard, noise, attitude, depth_variance)["drms"]
                  < values["drms"])


def test_every_transducer_heard_it_is_the_maps_round_of_ranges_bit_for_bit_and_padding_changes_nothing():
    rng = np.random.default_rng(3)
    points = rng.uniform(-50, 50, (30, 3))
    points[:, 2] = 12.0
    beacons = rng.uniform(-20, 20, (5, 3))
    beacons[:, 2] = 1.0
    attitude = math.radians(1.0) ** 2
    ref = horizontal_std(points, beacons, beacons, 0.02, attitude, 1e-4)
    values = layout_values(points, beacons, beacons, 1.0, 0.02, attitude, 1e-4)
    np.testing.assert_array_equal(values["drms"], ref)
    for slots in (8, 16):
        b, a, h, v = padded(beacons, beacons, np.ones((30, 5)), np.full((30, 5), 0.02), slots)
        more = layout_values(points, b, a, h, v, attitude, 1e-4)
        for name in ("drms", "drms_3d", "log_det"):
            np.testing.assert_array_equal(more[name], values[name])


@pytest.mark.parametrize("n", [3, 4, 5, 8])
def test_a_regular_polygon_in_the_plane_reaches_the_2d_closed_form(n):
    """N range sensors at bearings 2πk/N around a point in its plane (a depth sensor pins the plane's normal, which
    the ranges do not see): the horizontal block of J is N/(2σ²) I, det N²/(4σ⁴) and the bound's trace 4σ²/N; a
    layout with Σ e^{2iθ} ≠ 0 falls short by |Σ e^{2iθ}|²/(4σ⁴)."""
    sigma = 0.2
    angle = 2 * math.pi * np.arange(n) / n + 0.3
    beacons = np.column_stack([80 * np.cos(angle), 80 * np.sin(angle), np.full(n, 10.0)])
    point = np.array([[0.0, 0.0, 10.0]])
    J = layout_values(point, beacons, beacons, 1.0, sigma ** 2, 0.0, 1e-6)["J"][0][:2, :2]
    np.testing.assert_allclose(J, n / (2 * sigma ** 2) * np.eye(2), rtol=1e-12, atol=1e-9)
    assert np.linalg.det(J) == pytest.approx(bishop_2d_determinant(n, sigma), rel=1e-12)
    assert np.trace(np.linalg.inv(J)) == pytest.approx(bishop_2d_crb_trace(n, sigma), rel=1e-12)
    angle[0] += 0.4
    skewed = np.column_stack([80 * np.cos(angle), 80 * np.sin(angle), np.full(n, 10.0)])
    Js = layout_values(point, skewed, skewed, 1.0, sigma ** 2, 0.0, 1e-6)["J"][0][:2, :2]
    shortfall = abs(np.exp(2j * angle).sum()) ** 2 / (4 * sigma ** 4)
    assert np.linalg.det(Js) == pytest.approx(bishop_2d_determinant(n, sigma) - shortfall, rel=1e-10)


@pytest.mark.parametrize("n", [3, 4, 8])
def test_the_ring_at_root_two_h_below_gives_the_3d_closed_form(n):
    """N transponders on a ring of radius √2 h at h below a point, no depth sensor: det J = (N/3)³/σ⁶, tr J⁻¹ =
    9σ²/N (PDOP 1.5 at N = 4), the lines of sight 35.26° below the horizontal; rings a little wider or narrower do
    worse in both."""
    sigma, h = 0.05, 120.0
    point = np.array([[0.0, 0.0, 0.0]])

    def J_at(radius):
        angle = 2 * math.pi * np.arange(n) / n
        beacons = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.full(n, h)])
        return layout_values(point, beacons, beacons, 1.0, sigma ** 2, 0.0, np.inf)["J"][0]

    J = J_at(RING_RADIUS_RATIO * h)
    assert math.degrees(math.atan(h / (RING_RADIUS_RATIO * h))) == pytest.approx(RING_ELEVATION_DEG, abs=1e-12)
    assert RING_ELEVATION_DEG == pytest.approx(35.2644, abs=1e-4)
    assert np.linalg.det(J) == pytest.approx(ring_determinant(n, sigma), rel=1e-10)
    assert np.trace(np.linalg.inv(J)) == pytest.approx(ring_crb_trace(n, sigma), rel=1e-10)
    if n == 4:
        assert math.sqrt(np.trace(np.linalg.inv(J))) / sigma == pytest.approx(1.5, rel=1e-10)
    for other in (1.2 * RING_RADIUS_RATIO * h, 0.8 * RING_RADIUS_RATIO * h):
        assert np.linalg.det(J_at(other)) < np.linalg.det(J)
        assert np.trace(np.linalg.inv(J_at(other))) > np.trace(np.linalg.inv(J))


def test_the_criteria_are_the_percentile_mean_and_max_of_the_work_areas_numbers():
    rng = np.random.default_rng(11)
    drms = rng.uniform(0.1, 2.0, (4, 50))
    drms[1, 7] = np.nan  # no fix there: an infinite DRMS
    log_det = rng.normal(10, 2, (4, 50))
    log_det[1, 7] = np.nan
    filled = np.where(np.isnan(drms), np.inf, drms)
    np.testing.assert_array_equal(criterion("percentile", drms, log_det, 90.0),
                                  np.percentile(filled, 90.0, axis=1, method="higher"))
    np.testing.assert_array_equal(criterion("worst", drms, log_det, 90.0), filled.max(axis=1))
    np.testing.assert_allclose(criterion("a-optimal", drms, log_det, 90.0), np.mean(filled ** 2, axis=1))
    np.testing.assert_allclose(criterion("d-optimal", drms, log_det, 90.0),
                               -np.mean(np.where(np.isnan(log_det), -np.inf, log_det), axis=1))
    assert np.isinf(criterion("worst", drms, log_det, 90.0)[1])
    with pytest.raises(ValueError, match="criterion"):
        criterion("e-optimal", drms, log_det, 90.0)
    availability = np.ones((4, 50))
    availability[0, :10] = 0.9
    share = coverage(drms, availability, 1.0, 95.0)
    expected = 100.0 * np.mean((filled <= 1.0) & (availability >= 0.95), axis=1)
    np.testing.assert_allclose(share, expected)
