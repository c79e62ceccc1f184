"""Target core: the diver's reference trajectory and depth (pressure) sensor.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Sections 4-5.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from models.core import SEED_PARAMETERS, ComponentCore, Variable, resolve_parameters
from models.target.trajectories import (OPEN_DURATION, Semicircle, Spiral, random_path,
                                        read_trajectory_file, square)

_DEPTH_NOISE, _RANDOM_PATH = range(2)
TRAJECTORIES = ("semicircle", "spiral", "random", "square", "file")


class TargetCore(ComponentCore):
    """Diver following a reference trajectory, with a depth sensor.

    The depth sensor reads ``d̃ = z + σ_depth w`` at every communication point.

    Attributes
    ----------
    path : object
        The trajectory; ``path.state(t, B)`` gives position [m] and velocity
        [m/s], each (B, 3).
    """

    name = "target"
    component_index = 2
    batched_parameters = frozenset({"cell", "depth_sigma"})

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("trajectory", "parameter", "String", "semicircle", description="Reference trajectory",
                     choices=TRAJECTORIES),
            Variable("trajectory_file", "parameter", "String", "",
                     description="CSV time [s], N, E, D [m] (trajectory = file)"),
            Variable("speed", "parameter", "Real", 0.5, "m/s", "Swimming speed", min=0.0, max=10.0,
                     min_exclusive=True),
            Variable("depth", "parameter", "Real", 5.0, "m", "Swimming depth", min=0.0, max=11000.0),
            Variable("radius", "parameter", "Real", 15.0, "m",
                     "Semicircle radius; start distance of the random path", min=0.0, max=1e4, min_exclusive=True),
            Variable("spiral_start_radius", "parameter", "Real", 2.0, "m", "Spiral start radius",
                     min=0.0, max=1e4),
            Variable("spiral_pitch", "parameter", "Real", 5.0, "m", "Spiral radial growth per turn",
                     min=0.0, max=1e4, min_exclusive=True),
            Variable("square_side", "parameter", "Real", 10.0, "m", "Side of the square", min=0.0, max=1e4,
                     min_exclusive=True),
            Variable("turn_interval", "parameter", "Real", 10.0, "s", "Random path: time between turns",
                     min=0.0, max=1e5, min_exclusive=True),
            Variable("max_radius", "parameter", "Real", 30.0, "m", "Random path: radius it stays within",
                     min=0.0, max=1e5, min_exclusive=True),
            Variable("depth_sigma", "parameter", "Real", 0.01, "m", "Depth sensor standard deviation",
                     min=0.0, max=1000.0),
        )
        outputs = tuple(
            Variable(n, "output", "Real", 0.0, u, f"True target {what}, {axis} [NED]")
            for n, u, what, axis in zip(("pos_x", "pos_y", "pos_z", "vel_x", "vel_y", "vel_z"),
                                        ("m",) * 3 + ("m/s",) * 3, ("position",) * 3 + ("velocity",) * 3,
                                        ("North", "East", "Down") * 2)
        ) + (Variable("depth_measured", "output", "Real", 0.0, "m", "Depth-sensor reading"),)
        return params + SEED_PARAMETERS + outputs

    def __init__(self, params, replicates=None, n_beacons: int = 4) -> None:
        super().__init__(params, replicates, n_beacons)
        if self.params["trajectory"] == "file":
            self.file_path = read_trajectory_file(self.params["trajectory_file"])

    def _make_path(self):
        p = self.params
        kind = p["trajectory"]
        if kind == "semicircle":
            return Semicircle(p["radius"], p["speed"], p["depth"])
        if kind == "spiral":
            return Spiral(p["spiral_start_radius"], p["spiral_pitch"], p["speed"], p["depth"])
        if kind == "square":
            return square(p["square_side"], p["speed"], p["depth"])
        if kind == "file":
            return self.file_path
        legs = int(math.ceil(OPEN_DURATION * 10.0 / p["turn_interval"])) + 1
        uniforms = np.stack([self.rng.draw(_RANDOM_PATH, "uniform", 2) for _ in range(legs)], axis=1)
        return random_path(uniforms, np.array([p["radius"], 0.0]), p["speed"], p["turn_interval"],
                           p["max_radius"], p["depth"])

    def _initialize(self, t0: float) -> None:
        self.rng = self.streams()
        self.path = self._make_path()
        self._outputs(t0)

    def _step(self, t: float, dt: float) -> None:
        self._outputs(t + dt)

    def _outputs(self, t: float) -> None:
        pos, vel = self.path.state(t, self.batch)
        depth = pos[:, 2] + self.params["depth_sigma"] * self.rng.draw(_DEPTH_NOISE, "normal", 1)[:, 0]
        self.outputs = dict(pos_x=pos[:, 0], pos_y=pos[:, 1], pos_z=pos[:, 2],
                            vel_x=vel[:, 0], vel_y=vel[:, 1], vel_z=vel[:, 2], depth_measured=depth)


def natural_duration(params: Mapping[str, Any]) -> float:
    """Duration of one pass of the configured trajectory [s].

    Semicircle: π r / v; square: 4 s / v; file: its last time; spiral and
    random: :data:`~models.target.trajectories.OPEN_DURATION`.
    """
    p = resolve_parameters(TargetCore.variables(), params, "target")
    kind = p["trajectory"]
    if kind == "semicircle":
        return math.pi * p["radius"] / p["speed"]
    if kind == "square":
        return 4.0 * p["square_side"] / p["speed"]
    if kind == "file":
        return read_trajectory_file(p["trajectory_file"]).duration
    return OPEN_DURATION


def start_state(params: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Position [m] and velocity [m/s] of the diver at t = 0, each (3,).

    Deterministic for every trajectory (the random path starts at (r, 0)).
    """
    core = TargetCore(params)  # validates, and reads a trajectory file once
    p = core.params
    if p["trajectory"] == "random":
        return np.array([p["radius"], 0.0, p["depth"]]), np.zeros(3)
    pos, vel = core._make_path().state(0.0, 1)
    return pos[0], vel[0]
