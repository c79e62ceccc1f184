"""The calibration solver's leg models: the straight ray at one speed per transponder and the direct eigenray
through a profile (its travel time, its gradient from the ray's angles)."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.acoustics.sound_speed import profile_table
from sblsim.models.calibration import EigenRay, Replies, StraightRay, solve
from sblsim.models.errors import ModelError

SURFACE_U = -26.59


def _legs(rng, n=24):
    """Transducer points near the surface within 150 m of the origin, and a transponder ~1.2 km deep, ~1 km off."""
    points = np.column_stack([rng.uniform(-150, 150, n), rng.uniform(-150, 150, n), SURFACE_U + rng.uniform(-1, 1, n)])
    x = np.array([-986.6, -26.1, -1203.3]) + rng.normal(0.0, 1.0, (n, 3))
    return points, x, np.zeros(n, dtype=int)


@pytest.fixture(scope="module")
def ctd():
    return EigenRay(profile_table("ctd:NCL1", "", 15.0, 35.0), 1481.5, SURFACE_U)


@pytest.mark.slow
def test_eigenray_gradient_equals_finite_differences(ctd):
    points, x, j = _legs(np.random.default_rng(3))
    length, gradient = ctd.legs(points, x, j)
    h = 1e-3
    fd = np.column_stack([(ctd.legs(points, x + h * e, j)[0] - ctd.legs(points, x - h * e, j)[0]) / (2 * h)
                          for e in np.eye(3)])
    np.testing.assert_allclose(gradient, fd, atol=1e-7)
    # the ray bends: its gradient is not the straight line's unit vector (by more than the tolerance above)
    assert np.max(np.abs(gradient - StraightRay().legs(points, x, j)[1])) > 1e-4


@pytest.mark.slow
def test_eigenray_in_isovelocity_water_is_the_straight_ray():
    c = 1490.0
    iso = EigenRay(np.array([[0.0, c], [3000.0, c]]), c, SURFACE_U)
    points, x, j = _legs(np.random.default_rng(4))
    length, gradient = iso.legs(points, x, j)
    straight, unit = StraightRay().legs(points, x, j)
    np.testing.assert_allclose(length, straight, atol=1e-9)
    np.testing.assert_allclose(gradient, unit, atol=1e-12)
    # at another reference speed the path length is c0 tau: scaled by c0 / c
    other = EigenRay(np.array([[0.0, c], [3000.0, c]]), 1500.0, SURFACE_U)
    np.testing.assert_allclose(other.legs(points, x, j)[0], straight * 1500.0 / c, rtol=1e-12)


def test_eigenray_time_is_close_to_the_harmonic_mean_straight_ray(ctd):
    """Nearly vertical legs: the eigenray's time is the vertical path's over the harmonic mean (to bending)."""
    n = 5
    points = np.column_stack([np.zeros(n), np.zeros(n), np.full(n, SURFACE_U)])
    x = np.column_stack([np.full(n, 1e-3), np.zeros(n), SURFACE_U - np.linspace(500.0, 1200.0, n)])
    length, _ = ctd.legs(points, x, np.zeros(n, dtype=int))
    # the vertical time by the trapezoid rule on a fine grid of the profile (linear between its rows)
    table = ctd.table
    for k, depth in enumerate(np.linspace(500.0, 1200.0, n)):
        z = np.linspace(0.0, depth, 200001)
        slowness = 1.0 / np.interp(z, table[:, 0], table[:, 1])
        tau = np.sum(0.5 * (slowness[1:] + slowness[:-1]) * np.diff(z))
        assert length[k] / ctd.reference_speed == pytest.approx(tau, abs=1e-9)


def test_straight_ray_with_one_speed_per_transponder():
    rng = np.random.default_rng(5)
    points, x, _ = _legs(rng, 10)
    j = np.array([0, 1] * 5)
    ratio = np.array([1.0, 1500.0 / 1480.0])
    length, gradient = StraightRay(ratio).legs(points, x, j)
    plain, unit = StraightRay().legs(points, x, j)
    np.testing.assert_allclose(length, plain * ratio[j], rtol=1e-15)
    np.testing.assert_allclose(gradient, unit * ratio[j][:, None], rtol=1e-15)
    with pytest.raises(ModelError, match="scale"):
        StraightRay([1.0, -1.0])
    with pytest.raises(ModelError, match="speed ratios"):
        StraightRay([1.0]).legs(points, x, j)


def _survey(rng, legs_true, c0, truth, n=200, noise=0.0):
    """Replies of a circle of radius 150 m around the origin, times from a leg model at the truth (plus a white
    noise of ``noise`` [s]), 1 cm GNSS."""
    angle = rng.uniform(0, 2 * np.pi, n)
    tx = np.column_stack([150 * np.cos(angle), 150 * np.sin(angle), np.full(n, SURFACE_U)])
    rx = tx + np.column_stack([rng.normal(0, 1.0, n), rng.normal(0, 1.0, n), np.zeros(n)])
    k = rng.integers(0, len(truth), n)
    x = truth[k]
    twtt = (legs_true.legs(tx, x, k)[0] + legs_true.legs(rx, x, k)[0]) / c0 + rng.normal(0.0, noise, n)
    sigma = np.full((n, 3), 0.01)
    return Replies(tx, sigma, rx, sigma, twtt, k)


@pytest.mark.slow
def test_the_solver_recovers_a_rigid_shift_through_the_profile(ctd):
    """Noise-free times through the profile: the eigenray solver recovers the shift exactly, a straight ray at
    the harmonic means does not (the bending it leaves is the difference the NCL1 table reports)."""
    rng = np.random.default_rng(6)
    apriori = np.array([[-986.6, -26.1, -1203.3], [537.0, -788.0, -1173.2], [490.1, 816.0, -1160.4]])
    shift = np.array([-0.1, 0.15, 0.12])
    replies = _survey(rng, ctd, ctd.reference_speed, apriori + shift, n=24)
    ray = solve(replies, apriori, ctd.reference_speed, rigid=True, outlier_factor=None, legs=ctd)
    np.testing.assert_allclose(ray.offset[0], shift, atol=1e-6)
    assert np.max(np.abs(ray.residual_s)) < 1e-10
    table = ctd.table
    hm = []
    for up in apriori[:, 2]:
        z = np.linspace(0.0, SURFACE_U - up, 100001)
        slowness = 1.0 / np.interp(z, table[:, 0], table[:, 1])
        hm.append(z[-1] / np.sum(0.5 * (slowness[1:] + slowness[:-1]) * np.diff(z)))
    straight = solve(replies, apriori, ctd.reference_speed, rigid=True, outlier_factor=None,
                     legs=StraightRay(ctd.reference_speed / np.array(hm)))
    assert np.max(np.abs(straight.residual_s)) > 1e-7
    assert np.linalg.norm(straight.offset[0] - shift) > 1e-3


@pytest.mark.slow
def test_a_straight_profile_of_one_speed_equals_the_solver_at_that_speed():
    rng = np.random.default_rng(7)
    c = 1495.0
    apriori = np.array([[-300.0, 0.0, -500.0], [300.0, 100.0, -520.0]])
    replies = _survey(rng, StraightRay(), c, apriori + [0.05, -0.02, 0.03], n=40, noise=2e-5)
    plain = solve(replies, apriori, c, rigid=True, outlier_factor=None)
    ray = solve(replies, apriori, c, rigid=True, outlier_factor=None,
                legs=EigenRay(np.array([[0.0, c], [2000.0, c]]), c, SURFACE_U))
    np.testing.assert_allclose(ray.offset, plain.offset, atol=1e-9)
    np.testing.assert_allclose(ray.sigma, plain.sigma, rtol=1e-6)


@pytest.mark.parametrize("table,speed,surface,message", [
    (np.zeros((0, 2)), 1500.0, 0.0, "rows of depth"),
    (np.array([[10.0, 1500.0], [5.0, 1500.0]]), 1500.0, 0.0, "depths must increase"),
    (np.array([[0.0, 1900.0]]), 1500.0, 0.0, r"\[1300, 1800\]"),
    (np.array([[0.0, 1500.0]]), 2000.0, 0.0, "sound_speed_mps"),
    (np.array([[0.0, 1500.0]]), 1500.0, np.nan, "surface_u_m"),
])
def test_bad_profiles_are_refused(table, speed, surface, message):
    with pytest.raises(ModelError, match=message):
        EigenRay(table, speed, surface)
