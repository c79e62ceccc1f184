"""``sblsim design``'s work: from a design problem to its proposed designs, each confirmed by Monte Carlo.

1. **Resolve** the problem (:func:`resolve`): the base scenario's plan, the work area's points at the vehicle's
   depths, the seafloor region and the areas to avoid, what the scenario gives to the keys left at 0 or empty.
2. **Candidates** (:func:`candidates`): per system, every count (LBL transponders) and combination of the grades
   that change that system's accuracy (:data:`~sblsim.orchestrator.design.keys.GRADES`), with its cost,
   in the order of their cost.
3. **Search** each candidate's layout (:mod:`~sblsim.orchestrator.design.search`: an LBL's ring, then its free
   placement started from it; an SBL's arm; a USBL has no layout) for the criterion over the work area, in the order
   of cost, until the cheapest that meets the prescription (every candidate with ``search.pareto``); with
   ``workers`` above 1, that many candidates at once, the result the same as one at a time.
4. **Propose** the best design of each system (the cheapest that meets, else the one of the largest coverage), and
   with ``search.pareto`` every design of the front of cost against the criterion; each is evaluated again through
   the accuracy map itself (:func:`sblsim.orchestrator.maps.point_accuracy`), whose numbers the outputs carry.
5. **Confirm** each proposal by Monte Carlo (:mod:`~sblsim.orchestrator.design.confirm`).
"""

from __future__ import annotations

import itertools
import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from multiprocessing import get_context
from typing import Any, Callable, Mapping

import numpy as np

from sblsim.models.acoustics.channel.interface import FLIGHT_CAPACITY
from sblsim.models.declarations import ModelError
from sblsim.models.design.area import spread
from sblsim.models.design.criteria import ECHO_LIMIT, coverage, criterion
from sblsim.models.errors import ConfigError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.campaign.executors import stop_pool
from sblsim.orchestrator.campaign.worker import watch_parent
from sblsim.orchestrator.cosim.config import apply_overrides, check_site_keys
from sblsim.orchestrator.cosim.plan import RunPlan, load_plan, make_plan, thaw
from sblsim.orchestrator.design.area import Area, existing_devices, polygon, work_area_points
from sblsim.orchestrator.design.evaluate import Detection, LayoutEvaluator, Levels, judged, problem_items
from sblsim.orchestrator.design.keys import GRADES, SYSTEM_NAMES
from sblsim.orchestrator.design.search import Objective, Result, optimise_baseline, optimise_free, optimise_ring
from sblsim.orchestrator.io.progress import Progress, ProgressSpec
from sblsim.orchestrator.maps import diver_depth, point_accuracy

#: The slowest sound speed a slot period is sized for [m/s] (any water; the eigenrays' bending on top: a margin).
SLOWEST_SOUND = 1400.0
#: The quantiles of the DRMS over the work area that a design reports [%].
QUANTILES = (50.0, 95.0)
#: The grid per axis over the seafloor region on which some room outside the areas to avoid must be found.
ROOM_GRID = 201
#: Designs that do not meet and miss the prescription by at most this much more than the nearest one (relatively)
#: are taken as near: the cheapest of them is ranked first (a costlier design is not proposed for a few tenths of a
#: millimetre).
NEAR = 0.01


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


@dataclass
class Candidate:
    """A system with a count and grades, and its cost (the layout is searched)."""

    system: str
    count: int
    grades: dict[str, str]
    cost: float
    order: int = 0
    kept: int = 0

    @property
    def label(self) -> str:
        grades = ", ".join(f"{k} {v}" for k, v in self.grades.items())
        what = f"{self.system.upper()}, {self.count} {SYSTEMS[self.system].marker}"
        what += f" ({self.kept} in place)" if self.kept else ""
        return what + (f", {grades}" if grades else "")

    @property
    def layout(self) -> str:
        """How the system's transducers are placed (:attr:`~sblsim.models.systems.System.design_layout`)."""
        return SYSTEMS[self.system].design_layout


@dataclass
class Design:
    """A candidate's searched layout and its accuracy over the work area.

    Attributes
    ----------
    candidate : Candidate
    items : list of str
        The overrides of the base scenario that make the design (its scenario file's difference).
    transponders : ndarray or None
        An LBL's seafloor positions (n, 3), NED [m].
    baseline : float or None
        An SBL's arm [m].
    value : float
        The criterion (:func:`sblsim.models.design.criteria.criterion`).
    values : dict
        ``drms``, ``drms_3d``, ``log_det``, ``availability`` at the work area's points, (M,) each.
    history : list of float
        The search's best criterion after each generation.
    cycle : float
        The time of one cycle [s].
    evaluated_by : str
        ``map`` (the accuracy map itself) or ``search`` (the search's tables).
    evaluations : int
        The layouts the search evaluated over the work area.
    meets : bool
        Whether it meets every part of the prescription (:meth:`Searcher.judge`).
    coverage : float
        The share of the work area's points that meet the prescription [%].
    feasible : bool
        Every transponder inside the seafloor region and outside the areas to avoid.
    shortfalls : list of dict
        What fails (:func:`shortfalls`); empty where it meets.
    miss : float
        By how much the nearest-to-failing part misses, as a ratio (:func:`shortfalls`; at most 1 where every part
        but the coverage holds).
    """

    candidate: Candidate
    items: list[str]
    transponders: np.ndarray | None
    baseline: float | None
    value: float
    values: dict
    history: list[float]
    cycle: float
    evaluated_by: str = "search"
    evaluations: int = 1
    meets: bool = False
    coverage: float = 0.0
    feasible: bool = True
    shortfalls: list = field(default_factory=list)
    miss: float = 0.0
    name: str = ""
    monte_carlo: list = field(default_factory=list)
    path: list = field(default_factory=list)


def _depth_default(plan: RunPlan) -> float:
    return float(diver_depth(plan)[0])


def resolve(sections: dict, source: Any, scenario_items: list[str] | None = None) -> Resolved:
    """The problem resolved against its base scenario (module docstring, step 1).

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


def candidates(resolved: Resolved) -> list[Candidate]:
    """Every candidate of the problem, in the order of cost (then of the systems, counts and grades as listed).

    With transponders in place (:attr:`Resolved.kept`, k of them), an LBL's counts start at k and only the
    transponders added are paid for."""
    c = resolved.sections["candidates"]
    kept = len(resolved.kept)
    out = []
    for name in [s for s in SYSTEM_NAMES if s in c["systems"]]:
        system = SYSTEMS[name]
        categories = [k for k in system.design_grades if c[k]]
        choices = [[(k, grade, (c[f"{k}_cost"] or [0.0] * len(c[k]))[i]) for i, grade in enumerate(c[k])]
                   for k in categories]
        paid = 0
        if system.design_layout == "seafloor":  # each transponder added paid
            counts = range(max(c["transponders"][0], kept), c["transponders"][1] + 1)
            base, each, paid = 0.0, c["transponder_cost"], kept
        else:  # the system paid: an SBL's beacons on their circle, or one transceiver
            counts = [c["sbl_beacons"] if system.design_layout == "platform" else 1]
            base, each = c.get(f"{name}_cost", 0.0), 0.0
        for count in counts:
            for combo in itertools.product(*choices):
                cost = base + (count - paid) * each + sum(x[2] for x in combo)
                out.append(Candidate(name, count, {k: g for k, g, _ in combo}, float(cost), len(out), paid))
    return sorted(out, key=lambda x: (x.cost, x.order))


def grade_items(candidate: Candidate) -> list[str]:
    """The overrides of a candidate's grades (:data:`~sblsim.orchestrator.design.keys.GRADES`)."""
    return [f"{GRADES[k][g][0]}={GRADES[k][g][1]!r}" for k, g in candidate.grades.items()]


def layout_items(system: str, count: int, transponders: np.ndarray | None = None,
                 baseline: float | None = None) -> list[str]:
    """The overrides of a system's layout (:meth:`~sblsim.models.systems.System.design_items`)."""
    return SYSTEMS[system].design_items(count, transponders, baseline)


def plan_of(resolved: Resolved, items: list[str]) -> RunPlan:
    """The plan of the base scenario with the problem's and a design's overrides."""
    source = resolved.source
    if isinstance(source, Mapping):
        return make_plan(apply_overrides(thaw(source), [*resolved.items, *items], None))
    return load_plan(source, [*resolved.items, *items])


def slot_period(plan: RunPlan, transducers: np.ndarray, points: np.ndarray) -> float:
    """The sampling time a design runs with [s]: the scenario's, or longer where a packet from the farthest
    transducer to the farthest work-area point would stay in flight beyond what the channel holds
    (:data:`~sblsim.models.acoustics.core.FLIGHT_CAPACITY` slots; the straight path at :data:`SLOWEST_SOUND`, two
    legs for two-way ranging and a USBL, the turnaround and three of its jitter's standard deviations on top)."""
    acoustics = plan["acoustics"]
    period = float(plan["simulation"]["sampling_time"])
    legs = 2 if (acoustics["ranging"] == "twtt" or plan.system.measures_direction) else 1
    distance = float(np.max(np.linalg.norm(points[:, None, :] - transducers[None, :, :], axis=-1)))
    turnaround = acoustics["turnaround"] + 3.0 * acoustics["turnaround_sigma"] if legs == 2 else 0.0
    flight = 1.1 * (legs * distance / SLOWEST_SOUND + turnaround)
    return max(period, flight / (FLIGHT_CAPACITY - 1))


def _sampling_items(plan: RunPlan, period: float) -> list[str]:
    """The overrides of a design's longer sampling time ``period`` [s]: it, and the scenario's duration made a whole
    number of it (the next one up), as the run requires."""
    if period == plan["simulation"]["sampling_time"]:
        return []
    items = [f"simulation.sampling_time={period!r}"]
    ratio = float(plan["simulation"]["duration"]) / period
    if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):  # not whole already: the next whole number of them
        items.append(f"simulation.duration={math.ceil(ratio) * period!r}")
    return items


class Searcher:
    """The search of a resolved problem's candidates (module docstring, step 3); one per process.

    Parameters
    ----------
    resolved : Resolved
    counted : callable, optional
        Called with the number of layouts of each evaluation over the work area (the progress).
    """

    def __init__(self, resolved: Resolved, counted: Callable[[int], object] | None = None) -> None:
        self.resolved = resolved
        self.counted = counted
        self._detections: dict = {}

    def detection(self, plan: RunPlan, transducer_depth: float) -> Detection:
        """The site's detection table for transducers at a depth (made once per system and depth)."""
        key = (plan.system.name, plan["acoustics"]["ranging"], round(transducer_depth, 9))
        if key not in self._detections:
            r = self.resolved
            low, high = r.seafloor.bounds()
            wlow, whigh = r.area.bounds()
            corners = np.array([[a, b] for a in (low[0], high[0], wlow[0], whigh[0])
                                for b in (low[1], high[1], wlow[1], whigh[1])])
            reach = float(np.max(np.hypot(*(corners[:, None] - corners[None]).reshape(-1, 2).T)))
            self._detections[key] = Detection(plan, transducer_depth, r.depths, reach)
        return self._detections[key]

    def objective(self, plan: RunPlan, transducer_depth: float) -> Objective:
        r = self.resolved
        detection = self.detection(plan, transducer_depth) if plan["acoustics"]["detection"] == "snr" else None
        loss = plan["acoustics"]["loss_pct"] / 100.0
        evaluator = LayoutEvaluator(r.points, Levels.of(plan), detection, loss,
                                    echo_margin_pct=r.sections["prescription"]["echo_margin_pct"])
        evaluator.counted = self.counted
        s, p = r.sections["search"], r.sections["prescription"]
        return Objective(evaluator, s["criterion"], p["dimensions"], p["coverage_pct"])

    def search(self, candidate: Candidate) -> Design:
        """A candidate's layout searched and its accuracy over the work area (by the search's tables)."""
        r = self.resolved
        s = r.sections["search"]
        grades = grade_items(candidate)
        options = dict(seed=s["seed"], population=s["population"], generations=s["generations"])
        transponders = baseline = None
        history: list[float] = []
        feasible = True
        name, n = candidate.system, candidate.count
        if candidate.layout == "seafloor":
            provisional = plan_of(r, [*layout_items(name, n, _provisional_ring(r, n)), *grades])
            objective = self.objective(provisional, r.seafloor_depth)
            if n == len(r.kept):  # every transponder in place: nothing to search
                transponders = r.kept.copy()
                found = Result(transponders, float(objective.values(transponders[None])[0]), [], np.zeros(0))
            else:
                kept = dict(fixed=r.kept, footprint=r.footprint) if len(r.kept) or r.footprint else {}
                ring_found = optimise_ring(objective, n, r.seafloor, r.avoid, r.seafloor_depth, polish=s["polish"],
                                           **options, **kept)
                found = optimise_free(objective, n, r.seafloor, r.avoid, r.seafloor_depth, polish=s["polish"],
                                      start=ring_found.layout, **options, **kept)
                ring_ok, free_ok = _feasible(ring_found.layout, r), _feasible(found.layout, r)
                if ring_ok and (ring_found.value <= found.value or not free_ok):
                    found = ring_found
                history = ring_found.history + found.history  # neither feasible: the free layout, which cannot meet
            transponders = found.layout
            feasible = _placed(transponders, r.seafloor, r.avoid)  # the footprint: its own part (shortfalls)
            layout = layout_items(name, n, transponders)
            value, values = found.value, objective.evaluator.evaluate(transponders[None])
            positions = transponders
        elif candidate.layout == "platform":
            low, high = r.sections["candidates"]["sbl_baseline_m"]
            provisional = plan_of(r, [*layout_items(name, n, baseline=1.0), *grades])
            unit = np.asarray(provisional.lever_arms, dtype=float)
            objective = self.objective(provisional, float(unit[0, 2]))
            found = optimise_baseline(objective, unit, low, high, **options)
            baseline, history = float(found.variables[0]), found.history
            layout = layout_items(name, n, baseline=baseline)
            value, values = found.value, objective.evaluator.evaluate(found.layout[None])
            positions = found.layout
        else:
            plan = plan_of(r, [*layout_items(name, n), *grades])
            arms = np.asarray(plan.lever_arms, dtype=float)
            detection = None
            if plan["acoustics"]["detection"] == "snr":
                detection = tuple(a[0] for a in self.detection(plan, float(arms[0, 2]))(r.points, arms[None]))
            values = judged(point_accuracy(plan, r.points, detection=detection), r.sections)
            layout, positions = layout_items(name, n), arms
            value = self.criterion(values)
            values = {k: v[None] for k, v in values.items()}
            if self.counted is not None:
                self.counted(1)
        evaluations = objective.evaluator.evaluations if candidate.layout else 1
        plan = plan_of(r, [*layout, *grades])
        period = slot_period(plan, positions, r.points)
        items = [*layout, *grades, *_sampling_items(plan, period)]
        slots = 1 if plan.system.measures_direction else candidate.count
        design = Design(candidate, items, transponders, baseline, float(value), {k: v[0] for k, v in values.items()},
                        history, slots * period, evaluations=evaluations, feasible=feasible)
        self.judge(design)
        return design

    def drms(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """The DRMS of the prescription's dimensions among a design's values (:func:`point_accuracy`'s) [m]."""
        return values["drms" if self.resolved.sections["prescription"]["dimensions"] == "horizontal" else "drms_3d"]

    def criterion(self, values: Mapping[str, np.ndarray]) -> float:
        """The search's criterion of a design's values over the work area."""
        return float(criterion(self.resolved.sections["search"]["criterion"], self.drms(values), values["log_det"],
                               self.resolved.sections["prescription"]["coverage_pct"], values["echo"]))

    def judge(self, design: Design) -> None:
        """Whether a design meets the prescription, and its coverage [%] (from its values)."""
        p = self.resolved.sections["prescription"]
        drms = self.drms(design.values)
        design.coverage = float(coverage(drms, design.values["availability"], p["drms_m"], p["availability_pct"],
                                         design.values["echo"]))
        design.shortfalls, design.miss = shortfalls(design, drms, p, self.resolved.points, self.resolved.seafloor,
                                                    self.resolved.footprint)
        design.meets = not design.shortfalls

    def on_the_map(self, design: Design) -> None:
        """A design evaluated again through the accuracy map itself (:func:`point_accuracy`), and judged."""
        r = self.resolved
        plan = plan_of(r, design.items)
        design.values = judged(point_accuracy(plan, r.points), r.sections)
        design.value = self.criterion(design.values)
        design.evaluated_by = "map"
        self.judge(design)


def shortfalls(design: Design, drms: np.ndarray, prescription: Mapping[str, Any], points: np.ndarray | None = None,
               seafloor: Area | None = None, footprint: float = 0.0) -> tuple[list[dict], float]:
    """What of the prescription a design fails, and by how much.

    The parts: the transponders' places (``transponders``: inside the seafloor region, outside the areas to avoid),
    their ``footprint`` (the largest distance between two of them against ``footprint`` [m], where it is given),
    the ``coverage`` (the share of the work area's points that meet; below ``coverage_pct`` it fails, and the line
    says why: the ``drms`` at the coverage's percentile of the points, a point without a fix of direct rays counting
    as infinite, above ``drms_m``; the ``availability`` that that share of the points reaches, below
    ``availability_pct``) and the ``cycle`` (above ``update_interval_s``). Where no point has a fix, the DRMS clause
    names how far the work area's ``points`` (M, 3) NED [m] lie from the nearest transponder and how far the
    ``seafloor`` region reaches from its middle (a work area beyond the site's reach, said in the user's terms).

    Returns
    -------
    list of dict
        Each failing part: ``part``, ``required``, ``achieved`` (in the prescription's units: m, %, s) and ``text``
        (one clause); empty where the design meets.
    float
        The largest ratio by which a part misses (achieved over required for the DRMS and the cycle, required over
        achieved for the availability; ``inf`` for misplaced transponders or no fix): the nearer to 1, the nearer
        the design is to meeting.
    """
    out: list[dict] = []
    share = prescription["coverage_pct"]
    values = np.where(np.isfinite(drms) & (design.values["echo"] <= ECHO_LIMIT), drms, np.inf)
    at = float(np.percentile(values, share, method="higher"))
    reached = 100.0 * float(np.percentile(design.values["availability"], 100.0 - share, method="lower"))
    ratios = [at / prescription["drms_m"]]
    ratios.append(prescription["availability_pct"] / reached if reached > 0.0 else
                  (math.inf if prescription["availability_pct"] > 0.0 else 0.0))
    wide = footprint > 0.0 and design.transponders is not None and float(spread(design.transponders[:, :2])) > \
        footprint + 1e-6
    if not design.feasible:
        out.append({"part": "transponders", "required": 0.0, "achieved": 1.0,
                    "text": "a transponder outside the seafloor region or in an area to avoid"})
        ratios.append(math.inf)
    if wide:
        achieved = float(spread(design.transponders[:, :2]))
        out.append({"part": "footprint", "required": footprint, "achieved": achieved,
                    "text": f"the transponders spread over {achieved:.4g} m against the footprint of {footprint:g} m"})
        ratios.append(achieved / footprint)
    if design.coverage < share - 1e-9:
        out.append({"part": "coverage", "required": share, "achieved": design.coverage,
                    "text": f"coverage {design.coverage:.1f} % of the work area against {share:g} %"})
        if at > prescription["drms_m"]:
            how = ("no fix of direct rays there" + _reach(design, drms, points, seafloor) if not math.isfinite(at) else
                   f"{at:.3g} m against {prescription['drms_m']:g} m, {100.0 * (at / prescription['drms_m'] - 1.0):.0f}"
                   " % above")
            out.append({"part": "drms", "required": prescription["drms_m"], "achieved": at,
                        "text": f"DRMS at {share:g} % of the work area {how}"})
        if reached < prescription["availability_pct"] - 1e-9:
            out.append({"part": "availability", "required": prescription["availability_pct"], "achieved": reached,
                        "text": f"availability at {share:g} % of the work area {reached:.1f} % against "
                                f"{prescription['availability_pct']:g} %, "
                                f"{prescription['availability_pct'] - reached:.1f} points short"})
    interval = prescription["update_interval_s"]
    if interval > 0.0:
        ratios.append(design.cycle / interval)
        if design.cycle > interval + 1e-9:
            out.append({"part": "cycle", "required": interval, "achieved": design.cycle,
                        "text": f"cycle {design.cycle:.3g} s against {interval:g} s"})
    return out, max(ratios)


def _reach(design: Design, drms: np.ndarray, points: np.ndarray | None, seafloor: Area | None) -> str:
    """Where no point of the work area has a fix: how far it lies from the transponders, and the seafloor region's
    reach (a clause for :func:`shortfalls`; empty where some point has a fix or nothing is known)."""
    if points is None or design.transponders is None or np.isfinite(drms).any():
        return ""
    gap = float(np.min(np.hypot(*(points[:, None, :2] - design.transponders[None, :, :2]).transpose(2, 0, 1))))
    where = "" if seafloor is None else (
        f", the seafloor region reaching {seafloor.reach / 1000.0:.3g} km from its middle "
        f"({seafloor.middle[0] / 1000.0:.3g}, {seafloor.middle[1] / 1000.0:.3g}) km North, East")
    return f" (the work area's nearest point {gap / 1000.0:.3g} km from the nearest transponder{where})"


def ranked(designs: list[Design]) -> list[Design]:
    """Designs best first: those that meet, cheapest first (then by criterion); then the others by coverage, and
    among the same coverage by how much they miss (:attr:`Design.miss`), those within :data:`NEAR` of the nearest
    cheapest first."""
    meeting = sorted((d for d in designs if d.meets), key=lambda d: (d.candidate.cost, d.value, d.candidate.order))
    rest = sorted((d for d in designs if not d.meets),
                  key=lambda d: (-d.coverage, d.miss, d.candidate.cost, d.candidate.order))
    out = meeting
    while rest:
        top = rest[0]
        near = [d for d in rest if d.coverage == top.coverage and (d.miss <= top.miss * (1.0 + NEAR))]
        out = out + sorted(near, key=lambda d: (d.candidate.cost, d.miss, d.candidate.order))
        taken = {id(d) for d in near}
        rest = [d for d in rest if id(d) not in taken]
    return out


def _provisional_ring(r: Resolved, n: int) -> np.ndarray:
    """A ring of n transponders inside the seafloor region (the plan of a candidate before its layout is known)."""
    centre = r.seafloor.middle
    angle = 2.0 * math.pi * np.arange(n) / n
    return np.column_stack([centre[0] + np.cos(angle), centre[1] + np.sin(angle), np.full(n, r.seafloor_depth)])


def _feasible(layout: np.ndarray, r: Resolved) -> bool:
    """Every transponder inside the seafloor region and outside the areas to avoid (their boundaries allowed), and
    within the footprint (:attr:`Resolved.footprint`) of one another."""
    return _placed(layout, r.seafloor, r.avoid) and not (r.footprint > 0.0 and float(spread(layout[:, :2])) >
                                                          r.footprint + 1e-6)


def _placed(layout: np.ndarray, seafloor: Area | None, avoid: list[Area]) -> bool:
    """Every transponder inside the seafloor region (where known) and outside the areas to avoid."""
    xy = layout[:, :2]
    inside = seafloor is None or bool(np.all(seafloor.contains(xy)))
    return inside and all(np.all(a.distance(xy) >= -1e-9) for a in avoid)


_WORKER: Searcher | None = None


def _start_worker(resolved: Resolved, parent: int) -> None:
    """A worker process's searcher (it exits as soon as the design's process is gone)."""
    global _WORKER
    watch_parent(parent)
    _WORKER = Searcher(resolved)


def _search_in_worker(candidate: Candidate) -> Design:
    return _WORKER.search(candidate)


@dataclass
class DesignRun:
    """What a design problem gave: its resolution, every candidate searched (in the order of cost) and the
    proposed designs (best first)."""

    resolved: Resolved
    searched: list[Design]
    proposed: list[Design]

    @property
    def best(self) -> Design:
        return self.proposed[0]


def search_all(resolved: Resolved, workers: int = 1, progress: ProgressSpec = False, layouts: int = 0) -> DesignRun:
    """Steps 3 and 4 of the module docstring: the candidates searched in the order of cost, the proposals made and
    evaluated on the map.

    ``progress`` reports the layouts evaluated against ``layouts``, the most the search evaluates
    (:func:`~sblsim.orchestrator.design.effort.estimate`; the search may stop before), or the candidates searched
    where ``layouts`` is 0."""
    todo = candidates(resolved)
    pareto = resolved.sections["search"]["pareto"]
    searched: list[Design] = []
    bar = Progress(layouts or len(todo), "design", "layout" if layouts else "candidate", progress)
    searcher = Searcher(resolved, bar.update if layouts and bar.active else None)
    pool, finished = None, False
    if workers > 1 and len(todo) > 1:
        pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=_start_worker,
                                   initargs=(resolved, os.getpid()))
    try:
        met_cost = math.inf
        start = 0
        while start < len(todo):
            batch = [c for c in todo[start:start + (workers if pool else 1)]]
            results = list(pool.map(_search_in_worker, batch)) if pool else [searcher.search(c) for c in batch]
            for design in results:
                if not pareto and design.candidate.cost > met_cost:
                    break  # the sequential search would have stopped before it
                if design.meets:  # a table's verdict, checked on the map itself
                    searcher.on_the_map(design)
                searched.append(design)
                if not layouts or pool is not None:  # a worker's evaluations counted when its candidate is done
                    bar.update(design.evaluations if layouts else 1)
                if design.meets:
                    met_cost = min(met_cost, design.candidate.cost)
            start += len(batch)
            if not pareto and todo[start:start + 1] and todo[start].cost > met_cost:
                break
        finished = True
    finally:
        if pool is not None and finished:
            pool.shutdown(cancel_futures=True)
        elif pool is not None:  # interrupted or failed: the candidates under way stopped at once
            stop_pool(pool)
        bar.close()
    proposed = []
    for system in SYSTEM_NAMES:
        mine = [d for d in searched if d.candidate.system == system]
        if mine:
            proposed.append(ranked(mine)[0])
    if pareto:
        proposed += [d for d in pareto_front(searched) if d not in proposed]
    for design in proposed:
        if design.evaluated_by != "map":
            searcher.on_the_map(design)
    proposed = ranked(proposed)
    names = set()
    for design in proposed:
        design.name = _name(resolved.sections["design"]["name"], design, names)
    return DesignRun(resolved, searched, proposed)


def pareto_front(designs: list[Design]) -> list[Design]:
    """The designs that no other beats in both cost and criterion (the Pareto front), by cost."""
    front = [d for d in designs if not any(o.candidate.cost <= d.candidate.cost and o.value <= d.value and
                                           (o.candidate.cost < d.candidate.cost or o.value < d.value)
                                           for o in designs)]
    return sorted(front, key=lambda d: (d.candidate.cost, d.value))


def _name(stem: str, design: Design, taken: set) -> str:
    c = design.candidate
    name = f"{stem}-{c.system}" + (f"{c.count}" if c.layout == "seafloor" else "")
    base, k = name, 2
    while name in taken:
        name, k = f"{base}-{k}", k + 1
    taken.add(name)
    return name


def quantiles(design: Design, dimensions: str) -> dict[str, float]:
    """The DRMS over the work area (``drms_p50_m``, ``drms_p95_m``, ``drms_max_m``) [m]; a point without a fix
    counts as an infinite DRMS (then ``inf``)."""
    drms = design.values["drms" if dimensions == "horizontal" else "drms_3d"]
    drms = np.where(np.isfinite(drms), drms, np.inf)
    out = {f"drms_p{q:g}_m": float(np.percentile(drms, q, method="higher")) for q in QUANTILES}
    out["drms_max_m"] = float(drms.max())
    return out


__all__ = ["Candidate", "Design", "DesignRun", "NEAR", "QUANTILES", "ROOM_GRID", "Resolved", "SLOWEST_SOUND",
           "Searcher", "candidates", "grade_items", "layout_items", "pareto_front", "plan_of", "quantiles", "ranked",
           "resolve", "room", "search_all", "shortfalls", "slot_period"]
