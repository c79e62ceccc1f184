"""A design problem as data: ``DESIGN.toml`` (or the keyword arguments of :func:`sblsim.design`), its declared keys,
the hardware grades a design chooses among, and the work area and seafloor region as geometry.

A problem names a base scenario (its site: profile, water depth, sea state, source level, frequency), a **work
area** (a circle or polygon at one or several vehicle depths), a **prescription** (a horizontal or 3-D DRMS at a
share of the work area, a fix in a share of the cycles, an update interval), the **candidates** (systems, the
LBL transponders' count and the seafloor region where they may go with the areas to avoid, the SBL's arm length,
the hardware grades with their costs) and the **search** (its criterion, seed and effort). Every key is a
:class:`~sblsim.models.declarations.Variable` (:data:`DESIGN_KEYS`: type, default, unit, meaning, range or
choices), checked by :func:`check_problem` with one-line errors naming ``section.key`` and the allowed range; the
docs' table of keys is made from the same declarations (docs/design.md).

A design file is data: it never names a file that is read or written (the base scenario is a built-in one, or the
command line's ``--scenario``) but the water's outline of a telemetry array (``site.area.file``, a declared file
key read by :mod:`~sblsim.orchestrator.design.area_file`, bounded), and the overrides it gives refuse a value
that names a file or code in any key declared to take one (:func:`sblsim.orchestrator.cosim.config.file_keys`).
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from sblsim.models.declarations import FileKey, ModelError, Variable, shown
from sblsim.models.design.criteria import CRITERIA, DIMENSIONS, MAX_ECHO_MARGIN_PCT
from sblsim.models.design.detection_curve import DetectionCurve, ReceiverCurves
from sblsim.models.errors import ConfigError
from sblsim.models.platform.waves import WAVE_HEIGHT
from sblsim.models.systems import SYSTEMS
from sblsim.models.tracking.schedule import PING_TYPES
from sblsim.orchestrator.cosim.config import BUILTIN_SCENARIOS, named_files, parse_override, path_from
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.tables import regular_file

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
#: The largest design file read [bytes].
MAX_BYTES = 1 << 20
#: The most vertices of a polygon, areas to avoid, overrides and vehicle depths.
MAX_VERTICES, MAX_AVOID, MAX_SET, MAX_DEPTHS = 200, 50, 200, 10
#: The most receivers of a telemetry array.
MAX_RECEIVERS = 100
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
_FOLDER = files("sblsim.orchestrator") / "designs"
#: The built-in design problems: name -> its TOML file in this package.
BUILTIN_DESIGNS = {name: f"{name}.toml" for name in ("lbl-field-2km", "usbl-deep-head", "lake-hald-array")}


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

#: Every key of a design problem: section -> its keys (the docs' table, :func:`check_problem`, the defaults).
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


def _value(section: str, key: Key, value: Any) -> Any:
    """One key's value checked against its declaration (a list item by item); returned as its type."""
    try:
        return _checked(section, key, value)
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def _checked(section: str, key: Key, value: Any) -> Any:
    where = f"{section}.{key.name}"
    if key.length is None:
        if isinstance(value, (list, tuple, dict)):
            raise ConfigError(f"{where}: expected one value ({key.allowed()}), got a {type(value).__name__}")
        value = key.variable.coerce(value, where)
        if key.variable.type == "String" and (len(value) > 20000 or "\0" in value):
            raise ConfigError(f"{where}: a text of at most 20,000 characters, got {len(value):,}")
        return value
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{where}: expected {key.allowed()}, got {shown(value)}")
    low, high = key.length
    if not low <= len(value) <= high:
        raise ConfigError(f"{where}: {len(value)} values; expected {key.allowed()}")
    out = [key.variable.coerce(item, f"{where}[{k}]") for k, item in enumerate(value)]
    if key.variable.type == "String" and any(len(v) > 20000 or "\0" in v for v in out):
        raise ConfigError(f"{where}: each text at most 20,000 characters")
    return out


def check_problem(raw: Mapping[str, Any], scenario_given: bool = False) -> dict[str, dict[str, Any]]:
    """A design problem's sections checked against :data:`DESIGN_KEYS` and completed with the defaults.

    Parameters
    ----------
    raw : mapping
        Section -> key -> value, as read from ``DESIGN.toml`` (or given to :func:`sblsim.design`).
    scenario_given : bool
        The base scenario is given apart (``--scenario``): ``design.scenario`` may be empty.

    Returns
    -------
    dict
        Every section and key (the problem as resolved, before the scenario's defaults fill what depends on it).

    Raises
    ------
    ConfigError
        One line naming ``section.key`` and what is allowed: an unknown section or key, a value of the wrong type,
        outside its range or not one of its choices, a list of the wrong length, lists of grades and costs of
        different lengths, an invalid polygon, a name that is not a file name, a scenario that is not built in, an
        override that names a file or code.
    """
    if not isinstance(raw, Mapping):
        raise ConfigError(f"design: expected sections {', '.join(SECTIONS)}, got {shown(raw)}")
    problem = defaults()
    raw = _nested_sections(raw)
    for section, values in raw.items():
        if section not in DESIGN_KEYS:
            raise ConfigError(f"design: unknown section [{str(section)[:40]}]; the sections: {', '.join(SECTIONS)}")
        if not isinstance(values, Mapping):
            raise ConfigError(f"[{section}]: expected a table of keys, got {shown(values)}")
        keys = {k.name: k for k in DESIGN_KEYS[section]}
        for name, value in values.items():
            if name not in keys:
                raise ConfigError(f"{section}.{str(name)[:40]}: not a key of [{section}]; its keys: "
                                  f"{', '.join(keys)}")
            problem[section][name] = _value(section, keys[name], value)
    _check_together(problem, scenario_given)
    return problem


def _nested_sections(raw: Mapping[str, Any]) -> dict[str, Any]:
    """TOML's ``[site.area]`` (``{"site": {"area": {...}}}``) as the section ``site.area``."""
    out = dict(raw)
    site = out.get("site")
    if isinstance(site, Mapping):
        del out["site"]
        for name, values in site.items():
            if not isinstance(values, Mapping):
                raise ConfigError(f"site.{str(name)[:40]}: expected the table [site.area], got {shown(values)}")
            out[f"site.{name}"] = values
    return out


def is_telemetry(problem: Mapping[str, Mapping[str, Any]]) -> bool:
    """Whether a checked problem designs a telemetry array (``candidates.systems = ["ilbl"]``)."""
    return TELEMETRY in problem["candidates"]["systems"]


def _check_telemetry(problem: dict[str, dict[str, Any]]) -> None:
    """An ilbl design's keys together: alone among the systems, its water given once, its detection curve."""
    if problem["candidates"]["systems"] != [TELEMETRY]:
        raise ConfigError(f"candidates.systems: {', '.join(problem['candidates']['systems'])}; ilbl (a telemetry "
                          f"array) is designed alone: allowed ['ilbl'] or any of {', '.join(SYSTEM_NAMES)}")
    for name, empty in (("scenario", ""), ("set", [])):
        if problem["design"][name] != empty:
            raise ConfigError(f"design.{name}: an ilbl design (a telemetry array) reads no base scenario; allowed "
                              f"{empty!r} (the site is [site.area] and [detection])")
    low, high = problem["candidates"]["receivers"]
    if low > high:
        raise ConfigError(f"candidates.receivers: the fewest ({low}) is above the most ({high})")
    area = problem["site.area"]
    if bool(area["polygon"]) == bool(area["file"]):
        raise ConfigError("site.area: give the water as site.area.polygon or site.area.file (one of them)")
    if area["polygon"]:
        polygon(area["polygon"], "site.area.polygon")
    if area["origin"]:
        area_origin(area["origin"])
    if area["max_shore_m"] and area["max_shore_m"] < area["min_shore_m"]:
        raise ConfigError(f"site.area.max_shore_m: {area['max_shore_m']:g} m is below site.area.min_shore_m "
                          f"({area['min_shore_m']:g} m); allowed 0 (any) or at least it")
    if problem["work_area"]["shape"] == "polygon":
        polygon(problem["work_area"]["polygon"], "work_area.polygon")
    elif problem["work_area"]["shape"] != "site":
        raise ConfigError(f"work_area.shape: {problem['work_area']['shape']!r} for an ilbl design; allowed site or "
                          "polygon")
    receiver_curves(problem)


def area_origin(text: str) -> tuple[float, float]:
    """``site.area.origin``: 'latitude longitude' [°, WGS 84] as two numbers.

    Raises
    ------
    ConfigError
        One line naming the key and the allowed ranges.
    """
    parts = text.replace(",", " ").split()
    try:
        lat, lon = (float(v) for v in parts)
    except ValueError:
        lat = lon = math.nan
    if len(parts) != 2 or not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ConfigError(f"site.area.origin: {text[:40]!r}; allowed 'latitude longitude' with a latitude in "
                          "[-90, 90] and a longitude in [-180, 180] (WGS 84 degrees), e.g. '60.38 5.34'")
    return lat, lon


def receiver_curves(problem: Mapping[str, Mapping[str, Any]]) -> DetectionCurve | ReceiverCurves:
    """An ilbl design's detection curves: the site's (:func:`detection_curve`), and with ``detection.per_receiver``
    each receiver in place (``candidates.existing_m``, first in every layout, in its order) with its own logistic
    curve (:class:`~sblsim.models.design.detection_curve.ReceiverCurves`; a range test at that receiver, Kessel et
    al. 2014 as the module's).

    Raises
    ------
    ConfigError
        Naming ``detection.per_receiver``: a row of other than four numbers, more rows than
        :data:`MAX_RECEIVERS`, a row at no receiver of ``candidates.existing_m``, two rows for one receiver, a
        ``range_50_m`` or ``slope`` outside the logistic curve's allowed range.
    """
    site = site_curve(problem)
    text = problem["detection"]["per_receiver"]
    rows = [r for r in text.replace(",", " ").split(";") if r.strip()]
    if not rows:
        return site
    where = "detection.per_receiver"
    if len(rows) > MAX_RECEIVERS:
        raise ConfigError(f"{where}: {len(rows)} rows; allowed at most {MAX_RECEIVERS}")
    kept = existing_devices(problem["candidates"]["existing_m"])[:, :2]
    curves: list[DetectionCurve | None] = [None] * len(kept)
    for k, row in enumerate(rows):
        try:
            values = [float(x) for x in row.split()]
        except ValueError:
            values = []
        if len(values) != 4 or not all(math.isfinite(v) for v in values):
            raise ConfigError(f"{where}: expected 'north east range_50_m slope; ...' in numbers, got "
                              f"{row.strip()[:40]!r}")
        north, east, range_50_m, slope = values
        at = np.flatnonzero(np.hypot(kept[:, 0] - north, kept[:, 1] - east) <= 1e-6) if len(kept) else []
        if not len(at):
            raise ConfigError(f"{where}: no receiver of candidates.existing_m at {north:g} m North, {east:g} m East; "
                              "allowed the places of the receivers in place")
        if curves[at[0]] is not None:
            raise ConfigError(f"{where}: two curves for the receiver at {north:g} m North, {east:g} m East; allowed "
                              "one per receiver in place")
        try:
            curves[at[0]] = DetectionCurve.logistic(range_50_m, slope, f"{where}[{k}]")
        except ModelError as exc:
            raise ConfigError(str(exc)) from None
    return ReceiverCurves(site, tuple(curves))


def site_curve(problem: Mapping[str, Mapping[str, Any]]) -> DetectionCurve:
    """An ilbl design's site-wide detection curve: the range test's (:func:`detection_curve`), or, with
    ``tag.source_level_db`` and neither ``detection.range_50_m`` nor ``detection.table``, the site's SNR model
    (:meth:`~sblsim.models.design.detection_curve.DetectionCurve.sonar_equation`, the ``[detection]`` keys of
    :data:`SNR_KEYS`).

    Raises
    ------
    ConfigError
        As :func:`detection_curve`; naming ``tag.source_level_db`` where the site hears the tag nowhere.
    """
    section, level = problem["detection"], problem["tag"]["source_level_db"]
    if level <= 0.0 or section["range_50_m"] > 0.0 or section["table"]:
        return detection_curve(section)
    try:
        return DetectionCurve.sonar_equation(level, section["frequency_hz"], section["bandwidth_hz"],
                                             section["beaufort"], section["shipping"], section["threshold_db"],
                                             section["fluctuation_db"], section["directivity_db"],
                                             section["temperature_c"], section["salinity"])
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def detection_curve(section: Mapping[str, Any]) -> DetectionCurve:
    """The detection range curve of a checked ``[detection]`` section
    (:meth:`~sblsim.models.design.detection_curve.DetectionCurve.from_mapping`).

    Raises
    ------
    ConfigError
        Naming ``detection.range_50_m``, ``detection.slope`` or ``detection.table`` and what is allowed.
    """
    values: dict[str, Any] = {}
    if section["table"]:
        rows = [r for r in section["table"].replace(",", " ").split(";") if r.strip()]
        try:
            values["table"] = [[float(x) for x in r.split()] for r in rows[:MAX_VERTICES + 1]]
        except ValueError:
            raise ConfigError("detection.table: expected 'distance_m probability; ...' in numbers") from None
        if not 2 <= len(rows) <= MAX_VERTICES or any(len(r) != 2 for r in values["table"]):
            raise ConfigError(f"detection.table: {len(rows)} rows; allowed 2 to {MAX_VERTICES} rows "
                              "'distance_m probability'")
    for name in ("range_50_m", "slope"):
        if section[name] > 0.0:
            values[name] = section[name]
    if not values:
        raise ConfigError("detection: missing; give detection.range_50_m and detection.slope, or detection.table "
                          "(or the tag's tag.source_level_db: the site's SNR model)")
    try:
        return DetectionCurve.from_mapping(values, "detection")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def _check_together(problem: dict[str, dict[str, Any]], scenario_given: bool) -> None:
    """What one key cannot check alone (module docstring of :func:`check_problem`)."""
    design, candidates = problem["design"], problem["candidates"]
    if not _NAME.fullmatch(design["name"]):
        raise ConfigError(f"design.name: {design['name'][:40]!r} is not a name of 1 to 64 letters, digits, '.', '_' "
                          "or '-' (starting with a letter or digit)")
    if is_telemetry(problem):
        _check_telemetry(problem)
    elif problem["site.area"] != defaults()["site.area"]:  # the water places receivers of a telemetry array only
        given = next(k for k, v in problem["site.area"].items() if v != defaults()["site.area"][k])
        raise ConfigError(f"site.area.{given}: no effect in a design of {', '.join(candidates['systems'])} "
                          f"([site.area] is the water of an {TELEMETRY} design, candidates.systems = "
                          f"['{TELEMETRY}']); allowed: no [site.area] (where transponders may go: [seafloor] shape, "
                          "polygon, avoid; the work area: [work_area])")
    elif problem["work_area"]["shape"] == "site":
        raise ConfigError("work_area.shape: site is the water of an ilbl design (candidates.systems = ['ilbl']); "
                          "allowed circle or polygon")
    telemetry = is_telemetry(problem)
    if problem["detection"]["per_receiver"].strip() and not telemetry:
        raise ConfigError(f"detection.per_receiver: for {', '.join(candidates['systems'])}; a curve per receiver "
                          f"applies to an {TELEMETRY} design only; allowed ''")
    _check_noise_and_depth(problem, telemetry)
    # a file names no file to read
    if not scenario_given and not telemetry and design["scenario"] not in BUILTIN_SCENARIOS:
        given = f"{design['scenario'][:60]!r} is not a built-in scenario" if design["scenario"] else "missing"
        raise ConfigError(f"design.scenario: {given}; give one of {', '.join(BUILTIN_SCENARIOS)} (a CONFIG.toml: "
                          "--scenario)")
    for item in design["set"]:
        key = item.split("=", 1)[0].strip()
        if "=" not in item or not key:
            raise ConfigError(f"design.set: expected 'section.key=value', got {item[:60]!r}")
        try:
            section, name, value = parse_override(item)
        except ConfigError:
            continue  # the scenario's overrides name it when they are applied
        if named_files({section: {name: value}}):  # a declared file key naming a file (or code): never opened
            raise ConfigError(f"design.set: {section}.{name} names a file or code, which a design file may not (give "
                              "a configuration with --scenario)")
    low, high = candidates["transponders"]
    if low > high:
        raise ConfigError(f"candidates.transponders: the fewest ({low}) is above the most ({high})")
    short, long = candidates["sbl_baseline_m"]
    if short > long:
        raise ConfigError(f"candidates.sbl_baseline_m: the shortest ({short:g} m) is above the longest ({long:g} m)")
    for category in GRADES:
        grades, costs = candidates[category], candidates[f"{category}_cost"]
        if costs and len(costs) != len(grades):
            raise ConfigError(f"candidates.{category}_cost: {len(costs)} costs for {len(grades)} grades in "
                              f"candidates.{category}")
        if len(set(grades)) != len(grades):
            raise ConfigError(f"candidates.{category}: a grade is listed twice")
    if len(set(candidates["systems"])) != len(candidates["systems"]):
        raise ConfigError("candidates.systems: a system is listed twice")
    for section in ("work_area", "seafloor"):
        if problem[section]["shape"] == "polygon" and not is_telemetry(problem):
            polygon(problem[section]["polygon"], f"{section}.polygon")
    for k, text in enumerate(problem["seafloor"]["avoid"]):
        polygon(text, f"seafloor.avoid[{k}]")
    _check_kept(problem)


def _check_kept(problem: dict[str, dict[str, Any]]) -> None:
    """``candidates.existing_m`` and ``footprint_m`` against the systems and the counts (the places against the
    region or the water: when they are resolved)."""
    c = problem["candidates"]
    if not c["existing_m"] and not c["footprint_m"]:
        return
    telemetry = is_telemetry(problem)
    placed = telemetry or any(SYSTEMS[s].design_layout == "seafloor" for s in c["systems"])
    for name in ("existing_m", "footprint_m"):
        if c[name] and not placed:
            raise ConfigError(f"candidates.{name}: the systems {', '.join(c['systems'])} place no device (an SBL's "
                              "beacons and a USBL's transceiver stand on the platform: the SBL's arm is "
                              "candidates.sbl_baseline_m); allowed with an LBL's transponders or an ilbl array's "
                              "receivers")
    kept = existing_devices(c["existing_m"])
    if telemetry and np.isfinite(kept[:, 2]).any() and not c["receiver_depth_m"]:
        raise ConfigError("candidates.existing_m: an ilbl array's receivers are placed in the plane without "
                          "candidates.receiver_depth_m; allowed 'north east; north east; ...' [m] without a depth "
                          "(or the added receivers' depths in candidates.receiver_depth_m: 3-D)")
    most = c["receivers" if telemetry else "transponders"][1]
    if len(kept) > most:
        raise ConfigError(f"candidates.existing_m: {len(kept)} devices exist, more than the most designed "
                          f"(candidates.{'receivers' if telemetry else 'transponders'}: {most}); allowed at most "
                          f"{most}")
    spread = float(np.max(np.hypot(*(kept[:, None, :2] - kept[None, :, :2]).transpose(2, 0, 1)))) if len(kept) else 0.0
    if c["footprint_m"] and spread > c["footprint_m"]:
        raise ConfigError(f"candidates.footprint_m: {c['footprint_m']:g} m is below the existing devices' own "
                          f"spread ({spread:.6g} m, candidates.existing_m); allowed 0 (any) or at least it")


def existing_devices(text: str, where: str = "candidates.existing_m") -> np.ndarray:
    """The devices already in place from ``"north east [depth]; ..."`` [m], (k, 3) North, East, depth; the depth
    NaN where not given (k = 0 for an empty text).

    Raises
    ------
    ConfigError
        Naming ``where``: rows of other than two or three numbers, a value not finite or beyond ±100000 m, a
        negative depth, more than :data:`MAX_RECEIVERS` rows, two devices at one place.
    """
    rows = [r for r in text.replace(",", " ").split(";") if r.strip()]
    if len(rows) > MAX_RECEIVERS:
        raise ConfigError(f"{where}: {len(rows)} devices; allowed at most {MAX_RECEIVERS}")
    out = np.full((len(rows), 3), np.nan)
    for k, row in enumerate(rows):
        try:
            values = [float(x) for x in row.split()]
        except ValueError:
            raise ConfigError(f"{where}: expected 'north east [depth]; ...' in metres, got {row.strip()[:40]!r}") \
                from None
        if len(values) not in (2, 3) or not np.all(np.isfinite(values)) or max(abs(v) for v in values) > 1e5 \
                or (len(values) == 3 and values[2] < 0.0):
            raise ConfigError(f"{where}: {row.strip()[:40]!r}; allowed 'north east [depth]' in metres, each within "
                              "±100000, the depth at least 0")
        out[k, :len(values)] = values
    if len(out) > 1:
        gaps = np.hypot(*(out[:, None, :2] - out[None, :, :2]).transpose(2, 0, 1)) + np.diag(np.full(len(out), np.inf))
        if gaps.min() < 1e-6:
            raise ConfigError(f"{where}: two devices at one place; allowed distinct places")
    return out


def _check_noise_and_depth(problem: dict[str, dict[str, Any]], telemetry: bool) -> None:
    """The keys that apply to some systems only (no depth sensor, an echo margin, ...), each refused in one line
    naming it and the systems where it cannot apply (a range-dependent noise, ``detection.range_k``, applies to
    every system)."""
    systems = ", ".join(problem["candidates"]["systems"])
    if telemetry:
        _check_telemetry_depths(problem)
        _check_tag(problem)
    else:
        _refuse_tag(problem, systems)
    if not telemetry and problem["candidates"]["receiver_depth_m"]:
        raise ConfigError(f"candidates.receiver_depth_m: for {systems}; the receivers' depths apply to an "
                          f"{TELEMETRY} design only; allowed []")
    if telemetry and problem["prescription"]["echo_margin_pct"] > 0.0:
        raise ConfigError(f"prescription.echo_margin_pct: {problem['prescription']['echo_margin_pct']:g} % for "
                          f"{systems}; an {TELEMETRY} design's detection curve has no reflections to keep a margin "
                          "from; allowed 0")


def _refuse_tag(problem: dict[str, dict[str, Any]], systems: str) -> None:
    """The tag's keys (``[tag]``), the site's SNR model (:data:`SNR_KEYS`) and the confirmation's multipath
    (:data:`MULTIPATH_KEYS`) changed for other systems than an ilbl design: refused in one line naming the first."""
    start = defaults()
    for section, names in (("tag", [k.name for k in DESIGN_KEYS["tag"]]), ("detection", SNR_KEYS)):
        for name in names:
            if problem[section][name] != start[section][name]:
                raise ConfigError(f"{section}.{name}: {shown(problem[section][name])} for {systems}; a tag's ping "
                                  f"type, burst interval, power class and the site's SNR model apply to an "
                                  f"{TELEMETRY} design only; allowed {shown(start[section][name])}")
    for name in MULTIPATH_KEYS:
        if problem["detection"][name] != start["detection"][name]:
            raise ConfigError(f"detection.{name}: {shown(problem['detection'][name])} for {systems}; the "
                              f"confirmation's multipath applies to an {TELEMETRY} design only (the others' channel "
                              f"has its own: design.set acoustics.outlier_pct, outlier_excess); allowed "
                              f"{shown(start['detection'][name])}")


def _check_tag(problem: dict[str, dict[str, Any]]) -> None:
    """An ilbl design's tag: its burst interval as its ping type takes it (``rbi`` [min, max] with min <= max or
    empty, ``sbi`` [D] or [D, D], ``pbi`` empty and a ``burst_sequence`` file), and the detection curve's source
    (a range test's curve or the site's SNR model, not both).

    Raises
    ------
    ConfigError
        In one line naming ``tag.burst_interval_s``, ``tag.burst_sequence`` or ``tag.source_level_db``; or a key of
        the SNR model (:data:`SNR_KEYS`) changed where the curve is the range test's (it has no effect).
    """
    tag = problem["tag"]
    kind, interval, sequence = tag["ping_type"], tag["burst_interval_s"], tag["burst_sequence"]
    given = f"[{', '.join(f'{v:g}' for v in interval)}] s"
    if kind == "rbi" and len(interval) == 2 and interval[0] > interval[1]:
        raise ConfigError(f"tag.burst_interval_s: {given}, the shortest above the longest; allowed [min, max] with "
                          "0.1 <= min <= max <= 86400 s")
    if kind == "rbi" and len(interval) == 1:
        raise ConfigError(f"tag.burst_interval_s: {given} for rbi; allowed [min, max] [s] (empty: [20, 40])")
    if kind == "sbi" and (not interval or interval[0] != interval[-1]):
        raise ConfigError(f"tag.burst_interval_s: {given} for sbi; allowed its one interval [D] or [D, D] [s]")
    if kind == "pbi" and interval:
        raise ConfigError(f"tag.burst_interval_s: {given} for pbi; allowed [] (the intervals: tag.burst_sequence)")
    if kind == "pbi" and not sequence:
        raise ConfigError("tag.burst_sequence: missing for pbi; allowed a file of the tag's intervals [s], one per "
                          "row")
    if kind != "pbi" and sequence:
        raise ConfigError(f"tag.burst_sequence: given for {kind}; allowed '' (a sequence is pbi's)")
    detection = problem["detection"]
    if tag["source_level_db"] > 0.0 and (detection["range_50_m"] > 0.0 or detection["table"]):
        raise ConfigError(f"tag.source_level_db: {tag['source_level_db']:g} dB with a range test's curve "
                          "(detection.range_50_m or detection.table); allowed one of them: 0 (the range test's "
                          "curve) or the site's SNR model without range_50_m and table")
    if tag["source_level_db"] <= 0.0:  # the range test's curve: the SNR model's keys are read by nothing
        start = defaults()["detection"]
        for name in SNR_KEYS:
            if detection[name] != start[name]:
                raise ConfigError(f"detection.{name}: {shown(detection[name])} has no effect: the detection curve "
                                  "is the range test's (detection.range_50_m or detection.table), not the site's SNR "
                                  f"model, which alone reads it; allowed its default {shown(start[name])}, or "
                                  "tag.source_level_db without range_50_m and table (the SNR model)")


def is_three_d(problem: Mapping[str, Mapping[str, Any]]) -> bool:
    """Whether a checked ilbl problem is in 3-D (``candidates.receiver_depth_m`` given)."""
    return bool(problem["candidates"]["receiver_depth_m"])


def _check_telemetry_depths(problem: dict[str, dict[str, Any]]) -> None:
    """An ilbl design's depths: planar (no receiver depth, no tag depth, a depth sensor implied) or 3-D (both);
    without a depth sensor in 3-D, a fix of four unknowns and receivers at more than one depth.

    Raises
    ------
    ConfigError
        In one line naming the key: ``work_area.depth_sensor`` false or ``work_area.depths_m`` given in a planar
        design; ``work_area.depths_m`` empty in 3-D; ``prescription.fix_receivers`` below 4 without a sensor;
        ``candidates.receiver_depth_m`` at one depth (the receivers in place too) without a sensor.
    """
    c, work = problem["candidates"], problem["work_area"]
    if not is_three_d(problem):
        if not work["depth_sensor"]:
            raise ConfigError(f"work_area.depth_sensor: false for a planar {TELEMETRY} design; its tag and receivers "
                              "are in one plane (no depth to sense): allowed true, or the receivers' depths "
                              "(candidates.receiver_depth_m) and the tag's (work_area.depths_m) for a 3-D design")
        if work["depths_m"]:
            raise ConfigError(f"work_area.depths_m: the tag's depths for a planar {TELEMETRY} design; allowed [] or "
                              "with the receivers' depths (candidates.receiver_depth_m: 3-D)")
        return
    if not work["depths_m"]:
        raise ConfigError(f"work_area.depths_m: empty for a 3-D {TELEMETRY} design (candidates.receiver_depth_m "
                          "given); allowed 1 to 10 depths of the tag [m]")
    if work["depth_sensor"]:
        return
    if problem["prescription"]["fix_receivers"] < 4:
        raise ConfigError(f"prescription.fix_receivers: {problem['prescription']['fix_receivers']} without a depth "
                          "sensor in 3-D (a fix of north, east, depth and the emission); allowed 4 to 10")
    kept = existing_devices(c["existing_m"])
    depths = set(c["receiver_depth_m"]) | {d if np.isfinite(d) else c["receiver_depth_m"][0] for d in kept[:, 2]}
    if len(depths) < 2:
        raise ConfigError(f"candidates.receiver_depth_m: every receiver at {min(depths):g} m without a depth sensor "
                          "(work_area.depth_sensor = false): a planar array cannot fix a tag's depth (no information "
                          "about it at the receivers' depth, a mirror solution elsewhere); allowed two depths or "
                          "more, or a depth sensor")


def polygon(text: str, where: str) -> np.ndarray:
    """A polygon's vertices from ``"north east; north east; ..."`` [m], (V, 2), at least three, not degenerate.

    Raises
    ------
    ConfigError
        Naming ``where``.
    """
    rows = [r for r in text.replace(",", " ").split(";") if r.strip()]
    if not 3 <= len(rows) <= MAX_VERTICES:
        raise ConfigError(f"{where}: {len(rows)} vertices; give 3 to {MAX_VERTICES} as 'north east; north east; "
                          "...' [m]")
    try:
        vertices = np.array([[float(x) for x in r.split()] for r in rows], dtype=float)
    except ValueError:
        raise ConfigError(f"{where}: expected 'north east; north east; ...' in metres") from None
    if vertices.ndim != 2 or vertices.shape[1] != 2 or not np.all(np.isfinite(vertices)) \
            or np.abs(vertices).max() > 1e5:
        raise ConfigError(f"{where}: expected 'north east; north east; ...' in metres, each within ±100000")
    n, e = vertices.T
    if abs(np.dot(n, np.roll(e, -1)) - np.dot(e, np.roll(n, -1))) < 1e-6:
        raise ConfigError(f"{where}: the polygon encloses no area")
    return vertices


def read_problem(source: str | Path) -> dict[str, Any]:
    """The raw sections of a built-in design problem (:data:`BUILTIN_DESIGNS`) or a ``DESIGN.toml`` file.

    Raises
    ------
    ConfigError
        A file that is missing, not a regular file, larger than :data:`MAX_BYTES`, not UTF-8 or not valid TOML.
    """
    name = str(source)
    if name in BUILTIN_DESIGNS:
        return tomlfile.loads((_FOLDER / BUILTIN_DESIGNS[name]).read_text(encoding="utf-8"))
    path = Path(source)
    if path.suffix != ".toml" and not path.exists():
        raise ConfigError(f"design: {name[:80]!r} is neither a built-in design ({', '.join(BUILTIN_DESIGNS)}) nor a "
                          "DESIGN.toml file")
    try:
        size = regular_file(path, "design")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None
    if size > MAX_BYTES:
        raise ConfigError(f"design: {name[:80]!r} is {size:,} bytes; a design file is at most {MAX_BYTES:,}")
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_BYTES + 1)
        raw = tomlfile.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"design: {name[:80]!r} is not valid TOML ({' '.join(str(exc).split())[:160]})") from None
    except OSError as exc:
        raise ConfigError(f"design: {name[:80]!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    area = raw.get("site", {}).get("area") if isinstance(raw.get("site"), Mapping) else None
    if isinstance(area, dict) and isinstance(area.get("file"), str) and area["file"]:  # from the file's folder
        area["file"] = path_from(path.resolve().parent, area["file"], "site.area.file", confined=True)
    tag = raw.get("tag")
    if isinstance(tag, dict) and isinstance(tag.get("burst_sequence"), str) and tag["burst_sequence"]:
        tag["burst_sequence"] = path_from(path.resolve().parent, tag["burst_sequence"], "tag.burst_sequence",
                                          confined=True)
    return raw


# --------------------------------------------------------------------------- geometry of the areas

@dataclass(frozen=True)
class Area:
    """A circle or polygon in the horizontal plane (North, East [m])."""

    vertices: np.ndarray | None = None
    centre: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0

    @classmethod
    def of(cls, section: Mapping[str, Any], where: str, radius: float | None = None) -> Area:
        """The area of a ``[work_area]`` or ``[seafloor]`` section (``radius`` in place of a 0 radius)."""
        if section["shape"] == "polygon":
            return cls(vertices=polygon(section["polygon"], f"{where}.polygon"))
        r = section["radius_m"] if section["radius_m"] > 0.0 or radius is None else radius
        return cls(centre=(section["centre_north_m"], section["centre_east_m"]), radius=float(r))

    @property
    def middle(self) -> tuple[float, float]:
        """The circle's centre, or the mean of the polygon's vertices (North, East) [m]."""
        return self.centre if self.vertices is None else tuple(float(v) for v in self.vertices.mean(axis=0))

    @property
    def reach(self) -> float:
        """The largest distance from :attr:`middle` to the boundary [m]."""
        if self.vertices is None:
            return self.radius
        return float(np.max(np.hypot(*(self.vertices - np.asarray(self.middle)).T)))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box's lower and upper corners (North, East) [m]."""
        if self.vertices is not None:
            return self.vertices.min(axis=0), self.vertices.max(axis=0)
        c = np.asarray(self.centre)
        return c - self.radius, c + self.radius

    def distance(self, points: np.ndarray) -> np.ndarray:
        """The signed distance of points (..., 2) to the area's boundary [m]: negative inside."""
        points = np.asarray(points, dtype=float)
        if self.vertices is None:
            return np.hypot(points[..., 0] - self.centre[0], points[..., 1] - self.centre[1]) - self.radius
        return signed_distance(points, self.vertices)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Which points (..., 2) lie inside (or on) the area."""
        return self.distance(points) <= 1e-9

    def outline(self) -> np.ndarray:
        """Points of the boundary (K, 2), closed (for figures)."""
        if self.vertices is not None:
            return np.vstack([self.vertices, self.vertices[:1]])
        a = np.linspace(0.0, 2.0 * math.pi, 181)
        return np.column_stack([self.centre[0] + self.radius * np.cos(a), self.centre[1] + self.radius * np.sin(a)])


def signed_distance(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Signed distance of points (..., 2) to a polygon's boundary (V, 2) [m]: negative inside (even-odd rule)."""
    p = np.asarray(points, dtype=float)[..., None, :]
    a, b = vertices, np.roll(vertices, -1, axis=0)
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.sum(ab * ab, axis=-1), 0.0, 1.0)
    nearest = np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=-1)
    # inside: a ray to the East crosses the edges an odd number of times
    y, x = p[..., 0], p[..., 1]
    crosses = ((a[:, 0] > y) != (b[:, 0] > y)) & (x < a[:, 1] + (y - a[:, 0]) * ab[:, 1] / np.where(
        ab[:, 0] == 0.0, 1.0, ab[:, 0]))
    inside = np.sum(crosses, axis=-1) % 2 == 1
    return np.where(inside, -nearest, nearest)


def work_area_points(area: Area, count: int, depths: list[float]) -> np.ndarray:
    """The work area's points: a regular grid of ``count`` × ``count`` over its bounding box, those inside, at
    each depth; (M, 3) NED [m], depth-major, North-major within a depth.

    Raises
    ------
    ConfigError
        If no grid point lies inside the area.
    """
    low, high = area.bounds()
    north = np.linspace(low[0], high[0], count)
    east = np.linspace(low[1], high[1], count)
    N, E = np.meshgrid(north, east, indexing="ij")
    plane = np.column_stack([N.ravel(), E.ravel()])
    plane = plane[area.contains(plane)]
    if plane.shape[0] == 0:
        raise ConfigError("work_area: no grid point lies inside the work area; give more work_area.points")
    return np.vstack([np.column_stack([plane, np.full(len(plane), d)]) for d in depths])


__all__ = ["Area", "BUILTIN_DESIGNS", "DESIGN_KEYS", "GRADES", "Key", "MAX_RECEIVERS", "MULTIPATH_KEYS", "SECTIONS",
           "SNR_KEYS", "SYSTEM_CHOICES", "SYSTEM_NAMES", "TELEMETRY", "check_problem", "defaults", "detection_curve",
           "existing_devices", "is_telemetry", "is_three_d", "polygon", "read_problem", "receiver_curves",
           "signed_distance", "site_curve", "work_area_points"]
