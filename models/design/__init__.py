"""Designing a positioning system for a site: the criteria a design is judged by, over a work area.

A design (a system, its transducers' places, its hardware grades) is judged by the Fisher information of one
cycle of measurements at the points of a **work area**, the same information as the accuracy map's
(``sblsim map``):

* :mod:`~sblsim.models.design.information`: a layout's Fisher information at a point, each transducer's range
  weighted by the probability that it is heard (:func:`~sblsim.models.design.information.layout_information`),
  one casadi function that the map evaluates and the design's search runs compiled;
* :mod:`~sblsim.models.design.criteria`: the criteria over a work area (D-optimal, A-optimal, worst point,
  percentile), the prescription's coverage, and the closed forms of the optimal geometries that the tests hold
  the search to (Bishop, Fidan, Anderson, Doğançay, Pathirana, "Optimality analysis of sensor-target
  localization geometries", Automatica 46(3):479-492, 2010);
* a telemetry array (receivers hearing a tag, the emission unknown), its own modules, imported by name:
  :mod:`~sblsim.models.design.detection_curve` (a range test's detection range curve),
  :mod:`~sblsim.models.design.telemetry` (the positioning yield, the DRMS of a fix),
  :mod:`~sblsim.models.design.sync_graph` (the sync coverage),
  :mod:`~sblsim.models.design.area` (the study area's polygon) and :mod:`~sblsim.models.design.lake_hald` (a
  layout evaluated over an area; the Lake Hald array's).

No optimiser lives here: the search, the Monte Carlo confirmation and the outputs are the orchestrator's
(``sblsim design``). This package imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from sblsim.models.design.criteria import (
    CRITERIA,
    DIMENSIONS,
    ECHO_LIMIT,
    RING_ELEVATION_DEG,
    RING_RADIUS_RATIO,
    bishop_2d_crb_trace,
    bishop_2d_determinant,
    coverage,
    criterion,
    ring_crb_trace,
    ring_determinant,
)
from sblsim.models.design.information import (
    FAR,
    OUTPUTS,
    SLOTS,
    layout_horizontal_std,
    layout_information,
    layout_values,
    padded,
    slots_for,
)

__all__ = ["CRITERIA", "DIMENSIONS", "ECHO_LIMIT", "FAR", "OUTPUTS", "RING_ELEVATION_DEG", "RING_RADIUS_RATIO", "SLOTS",
           "bishop_2d_crb_trace", "bishop_2d_determinant", "coverage", "criterion", "layout_horizontal_std",
           "layout_information", "layout_values", "padded", "ring_crb_trace", "ring_determinant", "slots_for"]
