"""``sblsim design``'s work: from a design problem to its proposed designs, each confirmed by Monte Carlo.

1. **Resolve** the problem (:func:`~sblsim.orchestrator.design.resolution.resolve`): the base scenario's plan, the
   work area's points at the vehicle's depths, the seafloor region and the areas to avoid, what the scenario gives to
   the keys left at 0 or empty.
2. **Candidates** (:func:`~sblsim.orchestrator.design.candidates.candidates`): per system, every count (LBL
   transponders) and combination of the grades that change that system's accuracy
   (:data:`~sblsim.orchestrator.design.keys.GRADES`), with its cost, in the order of their cost.
3. **Search** each candidate's layout (:class:`~sblsim.orchestrator.design.searcher.Searcher` with
   :mod:`~sblsim.orchestrator.design.search`: an LBL's ring, then its free placement started from it; an SBL's arm; a
   USBL has no layout) for the criterion over the work area, in the order of cost, until the cheapest that meets the
   prescription (every candidate with ``search.pareto``); with ``workers`` above 1, that many candidates at once, the
   result the same as one at a time.
4. **Propose** the best design of each system (the cheapest that meets, else the one of the largest coverage), and
   with ``search.pareto`` every design of the front of cost against the criterion; each is evaluated again through
   the accuracy map itself (:func:`sblsim.orchestrator.maps.point_accuracy`), whose numbers the outputs carry.
5. **Confirm** each proposal by Monte Carlo (:mod:`~sblsim.orchestrator.design.confirm`).
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context

from sblsim.orchestrator.campaign.executors import stop_pool
from sblsim.orchestrator.campaign.worker import watch_parent
from sblsim.orchestrator.design.candidates import Candidate, candidates
from sblsim.orchestrator.design.judgement import Design, pareto_front, ranked
from sblsim.orchestrator.design.keys import SYSTEM_NAMES
from sblsim.orchestrator.design.resolution import Resolved
from sblsim.orchestrator.design.searcher import Searcher
from sblsim.orchestrator.io.progress import Progress, ProgressSpec

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


def _name(stem: str, design: Design, taken: set) -> str:
    c = design.candidate
    name = f"{stem}-{c.system}" + (f"{c.count}" if c.layout == "seafloor" else "")
    base, k = name, 2
    while name in taken:
        name, k = f"{base}-{k}", k + 1
    taken.add(name)
    return name


__all__ = ["DesignRun", "search_all"]
