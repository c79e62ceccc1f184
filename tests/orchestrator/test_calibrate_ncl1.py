"""Survey B (GNATSS NCL1, day 208) solved by ``sblsim calibrate``: the built-in survey ``ncl1-2022-208`` with a
straight ray at each transponder's harmonic mean and with the direct eigenray through the CTD."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from sblsim.fmus.compiled_functions import compiled_exact_points
from sblsim.models.acoustics.sound_speed import profile_table
from sblsim.models.calibration import EigenRay, solve
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.surveys.calibrate import calibrate, leg_model, load_survey
from sblsim.orchestrator.surveys.gnatss import community_editing, read_ncl1, straight_ray_residuals
from sblsim.orchestrator.surveys.log import SurveyLog

#: GNATSS's own harmonic means of the CTD for NCL1 (its tests/data/config.yaml, sv_mean) [m/s].
GNATSS_SV_MEAN = (1481.551, 1481.521, 1481.509)
RAY = ['solver.propagation=ray']


@pytest.fixture(scope="module")
def straight():
    return calibrate(load_survey("ncl1-2022-208"))


@pytest.fixture(scope="module")
def ray():
    return calibrate(load_survey("ncl1-2022-208", overrides=RAY))


def _shift(result) -> np.ndarray:
    t = result.solution["transponders"]
    offsets = np.array([[x["e_m"], x["n_m"], x["u_m"]] for x in t])
    np.testing.assert_allclose(offsets, np.tile(offsets[0], (len(t), 1)), atol=1e-12)  # one rigid shift
    return offsets[0]


@pytest.mark.slow
def test_the_command_writes_the_named_keys(tmp_path, straight):
    assert main(["calibrate", "ncl1-2022-208", "--out", str(tmp_path / "b")]) == 0
    s = json.loads((tmp_path / "b" / "solution.json").read_text())
    for key in ("transponders", "segments", "twtt_residual_rms_s", "pings_used", "pings_rejected",
                "sound_speed_mps", "solver"):
        assert key in s
    assert [t["id"] for t in s["transponders"]] == ["NCL1-1", "NCL1-2", "NCL1-3"]
    assert set(s["transponders"][0]) >= {"id", "n_m", "e_m", "u_m", "sigma_n_m", "sigma_e_m", "sigma_u_m",
                                         "sound_speed_mps"}
    assert s["solver"]["propagation"] == "straight" and s["solver"]["sound_speed_profile"] == "ctd:NCL1"
    assert s["transponders"] == straight.solution["transponders"]
    # the community editing's 54 pings (an independent count of the reader's test), none rejected
    log, site = read_ncl1()
    assert s["pings_used"] == community_editing(log, site)["ping"].nunique() == 54
    assert s["pings_rejected"] == 0
    # each transponder's speed: the harmonic mean of the CTD from 4 m to its depth, GNATSS's within 2 mm/s
    speeds = [t["sound_speed_mps"] for t in s["transponders"]]
    np.testing.assert_allclose(speeds, GNATSS_SV_MEAN, atol=2e-3)
    np.testing.assert_allclose(speeds, [t.sound_speed_mps for t in site.transponders], rtol=1e-14)


@pytest.mark.slow
def test_the_straight_ray_residuals_are_the_readers_check_at_the_shift(straight):
    """The TWTT residual RMS against an independent model: the reader's straight-ray residuals at the shift."""
    log, site = read_ncl1()
    frame = straight.survey.log.frame
    independent = straight_ray_residuals(frame, site, _shift(straight))
    np.testing.assert_allclose(straight.residuals["residual_s"], independent, atol=1e-12)
    assert straight.solution["twtt_residual_rms_s"] == pytest.approx(np.sqrt(np.mean(independent ** 2)), rel=1e-9)


@pytest.mark.slow
def test_replies_are_paired_by_identity_a_shuffled_log_gives_the_same_solution(straight):
    survey = straight.survey
    f = survey.log.frame
    shuffled = f.sample(frac=1.0, random_state=11).reset_index(drop=True)
    assert not (shuffled["transponder"].to_numpy() == f["transponder"].to_numpy()).all()
    # and the transponders listed in another order
    order = [2, 0, 1]
    log = SurveyLog(shuffled, "shuffled", [""] * len(f), dict(survey.log.counts))
    other = dataclasses.replace(survey, log=log, ids=[survey.ids[k] for k in order], apriori=survey.apriori[order],
                                depth_m=survey.depth_m[order])
    again = calibrate(other)
    by_id = {t["id"]: t for t in again.solution["transponders"]}
    for t in straight.solution["transponders"]:
        for key in ("e_m", "n_m", "u_m", "sigma_e_m", "sigma_n_m", "sigma_u_m", "sound_speed_mps"):
            assert by_id[t["id"]][key] == pytest.approx(t[key], abs=1e-9)
    assert again.solution["twtt_residual_rms_s"] == pytest.approx(straight.solution["twtt_residual_rms_s"], rel=1e-9)
    # pairing by arrival order instead (the replies of each ping relabelled in time order) is another solution
    wrong = f.copy()
    wrong["arrival"] = wrong["t_rx_s"]
    wrong = wrong.sort_values(["ping", "arrival"])
    wrong["transponder"] = np.tile(survey.ids, len(wrong) // 3)
    bad = calibrate(dataclasses.replace(survey, log=SurveyLog(wrong.drop(columns="arrival").reset_index(drop=True),
                                                              "by arrival", [""] * len(f), dict(survey.log.counts))))
    assert bad.solution["twtt_residual_rms_s"] > 100 * straight.solution["twtt_residual_rms_s"]


def _objective(survey, legs, shift, weight):
    replies = survey.log.replies(survey.ids)
    x = survey.apriori[replies.transponder] + shift
    c0 = survey.solver["sound_speed_mps"]
    v = c0 * replies.twtt - legs.legs(replies.tx, x, replies.transponder)[0] \
        - legs.legs(replies.rx, x, replies.transponder)[0]
    return float(np.sum(weight * v ** 2))


@pytest.mark.slow
@pytest.mark.parametrize("which", ["straight", "ray"])
def test_each_solution_is_a_weighted_least_squares_minimum(which, straight, ray):
    result = straight if which == "straight" else ray
    legs, _ = leg_model(result.survey)
    shift = _shift(result)
    w = result.segments[0][3].weight
    f0 = _objective(result.survey, legs, shift, w)
    h = 2e-3
    for axis in np.eye(3):
        plus, minus = (_objective(result.survey, legs, shift + s * h * axis, w) for s in (1.0, -1.0))
        rise = 0.5 * (plus + minus) - f0
        assert rise > 0.0
        # the first-order change (the gradient) is round-off beside the second-order one
        assert abs(plus - minus) < 1e-3 * rise


@pytest.mark.slow
def test_ray_and_straight_ray_against_each_other(straight, ray):
    """The eigenray solution: the same pings, a shift within a few sigma horizontally of the straight ray's; its
    vertical differs (the straight ray's harmonic mean starts 4 m down and ignores the bending)."""
    assert ray.solution["pings_used"] == straight.solution["pings_used"]
    a, b = _shift(straight), _shift(ray)
    sigma = np.array([straight.solution["transponders"][0][k] for k in ("sigma_e_m", "sigma_n_m", "sigma_u_m")])
    assert np.all(np.abs(b[:2] - a[:2]) < sigma[:2])
    assert abs(b[2] - a[2]) > 5 * sigma[2]
    assert ray.solution["solver"]["propagation"] == "ray"
    assert "sound_speed_mps" not in ray.solution["transponders"][0]


@pytest.mark.slow
def test_the_eigenray_through_one_speed_is_the_straight_ray_at_that_speed(straight):
    """Isovelocity water on the survey's geometry: the ray leg's solution is the straight ray's."""
    survey = straight.survey
    c = 1481.5
    replies = survey.log.replies(survey.ids)
    plain = solve(replies, survey.apriori, c, rigid=True, outlier_factor=None)
    iso = EigenRay(np.array([[0.0, c], [2000.0, c]]), c, survey.solver["surface_u_m"], compiled_exact_points())
    ray = solve(replies, survey.apriori, c, rigid=True, outlier_factor=None, legs=iso)
    np.testing.assert_allclose(ray.offset, plain.offset, atol=1e-8)
    np.testing.assert_allclose(ray.residual_s, plain.residual_s, atol=1e-11)
    # and not the CTD's (its bending: centimetres on each leg)
    ctd = EigenRay(profile_table("ctd:NCL1", "", 15.0, 35.0), c, survey.solver["surface_u_m"], compiled_exact_points())
    assert np.max(np.abs(ctd.legs(replies.tx, survey.apriori[replies.transponder], replies.transponder)[0]
                         - iso.legs(replies.tx, survey.apriori[replies.transponder], replies.transponder)[0])) > 0.05


@pytest.mark.parametrize("argv,message", [
    (["--set", 'solver.propagation="bent"'], "solver.propagation: 'bent' is not one of straight, ray"),
    (["--set", 'solver.propagation="ray"', "--set", 'solver.sound_speed_profile=""'],
     'propagation = "ray" needs a profile'),
    (["--set", 'solver.sound_speed_profile="ctd:NOPE"'], "unknown cast"),
    (["--set", "solver.harmonic_mean_start_depth_m=-1"], "solver.harmonic_mean_start_depth_m: -1 is outside"),
    (["--set", "solver.harmonic_mean_start_depth_m=1170"], "is not below the start depth"),
])
def test_bad_propagation_settings_are_refused_in_one_line(tmp_path, capsys, argv, message):
    assert main(["calibrate", "ncl1-2022-208", "--out", str(tmp_path / "x"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()
