"""A design whose work area lies beyond the seafloor region's reach (issue 69: before, a refusal naming
``simulation.duration``, a key the user never set, then a traceback from the polish): the design's longer sampling
time comes with a duration of whole sampling times, and a problem no layout positions says what fails."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sblsim.orchestrator.cosim.plan import load_plan
from sblsim.orchestrator.design.area import Area
from sblsim.orchestrator.design.judgement import shortfalls
from sblsim.orchestrator.design.slot_period import _sampling_items


@pytest.mark.parametrize("period", [3.0, 20.5187, 30.0, 7.0])
def test_a_longer_sampling_time_comes_with_a_whole_number_of_them(period):
    """The scenario's 900 s: kept where it is a whole number of the design's sampling time, else the next whole
    number of them; the plan with those overrides is accepted."""
    plan = load_plan("lbl-field", [])
    items = _sampling_items(plan, period)
    duration = float(plan["simulation"]["duration"])
    if period == plan["simulation"]["sampling_time"]:
        assert items == []
        return
    ratio = duration / period
    if abs(ratio - round(ratio)) < 1e-9 * ratio:
        assert items == [f"simulation.sampling_time={period!r}"]
    else:
        given = float(items[1].split("=")[1])
        assert math.isclose(given, math.ceil(ratio) * period) and duration < given < duration + period
    load_plan("lbl-field", items)  # accepted: no "not a whole number of sampling times"


@pytest.mark.slow
def test_a_work_area_90_km_out_does_not_meet_and_says_why(tmp_path, capsys):
    """LBL transponders within 2.5 km of the centre, the work area 90 km North: exit 0, no traceback, does not meet
    with coverage 0 % and availability named among what fails, design.json strict JSON."""
    from sblsim.orchestrator.cli import main

    problem = tmp_path / "far.toml"
    problem.write_text('[design]\nname = "far"\nscenario = "lbl-field"\n[work_area]\nshape = "circle"\n'
                       'radius_m = 500.0\ncentre_north_m = 90000.0\ndepths_m = [150.0]\npoints = 5\n'
                       '[prescription]\ndrms_m = 0.1\ndimensions = "horizontal"\ncoverage_pct = 95.0\n'
                       'availability_pct = 95.0\n[candidates]\nsystems = ["lbl"]\ntransponders = [3, 4]\n'
                       'transponder_cost = 1.0\nranging = ["wide-band"]\nranging_cost = [0.0]\n'
                       '[seafloor]\nshape = "circle"\nradius_m = 2500.0\n[monte_carlo]\nreplicates = 10\n')
    assert main(["design", str(problem), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "no candidate meets" in out and "coverage 0.0 % of the work area" in out and "availability" in out
    assert "km from the nearest transponder, the seafloor region reaching 2.5 km from its middle" in out, out
    record = json.loads((tmp_path / "o" / "design.json").read_text())
    assert record["meets"] is False and not any(d["meets"] for d in record["designs"])
    assert {"coverage", "availability"} <= {f["part"] for f in record["designs"][0]["fails"]}


def test_a_work_area_no_fix_reaches_says_how_far_it_lies_from_the_transponders():
    """No point with a fix: the DRMS clause names the work area's distance from the nearest transponder (three at
    (0, 0), (1, 0), (0, 1) km; the nearest point (89.5, 0.2) km: 88.50023 km by hand) and the seafloor region's
    reach (a circle of 2.5 km round (0, 0)); a point with a fix: no such clause."""
    from types import SimpleNamespace

    design = SimpleNamespace(values={"echo": np.zeros(2), "availability": np.zeros(2)}, feasible=True, coverage=0.0,
                             cycle=1.0, transponders=np.array([[0.0, 0.0, 150.0], [1000.0, 0.0, 150.0],
                                                               [0.0, 1000.0, 150.0]]))
    points = np.array([[89500.0, 200.0, 100.0], [90500.0, 0.0, 100.0]])
    prescription = {"coverage_pct": 95.0, "drms_m": 0.1, "availability_pct": 95.0, "update_interval_s": 0.0}
    found, _ = shortfalls(design, np.full(2, np.inf), prescription, points, Area(radius=2500.0))
    (drms,) = [f["text"] for f in found if f["part"] == "drms"]
    gap = math.hypot(89500.0 - 1000.0, 200.0) / 1000.0
    assert f"nearest point {gap:.3g} km from the nearest transponder" in drms and "reaching 2.5 km" in drms, drms
    found, _ = shortfalls(design, np.array([np.inf, 5.0]), prescription, points, Area(radius=2500.0))
    assert not any("nearest transponder" in f["text"] for f in found), found
