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
from sblsim.orchestrator.design.evaluate import LayoutEvaluator
from sblsim.orchestrator.design.problem import Area

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


def _constraints(n: int, region: Area, avoid: list[Area], layouts) -> list:
    """The region and the areas to avoid as one vectorised constraint on the variables (D, S): each transponder's
    signed distance to the region (≤ 0: inside) and to each area (≥ 0: outside)."""
    def distances(x):
        positions = layouts(x)[..., :2]  # (S, n, 2)
        parts = [region.distance(positions).T] + [a.distance(positions).T for a in avoid]
        return np.concatenate(parts, axis=0)
    low = np.concatenate([np.full(n, -np.inf), np.zeros(n * len(avoid))])
    high = np.concatenate([np.zeros(n), np.full(n * len(avoid), np.inf)])
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


def _polish(objective: Objective, x: np.ndarray, layout_of, bounds, n: int, region: Area, avoid: list[Area]
            ) -> np.ndarray:
    """The variables ``x`` polished: by SLSQP on the criterion's gradient for a smooth criterion (:data:`SMOOTH`;
    the site's weights and noises held at their values at ``x``), else by Powell's derivative-free search within
    the bounds (a layout outside the region or in an area to avoid penalised); ``x`` where the polish does not lower
    the criterion of a feasible layout."""
    def inside(v):
        pos = layout_of(np.asarray(v)[:, None])[0, :, :2]
        return np.concatenate([-region.distance(pos)] + [a.distance(pos) for a in avoid])

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


def optimise_ring(objective: Objective, n: int, region: Area, avoid: list[Area], depth: float,
                  bearing: float | None = None, seed: int = 0, population: int = 10, generations: int = 60,
                  polish: bool = True) -> Result:
    """The best regular ring of n transponders around the region's centre, its radius (and its bearing) searched
    (module docstring).

    Parameters
    ----------
    objective : Objective
    n : int
    region : Area
        Where the transponders may go; the ring's centre is its circle's centre or its vertices' mean.
    avoid : list of Area
    depth : float
        The transponders' depth [m].
    bearing : float, optional
        The first transponder's bearing from North [rad]; default searched in [0, 2π/n).
    seed, population, generations, polish
        The differential evolution's (population per variable) and the gradient polish.

    Returns
    -------
    Result
        Its ``variables`` the radius [m] (and the bearing [rad]).
    """
    centre, reach = region.middle, region.reach
    bounds = [(min(1.0, reach), reach)] + ([] if bearing is not None else [(0.0, 2.0 * math.pi / n)])
    steps = 2.0 * math.pi * np.arange(n) / n

    def layouts(x):
        if isinstance(x, ca.MX):
            angle = (x[1] if bearing is None else bearing) + ca.DM(steps)
            return ca.horzcat(centre[0] + x[0] * ca.cos(angle), centre[1] + x[0] * ca.sin(angle),
                              ca.DM.ones(n) * depth)
        x = np.asarray(x, dtype=float).reshape(len(bounds), -1)
        radius, first = x[0], (x[1] if bearing is None else np.full(x.shape[1], bearing))
        angle = first[:, None] + steps[None, :]
        north = centre[0] + radius[:, None] * np.cos(angle)
        east = centre[1] + radius[:, None] * np.sin(angle)
        return np.stack([north, east, np.full_like(north, depth)], axis=-1)

    constraints = _constraints(n, region, avoid, layouts)
    x, value, history = _evolve(objective, bounds, layouts, constraints, seed, population, generations)
    if polish:
        x = _polish(objective, x, layouts, bounds, n, region, avoid)
        value = float(objective.values(layouts(x[:, None]))[0])
        history.append(value)
    return Result(layouts(x[:, None])[0], value, history, x)


def optimise_free(objective: Objective, n: int, region: Area, avoid: list[Area], depth: float, seed: int = 0,
                  population: int = 10, generations: int = 60, polish: bool = True,
                  start: np.ndarray | None = None) -> Result:
    """The best placement of n transponders anywhere in the region outside the areas to avoid (module docstring).

    Parameters
    ----------
    objective, n, region, avoid, depth, seed, population, generations, polish
        As :func:`optimise_ring`.
    start : ndarray, shape (n, 3), optional
        A layout the population starts from (a ring's), where it is feasible.

    Returns
    -------
    Result
    """
    low, high = region.bounds()
    bounds = [(low[0], high[0])] * n + [(low[1], high[1])] * n

    def layouts(x):
        if isinstance(x, ca.MX):
            return ca.horzcat(x[:n], x[n:], ca.DM.ones(n) * depth)
        return _free(x, n, depth)

    x0 = None
    if start is not None:
        x0 = np.concatenate([start[:, 0], start[:, 1]])
        x0 = np.clip(x0, [b[0] for b in bounds], [b[1] for b in bounds])
    constraints = _constraints(n, region, avoid, layouts)
    x, value, history = _evolve(objective, bounds, layouts, constraints, seed, population * 2, generations, x0)
    if polish:
        x = _polish(objective, x, layouts, bounds, n, region, avoid)
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
