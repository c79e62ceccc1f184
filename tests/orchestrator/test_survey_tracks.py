"""The moving tags' σ where the receivers' positions are off: with the survey error the synchronisation sees taken
(the default where none is stated) the tracks' NEES against their truth is a consistent one's, where with the
positions taken as exact (``survey_sigma=0``) it is not (benchmarks/bench_survey_tracks.py runs 20 arrays)."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study import run_study

#: The survey's error put into every deployment [m per horizontal axis].
OFF = 2.0


def _nees(study, sim) -> np.ndarray:
    """Every tracked row's 2-D NEES against the tag's true path read on the reference receiver's clock."""
    names = study.deployments.table["receiver"].astype(str).tolist()
    k = names.index(study.summary["clocks"]["reference_receiver"])  # the simulation's order: none redeployed
    found = []
    for tag in study.tags.itertuples():
        assert tag.status == "tracked", tag.reason
        truth = sim.truth[tag.tag]
        on_clock = sim.clock_time(k, truth["tau"].to_numpy())
        rows = study.tracks[study.tracks["tag"] == tag.tag]
        ex = rows["x"].to_numpy() - np.interp(rows["epoch_s"], on_clock, truth["x"])
        ey = rows["y"].to_numpy() - np.interp(rows["epoch_s"], on_clock, truth["y"])
        found.append((ex / rows["sigma_x"].to_numpy()) ** 2 + (ey / rows["sigma_y"].to_numpy()) ** 2)
    return np.concatenate(found)


@pytest.mark.slow
def test_the_survey_error_seen_makes_the_moving_tags_nees_consistent(tmp_path):
    taken, exact, seen = [], [], []
    for seed in range(1, 5):
        sim = simulate_study(n_receivers=9, n_tags=4, days=0.25, redeployed=0, seed=seed)
        files = sim.write(tmp_path / f"{seed}", "vue")
        off = sim.positions[:, :2] + OFF * np.random.default_rng(100 + seed).normal(size=(len(sim.positions), 2))
        lat, lon = sim.frame.to_latlon(off[:, 0], off[:, 1])
        sim.deployments.assign(deploy_lat=lat, deploy_long=lon).to_csv(files["deployments"], index=False,
                                                                       float_format="%.10f")
        animals = [t for t in sim.sheet["transmitter"] if t not in set(sim.deployments["transmitter"])]
        for found, survey in ((taken, None), (exact, 0.0)):
            study = run_study(files["detections"], files["deployments"], files["tags"], chosen=animals, workers=1,
                              workdir=tmp_path / f"{seed}-{survey}", survey_sigma=survey)
            found.append(_nees(study, sim))
            if survey is None:
                clocks = study.summary["clocks"]
                assert clocks["survey_sigma_from"] == "seen"
                seen.append(clocks["survey_sigma_m"])
    taken, exact = np.mean(np.concatenate(taken)), np.mean(np.concatenate(exact))
    print(f"moving tags' NEES on positions off by {OFF} m: {taken:.2f} with the survey error seen taken "
          f"({', '.join(f'{s:.2f}' for s in seen)} m), {exact:.2f} with the positions taken as exact")
    assert 0.5 * OFF < np.sqrt(np.mean(np.square(seen))) < 1.5 * OFF
    assert 1.0 <= taken <= 3.5  # a consistent σ: 2
    assert exact > 2.0 * taken
