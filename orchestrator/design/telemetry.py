"""``sblsim design`` of a telemetry array (``candidates.systems = ["ilbl"]``): how many receivers (hydrophones) to
moor, and where in the water, so that a tag's pings are positioned to the prescription; each proposal confirmed by
simulated tags.

1. **Resolve** (:func:`resolve`): the water (``[site.area]``: a polygon, or a CSV or GeoJSON file), the work area's
   points (a grid over the water, or over ``work_area.polygon`` within it), the places a receiver may go (a finer
   grid over the water, ``site.area.min_shore_m`` / ``max_shore_m`` from the shore; or points along the mooring
   lines ``site.area.lines`` at the grid's step), the detection range curve
   (``[detection]``) and the timing σ = c σ_toa.
2. **Search** each receiver count from ``candidates.receivers``' fewest
   (:func:`~sblsim.orchestrator.design.telemetry_search.search_count`): the layout starts as the k-means centres of the
   work area's points, then a seeded local search moves one receiver at a time to another place; every place is a point
   of the grid of allowed places, so **no receiver is ever outside the water**. The search's criterion is smooth and
   cheap: per point, the DRMS of the information averaged over the detections
   (:func:`~sblsim.models.design.telemetry.expected_information_drms`) over the prescription's DRMS, plus 10 × the
   positioning yield's shortfall, at the prescription's coverage percentile (plus a tenth of its mean), plus the sync
   graph's shortfall (receivers hearing fewer than two sync tags, parts beyond one). Receivers already moored
   (``candidates.existing_m``) are in every layout, first, and only the others are placed and paid for; a footprint
   (``candidates.footprint_m``) keeps the places within it of every receiver in place and penalises a layout whose
   spread exceeds it.
3. **Judge** (:func:`~sblsim.orchestrator.design.telemetry_judgement.judge`) with the criteria of the field: the
   positioning yield (a ping heard by ≥ 3 receivers, the exact Poisson-binomial), the DRMS as the RMS over the pings
   that are fixed (:func:`~sblsim.models.design.telemetry.fixed_ping_drms`, what single-ping fixes measure) and the sync
   coverage (every receiver hears two other receivers' sync tags with probability ≥ ``detection.sync_p``, the sync graph
   connected). A point meets where its DRMS is at most ``prescription.drms_m`` and its yield at least
   ``prescription.positioning_yield_pct``; the design meets where ``coverage_pct`` of the points do and the sync graph
   is met. The counts are searched in order until one meets (every count with ``search.pareto``;
   :func:`~sblsim.orchestrator.design.telemetry_search.search_all`).
4. **Confirm** by simulated tags (:mod:`sblsim.orchestrator.design.telemetry_confirm`): at the work area's worst
   and median points and along an animal's walk, pings fixed and tracked, the simulated yield and DRMS beside the
   predicted.

This module resolves the problem (step 1); the tag is :mod:`~sblsim.orchestrator.design.telemetry_tag`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
from scipy.spatial import cKDTree

from sblsim.models.design import area as areas
from sblsim.models.errors import ConfigError, ModelError
from sblsim.models.sync.scale import looks_like_degrees
from sblsim.orchestrator.design.area import existing_devices, polygon
from sblsim.orchestrator.design.area_file import read_area
from sblsim.orchestrator.design.checks import is_three_d
from sblsim.orchestrator.design.curves import receiver_curves
from sblsim.orchestrator.design.telemetry_tag import Tag, tag_of

#: The places a receiver may go: about this many grid points over the water.
SITE_POINTS = 4000
#: The least extent of the water [m]: an outline smaller is no telemetry site (degrees or kilometres taken for
#: metres), and metres per degree of latitude (the size such an outline would have in degrees).
MIN_WATER_M = 1.0
DEGREE_M = 111_195.0
#: The most mooring lines (``site.area.lines``) and vertices of one.
MAX_LINES, MAX_LINE_VERTICES = 100, 200


@dataclass
class TelemetryProblem:
    """A telemetry array's design problem resolved (module docstring, step 1); coordinates (North, East) [m]."""

    sections: dict
    water: Any
    work: Any
    points: np.ndarray
    sites: np.ndarray
    curve: Any
    sigma_m: float
    sigma_per_m: float = 0.0  # detection.range_k: the timing noise's growth with distance [m/m]
    receiver_depths: np.ndarray | None = None  # 3-D: the added receivers' depths in turn [m]; None: planar
    tag: Tag = field(default_factory=Tag)  # the tag the confirmation simulates and tracks ([tag])

    @property
    def three_d(self) -> bool:
        """Receivers and tag at depths (``candidates.receiver_depth_m``): points and receivers (North, East, depth)
        [m], depth positive down."""
        return self.receiver_depths is not None

    @property
    def depth_sigma(self) -> float | None:
        """The tag's depth sensor's σ [m] in 3-D (``detection.depth_sigma_m``); None: planar or no sensor."""
        if not self.three_d or not self.sections["work_area"]["depth_sensor"]:
            return None
        return float(self.sections["detection"]["depth_sigma_m"])

    @property
    def horizontal(self) -> bool:
        """The DRMS of North and East (else of all axes: ``prescription.dimensions = "3d"``)."""
        return self.prescription["dimensions"] != "3d"

    def layout(self, kept: np.ndarray, placed: np.ndarray) -> np.ndarray:
        """The receivers in place and the ``placed`` (k, 2) [m], each added receiver at its depth in 3-D."""
        if self.three_d:
            depths = self.receiver_depths[np.arange(len(placed)) % len(self.receiver_depths)]
            placed = np.column_stack([placed, depths])
        return np.vstack([kept, placed])

    @property
    def prescription(self) -> dict:
        return self.sections["prescription"]

    @property
    def needed(self) -> int:
        """The receivers a ping's fix needs (``prescription.fix_receivers``)."""
        return int(self.prescription["fix_receivers"])

    @property
    def required_yield(self) -> float:
        return self.prescription["positioning_yield_pct"] / 100.0

    @property
    def kept(self) -> np.ndarray:
        """The receivers in place (``candidates.existing_m``), (k, 2) (North, East) [m], in 3-D (k, 3) with their
        depth (default the first of ``candidates.receiver_depth_m``): every layout holds them, first."""
        kept = existing_devices(self.sections["candidates"]["existing_m"])
        if not self.three_d:
            return kept[:, :2]
        return np.column_stack([kept[:, :2], np.where(np.isfinite(kept[:, 2]), kept[:, 2], self.receiver_depths[0])])

    @property
    def footprint(self) -> float:
        """The largest distance between any two receivers (``candidates.footprint_m``; 0: any) [m]."""
        return float(self.sections["candidates"]["footprint_m"])


def water_polygon(section: Mapping[str, Any]):
    """The water of a checked ``[site.area]`` section, (North, East) [m].

    Raises
    ------
    ConfigError
        An outline that does not read or is not a polygon; one less than :data:`MIN_WATER_M` across (no acoustic
        range is that short: an outline in degrees or kilometres, named).
    """
    if section["file"]:
        water, where = read_area(section["file"]), "site.area.file"
    else:
        where = "site.area.polygon"
        try:
            water = areas.polygon(polygon(section["polygon"], where), where)
        except ModelError as exc:
            raise ConfigError(str(exc)) from None
    north0, east0, north1, east1 = water.bounds
    across = max(north1 - north0, east1 - east0)
    if across < MIN_WATER_M:
        degrees = looks_like_degrees(np.array([east0, east1]), np.array([north0, north1]))
        unit = (f"degrees (latitude, longitude: about {across * DEGREE_M / 1e3:.3g} km across)" if degrees else
                f"kilometres ({across * 1e3:.3g} m across)")
        raise ConfigError(f"{where}: the water is {across:.3g} m across (North {north0:.6g} to {north1:.6g}, East "
                          f"{east0:.6g} to {east1:.6g}), less than any acoustic range; it looks like {unit}; allowed: "
                          f"an outline at least {MIN_WATER_M:g} m across, in metres North and East of an origin "
                          "(site.area.origin 'latitude longitude' places it)")
    return water


def mooring_lines(text: str, where: str = "site.area.lines") -> list[np.ndarray]:
    """The mooring lines of ``'north east; north east; ... | north east; ...'`` [m]: a list of (V, 2) arrays.

    Raises
    ------
    ConfigError
        Naming ``where``: more than :data:`MAX_LINES` lines, a line of fewer than 2 or more than
        :data:`MAX_LINE_VERTICES` vertices, a vertex not two finite numbers within ±100000 m.
    """
    lines = [line for line in text.split("|") if line.strip()]
    if len(lines) > MAX_LINES:
        raise ConfigError(f"{where}: {len(lines)} lines; allowed at most {MAX_LINES}")
    out = []
    for k, line in enumerate(lines):
        rows = [r for r in line.replace(",", " ").split(";") if r.strip()]
        try:
            vertices = np.array([[float(x) for x in r.split()] for r in rows[:MAX_LINE_VERTICES + 1]], dtype=float)
        except ValueError:
            vertices = np.empty((0, 0))
        if not 2 <= len(rows) <= MAX_LINE_VERTICES or vertices.ndim != 2 or vertices.shape[1] != 2 \
                or not np.isfinite(vertices).all() or np.abs(vertices).max() > 1e5:
            raise ConfigError(f"{where}[{k}]: {line.strip()[:40]!r}; allowed 2 to {MAX_LINE_VERTICES} vertices "
                              "'north east; north east; ...' in metres, each within ±100000")
        out.append(vertices)
    return out


def resolve(sections: dict) -> TelemetryProblem:
    """The problem resolved (module docstring, step 1).

    Raises
    ------
    ConfigError
        A water outline that does not read or is not a polygon, no work-area point in the water, no place for a
        receiver within the shore distances, fewer places than the most receivers.
    """
    site = sections["site.area"]
    water = water_polygon(site)
    work_section = sections["work_area"]
    work = water
    if work_section["shape"] == "polygon":
        try:
            work = areas.polygon(polygon(work_section["polygon"], "work_area.polygon"), "work_area.polygon")
        except ModelError as exc:
            raise ConfigError(str(exc)) from None
    x0, y0, x1, y1 = work.bounds
    spacing = max(x1 - x0, y1 - y0) / work_section["points"]
    points = areas.grid(work, spacing)
    points = points[areas.inside(water, points)]
    if len(points) == 0:
        raise ConfigError("work_area: no grid point lies in the water (site.area); give more work_area.points or a "
                          "work_area.polygon inside the water")
    depths = None
    if is_three_d(sections):  # every horizontal point at each of the tag's depths, the shallowest first
        depths = np.asarray(sections["candidates"]["receiver_depth_m"], float)
        points = np.vstack([np.column_stack([points, np.full(len(points), z)])
                            for z in sorted(work_section["depths_m"])])
    step = math.sqrt(water.area / SITE_POINTS)
    max_shore = site["max_shore_m"] or None
    if site["lines"].strip():  # only on the mooring lines, at the grid's step
        try:
            sites = areas.line_places(water, mooring_lines(site["lines"]), step)
        except ModelError as exc:
            raise ConfigError(str(exc)) from None
        sites = sites[areas.inside(water, sites, site["min_shore_m"], max_shore)]
    else:
        sites = areas.grid(water, step, site["min_shore_m"])
        if max_shore is not None:
            sites = sites[areas.inside(water, sites, site["min_shore_m"], max_shore)]
    most = sections["candidates"]["receivers"][1]
    if len(sites) < most:
        where = "site.area.lines" if site["lines"].strip() else "site.area.min_shore_m"
        raise ConfigError(f"{where}: {len(sites)} places for a receiver within the shore distances, "
                          f"fewer than candidates.receivers' most ({most}); allowed lines or distances that leave "
                          "room")
    sites = _kept_sites(sections, water, sites, step)
    curve = receiver_curves(sections)
    sigma = sections["detection"]["sound_speed"] * sections["detection"]["sigma_toa_s"]
    return TelemetryProblem(sections, water, work, points, sites, curve, float(sigma),
                            float(sections["detection"]["range_k"]), depths, tag_of(sections["tag"]))


def _kept_sites(sections: dict, water: Any, sites: np.ndarray, step: float) -> np.ndarray:
    """The places left for the receivers added: within ``candidates.footprint_m`` of each receiver in place
    (``candidates.existing_m``, checked against the water and the shore distances).

    Raises
    ------
    ConfigError
        Naming ``candidates.existing_m``: a receiver in place outside the water or the shore distances; naming
        ``candidates.footprint_m``: fewer places within it than receivers to add, or no two places within it
        (``step`` [m], the places' spacing).
    """
    c, site = sections["candidates"], sections["site.area"]
    kept = existing_devices(c["existing_m"])[:, :2]
    footprint = float(c["footprint_m"])
    for north, east in kept:
        if not areas.inside(water, np.array([[north, east]]), site["min_shore_m"], site["max_shore_m"] or None)[0]:
            raise ConfigError(f"candidates.existing_m: the receiver at {north:g} m North, {east:g} m East stands "
                              "outside the water (site.area) or its shore distances (site.area.min_shore_m, "
                              "max_shore_m); allowed places in the water within them")
    if footprint <= 0.0:
        return sites
    added = c["receivers"][1] - len(kept)
    if len(kept):
        sites = sites[np.all(np.linalg.norm(sites[:, None] - kept[None], axis=-1) <= footprint, axis=1)]
    if added > 0 and len(sites) < added:
        raise ConfigError(f"candidates.footprint_m: {footprint:g} m leaves {len(sites)} places for a receiver within "
                          f"it of every receiver in place, fewer than the {added} to add (candidates.receivers' "
                          "most); allowed a larger footprint")
    if not len(kept) and (len(sites) < 2 or cKDTree(sites).query(sites, k=2)[0][:, 1].min() > footprint):
        raise ConfigError(f"candidates.footprint_m: {footprint:g} m is below the spacing of the places for a "
                          f"receiver ({step:.3g} m): no two receivers can be placed within it; allowed a larger "
                          "footprint")
    return sites


def within(problem: TelemetryProblem, receivers: np.ndarray) -> bool:
    """Whether every receiver is in the water, within the shore distances."""
    site = problem.sections["site.area"]
    return bool(np.all(areas.inside(problem.water, receivers[:, :2], site["min_shore_m"],
                                    site["max_shore_m"] or None)))


__all__ = ["MAX_LINES", "MAX_LINE_VERTICES", "SITE_POINTS", "TelemetryProblem", "mooring_lines", "resolve",
           "water_polygon", "within"]
