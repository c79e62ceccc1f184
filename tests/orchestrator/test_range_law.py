"""The range-dependent noise law ``σ = σ₀ + k d`` in runs: ``acoustics.range_k`` ties the receivers' ``range_k``,
and a receiver that weighs the law is consistent (its NEES near the 3 of a position's chi-square) where one that
ignores it is not."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run_batch, with_replicates

#: The scenarios' fixed-detection, straight-path variants: an LBL of 250 m radius with a vehicle at 150 m depth
#: (ranges of 200–400 m) and a USBL with a vehicle 300 m out at 100 m depth (a slant range of ~320 m).
SCENARIOS = {
    "lbl-field": ["acoustics.detection=fixed", "acoustics.propagation=straight", "simulation.duration=300"],
    "usbl-deep": ["acoustics.detection=fixed", "acoustics.propagation=straight", "simulation.duration=800",
                  "target.radius=300", "target.depth=100"],
}
K = 0.002  # k d of 0.4–0.8 m against σ₀ 0.05 and 0.2 m: the law dominates


def test_the_receivers_range_k_is_tied_from_the_channels():
    cfg = load_config("lbl-field", [f"acoustics.range_k={K}"], seed=1)
    assert cfg["acoustics"]["range_k"] == K and cfg["receiver"]["range_k"] == K
    assert load_config("lbl-field", [], seed=1)["receiver"]["range_k"] == 0.0
    given = load_config("lbl-field", [f"acoustics.range_k={K}", "receiver.range_k=0"], seed=1)
    assert given["receiver"]["range_k"] == 0.0  # a key the user set is kept


@pytest.mark.slow
@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_the_default_receiver_is_consistent_under_the_law_and_not_without_it(scenario):
    """20 seeds of the scenario's default receiver (ekf-seq) with acoustics.range_k = 0.002: the mean NEES of the
    position in [1.5, 4.5]; the same runs with the receiver's range_k forced to 0 (R of σ₀ alone): out of it."""
    nees = {}
    for weighed in (K, 0.0):
        cfg = load_config(scenario, SCENARIOS[scenario] + [f"acoustics.range_k={K}", f"receiver.range_k={weighed}"],
                          seed=1)
        nees[weighed] = float(np.mean(run_batch(with_replicates(cfg, range(20)), timeseries=False)
                                      .metrics["nees_mean"]))
    assert 1.5 <= nees[K] <= 4.5, nees
    assert not 1.5 <= nees[0.0] <= 4.5, nees
