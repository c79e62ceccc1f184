"""The clock model of ``sblsim sync`` (:mod:`sblsim.models.sync`) on simulated sync-tag detections: 20 receivers
with offsets of ±2 s and drifts of ±20 ppm, sync tags every 540–660 s, 0.15 ms timing noise, 5 % multipath echoes;
the offsets recovered against the simulated clocks, within 3 of their own sigmas."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from sblsim.models.declarations import ModelError
from sblsim.models.sync import clocks
from sblsim.models.sync.clocks import Geometry, fit_clocks
from sblsim.models.sync.emissions import connected, group_emissions, later_duplicates
from sblsim.models.sync.positions import position_emissions
from sblsim.models.sync.selected_inversion import selected_inverse
from sblsim.models.sync.simulate import simulate_sync


@pytest.fixture(scope="module")
def case():
    sim = simulate_sync(n_receivers=20, hours=24.0, seed=1, echo_share=0.05)
    origin = np.floor(sim.time.min())
    t = sim.time - origin
    emission = group_emissions(sim.tag, t, np.full(20, 180.0))
    duplicate = later_duplicates(emission, sim.receiver, t)
    distance = np.linalg.norm(sim.positions[sim.tag] - sim.positions[sim.receiver], axis=1)
    linked = connected(sim.receiver, emission, 20, 0)
    fit = fit_clocks(sim.receiver, emission, t, distance, np.full(len(t), 1 / sim.sound_speed), ~duplicate, linked,
                     0, 3600.0)
    return sim, origin, emission, duplicate, distance, linked, fit


def test_the_emissions_are_grouped_as_simulated_and_the_echoes_found(case):
    sim, _, emission, duplicate, _, linked, _ = case
    pairs = set(zip(emission.tolist(), sim.emission.tolist()))
    assert len(pairs) == len(set(emission.tolist())) == len(set(sim.emission.tolist()))  # one to one
    assert np.array_equal(duplicate, sim.echo) and linked.all()


def test_offsets_recovered_within_three_sigmas(case):
    sim, origin, _, _, _, _, fit = case
    z, errors = [], []
    for j in range(1, 20):
        truth = sim.offset(np.full(len(fit.edges), j), fit.edges + origin, reference=0)
        error = fit.knots[j] - truth
        errors.append(error)
        z.append(error / fit.knot_sigma[j])
    z, errors = np.concatenate(z), np.concatenate(errors)
    assert np.mean(np.abs(z) <= 3) >= 0.95
    assert 0.7 < np.std(z) < 1.3  # the sigmas are the errors' own, not merely large
    assert np.abs(errors).max() < 0.3e-3
    assert np.all(fit.knots[0] == 0) and fit.kept[sim.echo].sum() == 0


def test_the_sound_speed_estimated_with_the_clocks(case):
    sim, origin, emission, duplicate, distance, linked, _ = case
    fit = fit_clocks(sim.receiver, emission, sim.time - origin, distance, None, ~duplicate, linked, 0, 3600.0)
    speed = 1 / fit.slowness
    sigma = fit.slowness_sigma / fit.slowness ** 2
    assert abs(speed - sim.sound_speed) < 3 * sigma and sigma < 0.1


def test_an_emission_positioned_from_synchronised_arrivals(case):
    sim, origin, emission, duplicate, _, _, fit = case
    tag = 7
    rows = np.flatnonzero((sim.tag == tag) & ~duplicate & (sim.receiver != tag))
    ems, local = np.unique(emission[rows], return_inverse=True)
    arrival = np.full((len(ems), 20), np.nan)
    t = sim.time[rows] - origin
    arrival[local, sim.receiver[rows]] = t - fit.offset(sim.receiver[rows], t)
    fixes = position_emissions(arrival, sim.positions, np.full(20, 0.15e-3), np.full(len(ems), 1 / sim.sound_speed))
    error = fixes.position[fixes.ok] - sim.positions[tag]
    nees = np.einsum("ek,ekl,el->e", error, np.linalg.inv(fixes.covariance[fixes.ok]), error)
    assert fixes.ok.mean() > 0.9 and np.median(np.linalg.norm(error, axis=1)) < 0.5
    assert 1.0 < nees.mean() < 3.5


def test_nothing_to_synchronise_is_refused():
    with pytest.raises(ModelError, match="fewer than two receivers"):
        fit_clocks(np.array([0, 0]), np.array([0, 1]), np.array([1.0, 2.0]), np.zeros(2), None, np.ones(2, bool),
                   np.array([True, False]), 0, 3600.0)


@pytest.fixture(scope="module")
def surveyed():
    """12 receivers over 12 h whose table positions are the truth plus a survey error of 2 m per axis."""
    sim = simulate_sync(n_receivers=12, hours=12.0, seed=2)
    origin = np.floor(sim.time.min())
    t = sim.time - origin
    emission = group_emissions(sim.tag, t, np.full(12, 180.0))
    duplicate = later_duplicates(emission, sim.receiver, t)
    table = sim.positions + np.random.default_rng(7).normal(0, 2.0, sim.positions.shape)
    distance = np.linalg.norm(table[sim.tag] - table[sim.receiver], axis=1)
    linked = connected(sim.receiver, emission, 12, 0)
    args = (sim.receiver, emission, t, distance, np.full(len(t), 1 / sim.sound_speed), ~duplicate, linked, 0, 3600.0)
    return sim, origin, table, args


def _within(sim, origin, fit) -> float:
    z = [(fit.knots[j] - sim.offset(np.full(len(fit.edges), j), fit.edges + origin, reference=0)) / fit.knot_sigma[j]
         for j in range(1, len(sim.positions))]
    return float(np.mean(np.abs(np.concatenate(z)) <= 3))


def test_the_positions_refined_with_the_clocks_from_a_surveyed_table(surveyed):
    sim, origin, table, args = surveyed
    fixed = fit_clocks(*args)
    fit = fit_clocks(*args, geometry=Geometry(sim.tag, table, 2.0))
    refined = table + fit.shift
    error, before = refined - sim.positions, table - sim.positions
    assert np.sqrt(np.mean(error ** 2)) < 0.75 * np.sqrt(np.mean(before ** 2))  # closer than the table
    sigma = np.sqrt(np.stack([fit.shift_covariance[:, 0, 0], fit.shift_covariance[:, 1, 1]], axis=1))
    assert np.all(np.abs(error) <= 3 * sigma)  # and within 3 of its own sigmas
    # the arrivals fix the array's shape: without its translation (the prior's, the gauge) the error is centimetres
    assert np.sqrt(np.mean((error - error.mean(axis=0)) ** 2)) < 0.1
    # the table's error biased the fixed fit's clocks; the refined fit's are within their sigmas again
    assert _within(sim, origin, fit) >= 0.95 > _within(sim, origin, fixed)
    assert np.median(fit.scale) < 0.2e-3 < np.median(fixed.scale)


def test_a_tight_survey_prior_is_the_fixed_positions(surveyed):
    """The refinement reduces to the fixed fit when the survey sigma is tiny (its code path checked against the
    fixed one), and a survey sigma that is not finite is refused (the prior must fix the datum)."""
    sim, _, table, args = surveyed
    fixed = fit_clocks(*args)
    tight = fit_clocks(*args, geometry=Geometry(sim.tag, table, 1e-4))
    np.testing.assert_allclose(tight.knots[1:], fixed.knots[1:], rtol=0, atol=2e-7)
    np.testing.assert_allclose(tight.knot_sigma[1:], fixed.knot_sigma[1:], rtol=1e-3)
    assert np.abs(tight.shift).max() < 1e-3 and np.array_equal(tight.kept, fixed.kept)
    with pytest.raises(ModelError, match="survey sigma"):
        fit_clocks(*args, geometry=Geometry(sim.tag, table, np.inf))


def test_the_selected_inverse_is_the_dense_inverse():
    """:func:`selected_inverse` on a random block-tridiagonal matrix (a shuffled order, as the knots' receiver-major
    numbering is) with a dense border: the solution, the diagonal, the pairs' covariances and the border's block
    against the dense inverse."""
    rng = np.random.default_rng(4)
    n, width, border = 60, 5, 3
    band = np.zeros((n, n))
    for off in range(width + 1):
        v = rng.normal(size=n - off)
        band += np.diag(v, off) + (np.diag(v, -off) if off else 0)
    band = band @ band.T  # SPD, bandwidth 2 * width
    full = np.zeros((n + border, n + border))
    full[:n, :n] = band + n * np.eye(n)
    C = rng.normal(size=(n, border))
    full[:n, n:], full[n:, :n] = C, C.T
    full[n:, n:] = C.T @ C + np.eye(border) * 5
    shuffle = rng.permutation(n)  # order[new] = old
    old = np.r_[shuffle, np.arange(n, n + border)]
    S = np.empty_like(full)
    S[np.ix_(old, old)] = full
    rhs = rng.normal(size=n + border)
    pairs = np.c_[shuffle[:-3], shuffle[3:]]  # three apart in the band's order
    x, sel = selected_inverse(sp.csr_matrix(S), n, shuffle, rhs, pairs)
    inverse = np.linalg.inv(S)
    np.testing.assert_allclose(x, inverse @ rhs, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(sel.variance, np.diag(inverse)[:n], rtol=1e-10)
    np.testing.assert_allclose(sel.following, inverse[pairs[:, 0], pairs[:, 1]], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(sel.border, inverse[n:, n:], rtol=1e-10)


def test_the_sparse_sigmas_are_the_dense_ones(surveyed, monkeypatch):
    """The fit's sigmas by the selected inverse (beyond :data:`DENSE_LIMIT`) equal the dense inverse's on a small
    problem: the offsets', the drifts', the slowness's and the refined positions' (to 1e-3: the reweighting's
    solves differ in rounding between the two paths; the inverse itself is exact, the test above)."""
    sim, _, table, args = surveyed
    args = args[:4] + (None,) + args[5:]  # the slowness estimated: a border unknown
    geometry = Geometry(sim.tag, table, 2.0)
    dense = fit_clocks(*args, geometry=geometry)
    monkeypatch.setattr(clocks, "DENSE_LIMIT", 0)
    sparse = fit_clocks(*args, geometry=geometry)
    np.testing.assert_allclose(sparse.knots[1:], dense.knots[1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sparse.knot_sigma[1:], dense.knot_sigma[1:], rtol=1e-3)
    np.testing.assert_allclose(sparse.drift_sigma[1:], dense.drift_sigma[1:], rtol=1e-3)
    np.testing.assert_allclose(sparse.slowness_sigma, dense.slowness_sigma, rtol=1e-3)
    np.testing.assert_allclose(sparse.shift_covariance, dense.shift_covariance, rtol=1e-3, atol=1e-12)
    assert len(dense.edges) > 10  # many blocks: the recursion exercised
    # without the sigmas (a leave-one-out refit) the pass that converges gives the shifts and their covariance
    quick = fit_clocks(*args, geometry=geometry, sigmas=False)
    np.testing.assert_allclose(quick.shift, dense.shift, rtol=0, atol=2e-3)
    np.testing.assert_allclose(quick.shift_covariance, dense.shift_covariance, rtol=1e-2, atol=1e-6)  # of 0.5 m²
    assert np.isnan(quick.knot_sigma[1:]).all()


def test_the_refinement_does_not_depend_on_the_time_origin(surveyed):
    """The same arrivals a month from the time origin (2,592,000 s: whole bins) give the same positions and clocks:
    each emission's observations are taken from its first arrival, so times of 10⁶ s do not cancel in the
    positions' equations (without it the shifts wandered by centimetres from one Gauss-Newton pass to the next)."""
    sim, _, table, args = surveyed
    geometry = Geometry(sim.tag, table, 2.0)
    near = fit_clocks(*args, geometry=geometry)
    far = fit_clocks(*args[:2], args[2] + 2_592_000.0, *args[3:], geometry=geometry)
    np.testing.assert_allclose(far.shift, near.shift, rtol=0, atol=1e-3)
    np.testing.assert_allclose(far.knots[1:], near.knots[1:], rtol=0, atol=1e-8)


def test_a_clock_the_arrivals_leave_free_is_a_model_error_not_a_traceback():
    """A receiver marked synchronised whose every arrival is of an emission no other receiver heard (each one's
    emission time takes it whole), its times without noise: SuperLU finds the normal equations exactly singular.
    Said as the model's one-line refusal (which a sync tag's leave-one-out catches: that tag left unscored), where
    SuperLU's own RuntimeError ("Factor is exactly singular") went through the study (found in a refined study's
    synchronisation on 20 receivers with 4 sync tags, one left out)."""
    rng = np.random.default_rng(0)
    shared = np.repeat(np.arange(200), 2)  # emissions heard by receivers 0 and 1
    alone = np.arange(200, 400)  # emissions heard by receiver 2 alone
    receiver = np.r_[np.tile([0, 1], 200), np.full(200, 2)]
    emission = np.r_[shared, alone]
    distance = np.r_[np.tile([100.0, 150.0], 200), np.full(200, 120.0)]
    time = np.r_[shared * 30.0 + 5.0 + distance[:400] / 1480.0 + rng.normal(0, 1e-4, 400),
                 (alone - 200) * 30.0 + 7.1]
    with pytest.raises(ModelError, match="normal equations are singular") as caught:
        fit_clocks(receiver, emission, time, distance, np.full(600, 1 / 1480.0), np.ones(600, bool),
                   np.ones(3, bool), 0, 3600.0)
    assert "\n" not in str(caught.value)
    fit = fit_clocks(receiver, emission, time, distance, np.full(600, 1 / 1480.0), np.ones(600, bool),
                     np.array([True, True, False]), 0, 3600.0)  # without it: the two others synchronised
    assert np.isfinite(fit.knots[1]).all() and not np.isfinite(fit.knots[2]).any()
