"""A design problem's declared keys: every section's keys as :class:`~sblsim.models.declarations.Variable` records
(:data:`DESIGN_KEYS`: type, default, unit, meaning, range or choices; the docs' table of keys is made from them,
docs/design.md), the systems a design may propose and the hardware grades it chooses among (:data:`GRADES`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sblsim.models.declarations import FileKey, Variable
from sblsim.models.design.criteria import CRITERIA, DIMENSIONS, MAX_ECHO_MARGIN_PCT
from sblsim.models.platform.waves import WAVE_HEIGHT
from sblsim.models.systems import SYSTEMS
from sblsim.models.tracking.schedule import PING_TYPES
from sblsim.orchestrator.cosim.config import BUILTIN_SCENARIOS

#: The systems a design may propose (the registry's that it can search: :attr:`~sblsim.models.systems.System.designed`),
#: in the order they are searched.
SYSTEM_NAMES = tuple(name for name, system in SYSTEMS.items() if system.designed)
#: The system a telemetry array is designed as (receivers hearing a tag: :mod:`~sblsim.orchestrator.design.telemetry`),
#: designed alone.
TELEMETRY = next(name for name, system in SYSTEMS.items() if "toa" in system.ranging)
#: What ``candidates.systems`` accepts.
SYSTEM_CHOICES = (*SYSTEM_NAMES, TELEMETRY)
#: The hardware grades a design chooses among: category -> grade -> (configuration key, value). The figures and
#: their sources: docs/hardware-grades.md ("Grades a design chooses among").
GRADES: dict[str, dict[str, tuple[str, float]]] = {
    "gps": {"standalone": ("platform.gps_sigma", 2.0), "dgps": ("platform.gps_sigma", 0.1),
            "rtk": ("platform.gps_sigma", 0.02)},
    "imu": {"mems": ("platform.imu_sigma_deg", 1.0), "survey": ("platform.imu_sigma_deg", 0.02)},
    "usbl_head": {"low-cost": ("platform.usbl_angle_sigma_deg", 0.5),
                  "survey": ("platform.usbl_angle_sigma_deg", 0.14)},
    "ranging": {"cw": ("acoustics.sigma_range", 0.1), "wide-band": ("acoustics.sigma_range", 0.02)},
}
#: The most vertices of a polygon, areas to avoid, overrides and vehicle depths.
MAX_VERTICES, MAX_AVOID, MAX_SET, MAX_DEPTHS = 200, 50, 200, 10
#: The most receivers of a telemetry array.
MAX_RECEIVERS = 100


@dataclass(frozen=True)
class Key:
    """A declared key of a design problem: its :class:`Variable` (type, default, unit, meaning, range or
    choices of one value) and, for a list, its allowed length ``(low, high)``."""

    variable: Variable
    length: tuple[int, int] | None = None

    @property
    def name(self) -> str:
        return self.variable.name

    @property
    def start(self) -> Any:
        start = self.variable.start
        return list(start) if isinstance(start, (list, tuple)) else start

    def allowed(self) -> str:
        """The allowed values in words (a list: its length and each item's range)."""
        one = self.variable.allowed()
        if self.length is None:
            return one
        low, high = self.length
        count = f"{low}" if low == high else f"{low} to {high}"
        return f"a list of {count} values, each {one}"


def _key(name: str, type_: str, start: Any, unit: str, description: str, length: tuple[int, int] | None = None,
         file: FileKey | None = None, **allowed: Any) -> Key:
    item = start[0] if isinstance(start, list) and start else (start if not isinstance(start, list) else None)
    if item is None:
        item = {"Real": 0.0, "Integer": 0, "String": (allowed.get("choices") or ("",))[0], "Boolean": False}[type_]
    variable = Variable(name, "parameter", type_, start if length else item, unit, description, scope="config",
                        file=file, **allowed)
    return Key(variable, length)


_POSITION = dict(min=-1e5, max=1e5)
_COST = dict(min=0.0, max=1e9)
_GRADE_LIST = (0, 10)
#: Every key of a design problem: section -> its keys (the docs' table,
#: :func:`~sblsim.orchestrator.design.problem.check_problem`, the defaults).
DESIGN_KEYS: dict[str, tuple[Key, ...]] = {
    "design": (
        _key("name", "String", "design", "", "the design's name (its designs' files: NAME-lbl4.toml, NAME-sbl.toml, "
                                             "NAME-usbl.toml)"),
        _key("scenario", "String", "", "", f"the base scenario, its site and error levels: one of "
                                           f"{', '.join(BUILTIN_SCENARIOS)} (a CONFIG.toml: --scenario)"),
        _key("set", "String", [], "", "overrides of the base scenario, 'section.key=value' as --set takes them",
             (0, MAX_SET)),
    ),
    "work_area": (
        _key("shape", "String", "circle", "", "the work area: a circle, a polygon, or the site's water (site.area, "
                                              "an ilbl design)", choices=("circle", "polygon", "site")),
        _key("centre_north_m", "Real", 0.0, "m", "North of the circle's centre", **_POSITION),
        _key("centre_east_m", "Real", 0.0, "m", "East of the circle's centre", **_POSITION),
        _key("radius_m", "Real", 100.0, "m", "the circle's radius", min=0.0, max=1e5, min_exclusive=True),
        _key("polygon", "String", "", "", "the polygon's vertices 'north east; north east; ...' [m]"),
        _key("depths_m", "Real", [], "m", "the vehicle's depths (empty: the scenario's target depth)",
             (0, MAX_DEPTHS), min=0.0, max=11000.0),
        _key("points", "Integer", 21, "", "grid points across the work area's bounding box per axis (21: 441 in "
                                          "the box)", min=3, max=201),
        _key("depth_sensor", "Boolean", True, "", "the vehicle reports its depth (false: no depth sensor, its fix of "
                                                 "the ranges alone; an ilbl design: in 3-D only, with "
                                                 "candidates.receiver_depth_m)"),
    ),
    "prescription": (
        _key("drms_m", "Real", 1.0, "m", "the DRMS to meet", min=0.0, max=1e4, min_exclusive=True),
        _key("dimensions", "String", "horizontal", "", "the DRMS of North and East, or of all three axes",
             choices=DIMENSIONS),
        _key("coverage_pct", "Real", 95.0, "%", "the share of the work area where the DRMS must be met",
             min=0.0, max=100.0, min_exclusive=True),
        _key("availability_pct", "Real", 95.0, "%", "the share of cycles with a fix that those points need",
             min=0.0, max=100.0),
        _key("update_interval_s", "Real", 0.0, "s", "the longest cycle (a fix at least this often; 0: any)",
             min=0.0, max=3600.0),
        _key("positioning_yield_pct", "Real", 80.0, "%", "an ilbl design: the share of a tag's pings heard by "
                                                          "enough receivers to be fixed, at those points",
             min=0.0, max=100.0),
        _key("fix_receivers", "Integer", 3, "", "an ilbl design: the receivers a ping's fix needs (3, the least in "
                                                 "2-D; 4, a redundant fix without three's two solutions)",
             min=3, max=10),
        _key("fix_gate_m", "Real", 0.0, "m", "an ilbl design: a ping's fix counts only where the DRMS of its "
                                            "receivers' geometry is at most this (an HPE filter; 0: every fix)",
             min=0.0, max=1e4),
        _key("echo_margin_pct", "Real", 0.0, "%", "a margin from the echo limit: a point counts only where its fix "
                                                 "takes ranges of reflections in at most 1 % minus this of the cycles",
             min=0.0, max=MAX_ECHO_MARGIN_PCT),
    ),
    "candidates": (
        _key("systems", "String", list(SYSTEM_NAMES), "", "the systems to design (ilbl: a telemetry array, alone)",
             (1, len(SYSTEM_NAMES)), choices=SYSTEM_CHOICES),
        _key("transponders", "Integer", [3, 8], "", "the LBL's fewest and most seafloor transponders", (2, 2),
             min=3, max=16),
        _key("transponder_cost", "Real", 1.0, "1", "the cost of one seafloor transponder", **_COST),
        _key("sbl_cost", "Real", 0.0, "1", "the cost of the SBL platform", **_COST),
        _key("usbl_cost", "Real", 0.0, "1", "the cost of the USBL transceiver", **_COST),
        _key("sbl_baseline_m", "Real", [0.4, 3.0], "m", "the SBL's shortest and longest arm", (2, 2),
             min=0.0, max=1000.0, min_exclusive=True),
        _key("sbl_beacons", "Integer", 4, "", "the SBL's beacons on their circle", min=3, max=16),
        _key("receivers", "Integer", [3, 40], "", "an ilbl array's fewest and most receivers", (2, 2),
             min=3, max=MAX_RECEIVERS),
        _key("receiver_cost", "Real", 1.0, "1", "the cost of one receiver (an ilbl array's)", **_COST),
        _key("sync_tag_cost", "Real", 0.0, "1", "the cost of the sync tag moored at each receiver", **_COST),
        _key("existing_m", "String", "", "", "devices already in place, kept: 'north east [depth]; ...' [m] (an "
                                             "LBL's transponders, depth default seafloor.depth_m; an ilbl array's "
                                             "receivers, 'north east', a depth in 3-D only, default "
                                             "candidates.receiver_depth_m's first); only the devices added are paid "
                                             "for"),
        _key("receiver_depth_m", "Real", [], "m", "an ilbl design: the added receivers' mooring depths, one receiver "
                                                  "each in turn (empty: planar, the receivers and the tag in one "
                                                  "plane; given: 3-D, with work_area.depths_m)", (0, MAX_DEPTHS),
             min=0.0, max=11000.0),
        _key("footprint_m", "Real", 0.0, "m", "the largest distance between any two devices (an LBL's transponders, "
                                              "an ilbl array's receivers; 0: any)", min=0.0, max=1e6),
        *(k for category, grades in GRADES.items() for k in (
            _key(category, "String", [], "", f"the {category.replace('_', ' ')} grades to choose among "
                                              f"(empty: the scenario's)", _GRADE_LIST, choices=tuple(grades)),
            _key(f"{category}_cost", "Real", [], "1", f"the cost of each {category.replace('_', ' ')} grade, in its "
                                                     f"order (empty: free)", _GRADE_LIST, **_COST))),
    ),
    "seafloor": (
        _key("shape", "String", "circle", "", "where LBL transponders may go: a circle or a polygon",
             choices=("circle", "polygon")),
        _key("centre_north_m", "Real", 0.0, "m", "North of the circle's centre", **_POSITION),
        _key("centre_east_m", "Real", 0.0, "m", "East of the circle's centre", **_POSITION),
        _key("radius_m", "Real", 0.0, "m", "the circle's radius (0: the work area's)", min=0.0, max=1e5),
        _key("polygon", "String", "", "", "the polygon's vertices 'north east; north east; ...' [m]"),
        _key("avoid", "String", [], "", "areas no transponder may go, each a polygon 'north east; ...' [m]",
             (0, MAX_AVOID)),
        _key("depth_m", "Real", 0.0, "m", "the transponders' depth (0: an LBL scenario's platform.seafloor_depth, "
                                          "else 1 m above acoustics.water_depth)", min=0.0, max=11000.0),
    ),
    "site.area": (
        _key("polygon", "String", "", "", "an ilbl design: the water, its vertices 'north east; north east; ...' [m] "
                                          "(or site.area.file)"),
        _key("file", "String", "", "", "the water's outline: a CSV of vertices (north_m, east_m) or a GeoJSON "
                                       "polygon [m] (relative: from the design file's folder)", file=FileKey()),
        _key("min_shore_m", "Real", 0.0, "m", "the least distance of a receiver from the shore", min=0.0, max=1e5),
        _key("max_shore_m", "Real", 0.0, "m", "the largest distance of a receiver from the shore (0: any)",
             min=0.0, max=1e5),
        _key("lines", "String", "", "", "receivers only on these mooring lines, each 'north east; north east; ...' "
                                        "[m], the lines apart by a vertical bar (empty: anywhere in the water)"),
        _key("origin", "String", "", "", "where north 0, east 0 is: 'latitude longitude' [°, WGS 84]; the "
                                         "design's receivers.csv then gives each receiver's lat, lon (projected by "
                                         "pyproj in the UTM zone of the origin; empty: no lat, lon)"),
    ),
    "detection": (
        _key("range_50_m", "Real", 0.0, "m", "the distance at which half the pings are heard (with slope; 0: the "
                                            "table)", min=0.0, max=1e5),
        _key("slope", "Real", 0.0, "1", "the logistic curve's steepness at range_50_m [1/m]", min=0.0, max=1e3),
        _key("table", "String", "", "", "the range test's curve 'distance_m probability; ...', non-increasing"),
        _key("sync_p", "Real", 0.5, "1", "the probability per sync ping a sync link needs", min=0.0, max=1.0,
             min_exclusive=True),
        _key("sigma_toa_s", "Real", 1.5e-4, "s", "the timing noise of an arrival", min=0.0, max=1.0,
             min_exclusive=True),
        _key("sound_speed", "Real", 1480.0, "m/s", "the sound speed of the water", min=1000.0, max=2000.0),
        _key("range_k", "Real", 0.0, "1", "the range noise's growth with distance [m/m] (0: constant), every "
                                          "system: an ilbl design's sigma = sound_speed * sigma_toa_s + range_k * "
                                          "distance; lbl, sbl, usbl: the design scenario's acoustics.range_k, "
                                          "sigma = sigma_range + range_k * range",
             min=0.0, max=0.1),
        _key("multipath_pct", "Real", 0.0, "%", "an ilbl design's confirmation: the share of heard arrivals that are "
                                                "a reflection, late by an exponential excess path (the channel's "
                                                "acoustics.outlier_pct; the prediction leaves it out, the "
                                                "walk's tracker models it)",
             min=0.0, max=100.0),
        _key("multipath_excess_m", "Real", 2.0, "m", "an ilbl design's confirmation: a reflection's mean excess path "
                                                     "(exponential; the channel's acoustics.outlier_excess)",
             min=0.0, max=1e4, min_exclusive=True),
        _key("depth_sigma_m", "Real", 0.3, "m", "an ilbl design in 3-D: the tag's depth sensor's standard deviation "
                                                "(work_area.depth_sensor)", min=0.0, max=1000.0, min_exclusive=True),
        _key("per_receiver", "String", "", "", "an ilbl design: receivers in place with their own range test's "
                                               "curve, 'north east range_50_m slope; ...' [m, m, m, 1/m], each at a "
                                               "place of candidates.existing_m (the others: the site's curve)"),
        _key("frequency_hz", "Real", 69000.0, "Hz", "an ilbl design's SNR model (tag.source_level_db): the tag's "
                                                    "frequency", min=1000.0, max=1e6),
        _key("bandwidth_hz", "Real", 5000.0, "Hz", "the SNR model: the receiver's noise band", min=1.0, max=1e6),
        _key("beaufort", "Integer", 2, "", "the SNR model: the sea state of the wind noise (Wenz)", min=0,
             max=len(WAVE_HEIGHT) - 1),
        _key("shipping", "Real", 0.5, "1", "the SNR model: the shipping activity of the ambient noise (Wenz), 0 "
                                          "to 1", min=0.0, max=1.0),
        _key("threshold_db", "Real", 12.0, "dB", "the SNR model: the SNR of a 50 % detection", min=-30.0,
             max=60.0),
        _key("fluctuation_db", "Real", 3.0, "dB", "the SNR model: the received level's log-normal fluctuation (0: "
                                                  "a sharp threshold)", min=0.0, max=20.0),
        _key("directivity_db", "Real", 0.0, "dB", "the SNR model: the receiver's directivity index", min=0.0,
             max=40.0),
        _key("temperature_c", "Real", 10.0, "degC", "the SNR model: the water's temperature (absorption)",
             min=-2.0, max=40.0),
        _key("salinity", "Real", 35.0, "g/kg", "the SNR model: the water's salinity (absorption; 0: fresh "
                                               "water)", min=0.0, max=45.0),
    ),
    "tag": (
        _key("ping_type", "String", "rbi", "", "an ilbl design: the tag's ping type as the tracker names it (sbi: "
                                               "stable, rbi: random, pbi: pseudo-random burst interval)",
             choices=tuple(PING_TYPES)),
        _key("burst_interval_s", "Real", [], "s", "an ilbl design: rbi, the burst interval's [min, max] (empty: "
                                                 "[20, 40]); sbi, its one interval [D] or [D, D]; pbi, empty",
             (0, 2), min=0.1, max=86400.0),
        _key("burst_sequence", "String", "", "", "an ilbl design, pbi: a file of the tag's intervals [s] in order, "
                                                 "one per row (relative: from the design file's folder)",
             file=FileKey()),
        _key("source_level_db", "Real", 0.0, "dB", "an ilbl design: the tag's power class as its source level [dB re "
                                                   "1 uPa at 1 m] (0: none); given without detection.range_50_m or "
                                                   "table, the detection curve is the site's SNR model",
             min=0.0, max=250.0),
    ),
    "search": (
        _key("criterion", "String", "percentile", "", "what a layout minimises over the work area (docs/design.md: "
                                                      "the criteria)", choices=tuple(CRITERIA)),
        _key("pareto", "Boolean", False, "", "design every count and grade (the front of cost against the "
                                             "criterion), not only up to the cheapest that meets"),
        _key("population", "Integer", 10, "", "the differential evolution's population per free coordinate",
             min=4, max=200),
        _key("generations", "Integer", 60, "", "the differential evolution's most generations", min=1, max=10000),
        _key("polish", "Boolean", True, "", "polish each layout: SLSQP on the criterion's gradient (d-optimal, "
                                            "a-optimal), Powell's search (the others)"),
        _key("seed", "Integer", 0, "", "the search's seed", min=0, max=2**31 - 1),
    ),
    "monte_carlo": (
        _key("replicates", "Integer", 40, "", "static-vehicle runs at each checked point", min=10, max=10000),
        _key("cycles", "Integer", 3, "", "cycles of each static run", min=1, max=100),
        _key("tolerance_pct", "Real", 15.0, "%", "a prediction further than this from its Monte Carlo is flagged",
             min=0.0, max=100.0, min_exclusive=True),
        _key("path", "Boolean", True, "", "also run the scenario's receiver on a path across the work area"),
        _key("path_replicates", "Integer", 2, "", "replicates of the path", min=1, max=1000),
        _key("sync_clocks", "Boolean", True, "", "an ilbl design: also track the path's pings through receiver "
                                                 "clocks synchronised from the sync tags"),
    ),
}
#: The sections of a design problem.
SECTIONS = tuple(DESIGN_KEYS)
#: The keys of ``[detection]`` that only the site's SNR model reads (``tag.source_level_db``).
#: The keys of ``[detection]`` of an ilbl design's multipath (its confirmation's late arrivals).
MULTIPATH_KEYS = ("multipath_pct", "multipath_excess_m")
SNR_KEYS = ("frequency_hz", "bandwidth_hz", "beaufort", "shipping", "threshold_db", "fluctuation_db",
            "directivity_db", "temperature_c", "salinity")


def defaults() -> dict[str, dict[str, Any]]:
    """Every key of :data:`DESIGN_KEYS` at its default (lists new lists)."""
    return {section: {k.name: k.start for k in keys} for section, keys in DESIGN_KEYS.items()}


__all__ = ["DESIGN_KEYS", "GRADES", "Key", "MAX_RECEIVERS", "MULTIPATH_KEYS", "SECTIONS", "SNR_KEYS", "SYSTEM_CHOICES",
           "SYSTEM_NAMES", "TELEMETRY", "defaults"]
