"""The telemetry array's design in 3-D (issue 70): receivers moored at depths (``candidates.receiver_depth_m``), a
tag at the work area's depths (``work_area.depths_m``), with a depth sensor (``detection.depth_sigma_m``) or without
(``work_area.depth_sensor = false``). The prediction against an independent numpy Fisher computation of
(North, East, depth, emission), the places against the water, the refusals, the Monte Carlo against the prediction
and the planar case against itself."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from sblsim.models.errors import ConfigError
from sblsim.orchestrator.design import telemetry as t
from sblsim.orchestrator.design import telemetry_confirm as tc
from sblsim.orchestrator.design import telemetry_judgement as tj
from sblsim.orchestrator.design import telemetry_output as out
from sblsim.orchestrator.design import telemetry_search as ts
from sblsim.orchestrator.design.keys import TELEMETRY
from sblsim.orchestrator.design.problem import check_problem

#: A pond of 100 m, receivers at 1 m and 15 m, the tag at 4 m and 10 m; the curve's 50 % at 150 m (each receiver
#: uncertain: the enumeration of the detection patterns is exercised); a fix of four receivers counts where its own
#: geometry gives at most 5 m.
POND = {
    "design": {"name": "pond3d"},
    "site.area": {"polygon": "0 0; 0 100; 100 100; 100 0"},
    "detection": {"range_50_m": 150.0, "slope": 0.03, "sync_p": 0.5, "sigma_toa_s": 1e-4, "sound_speed": 1480.0},
    "work_area": {"shape": "site", "points": 5, "depths_m": [4.0, 10.0]},
    "prescription": {"drms_m": 1.0, "coverage_pct": 90.0, "fix_receivers": 4, "positioning_yield_pct": 50.0,
                     "fix_gate_m": 5.0},
    "candidates": {"systems": [TELEMETRY], "receivers": [4, 6], "receiver_depth_m": [1.0, 15.0]},
    "search": {"generations": 1, "seed": 3},
    "monte_carlo": {"replicates": 10, "path": False},
}
#: A layout of six receivers at two depths (North, East, depth) [m].
LAYOUT = np.array([[5.0, 5.0, 1.0], [95.0, 10.0, 15.0], [90.0, 90.0, 1.0], [10.0, 95.0, 15.0], [50.0, 30.0, 1.0],
                   [40.0, 70.0, 15.0]])


def _with(base: dict, **changes) -> dict:
    out = {k: dict(v) for k, v in base.items()}
    for section, values in changes.items():
        out.setdefault(section, {}).update(values)
    return out


def _numpy_drms(point, receivers, sigma, heard, depth_sigma, horizontal):
    """The DRMS of one fix by numpy: the full Fisher information of (North, East, depth, c t_e) summed over the
    receivers heard (weights ``heard``), plus 1/σ_d² on the depth, inverted whole (its position block is the
    inverse of the Schur complement of the emission)."""
    H = np.zeros((4, 4))
    for r, s, h in zip(receivers, sigma, heard):
        g = np.append((point - r) / np.linalg.norm(point - r), 1.0)
        H += h / s**2 * np.outer(g, g)
    if depth_sigma is not None:
        H[2, 2] += 1.0 / depth_sigma**2
    if np.linalg.cond(H) > 1e12:
        return np.inf
    C = np.linalg.inv(H)
    return float(np.sqrt(np.trace(C[:2, :2]) if horizontal else np.trace(C[:3, :3])))


@pytest.mark.parametrize("sensor, dimensions", [(True, "horizontal"), (False, "horizontal"), (True, "3d"),
                                                (False, "3d")])
def test_the_3d_prediction_equals_an_independent_fisher_computation(sensor, dimensions):
    """At every work-area point (each horizontal point at each of the tag's depths), the averaged information's DRMS
    and the fixed pings' RMS (every detection pattern enumerated, a fix needing 4 receivers and its own DRMS at most
    the 5 m gate) equal numpy's full Fisher of (x, y, z, c t_e) to 1e-9, with the depth sensor's term (σ 0.3 m) and
    without it."""
    problem = t.resolve(check_problem(_with(POND, work_area={"depth_sensor": sensor},
                                            prescription={"dimensions": dimensions})))
    assert problem.points.shape == (2 * 25, 3) and set(problem.points[:, 2]) == {4.0, 10.0}
    design = tj.TelemetryDesign(len(LAYOUT), 0.0, LAYOUT, 0.0)
    tj.judge(design, problem, np.random.default_rng(0))
    depth_sigma = 0.3 if sensor else None
    horizontal = dimensions == "horizontal"
    sigma = np.full(len(LAYOUT), 1480.0 * 1e-4)
    for j, point in enumerate(problem.points):
        q = problem.curve.probability(np.linalg.norm(LAYOUT - point, axis=1))
        expected = _numpy_drms(point, LAYOUT, sigma, q, depth_sigma, horizontal)
        assert design.drms_expected[j] == pytest.approx(expected, rel=1e-9)
        total, weight = 0.0, 0.0
        for bits in itertools.product((0, 1), repeat=len(LAYOUT)):
            heard = np.array(bits, float)
            if heard.sum() < 4:
                continue
            value = _numpy_drms(point, LAYOUT, sigma, heard, depth_sigma, horizontal)
            p = float(np.prod(np.where(heard > 0, q, 1.0 - q)))
            if value <= 5.0:
                total, weight = total + p * value**2, weight + p
        assert design.drms_fixed[j] == pytest.approx(np.sqrt(total / weight), rel=1e-9)
        assert design.fixable[j] == pytest.approx(weight, rel=1e-9)
    # the depth sensor helps the horizontal fix: the depth and the emission trade against each other without it
    if not sensor:
        with_sensor = tj.TelemetryDesign(len(LAYOUT), 0.0, LAYOUT, 0.0)
        tj.judge(with_sensor, t.resolve(check_problem(_with(POND, prescription={"dimensions": dimensions}))),
                np.random.default_rng(0))
        assert np.all(with_sensor.drms_expected < design.drms_expected)


def test_the_receivers_stay_in_the_water_at_their_stated_depths():
    """The searched layouts' receivers lie in the water at ``candidates.receiver_depth_m`` in turn; a receiver in
    place keeps its own depth (or takes the first where it has none)."""
    problem = t.resolve(check_problem(_with(POND, candidates={"existing_m": "20 20 7; 80 80"})))
    run = ts.search_all(problem)
    assert len(run.searched) >= 2
    for design in run.searched:
        assert t.within(problem, design.receivers) and design.receivers.shape[1] == 3
        np.testing.assert_array_equal(design.receivers[:2], [[20.0, 20.0, 7.0], [80.0, 80.0, 1.0]])
        added = design.receivers[2:, 2]
        np.testing.assert_array_equal(added, np.array([1.0, 15.0])[np.arange(len(added)) % 2])


@pytest.mark.parametrize("changes, key", [
    ({"candidates": {"receiver_depth_m": [5.0]}, "work_area": {"depth_sensor": False}}, "candidates.receiver_depth_m"),
    ({"candidates": {"receiver_depth_m": [5.0], "existing_m": "20 20"}, "work_area": {"depth_sensor": False}},
     "candidates.receiver_depth_m"),
    ({"work_area": {"depth_sensor": False}, "prescription": {"fix_receivers": 3}}, "prescription.fix_receivers"),
    ({"work_area": {"depths_m": []}}, "work_area.depths_m"),
    ({"candidates": {"receiver_depth_m": []}}, "work_area.depths_m"),
    ({"candidates": {"receiver_depth_m": [], "existing_m": "20 20 4"}, "work_area": {"depths_m": []}},
     "candidates.existing_m"),
    ({"candidates": {"receiver_depth_m": []}, "work_area": {"depths_m": [], "depth_sensor": False}},
     "work_area.depth_sensor"),
])
def test_a_depth_that_cannot_be_fixed_is_refused_in_one_line(changes, key):
    """Refused in one line naming the key: a planar array (every receiver at one depth, those in place too)
    without a depth sensor; a fix of fewer than four receivers without one; the receivers' depths without the
    tag's, the tag's without the receivers'; a depth for a receiver in place of a planar design; no depth sensor
    in a planar design."""
    with pytest.raises(ConfigError) as error:
        check_problem(_with(POND, **changes))
    assert str(error.value).startswith(f"{key}:") and "\n" not in str(error.value)


def test_a_planar_array_has_no_information_about_a_depth_at_its_own():
    """Why a planar array without a sensor is refused: at the receivers' depth every direction to the tag is
    horizontal, the depth's column of the Fisher information is zero (numpy: a zero row) and the fix is singular;
    elsewhere the depth's mirror about the plane fits the same ranges."""
    from sblsim.models.design import telemetry as tm

    flat = LAYOUT.copy()
    flat[:, 2] = 5.0
    at, off = np.array([[50.0, 50.0, 5.0]]), np.array([[50.0, 50.0, 8.0]])
    assert np.isinf(tm.fix_drms(at, flat, 0.148)[0])
    assert np.isfinite(tm.fix_drms(off, flat, 0.148)[0])
    mirror = np.array([50.0, 50.0, 2.0])
    np.testing.assert_allclose(np.linalg.norm(flat - off[0], axis=1), np.linalg.norm(flat - mirror, axis=1))
    assert np.isfinite(tm.fix_drms(at, flat, 0.148, depth_sigma_m=0.3)[0])  # a sensor gives it


@pytest.mark.slow
@pytest.mark.parametrize("sensor", [True, False])
def test_the_3d_monte_carlo_agrees_with_the_prediction(sensor):
    """Simulated pings at the worst and median points fixed by 3-D least squares (with the sensor's readings where
    it has one), 1,000 pings each: the simulated DRMS within [0.85, 1.15] of the predicted and the yield within 5
    points. Without a sensor a fix takes five receivers (one redundant: four ranges fit a wrong solution of the four
    unknowns often, as three do in 2-D; measured 2.8 and 12 times the predicted with four)."""
    problem = t.resolve(check_problem(_with(POND, work_area={"depth_sensor": sensor},
                                            prescription={"fix_receivers": 4 if sensor else 5},
                                            monte_carlo={"replicates": 40})))
    design = tj.TelemetryDesign(len(LAYOUT), 0.0, LAYOUT, 0.0)
    tj.judge(design, problem, np.random.default_rng(0))
    tc.confirm(design, problem)
    assert len(design.monte_carlo) == 2
    for row in design.monte_carlo:
        assert row["depth_m"] in (4.0, 10.0) and row["fixes"] >= 0.9 * row["pings"] * row["predicted_fixed"]
        assert 0.85 <= row["ratio"] <= 1.15, row
        assert abs(row["simulated_yield"] - row["predicted_yield"]) <= 0.05, row


@pytest.mark.slow
def test_the_3d_walk_is_tracked_in_3d():
    """The walk at the work area's depths, fixed in 3-D and tracked by the replay tracker with the sensor's
    readings: a finite track, its error small against the pond, the simulated DRMS near the predicted."""
    problem = t.resolve(check_problem(_with(POND, monte_carlo={"path": True, "sync_clocks": False})))
    design = tj.TelemetryDesign(len(LAYOUT), 0.0, LAYOUT, 0.0)
    tj.judge(design, problem, np.random.default_rng(0))
    row = tc.path_check(design, problem, np.random.default_rng(1))
    assert row["tracked_pings"] > 100 and np.isfinite(row["tracked_rms_m"]) and row["tracked_rms_m"] < 1.0, row
    assert 0.85 <= row["ratio"] <= 1.15, row
    depths = tc.walk_depth(problem, np.linspace(0.0, 3600.0, 101))
    assert depths.min() == pytest.approx(4.0) and depths.max() == pytest.approx(10.0)


@pytest.mark.slow
def test_the_planar_case_is_unchanged():
    """Without the receivers' depths the design is planar: its ``design.json`` is the same whatever the 3-D keys
    say (``detection.depth_sigma_m``) but for the problem's echo; and a 3-D design whose receivers and tag all lie at
    the surface with a depth sensor predicts what the planar design predicts (the depth's information decouples)."""
    planar = _with(POND, work_area={"depths_m": []}, candidates={"receiver_depth_m": []})
    a = t.resolve(check_problem(planar))
    b = t.resolve(check_problem(_with(planar, detection={"depth_sigma_m": 5.0})))
    docs = []
    for problem in (a, b):
        run = ts.search_all(problem)
        for design in run.proposed:
            tc.confirm(design, problem)
        docs.append(json.loads(json.dumps(out.document(run), allow_nan=True)))
    for doc in docs:
        doc.pop("problem")
    assert docs[0] == docs[1]
    flat = t.resolve(check_problem(_with(POND, work_area={"depths_m": [0.0]},
                                         candidates={"receiver_depth_m": [0.0]})))
    layout = LAYOUT * [1, 1, 0] + [0.5, 0.5, 0.0]  # off the work area's points: no receiver at a tag's place
    two, three = tj.TelemetryDesign(6, 0.0, layout[:, :2], 0.0), tj.TelemetryDesign(6, 0.0, layout, 0.0)
    tj.judge(two, a, np.random.default_rng(0))
    tj.judge(three, flat, np.random.default_rng(0))
    np.testing.assert_allclose(three.drms_fixed, two.drms_fixed, rtol=1e-9)
    np.testing.assert_allclose(three.drms_expected, two.drms_expected, rtol=1e-9)
    np.testing.assert_allclose(three.positioning_yield, two.positioning_yield, rtol=1e-12)
