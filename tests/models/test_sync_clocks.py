"""The clock model of ``sblsim sync`` (:mod:`sblsim.models.sync`) on simulated sync-tag detections: 20 receivers
with offsets of ±2 s and drifts of ±20 ppm, sync tags every 540–660 s, 0.15 ms timing noise, 5 % multipath echoes;
the offsets recovered against the simulated clocks, within 3 of their own sigmas."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.sync.clocks import connected, fit_clocks, group_emissions, later_duplicates
from sblsim.models.sync.positions import position_emissions
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
