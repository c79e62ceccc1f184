"""The reference tags' score confirmed by a Monte Carlo (issue 97, item 3: an honest σ on still tags): simulated
studies whose deployments are off by a survey error the study is told, three sync tags of each given as reference
tags at their receivers, their NEES as the study scores them and of their places against the simulation's truth
(``benchmarks/bench_reference_tags.py`` runs more)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from sblsim.orchestrator.telemetry.outputs import write_study
from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study import run_study

#: The survey error put into every deployment and stated to the study [m per horizontal axis].
SURVEY = 2.0
#: The arrays simulated, each with three reference tags.
ARRAYS = 12


def _array(seed: int, folder) -> list[tuple[float, float]]:
    """One study of 16 receivers on positions off by :data:`SURVEY`: each reference tag's NEES as scored and of its
    place against its true position on the place's covariance alone."""
    sim = simulate_study(n_receivers=16, n_tags=0, days=0.25, redeployed=0, seed=seed)
    files = sim.write(folder / "in", "vue")
    rng = np.random.default_rng(100 + seed)
    off = sim.positions[:, :2] + SURVEY * rng.normal(size=(len(sim.positions), 2))
    lat, lon = sim.frame.to_latlon(off[:, 0], off[:, 1])
    deployments = sim.deployments.assign(deploy_lat=lat, deploy_long=lon)
    at = np.sort(rng.choice(len(deployments), 3, replace=False))
    references = deployments["transmitter"].iloc[at].tolist()
    sheet = sim.sheet.copy()
    sheet.loc[sheet["transmitter"].isin(references), "role"] = "reference"
    sheet["receiver"] = sheet["transmitter"].map(dict(zip(references, deployments["station"].iloc[at]))).fillna("")
    deployments.loc[deployments.index[at], "transmitter"] = ""
    deployments.to_csv(files["deployments"], index=False, float_format="%.10f")
    sheet.to_csv(files["tags"], index=False)
    outcome = run_study(files["detections"], files["deployments"], files["tags"], workdir=folder / "work",
                        chosen=references, workers=1, survey_sigma=SURVEY)
    write_study(outcome, folder / "out")
    scored = pd.read_csv(folder / "out" / "reference_tags.csv", dtype={"tag": str}).set_index("tag")
    tags = pd.read_csv(folder / "out" / "tags.csv", dtype={"tag": str}).set_index("tag")
    tracks = pd.read_csv(folder / "out" / "tracks.csv", dtype={"tag": str})
    found = []
    for tag, k in zip(references, at):
        assert scored.loc[tag, "kind"] == "reference" and scored.loc[tag, "survey_sigma_m"] == SURVEY
        still = json.loads((folder / "out" / tags.loc[tag, "folder"] / "summary.json").read_text())["motion"]
        P = np.asarray(still["still"]["covariance"], float)[:2, :2]
        e = tracks.loc[tracks["tag"] == tag, ["x", "y"]].to_numpy(float)[0] - sim.positions[k, :2]
        found.append((float(scored.loc[tag, "nees"]), float(e @ np.linalg.solve(P, e))))
    return found


@pytest.mark.slow
def test_the_reference_tags_score_holds_where_the_positions_are_off(tmp_path):
    """Over 12 arrays (36 reference tags at receivers 2 m off per axis, that error stated), the mean NEES as scored
    lies within χ²(72)/36's 99 % interval, and that of the places against their true positions no higher and at
    least 1 (the issue's [1, 3]; their covariance holds the receivers' jackknife beside the survey's term, on the
    large side: docs/telemetry.md)."""
    found = np.array([row for seed in range(1, ARRAYS + 1) for row in _array(seed, tmp_path / str(seed))])
    n = len(found)
    low, high = chi2.ppf(0.005, 2 * n) / n, chi2.ppf(0.995, 2 * n) / n
    scored, truth = found.mean(axis=0)
    print(f"{n} reference tags: NEES {scored:.2f} as scored, {truth:.2f} against the truth "
          f"(99 % of consistent studies: {low:.2f} to {high:.2f})")
    assert low <= scored <= high
    assert 1.0 <= truth <= high
