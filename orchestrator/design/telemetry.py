"""``sblsim design`` of a telemetry array (``candidates.systems = ["ilbl"]``): how many receivers (hydrophones) to
moor, and where in the water, so that a tag's pings are positioned to the prescription; each proposal confirmed by
simulated tags.

1. **Resolve** (:func:`resolve`): the water (``[site.area]``: a polygon, or a CSV or GeoJSON file), the work area's
   points (a grid over the water, or over ``work_area.polygon`` within it), the places a receiver may go (a finer
   grid over the water, ``site.area.min_shore_m`` / ``max_shore_m`` from the shore; or points along the mooring
   lines ``site.area.lines`` at the grid's step), the detection range curve
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
4. **Confirm** by simulated tags (:mod:`sblsim.orchestrator.design.telemetry_confirm`): at the work area's worst
   and median points and along an animal's walk, pings fixed and tracked, the simulated yield and DRMS beside the
   predicted.
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
from sblsim.models.sync.scale import looks_like_degrees
from sblsim.orchestrator.design.area import existing_devices, polygon
from sblsim.orchestrator.design.area_file import read_area
from sblsim.orchestrator.design.checks import is_three_d
from sblsim.orchestrator.design.curves import receiver_curves
from sblsim.orchestrator.design.effort import Estimate
from sblsim.orchestrator.tracks.toa import read_burst_sequence

#: The places a receiver may go: about this many grid points over the water.
SITE_POINTS = 4000
#: The least extent of the water [m]: an outline smaller is no telemetry site (degrees or kilometres taken for
#: metres), and metres per degree of latitude (the size such an outline would have in degrees).
MIN_WATER_M = 1.0
DEGREE_M = 111_195.0
#: The most mooring lines (``site.area.lines``) and vertices of one.
MAX_LINES, MAX_LINE_VERTICES = 100, 200
#: Local-search moves per receiver count: ``search.generations`` times this.
MOVES_PER_GENERATION = 5
#: Patterns per point of the fixed pings' Monte Carlo, where the enumeration does not reach.
PATTERN_SAMPLES = 400
#: Pings simulated at a checked point: ``monte_carlo.replicates`` times this.
PINGS_PER_REPLICATE = 25
#: Seconds per layout, point and receiver of the search's criterion (0.5 µs measured), of the judgement (40 µs
#: measured: the fixed pings' patterns) and per simulated ping fixed.
SEARCH_SECONDS, JUDGE_SECONDS, PING_SECONDS = 1.0e-6, 1.0e-4, 1.0e-3
#: The search's criterion grows by this times the share by which a layout's spread exceeds the footprint.
FOOTPRINT_PENALTY = 10.0


#: A random-interval tag's burst interval where ``tag.burst_interval_s`` is empty [s]: the worked case's
#: (``lake-hald-array``), the one the confirmation simulated before the tag was a key.
DEFAULT_BURST_INTERVAL = (20.0, 40.0)


@dataclass(frozen=True)
class Tag:
    """The tag a design is confirmed with (``[tag]``): its ping type as the tracker names it
    (:data:`~sblsim.models.tracking.schedule.PING_TYPES`) and its intervals.

    Attributes
    ----------
    ping_type : str
        ``sbi``, ``rbi`` or ``pbi``.
    burst_interval : tuple of float
        ``rbi``: (min, max) [s]; ``sbi``: (Δ, Δ) [s]; ``pbi``: the sequence's (shortest, longest) [s].
    burst_sequence : numpy.ndarray or None
        ``pbi``: the tag's intervals in order [s] (k,); else None.
    source_level_db : float
        The tag's source level [dB re 1 µPa at 1 m] (0: none given; the detection curve is a range test's).
    """

    ping_type: str = "rbi"
    burst_interval: tuple[float, float] = DEFAULT_BURST_INTERVAL
    burst_sequence: np.ndarray | None = None
    source_level_db: float = 0.0

    def record(self) -> dict[str, Any]:
        """What ``design.json`` records of the tag."""
        out: dict[str, Any] = {"ping_type": self.ping_type, "burst_interval_s": list(self.burst_interval)}
        if self.burst_sequence is not None:
            out["burst_sequence_intervals"] = int(len(self.burst_sequence))
        if self.source_level_db > 0.0:
            out["source_level_db"] = self.source_level_db
        return out


def tag_of(section: Mapping[str, Any]) -> Tag:
    """The tag of a checked ``[tag]`` section (its keys checked together by the problem); a ``pbi`` tag's
    sequence read from its file (:func:`~sblsim.orchestrator.tracks.toa.read_burst_sequence`, the tracker's
    ``--burst-sequence`` reader: bounded, one line naming the file and line where a row is bad).

    Raises
    ------
    ConfigError
        Naming ``tag.burst_sequence`` and the reader's reason.
    """
    kind, interval = section["ping_type"], tuple(float(v) for v in section["burst_interval_s"])
    sequence = None
    if kind == "pbi":
        try:
            sequence = read_burst_sequence(section["burst_sequence"])
        except ModelError as exc:
            raise ConfigError(f"tag.burst_sequence: {exc}") from None
        interval = (float(sequence.min()), float(sequence.max()))
    elif kind == "sbi":
        interval = (interval[0], interval[0])
    else:
        interval = interval or DEFAULT_BURST_INTERVAL
    return Tag(kind, interval, sequence, float(section["source_level_db"]))


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


__all__ = ["DEFAULT_BURST_INTERVAL", "JUDGE_SECONDS", "MAX_LINES",
           "MAX_LINE_VERTICES", "MOVES_PER_GENERATION", "PATTERN_SAMPLES", "PINGS_PER_REPLICATE", "PING_SECONDS",
           "SEARCH_SECONDS", "SITE_POINTS", "Tag", "TelemetryDesign", "TelemetryProblem", "TelemetryRun", "estimate",
           "fixed_pings", "judge", "ranked", "resolve", "search_all", "search_count", "shortfalls", "sync_hearing",
           "mooring_lines", "tag_of", "water_polygon", "within"]
