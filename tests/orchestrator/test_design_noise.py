"""The design keys a designer lacks (issue 70, part 4): a range-dependent noise law (``detection.range_k``, every
system's), no depth sensor (``work_area.depth_sensor``), a margin from the echo limit
(``prescription.echo_margin_pct``) and the base scenario's depth taken from the work area; each against a closed
form or an independent numpy computation, and the refusals where a key cannot apply."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from sblsim.models.design import telemetry as tm
from sblsim.models.design.criteria import (
    ECHO_LIMIT,
    RING_RATIO_PROPORTIONAL,
    coverage,
    criterion,
    judged_echo,
    ring_noise_drms,
)
from sblsim.models.design.information import layout_values
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.design import telemetry as telemetry_design
from sblsim.orchestrator.design import telemetry_confirm, telemetry_judgement
from sblsim.orchestrator.design.candidates import layout_items
from sblsim.orchestrator.design.evaluate import NO_DEPTH_SIGMA, LayoutEvaluator, Levels, judged, problem_items
from sblsim.orchestrator.design.keys import TELEMETRY
from sblsim.orchestrator.design.problem import check_problem
from sblsim.orchestrator.design.resolution import plan_of, resolve
from sblsim.orchestrator.maps import diver_depth, point_accuracy
from tests.helpers import problem_with as _with

#: A small LBL problem at the semicircle site (fixed detection: every range heard, one σ).
FIELD = {
    "design": {"name": "noise", "scenario": "semicircle"},
    "work_area": {"radius_m": 30.0, "depths_m": [5.0], "points": 7},
    "candidates": {"systems": ["lbl"]},
    "seafloor": {"radius_m": 60.0, "depth_m": 20.0},
}
#: A small lake for an ilbl design: a square of 300 m, a detection curve that hears every ping within it.
POND = {
    "design": {"name": "pond"},
    "site.area": {"polygon": "0 0; 0 300; 300 300; 300 0"},
    "detection": {"range_50_m": 5000.0, "slope": 0.01, "sync_p": 0.5, "sigma_toa_s": 1e-4, "sound_speed": 1480.0},
    "work_area": {"shape": "site", "points": 6},
    "prescription": {"drms_m": 2.0, "coverage_pct": 90.0},
    "candidates": {"systems": [TELEMETRY], "receivers": [4, 6]},
    "search": {"generations": 2, "seed": 3},
    "monte_carlo": {"replicates": 40, "path": False},
}



def _numpy_drms(points, beacons, variance, depth_variance):
    """Horizontal and 3-D DRMS of one cycle of ranges plus a depth, the information summed and inverted by numpy;
    ``variance`` (M, n) [m²], ``depth_variance`` [m²] (``inf``: no depth term)."""
    out = []
    for p, v in zip(points, variance):
        u = p - beacons
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        J = (u / v[:, None]).T @ u
        if np.isfinite(depth_variance):
            J[2, 2] += 1.0 / depth_variance
        C = np.linalg.inv(J)
        out.append((math.sqrt(C[0, 0] + C[1, 1]), math.sqrt(np.trace(C))))
    return np.array(out).T


# --------------------------------------------------------------------------- the range-dependent noise law

def test_a_centred_ring_with_the_law_is_the_ring_formula_at_the_rings_slant_range():
    """σ = σ₀ + k ρ per point and transponder through the design's information (casadi's): at the centre of a
    regular ring the DRMS is the constant-σ ring formula with σ at the ring's slant range, horizontal and 3-D, to
    1e-9; and it is not the formula at σ₀ (the law acts)."""
    n, radius, height, sigma0, k = 5, 70.0, 40.0, 0.05, 0.002
    angle = 2.0 * np.pi * np.arange(n) / n
    beacons = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.full(n, height)])
    point = np.zeros((1, 3))
    sigma = tm.range_sigma(np.linalg.norm(point[:, None] - beacons[None], axis=-1), sigma0, k)  # (1, n)
    values = layout_values(point, beacons, beacons, 1.0, sigma ** 2, 0.0, np.inf)
    rho = math.hypot(radius, height)
    s = sigma0 + k * rho
    assert values["drms"][0] == pytest.approx(2.0 * s * rho / (radius * math.sqrt(n)), rel=1e-9)
    assert values["drms_3d"][0] == pytest.approx(s * rho * math.sqrt(4 / radius**2 + 1 / height**2) / math.sqrt(n),
                                                 rel=1e-9)
    assert ring_noise_drms(n, radius, height, sigma0, k) == pytest.approx(values["drms"][0], rel=1e-9)
    assert ring_noise_drms(n, radius, height, sigma0, k, horizontal=False) == pytest.approx(values["drms_3d"][0],
                                                                                            rel=1e-9)
    assert values["drms"][0] > 1.5 * ring_noise_drms(n, radius, height, sigma0, 0.0)


@pytest.mark.parametrize("sigma0, per_m, ratio", [(0.0, 0.01, RING_RATIO_PROPORTIONAL), (0.1, 0.0, math.sqrt(2.0))])
def test_the_d_optimal_ring_with_sigma_proportional_to_range_is_at_r_over_h_0_7071(sigma0, per_m, ratio):
    """The ring radius maximising log det J of the design's information with the law (σ ∝ range): r/h = 1/√2 =
    0.7071 (the derivative of 4 log r − 6 log(r² + h²), by hand), against √2 with a constant σ; found by a
    bounded scalar search to 1e-5."""
    n, height = 4, 100.0
    angle = 2.0 * np.pi * np.arange(n) / n

    def minus_log_det(r):
        beacons = np.column_stack([r * np.cos(angle), r * np.sin(angle), np.full(n, height)])
        point = np.zeros((1, 3))
        d = np.linalg.norm(point[:, None] - beacons[None], axis=-1)
        sigma = per_m * d if sigma0 == 0.0 else tm.range_sigma(d, sigma0, per_m)
        return -float(layout_values(point, beacons, beacons, 1.0, sigma ** 2, 0.0, np.inf)["log_det"][0])

    found = minimize_scalar(minus_log_det, bounds=(10.0, 400.0), method="bounded", options={"xatol": 1e-5})
    assert found.x / height == pytest.approx(ratio, abs=1e-5)
    assert RING_RATIO_PROPORTIONAL == pytest.approx(0.7071, abs=1e-4)


def test_the_ilbl_design_with_the_law_is_an_independent_fisher_computation():
    """``detection.range_k``: the telemetry design's averaged information's DRMS at every work-area point equals a
    full 3 × 3 numpy inversion of (x, y, c t_e) with σᵢ = c σ_toa + k dᵢ, to 1e-9; at the centre of a regular ring
    every receiver heard it is 2 σ(r) / √N (the unknown emission costs nothing there)."""
    k = 0.004
    problem = telemetry_design.resolve(check_problem(_with(POND, detection={"range_k": k})))
    assert problem.sigma_per_m == k
    n, radius = 6, 100.0
    angle = 2.0 * np.pi * np.arange(n) / n
    receivers = np.column_stack([150.0 + radius * np.cos(angle), 150.0 + radius * np.sin(angle)])
    design = telemetry_judgement.TelemetryDesign(n, float(n), receivers, 0.0)
    telemetry_judgement.judge(design, problem, np.random.default_rng(0))
    sigma0 = 1480.0 * 1e-4
    for j, point in enumerate(problem.points):
        d = np.linalg.norm(point - receivers, axis=1)
        q = problem.curve.probability(d)
        H = np.column_stack([(point - receivers) / d[:, None], np.ones(n)])
        C = np.linalg.inv((H * (q / (sigma0 + k * d) ** 2)[:, None]).T @ H)
        assert design.drms_expected[j] == pytest.approx(math.sqrt(C[0, 0] + C[1, 1]), rel=1e-9)
    centre = tm.expected_information_drms(np.array([[150.0, 150.0]]), receivers,
                                          tm.range_sigma(np.full((1, n), radius), sigma0, k), 1.0)
    assert centre[0] == pytest.approx(2.0 * (sigma0 + k * radius) / math.sqrt(n), rel=1e-12)


def test_the_simulated_pings_carry_the_law():
    """``range_noise``: the arrivals' added noise has the standard deviation sqrt((σ₀ + k d)² − σ₀²) / c (10⁵
    draws, within 2 %); with k = 0 the array itself, nothing drawn."""
    rng = np.random.default_rng(5)
    d = np.array([10.0, 200.0, 800.0])
    toa = np.zeros((100_000, 3))
    out = tm.range_noise(toa, d, 0.15, 0.002, 1500.0, rng)
    expected = np.sqrt((0.15 + 0.002 * d) ** 2 - 0.15 ** 2) / 1500.0
    assert np.std(out, axis=0) == pytest.approx(expected, rel=0.02)
    state = rng.bit_generator.state
    assert tm.range_noise(toa, d, 0.15, 0.0, 1500.0, rng) is toa and rng.bit_generator.state == state


@pytest.mark.slow
def test_the_ilbl_confirmation_with_the_law_agrees_with_the_prediction():
    """A tag at the middle of a ring of six receivers, σ growing 4 mm per metre (σ₀ 0.148 m, 0.548 m at 100 m):
    1,000 simulated pings carrying the law, fixed by weighted least squares, give the predicted DRMS within 10 %,
    and 1.5 times the DRMS the constant σ₀ would predict at least (the law is in the simulation)."""
    k = 0.004
    problem = telemetry_design.resolve(check_problem(_with(POND, detection={"range_k": k})))
    n = 6
    angle = 2.0 * np.pi * np.arange(n) / n + 0.3
    receivers = np.column_stack([150.0 + 100.0 * np.cos(angle), 150.0 + 100.0 * np.sin(angle)])
    design = telemetry_judgement.TelemetryDesign(n, float(n), receivers, 0.0)
    telemetry_judgement.judge(design, problem, np.random.default_rng(0))
    index = int(np.argmin(np.linalg.norm(problem.points - 150.0, axis=1)))
    row = telemetry_confirm.static_check(design, problem, "median", index, np.random.default_rng(11))
    assert row["fixes"] >= 900
    assert 0.9 <= row["ratio"] <= 1.1, row
    point = problem.points[index]
    constant = tm.fix_drms(point[None], receivers, 1480.0 * 1e-4)[0]
    assert row["simulated_drms_m"] > 1.5 * constant


@pytest.mark.parametrize("system", ["lbl", "sbl", "usbl"])
def test_a_range_dependent_noise_is_taken_by_every_system(system):
    """LBL, SBL, USBL: the channel draws and the receivers weigh the range law (``acoustics.range_k``): the key is
    accepted and becomes the design scenario's (tests/orchestrator/test_range_law.py: the prediction)."""
    problem = check_problem(_with(FIELD, detection={"range_k": 0.001}, candidates={"systems": [system]}))
    assert problem["detection"]["range_k"] == 0.001
    assert resolve(problem, "semicircle").plan["acoustics"]["range_k"] == 0.001
    with pytest.raises(ConfigError) as error:  # its allowed range
        check_problem(_with(FIELD, detection={"range_k": 0.2}))
    assert str(error.value).startswith("detection.range_k:") and "\n" not in str(error.value)


# --------------------------------------------------------------------------- no depth sensor

@pytest.mark.parametrize("sensor", [True, False])
def test_without_a_depth_sensor_the_information_has_no_depth_term(sensor):
    """``work_area.depth_sensor``: the design's information at every work-area point (the search's evaluator and
    the map itself) equals a numpy summation and inversion with the scenario's depth sensor (0.01 m) or without
    one (σ_d = 1000 m, to 1e-9; no depth term at all, to 1e-6), horizontal and 3-D."""
    resolved = resolve(check_problem(_with(FIELD, work_area={"depth_sensor": sensor})), "semicircle")
    plan = resolved.plan
    depth_sigma = 0.01 if sensor else NO_DEPTH_SIGMA
    assert plan["target"]["depth_sigma"] == depth_sigma
    n = 4
    angle = 2.0 * np.pi * np.arange(n) / n + 0.2
    beacons = np.column_stack([55.0 * np.cos(angle), 50.0 * np.sin(angle), np.full(n, 20.0)])
    design_plan = plan_of(resolved, layout_items(FIELD["candidates"]["systems"][0], n, beacons))
    variance = design_plan["acoustics"]["sigma_range"] ** 2 + design_plan["platform"]["survey_sigma"] ** 2
    points = resolved.points
    values = LayoutEvaluator(points, Levels.of(design_plan), compiled=False).evaluate(beacons[None])
    mapped = point_accuracy(design_plan, points)
    horizontal, total = _numpy_drms(points, beacons, np.full((len(points), n), variance), depth_sigma ** 2)
    for drms, drms_3d in ((values["drms"][0], values["drms_3d"][0]), (mapped["drms"], mapped["drms_3d"])):
        np.testing.assert_allclose(drms, horizontal, rtol=1e-9)
        np.testing.assert_allclose(drms_3d, total, rtol=1e-9)
    if not sensor:  # the 1000 m sensor is none: the fix of the ranges alone
        horizontal, total = _numpy_drms(points, beacons, np.full((len(points), n), variance), np.inf)
        np.testing.assert_allclose(values["drms_3d"][0], total, rtol=1e-6)
        np.testing.assert_allclose(values["drms"][0], horizontal, rtol=1e-6)
        with_sensor = _numpy_drms(points, beacons, np.full((len(points), n), variance), 1e-4)[1]
        assert np.all(total > 1.2 * with_sensor)  # the depth unknown costs the 3-D fix


def test_no_depth_sensor_is_refused_for_an_ilbl_design():
    """An ilbl design's tag and receivers are in one plane: ``work_area.depth_sensor = false`` refused in one
    line naming the key."""
    with pytest.raises(ConfigError) as error:
        check_problem(_with(POND, work_area={"depth_sensor": False}))
    assert str(error.value).startswith("work_area.depth_sensor:") and "\n" not in str(error.value)


# --------------------------------------------------------------------------- the echo margin

def test_an_echo_margin_removes_exactly_the_points_an_independent_count_says():
    """``judged_echo``: with a margin of m percentage points a point counts only where its probability of a fix
    of reflections is at most 1 % − m (an independent mask), in the coverage, the percentile and the worst
    criteria; a margin of 0 is the same array (every figure bit for bit)."""
    rng = np.random.default_rng(2)
    echo = rng.uniform(0.0, 0.02, 500)
    echo[:5] = [0.0, 0.004, 0.005, 0.0050001, 0.01]
    drms = rng.uniform(0.01, 0.1, 500)
    availability = np.ones(500)
    assert judged_echo(echo, 0.0) is echo
    for margin in (0.2, 0.5, 0.9):
        keep = echo <= ECHO_LIMIT - margin / 100.0
        judged_values = judged_echo(echo, margin)
        assert np.array_equal(judged_values <= ECHO_LIMIT, keep)
        assert coverage(drms, availability, 1.0, 95.0, judged_values) == pytest.approx(100.0 * keep.mean(), abs=1e-12)
        assert criterion("worst", drms, np.zeros(500), 50.0, judged_values) == math.inf
        kept = np.sort(np.where(keep, drms, np.inf))
        assert criterion("percentile", drms, np.zeros(500), 30.0, judged_values) == np.percentile(
            kept, 30.0, method="higher")
    sections = {"prescription": {"echo_margin_pct": 0.0}}
    values = {"echo": echo}
    assert judged(values, sections) is values
    with pytest.raises(ValueError):
        judged_echo(echo, 1.0)


def test_an_echo_margin_is_refused_for_an_ilbl_design():
    with pytest.raises(ConfigError) as error:
        check_problem(_with(POND, prescription={"echo_margin_pct": 0.5}))
    assert str(error.value).startswith("prescription.echo_margin_pct:") and "\n" not in str(error.value)


# --------------------------------------------------------------------------- the scenario's depth

def test_the_base_scenarios_depth_is_the_work_areas():
    """A work area at 12 m over a scenario whose vehicle swims at 5 m: the resolved scenario (and so every
    design's scenario file, and its map drawn at ``target.depth``) is at 12 m; at the scenario's own depth no
    override is made (the scenario as it was)."""
    resolved = resolve(check_problem(_with(FIELD, work_area={"depths_m": [12.0]})), "semicircle")
    assert resolved.plan["target"]["depth"] == 12.0
    assert diver_depth(plan_of(resolved, []))[0] == 12.0
    assert "target.depth=12.0" in resolved.items
    same = resolve(check_problem(FIELD), "semicircle")
    assert problem_items(same.sections, same.plan) == [] and same.items == []


@pytest.mark.slow
def test_a_design_without_a_depth_sensor_is_confirmed_by_its_monte_carlo(tmp_path):
    """``work_area.depth_sensor = false`` with a 3-D prescription: the design's scenario has no depth sensor to
    speak of (``target.depth_sigma`` 1000 m), it needs more transponders than with one, and the static runs of its
    ``lsq`` receiver give the predicted 3-D DRMS within 15 % at the worst and the median point."""
    import sblsim

    problem = _with(FIELD, work_area={"radius_m": 30.0, "points": 11}, candidates={"transponders": [3, 8]},
                    prescription={"drms_m": 0.12, "coverage_pct": 90.0, "dimensions": "3d"},
                    search={"seed": 4, "generations": 30}, monte_carlo={"replicates": 10, "path": False})
    counts = {}
    for sensor in (True, False):
        result = sblsim.design(None, **_with(problem, work_area={"depth_sensor": sensor}), out=tmp_path / str(sensor))
        best = result.designs[0]
        counts[sensor] = len(best["transponders_m"])
        assert best["meets"]
        assert all(0.85 <= row["ratio"] <= 1.15 for row in best["monte_carlo"]), best["monte_carlo"]
        text = (tmp_path / str(sensor) / f"{best['name']}.toml").read_text()
        assert (f"depth_sigma = {NO_DEPTH_SIGMA}" in text) != sensor
    assert counts[False] > counts[True]
