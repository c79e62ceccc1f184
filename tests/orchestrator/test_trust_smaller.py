"""Smaller items of "Trust v6": ``sblsim.map`` (the command's name; ``accuracy_map`` kept), a number given to the API
as text as the command line takes it, a compared system that places its transducers where the scenario's does keeps
the scenario's layout, an SBL arm at the bound it is best at, and the design's layout figure at every depth."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.design.search import optimise_baseline


def test_map_is_the_command_s_function_and_gives_the_command_s_numbers(tmp_path):
    assert sblsim.map is sblsim.accuracy_map and "map" in sblsim.__all__ and "accuracy_map" in sblsim.__all__
    result = sblsim.map("semicircle", extent=6.0, step=3.0)
    assert main(["map", "semicircle", "--extent", "6", "--step", "3", "--out", str(tmp_path / "m")]) == 0
    written = pd.read_csv(tmp_path / "m" / "map.csv")
    np.testing.assert_allclose(result.table["drms"].to_numpy(), written["drms"].to_numpy(), rtol=1e-12, atol=0)


#: Texts the command line reads as numbers, each given to a key declared as a number.
TEXTS = {"target.depth": "7.5", "simulation.duration": "6", "platform.baseline": " 2.5e0 ",
         "receiver.sigma_range": "0.2"}


def test_a_number_given_as_text_is_the_number_the_command_line_reads():
    from_text = sblsim.load("semicircle", set=TEXTS)
    from_cli = load_config("semicircle", [f"{k}={v.strip()}" for k, v in TEXTS.items()])  # what --set reads
    for key in TEXTS:
        section, name = key.split(".")
        assert from_text[section][name] == from_cli[section][name] == float(TEXTS[key])
    # a text that is no number, or a number given to a choice, is still refused as before
    with pytest.raises(sblsim.SblsimError, match="target.depth"):
        sblsim.load("semicircle", set={"target.depth": "deep"})
    with pytest.raises(sblsim.SblsimError, match="platform.layout"):
        sblsim.load("semicircle", set={"platform.layout": "3"})


@pytest.mark.slow
def test_a_run_given_numbers_as_text_is_the_run_given_the_numbers():
    ran = sblsim.run("semicircle", set={"simulation.duration": "3", "target.depth": "7.5"})
    same = sblsim.run("semicircle", set={"simulation.duration": 3.0, "target.depth": 7.5})
    np.testing.assert_array_equal(ran.timeseries["est_x"].to_numpy(), same.timeseries["est_x"].to_numpy())


def test_the_inverted_lbl_compared_on_an_lbl_site_keeps_its_layout():
    """``map --compare platform.system=lbl,ilbl`` at lbl-field: both on the site's 250 m circle (not ilbl's 50 m
    default), the ilbl panel the map of the site with ilbl set by hand."""
    compared = sblsim.map("lbl-field", compare=("platform.system", ["lbl", "ilbl"]), extent=400.0, step=200.0)
    site = sblsim.load("lbl-field")["platform"]
    for cfg in compared.configs:
        for key in ("layout", "beacons", "baseline"):
            assert cfg["platform"][key] == site[key], (cfg["platform"]["system"], key)
    by_hand = sblsim.map("lbl-field", set={"platform.system": "ilbl", "simulation.receiver": "ekf-seq"}, extent=400.0,
                         step=200.0)
    np.testing.assert_allclose(compared.maps[1], by_hand.maps[0], rtol=1e-12, atol=0)


class _Arm:
    """A criterion of the arm alone (the East of the first beacon, which lies on the East axis at 1 m): ``shape``
    of the arm [m]."""

    def __init__(self, shape):
        self.shape = shape

    def values(self, layouts):
        return self.shape(np.asarray(layouts)[:, 0, 1])


UNIT = np.array([[0.0, 1.0, 0.5], [1.0, 0.0, 0.5], [0.0, -1.0, 0.5], [-1.0, 0.0, 0.5]])


def test_an_sbl_arm_at_the_bound_it_is_best_at_is_the_bound():
    longer = optimise_baseline(_Arm(lambda arm: 1.0 / arm), UNIT, 0.4, 10.0)
    assert longer.variables[0] == 10.0 and longer.layout[0, 1] == 10.0 and longer.value == 0.1
    shorter = optimise_baseline(_Arm(lambda arm: arm), UNIT, 0.4, 10.0)
    assert shorter.variables[0] == 0.4
    inside = optimise_baseline(_Arm(lambda arm: (np.log(arm) - np.log(2.0)) ** 2), UNIT, 0.4, 10.0)
    assert inside.variables[0] == pytest.approx(2.0, rel=0.05)  # an optimum inside stays the search's


@pytest.mark.slow
def test_the_design_figure_draws_every_depth_and_its_labels_inside_the_panels():
    """Two work-area depths: a row of panels each (each titled with its depth), every Monte Carlo label within its
    panel; the SBL's arm at its 10 m bound."""
    result = sblsim.design(None, workers=1, design={"name": "small", "scenario": "semicircle"},
                           work_area={"radius_m": 30.0, "depths_m": [5.0, 12.0], "points": 7},
                           prescription={"drms_m": 0.12, "coverage_pct": 90.0},
                           candidates={"systems": ["lbl", "sbl"], "transponders": [3, 3],
                                       "sbl_baseline_m": [0.4, 10.0]},
                           seafloor={"radius_m": 60.0, "depth_m": 20.0}, search={"seed": 4, "generations": 10},
                           monte_carlo={"replicates": 10, "path": False})
    assert [d["baseline_m"] for d in result.designs if d["system"] == "sbl"] == [10.0]
    figure = result.plot()["layout"]
    panels = [ax for ax in figure.axes if ax.get_title()]
    assert len(panels) == 2 * len(result.designs)
    depths = [ax.get_title().rsplit("vehicle at ", 1)[1] for ax in panels]
    assert sorted(set(depths)) == ["12 m", "5 m"] and depths.count("12 m") == len(result.designs)
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    labels = 0
    for ax in panels:
        box = ax.get_window_extent(renderer)
        for text in ax.texts:
            if "MC/map" in text.get_text():
                labels += 1
                extent = text.get_window_extent(renderer)
                assert box.x0 - 1 <= extent.x0 and extent.x1 <= box.x1 + 1, text.get_text()
    assert labels >= 2
