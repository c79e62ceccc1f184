"""``sblsim map``: where the system meets an accuracy prescription.

For a configuration, the horizontal standard deviation (DRMS) of a position
fix from one round of fresh ranges (one per beacon) plus the depth, from
their Fisher information ``Σ_k H_kᵀ H_k / r_k`` over the rows of the
measurement model (:func:`sblsim.models.fisher.fisher_information`, H from the
model's casadi Jacobian; the model is the receivers' ranges-plus-depth
:class:`~sblsim.models.receiver.measurement.RangeDepthModel`, given to
:func:`sblsim.models.fisher.horizontal_std` as an object), on a
grid around the platform at the diver's depth: the platform level at its
mean heading, its reference at the origin, the beacons at their lever arms,
with the configured range noise, GPS, IMU and depth-sensor errors
(:func:`sblsim.orchestrator.cosim.plan.bound_parameters`). It is the accuracy of one
round of ranges without a motion model (a filter does better by averaging;
the PCRB of a run says how much), and it is the design question of the
paper: which baseline and sensors keep the diver within a required accuracy
over the working area.

The systems (``platform.system``): LBL maps the same way, the beacons the
seafloor transponders (their positions, :func:`~sblsim.models.platform.geometry.lever_arms`),
with the survey error in place of the GPS and no attitude term
(:func:`~sblsim.orchestrator.cosim.plan.bound_parameters`). USBL maps one packet
of slant range, azimuth and elevation from the transceiver plus the depth
(:func:`sblsim.models.systems.usbl_map.horizontal_std`), with the receivers' R:
``σ_r²`` for the range, ``σ_a² = (σ_θ / max(cos φ, 0.1))² + σ_att²`` for each
angle (φ the line of sight's angle off the vertical), plus the transceiver
position's error ``σ_b² = σ_GPS² + (σ_att h)²`` per axis along the range and
across both angles; computed from the packet's polar-fix covariance
``J diag(σ_r², σ_a², σ_a²) Jᵀ + σ_b² I``, finite everywhere (straight below the
transceiver too) and never below ``√2 σ_b``. What no receiver's R holds is not
in a map either (the USBL array's misalignment, the TWTT turnaround jitter). ``--compare
platform.system=sbl,lbl,usbl`` maps each system from the defaults of
``sblsim compare --systems`` (each system object's
:attr:`~sblsim.models.systems.System.compare_defaults`), the user's ``--set`` over them. Each
system's map is its object's :meth:`~sblsim.models.systems.System.horizontal_std`.

The work is one module per job, read bottom up: the grid and the diver's depth
(:mod:`~sblsim.orchestrator.maps.map_grid`), what the site lets through (:mod:`~sblsim.orchestrator.maps.detection`),
the offsets of reflected arrivals (:mod:`~sblsim.orchestrator.maps.echoes`), the accuracy at points and on a grid
(:mod:`~sblsim.orchestrator.maps.accuracy`), a command's maps (:mod:`~sblsim.orchestrator.maps.panels`) and their
table, figure and files (:mod:`~sblsim.orchestrator.maps.output`); their names are importable from here.
"""

from __future__ import annotations

from sblsim.orchestrator.maps.accuracy import (
    MIN_AVAILABILITY,
    accuracy_map,
    availability_map,
    point_accuracy,
    site_maps,
)
from sblsim.orchestrator.maps.detection import fix_probability, grown_noise, packet_probabilities
from sblsim.orchestrator.maps.echoes import ECHO_DISTANCES, echo_spread, range_echo_spread
from sblsim.orchestrator.maps.map_grid import (
    MAX_EXTENT,
    MAX_POINTS,
    check_depth,
    diver_depth,
    grid,
    grid_points,
    parse_levels,
)
from sblsim.orchestrator.maps.output import ECHO_ONLY, plot, system_line, table, write
from sblsim.orchestrator.maps.panels import MapConfig, make_maps

__all__ = [
    "accuracy_map", "availability_map", "check_depth", "diver_depth", "ECHO_DISTANCES", "ECHO_ONLY", "echo_spread",
    "fix_probability", "grid", "grid_points", "grown_noise", "make_maps", "MapConfig", "MAX_EXTENT", "MAX_POINTS",
    "MIN_AVAILABILITY", "packet_probabilities", "parse_levels", "plot", "point_accuracy", "range_echo_spread",
    "site_maps", "system_line", "table", "write"
]
