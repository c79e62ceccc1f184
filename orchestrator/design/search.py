"""The search of a design: layouts that minimise a criterion over the work area, for each candidate count and grade.

* **Free placement** (:func:`optimise_free`): the North and East of each of n transponders inside the seafloor
  region and outside its areas to avoid, by scipy's differential evolution (seeded, its population evaluated as
  one array, the region and the areas as vectorised constraints: Lampinen's feasibility rules) started from the
  best regular ring, then polished: for the smooth criteria (D-optimal, A-optimal) by SLSQP with the criterion's
  gradient, which casadi derives from the Fisher information (the site's detection held at its values there), for
  the others by Powell's derivative-free search (Powell, The Computer Journal 7(2):155-162, 1964).
  Storn, Price, "Differential evolution", J. Global Optimization 11:341-359, 1997; Lampinen, "A constraint
  handling approach for the differential evolution algorithm", CEC 2002.
* **A regular ring** (:func:`optimise_ring`): n transponders equally spaced on a circle around the region's
  centre, its radius and the first one's bearing the unknowns (the same search, two dimensions; one with the
  bearing given).
* **An SBL's arm** (:func:`optimise_baseline`): the beacons' circle on the platform, its radius the unknown
  (bounded by ``candidates.sbl_baseline_m``).

Transponders already in place (``fixed``: ``candidates.existing_m``) are the first of every layout, where they are;
only the others are placed (the ring is of those). A footprint (``candidates.footprint_m``) bounds the distance of
every pair with a placed transponder, a constraint of the evolution and the polish like the region's (the free
placement's box narrowed to within it of every transponder in place).

Each returns the layout, its criterion and the search's history (the best criterion after each generation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.optimize import NonlinearConstraint, differential_evolution, minimize

from sblsim.models.design.criteria import criterion as criterion_of
from sblsim.models.design.information import layout_information
from sblsim.orchestrator.design.area import Area
from sblsim.orchestrator.design.evaluate import LayoutEvaluator

#: Criteria that are smooth in the layout: polished with their gradient.
SMOOTH = ("d-optimal", "a-optimal")
#: Relative tolerance of the differential evolution's convergence (the population's spread of criteria).
TOLERANCE = 1e-3


@dataclass
class Objective:
    """What a layout search minimises: a criterion of the evaluator's accuracy over the work area.

    Attributes
    ----------
    evaluator : LayoutEvaluator
    criterion : str
        One of :data:`sblsim.models.design.criteria.CRITERIA`.
    dimensions : str
        ``horizontal`` or ``3d`` (which DRMS the criterion reads).
    coverage_pct : float
        The percentile of the ``percentile`` criterion [%].
    """

    evaluator: LayoutEvaluator
    criterion: str = "percentile"
    dimensions: str = "horizontal"
    coverage_pct: float = 95.0

    def values(self, layouts: np.ndarray) -> np.ndarray:
        """The criterion of S layouts (S, n, 3) whose transducers' lever arms are their positions (a fixed array,
        or a platform at the origin), (S,)."""
        out = self.evaluator.evaluate(layouts)
        drms = out["drms" if self.dimensions == "horizontal" else "drms_3d"]
        return criterion_of(self.criterion, drms, out["log_det"], self.coverage_pct, out["echo"])


@dataclass
class Result:
    """A layout found, its criterion and the search's history (the best criterion per generation)."""

    layout: np.ndarray
    value: float
    history: list[float]
    variables: np.ndarray


def _free(x: np.ndarray, n: int, depth: float) -> np.ndarray:
    """Free-placement variables (2 n, S) ``[north_1..n, east_1..n]`` -> layouts (S, n, 3)."""
    x = np.asarray(x, dtype=float).reshape(2 * n, -1)
    return np.stack([x[:n].T, x[n:].T, np.full((x.shape[1], n), depth)], axis=-1)


def _pairs(n: int, kept: int) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i < j) of n devices of which at least one is placed (not among the first ``kept``)."""
    i, j = np.triu_indices(n, 1)
    placed = j >= kept
    return i[placed], j[placed]


def _constraints(n: int, region: Area, avoid: list[Area], layouts, kept: int = 0, footprint: float = 0.0) -> list:
    """The region and the areas to avoid as one vectorised constraint on the variables (D, S): each placed
    transponder's signed distance to the region (≤ 0: inside) and to each area (≥ 0: outside); with a
    ``footprint`` [m], the distance of every pair with a placed transponder (≤ it). The first ``kept`` transponders
    of a layout are in place already (not placed)."""
    placed = n - kept
    i, j = _pairs(n, kept)

    def distances(x):
        layout = layouts(x)
        positions = layout[:, kept:, :2]  # (S, n - kept, 2)
        parts = [region.distance(positions).T] + [a.distance(positions).T for a in avoid]
        if footprint > 0.0:
            parts.append(np.linalg.norm(layout[:, i, :2] - layout[:, j, :2], axis=-1).T)
        return np.concatenate(parts, axis=0)
    pairs = len(i) if footprint > 0.0 else 0
    low = np.concatenate([np.full(placed, -np.inf), np.zeros(placed * len(avoid)), np.zeros(pairs)])
    high = np.concatenate([np.zeros(placed), np.full(placed * len(avoid), np.inf), np.full(pairs, footprint)])
    return [NonlinearConstraint(distances, low, high)]


def _evolve(objective: Objective, bounds, layouts, constraints, seed: int, population: int, generations: int,
            x0=None) -> tuple[np.ndarray, float, list[float]]:
    history: list[float] = []

    def energy(x):
        return objective.values(layouts(x))

    def track(intermediate_result):  # scipy passes the best so far by this name
        history.append(float(intermediate_result.fun))

    result = differential_evolution(energy, bounds, maxiter=generations, popsize=population, tol=TOLERANCE,
                                    rng=np.random.default_rng(seed), polish=False, init="latinhypercube",
                                    vectorized=True, updating="deferred", constraints=constraints or (), x0=x0,
                                    callback=track)
    x = np.asarray(result.x, dtype=float)
    return x, float(energy(x[:, None])[0]), history


def _polish(objective: Objective, x: np.ndarray, layout_of, bounds, n: int, region: Area, avoid: list[Area],
            kept: int = 0, footprint: float = 0.0) -> np.ndarray:
    """The variables ``x`` polished: by SLSQP on the criterion's gradient for a smooth criterion (:data:`SMOOTH`;
    the site's weights and noises held at their values at ``x``), else by Powell's derivative-free search within
    the bounds (a layout outside the region, in an area to avoid or beyond the ``footprint`` penalised); ``x`` where
    the polish does not lower the criterion of a feasible layout. The first ``kept`` transponders are in place."""
    i, j = _pairs(n, kept)

    def inside(v):
        layout = layout_of(np.asarray(v)[:, None])[0, :, :2]
        pos = layout[kept:]
        parts = [-region.distance(pos)] + [a.distance(pos) for a in avoid]
        if footprint > 0.0:
            parts.append(footprint - np.linalg.norm(layout[i] - layout[j], axis=-1))
        return np.concatenate(parts)

    start = objective.values(layout_of(x[:, None]))[0]
    if not np.isfinite(start):  # no work-area point positioned from anywhere the search went: nothing to polish
        return x
    low, high = np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])
    if objective.criterion in SMOOTH:
        found = _gradient_polish(objective, x, layout_of, bounds, n, inside)
    else:
        def penalised(v):
            value = objective.values(layout_of(np.asarray(v)[:, None]))[0]
            outside = float(np.sum(np.maximum(-inside(v), 0.0)))
            return value + 1e3 * (1.0 + abs(value)) * outside if outside > 0.0 else value

        found = minimize(penalised, x, method="Powell", bounds=bounds,
                         options={"xtol": 1e-8, "ftol": 1e-12, "maxfev": 400 * x.size}).x
    candidate = np.clip(np.asarray(found, dtype=float), low, high)
    if np.all(inside(candidate) >= -1e-9) and objective.values(layout_of(candidate[:, None]))[0] < start:
        return candidate
    return x


def _gradient_polish(objective: Objective, x: np.ndarray, layout_of, bounds, n: int, inside) -> np.ndarray:
    """SLSQP from ``x`` on a smooth criterion and its gradient, which casadi derives through the layout function."""
    evaluator = objective.evaluator
    layout = layout_of(x[:, None])
    weight, noise = evaluator.heard(layout)[:2]
    m = evaluator.m
    variables = ca.MX.sym("x", x.size)
    positions = layout_of(variables)
    f = layout_information(n).map("design_polish", "serial", m, [1, 2, 5, 6], [])
    out = f(ca.DM(evaluator.points.T), ca.vec(positions.T), ca.vec(positions.T), ca.DM(weight[0].T), ca.DM(noise[0].T),
            evaluator.levels.attitude_variance, evaluator.levels.depth_variance)
    if objective.criterion == "d-optimal":
        value = -ca.sum2(out[3]) / m
    else:
        drms = out[1] if objective.dimensions == "horizontal" else out[2]
        value = ca.sum2(drms ** 2) / m
    scale = abs(float(ca.Function("v", [variables], [value])(x))) or 1.0
    g = ca.Function("polish", [variables], [value / scale, ca.gradient(value / scale, variables)])

    def fun(v):
        f_value, gradient = g(v)
        return float(f_value), np.asarray(gradient, dtype=float).ravel()

    return minimize(fun, x, jac=True, method="SLSQP", bounds=bounds, constraints=[{"type": "ineq", "fun": inside}],
                    options={"maxiter": 300, "ftol": 1e-15}).x


def _kept(fixed: np.ndarray | None) -> np.ndarray:
    """The devices in place (k, 3) NED [m] (none: (0, 3))."""
    return np.zeros((0, 3)) if fixed is None else np.asarray(fixed, dtype=float).reshape(-1, 3)


def _with_kept(kept: np.ndarray, placed):
    """A layout of the devices in place followed by those placed: numpy (S, n, 3) or casadi (n, 3)."""
    if isinstance(placed, ca.MX):
        return ca.vertcat(ca.DM(kept), placed) if len(kept) else placed
    if not len(kept):
        return placed
    return np.concatenate([np.broadcast_to(kept, (placed.shape[0],) + kept.shape), placed], axis=1)


def optimise_ring(objective: Objective, n: int, region: Area, avoid: list[Area], depth: float,
                  bearing: float | None = None, seed: int = 0, population: int = 10, generations: int = 60,
                  polish: bool = True, fixed: np.ndarray | None = None, footprint: float = 0.0) -> Result:
    """The best regular ring of n transponders around the region's centre, its radius (and its bearing) searched
    (module docstring).

    Parameters
    ----------
    objective : Objective
    n : int
        The transponders, those in place (``fixed``) included.
    region : Area
        Where the transponders may go; the ring's centre is its circle's centre or its vertices' mean.
    avoid : list of Area
    depth : float
        The transponders' depth [m].
    bearing : float, optional
        The first transponder's bearing from North [rad]; default searched in [0, 2π/n).
    seed, population, generations, polish
        The differential evolution's (population per variable) and the gradient polish.
    fixed : ndarray, shape (k, 3), optional
        Transponders in place, NED [m], k < n: every layout holds them first; the ring is of the n − k others.
    footprint : float, optional
        The largest distance between any two transponders [m] (0: any), a constraint like the region's.

    Returns
    -------
    Result
        Its ``variables`` the radius [m] (and the bearing [rad]).
    """
    kept = _kept(fixed)
    placed = n - len(kept)
    centre, reach = region.middle, region.reach
    bounds = [(min(1.0, reach), reach)] + ([] if bearing is not None else [(0.0, 2.0 * math.pi / placed)])
    steps = 2.0 * math.pi * np.arange(placed) / placed

    def layouts(x):
        if isinstance(x, ca.MX):
            angle = (x[1] if bearing is None else bearing) + ca.DM(steps)
            return _with_kept(kept, ca.horzcat(centre[0] + x[0] * ca.cos(angle), centre[1] + x[0] * ca.sin(angle),
                                               ca.DM.ones(placed) * depth))
        x = np.asarray(x, dtype=float).reshape(len(bounds), -1)
        radius, first = x[0], (x[1] if bearing is None else np.full(x.shape[1], bearing))
        angle = first[:, None] + steps[None, :]
        north = centre[0] + radius[:, None] * np.cos(angle)
        east = centre[1] + radius[:, None] * np.sin(angle)
        return _with_kept(kept, np.stack([north, east, np.full_like(north, depth)], axis=-1))

    constraints = _constraints(n, region, avoid, layouts, len(kept), footprint)
    x, value, history = _evolve(objective, bounds, layouts, constraints, seed, population, generations)
    if polish:
        x = _polish(objective, x, layouts, bounds, n, region, avoid, len(kept), footprint)
        value = float(objective.values(layouts(x[:, None]))[0])
        history.append(value)
    return Result(layouts(x[:, None])[0], value, history, x)


def optimise_free(objective: Objective, n: int, region: Area, avoid: list[Area], depth: float, seed: int = 0,
                  population: int = 10, generations: int = 60, polish: bool = True,
                  start: np.ndarray | None = None, fixed: np.ndarray | None = None, footprint: float = 0.0) -> Result:
    """The best placement of n transponders anywhere in the region outside the areas to avoid (module docstring).

    Parameters
    ----------
    objective, n, region, avoid, depth, seed, population, generations, polish, fixed, footprint
        As :func:`optimise_ring`; with transponders in place (``fixed``) the n − k others are placed, within
        ``footprint`` of each of them (the search's box narrowed to it).
    start : ndarray, shape (n, 3), optional
        A layout the population starts from (a ring's), where it is feasible.

    Returns
    -------
    Result
    """
    kept = _kept(fixed)
    placed = n - len(kept)
    low, high = region.bounds()
    if footprint > 0.0 and len(kept):  # within the footprint of every transponder in place
        low = np.maximum(low, kept[:, :2].max(axis=0) - footprint)
        high = np.maximum(low, np.minimum(high, kept[:, :2].min(axis=0) + footprint))
    bounds = [(low[0], high[0])] * placed + [(low[1], high[1])] * placed

    def layouts(x):
        if isinstance(x, ca.MX):
            return _with_kept(kept, ca.horzcat(x[:placed], x[placed:], ca.DM.ones(placed) * depth))
        return _with_kept(kept, _free(x, placed, depth))

    x0 = None
    if start is not None:
        x0 = np.concatenate([start[len(kept):, 0], start[len(kept):, 1]])
        x0 = np.clip(x0, [b[0] for b in bounds], [b[1] for b in bounds])
    constraints = _constraints(n, region, avoid, layouts, len(kept), footprint)
    x, value, history = _evolve(objective, bounds, layouts, constraints, seed, population * 2, generations, x0)
    if polish:
        x = _polish(objective, x, layouts, bounds, n, region, avoid, len(kept), footprint)
        value = float(objective.values(layouts(x[:, None]))[0])
        history.append(value)
    return Result(layouts(x[:, None])[0], value, history, x)


def optimise_baseline(objective: Objective, unit_arms: np.ndarray, shortest: float, longest: float,
                      seed: int = 0, population: int = 10, generations: int = 60) -> Result:
    """The best arm length of an SBL whose beacons' lever arms at an arm of 1 m are ``unit_arms`` (n, 3): their
    horizontal parts scale with the arm, their depth stays (module docstring); searched on the logarithm of the arm
    in ``[shortest, longest]`` [m]."""
    def scaled(arm):
        out = np.repeat(unit_arms[None], arm.size, axis=0).copy()
        out[..., :2] *= arm[:, None, None]
        return out

    def layouts(x):
        return scaled(np.exp(np.asarray(x, dtype=float).reshape(1, -1)[0]))

    bounds = [(math.log(shortest), math.log(longest))] if longest > shortest else [(math.log(shortest),) * 2]
    if bounds[0][0] == bounds[0][1]:
        arm = np.array([float(shortest)])
        return Result(scaled(arm)[0], float(objective.values(scaled(arm))[0]), [], arm)
    x, value, history = _evolve(objective, bounds, layouts, None, seed, population, generations)
    # an arm at a bound where the criterion falls all the way to it (the evolution stops short of it: 9.977 m of
    # 10 m), the bound itself
    ends = np.array([float(shortest), float(longest)])
    at_ends = objective.values(scaled(ends))
    if float(at_ends.min()) <= value:
        arm = ends[[int(np.argmin(at_ends))]]
        return Result(scaled(arm)[0], float(at_ends.min()), history, arm)
    return Result(layouts(x[:, None])[0], value, history, np.exp(x))


__all__ = ["Objective", "Result", "SMOOTH", "TOLERANCE", "optimise_baseline", "optimise_free", "optimise_ring"]
