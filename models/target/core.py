"""Target: the diver's reference trajectory and depth (pressure) sensor.

The depth sensor is sampled every ``sample_period`` T_s at ``t_k = t0 + k T_s``,
``d̃_k = z(t_k) + σ_depth w_k``, and the reading is held until the next
sample. The random path turns every ``turn_interval`` from the start time:
at each turn the diver takes a new heading drawn uniformly in [0, 2π), or,
when the next leg would leave the disc of radius ``max_radius``, within ±60°
of the bearing to the centre.

The random walk (``random-walk``) is drawn from the receivers' own motion
model: white-noise acceleration with spectral densities ``walk_q_horizontal``
and ``walk_q_vertical`` [m²/s³], discretized exactly at every sample
(``x_k+1 = Φ x_k + w_k``, ``w_k ~ N(0, Q(T_s))`` per axis), moving at
constant velocity between samples, from a start drawn from
``N([r, 0, depth, 0, v, 0], diag(p0_position², p0_velocity²))``. With the
receiver's q and P0 equal to these, the posterior Cramér-Rao bound
(:mod:`sblsim.models.bound`) is a true bound on its mean squared error.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Sections 4-5.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.component import Component
from sblsim.models.declarations import SEED_PARAMETERS, Column, FileKey, ModelError, Table, Variable, resolve_parameters
from sblsim.models.expressions import padded_rows, sample_due, switch
from sblsim.models.program import ProgramBuilder, Stream
from sblsim.models.table_text import format_table, parse_table
from sblsim.models.target.trajectories import (
    OPEN_DURATION,
    read_trajectory_file,
    semicircle,
    spiral,
    square_rows,
    waypoints,
)

TRAJECTORIES = ("semicircle", "spiral", "random", "square", "file", "random-walk")
#: Largest number of waypoints of a trajectory file.
MAX_WAYPOINTS = 512
WAYPOINTS = Table(
    columns=(Column("waypoint_time", "s", "Waypoint time", -1e7, 1e7),
             Column("waypoint_north", "m", "Waypoint North", -1e6, 1e6),
             Column("waypoint_east", "m", "Waypoint East", -1e6, 1e6),
             Column("waypoint_down", "m", "Waypoint depth", 0.0, 11000.0)),
    max_rows=MAX_WAYPOINTS, increasing=True, min_rows=2, when=("trajectory", "file"))

_DEPTH_NOISE, _RANDOM_PATH, _WALK_START, _WALK = range(4)


def _leg_direction(uniforms, start, leg, max_radius):
    """Heading of a random-path leg from its start: uniform, or toward the centre when it would leave the disc."""
    heading = 2.0 * math.pi * uniforms[0]
    nxt = start + leg * ca.vertcat(ca.cos(heading), ca.sin(heading))
    home = ca.atan2(-start[1], -start[0]) + (2.0 * math.pi / 3.0) * (uniforms[1] - 0.5)
    heading = ca.if_else(ca.norm_2(nxt) > max_radius, home, heading)
    return ca.vertcat(ca.cos(heading), ca.sin(heading))


class Target(Component):
    """Diver following a reference trajectory, with a depth sensor."""

    name = "target"
    component_index = 2

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("trajectory", "parameter", "String", "semicircle", description="Reference trajectory",
                     choices=TRAJECTORIES),
            Variable("trajectory_file", "parameter", "String", "", scope="config", file=FileKey(),
                     description="CSV of time [s], N, E, D [m] (trajectory = file)"),
            Variable("waypoints", "parameter", "String", "", scope="config",
                     description="Waypoints 'time N E D; ...' [s, m] (trajectory = file, instead of a file)"),
            Variable("waypoint_rows", "parameter", "Integer", 0, scope="fmu", table=WAYPOINTS,
                     description="Waypoints in use (trajectory = file)", min=0, max=MAX_WAYPOINTS),
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
            Variable("walk_q_horizontal", "parameter", "Real", 0.01, "m2/s3",
                     "Random walk: horizontal acceleration spectral density", min=0.0, max=100.0),
            Variable("walk_q_vertical", "parameter", "Real", 0.001, "m2/s3",
                     "Random walk: vertical acceleration spectral density", min=0.0, max=100.0),
            Variable("walk_p0_position", "parameter", "Real", 1.0, "m",
                     "Random walk: standard deviation of the start position", min=0.0, max=1e4),
            Variable("walk_p0_velocity", "parameter", "Real", 0.5, "m/s",
                     "Random walk: standard deviation of the start velocity", min=0.0, max=100.0),
            Variable("sample_period", "parameter", "Real", 0.1, "s",
                     "Depth-sensor sampling period T_s (the sampling time T)", min=0.001, max=60.0, scope="fmu"),
        )
        outputs = tuple(
            Variable(n, "output", "Real", 0.0, u, f"True target {what}, {axis} [NED]")
            for n, u, what, axis in zip(("pos_x", "pos_y", "pos_z", "vel_x", "vel_y", "vel_z"),
                                        ("m",) * 3 + ("m/s",) * 3, ("position",) * 3 + ("velocity",) * 3,
                                        ("North", "East", "Down") * 2)
        ) + (Variable("depth_measured", "output", "Real", 0.0, "m", "Depth-sensor reading", discrete=True),)
        return params + SEED_PARAMETERS + outputs

    @classmethod
    def fmu_parameters(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """FMU parameters of a configuration section: a trajectory file or waypoint text becomes the table.

        Raises
        ------
        ModelError
            If the file or text is malformed, or ``trajectory = file`` has neither.
        """
        out = super().fmu_parameters(values, n_beacons)
        if values.get("trajectory") == "file":
            out.update(WAYPOINTS.values(file_waypoints(values), "waypoint_rows"))
        return out

    @classmethod
    def reach(cls, values: Mapping[str, Any]) -> tuple[np.ndarray, float, float] | None:
        """Where a configuration's diver goes: its depths [m] and its least and greatest horizontal distance from
        the platform's centre [m] (the semicircle's radius, the square's corners, the random path's
        ``max_radius``, a file's waypoints), or None for a trajectory that does not bound them (a spiral, a random
        walk).

        Raises
        ------
        ModelError
            As :func:`file_waypoints`, for ``trajectory = file``.
        """
        kind = values["trajectory"]
        if kind == "file":
            rows = file_waypoints(values)
            return rows[:, 3], 0.0, float(np.linalg.norm(rows[:, 1:3], axis=1).max())
        if kind in ("semicircle", "square", "random"):
            far = {"semicircle": float(values["radius"]), "square": float(values["square_side"]) / np.sqrt(2.0),
                   "random": float(values["max_radius"])}[kind]
            return np.array([float(values["depth"])]), (far if kind == "semicircle" else 0.0), far
        return None

    @classmethod
    def config_values(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """Configuration keys from FMU parameters: the waypoint table becomes the ``waypoints`` text."""
        out = super().config_values(values, n_beacons)
        if out.get("trajectory") == "file":
            out["waypoints"] = format_table(WAYPOINTS.rows(values, "waypoint_rows"))
        return out

    @classmethod
    def build(cls, n_beacons: int):
        N = MAX_WAYPOINTS
        b = ProgramBuilder(cls, n_beacons,
                           states=[("t0", 1), ("k", 1), ("reading", 1), ("leg", 1), ("start", 2), ("direction", 2),
                                   ("walk", 6), ("walk_time", 1)],
                           derived=[("times", N), ("points", 3 * N), ("first", 1), ("last", 1)])

        def prepare(p):
            is_square = p["trajectory"] == TRAJECTORIES.index("square")
            square = square_rows(p["square_side"], p["speed"], p["depth"])
            count = ca.if_else(is_square, len(square), p["waypoint_rows"])
            columns = [ca.if_else(is_square, ca.vertcat(*[row[j] for row in square], ca.MX.zeros(N - len(square))),
                                  p[col.name]) for j, col in enumerate(WAYPOINTS.columns)]
            padded, last = padded_rows(count, columns, 1.0)
            values = ca.vertcat(padded[0], ca.vec(ca.horzcat(*padded[1:]).T), padded[0][0], last[0])
            # only a waypoint path reads them: the others skip the table work (a short-circuit conditional)
            tabled = ca.logic_or(is_square, p["trajectory"] == TRAJECTORIES.index("file"))
            values = ca.if_else(tabled, values, ca.MX.zeros(values.shape), True)
            return {"times": values[0:N], "points": values[N:4 * N], "first": values[4 * N], "last": values[4 * N + 1]}

        t = ca.SX.sym("t")
        xs, ps, ds = b.X.unpack(b.x), b.params(), b.D.unpack(b.d)
        branches = {
            "semicircle": lambda: semicircle(t, ps["radius"], ps["speed"], ps["depth"]),
            "spiral": lambda: spiral(t, ps["spiral_start_radius"], ps["spiral_pitch"], ps["speed"], ps["depth"]),
            "random": lambda: (ca.vertcat(xs["start"] + ps["speed"] * (t - xs["t0"] - xs["leg"] * ps["turn_interval"])
                                          * xs["direction"], ps["depth"]),
                               ca.vertcat(ps["speed"] * xs["direction"], 0.0)),
            "waypoints": lambda: waypoints(t, ds["times"], ds["points"], ds["first"], ds["last"]),
            "random-walk": lambda: (xs["walk"][0:3] + xs["walk"][3:6] * (t - xs["walk_time"]), xs["walk"][3:6]),
        }
        functions = {name: ca.Function(f"{b.prefix}_path_{name.replace('-', '_')}", [b.x, b.p, b.d, t],
                                       list(body()), ["x", "p", "d", "t"], ["pos", "vel"])
                     for name, body in branches.items()}
        # by trajectory index; the square and a file are waypoint paths
        tabled = {"square": "waypoints", "file": "waypoints"}
        path_switch = switch(f"{b.prefix}_path", [functions[tabled.get(name, name)] for name in TRAJECTORIES])
        zeros = {name: ca.SX.zeros(n) for name, n in b.X.blocks}

        def path(x, p, d, t):
            """Position and velocity of the configured trajectory at ``t`` (only its branch runs)."""
            pos, vel = path_switch(p["trajectory"], b.X.pack(x, zeros), b.p, b.d, t)
            return pos, vel

        def walk_mean(p):
            return ca.vertcat(p["radius"], 0.0, p["depth"], 0.0, p["speed"], 0.0)

        def init(p, d, w, t0):
            start = ca.vertcat(p["radius"], 0.0)
            direction = _leg_direction(w[_RANDOM_PATH], start, p["speed"] * p["turn_interval"], p["max_radius"])
            spread = ca.vertcat(*([p["walk_p0_position"]] * 3), *([p["walk_p0_velocity"]] * 3))
            x = {"t0": t0, "k": 0, "leg": 0, "start": start, "direction": direction,
                 "walk": walk_mean(p) + spread * w[_WALK_START], "walk_time": t0}
            pos, _ = path(x, p, d, t0)
            return {**x, "reading": pos[2] + p["depth_sigma"] * w[_DEPTH_NOISE][0]}

        def turn_due(x, u, p, d, t, h):
            return ca.logic_and(p["trajectory"] == TRAJECTORIES.index("random"),
                                sample_due(x["leg"], x["t0"], p["turn_interval"], t, h))

        def turn(x, u, p, d, w, t, h):
            leg = p["speed"] * p["turn_interval"]
            start = x["start"] + leg * x["direction"]
            return {"leg": x["leg"] + 1, "start": start,
                    "direction": _leg_direction(w[_RANDOM_PATH], start, leg, p["max_radius"])}

        def sample_due_(x, u, p, d, t, h):
            return sample_due(x["k"], x["t0"], p["sample_period"], t, h)

        def sample(x, u, p, d, w, t, h):
            k = x["k"] + 1
            t_k = x["t0"] + k * p["sample_period"]
            walk = walk_step(x["walk"], p["sample_period"], p["walk_q_horizontal"], p["walk_q_vertical"], w[_WALK])
            x = {**x, "walk": walk, "walk_time": t_k}
            pos, _ = path(x, p, d, t_k)
            return {"k": k, "walk": walk, "walk_time": t_k,
                    "reading": pos[2] + p["depth_sigma"] * w[_DEPTH_NOISE][0]}

        def output(x, p, d, t):
            pos, vel = path(x, p, d, t)
            out = {f"pos_{a}": pos[k] for k, a in enumerate("xyz")}
            out.update({f"vel_{a}": vel[k] for k, a in enumerate("xyz")})
            out["depth_measured"] = x["reading"]
            return out

        depth, legs = Stream(_DEPTH_NOISE, "normal", 1), Stream(_RANDOM_PATH, "uniform", 2)
        walk_start = Stream(_WALK_START, "normal", 6, when=("trajectory", "random-walk"))
        walk = Stream(_WALK, "normal", 6, when=("trajectory", "random-walk"))
        return b.program(b.prepare(prepare), b.init(init, (depth, legs, walk_start)), b.output(output),
                         events=[b.event("turn", turn_due, turn, (legs,)),
                                 b.event("sample", sample_due_, sample, (depth, walk))])


def walk_step(walk, dt, q_horizontal, q_vertical, noise) -> ca.SX:
    """One exact step of white-noise acceleration: ``[p, v] ← Φ(dt) [p, v] + w``, ``w ~ N(0, Q(dt))`` per axis.

    ``walk`` is (p_x, p_y, p_z, v_x, v_y, v_z); ``noise`` six standard normals; the
    Cholesky factor of ``q [[dt³/3, dt²/2], [dt²/2, dt]]`` is
    ``sqrt(q) [[sqrt(dt³/3), 0], [sqrt(3 dt)/2, sqrt(dt/4)]]``.
    """
    out = []
    l00, l10, l11 = ca.sqrt(dt**3 / 3.0), ca.sqrt(3.0 * dt) / 2.0, ca.sqrt(dt / 4.0)
    for axis, q in enumerate((q_horizontal, q_horizontal, q_vertical)):
        s = ca.sqrt(q)
        position = walk[axis] + dt * walk[axis + 3] + s * l00 * noise[2 * axis]
        velocity = walk[axis + 3] + s * (l10 * noise[2 * axis] + l11 * noise[2 * axis + 1])
        out.append((position, velocity))
    return ca.vertcat(*[p for p, _ in out], *[v for _, v in out])


def file_waypoints(values: Mapping[str, Any]) -> np.ndarray:
    """The waypoints of ``trajectory = file``: from ``trajectory_file``, else from the ``waypoints`` text.

    Returns
    -------
    ndarray, shape (rows, 4)
        time [s], N, E, D [m].

    Raises
    ------
    ModelError
        If neither is given, or the file or text is malformed.
    """
    if values.get("trajectory_file"):
        path = Path(values["trajectory_file"])
        stamp = (path.stat().st_size, path.stat().st_mtime_ns) if path.is_file() else None
        return _read_file(str(path), stamp).copy()
    rows = parse_table(values.get("waypoints", ""), WAYPOINTS, "target.waypoints")
    if rows.shape[0] < 2:
        raise ModelError("target.trajectory_file: trajectory = file needs a trajectory_file (or at least 2 "
                         "waypoints 'time N E D; ...')")
    return rows


@lru_cache(maxsize=64)
def _read_file(path: str, stamp) -> np.ndarray:
    return read_trajectory_file(path, WAYPOINTS)


def natural_duration(params: Mapping[str, Any]) -> float:
    """Duration of one pass of the configured trajectory [s].

    Semicircle: π r / v; square: 4 s / v; file: its last time; spiral, random
    and random-walk: :data:`~sblsim.models.target.trajectories.OPEN_DURATION`.
    """
    p = resolve_parameters(Target.config_parameters(), params, "target")
    kind = p["trajectory"]
    if kind == "semicircle":
        return math.pi * p["radius"] / p["speed"]
    if kind == "square":
        return 4.0 * p["square_side"] / p["speed"]
    if kind == "file":
        return float(file_waypoints(p)[-1, 0])
    return OPEN_DURATION


def start_state(params: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Position [m] and velocity [m/s] of the diver at t = 0, each (3,), from the model itself.

    Deterministic for every trajectory (the random path starts at (r, 0),
    and its first heading is random, so its velocity is given as zero; the
    random walk gives the mean of its start, (r, 0, depth) at (0, v, 0)).
    """
    p = resolve_parameters(Target.config_parameters(), params, "target")
    pos, vel = _start_state(tuple(sorted(p.items())))
    return pos.copy(), vel.copy()


@lru_cache(maxsize=256)
def _start_state(items: tuple) -> tuple[np.ndarray, np.ndarray]:
    p = dict(items)
    program = Target.program()
    vector = Target.parameter_vector(Target.fmu_parameters(p))
    d = program.prepare(vector)
    width = sum(s.width for s in program.init_streams)
    x = program.init(vector, d, np.zeros(width), 0.0)
    y = np.asarray(program.output(x, vector, d, 0.0)).reshape(-1)
    names = [v.name for v in Target.outputs()]
    pos = np.array([y[names.index(f"pos_{a}")] for a in "xyz"])
    vel = np.array([y[names.index(f"vel_{a}")] for a in "xyz"])
    return pos, (np.zeros(3) if p["trajectory"] == "random" else vel)


__all__ = ["MAX_WAYPOINTS", "TRAJECTORIES", "Target", "WAYPOINTS", "file_waypoints", "natural_duration",
           "start_state"]
