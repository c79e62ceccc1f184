"""Reference trajectories of the diver (target), exact in continuous time.

Every trajectory returns the position [m] and velocity [m/s] at any time, so
the target does not depend on the communication step. Scenario geometry
(sblsim's choice, after the paper's scenarios): the semicircle and the spiral
are centred on the SBL cross; the diver swims at constant speed and holds
position once a finite path ends.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 5
(scenarios 1-3 and the harbour validation).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from models.core import ModelError

#: Simulated duration of the open-ended trajectories (spiral, random) [s].
OPEN_DURATION = 100.0


class Semicircle:
    """Half circle of radius r around the origin, from (0, -r) through (r, 0) to (0, r)."""

    def __init__(self, radius: float, speed: float, depth: float) -> None:
        self.radius, self.speed, self.depth = radius, speed, depth
        self.duration = math.pi * radius / speed

    def state(self, t: float, batch: int) -> tuple[np.ndarray, np.ndarray]:
        tc = min(t, self.duration)
        theta = -0.5 * math.pi + self.speed * tc / self.radius
        moving = self.speed if t < self.duration else 0.0
        pos = [self.radius * math.cos(theta), self.radius * math.sin(theta), self.depth]
        vel = [-moving * math.sin(theta), moving * math.cos(theta), 0.0]
        return np.tile(pos, (batch, 1)), np.tile(vel, (batch, 1))


class Spiral:
    """Archimedean spiral ``ρ = ρ0 + k θ`` (k = pitch / 2π), swum at constant speed.

    Arc length ``s(θ) = (k/2)[u √(1+u²) + asinh u]`` with ``u = ρ/k`` is inverted
    on a dense table.
    """

    def __init__(self, start_radius: float, pitch: float, speed: float, depth: float) -> None:
        self.k = pitch / (2.0 * math.pi)
        self.start_radius, self.speed, self.depth = start_radius, speed, depth
        self.duration = OPEN_DURATION

        def arc(rho: np.ndarray) -> np.ndarray:
            u = rho / self.k
            return 0.5 * self.k * (u * np.sqrt(1.0 + u * u) + np.arcsinh(u))

        length = speed * self.duration * 1.5 + 1.0
        rho_max = math.sqrt(start_radius**2 + 2.0 * self.k * length) + self.k
        self._rho = np.linspace(start_radius, rho_max, 200_001)
        self._s = arc(self._rho) - arc(np.array(start_radius))

    def state(self, t: float, batch: int) -> tuple[np.ndarray, np.ndarray]:
        rho = float(np.interp(self.speed * t, self._s, self._rho))
        theta = (rho - self.start_radius) / self.k
        c, s = math.cos(theta), math.sin(theta)
        tangent = np.array([self.k * c - rho * s, self.k * s + rho * c])
        tangent *= self.speed / np.linalg.norm(tangent)
        return (np.tile([rho * c, rho * s, self.depth], (batch, 1)),
                np.tile([tangent[0], tangent[1], 0.0], (batch, 1)))


class Waypoints:
    """Piecewise-linear path through timed waypoints, shared by all replicates or per replicate.

    Parameters
    ----------
    times : ndarray, shape (n,)
        Strictly increasing waypoint times [s].
    points : ndarray, shape (n, 3) or (B, n, 3)
        Waypoints [m] (NED).
    """

    def __init__(self, times: np.ndarray, points: np.ndarray) -> None:
        self.times = np.asarray(times, float)
        self.points = np.asarray(points, float)
        self.duration = float(self.times[-1])

    def state(self, t: float, batch: int) -> tuple[np.ndarray, np.ndarray]:
        pts = self.points if self.points.ndim == 3 else np.broadcast_to(self.points, (batch,) + self.points.shape)
        if t >= self.times[-1]:
            return pts[:, -1, :].copy(), np.zeros((batch, 3))
        if t < self.times[0]:
            return pts[:, 0, :].copy(), np.zeros((batch, 3))
        k = int(np.searchsorted(self.times, t, side="right") - 1)
        span = self.times[k + 1] - self.times[k]
        vel = (pts[:, k + 1, :] - pts[:, k, :]) / span
        return pts[:, k, :] + vel * (t - self.times[k]), vel


def square(side: float, speed: float, depth: float) -> Waypoints:
    """Square of the given side centred on the origin, from its SW corner N, E, S, W."""
    h = 0.5 * side
    corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h], [-h, -h]])
    times = np.arange(5) * side / speed
    return Waypoints(times, np.column_stack([corners, np.full(5, depth)]))


def random_path(uniforms: np.ndarray, start: np.ndarray, speed: float, interval: float,
                max_radius: float, depth: float) -> Waypoints:
    """Random path with sudden changes of direction, one per replicate.

    Each ``interval`` the diver turns to a new heading drawn uniformly in
    [0, 2π); when a leg would leave the disc of radius ``max_radius`` the
    heading is drawn within ±60° of the bearing to the centre instead.

    Parameters
    ----------
    uniforms : ndarray, shape (B, n_legs, 2)
        Uniform [0, 1) draws, two per leg.
    start : ndarray, shape (2,)
        Start position (N, E) [m].
    """
    batch, legs, _ = uniforms.shape
    leg = speed * interval
    points = np.empty((batch, legs + 1, 2))
    points[:, 0] = start
    for j in range(legs):
        p = points[:, j]
        heading = 2.0 * np.pi * uniforms[:, j, 0]
        nxt = p + leg * np.column_stack([np.cos(heading), np.sin(heading)])
        outside = np.linalg.norm(nxt, axis=1) > max_radius
        home = np.arctan2(-p[:, 1], -p[:, 0]) + np.deg2rad(120.0) * (uniforms[:, j, 1] - 0.5)
        heading = np.where(outside, home, heading)
        points[:, j + 1] = p + leg * np.column_stack([np.cos(heading), np.sin(heading)])
    xyz = np.concatenate([points, np.full((batch, legs + 1, 1), depth)], axis=2)
    return Waypoints(np.arange(legs + 1) * interval, xyz)


def read_trajectory_file(path: str | Path) -> Waypoints:
    """Read a trajectory CSV with columns time [s], N [m], E [m], D [m].

    A header line is allowed; at least two rows with strictly increasing,
    finite times.

    Raises
    ------
    ModelError
        If the file is missing or malformed; the message names
        ``target.trajectory_file``.
    """
    import pandas as pd

    field = "target.trajectory_file"
    if not str(path) or not Path(path).is_file():
        raise ModelError(f"{field}: no such file {str(path)!r}")
    try:
        table = pd.read_csv(path, header=None, comment="#", skip_blank_lines=True, dtype=str)
        if table.shape[0] and pd.to_numeric(table.iloc[0], errors="coerce").isna().any():
            table = table.iloc[1:]  # a header line
        data = table.apply(pd.to_numeric, errors="raise").to_numpy(float)
    except (ValueError, OSError, pd.errors.ParserError) as exc:
        raise ModelError(f"{field}: {str(path)!r} is not a CSV of numbers time, N, E, D ({exc.__class__.__name__})") from None
    if data.ndim != 2 or data.shape[1] != 4:
        raise ModelError(f"{field}: {str(path)!r} must have 4 columns time [s], N, E, D [m]; found {data.shape[-1]}")
    if data.shape[0] < 2 or not np.all(np.isfinite(data)):
        raise ModelError(f"{field}: {str(path)!r} needs at least 2 rows of finite numbers")
    if np.any(np.diff(data[:, 0]) <= 0):
        raise ModelError(f"{field}: times in {str(path)!r} must be strictly increasing")
    return Waypoints(data[:, 0], data[:, 1:])
