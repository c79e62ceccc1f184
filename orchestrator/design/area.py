"""A design problem's places as geometry: the work area (:class:`Area`, its points at the vehicle depths), a polygon
and the devices already in the water as arrays, and the telemetry site's origin [°, WGS 84].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from sblsim.models.errors import ConfigError
from sblsim.orchestrator.design.keys import MAX_RECEIVERS, MAX_VERTICES


def area_origin(text: str) -> tuple[float, float]:
    """``site.area.origin``: 'latitude longitude' [°, WGS 84] as two numbers.

    Raises
    ------
    ConfigError
        One line naming the key and the allowed ranges.
    """
    parts = text.replace(",", " ").split()
    try:
        lat, lon = (float(v) for v in parts)
    except ValueError:
        lat = lon = math.nan
    if len(parts) != 2 or not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ConfigError(f"site.area.origin: {text[:40]!r}; allowed 'latitude longitude' with a latitude in "
                          "[-90, 90] and a longitude in [-180, 180] (WGS 84 degrees), e.g. '60.38 5.34'")
    return lat, lon


def existing_devices(text: str, where: str = "candidates.existing_m") -> np.ndarray:
    """The devices already in place from ``"north east [depth]; ..."`` [m], (k, 3) North, East, depth; the depth
    NaN where not given (k = 0 for an empty text).

    Raises
    ------
    ConfigError
        Naming ``where``: rows of other than two or three numbers, a value not finite or beyond ±100000 m, a
        negative depth, more than :data:`~sblsim.orchestrator.design.keys.MAX_RECEIVERS` rows, two devices at one place.
    """
    rows = [r for r in text.replace(",", " ").split(";") if r.strip()]
    if len(rows) > MAX_RECEIVERS:
        raise ConfigError(f"{where}: {len(rows)} devices; allowed at most {MAX_RECEIVERS}")
    out = np.full((len(rows), 3), np.nan)
    for k, row in enumerate(rows):
        try:
            values = [float(x) for x in row.split()]
        except ValueError:
            raise ConfigError(f"{where}: expected 'north east [depth]; ...' in metres, got {row.strip()[:40]!r}") \
                from None
        if len(values) not in (2, 3) or not np.all(np.isfinite(values)) or max(abs(v) for v in values) > 1e5 \
                or (len(values) == 3 and values[2] < 0.0):
            raise ConfigError(f"{where}: {row.strip()[:40]!r}; allowed 'north east [depth]' in metres, each within "
                              "±100000, the depth at least 0")
        out[k, :len(values)] = values
    if len(out) > 1:
        gaps = np.hypot(*(out[:, None, :2] - out[None, :, :2]).transpose(2, 0, 1)) + np.diag(np.full(len(out), np.inf))
        if gaps.min() < 1e-6:
            raise ConfigError(f"{where}: two devices at one place; allowed distinct places")
    return out


def polygon(text: str, where: str) -> np.ndarray:
    """A polygon's vertices from ``"north east; north east; ..."`` [m], (V, 2), at least three, not degenerate.

    Raises
    ------
    ConfigError
        Naming ``where``.
    """
    rows = [r for r in text.replace(",", " ").split(";") if r.strip()]
    if not 3 <= len(rows) <= MAX_VERTICES:
        raise ConfigError(f"{where}: {len(rows)} vertices; give 3 to {MAX_VERTICES} as 'north east; north east; "
                          "...' [m]")
    try:
        vertices = np.array([[float(x) for x in r.split()] for r in rows], dtype=float)
    except ValueError:
        raise ConfigError(f"{where}: expected 'north east; north east; ...' in metres") from None
    if vertices.ndim != 2 or vertices.shape[1] != 2 or not np.all(np.isfinite(vertices)) \
            or np.abs(vertices).max() > 1e5:
        raise ConfigError(f"{where}: expected 'north east; north east; ...' in metres, each within ±100000")
    n, e = vertices.T
    if abs(np.dot(n, np.roll(e, -1)) - np.dot(e, np.roll(n, -1))) < 1e-6:
        raise ConfigError(f"{where}: the polygon encloses no area")
    return vertices


@dataclass(frozen=True)
class Area:
    """A circle or polygon in the horizontal plane (North, East [m])."""

    vertices: np.ndarray | None = None
    centre: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0

    @classmethod
    def of(cls, section: Mapping[str, Any], where: str, radius: float | None = None) -> Area:
        """The area of a ``[work_area]`` or ``[seafloor]`` section (``radius`` in place of a 0 radius)."""
        if section["shape"] == "polygon":
            return cls(vertices=polygon(section["polygon"], f"{where}.polygon"))
        r = section["radius_m"] if section["radius_m"] > 0.0 or radius is None else radius
        return cls(centre=(section["centre_north_m"], section["centre_east_m"]), radius=float(r))

    @property
    def middle(self) -> tuple[float, float]:
        """The circle's centre, or the mean of the polygon's vertices (North, East) [m]."""
        return self.centre if self.vertices is None else tuple(float(v) for v in self.vertices.mean(axis=0))

    @property
    def reach(self) -> float:
        """The largest distance from :attr:`middle` to the boundary [m]."""
        if self.vertices is None:
            return self.radius
        return float(np.max(np.hypot(*(self.vertices - np.asarray(self.middle)).T)))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box's lower and upper corners (North, East) [m]."""
        if self.vertices is not None:
            return self.vertices.min(axis=0), self.vertices.max(axis=0)
        c = np.asarray(self.centre)
        return c - self.radius, c + self.radius

    def distance(self, points: np.ndarray) -> np.ndarray:
        """The signed distance of points (..., 2) to the area's boundary [m]: negative inside."""
        points = np.asarray(points, dtype=float)
        if self.vertices is None:
            return np.hypot(points[..., 0] - self.centre[0], points[..., 1] - self.centre[1]) - self.radius
        return signed_distance(points, self.vertices)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Which points (..., 2) lie inside (or on) the area."""
        return self.distance(points) <= 1e-9

    def outline(self) -> np.ndarray:
        """Points of the boundary (K, 2), closed (for figures)."""
        if self.vertices is not None:
            return np.vstack([self.vertices, self.vertices[:1]])
        a = np.linspace(0.0, 2.0 * math.pi, 181)
        return np.column_stack([self.centre[0] + self.radius * np.cos(a), self.centre[1] + self.radius * np.sin(a)])


def signed_distance(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Signed distance of points (..., 2) to a polygon's boundary (V, 2) [m]: negative inside (even-odd rule)."""
    p = np.asarray(points, dtype=float)[..., None, :]
    a, b = vertices, np.roll(vertices, -1, axis=0)
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.sum(ab * ab, axis=-1), 0.0, 1.0)
    nearest = np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=-1)
    # inside: a ray to the East crosses the edges an odd number of times
    y, x = p[..., 0], p[..., 1]
    crosses = ((a[:, 0] > y) != (b[:, 0] > y)) & (x < a[:, 1] + (y - a[:, 0]) * ab[:, 1] / np.where(
        ab[:, 0] == 0.0, 1.0, ab[:, 0]))
    inside = np.sum(crosses, axis=-1) % 2 == 1
    return np.where(inside, -nearest, nearest)


def work_area_points(area: Area, count: int, depths: list[float]) -> np.ndarray:
    """The work area's points: a regular grid of ``count`` × ``count`` over its bounding box, those inside, at
    each depth; (M, 3) NED [m], depth-major, North-major within a depth.

    Raises
    ------
    ConfigError
        If no grid point lies inside the area.
    """
    low, high = area.bounds()
    north = np.linspace(low[0], high[0], count)
    east = np.linspace(low[1], high[1], count)
    N, E = np.meshgrid(north, east, indexing="ij")
    plane = np.column_stack([N.ravel(), E.ravel()])
    plane = plane[area.contains(plane)]
    if plane.shape[0] == 0:
        raise ConfigError("work_area: no grid point lies inside the work area; give more work_area.points")
    return np.vstack([np.column_stack([plane, np.full(len(plane), d)]) for d in depths])


__all__ = ["Area", "existing_devices", "polygon", "signed_distance", "work_area_points"]
