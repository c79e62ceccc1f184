"""The range-dependent noise law ``σ = σ₀ + k d`` in runs and designs: ``acoustics.range_k`` ties the receivers'
``range_k``, and a receiver that weighs the law is consistent (its NEES near the 3 of a position's chi-square) where
one that ignores it is not; a design's ``detection.range_k`` is its scenario's ``acoustics.range_k`` for every
system, and its prediction an independent numpy Fisher computation with σ_i(p) = σ₀ + k ‖p − b_i‖."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import as_plan
from sblsim.orchestrator.cosim.run import run, run_batch, with_replicates
from sblsim.orchestrator.design.candidates import layout_items
from sblsim.orchestrator.design.evaluate import LayoutEvaluator, Levels
from sblsim.orchestrator.design.problem import check_problem, read_problem
from sblsim.orchestrator.design.resolution import plan_of, resolve
from sblsim.orchestrator.maps import point_accuracy
from sblsim.orchestrator.montecarlo.error_sources import SOURCES, switched_off
from tests.helpers import problem_with

#: The scenarios' fixed-detection, straight-path variants: an LBL of 250 m radius with a vehicle at 150 m depth
#: (ranges of 200–400 m), the same field as an inverted LBL (the vehicle's pings heard by the four), and a USBL
#: with a vehicle 300 m out at 100 m depth (a slant range of ~320 m).
SCENARIOS = {
    "lbl-field": ("lbl-field", ["acoustics.detection=fixed", "acoustics.propagation=straight",
                                "simulation.duration=300"]),
    "lbl-field as ilbl": ("lbl-field", ["platform.system=ilbl", "acoustics.detection=fixed",
                                        "acoustics.propagation=straight", "simulation.duration=300"]),
    "usbl-deep": ("usbl-deep", ["acoustics.detection=fixed", "acoustics.propagation=straight",
                                "simulation.duration=800", "target.radius=300", "target.depth=100"]),
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
    nees, ratio = {}, {}
    for weighed in (K, 0.0):
        name, items = SCENARIOS[scenario]
        cfg = load_config(name, items + [f"acoustics.range_k={K}", f"receiver.range_k={weighed}"], seed=1)
        metrics = run_batch(with_replicates(cfg, range(20)), timeseries=False).metrics
        nees[weighed] = float(np.mean(metrics["nees_mean"]))
        ratio[weighed] = float(np.sqrt(np.mean(metrics["e_tot_rms"] ** 2) / np.mean(metrics["pcrb_rms"] ** 2)))
    assert 1.5 <= nees[K] <= 4.5, nees
    assert not 1.5 <= nees[0.0] <= 4.5, nees
    # the PCRB with the law (each range's variance at its true length) holds the consistent receiver's RMS within
    # 1.3 times, and bounds it from below
    assert 1.0 <= ratio[K] <= 1.3, ratio


# --------------------------------------------------------------------------- the design with the law

#: A small LBL problem at the semicircle site (fixed detection: every range heard; σ₀ 0.1 m, survey 0.1 m by
#: default), the law's k large enough to change every figure.
FIELD = {
    "design": {"name": "law", "scenario": "semicircle"},
    "work_area": {"radius_m": 30.0, "depths_m": [5.0], "points": 7},
    "candidates": {"systems": ["lbl"]},
    "seafloor": {"radius_m": 60.0, "depth_m": 20.0},
    "detection": {"range_k": 0.01},
}


def _numpy_drms(points, beacons, variance, depth_variance):
    """Horizontal and 3-D DRMS of one cycle of ranges plus a depth, the information summed and inverted by numpy;
    ``variance`` (M, n) [m²]."""
    out = []
    for p, v in zip(points, variance):
        u = p - beacons
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        J = (u / v[:, None]).T @ u
        J[2, 2] += 1.0 / depth_variance
        C = np.linalg.inv(J)
        out.append((math.sqrt(C[0, 0] + C[1, 1]), math.sqrt(np.trace(C))))
    return np.array(out).T


@pytest.mark.parametrize("system", ["lbl", "usbl"])
def test_the_designs_prediction_with_the_law_is_an_independent_fisher_computation(system):
    """detection.range_k = 0.01 in an LBL design (and a USBL's: the key accepted, its scenario's
    acoustics.range_k set): the design's scenario carries acoustics.range_k; the search's evaluator and the map's
    DRMS at the work-area points equal a numpy Fisher sum with σ_i² = (σ₀ + k ‖p − b_i‖)² + σ_survey², to 1e-9;
    and they differ from the constant σ₀'s."""
    problem = check_problem(problem_with(FIELD, candidates={"systems": [system]}))
    resolved = resolve(problem, "semicircle")
    assert resolved.plan["acoustics"]["range_k"] == 0.01 and "acoustics.range_k=0.01" in resolved.items
    assert resolved.plan["receiver"]["range_k"] == 0.01
    if system != "lbl":
        return
    n = 4
    angle = 2.0 * np.pi * np.arange(n) / n + 0.2
    beacons = np.column_stack([55.0 * np.cos(angle), 50.0 * np.sin(angle), np.full(n, 20.0)])
    plan = plan_of(resolved, layout_items("lbl", n, beacons))
    sigma0, survey = plan["acoustics"]["sigma_range"], plan["platform"]["survey_sigma"]
    points = resolved.points
    d = np.linalg.norm(points[:, None, :] - beacons[None], axis=-1)
    variance = (sigma0 + 0.01 * d) ** 2 + survey ** 2
    depth_variance = plan["target"]["depth_sigma"] ** 2
    horizontal, total = _numpy_drms(points, beacons, variance, depth_variance)
    values = LayoutEvaluator(points, Levels.of(plan), compiled=False).evaluate(beacons[None])
    mapped = point_accuracy(plan, points)
    for drms, drms_3d in ((values["drms"][0], values["drms_3d"][0]), (mapped["drms"], mapped["drms_3d"])):
        np.testing.assert_allclose(drms, horizontal, rtol=1e-9)
        np.testing.assert_allclose(drms_3d, total, rtol=1e-9)
    constant = _numpy_drms(points, beacons, np.full_like(d, sigma0 ** 2 + survey ** 2), depth_variance)[0]
    assert np.all(horizontal > 1.5 * constant)


@pytest.mark.slow
def test_an_lbl_design_with_the_law_is_confirmed_by_its_monte_carlo(tmp_path):
    """The built-in lbl-field-2km problem's LBL with detection.range_k = 0.0005 (σ grows by 0.5 mm per metre over
    ranges of up to ~3 km at an SNR site) and 1 m at 95 %: the design meets, its scenario carries the law, and
    its Monte Carlo (the static runs at the worst and the median point) gives simulated / predicted DRMS in
    [0.85, 1.15]; the same problem without the law predicts smaller figures (the law is in the prediction)."""
    import sblsim

    problem = problem_with(read_problem("lbl-field-2km"), candidates={"systems": ["lbl"]},
                           detection={"range_k": 0.0005}, prescription={"drms_m": 1.0}, work_area={"points": 11},
                           search={"seed": 1, "generations": 10}, monte_carlo={"path": False, "replicates": 20})
    result = sblsim.design(None, **problem, out=tmp_path / "law")
    best = result.designs[0]
    assert best["meets"]
    assert "range_k = 0.0005" in (tmp_path / "law" / f"{best['name']}.toml").read_text()
    rows = {row["point"]: row for row in best["monte_carlo"]}
    assert set(rows) == {"worst", "median"}
    assert all(0.85 <= row["ratio"] <= 1.15 for row in rows.values()), best["monte_carlo"]
    constant = sblsim.design(None, **problem_with(problem, detection={"range_k": 0.0}), out=tmp_path / "constant")
    assert best["predicted"]["drms_p95_m"] > 2.0 * constant.designs[0]["predicted"]["drms_p95_m"]


# --------------------------------------------------------------------------- the bound and the budget

def test_a_run_with_the_law_has_a_larger_bound_and_its_budget_switches_the_law_off():
    """The PCRB takes the law (each range's variance at its true length, the compiled metrics pass): a run with
    acoustics.range_k > 0 has a finite bound above the constant noise's on the same runs; the budget's range_noise
    source switches the law off with σ₀ (what it costs is the white range noise's)."""
    items = ["simulation.duration=30"]
    law = run_batch(with_replicates(load_config("semicircle", items + ["acoustics.range_k=0.01"], seed=1),
                                    range(2))).metrics
    constant = run_batch(with_replicates(load_config("semicircle", items, seed=1), range(2))).metrics
    assert np.all(np.isfinite(law["pcrb_rms"])) and np.all(law["pcrb_rms"] > 1.2 * constant["pcrb_rms"])
    assert np.all(np.isfinite(law["e_tot_rms"]))
    cfg = load_config("semicircle", ["acoustics.range_k=0.01"], seed=1)
    off = switched_off(cfg, SOURCES["range_noise"][1])
    assert off["acoustics"]["sigma_range"] == 0.0 and off["acoustics"]["range_k"] == 0.0
    assert off["receiver"] == cfg["receiver"] and off["receiver"]["range_k"] == 0.01


def test_the_usbl_map_with_the_law_is_the_constant_map_at_the_laws_sigma_of_each_point():
    """A USBL's one packet: the map with acoustics.range_k = 0.002 at a point p equals the map of the constant
    σ = σ₀ + k ‖p − transceiver‖ there (σ₀ 0.2 m; fixed detection), to 1e-12, at two points of different slant
    ranges, and is larger than the constant σ₀'s."""
    base = ["acoustics.detection=fixed", "acoustics.propagation=straight"]
    plan = as_plan(load_config("usbl-deep", base + ["acoustics.range_k=0.002"], seed=1))
    points = np.array([[300.0, 0.0, 100.0], [900.0, 400.0, 600.0]])
    mapped = point_accuracy(plan, points)["drms"]
    transceiver = plan.lever_arms[0]
    for k, p in enumerate(points):
        sigma = float(0.2 + 0.002 * np.linalg.norm(p - transceiver))
        constant = as_plan(load_config("usbl-deep", base + [f"acoustics.sigma_range={sigma!r}"], seed=1))
        assert math.isclose(mapped[k], point_accuracy(constant, p[None])["drms"][0], rel_tol=1e-12)
    plain = point_accuracy(as_plan(load_config("usbl-deep", base, seed=1)), points)["drms"]
    assert np.all(mapped > plain)


@pytest.mark.slow
def test_the_fmus_carry_the_law_as_the_local_engine_does():
    """The FMUs generated from the same declarations: a run with acoustics.range_k = 0.01 on the fmu engine gives
    the local engine's metrics (the channel's draws and the receiver's R alike), and they differ from k = 0's."""
    items = ["simulation.duration=20", "simulation.receiver=ekf-seq"]
    cfg = load_config("semicircle", items + ["acoustics.range_k=0.01"], seed=2)
    local, fmu = run(cfg).metrics, run(cfg, engine="fmu").metrics
    for key in ("e_tot_rms", "nees_mean", "nis_mean"):
        np.testing.assert_allclose(fmu[key], local[key], rtol=1e-9)
    constant = run(load_config("semicircle", items, seed=2)).metrics
    assert not np.isclose(constant["e_tot_rms"][0], local["e_tot_rms"][0], rtol=1e-3)


@pytest.mark.slow
def test_sblsim_run_with_the_law_prints_its_bound(tmp_path, capsys):
    """``sblsim run`` with acoustics.range_k > 0: the PCRB printed and in summary.json (a number), the NEES as
    ever (exit 0)."""
    code = main(["run", "semicircle", "--set", "acoustics.range_k=0.01", "--set", "simulation.duration=20",
                 "--out", str(tmp_path / "run")])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "PCRB RMS n/a" not in captured.out and "NEES" in captured.out
    assert isinstance(json.loads((tmp_path / "run" / "summary.json").read_text())["pcrb_rms"], float)
