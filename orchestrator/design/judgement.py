"""A searched design and its judgement against the prescription: what of it the design fails and by how much
(:func:`shortfalls`), the designs ranked best first (:func:`ranked`), the Pareto front of cost against the criterion
and the DRMS quantiles over the work area a design reports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from sblsim.models.design.area import spread
from sblsim.models.design.criteria import ECHO_LIMIT
from sblsim.orchestrator.design.area import Area
from sblsim.orchestrator.design.candidates import Candidate

#: The quantiles of the DRMS over the work area that a design reports [%].
QUANTILES = (50.0, 95.0)
#: Designs that do not meet and miss the prescription by at most this much more than the nearest one (relatively)
#: are taken as near: the cheapest of them is ranked first (a costlier design is not proposed for a few tenths of a
#: millimetre).
NEAR = 0.01


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
        Whether it meets every part of the prescription
        (:meth:`~sblsim.orchestrator.design.searcher.Searcher.judge`).
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


def pareto_front(designs: list[Design]) -> list[Design]:
    """The designs that no other beats in both cost and criterion (the Pareto front), by cost."""
    front = [d for d in designs if not any(o.candidate.cost <= d.candidate.cost and o.value <= d.value and
                                           (o.candidate.cost < d.candidate.cost or o.value < d.value)
                                           for o in designs)]
    return sorted(front, key=lambda d: (d.candidate.cost, d.value))


def quantiles(design: Design, dimensions: str) -> dict[str, float]:
    """The DRMS over the work area (``drms_p50_m``, ``drms_p95_m``, ``drms_max_m``) [m]; a point without a fix
    counts as an infinite DRMS (then ``inf``)."""
    drms = design.values["drms" if dimensions == "horizontal" else "drms_3d"]
    drms = np.where(np.isfinite(drms), drms, np.inf)
    out = {f"drms_p{q:g}_m": float(np.percentile(drms, q, method="higher")) for q in QUANTILES}
    out["drms_max_m"] = float(drms.max())
    return out


__all__ = ["Design", "NEAR", "QUANTILES", "pareto_front", "quantiles", "ranked", "shortfalls"]
