"""The moving ocean of the channel: every travel time scaled by ``1 + ε(t)``, ε a smooth stationary random process.

* :func:`sblsim.models.acoustics.core.ocean_perturbation` against its covariance: over many draws of its random
  Fourier features (numpy), the standard deviation is σ and the correlation at a lag τ is ``exp(−τ² / (2 ℓ²))``.
* Through the channel (an LBL of one-way ranges, no range noise, the assumed speed the true one): every range is its
  true length times ``1 + ε(t)``, the same ε for every transponder at one time, of std σ over runs, changing
  smoothly within a run; with σ = 0 the ranges are exactly those of a steady ocean.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from sblsim.models.acoustics.channel.ocean import OCEAN_FEATURES, ocean_perturbation
from sblsim.models.expressions import only_where
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run


def test_the_perturbation_has_its_std_and_gaussian_correlation():
    t, sigma, w, phi = ca.SX.sym("t"), ca.SX.sym("s"), ca.SX.sym("w", OCEAN_FEATURES), ca.SX.sym("p", OCEAN_FEATURES)
    f = ca.Function("eps", [t, sigma, w, phi], [ocean_perturbation(t, sigma, w, phi)])
    rng = np.random.default_rng(4)
    scale, draws = 600.0, 20000
    omega = rng.normal(size=(draws, OCEAN_FEATURES)) / scale
    phase = rng.uniform(0, 2 * np.pi, size=(draws, OCEAN_FEATURES))
    mapped = f.map(draws)
    at = {lag: np.asarray(mapped(1000.0 + lag, 2e-4, omega.T, phase.T)).ravel() for lag in (0.0, scale, 3 * scale)}
    assert np.std(at[0.0]) == pytest.approx(2e-4, rel=0.03)
    assert np.corrcoef(at[0.0], at[scale])[0, 1] == pytest.approx(np.exp(-0.5), abs=0.03)
    assert abs(np.corrcoef(at[0.0], at[3 * scale])[0, 1]) < 0.05


def test_the_channels_perturbation_is_computed_only_where_the_ocean_moves():
    """The slot's ε (:func:`~sblsim.models.expressions.only_where`, as the channel calls it): where σ > 0 the same
    number as the perturbation written out, bit for bit; where σ = 0 an exact 0 without its cosines (features that
    are not finite leave it 0, where ``0 · Σ cos`` would be NaN)."""
    t, ppm = ca.SX.sym("t"), ca.SX.sym("ppm")
    w, phi = ca.SX.sym("w", OCEAN_FEATURES), ca.SX.sym("p", OCEAN_FEATURES)
    switched = ca.Function("eps", [t, ppm, w, phi], [only_where(
        "sblsim_ocean", ppm > 0, lambda at: ocean_perturbation(at, ppm * 1e-6, w, phi), t)])
    written = ca.Function("eps", [t, ppm, w, phi], [ocean_perturbation(t, ppm * 1e-6, w, phi)])
    rng = np.random.default_rng(5)
    for _ in range(200):
        args = (rng.uniform(0, 1e4), rng.choice([0.0, rng.uniform(0, 1e4)]), rng.normal(size=OCEAN_FEATURES) / 60,
                rng.uniform(0, 2 * np.pi, OCEAN_FEATURES))
        eps = float(switched(*args))
        assert eps == float(written(*args)) if args[1] > 0 else eps == 0.0
    nan = np.full(OCEAN_FEATURES, np.nan)
    assert float(switched(10.0, 0.0, nan, nan)) == 0.0 and np.isnan(float(written(10.0, 0.0, nan, nan)))


@pytest.fixture(scope="module")
def lbl():
    sets = ["platform.system=lbl", "acoustics.ranging=owtt", "acoustics.sigma_range=0", "simulation.duration=120",
            "simulation.sampling_time=1", "acoustics.ntd_time_scale=60"]
    steady = run(load_config("random-walk", sets), replicates=range(40)).timeseries
    moving = run(load_config("random-walk", sets + ["acoustics.ntd_sigma_ppm=1000"]), replicates=range(40)).timeseries
    return steady, moving


def test_every_range_is_its_length_times_one_plus_the_oceans_change(lbl):
    steady, moving = lbl
    # the geometry is the same (a one-way range's true length at its reception, which the ocean moves by a few ms)
    np.testing.assert_allclose(moving["range_true"], steady["range_true"], rtol=1e-5, atol=0)
    valid = moving["packet_valid"].astype(bool) & (moving["range_true"] > 0)
    ratio = (moving["range"] / moving["range_true"] - 1.0)[valid]
    steady_ratio = (steady["range"] / steady["range_true"] - 1.0)[valid]
    assert np.abs(steady_ratio).max() < 2e-6  # a steady ocean: only the diver's motion over the travel time
    change = ratio - steady_ratio
    assert np.std(change) == pytest.approx(1e-3, rel=0.2)  # σ = 1000 ppm over 40 runs
    # smooth within a run: the change of ε between consecutive packets (1 s) is small against its spread (60 s)
    frame = moving[valid].assign(change=change)
    steps = frame.groupby("replicate")["change"].diff().dropna()
    assert np.std(steps) < 0.1 * np.std(change)
