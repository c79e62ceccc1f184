"""The search of one candidate's layout (:mod:`~sblsim.orchestrator.design.run`'s step 3): an LBL's ring, then its
free placement started from it; an SBL's arm; a USBL has no layout. Each searched for the criterion over the work
area (:mod:`~sblsim.orchestrator.design.search`), its cycle sized, judged against the prescription, and evaluated
again through the accuracy map itself (:func:`sblsim.orchestrator.maps.point_accuracy`).
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np

from sblsim.models.design.area import spread
from sblsim.models.design.criteria import coverage, criterion
from sblsim.orchestrator.cosim.plan import RunPlan
from sblsim.orchestrator.design.area import Area
from sblsim.orchestrator.design.candidates import Candidate, grade_items, layout_items
from sblsim.orchestrator.design.evaluate import Detection, LayoutEvaluator, Levels, judged
from sblsim.orchestrator.design.judgement import Design, shortfalls
from sblsim.orchestrator.design.resolution import Resolved, plan_of
from sblsim.orchestrator.design.search import Objective, Result, optimise_baseline, optimise_free, optimise_ring
from sblsim.orchestrator.design.slot_period import _sampling_items, slot_period
from sblsim.orchestrator.maps import point_accuracy


class Searcher:
    """The search of a resolved problem's candidates (:mod:`~sblsim.orchestrator.design.run`, step 3); one per
    process.

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


def _provisional_ring(r: Resolved, n: int) -> np.ndarray:
    """A ring of n transponders inside the seafloor region (the plan of a candidate before its layout is known)."""
    centre = r.seafloor.middle
    angle = 2.0 * math.pi * np.arange(n) / n
    return np.column_stack([centre[0] + np.cos(angle), centre[1] + np.sin(angle), np.full(n, r.seafloor_depth)])


def _feasible(layout: np.ndarray, r: Resolved) -> bool:
    """Every transponder inside the seafloor region and outside the areas to avoid (their boundaries allowed), and
    within the footprint (:attr:`~sblsim.orchestrator.design.resolution.Resolved.footprint`) of one another."""
    return _placed(layout, r.seafloor, r.avoid) and not (r.footprint > 0.0 and float(spread(layout[:, :2])) >
                                                          r.footprint + 1e-6)


def _placed(layout: np.ndarray, seafloor: Area | None, avoid: list[Area]) -> bool:
    """Every transponder inside the seafloor region (where known) and outside the areas to avoid."""
    xy = layout[:, :2]
    inside = seafloor is None or bool(np.all(seafloor.contains(xy)))
    return inside and all(np.all(a.distance(xy) >= -1e-9) for a in avoid)


__all__ = ["Searcher"]
