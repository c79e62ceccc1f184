"""The family table of detection by signal-to-noise: every eigenray family interpolated at the eigenray table's nodes
against the exact solve of the sonar equation (:func:`sblsim.models.acoustics.detection.family_levels`)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from sblsim.fmus.compiled_functions import compiled_family_levels, compiled_family_points
from sblsim.models.acoustics import detection, ray_tables, rays
from sblsim.models.acoustics.sound_speed import munk_table, profile_table
from tests.models.test_rays import _tabulated

#: A site's numbers (detection.SITE): 190 dB, threshold 12 dB, DI 0, fluctuation 3 dB, 25 kHz, 0.0043 dB/m, noise
#: 70.7 dB, wave height 0.2 m, a sand-like floor.
SITE = np.array([190.0, 12.0, 0.0, 3.0, 25000.0, 4.3e-3, 70.7, 0.2, 1.9, 1650.0, 0.8])


def _table(name):
    return {"munk": munk_table(), "NCL1": profile_table("ctd:NCL1", "", 15.0, 35.0)}[name]


def _compiled():
    paths, levels = compiled_family_points(), compiled_family_levels()
    if paths is None or levels is None:
        pytest.skip("no C compiler")
    return paths, levels


def _values(columns):
    cols = [columns[c.name] for c in ray_tables.FAMILY_TABLE.columns]
    return np.asarray(ray_tables.ray_values([ca.DM(c) for c in cols])).ravel()


def _levels(f, use, table, depth, bounds, columns, zs, zr, x):
    """``f`` (family_levels_grid, or family_levels when ``columns`` is None and ``use`` is None) at points: each
    output (3, n)."""
    nodes, speeds = rays.profile_arrays(table)
    n = zs.size
    points = (zs[None], zr[None], x[None], np.full((1, n), depth), np.ones((1, n)), np.full((1, n), 1500.0))
    if use is None:
        return [np.asarray(o) for o in f.map(n)(*points, nodes, speeds, SITE)]
    bounds = np.asarray(bounds, dtype=float)
    values = _values(columns) if columns is not None else np.zeros(len(ray_tables.FAMILY_TABLE.columns) * 512)
    return [np.asarray(o) for o in f.map(n)(use, *points, nodes, speeds, SITE, bounds, ray_tables.ray_grid(bounds),
                                            values)]


def _answered(columns, bounds, zs, zr, x):
    """Which points the family table answers (its cells' ``ray_family_exact``)."""
    return _tabulated(columns, bounds, zs, zr, x, "ray_family_exact")


#: (profile, water depth, box, the least share of points the table answers): the benchmark's SBL geometry through
#: Munk in 20 m of water and its LBL one (transponders 1 m above the floor, the box up to the floor), a diver 1000 m
#: deep within 220 m through the NCL1 cast without boundaries, and a box far too coarse for the nodes (it answers
#: nothing).
CASES = [("munk", 20.0, (0.0, 2.5, 4.0, 6.0, 2.0, 28.0), 0.8),
         ("munk", 20.0, (18.0, 20.0, 4.0, 6.0, 2.0, 28.0), 0.8),
         ("NCL1", 0.0, (0.0, 5.0, 990.0, 1010.0, 0.0, 220.0), 0.8),
         ("munk", 1500.0, (0.0, 50.0, 100.0, 1400.0, 0.0, 2500.0), 0.0)]


@pytest.mark.slow
@pytest.mark.parametrize("name, depth, bounds, share", CASES)
def test_the_family_table_holds_the_exact_solve(name, depth, bounds, share):
    """Inside the box, the channel's levels equal the exact solve of every family within 1 µs, 2e-4 rad and 0.02 dB
    with the same families, at random geometries (the table answers a share of them; the exact solve the rest)."""
    paths, levels = _compiled()
    table = _table(name)
    columns = detection.level_table(table, depth, bounds, SITE, paths, levels)
    rng = np.random.default_rng(11)
    n = 60
    zs, zr, x = (rng.uniform(bounds[2 * j], bounds[2 * j + 1], n) for j in range(3))
    want = _levels(levels, None, table, depth, bounds, None, zs, zr, x)
    got = _levels(detection.family_levels_grid(), 1.0, table, depth, bounds, columns, zs, zr, x)
    np.testing.assert_array_equal(got[3], want[3])
    exists = want[3] > 0.5
    assert exists[0].any()
    for k, tolerance in ((0, 1e-6), (1, 2e-4), (2, 2e-4), (4, 0.02)):
        assert np.max(np.abs(got[k] - want[k])[exists]) <= tolerance, k
    np.testing.assert_array_equal(got[4][~exists], detection.NO_SNR)
    answered = _answered(columns, bounds, zs, zr, x)
    if share == 0.0:
        assert not answered.any() and columns["exact_share"] == 1.0
    else:
        assert answered.mean() > share, answered.mean()
        # the answered points are interpolated, not solved: they differ from the exact solve (by far less)
        assert np.any(got[0][:, answered] != want[0][:, answered])
    # the others are the exact solve itself (casadi's evaluation against the compiled one: round-off)
    for k in (0, 1, 2, 4, 5):
        np.testing.assert_allclose(got[k][:, ~answered][exists[:, ~answered]],
                                   want[k][:, ~answered][exists[:, ~answered]], rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_the_family_table_is_the_image_paths_in_isovelocity_water():
    """In water of one speed every family is its isovelocity image: the straight line and its images in the surface
    and the bottom, spherical spreading and the image's length, so the table answers everywhere."""
    c, depth = 1493.0, 40.0
    table = np.array([[0.0, c], [100.0, c]])
    bounds = (0.0, 5.0, 10.0, 30.0, 0.0, 200.0)
    # as a run builds it: compiled in the local engine's library (None: casadi's own evaluation)
    columns = detection.level_table(table, depth, bounds, SITE, compiled_family_points(), compiled_family_levels())
    assert columns["exact_share"] == 0.0
    rng = np.random.default_rng(5)
    zs, zr, x = (rng.uniform(bounds[2 * j], bounds[2 * j + 1], 40) for j in range(3))
    nodes, speeds = rays.profile_arrays(table)
    bounds_a = np.asarray(bounds, float)
    out = ray_tables._arrivals_grid().map(40)(1.0, zs[None], zr[None], x[None], depth, 1.0, 1500.0, nodes, speeds,
                                              bounds_a, ray_tables.ray_grid(bounds_a), _values(columns))
    tau, launch, _arrival, valid, spreading, length = (np.asarray(o) for o in out)
    np.testing.assert_array_equal(valid[3], 0.0)  # one straight line: no other eigenray of the direct family
    tau, launch, valid, spreading, length = (v[:3] for v in (tau, launch, valid, spreading, length))
    images = np.vstack([zr - zs, zs + zr, 2.0 * depth - zs - zr])
    paths = np.hypot(x, images)
    np.testing.assert_array_equal(valid, 1.0)
    np.testing.assert_allclose(tau, paths / c, rtol=1e-13, atol=0)
    np.testing.assert_allclose(length, paths, rtol=1e-12)
    np.testing.assert_allclose(spreading, 20.0 * np.log10(paths), rtol=0, atol=1e-9)
    np.testing.assert_allclose(launch[0], np.arctan2(zr - zs, x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(launch[1], -np.arctan2(zs + zr, x), rtol=0, atol=1e-12)


def test_without_a_family_table_the_levels_are_the_exact_solve():
    table = munk_table()
    rng = np.random.default_rng(3)
    zs, zr, x = rng.uniform(0, 30, 6), rng.uniform(0, 30, 6), rng.uniform(0, 200, 6)
    got = _levels(detection.family_levels_grid(), 0.0, table, 50.0, (0, 0, 0, 0, 0, 0), None, zs, zr, x)
    want = _levels(detection.family_levels(), None, table, 50.0, None, None, zs, zr, x)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
