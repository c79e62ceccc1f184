"""A telemetry array's layout judged with the criteria of the field (:mod:`~sblsim.orchestrator.design.telemetry`,
step 3): the positioning yield, the DRMS of the fixed pings (a fix of a geometry worse than ``prescription.fix_gate_m``
discarded), the sync coverage; what of the prescription a design fails and by how much, and the designs ranked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sblsim.models.design import area as areas
from sblsim.models.design import sync_graph as sg
from sblsim.models.design import telemetry as tm
from sblsim.orchestrator.design.telemetry import TelemetryProblem

#: Patterns per point of the fixed pings' Monte Carlo, where the enumeration does not reach.
PATTERN_SAMPLES = 400


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


def sync_hearing(receivers: np.ndarray, curve: Any) -> np.ndarray:
    """(..., n, n) [0–1], ``[i, j]`` the probability that receiver ``i`` hears the sync tag moored at receiver ``j``
    with receiver ``i``'s own curve (``detection.per_receiver``), else the site's; its own tag 0
    (:func:`~sblsim.models.design.sync_graph.sync_probabilities`, whose curve is applied along the tags' axis:
    transposed, which changes nothing where every receiver hears with the site's curve)."""
    return sg.sync_probabilities(receivers, curve.probability).swapaxes(-1, -2)


def judge(design: TelemetryDesign, problem: TelemetryProblem, rng: np.random.Generator) -> None:
    """A layout's criteria at the work area's points, and what of the prescription it fails
    (:mod:`~sblsim.orchestrator.design.telemetry`, step 3)."""
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
    design.sync = sg.sync_coverage(sync_hearing(receivers, problem.curve),
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
                    "text": f"sync coverage: {sync_share:.0f} % of the receivers hear {sg.SYNC_NEEDED} other sync "
                            f"tags with probability >= {problem.sections['detection']['sync_p']:g}, the sync graph "
                            f"in {int(sync.components)} part(s)"})
        ratios.append(100.0 / sync_share if sync_share > 0.0 else math.inf)
    return out, max(ratios)


def ranked(designs: list[TelemetryDesign]) -> list[TelemetryDesign]:
    """Designs best first: those that meet, cheapest first; then the others by coverage and how near they come."""
    meeting = sorted((d for d in designs if d.meets), key=lambda d: (d.cost, d.value))
    rest = sorted((d for d in designs if not d.meets), key=lambda d: (-d.coverage, d.miss, d.cost))
    return meeting + rest


__all__ = ["PATTERN_SAMPLES", "TelemetryDesign", "fixed_pings", "judge", "ranked", "shortfalls", "sync_hearing"]
