"""Survey B (GNATSS NCL1, day 208) with SeaGap's NTD: the day's change of the sound speed, which one CTD cast cannot
follow, taken out of the residuals without moving the horizontal solution."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.orchestrator.surveys.calibrate import calibrate, load_survey

#: The single-profile solution's TWTT residual RMS (docs/calibration.md, the straight ray at the harmonic means) [s]
SINGLE_PROFILE_RMS_S = 42.7e-6
NTD = ["solver.perturbation=ntd", "solver.n_bases=[4, 5, 6, 7, 8, 10, 12]", "solver.criterion=bic"]


@pytest.fixture(scope="module")
def both():
    return calibrate(load_survey("ncl1-2022-208")), calibrate(load_survey("ncl1-2022-208", overrides=NTD))


def test_the_ntd_fits_the_day_better_and_keeps_the_horizontal(both):
    single, ntd = both
    s, p = single.solution, ntd.solution
    assert s["twtt_residual_rms_s"] == pytest.approx(SINGLE_PROFILE_RMS_S, abs=0.05e-6)
    assert p["twtt_residual_rms_s"] < 0.7 * SINGLE_PROFILE_RMS_S
    a, b = s["array_displacement"], p["array_displacement"]
    assert np.hypot(a["e_m"] - b["e_m"], a["n_m"] - b["n_m"]) < 0.02
    # the search's table and its choice: the smallest BIC
    table = ntd.search
    assert list(table["n_bases"]) == [4, 5, 6, 7, 8, 10, 12]
    assert table.loc[table["chosen"], "bic"].iloc[0] == table["bic"].min()
    assert p["n_bases"] == int(table.loc[table["chosen"], "n_bases"].iloc[0])
    # the NTD takes what one cast leaves: Up trades against it (its sigma some ten times the single profile's)
    assert b["sigma_u_m"] > 5 * a["sigma_u_m"]
    assert "running" not in p and ntd.running is None  # the running solution has no perturbation model
