"""The study area of a telemetry array: the water (a lake, river or fjord outline) as a polygon, where receivers may
be moored and where tags are to be positioned.

A polygon is given by its vertices (x, y) [m] in the array's local frame, or as a GeoJSON geometry (a
``Polygon`` or ``MultiPolygon``, or a ``Feature`` of one; RFC 7946) whose coordinates are already in that frame;
reading such a file is the orchestrator's. The geometry is shapely's (GEOS): containment
(:func:`shapely.contains_xy`: a point on the outline is outside), the distance to the shore (the polygon's
boundary, islands' included), a grid of points inside.

A receiver's place is allowed (:func:`inside`) when it is inside the water and, optionally, at least
``min_shore_m`` from the shore (a mooring's margin) and at most ``max_shore_m`` from it (receivers moored from the
shore); with mooring lines, only on them (:func:`line_places`: points at a spacing along each polyline by shapely's
``interpolate``, every line inside the water).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
import shapely
from shapely.geometry import LineString, MultiPolygon, Polygon, shape

from sblsim.models.errors import ModelError

#: The most vertices of a study area.
MAX_VERTICES = 100_000
#: The most grid points :func:`grid` makes.
MAX_GRID_POINTS = 1_000_000


def polygon(area: Any, key: str = "site.area") -> Polygon | MultiPolygon:
    """A study area from its vertices or a GeoJSON geometry, checked.

    Parameters
    ----------
    area : array_like of shape (K, 2), Mapping, or shapely Polygon / MultiPolygon
        The outline's vertices (x, y) [m], K ≥ 3, in order (closing vertex optional); or a GeoJSON ``Polygon``,
        ``MultiPolygon`` or a ``Feature`` of one (holes: islands); or a shapely geometry.
    key : str, optional
        The key the errors name.

    Returns
    -------
    shapely Polygon or MultiPolygon

    Raises
    ------
    ModelError
        Naming ``key``: fewer than 3 vertices, a value not finite, a self-crossing outline (shapely's reason), no
        area, or a GeoJSON type other than those.
    """
    if isinstance(area, Mapping):
        geometry = area.get("geometry") if area.get("type") == "Feature" else area
        kind = geometry.get("type") if isinstance(geometry, Mapping) else None
        if kind not in ("Polygon", "MultiPolygon"):
            raise ModelError(f"{key}: a GeoJSON {kind or area.get('type')!r}; allowed a Polygon, a MultiPolygon or "
                             "a Feature of one")
        try:
            geom = shape(geometry)
        except (TypeError, ValueError, KeyError, IndexError, shapely.errors.GEOSException) as error:
            raise ModelError(f"{key}: the GeoJSON's coordinates are not a polygon ({error})") from None
    elif isinstance(area, (Polygon, MultiPolygon)):
        geom = area
    else:
        try:
            vertices = np.asarray(area, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(f"{key}: expected vertices [x_m, y_m], a GeoJSON polygon or a polygon") from None
        if vertices.ndim != 2 or vertices.shape[1] != 2 or not 3 <= len(vertices) <= MAX_VERTICES:
            raise ModelError(f"{key}: vertices of shape {vertices.shape}; allowed 3 to {MAX_VERTICES} rows "
                             "[x_m, y_m]")
        if not np.isfinite(vertices).all():
            raise ModelError(f"{key}: a vertex is not finite")
        geom = Polygon(vertices)
    coords = shapely.get_coordinates(geom)
    if not np.isfinite(coords).all():
        raise ModelError(f"{key}: a vertex is not finite")
    if len(coords) > MAX_VERTICES + 1:
        raise ModelError(f"{key}: {len(coords)} vertices; allowed at most {MAX_VERTICES}")
    if not geom.is_valid:
        raise ModelError(f"{key}: not a valid polygon ({shapely.is_valid_reason(geom)}); allowed an outline that "
                         "does not cross itself")
    if not geom.area > 0.0:
        raise ModelError(f"{key}: the polygon has no area; allowed an outline around water")
    return geom


def shore_distance(area: Polygon | MultiPolygon, points: np.ndarray) -> np.ndarray:
    """The distance from each point to the shore (the area's boundary, islands' included) [m].

    Parameters
    ----------
    area : shapely Polygon or MultiPolygon
    points : ndarray, shape (..., 2)
        [m].

    Returns
    -------
    ndarray, shape (...)
        [m].
    """
    points = np.asarray(points, float)
    return shapely.distance(area.boundary, shapely.points(points))


def inside(area: Polygon | MultiPolygon, points: np.ndarray, min_shore_m: float = 0.0,
           max_shore_m: float | None = None) -> np.ndarray:
    """Whether each point may hold a receiver: inside the water, at least ``min_shore_m`` and at most
    ``max_shore_m`` from the shore.

    Parameters
    ----------
    area : shapely Polygon or MultiPolygon
    points : ndarray, shape (..., 2)
        [m]; leading axes: layouts and receivers.
    min_shore_m : float, optional
        [m], 0 or more.
    max_shore_m : float, optional
        [m], at least ``min_shore_m``; None: no limit.

    Returns
    -------
    ndarray of bool, shape (...)

    Raises
    ------
    ModelError
        For a negative margin, or a largest distance below it.
    """
    if not (math.isfinite(min_shore_m) and min_shore_m >= 0.0):
        raise ModelError(f"shore distance: min_shore_m {min_shore_m!r}; allowed [0, inf) m")
    if max_shore_m is not None and not max_shore_m >= min_shore_m:
        raise ModelError(f"shore distance: max_shore_m {max_shore_m!r}; allowed [{min_shore_m:g}, inf) m")
    points = np.asarray(points, float)
    ok = shapely.contains_xy(area, points[..., 0], points[..., 1])
    if min_shore_m > 0.0 or max_shore_m is not None:
        d = shore_distance(area, points)
        ok &= d >= min_shore_m
        if max_shore_m is not None:
            ok &= d <= max_shore_m
    return ok


def grid(area: Polygon | MultiPolygon, spacing_m: float, min_shore_m: float = 0.0) -> np.ndarray:
    """The points of a square grid inside an area (the cells' centres of the area's bounding box, kept where
    :func:`inside`), e.g. a work area's points.

    Parameters
    ----------
    area : shapely Polygon or MultiPolygon
    spacing_m : float
        [m], positive.
    min_shore_m : float, optional
        [m].

    Returns
    -------
    ndarray, shape (M, 2)
        [m].

    Raises
    ------
    ModelError
        For a spacing not positive, or one giving more than :data:`MAX_GRID_POINTS` cells.
    """
    if not (math.isfinite(spacing_m) and spacing_m > 0.0):
        raise ModelError(f"grid spacing: {spacing_m!r} m; allowed (0, inf)")
    x0, y0, x1, y1 = area.bounds
    nx, ny = max(1, math.ceil((x1 - x0) / spacing_m)), max(1, math.ceil((y1 - y0) / spacing_m))
    if nx * ny > MAX_GRID_POINTS:
        raise ModelError(f"grid spacing: {spacing_m:g} m gives {nx * ny} cells; allowed at most {MAX_GRID_POINTS}")
    x = x0 + spacing_m * (np.arange(nx) + 0.5)
    y = y0 + spacing_m * (np.arange(ny) + 0.5)
    points = np.stack(np.meshgrid(x, y, indexing="xy"), axis=-1).reshape(-1, 2)
    return points[inside(area, points, min_shore_m)]


def line_places(area: Polygon | MultiPolygon, lines: list[np.ndarray], spacing_m: float,
                key: str = "site.area.lines") -> np.ndarray:
    """The places along mooring lines: on each polyline, points evenly spaced by about ``spacing_m`` from its first
    vertex to its last, both included (shapely's :meth:`~shapely.LineString.interpolate` at ``linspace(0, length,
    max(2, round(length / spacing_m) + 1))``); a place shared by two lines counted once.

    Parameters
    ----------
    area : shapely Polygon or MultiPolygon
        The water.
    lines : list of ndarray, each of shape (V, 2)
        Each line's vertices (x, y) [m], V ≥ 2, in order.
    spacing_m : float
        [m], positive.
    key : str, optional
        The key the errors name.

    Returns
    -------
    ndarray, shape (M, 2)
        [m], line by line in order.

    Raises
    ------
    ModelError
        Naming ``key[k]``: a line of fewer than two vertices or of no length, or one that leaves the water (or runs
        along its shore): where, in one line.
    """
    if not (math.isfinite(spacing_m) and spacing_m > 0.0):
        raise ModelError(f"{key}: a spacing of {spacing_m!r} m; allowed (0, inf)")
    out = []
    for k, vertices in enumerate(lines):
        vertices = np.asarray(vertices, float)
        if vertices.ndim != 2 or vertices.shape[0] < 2 or vertices.shape[1] != 2 or not np.isfinite(vertices).all():
            raise ModelError(f"{key}[{k}]: expected 2 or more vertices 'north east; north east' [m]")
        line = LineString(vertices)
        if not line.length > 0.0:
            raise ModelError(f"{key}[{k}]: the line has no length; allowed 2 or more distinct vertices")
        along = np.linspace(0.0, line.length, max(2, round(line.length / spacing_m) + 1))
        places = shapely.get_coordinates(line.interpolate(along))
        outside = ~shapely.contains_xy(area, places[:, 0], places[:, 1])
        if not area.contains(line) or outside.any():
            leaves = line.difference(area)
            where = shapely.get_coordinates(leaves.representative_point())[0] if not leaves.is_empty else \
                places[np.argmax(outside)]
            raise ModelError(f"{key}[{k}]: the line leaves the water (site.area) near {where[0]:.6g} m North, "
                             f"{where[1]:.6g} m East; allowed lines inside the water")
        out.append(places)
    places = np.vstack(out) if out else np.empty((0, 2))
    _, first = np.unique(np.round(places, 6), axis=0, return_index=True)
    return places[np.sort(first)]


def spread(points: np.ndarray) -> np.ndarray:
    """The largest distance between any two of a layout's devices (its footprint), per layout.

    Parameters
    ----------
    points : ndarray, shape (..., n, d)
        The devices' positions [m] (d = 2: North, East; or any number of coordinates); leading axes: layouts.

    Returns
    -------
    ndarray, shape (...)
        [m]; 0 for fewer than two devices.
    """
    points = np.asarray(points, float)
    if points.shape[-2] < 2:
        return np.zeros(points.shape[:-2])
    gaps = np.linalg.norm(points[..., :, None, :] - points[..., None, :, :], axis=-1)
    return gaps.max(axis=(-2, -1))


__all__ = ["MAX_GRID_POINTS", "MAX_VERTICES", "grid", "inside", "line_places", "polygon", "shore_distance",
           "spread"]
