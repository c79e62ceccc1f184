"""The search of a telemetry array's receiver counts and layouts (:mod:`~sblsim.orchestrator.design.telemetry`,
step 2): each count's layout from the k-means centres of the work area's points, then a seeded local search over the
grid of allowed places; the counts searched for the fewest that meets; and the most the design will do (its
estimate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from sblsim.models.design import area as areas
from sblsim.models.design import sync_graph as sg
from sblsim.models.design import telemetry as tm
from sblsim.orchestrator.design.effort import Estimate
from sblsim.orchestrator.design.telemetry import SITE_POINTS, TelemetryProblem
from sblsim.orchestrator.design.telemetry_judgement import TelemetryDesign, judge, ranked, sync_hearing

#: Local-search moves per receiver count: ``search.generations`` times this.
MOVES_PER_GENERATION = 5
#: Pings simulated at a checked point: ``monte_carlo.replicates`` times this.
PINGS_PER_REPLICATE = 25
#: Seconds per layout, point and receiver of the search's criterion (0.5 µs measured), of the judgement (40 µs
#: measured: the fixed pings' patterns) and per simulated ping fixed.
SEARCH_SECONDS, JUDGE_SECONDS, PING_SECONDS = 1.0e-6, 1.0e-4, 1.0e-3
#: The search's criterion grows by this times the share by which a layout's spread exceeds the footprint.
FOOTPRINT_PENALTY = 10.0


@dataclass
class TelemetryRun:
    """What a telemetry design gave: the problem, every count searched and the proposed designs (best first)."""

    resolved: TelemetryProblem
    searched: list
    proposed: list

    @property
    def best(self) -> TelemetryDesign:
        return self.proposed[0]


class _Objective:
    """The search's criterion of a layout (:mod:`~sblsim.orchestrator.design.telemetry`, step 2)."""

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
        sync = sg.sync_coverage(sync_hearing(receivers, p.curve),
                                p.sections["detection"]["sync_p"])
        return value + 5.0 * (1.0 - float(sync.share)) + 5.0 * (int(sync.components) - 1)


def search_count(problem: TelemetryProblem, count: int, rng: np.random.Generator) -> TelemetryDesign:
    """A count's layout (:mod:`~sblsim.orchestrator.design.telemetry`, step 2), judged
    (:func:`~sblsim.orchestrator.design.telemetry_judgement.judge`). The receivers in place
    (:attr:`~sblsim.orchestrator.design.telemetry.TelemetryProblem.kept`) are in every layout, first, and only the
    others are placed and paid for; with a footprint
    (:attr:`~sblsim.orchestrator.design.telemetry.TelemetryProblem.footprint`) the placed start within half of it of
    the middle of those in place (or of the work area) and the criterion grows by :data:`FOOTPRINT_PENALTY` times
    the share by which the layout's spread exceeds it."""
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


__all__ = ["FOOTPRINT_PENALTY", "JUDGE_SECONDS", "MOVES_PER_GENERATION", "PINGS_PER_REPLICATE", "PING_SECONDS",
           "SEARCH_SECONDS", "TelemetryRun", "estimate", "search_all", "search_count"]
