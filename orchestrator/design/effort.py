"""What a design problem will cost before it runs: its layouts, runs and time, estimated, and the bound on them.

A design's effort is set by its keys (``work_area.points`` and ``depths_m``, the candidates, ``search.population``,
``generations`` and ``pareto``, the Monte Carlo's ``replicates``, ``cycles`` and ``path_replicates``), and at
their largest it is years of computing. :func:`estimate` counts, from the resolved problem alone (nothing is
computed), the most the design can do:

* the **layouts** each candidate's search evaluates over the work area: an LBL's ring (two variables) and free
  placement (2 n variables), an SBL's arm (one): the differential evolution's population (``search.population``
  per variable, twice that for the free placement) in each of ``search.generations`` + 1 generations, and a
  polish of :data:`POLISH_PER_VARIABLE` evaluations per variable; a USBL one evaluation. Every candidate is
  counted (the search stops earlier: after the cheapest that meets, or when its population has converged), so
  the estimate is an upper bound;
* the **site's tables** (with detection by signal-to-noise): one per system, every :data:`~sblsim.orchestrator.
  design.evaluate.TABLE_STEP` of the horizontal distances the problem spans, at each vehicle depth;
* the **map** of each proposal over the work area, and the **runs** of its Monte Carlo: ``monte_carlo.replicates``
  static runs at two points and ``path_replicates`` runs of the path, each so many sampling times long.

Each is timed by a constant measured on one core (:data:`LAYOUT_POINT_SECONDS` ... :data:`RUN_SECONDS`: the
benchmarks' figures rounded up); the search's share is divided among the worker processes. A problem whose
estimate is above :data:`MAX_MINUTES` (or the caller's ``max_minutes``) is refused in one line with the estimate
(:func:`check_effort`), before anything is computed or written.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sblsim.models.design.information import slots_for
from sblsim.models.errors import ConfigError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.design.candidates import Candidate, candidates
from sblsim.orchestrator.design.confirm import PATH_SLOTS
from sblsim.orchestrator.design.evaluate import TABLE_STEP
from sblsim.orchestrator.design.resolution import Resolved

#: The longest a design may be estimated to take without the caller's ``max_minutes`` (``--max-minutes``) [min].
MAX_MINUTES = 60.0
#: The most minutes ``max_minutes`` allows (a year).
MAX_ALLOWED_MINUTES = 525960.0
#: Seconds per work-area point of one layout's evaluation by the compiled layout function, up to 8 transducers
#: (16: twice); measured 0.6 to 0.8 µs on one core (``bench_design``), the site's tables' interpolation included.
LAYOUT_POINT_SECONDS = 1.0e-6
#: Seconds of one layout's evaluation besides its points (the calls, the criterion).
LAYOUT_SECONDS = 5.0e-5
#: The polish's most evaluations per variable (Powell's search; SLSQP's iterations fewer).
POLISH_PER_VARIABLE = 400
#: Seconds per distance and vehicle depth of a site's detection table (eigenrays and sonar equation; 0.5 ms
#: measured).
TABLE_SECONDS = 5.0e-4
#: Seconds per work-area point and transducer of the accuracy map at a site with eigenrays (0.75 ms measured),
#: and with straight rays.
MAP_SECONDS = {"ray": 1.0e-3, "straight": 1.0e-5}
#: Seconds per replicate and sampling time of a Monte Carlo run, with eigenrays (0.4 to 0.9 ms measured) and with
#: straight rays (0.02 to 0.1 ms).
RUN_SECONDS = {"ray": 1.0e-3, "straight": 1.0e-4}


@dataclass(frozen=True)
class Estimate:
    """The most a design problem will do, and its time.

    Attributes
    ----------
    candidates : int
        Candidates to search.
    layouts : int
        Layouts evaluated over the work area, at most.
    points : int
        The work area's points.
    runs : int
        Simulated runs of the Monte Carlo, at most.
    seconds : float
        The estimated time, at most [s].
    """

    candidates: int
    layouts: int
    points: int
    runs: int
    seconds: float

    @property
    def time(self) -> str:
        """The time in words (seconds, minutes, hours or days)."""
        s = self.seconds
        if s < 120.0:
            return f"{max(s, 1.0):.0f} s"
        if s < 7200.0:
            return f"{s / 60.0:.0f} min"
        if s < 172800.0:
            return f"{s / 3600.0:.1f} h"
        return f"{s / 86400.0:,.0f} days"

    def line(self) -> str:
        """The estimate in one line."""
        return (f"{self.candidates:,} candidates, at most {self.layouts:,} layouts over {self.points:,} work-area "
                f"points and {self.runs:,} Monte Carlo runs: at most about {self.time}")


def search_layouts(candidate: Candidate, population: int, generations: int) -> int:
    """The most layouts a candidate's search evaluates (module docstring)."""
    layout = SYSTEMS[candidate.system].design_layout
    if layout == "seafloor":
        ring = population * 2 * (generations + 1) + POLISH_PER_VARIABLE * 2
        variables = 2 * candidate.count
        return ring + 2 * population * variables * (generations + 1) + POLISH_PER_VARIABLE * variables
    if layout == "platform":
        return population * (generations + 1)
    return 1


def estimate(resolved: Resolved, workers: int = 1) -> Estimate:
    """The most a resolved design problem will do and its time on ``workers`` processes (module docstring)."""
    sections = resolved.sections
    s, mc = sections["search"], sections["monte_carlo"]
    todo = candidates(resolved)
    m = len(resolved.points)
    plan = resolved.plan
    rays = "ray" if plan["acoustics"]["propagation"] == "ray" else "straight"
    search = 0.0
    layouts = 0
    for c in todo:
        count = search_layouts(c, s["population"], s["generations"])
        layouts += count
        scale = max(1.0, slots_for(c.count) / 8.0)
        search += count * (LAYOUT_SECONDS + LAYOUT_POINT_SECONDS * m * scale)
    search /= max(1, min(workers, len(todo)))
    systems = {c.system for c in todo}
    tables = 0.0
    if plan["acoustics"]["detection"] == "snr":
        low, high = resolved.seafloor.bounds()
        wlow, whigh = resolved.area.bounds()
        span = math.hypot(max(high[0], whigh[0]) - min(low[0], wlow[0]), max(high[1], whigh[1]) - min(low[1], wlow[1]))
        tables = len(systems) * (span / TABLE_STEP + 2.0) * len(resolved.depths) * TABLE_SECONDS
    proposals = len(todo) if s["pareto"] else len(systems)
    biggest = max(c.count for c in todo)
    maps = proposals * m * (biggest + 2) * MAP_SECONDS[rays]
    static = 2 * mc["replicates"] * ((biggest + 2) + mc["cycles"] * biggest)  # sampling times
    path = mc["path_replicates"] * PATH_SLOTS if mc["path"] else 0
    runs = proposals * (2 * mc["replicates"] + (mc["path_replicates"] if mc["path"] else 0))
    simulate = proposals * (static + path) * RUN_SECONDS[rays]
    seconds = search + tables + maps + simulate
    return Estimate(len(todo), layouts, m, runs, seconds)


def check_effort(effort: Estimate, max_minutes: float | None = None, option: str = "--max-minutes") -> None:
    """Refuse a problem estimated above its bound: :data:`MAX_MINUTES`, or ``max_minutes`` where given.

    Raises
    ------
    ConfigError
        One line with the estimate, the bound and how to allow it (``option``) or lower the effort.
    """
    bound = MAX_MINUTES if max_minutes is None else max_minutes
    if effort.seconds <= 60.0 * bound:
        return
    needed = math.ceil(effort.seconds / 60.0)
    allow = (f"give {option} {needed} to allow it, or less effort" if needed <= MAX_ALLOWED_MINUTES
             else "give less effort")
    raise ConfigError(f"design: estimated {effort.line()}, above the bound of {bound:g} min; {allow} (search."
                      "generations, search.population, work_area.points, work_area.depths_m, candidates, "
                      "monte_carlo.replicates)")


def check_minutes(value: object, where: str = "max_minutes") -> float | None:
    """A ``max_minutes`` argument checked: None, or a number in (0, :data:`MAX_ALLOWED_MINUTES`].

    Raises
    ------
    ConfigError
        Naming ``where`` and the allowed range.
    """
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not 0.0 < value <= MAX_ALLOWED_MINUTES:
        raise ConfigError(f"{where}: {value!r} is outside the allowed range (0, {MAX_ALLOWED_MINUTES:g}] min")
    return float(value)


__all__ = ["Estimate", "LAYOUT_POINT_SECONDS", "LAYOUT_SECONDS", "MAP_SECONDS", "MAX_ALLOWED_MINUTES", "MAX_MINUTES",
           "POLISH_PER_VARIABLE", "RUN_SECONDS", "TABLE_SECONDS", "check_effort", "check_minutes", "estimate",
           "search_layouts"]
