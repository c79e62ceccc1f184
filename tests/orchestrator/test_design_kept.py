"""``sblsim design`` with devices already in place (``candidates.existing_m``) and a footprint
(``candidates.footprint_m``), for an LBL's seafloor transponders and an ilbl array's receivers.

* The devices in place are in every layout searched, exactly where they were given, first; no count below theirs is
  searched; the cost is that of the devices added alone (checked against the count by hand); ``design.json`` marks
  them; the written scenario, which the Monte Carlo runs, holds them.
* The design's accuracy with them is an independent numpy Fisher computation (an LBL's map with the depth sensor; an
  ilbl array's averaged information with the emission time unknown) to 1e-9, and the one transponder added to two in
  place is no worse than a brute force over its place on a 2 m grid.
* Every pair of the proposed devices lies within the footprint (scipy's ``pdist``), and a layout beyond it fails
  with the part ``footprint``.
* The refusals: one line through ``sblsim design``, exit status 2, nothing written.
"""

from __future__ import annotations

import numpy as np
import pytest
import tomli_w
from scipy.spatial.distance import pdist

import sblsim
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.design.evaluate import LayoutEvaluator, Levels
from sblsim.orchestrator.design.judgement import shortfalls
from sblsim.orchestrator.design.problem import check_problem
from sblsim.orchestrator.design.resolution import plan_of, resolve
from sblsim.orchestrator.design.search import Objective
from tests.helpers import problem_with as _with

#: Two LBL transponders in place on a 20 m deep floor, a 30 m work area (the paper's fixed channel).
IN_PLACE = np.array([[40.0, 0.0, 20.0], [-20.0, 34.6, 20.0]])
LBL = {
    "design": {"name": "kept", "scenario": "semicircle"},
    "work_area": {"radius_m": 30.0, "depths_m": [5.0], "points": 9},
    "prescription": {"drms_m": 0.12, "coverage_pct": 90.0},
    "candidates": {"systems": ["lbl"], "transponders": [3, 5], "transponder_cost": 1.5,
                   "existing_m": "40 0; -20 34.6"},
    "seafloor": {"radius_m": 60.0, "depth_m": 20.0},
    "search": {"seed": 4, "generations": 10},
    "monte_carlo": {"replicates": 10, "path": False},
}
#: A small lake (an L, 300 m) with five receivers moored already.
L_LAKE = "0 0; 0 300; 150 300; 150 150; 300 150; 300 0"
MOORED = np.array([[20.0, 20.0], [280.0, 20.0], [20.0, 280.0], [130.0, 130.0], [75.0, 75.0]])
ILBL = {
    "design": {"name": "pond"},
    "site": {"area": {"polygon": L_LAKE}},
    "detection": {"range_50_m": 350.0, "slope": 0.02, "sync_p": 0.5, "sigma_toa_s": 1e-4, "sound_speed": 1480.0},
    "work_area": {"shape": "site", "points": 8},
    "prescription": {"drms_m": 2.0, "coverage_pct": 90.0, "positioning_yield_pct": 80.0},
    "candidates": {"systems": ["ilbl"], "receivers": [3, 7], "receiver_cost": 2.0, "sync_tag_cost": 0.5,
                   "existing_m": "; ".join(f"{n:g} {e:g}" for n, e in MOORED)},
    "search": {"generations": 6, "seed": 3},
    "monte_carlo": {"replicates": 10, "path": False},
}



@pytest.fixture(scope="module")
def lbl(tmp_path_factory):
    return sblsim.design(None, **LBL, out=tmp_path_factory.mktemp("kept") / "lbl")


@pytest.fixture(scope="module")
def ilbl(tmp_path_factory):
    return sblsim.design(None, **ILBL, out=tmp_path_factory.mktemp("kept") / "ilbl")


@pytest.mark.slow
def test_an_lbl_design_keeps_the_transponders_in_place_and_pays_only_for_those_added(lbl):
    """Every LBL layout searched holds the two transponders in place first, exactly; the counts start at 3 (the
    fewest allowed, above the two in place); each cost is 1.5 per transponder added; design.json marks the two, and
    the written scenario (which the Monte Carlo runs) places them."""
    searched = lbl.run.searched
    assert searched and min(d.candidate.count for d in searched) == 3
    for d in searched:
        np.testing.assert_array_equal(d.transponders[:2], IN_PLACE)
        assert d.candidate.cost == pytest.approx(1.5 * (len(d.transponders) - 2), abs=1e-12)
    for record in lbl.designs:
        n = len(record["transponders_m"])
        assert record["existing"] == [True, True] + [False] * (n - 2)
        assert record["transponders_m"][:2] == [[0.0, 40.0, 20.0], [34.6, -20.0, 20.0]]  # East, North, depth
        assert record["cost"] == pytest.approx(1.5 * (n - 2), abs=1e-12)
        cfg = load_config(str(lbl.out / record["scenario"]))
        offsets = np.array([[float(x) for x in row.split()] for row in cfg["platform"]["beacon_offsets"].split(";")])
        np.testing.assert_allclose(offsets[:2], IN_PLACE, rtol=0, atol=1e-12)
        assert record["monte_carlo"]


def test_the_lbl_design_s_map_is_an_independent_fisher_computation_with_the_transponders_in_place(lbl):
    """At every work-area point, the proposed design's DRMS (the map's) is sqrt of the North and East variances of
    J = Σ g gᵀ/σ² + e_z e_zᵀ/σ_d² over the transponders in place and added, inverted by numpy, to 1e-9."""
    best = lbl.run.best
    levels = Levels.of(plan_of(lbl.run.resolved, best.items))
    for j, p in enumerate(lbl.run.resolved.points):
        g = (p - best.transponders) / np.linalg.norm(p - best.transponders, axis=1)[:, None]
        J = g.T @ g / levels.noise_variance + np.diag([0.0, 0.0, 1.0 / levels.depth_variance])
        cov = np.linalg.inv(J)
        assert best.values["drms"][j] == pytest.approx(np.sqrt(cov[0, 0] + cov[1, 1]), rel=1e-9)


def test_a_transponder_in_place_keeps_its_own_depth_on_the_paper_s_fixed_channel():
    """A depth given (18 m, the floor 20 m) is kept: the layout holds it, and the map's DRMS is the numpy Fisher
    computation of that layout (the fixed channel hears every packet wherever the transponder is)."""
    result = sblsim.design(None, **_with(LBL, candidates={"existing_m": "40 0 18; -20 34.6", "transponders": [3, 3]},
                                         search={"generations": 5}))
    best = result.run.best
    np.testing.assert_array_equal(best.transponders[:2], [[40.0, 0.0, 18.0], [-20.0, 34.6, 20.0]])
    levels = Levels.of(plan_of(result.run.resolved, best.items))
    for j, p in enumerate(result.run.resolved.points):
        g = (p - best.transponders) / np.linalg.norm(p - best.transponders, axis=1)[:, None]
        cov = np.linalg.inv(g.T @ g / levels.noise_variance + np.diag([0.0, 0.0, 1.0 / levels.depth_variance]))
        assert best.values["drms"][j] == pytest.approx(np.sqrt(cov[0, 0] + cov[1, 1]), rel=1e-9)


def test_the_transponder_added_to_two_in_place_is_no_worse_than_a_brute_force_over_its_place():
    """Three transponders, two in place: the search's one added transponder gives a criterion (A-optimal, the
    search's own) no worse than the best of every place of a 2 m grid over the seafloor region."""
    problem = _with(LBL, candidates={"transponders": [3, 3]}, search={"criterion": "a-optimal"})
    r = resolve(check_problem(problem), "semicircle")
    from sblsim.orchestrator.design.candidates import candidates
    from sblsim.orchestrator.design.searcher import Searcher

    (candidate,) = candidates(r)
    design = Searcher(r).search(candidate)
    np.testing.assert_array_equal(design.transponders[:2], IN_PLACE)
    objective = Objective(LayoutEvaluator(r.points, Levels.of(plan_of(r, design.items))), "a-optimal",
                          coverage_pct=90.0)
    axis = np.arange(-60.0, 60.0 + 1e-9, 2.0)
    n, e = (a.ravel() for a in np.meshgrid(axis, axis, indexing="ij"))
    inside = np.hypot(n, e) <= 60.0
    layouts = np.stack([np.vstack([IN_PLACE, [a, b, 20.0]]) for a, b in zip(n[inside], e[inside])])
    values = objective.values(layouts)
    assert objective.values(design.transponders[None])[0] <= values.min() * (1.0 + 1e-6)


def test_an_ilbl_design_keeps_the_receivers_in_place_and_pays_only_for_those_added(ilbl):
    """Five receivers in place, counts of 3 to 7 asked: every count searched is at least 5, every layout holds the
    five first, exactly, the cost is 2.5 per receiver added (a receiver and its sync tag); design.json marks them."""
    searched = ilbl.run.searched
    assert searched and min(d.count for d in searched) >= 5
    for d in searched:
        np.testing.assert_array_equal(d.receivers[:5], MOORED)
        assert d.cost == pytest.approx(2.5 * (len(d.receivers) - 5), abs=1e-12)
    for record in ilbl.designs:
        n = len(record["receivers_m"])
        assert record["existing"] == [True] * 5 + [False] * (n - 5)
        assert record["receivers_m"][:5] == MOORED.tolist()
        assert record["cost"] == pytest.approx(2.5 * (n - 5), abs=1e-12)


def test_the_ilbl_design_s_information_is_an_independent_fisher_computation_with_the_receivers_in_place(ilbl):
    """The averaged information's DRMS at every work-area point is the full 3 × 3 Fisher information of (North,
    East, c t_e), each receiver weighted by its detection probability (the logistic curve by hand), inverted by
    numpy, over the receivers in place and added, to 1e-9."""
    best = ilbl.run.best
    sigma = 1480.0 * 1e-4
    for j, point in enumerate(ilbl.run.resolved.points):
        d = point - best.receivers
        r = np.linalg.norm(d, axis=1)
        q = 1.0 / (1.0 + np.exp(0.02 * (r - 350.0)))
        H = np.column_stack([d / r[:, None], np.ones(len(r))])
        cov = np.linalg.inv((H * (q / sigma**2)[:, None]).T @ H)
        assert best.drms_expected[j] == pytest.approx(np.sqrt(cov[0, 0] + cov[1, 1]), rel=1e-9)


@pytest.mark.slow
def test_every_pair_of_an_lbl_design_s_transponders_is_within_the_footprint():
    """A footprint of 80 m (four transponders free in a 60 m circle spread wider): every layout searched that does
    not fail for its footprint has every pair within it (pdist), the proposed one included; the same layout judged
    against half its own spread fails with the part ``footprint``, its achieved spread pdist's."""
    problem = _with(LBL, candidates={"existing_m": "", "footprint_m": 80.0, "transponders": [3, 4]})
    result = sblsim.design(None, **problem)
    for d in result.run.searched:
        spread = pdist(d.transponders[:, :2]).max()
        assert spread <= 80.0 + 1e-6 or "footprint" in [s["part"] for s in d.shortfalls]
    best = result.run.best
    assert best.meets and pdist(best.transponders[:, :2]).max() <= 80.0 + 1e-6
    assert result.designs[0]["spread_m"] == pytest.approx(pdist(best.transponders[:, :2]).max(), rel=1e-12)
    wide = pdist(best.transponders[:, :2]).max()
    fails, _ = shortfalls(best, best.values["drms"], result.run.resolved.sections["prescription"],
                          footprint=0.5 * wide)
    (part,) = [f for f in fails if f["part"] == "footprint"]
    assert part["achieved"] == pytest.approx(wide, rel=1e-12) and part["required"] == 0.5 * wide


def test_every_pair_of_an_ilbl_design_s_receivers_is_within_the_footprint():
    """Two receivers in place 110 m apart and a footprint of 200 m on the 300 m lake: every proposed receiver pair
    within it (pdist), the two in place kept."""
    problem = _with(ILBL, candidates={"existing_m": "20 20; 130 20", "footprint_m": 200.0, "receivers": [4, 6]})
    result = sblsim.design(None, **problem)
    for d in result.run.searched:
        np.testing.assert_array_equal(d.receivers[:2], [[20.0, 20.0], [130.0, 20.0]])
        assert pdist(d.receivers).max() <= 200.0 + 1e-6 or "footprint" in [s["part"] for s in d.shortfalls]
    for record in result.designs:
        assert pdist(np.array(record["receivers_m"])).max() <= 200.0 + 1e-6
        assert record["spread_m"] == pytest.approx(pdist(np.array(record["receivers_m"])).max(), rel=1e-12)


@pytest.mark.parametrize("problem, key, words", [
    (_with(LBL, candidates={"existing_m": "70 0"}), "candidates.existing_m", "outside the seafloor region"),
    (_with(LBL, seafloor={"avoid": ["30 -10; 30 10; 50 10; 50 -10"]}), "candidates.existing_m",
     "inside an area to avoid"),
    (_with(LBL, candidates={"existing_m": "0 0; 10 0; 20 0; 30 0; 40 0; 50 0"}), "candidates.existing_m",
     "more than the most"),
    (_with(LBL, candidates={"footprint_m": 60.0}), "candidates.footprint_m", "below the existing devices' own spread"),
    (_with(LBL, candidates={"existing_m": "0 0; 10 0", "footprint_m": 10.0},  # the lens of the two discs avoided
           seafloor={"avoid": ["0 0; -1 -5; 5 -10; 11 -5; 10 0; 11 5; 5 10; -1 5"]}), "candidates.footprint_m",
     "leaves no place"),
    (_with(ILBL, candidates={"existing_m": "20 20", "footprint_m": 4.5}), "candidates.footprint_m",
     "fewer than the 6 to add"),
    (_with(LBL, candidates={"systems": ["sbl", "usbl"]}), "candidates.existing_m", "place no device"),
    (_with(LBL, candidates={"systems": ["usbl"], "existing_m": "", "footprint_m": 5.0}), "candidates.footprint_m",
     "place no device"),
    (_with(LBL, candidates={"existing_m": "40 0 3"}), "candidates.existing_m", "below the deepest vehicle"),
    (_with(LBL, design={"scenario": "lbl-field"}, work_area={"radius_m": 500.0, "depths_m": [150.0]},
           seafloor={"depth_m": 0.0}, candidates={"existing_m": "40 0 250"}), "candidates.existing_m",
     "allowed the seafloor's, 299 m"),
    (_with(ILBL, candidates={"existing_m": "200 200"}), "candidates.existing_m", "outside the water"),
    (_with(ILBL, candidates={"existing_m": "20 20 4"}), "candidates.existing_m", "in the plane"),
    (_with(ILBL, candidates={"existing_m": "", "footprint_m": 1.0}), "candidates.footprint_m",
     "no two receivers can be placed"),
    (_with(ILBL, candidates={"existing_m": "20 20; 20 20.0000001"}), "candidates.existing_m", "one place"),
])
def test_a_kept_device_or_footprint_that_cannot_be_is_refused_in_one_line(problem, key, words, tmp_path, capsys):
    """Through ``sblsim design``: one line naming the key, exit status 2, nothing written."""
    path = tmp_path / "problem.toml"
    path.write_text(tomli_w.dumps(problem))
    assert main(["design", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"sblsim: error: {key}: ") and words in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "o").exists()
