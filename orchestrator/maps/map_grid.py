"""A map's grid and its diver's depth: the grid's East and North axes (:func:`grid`), its points at the
diver's depth (:func:`grid_points`, :func:`diver_depth`), the depth checked against the site
(:func:`check_depth`) and the accuracy levels a map contours (:func:`parse_levels`).
"""

from __future__ import annotations

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.target.core import file_waypoints
from sblsim.orchestrator.cosim.plan import RunPlan
from sblsim.orchestrator.cosim.systems import check_diver

MAX_POINTS = 1_000_000
#: The largest half-width of a map's grid [m].
MAX_EXTENT = 1e5


def parse_levels(text: str, option: str = "--levels") -> list[float]:
    """``0.5,1,2`` -> increasing positive accuracy levels [m].

    Raises
    ------
    ModelError
        Naming ``option`` and what is allowed.
    """
    try:
        levels = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ModelError(f"{option}: expected comma-separated accuracies in metres, e.g. 0.5,1,2; got {text!r}") \
            from None
    if not levels or not all(np.isfinite(v) and v > 0 for v in levels):
        raise ModelError(f"{option}: expected positive accuracies in metres, e.g. 0.5,1,2; got {text!r}")
    return sorted(set(levels))


def grid(extent: float, step: float, options: tuple[str, str] = ("--extent", "--step")
         ) -> tuple[np.ndarray, np.ndarray]:
    """East and North coordinates of the grid, ``−extent … extent`` every ``step`` [m].

    Raises
    ------
    ModelError
        If the extent (at most :data:`MAX_EXTENT`) or step is out of range or the grid too large, naming
        ``options``.
    """
    if not (np.isfinite(extent) and 0 < extent <= MAX_EXTENT):
        raise ModelError(f"{options[0]}: {extent!r} m is outside the allowed range (0, {MAX_EXTENT:g}]")
    if not (np.isfinite(step) and 0 < step <= extent):
        raise ModelError(f"{options[1]}: {step!r} m is outside the allowed range (0, extent = {extent:g}]")
    n = int(np.floor(2 * extent / step + 1e-9)) + 1
    if n * n > MAX_POINTS:
        raise ModelError(f"{options[1]}: {step:g} m gives {n}×{n} points over ±{extent:g} m; at most {MAX_POINTS} "
                         f"(use a step of at least {2 * extent / (np.sqrt(MAX_POINTS) - 1):.3g} m)")
    axis = -extent + step * np.arange(n)
    return axis, axis.copy()


def diver_depth(cfg: dict) -> tuple[float, str]:
    """The depth a map is drawn at when none is given [m], and where it comes from.

    ``target.depth`` for the built-in paths; for a trajectory file (or waypoints) the median depth of its
    waypoints, since ``target.depth`` does not apply to it.
    """
    target = cfg["target"]
    if target.get("trajectory") == "file":
        return float(np.median(file_waypoints(target)[:, 3])), "the median depth of the trajectory's waypoints"
    return float(target["depth"]), "target.depth"


def grid_points(plan: RunPlan, east: np.ndarray, north: np.ndarray, depth: float | None) -> np.ndarray:
    """The grid's points (M, 3), NED [m], at the diver's depth (default :func:`diver_depth`), north-major."""
    E, N = np.meshgrid(east, north)
    depth = diver_depth(plan)[0] if depth is None else float(depth)
    return np.column_stack([N.ravel(), E.ravel(), np.full(E.size, depth)])


def check_depth(cfg: dict, depth: float, option: str = "--depth") -> None:
    """Refuse a diver's depth of a map that the site cannot hold: at or below the water depth
    (``acoustics.water_depth``; 0: none), or where the system has no diver
    (:func:`~sblsim.orchestrator.cosim.systems.check_diver`: LBL's transponders stand on the seafloor).

    Raises
    ------
    ModelError
        Naming ``option`` (the option or argument that gave the depth) and the allowed range.
    """
    water = float(cfg["acoustics"]["water_depth"])
    if water > 0.0 and not depth < water:
        raise ModelError(f"{option}: {depth:g} m is outside the allowed range [0, {water:g}) m: the site's water is "
                         f"{water:g} m deep (acoustics.water_depth)")
    try:
        check_diver(cfg, depth)
    except ModelError as exc:
        raise ModelError(f"{option}: {depth:g} m is not above the seafloor: {exc}") from None
