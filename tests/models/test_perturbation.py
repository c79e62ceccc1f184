"""The perturbation's pieces against computations written here: scipy's B-splines, SeaGap's closed-form cubic,
the exact integral of a spline's curvature, a dense data covariance, the nadir angle's geometry, an AR(1) noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.interpolate import BSpline

from sblsim.models.calibration.perturbation import (
    akaike,
    basis,
    correlation_band,
    effective_scale,
    interval_bases,
    nadir_cosine,
    roughness,
    slant_direction,
    uniform_knots,
)


def _seagap_cubic(t, centre, step):
    """SeaGap's ``tbspline3``: the centred cubic B-spline of a knot interval ``step`` (written from its formula)."""
    x = np.abs((t - centre) / step)
    return np.where(x <= 1.0, (3 * x**3 - 6 * x**2 + 4) / 6, np.where(x <= 2.0, (2 - x) ** 3 / 6, 0.0))


def test_the_bases_are_scipys_and_seagaps_cubic_splines():
    start, end, n = 1000.0, 51000.0, 30
    knots = uniform_knots(start, end, n)
    t = np.linspace(start, end, 977)
    b = basis(t, knots)
    assert b.shape == (977, n)
    step = (end - start) / (n - 3)
    for j in range(n):
        element = BSpline.basis_element(knots[j:j + 5], extrapolate=False)(t)
        np.testing.assert_allclose(b[:, j], np.nan_to_num(element), atol=1e-12)
        # SeaGap's basis j (1-based j + 1) is centred at start + step (j - 1)
        np.testing.assert_allclose(b[:, j], _seagap_cubic(t, start + step * (j - 1), step), atol=1e-12)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-12)  # a partition of unity over the survey


def test_a_knot_interval_gives_garpos_count_of_bases():
    # GARPOS: int(duration / interval) intervals, three more bases
    assert interval_bases(0.0, 3600.0, 300.0) == 12 + 3
    assert interval_bases(0.0, 3599.0, 300.0) == 11 + 3
    assert interval_bases(0.0, 100.0, 300.0) == 1 + 3


def test_the_roughness_is_the_curvature_integral_in_hours():
    """For evenly spaced knots GARPOS's form is h^2 times the integral of the square of the spline's second
    derivative (piecewise linear: its values at the knots of full support, d_j, each on a hat of its two
    intervals; GARPOS gives the end hats both halves), time in hours: the d_j from scipy's spline, the integral
    of the hats' sum squared taken numerically."""
    rng = np.random.default_rng(5)
    knots = uniform_knots(0.0, 7.0 * 3600.0, 12)
    omega = roughness(knots)
    assert np.allclose(omega, omega.T)
    hours = knots / 3600.0
    h = hours[1] - hours[0]
    for _ in range(5):
        c = rng.normal(size=12)
        d = BSpline(hours, c, 3).derivative(2)(hours[3:13])
        nodes = np.concatenate(([hours[2]], hours[3:13], [hours[13]]))
        t = np.linspace(nodes[0], nodes[-1], 400001)
        values = np.interp(t, nodes, np.concatenate(([0.0], d, [0.0]))) ** 2
        integral = float(np.sum(0.5 * (values[1:] + values[:-1]) * np.diff(t)))
        assert c @ omega @ c == pytest.approx(h**2 * integral, rel=1e-6)
    # straight lines in time are not rough
    line = 2.0 + 0.5 * np.arange(12)
    np.testing.assert_allclose(omega @ line, 0.0, atol=1e-9)


def test_the_data_covariance_band_is_the_dense_matrix():
    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0.0, 900.0, 80))
    k = rng.integers(0, 3, 80)
    s = rng.uniform(0.8, 1.2, 80)
    mu_t, mu_mt = 40.0, 0.5
    band = correlation_band(t, k, s, mu_t, mu_mt)
    dense = np.zeros((80, 80))
    for i in range(80):
        for j in range(80):
            if abs(t[i] - t[j]) < 4 * mu_t:
                same = 1.0 if k[i] == k[j] else mu_mt
                dense[i, j] = math.exp(-abs(t[i] - t[j]) / mu_t) * same / (s[i] * s[j])
    rebuilt = np.zeros((80, 80))
    for d in range(band.shape[0]):
        idx = np.arange(80 - d)
        rebuilt[idx + d, idx] = band[d, :80 - d]
        rebuilt[idx, idx + d] = band[d, :80 - d]
    np.testing.assert_allclose(rebuilt, dense, atol=1e-15)


def test_the_nadir_angle_flat_and_on_a_sphere():
    points = np.array([[300.0, -400.0, 10.0], [0.0, 0.0, 5.0]])
    x = np.array([[0.0, 0.0, -2000.0], [0.0, 0.0, -2000.0]])
    flat = nadir_cosine(points, x)
    np.testing.assert_allclose(flat, [2010.0 / math.hypot(500.0, 2010.0), 1.0])
    # on a sphere: the angle at the transponder between the local vertical and the chord, law of cosines
    radius = 6.371e6
    arc = 500.0 / radius
    b, c = radius + 10.0, radius - 2000.0
    chord = math.sqrt(b * b + c * c - 2 * b * c * math.cos(arc))
    assert nadir_cosine(points[:1], x[:1], radius)[0] == pytest.approx(2010.0 / chord, rel=1e-8)  # cancellation here
    np.testing.assert_allclose(slant_direction(points[:1], x[:1]), [[-300.0 / 2010.0, 400.0 / 2010.0]])


def test_the_criteria_and_the_effective_scale():
    rng = np.random.default_rng(1)
    r = rng.normal(0.0, 2e-5, 500)
    aic, bic = akaike(r, 7)
    s2 = np.sum((r - r.mean()) ** 2) / 499
    assert aic == pytest.approx(500 * math.log(s2) + 14)
    assert bic == pytest.approx(500 * math.log(s2) + 7 * math.log(500))
    assert effective_scale(r) == pytest.approx(1.0, abs=0.1)
    rho, e = 0.8, np.zeros(20000)
    w = rng.normal(size=20000)
    for i in range(1, 20000):
        e[i] = rho * e[i - 1] + w[i]
    assert effective_scale(e) == pytest.approx(math.sqrt((1 + rho) / (1 - rho)), rel=0.05)
