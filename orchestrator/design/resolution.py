"""A design problem resolved against its base scenario (:mod:`~sblsim.orchestrator.design.run`'s step 1): the base
scenario's plan, the work area's points at the vehicle's depths, the seafloor region and the areas to avoid, an LBL's
transponders in place and its footprint, and what the scenario gives to the keys left at 0 or empty; the plan of the
base scenario with a design's overrides.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.errors import ConfigError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.config import apply_overrides, check_site_keys
from sblsim.orchestrator.cosim.plan import RunPlan, load_plan, make_plan, thaw
from sblsim.orchestrator.design.area import Area, existing_devices, polygon, work_area_points
from sblsim.orchestrator.design.evaluate import problem_items
from sblsim.orchestrator.maps import diver_depth

#: The grid per axis over the seafloor region on which some room outside the areas to avoid must be found.
ROOM_GRID = 201


@dataclass
class Resolved:
    """A design problem resolved against its base scenario.

    Attributes
    ----------
    sections : dict
        The problem as resolved (every key; what the scenario gives filled in).
    source : str, Path or mapping
        The base scenario.
    items : list of str
        The base scenario's overrides.
    plan : RunPlan
        The base scenario's plan.
    area, seafloor : Area
    avoid : list of Area
    points : ndarray, shape (M, 3)
        The work area's points, NED [m].
    kept : ndarray, shape (k, 3)
        An LBL's transponders in place (``candidates.existing_m``), NED [m]: every layout holds them, first.
    footprint : float
        The largest distance between any two of an LBL's transponders (``candidates.footprint_m``; 0: any) [m].
    """

    sections: dict
    source: Any
    items: list[str]
    plan: RunPlan
    area: Area
    seafloor: Area
    avoid: list[Area]
    points: np.ndarray
    kept: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    footprint: float = 0.0

    @property
    def depths(self) -> list[float]:
        return self.sections["work_area"]["depths_m"]

    @property
    def seafloor_depth(self) -> float:
        return self.sections["seafloor"]["depth_m"]


def _depth_default(plan: RunPlan) -> float:
    return float(diver_depth(plan)[0])


def resolve(sections: dict, source: Any, scenario_items: list[str] | None = None) -> Resolved:
    """The problem resolved against its base scenario (:mod:`~sblsim.orchestrator.design.run`, step 1).

    Parameters
    ----------
    sections : dict
        From :func:`~sblsim.orchestrator.design.problem.check_problem`.
    source : str, Path or mapping
        The base scenario (``design.scenario``, or the command line's ``--scenario``).
    scenario_items : list of str, optional
        Overrides of the base scenario (default ``design.set``).

    Raises
    ------
    ConfigError
        A base scenario or override that does not resolve; a vehicle depth at or below the seafloor or the water;
        a seafloor region without room outside its areas to avoid.
    """
    items = list(sections["design"]["set"] if scenario_items is None else scenario_items)
    try:
        plan = load_plan(source, items) if not isinstance(source, Mapping) else make_plan(
            apply_overrides(thaw(source), items, None))
    except ModelError as exc:
        raise ConfigError(f"design.scenario: {exc}") from None
    check_site_keys([plan], items, str(source) if not isinstance(source, Mapping) else "the configuration")
    sections = {k: dict(v) for k, v in sections.items()}
    work, floor = sections["work_area"], sections["seafloor"]
    if not work["depths_m"]:
        work["depths_m"] = [_depth_default(plan)]
    extra = problem_items(sections, plan)  # the problem's own keys as the scenario's: no depth sensor, its depth
    if extra:
        items = [*items, *extra]
        plan = load_plan(source, items) if not isinstance(source, Mapping) else make_plan(
            apply_overrides(thaw(source), items, None))
    water = float(plan["acoustics"]["water_depth"])
    if floor["depth_m"] == 0.0:  # the scenario's seafloor field, else 1 m above the site's floor
        field = plan.system.design_layout == "seafloor" or water == 0.0
        floor["depth_m"] = float(plan["platform"]["seafloor_depth"]) if field else water - 1.0
    deepest = max(work["depths_m"])
    if water > 0.0 and not deepest < water:  # every system: no vehicle in the seabed
        raise ConfigError(f"work_area.depths_m: {deepest:g} m is outside the allowed range [0, {water:g}) m: the "
                          f"site's water is {water:g} m deep (acoustics.water_depth)")
    fielded = any(SYSTEMS[s].design_layout == "seafloor" for s in sections["candidates"]["systems"])
    if fielded and not floor["depth_m"] > deepest:
        raise ConfigError(f"seafloor.depth_m: {floor['depth_m']:g} m is not below the work area's deepest vehicle "
                          f"({deepest:g} m, work_area.depths_m)")
    if water > 0.0 and floor["depth_m"] > water:
        raise ConfigError(f"seafloor.depth_m: {floor['depth_m']:g} m is below the site's water "
                          f"(acoustics.water_depth = {water:g} m)")
    area = Area.of(work, "work_area")
    if floor["shape"] == "circle" and floor["radius_m"] == 0.0:
        (floor["centre_north_m"], floor["centre_east_m"]), floor["radius_m"] = area.middle, area.reach
    seafloor = Area.of(floor, "seafloor")
    avoid = [Area(vertices=polygon(text, f"seafloor.avoid[{k}]")) for k, text in enumerate(floor["avoid"])]
    if fielded and avoid and not room(seafloor, avoid):
        raise ConfigError(f"seafloor.avoid: the areas to avoid cover the whole seafloor region (no point of a "
                          f"{ROOM_GRID} × {ROOM_GRID} grid over it is outside them); leave room for the transponders "
                          "(seafloor.radius_m, seafloor.polygon or fewer areas)")
    points = work_area_points(area, work["points"], work["depths_m"])
    kept, footprint = np.zeros((0, 3)), 0.0
    if fielded:
        kept, footprint = _kept(sections, seafloor, avoid, deepest, water, plan["acoustics"]["detection"] == "snr")
    return Resolved(sections, source, items, plan, area, seafloor, avoid, points, kept, footprint)


def _kept(sections: dict, seafloor: Area, avoid: list[Area], deepest: float, water: float, snr: bool = False
          ) -> tuple[np.ndarray, float]:
    """An LBL's transponders in place (k, 3) NED [m] (``candidates.existing_m``, a depth not given the seafloor's)
    and its footprint [m] (``candidates.footprint_m``), checked against the seafloor region, the areas to avoid,
    the vehicle's and the water's depths (at a site whose detection is by signal-to-noise, ``snr``, the seafloor's:
    the search tabulates the site's detection at one transducer depth), and the room left for the transponders
    added.

    Raises
    ------
    ConfigError
        Naming ``candidates.existing_m`` or ``candidates.footprint_m``: a transponder in place outside the region,
        in an area to avoid, not below the deepest vehicle or below the water; no room within the footprint of every
        transponder in place (where one is to be added).
    """
    c = sections["candidates"]
    kept = existing_devices(c["existing_m"])
    kept[:, 2] = np.where(np.isfinite(kept[:, 2]), kept[:, 2], sections["seafloor"]["depth_m"])
    footprint = float(c["footprint_m"])
    for north, east, depth in kept:
        where = f"candidates.existing_m: the transponder at {north:g} m North, {east:g} m East"
        if not seafloor.contains(np.array([north, east])):
            raise ConfigError(f"{where} stands outside the seafloor region (seafloor.*); allowed places inside it")
        for j, area in enumerate(avoid):
            if area.distance(np.array([north, east])) < -1e-9:
                raise ConfigError(f"{where} stands inside an area to avoid (seafloor.avoid[{j}]); allowed places "
                                  "outside them")
        if not depth > deepest or (water > 0.0 and depth > water):
            bottom = f" and the water's {water:g} m (acoustics.water_depth)" if water > 0.0 else ""
            raise ConfigError(f"{where}: its depth {depth:g} m; allowed below the deepest vehicle's {deepest:g} m "
                              f"(work_area.depths_m){bottom}")
        floor = sections["seafloor"]["depth_m"]
        if snr and abs(depth - floor) > 1e-9:
            raise ConfigError(f"{where}: its depth {depth:g} m at a site whose detection is by signal-to-noise; "
                              f"allowed the seafloor's, {floor:g} m (seafloor.depth_m), at which the search tabulates "
                              "the site")
    if footprint > 0.0 and len(kept) and len(kept) < c["transponders"][1] and \
            not room(seafloor, avoid, kept=kept, footprint=footprint):
        raise ConfigError(f"candidates.footprint_m: {footprint:g} m leaves no place in the seafloor region, outside "
                          "the areas to avoid, within it of every transponder in place (candidates.existing_m); "
                          "allowed a larger footprint")
    return kept, footprint


def room(region: Area, avoid: list[Area], count: int = 0, kept: np.ndarray | None = None,
         footprint: float = 0.0) -> bool:
    """Whether a point of a ``count`` × ``count`` grid over the region (default :data:`ROOM_GRID`; its centre and
    vertices too) lies inside it and outside every area to avoid (and, with ``kept`` (k, 2+) and a ``footprint``
    [m], within the footprint of each of those and not at one of their places: the grid then over the part of the
    region's box that is)."""
    count = count or ROOM_GRID
    low, high = region.bounds()
    near = kept is not None and len(kept) and footprint > 0.0
    extra = [region.middle] + ([] if region.vertices is None else list(region.vertices))
    if near:
        low = np.maximum(low, kept[:, :2].max(axis=0) - footprint)
        high = np.minimum(high, kept[:, :2].min(axis=0) + footprint)
        if np.any(low > high):
            return False
    N, E = np.meshgrid(np.linspace(low[0], high[0], count), np.linspace(low[1], high[1], count), indexing="ij")
    points = np.vstack([np.column_stack([N.ravel(), E.ravel()]), np.asarray(extra, dtype=float)])
    points = points[region.contains(points)]
    if near:  # within the footprint of each, and not at one of their places
        gaps = np.hypot(*(points[:, None, :] - kept[None, :, :2]).transpose(2, 0, 1))
        points = points[np.all(gaps <= footprint + 1e-9, axis=1) & np.all(gaps > 1e-6, axis=1)]
    for area in avoid:  # the points left, a chunk at a time (a polygon's distances are points × vertices)
        points = np.concatenate([part[area.distance(part) >= 0.0] for part in np.array_split(
            points, max(1, len(points) // 4096))]) if len(points) else points
    return len(points) > 0


def plan_of(resolved: Resolved, items: list[str]) -> RunPlan:
    """The plan of the base scenario with the problem's and a design's overrides."""
    source = resolved.source
    if isinstance(source, Mapping):
        return make_plan(apply_overrides(thaw(source), [*resolved.items, *items], None))
    return load_plan(source, [*resolved.items, *items])


__all__ = ["ROOM_GRID", "Resolved", "plan_of", "resolve", "room"]
