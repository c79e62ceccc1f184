"""A telemetry design's receivers only on given mooring lines (``site.area.lines``): every place and every designed
receiver on a line (by an independent point-to-segment distance) and in the water (by an independent ray casting);
a line that leaves the water refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

import sblsim
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.design.problem import check_problem
from tests.helpers import problem_with
from tests.orchestrator.test_design_telemetry import L_LAKE, _inside  # even-odd ray casting
from tests.orchestrator.test_design_telemetry import SMALL as TELEMETRY_SMALL

#: Three mooring lines: along the West arm, across the corner, down the South arm (a bend in the second).
LINES = "20 20; 20 280 | 130 280; 130 130; 280 130 | 280 20; 60 20"
#: The small L-shaped lake of tests/orchestrator/test_design_telemetry.py (its North-East quarter is land) with them.
SMALL = problem_with(TELEMETRY_SMALL, **{"site.area": {"polygon": L_LAKE, "lines": LINES}})


def _problem(**changes):
    return problem_with(SMALL, **changes)


def _vertices(text: str) -> np.ndarray:
    return np.array([[float(v) for v in r.split()] for r in text.split(";")])


def _line_distance(points: np.ndarray) -> np.ndarray:
    """Each point's distance to the nearest segment of :data:`LINES` [m] (projection clipped to the segment)."""
    best = np.full(len(points), np.inf)
    for line in LINES.split("|"):
        v = _vertices(line)
        for a, b in zip(v[:-1], v[1:]):
            t = np.clip((points - a) @ (b - a) / np.dot(b - a, b - a), 0.0, 1.0)
            best = np.minimum(best, np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1))
    return best


def test_the_places_are_points_along_the_lines_in_the_water():
    """Every place a receiver may go lies on a line (< 1 mm) and in the water; the places run the lines' length at
    the grid's step (the lines' 780 m over the step, about one place each, both ends of each line included)."""
    from sblsim.orchestrator.design.telemetry import resolve

    problem = resolve(check_problem(_problem()))
    sites = problem.sites
    assert (_line_distance(sites) < 1e-3).all()
    assert _inside(_vertices(L_LAKE), sites).all()
    step = np.sqrt(problem.water.area / 4000)
    assert abs(len(sites) - (780.0 / step + 3)) <= 3, (len(sites), step)
    ends = np.array([[20, 20], [20, 280], [130, 280], [280, 130], [280, 20], [60, 20]], float)
    assert all(np.min(np.linalg.norm(sites - e, axis=1)) < 1e-6 for e in ends)


@pytest.mark.parametrize("lines, message", [
    ("20 20; 20 280 | 100 100; 250 250", r"^site.area.lines\[1\]: the line leaves the water"),
    ("20 20; 20 280 | -10 20; 20 20", r"^site.area.lines\[1\]: the line leaves the water"),
    ("20 20", r"^site.area.lines\[0\]: '20 20'; allowed 2 to 200 vertices"),
    ("20 20; 20 x", r"^site.area.lines\[0\]: .*allowed 2 to 200 vertices"),
    ("20 20; 20 20", r"^site.area.lines\[0\]: the line has no length"),
    ("20 20; 20 40", r"^site.area.lines: \d+ places .* fewer than candidates.receivers' most \(7\)"),
])
def test_a_bad_mooring_line_is_refused_in_one_line(lines, message):
    with pytest.raises(ConfigError, match=message) as error:
        sblsim.design(None, **_problem(**{"site.area": {"polygon": L_LAKE, "lines": lines}}))
    assert "\n" not in str(error.value)


@pytest.mark.slow
def test_every_receiver_of_a_design_on_lines_lies_on_a_line_in_the_water():
    result = sblsim.design(None, **_problem())
    for design in result.designs:
        receivers = np.array(design["receivers_m"])
        assert (_line_distance(receivers) < 1e-3).all(), receivers
        assert _inside(_vertices(L_LAKE), receivers).all()
    assert result.designs[0]["meets"]
