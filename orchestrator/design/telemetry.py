"""``sblsim design`` of a telemetry array (``candidates.systems = ["ilbl"]``): how many receivers (hydrophones) to
moor, and where in the water, so that a tag's pings are positioned to the prescription; each proposal confirmed by
simulated tags.

1. **Resolve** (:func:`resolve`): the water (``[site.area]``: a polygon, or a CSV or GeoJSON file), the work area's
   points (a grid over the water, or over ``work_area.polygon`` within it), the places a receiver may go (a finer
   grid over the water, ``site.area.min_shore_m`` / ``max_shore_m`` from the shore), the detection range curve
   (``[detection]``) and the timing σ = c σ_toa.
2. **Search** each receiver count from ``candidates.receivers``' fewest (:func:`search_count`): the layout starts
   as the k-means centres of the work area's points, then a seeded local search moves one receiver at a time to
   another place; every place is a point of the grid of allowed places, so **no receiver is ever outside the
   water**. The search's criterion is smooth and cheap: per point, the DRMS of the information averaged over the
   detections (:func:`~sblsim.models.design.telemetry.expected_information_drms`) over the prescription's DRMS,
   plus 10 × the positioning yield's shortfall, at the prescription's coverage percentile (plus a tenth of its
   mean), plus the sync graph's shortfall (receivers hearing fewer than two sync tags, parts beyond one).
   Receivers already moored (``candidates.existing_m``) are in every layout, first, and only the others are
   placed and paid for; a footprint (``candidates.footprint_m``) keeps the places within it of every receiver in
   place and penalises a layout whose spread exceeds it.
3. **Judge** (:func:`judge`) with the criteria of the field: the positioning yield (a ping heard by ≥ 3 receivers,
   the exact Poisson-binomial), the DRMS as the RMS over the pings that are fixed
   (:func:`~sblsim.models.design.telemetry.fixed_ping_drms`, what single-ping fixes measure) and the sync coverage
   (every receiver hears two other receivers' sync tags with probability ≥ ``detection.sync_p``, the sync graph
   connected). A point meets where its DRMS is at most ``prescription.drms_m`` and its yield at least
   ``prescription.positioning_yield_pct``; the design meets where ``coverage_pct`` of the points do and the sync
   graph is met. The counts are searched in order until one meets (every count with ``search.pareto``).
4. **Confirm** (:func:`confirm`): tags at the work area's worst and median points ping
   (:func:`~sblsim.models.tracking.simulate.simulate_pings`, random burst intervals), each receiver hears each
   ping with the curve's probability at its distance, and each ping heard by ≥ 3 receivers is fixed by least
   squares with its emission time unknown (:func:`fixes`): the simulated yield and DRMS beside the predicted;
   with ``monte_carlo.path``, the same along an animal's correlated random walk through the work area
   (:func:`path_check`), whose pings are also tracked as a recorded tag's are, against the tracker's smoothing
   bound (:func:`~sblsim.orchestrator.design.telemetry_tracking.track_path`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
from scipy.spatial import cKDTree

from sblsim.models.design import area as areas
from sblsim.models.design import telemetry as tm
from sblsim.models.errors import ConfigError, ModelError
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.simulate import simulate_pings
from sblsim.orchestrator.design.area_file import read_area
from sblsim.orchestrator.design.effort import Estimate
from sblsim.orchestrator.design.problem import existing_devices, is_three_d, polygon, receiver_curves
from sblsim.orchestrator.design.telemetry_tracking import SYNC_STREAM, track_path, track_synchronised

#: The places a receiver may go: about this many grid points over the water.
SITE_POINTS = 4000
#: Local-search moves per receiver count: ``search.generations`` times this.
MOVES_PER_GENERATION = 5
#: Patterns per point of the fixed pings' Monte Carlo, where the enumeration does not reach.
PATTERN_SAMPLES = 400
#: Pings simulated at a checked point: ``monte_carlo.replicates`` times this.
PINGS_PER_REPLICATE = 25
#: The tag's random burst interval [s] of the confirmation (the single ping's criteria do not depend on it).
BURST_INTERVAL = (20.0, 40.0)
#: Seconds per layout, point and receiver of the search's criterion (0.5 µs measured), of the judgement (40 µs
#: measured: the fixed pings' patterns) and per simulated ping fixed.
SEARCH_SECONDS, JUDGE_SECONDS, PING_SECONDS = 1.0e-6, 1.0e-4, 1.0e-3
#: The path's animal: its speed [m/s] and the standard deviation of its turn per ping [rad]; the positions of the
#: path at which the prediction is made.
WALK_SPEED, WALK_TURN, PATH_PREDICTED = 0.3, 0.5, 200
#: A simulated yield within this many percentage points of the predicted is confirmed.
YIELD_TOLERANCE_PP = 5.0
#: The search's criterion grows by this times the share by which a layout's spread exceeds the footprint.
FOOTPRINT_PENALTY = 10.0
#: In 3-D, the walk's tag swims between the work area's shallowest and deepest depths as a sine of this period [s].
DEPTH_PERIOD = 3600.0
#: In 3-D a simulated ping's fix more than this above the surface [m] is discarded (a fish is below it; the margin
#: keeps a shallow tag's fixes whose depth errs upward).
SURFACE_MARGIN = 1.0


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


@dataclass
class TelemetryDesign:
    """A receiver count's searched layout and its criteria at the work area's points."""

    count: int
    cost: float
    receivers: np.ndarray
    value: float
    history: list = field(default_factory=list)
    evaluations: int = 0
    positioning_yield: np.ndarray | None = None
    drms_expected: np.ndarray | None = None
    drms_fixed: np.ndarray | None = None
    fixable: np.ndarray | None = None
    sync: Any = None
    coverage: float = 0.0
    shortfalls: list = field(default_factory=list)
    miss: float = math.inf
    meets: bool = False
    name: str = ""
    monte_carlo: list = field(default_factory=list)
    path: list = field(default_factory=list)
    kept: int = 0

    @property
    def label(self) -> str:
        return f"ILBL, {self.count} receivers" + (f" ({self.kept} in place)" if self.kept else "")


@dataclass
class TelemetryRun:
    """What a telemetry design gave: the problem, every count searched and the proposed designs (best first)."""

    resolved: TelemetryProblem
    searched: list
    proposed: list

    @property
    def best(self) -> TelemetryDesign:
        return self.proposed[0]


def water_polygon(section: Mapping[str, Any]):
    """The water of a checked ``[site.area]`` section, (North, East) [m]."""
    if section["file"]:
        return read_area(section["file"])
    try:
        return areas.polygon(polygon(section["polygon"], "site.area.polygon"), "site.area.polygon")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def sync_hearing(receivers: np.ndarray, curve: Any) -> np.ndarray:
    """(..., n, n) [0–1], ``[i, j]`` the probability that receiver ``i`` hears the sync tag moored at receiver ``j``
    with receiver ``i``'s own curve (``detection.per_receiver``), else the site's; its own tag 0
    (:func:`~sblsim.models.design.telemetry.sync_probabilities`, whose curve is applied along the tags' axis:
    transposed, which changes nothing where every receiver hears with the site's curve)."""
    return tm.sync_probabilities(receivers, curve.probability).swapaxes(-1, -2)


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
    sites = areas.grid(water, step, site["min_shore_m"])
    if max_shore is not None:
        sites = sites[areas.inside(water, sites, site["min_shore_m"], max_shore)]
    most = sections["candidates"]["receivers"][1]
    if len(sites) < most:
        raise ConfigError(f"site.area.min_shore_m: {len(sites)} places for a receiver within the shore distances, "
                          f"fewer than candidates.receivers' most ({most}); allowed distances that leave room")
    sites = _kept_sites(sections, water, sites, step)
    curve = receiver_curves(sections)
    sigma = sections["detection"]["sound_speed"] * sections["detection"]["sigma_toa_s"]
    return TelemetryProblem(sections, water, work, points, sites, curve, float(sigma),
                            float(sections["detection"]["range_k"]), depths)


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


class _Objective:
    """The search's criterion of a layout (module docstring, step 2)."""

    def __init__(self, problem: TelemetryProblem) -> None:
        self.problem = problem
        self.evaluations = 0

    def __call__(self, receivers: np.ndarray) -> float:
        p = self.problem
        self.evaluations += 1
        d = tm.distances(p.points, receivers)
        q = p.curve.probability(d)
        drms = tm.expected_information_drms(p.points, receivers, tm.range_sigma(d, p.sigma_m, p.sigma_per_m), q,
                                            p.depth_sigma, p.horizontal)
        score = np.minimum(np.where(np.isfinite(drms), drms, np.inf) / p.prescription["drms_m"], 1e3)
        score = score + 10.0 * np.maximum(0.0, p.required_yield - tm.positioning_yield(q, p.needed))
        value = float(np.percentile(score, p.prescription["coverage_pct"]) + 0.1 * np.mean(score))
        sync = tm.sync_coverage(sync_hearing(receivers, p.curve),
                                p.sections["detection"]["sync_p"])
        return value + 5.0 * (1.0 - float(sync.share)) + 5.0 * (int(sync.components) - 1)


def search_count(problem: TelemetryProblem, count: int, rng: np.random.Generator) -> TelemetryDesign:
    """A count's layout (module docstring, step 2), judged (:func:`judge`). The receivers in place
    (:attr:`TelemetryProblem.kept`) are in every layout, first, and only the others are placed and paid for; with a
    footprint (:attr:`TelemetryProblem.footprint`) the placed start within half of it of the middle of those in
    place (or of the work area) and the criterion grows by :data:`FOOTPRINT_PENALTY` times the share by which the
    layout's spread exceeds it."""
    sections = problem.sections
    kept, footprint = problem.kept, problem.footprint
    placed = count - len(kept)
    c = sections["candidates"]
    cost = placed * (c["receiver_cost"] + c["sync_tag_cost"])
    objective = _Objective(problem)

    def value_of(receivers: np.ndarray) -> float:
        value = objective(receivers)
        if footprint > 0.0:
            value += FOOTPRINT_PENALTY * max(0.0, float(areas.spread(receivers[:, :2])) / footprint - 1.0)
        return value

    if placed == 0:  # every receiver in place: nothing to search
        design = TelemetryDesign(count, cost, kept.copy(), value_of(kept), [], objective.evaluations, kept=len(kept))
        judge(design, problem, rng)
        return design
    tree = cKDTree(problem.sites)
    flat = problem.points[:, :2]  # the work area's horizontal points (each once per depth in 3-D)
    pool = flat
    if footprint > 0.0:
        middle = 0.5 * (kept[:, :2].min(axis=0) + kept[:, :2].max(axis=0)) if len(kept) else flat.mean(axis=0)
        pool = flat[np.linalg.norm(flat - middle, axis=1) <= 0.5 * footprint]
        if len(pool) < placed:
            pool = problem.sites[np.argsort(np.linalg.norm(problem.sites - middle, axis=1), kind="stable")[:placed]]
    chosen = pool[rng.choice(len(pool), size=min(placed, len(pool)), replace=False)]
    if len(chosen) < placed:
        chosen = np.vstack([chosen, problem.sites[rng.choice(len(problem.sites), placed - len(chosen), False)]])
    centres = np.vstack([kept[:, :2], chosen])
    for _ in range(30):  # Lloyd's iterations over the work area's points, the receivers in place held
        label = np.argmin(np.linalg.norm(pool[:, None] - centres[None], axis=-1), axis=1)
        for k in range(len(kept), count):
            if np.any(label == k):
                centres[k] = pool[label == k].mean(axis=0)
    chosen = centres[len(kept):]
    index = _distinct(tree.query(chosen)[1], tree, chosen)
    best = value_of(problem.layout(kept, problem.sites[index]))
    history = [best]
    x0, y0, x1, y1 = problem.water.bounds
    reach = 0.25 * max(x1 - x0, y1 - y0)
    step = math.sqrt(problem.water.area / SITE_POINTS)
    moves = sections["search"]["generations"] * MOVES_PER_GENERATION
    for move in range(moves):
        radius = max(2.0 * step, reach * (1.0 - move / moves))
        k = int(rng.integers(placed))
        target = problem.sites[index[k]] + rng.uniform(-radius, radius, 2)
        place = int(tree.query(target)[1])
        if place in index:
            continue
        trial = index.copy()
        trial[k] = place
        value = value_of(problem.layout(kept, problem.sites[trial]))
        if value < best:
            index, best = trial, value
        if (move + 1) % MOVES_PER_GENERATION == 0:
            history.append(best)
    design = TelemetryDesign(count, cost, problem.layout(kept, problem.sites[index]), best, history,
                             objective.evaluations, kept=len(kept))
    judge(design, problem, rng)
    return design


def _distinct(index: np.ndarray, tree: cKDTree, wanted: np.ndarray) -> np.ndarray:
    """Grid places, one per receiver, none twice (a repeated one moved to its nearest free place)."""
    out, taken = [], set()
    for k, i in enumerate(index):
        if int(i) in taken:
            for j in tree.query(wanted[k], k=min(64, tree.n))[1]:
                if int(j) not in taken:
                    i = j
                    break
        taken.add(int(i))
        out.append(int(i))
    return np.asarray(out, dtype=np.int64)


def judge(design: TelemetryDesign, problem: TelemetryProblem, rng: np.random.Generator) -> None:
    """A layout's criteria at the work area's points, and what of the prescription it fails (module docstring,
    step 3)."""
    p = problem.prescription
    receivers = design.receivers
    d = tm.distances(problem.points, receivers)
    q = problem.curve.probability(d)
    sigma = tm.range_sigma(d, problem.sigma_m, problem.sigma_per_m)
    design.positioning_yield = tm.positioning_yield(q, problem.needed)
    design.drms_expected = tm.expected_information_drms(problem.points, receivers, sigma, q, problem.depth_sigma,
                                                        problem.horizontal)
    design.drms_fixed, design.fixable = fixed_pings(problem.points, receivers, sigma, q, p["fix_gate_m"], rng,
                                                    needed=problem.needed, depth_sigma_m=problem.depth_sigma,
                                                    horizontal=problem.horizontal)
    design.sync = tm.sync_coverage(sync_hearing(receivers, problem.curve),
                                   problem.sections["detection"]["sync_p"])
    drms = np.where(np.isfinite(design.drms_fixed), design.drms_fixed, np.inf)
    good = (drms <= p["drms_m"]) & (design.positioning_yield >= problem.required_yield - 1e-12)
    design.coverage = 100.0 * float(np.mean(good))
    design.shortfalls, design.miss = shortfalls(design, problem)
    design.meets = not design.shortfalls


def fixed_pings(points: np.ndarray, receivers: np.ndarray, sigma_m, q: np.ndarray, gate_m: float,
                rng: np.random.Generator, samples: int = PATTERN_SAMPLES, needed: int = 3,
                depth_sigma_m: float | None = None, horizontal: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The RMS over the fixes that count of each detection pattern's DRMS, and the probability that a ping gives
    one: :func:`~sblsim.models.design.telemetry.fixed_ping_drms` where ``gate_m`` is 0 and ``needed`` 3, else the
    same over the patterns of at least ``needed`` receivers whose own DRMS is at most ``gate_m`` (a fix of a worse
    geometry is discarded, as a filter on the estimated horizontal position error discards it; 0: any), its
    patterns enumerated or drawn alike. Points and receivers (M, dim), (n, dim) [m] in 2-D or 3-D;
    ``depth_sigma_m`` and ``horizontal`` as :func:`~sblsim.models.design.telemetry.fix_drms` takes them (3-D: the
    depth sensor's σ [m], None for none; the DRMS of North and East or of all axes).

    Returns
    -------
    rms : ndarray, shape (M,)
        [m]; ``inf`` where no fix counts.
    fixed : ndarray, shape (M,)
        [0–1].
    """
    if gate_m <= 0.0 and needed <= 3:
        return tm.fixed_ping_drms(points, receivers, sigma_m, q, rng, samples, depth_sigma_m, horizontal)
    m, n = len(points), len(receivers)
    q = np.broadcast_to(np.asarray(q, float), (m, n))
    sigma = np.broadcast_to(np.asarray(sigma_m, float), (m, n))
    rms, fixed = np.full(m, np.inf), np.zeros(m)
    uncertain = (q > tm.CERTAIN) & (q < 1.0 - tm.CERTAIN)
    for j in range(m):
        free = np.flatnonzero(uncertain[j])
        if len(free) <= tm.ENUMERATE_MAX:
            bits = ((np.arange(2 ** len(free))[:, None] >> np.arange(len(free))) & 1).astype(bool)
            patterns = np.broadcast_to(q[j] >= 1.0 - tm.CERTAIN, (len(bits), n)).copy()
            patterns[:, free] = bits
            weight = np.prod(np.where(bits, q[j, free], 1.0 - q[j, free]), axis=1)
        else:
            patterns = rng.random((samples, n)) < q[j]
            weight = np.full(samples, 1.0 / samples)
        value = tm.fix_drms(points[j:j + 1], receivers, sigma[j], patterns[:, None, :], depth_sigma_m,
                            horizontal)[:, 0]
        ok = np.isfinite(value) & (patterns.sum(axis=1) >= needed) & ((value <= gate_m) if gate_m > 0.0 else True)
        fixed[j] = weight[ok].sum()
        if fixed[j] > 0.0:
            rms[j] = np.sqrt((weight[ok] * value[ok] ** 2).sum() / fixed[j])
    return rms, fixed


def shortfalls(design: TelemetryDesign, problem: TelemetryProblem) -> tuple[list[dict], float]:
    """What of the prescription a telemetry design fails, and by how much (the parts: ``receivers`` outside the
    water, ``coverage``, ``drms`` and ``positioning_yield`` at the coverage's percentile of the points,
    ``sync_coverage``); and the largest ratio by which a part misses."""
    p = problem.prescription
    share = p["coverage_pct"]
    out: list[dict] = []
    drms = np.where(np.isfinite(design.drms_fixed), design.drms_fixed, np.inf)
    at = float(np.percentile(drms, share, method="higher"))
    reached = 100.0 * float(np.percentile(design.positioning_yield, 100.0 - share, method="lower"))
    required = p["positioning_yield_pct"]
    ratios = [at / p["drms_m"], required / reached if reached > 0.0 else (math.inf if required > 0.0 else 0.0)]
    if not np.all(areas.inside(problem.water, design.receivers[:, :2])):
        out.append({"part": "receivers", "required": 0.0, "achieved": 1.0, "text": "a receiver outside the water"})
        ratios.append(math.inf)
    if design.coverage < share - 1e-9:
        out.append({"part": "coverage", "required": share, "achieved": design.coverage,
                    "text": f"coverage {design.coverage:.1f} % of the work area against {share:g} %"})
        if at > p["drms_m"]:
            how = ("no fixed ping there" if not math.isfinite(at) else
                   f"{at:.3g} m against {p['drms_m']:g} m, {100.0 * (at / p['drms_m'] - 1.0):.0f} % above")
            out.append({"part": "drms", "required": p["drms_m"], "achieved": at,
                        "text": f"DRMS of the fixed pings at {share:g} % of the work area {how}"})
        if reached < required - 1e-9:
            out.append({"part": "positioning_yield", "required": required, "achieved": reached,
                        "text": f"positioning yield at {share:g} % of the work area {reached:.1f} % against "
                                f"{required:g} %"})
    spread = float(areas.spread(design.receivers[:, :2]))
    if problem.footprint > 0.0 and spread > problem.footprint + 1e-6:
        out.append({"part": "footprint", "required": problem.footprint, "achieved": spread,
                    "text": f"the receivers spread over {spread:.4g} m against the footprint of "
                            f"{problem.footprint:g} m"})
        ratios.append(spread / problem.footprint)
    sync = design.sync
    if not bool(sync.met):
        sync_share = 100.0 * float(sync.share)
        out.append({"part": "sync_coverage", "required": 100.0, "achieved": sync_share,
                    "text": f"sync coverage: {sync_share:.0f} % of the receivers hear {tm.SYNC_NEEDED} other sync "
                            f"tags with probability >= {problem.sections['detection']['sync_p']:g}, the sync graph "
                            f"in {int(sync.components)} part(s)"})
        ratios.append(100.0 / sync_share if sync_share > 0.0 else math.inf)
    return out, max(ratios)


def ranked(designs: list[TelemetryDesign]) -> list[TelemetryDesign]:
    """Designs best first: those that meet, cheapest first; then the others by coverage and how near they come."""
    meeting = sorted((d for d in designs if d.meets), key=lambda d: (d.cost, d.value))
    rest = sorted((d for d in designs if not d.meets), key=lambda d: (-d.coverage, d.miss, d.cost))
    return meeting + rest


def search_all(problem: TelemetryProblem, progress: Any = None) -> TelemetryRun:
    """The receiver counts searched for the fewest that meets: the most first (none meets: the best of it is
    proposed), then by bisection between the fewest and the most, taking meeting as growing with the count (more
    receivers hear more); with ``search.pareto``, every count in order, each proposed. Each count's search is
    seeded by ``search.seed`` and the count alone, so the counts searched do not change one another's layout."""
    sections = problem.sections
    low, high = sections["candidates"]["receivers"]
    low = max(low, len(problem.kept))  # the receivers in place, at least
    done: dict[int, TelemetryDesign] = {}

    def searched_at(count: int) -> TelemetryDesign:
        if count not in done:
            done[count] = search_count(problem, count, np.random.default_rng([sections["search"]["seed"], count]))
            if progress is not None:
                progress(1)
        return done[count]

    if sections["search"]["pareto"]:
        for count in range(low, high + 1):
            searched_at(count)
    elif searched_at(high).meets:
        lo, hi = low - 1, high  # hi meets; lo does not (or is below the fewest)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if searched_at(mid).meets:
                hi = mid
            else:
                lo = mid
    searched = [done[k] for k in sorted(done)]
    proposed = ranked(searched) if sections["search"]["pareto"] else ranked(searched)[:1]
    for design in proposed:
        design.name = f"{sections['design']['name']}-ilbl{design.count}"
    return TelemetryRun(problem, searched, proposed)


# --------------------------------------------------------------------------- confirmation by simulated tags

def checked_points(design: TelemetryDesign, problem: TelemetryProblem) -> list[tuple[str, int]]:
    """The work area's worst point (the largest finite DRMS of the fixed pings) and its median point."""
    drms = design.drms_fixed
    finite = np.flatnonzero(np.isfinite(drms) & (design.fixable > 0.0))
    if not len(finite):
        return []
    order = finite[np.argsort(drms[finite], kind="stable")]
    return [("worst", int(order[-1])), ("median", int(order[(len(order) - 1) // 2]))]


def fixes(receivers: np.ndarray, toa: np.ndarray, sound_speed: float, water: Any = None,
          iterations: int = 30, sigma_m: np.ndarray | None = None, depth: np.ndarray | None = None,
          depth_weight: float = 1.0) -> np.ndarray:
    """Each ping's position [m] from its times of arrival at the receivers that heard it (NaN: not heard), the
    emission unknown: least squares on ``‖p − r_i‖ + c t_e = c toa_i`` over the receivers that heard, by
    Gauss-Newton from several starts at once (the centroid of those receivers, each receiver, a 5 × 5 grid over the
    receivers' box grown by half, in 3-D at three depths over their depths grown by half), the solution of the
    least residual in the ``water`` kept (a tie, as the two exact solutions three receivers can give: the nearest
    that centroid); NaN where no start converges in the water (a fix on land, or in 3-D more than
    :data:`SURFACE_MARGIN` above the surface, is discarded). In 3-D (receivers (North, East, depth), depth positive
    down) a depth sensor's ``depth`` reading is one more row, ``depth_weight (depth − z)``.

    Parameters
    ----------
    receivers : ndarray, shape (n, dim)
        [m]; dim 2 or 3.
    toa : ndarray, shape (K, n)
        [s]; NaN where not heard.
    sound_speed : float
        [m/s].
    water : shapely Polygon, optional
    iterations : int, optional
    sigma_m : ndarray, broadcastable to (K, n), optional
        Each arrival's standard deviation [m] where it differs between receivers (a range-dependent noise,
        ``detection.range_k``): each residual weighted by the smallest over it (None: every arrival alike).
    depth : ndarray, shape (K,), optional
        3-D: the tag's depth reading per ping [m] (None: no sensor).
    depth_weight : float, optional
        The reading's weight against an arrival's of the smallest σ: that σ over the sensor's [1].

    Returns
    -------
    ndarray, shape (K, dim)
        [m].
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    dim = receivers.shape[1]
    heard = np.isfinite(toa)
    w = heard.astype(float)
    wr = w if sigma_m is None else w * np.min(sigma_m, axis=-1, keepdims=True) / np.broadcast_to(sigma_m, w.shape)
    count = np.maximum(w.sum(axis=1), 1.0)
    ranges = sound_speed * np.where(heard, toa - np.nanmin(np.where(heard, toa, np.inf), axis=1, keepdims=True),
                                    0.0)
    centre = (w @ receivers) / count[:, None]
    low, high = receivers.min(axis=0), receivers.max(axis=0)
    pad = 0.5 * (high - low) + 1.0
    axes = [np.linspace(low[k] - pad[k], high[k] + pad[k], 5) for k in range(2)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    if dim == 3:
        levels = np.linspace(max(low[2] - pad[2], 0.0), high[2] + pad[2], 3)
        grid = np.column_stack([np.repeat(grid, len(levels), axis=0), np.tile(levels, len(grid))])
    common = np.vstack([receivers + 1e-3, grid])
    starts = np.concatenate([centre[:, None], np.broadcast_to(common, (len(toa),) + common.shape)], axis=1)
    x = np.concatenate([starts, np.zeros(starts.shape[:2] + (1,))], axis=-1)  # (K, S, dim + 1)
    dist = np.linalg.norm(x[:, :, None, :dim] - receivers, axis=-1)
    x[..., dim] = np.sum(w[:, None] * (ranges[:, None] - dist), axis=-1) / count[:, None]
    read = None
    if depth is not None:
        read = np.asarray(depth, float)[:, None]
        wd = np.where(np.isfinite(read), depth_weight, 0.0)  # (K, 1)
        read = np.where(np.isfinite(read), read, 0.0)
        row = np.zeros(dim + 1)
        row[2] = 1.0

    def residuals(x: np.ndarray) -> np.ndarray:
        dist = np.linalg.norm(x[:, :, None, :dim] - receivers, axis=-1)
        r = wr[:, None] * (ranges[:, None] - (dist + x[..., dim:dim + 1]))
        return r if read is None else np.concatenate([r, (wd * (read - x[..., 2]))[..., None]], axis=-1)

    for _ in range(iterations):
        diff = x[:, :, None, :dim] - receivers  # (K, S, n, dim)
        dist = np.maximum(np.linalg.norm(diff, axis=-1), 1e-9)
        residual = wr[:, None] * (ranges[:, None] - (dist + x[..., dim:dim + 1]))
        J = np.concatenate([diff / dist[..., None], np.ones(dist.shape + (1,))], axis=-1) * wr[:, None, :, None]
        if read is not None:
            residual = np.concatenate([residual, (wd * (read - x[..., 2]))[..., None]], axis=-1)
            J = np.concatenate([J, np.broadcast_to(wd[:, :, None, None] * row, J.shape[:2] + (1, dim + 1))],
                               axis=2)
        A = np.einsum("ksni,ksnj->ksij", J, J) + 1e-9 * np.eye(dim + 1)
        step = np.linalg.solve(A, np.einsum("ksni,ksn->ksi", J, residual)[..., None])[..., 0]
        x = x + step
        if np.all(np.linalg.norm(step, axis=-1) < 1e-9):
            break
    cost = np.sum(residuals(x) ** 2, axis=-1)
    ok = np.isfinite(cost) & (np.linalg.norm(step, axis=-1) < 1e-4)
    if water is not None:
        ok &= areas.inside(water, np.where(np.isfinite(x[..., :2]), x[..., :2], 0.0))
    if dim == 3:
        ok &= x[..., 2] >= -SURFACE_MARGIN  # a fish is below the surface
    cost = np.where(ok, cost, np.inf)
    best = cost.min(axis=1, keepdims=True)
    tied = np.isfinite(cost) & (cost <= best + 1e-6 * count[:, None] + 1e-9 * best)
    near = np.where(tied, np.linalg.norm(x[..., :dim] - centre[:, None], axis=-1), np.inf)
    pick = np.argmin(near, axis=1)
    out = x[np.arange(len(x)), pick, :dim]
    return np.where(np.isfinite(best), out, np.nan)


def _readings(problem: TelemetryProblem, positions: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
    """The tag's depth sensor's readings at the pings' true positions (K, 3) [m] (σ ``detection.depth_sigma_m``);
    None without a sensor, or in a planar design (``rng`` not drawn from)."""
    if problem.depth_sigma is None:
        return None
    return positions[:, 2] + problem.depth_sigma * rng.standard_normal(len(positions))


def _fixed(problem: TelemetryProblem, receivers: np.ndarray, toa: np.ndarray, sigma: np.ndarray,
           readings: np.ndarray | None) -> np.ndarray:
    """:func:`fixes` of a design's pings (3-D: with the depth readings weighted by the smallest arrival's σ over
    the sensor's)."""
    weight = 1.0 if readings is None else float(np.min(sigma)) / problem.depth_sigma
    return fixes(receivers, toa, problem.sections["detection"]["sound_speed"], problem.water,
                 sigma_m=sigma if problem.sigma_per_m else None, depth=readings, depth_weight=weight)


def _errors(problem: TelemetryProblem, estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The fixes' errors (rows where a fix was made) on the prescription's axes (North, East; or all in 3-D with
    ``prescription.dimensions = "3d"``) [m]."""
    axes = 2 if problem.horizontal else truth.shape[1]
    return (estimates - truth)[np.isfinite(estimates).all(axis=1)][:, :axes]


def static_check(design: TelemetryDesign, problem: TelemetryProblem, where: str, index: int,
                 rng: np.random.Generator) -> dict:
    """A tag at one point, pinging: its simulated yield and DRMS beside the predicted (module docstring, step 4);
    in 3-D at the point's depth, fixed in 3-D (with the depth sensor's readings where it has one)."""
    mc = problem.sections["monte_carlo"]
    detection = problem.sections["detection"]
    point = problem.points[index]
    pings = mc["replicates"] * PINGS_PER_REPLICATE
    settings = TrackerSettings(sound_speed=detection["sound_speed"], sigma_toa=detection["sigma_toa_s"])
    toa, positions, emissions = simulate_pings(design.receivers, pings, settings, rng, start=point, detection=1.0,
                                               ping_type="rbi", burst_interval=BURST_INTERVAL,
                                               path=lambda t: np.repeat(point[None], len(t), axis=0))
    q = problem.curve.probability(np.linalg.norm(design.receivers - point, axis=1))
    d = np.linalg.norm(design.receivers - point, axis=1)
    sigma = tm.range_sigma(d, problem.sigma_m, problem.sigma_per_m)
    toa = tm.range_noise(toa, d, problem.sigma_m, problem.sigma_per_m, detection["sound_speed"], rng)  # range_k
    toa[rng.random(toa.shape) >= q[None, :]] = np.nan  # the curve, receiver by receiver
    heard = np.isfinite(toa)
    enough = heard.sum(axis=1) >= problem.needed
    gate = problem.prescription["fix_gate_m"]
    own = tm.fix_drms(point[None], design.receivers, sigma[None], heard[:, None, :], problem.depth_sigma,
                      problem.horizontal)[:, 0]
    counted = enough & np.isfinite(own) & ((own <= gate) if gate > 0.0 else True)
    k = np.flatnonzero(counted)
    readings = _readings(problem, positions, rng)
    estimates = _fixed(problem, design.receivers, toa[k], sigma[None], None if readings is None else readings[k])
    errors = _errors(problem, estimates, positions[k])
    simulated = float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))) if len(errors) else math.inf
    predicted = float(design.drms_fixed[index])
    ratio = simulated / predicted if math.isfinite(simulated) and predicted > 0.0 else math.nan
    predicted_yield, simulated_yield = float(design.positioning_yield[index]), float(np.mean(enough))
    predicted_fixed, simulated_fixed = float(design.fixable[index]), float(np.mean(counted))
    confirmed = bool(abs(ratio - 1.0) <= mc["tolerance_pct"] / 100.0 and
                     abs(simulated_yield - predicted_yield) <= YIELD_TOLERANCE_PP / 100.0)
    depth = {"depth_m": float(point[2])} if problem.three_d else {}
    return {"point": where, "north_m": float(point[0]), "east_m": float(point[1]), **depth,
            "predicted_drms_m": predicted, "simulated_drms_m": simulated, "ratio": ratio, "confirmed": confirmed,
            "pings": int(pings), "fixes": int(len(errors)), "predicted_yield": predicted_yield,
            "simulated_yield": simulated_yield, "predicted_fixed": predicted_fixed, "simulated_fixed": simulated_fixed}


def walk_depth(problem: TelemetryProblem, times: np.ndarray) -> np.ndarray:
    """The walk's depth in 3-D at the emission ``times`` [s]: the work area's one depth, or between its shallowest
    and deepest as a sine of :data:`DEPTH_PERIOD` starting at their middle [m] (K,)."""
    depths = problem.sections["work_area"]["depths_m"]
    low, high = min(depths), max(depths)
    return 0.5 * (low + high) + 0.5 * (high - low) * np.sin(2.0 * math.pi * np.asarray(times, float) / DEPTH_PERIOD)


def walk(problem: TelemetryProblem, times: np.ndarray, rng: np.random.Generator, speed: float = WALK_SPEED,
         turn: float = WALK_TURN) -> np.ndarray:
    """A tagged animal's correlated random walk inside the work area (and the water) at the emission ``times``
    [s]: from the work area's point nearest its centroid, at ``speed`` [m/s], its heading turning by a normal of
    ``turn`` [rad] each ping; a step that would leave turns again (up to 50 draws, else the animal stays).

    Returns
    -------
    ndarray, shape (K, 2)
        (North, East) [m].
    """
    points = problem.points[:, :2]  # in 3-D: the horizontal walk (its depth :func:`walk_depth`'s)
    position = points[np.argmin(np.linalg.norm(points - points.mean(axis=0), axis=1))].copy()
    heading = rng.uniform(0.0, 2.0 * math.pi)
    out = np.empty((len(times), 2))
    steps = np.diff(np.asarray(times, float), prepend=float(times[0]))
    for k, dt in enumerate(steps):
        for _ in range(50):
            heading += rng.normal(0.0, turn)
            nxt = position + speed * dt * np.array([math.cos(heading), math.sin(heading)])
            if areas.inside(problem.work, nxt[None])[0] and areas.inside(problem.water, nxt[None])[0]:
                position = nxt
                break
            heading += rng.uniform(0.5, 1.5) * math.pi
        out[k] = position
    return out


def path_check(design: TelemetryDesign, problem: TelemetryProblem, rng: np.random.Generator) -> dict:
    """A tagged animal on a correlated random walk (:func:`walk`) through the work area, pinging as in
    :func:`static_check`: the simulated yield, share fixed and DRMS over the path beside the predicted at the
    path's positions (the RMS over the fixes that count of each ping position's predicted DRMS, weighted by its
    probability of a fix; :data:`PATH_PREDICTED` positions of the path, evenly spaced). In 3-D the walk's depth is
    :func:`walk_depth`'s, its pings fixed and tracked in 3-D (with the depth sensor's readings where it has one)."""
    mc, detection = problem.sections["monte_carlo"], problem.sections["detection"]
    pings = mc["replicates"] * PINGS_PER_REPLICATE
    settings = TrackerSettings(sound_speed=detection["sound_speed"], sigma_toa=detection["sigma_toa_s"])
    walked = np.random.default_rng(rng.integers(2**63))

    def path(t: np.ndarray) -> np.ndarray:
        out = walk(problem, t, walked)
        return np.column_stack([out, walk_depth(problem, t)]) if problem.three_d else out

    toa, positions, emissions = simulate_pings(design.receivers, pings, settings, rng, detection=1.0,
                                               ping_type="rbi", burst_interval=BURST_INTERVAL, path=path)
    d = np.linalg.norm(positions[:, None] - design.receivers[None], axis=-1)
    q = problem.curve.probability(d)
    sigma = tm.range_sigma(d, problem.sigma_m, problem.sigma_per_m)
    toa = tm.range_noise(toa, d, problem.sigma_m, problem.sigma_per_m, detection["sound_speed"], rng)
    toa[rng.random(toa.shape) >= q] = np.nan
    heard = np.isfinite(toa)
    own = tm.fix_drms(positions, design.receivers, sigma, heard, problem.depth_sigma, problem.horizontal)
    gate = problem.prescription["fix_gate_m"]
    enough = heard.sum(axis=1) >= problem.needed
    counted = enough & np.isfinite(own) & ((own <= gate) if gate > 0.0 else True)
    k = np.flatnonzero(counted)
    readings = _readings(problem, positions, rng)
    estimates = _fixed(problem, design.receivers, toa[k], sigma[k], None if readings is None else readings[k])
    errors = _errors(problem, estimates, positions[k])
    simulated = float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))) if len(errors) else math.inf
    chosen = np.linspace(0, pings - 1, min(PATH_PREDICTED, pings)).astype(int)
    rms, fixed = fixed_pings(positions[chosen], design.receivers, sigma[chosen], q[chosen], gate, rng,
                             needed=problem.needed, depth_sigma_m=problem.depth_sigma,
                             horizontal=problem.horizontal)
    ok = np.isfinite(rms) & (fixed > 0.0)
    predicted = float(np.sqrt(np.sum(fixed[ok] * rms[ok] ** 2) / np.sum(fixed[ok]))) if ok.any() else math.inf
    ratio = simulated / predicted if math.isfinite(simulated) and math.isfinite(predicted) else math.nan
    predicted_yield = float(np.mean(tm.positioning_yield(q[chosen], problem.needed)))
    simulated_yield = float(np.mean(enough))
    row = {"path": "correlated random walk", "pings": int(pings), "fixes": int(len(errors)),
           "length_m": float(np.sum(np.linalg.norm(np.diff(positions, axis=0), axis=1))),
           "predicted_drms_m": predicted, "simulated_drms_m": simulated, "ratio": ratio,
           "predicted_yield": predicted_yield, "simulated_yield": simulated_yield,
           "predicted_fixed": float(np.mean(fixed)), "simulated_fixed": float(np.mean(counted)),
           "confirmed": bool(abs(ratio - 1.0) <= mc["tolerance_pct"] / 100.0 and
                             abs(simulated_yield - predicted_yield) <= YIELD_TOLERANCE_PP / 100.0)
           } | track_path(design.receivers, toa, positions, emissions, detection["sound_speed"],
                          detection["sigma_toa_s"], BURST_INTERVAL, readings, problem.depth_sigma or 0.3)
    if mc["sync_clocks"] and np.isfinite(toa).any():  # the same pings through clocks synchronised from sync tags
        clocks = np.random.default_rng([problem.sections["search"]["seed"], design.count, SYNC_STREAM])
        row |= track_synchronised(design.receivers, toa, positions, emissions,
                                  sync_hearing(design.receivers, problem.curve),
                                  detection["sound_speed"], detection["sigma_toa_s"], BURST_INTERVAL, clocks, row,
                                  readings, problem.depth_sigma or 0.3)
    return row


def confirm(design: TelemetryDesign, problem: TelemetryProblem) -> None:
    """A proposed design's Monte Carlo rows (:func:`static_check` at :func:`checked_points`) and, with
    ``monte_carlo.path``, its path's row (:func:`path_check`)."""
    rng = np.random.default_rng([problem.sections["search"]["seed"], design.count, 1])
    design.monte_carlo = [static_check(design, problem, where, index, rng)
                          for where, index in checked_points(design, problem)]
    if problem.sections["monte_carlo"]["path"]:
        design.path = [path_check(design, problem, rng)]


def within(problem: TelemetryProblem, receivers: np.ndarray) -> bool:
    """Whether every receiver is in the water, within the shore distances."""
    site = problem.sections["site.area"]
    return bool(np.all(areas.inside(problem.water, receivers[:, :2], site["min_shore_m"],
                                    site["max_shore_m"] or None)))


def estimate(problem: TelemetryProblem):
    """The most the design will do (:class:`~sblsim.orchestrator.design.effort.Estimate`): every count's search
    (:data:`MOVES_PER_GENERATION` × ``search.generations`` layouts, at most :data:`SEARCH_SECONDS` per point and
    receiver each, and its judgement, :data:`JUDGE_SECONDS`), and the Monte Carlo's simulated pings."""
    sections = problem.sections
    low, high = sections["candidates"]["receivers"]
    counts = range(max(low, len(problem.kept)), high + 1)
    moves = sections["search"]["generations"] * MOVES_PER_GENERATION + 1
    m = len(problem.points)
    seconds = sum(moves * m * n * SEARCH_SECONDS + m * n * JUDGE_SECONDS for n in counts)
    runs = 2 * sections["monte_carlo"]["replicates"] * PINGS_PER_REPLICATE * (len(counts) if sections["search"][
        "pareto"] else 1)
    return Estimate(len(counts), moves * len(counts), m, runs, seconds + runs * PING_SECONDS)


__all__ = ["BURST_INTERVAL", "DEPTH_PERIOD", "JUDGE_SECONDS", "MOVES_PER_GENERATION", "PATH_PREDICTED",
           "PATTERN_SAMPLES", "PINGS_PER_REPLICATE", "PING_SECONDS", "SEARCH_SECONDS", "SITE_POINTS", "SURFACE_MARGIN",
           "TelemetryDesign",
           "TelemetryProblem", "TelemetryRun", "WALK_SPEED", "WALK_TURN", "YIELD_TOLERANCE_PP", "checked_points",
           "confirm", "estimate", "fixed_pings", "fixes", "judge", "path_check", "ranked", "resolve", "search_all",
           "search_count", "shortfalls", "static_check", "sync_hearing", "walk", "walk_depth", "water_polygon",
           "within"]
