"""The eigenray tables a channel interpolates instead of solving: the earliest eigenray, and every family's.

The exact solve of :mod:`sblsim.models.acoustics.rays` (a bracketed Newton iteration per eigenray) is tabled once
per run over the box of depths and distances the run needs (:data:`RAY_BOUNDS`): :data:`RAY_TABLE`, the earliest
eigenray at the nodes of :data:`RAY_GRID`, as offsets from the isovelocity image path that a trilinear
interpolation reproduces to :data:`RAY_TABLE_TOLERANCE` at every cell it is used in (a cell that would not is
marked for the exact solve), and :data:`FAMILY_TABLE`, each family's eigenray (direct, surface, bottom) with its
spreading, for multipath. :func:`first_arrival_grid` and :func:`arrivals_grid` evaluate them in the channel's
casadi program, so the local engine and the generated C use the same tables.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.rays import (
    BOTTOM,
    SURFACE,
    arrivals,
    first_arrival,
    first_arrival_function,
    profile_arrays,
)
from sblsim.models.acoustics.sound_speed import NODES
from sblsim.models.acoustics.spreading_loss import spherical_spreading
from sblsim.models.declarations import Column, Table
from sblsim.models.expressions import switch

#: Nodes of the eigenray table along the source depth, the receiver depth and the horizontal distance.
RAY_GRID = (4, 4, 32)
#: Rows of a full eigenray table (one per node, the source depth varying fastest, then the receiver depth).
RAY_TABLE_ROWS = RAY_GRID[0] * RAY_GRID[1] * RAY_GRID[2]
#: The earliest eigenray at each node of the table: its time over the length of the isovelocity image of its
#: path, its angles less the image's, its path, and whether a cell at the node needs the exact solve.
RAY_TABLE = Table(
    columns=(Column("ray_slowness", "s/m", "Eigenray table: travel time over the image path's length", 0.0, 1.0),
             Column("ray_launch_offset", "rad", "Eigenray table: launch angle less the image path's", -4.0, 4.0),
             Column("ray_arrival_offset", "rad", "Eigenray table: arrival angle less the image path's", -4.0, 4.0),
             Column("ray_kind", "1",
                    "Eigenray table: path (1 direct, 2 surface, 3 bottom, 4 the direct family's other; 0 none)",
                    0.0, 4.0),
             Column("ray_exact", "1", "Eigenray table: 1 where a cell at the node needs the exact solve", 0.0, 1.0)),
    max_rows=RAY_TABLE_ROWS)
#: The table's box: source depth, receiver depth [m] and horizontal distance [m], each (min, max).
RAY_BOUNDS = ("ray_zs_min", "ray_zs_max", "ray_zr_min", "ray_zr_max", "ray_x_min", "ray_x_max")
#: What the interpolated table must reproduce of the exact solve at the centre of every cell it is used in:
#: travel time [s] and angles [rad] (a cell beyond it is solved exactly).
RAY_TABLE_TOLERANCE = (1e-7, 1e-5)


def ray_grid(bounds):
    """The table's node coordinates from its box ``bounds`` (6,): the three axes stacked, (sum(RAY_GRID),).

    An empty box (``max ≤ min``) is given a width of 1 m so that the grid increases."""
    out = []
    for j, n in enumerate(RAY_GRID):
        lo, hi = bounds[2 * j], bounds[2 * j + 1]
        width = ca.if_else(hi > lo, hi - lo, 1.0) if isinstance(lo, (ca.SX, ca.MX)) else (hi - lo if hi > lo else 1.0)
        out += [lo + width * (k / (n - 1)) for k in range(n)]
    return ca.vertcat(*out) if isinstance(bounds[0], (ca.SX, ca.MX)) else np.array(out, dtype=float)


def ray_values(columns):
    """The interpolant's values from the table's columns (each (RAY_TABLE_ROWS, 1)): interleaved, the column
    fastest."""
    return ca.reshape(ca.horzcat(*columns).T, -1, 1)


@lru_cache(maxsize=1)
def _interpolant() -> ca.Function:
    return ca.interpolant("sblsim_ray_grid", "linear", list(RAY_GRID), len(RAY_TABLE.columns))


def _images(kind, zs, zr, x, depth):
    """Length [m] and launch and arrival angles [rad] of the isovelocity image of path ``kind``."""
    image = ca.if_else(kind == SURFACE, zs + zr, ca.if_else(kind == BOTTOM, 2.0 * depth - zs - zr, zr - zs))
    angle = ca.atan2(image, x)
    launch = ca.if_else(kind == SURFACE, -angle, angle)
    arrival = ca.if_else(kind == BOTTOM, -angle, angle)
    return ca.sqrt(x * x + image * image), launch, arrival


@lru_cache(maxsize=1)
def _image_function() -> ca.Function:
    """``(kind, zs, zr, x, depth) -> (length, launch, arrival)``: :func:`_images` (the builder's offsets)."""
    args = [ca.SX.sym(n) for n in ("kind", "zs", "zr", "x", "depth")]
    return ca.Function("sblsim_ray_image", args, list(_images(*args)))


@lru_cache(maxsize=1)
def _row_eigenray() -> ca.Function:
    """``(zs, zr, x, depth, row) -> (τ, launch, arrival, kind)``: the eigenray a table row gives at a geometry,
    ``τ / L`` times the image's length ``L`` and the image's angles plus the row's offsets."""
    zs, zr, x, depth = (ca.SX.sym(n) for n in ("zs", "zr", "x", "depth"))
    row = ca.SX.sym("row", len(RAY_TABLE.columns))
    kind = ca.floor(row[3] + 0.5)
    length, launch, arrival = _images(kind, zs, zr, x, depth)
    return ca.Function("sblsim_ray_row", [zs, zr, x, depth, row],
                       [row[0] * length, launch + row[1], arrival + row[2], kind])


@lru_cache(maxsize=1)
def _first_arrival_grid() -> ca.Function:
    """``(use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values) -> (τ, launch,
    arrival, kind)``: the table's interpolation inside its box where its cell allows, the exact solve elsewhere."""
    zs, zr, x, depth, use_table, constant = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "use_table", "c"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    row = ca.MX.sym("row", len(RAY_TABLE.columns))
    args = [zs, zr, x, depth, use_table, constant, nodes, speeds, row]
    tabled = ca.Function("sblsim_ray_tabled", args, _row_eigenray()(zs, zr, x, depth, row))
    exact = ca.Function("sblsim_ray_exact", args,
                        list(first_arrival_function()(use_table, zs, zr, x, depth, constant, nodes, speeds)))
    chosen = switch("sblsim_ray_choice", [tabled, exact])
    use = ca.MX.sym("use")
    bounds, grid = ca.MX.sym("bounds", 6), ca.MX.sym("grid", sum(RAY_GRID))
    values = ca.MX.sym("values", len(RAY_TABLE.columns) * RAY_TABLE_ROWS)
    row_value = _interpolant()(ca.vertcat(zs, zr, x), grid, values)
    tabulate = ca.logic_and(_in_box(use, zs, zr, x, bounds), row_value[4] == 0)  # false for NaN
    out = chosen(ca.logic_not(tabulate), zs, zr, x, depth, use_table, constant, nodes, speeds, row_value)
    return ca.Function("sblsim_first_arrival_grid",
                       [use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values], out,
                       {"never_inline": True})


def first_arrival_grid(use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values):
    """The earliest eigenray as :func:`first_arrival`, interpolated in an eigenray table where it holds.

    Inside the table's box, in a cell whose nodes all carry ``ray_exact = 0`` (every corner the same path, and
    the interpolation checked against the exact solve at the cell's centre when the table was built,
    :func:`eigenray_table`), the time is the multilinear interpolation of ``τ / L`` times the length ``L`` of the
    path's isovelocity image (the chord, or its image in the surface or the bottom) and the angles the image's
    plus the interpolated offsets; elsewhere, or without a table (``use`` false), the exact solve, which then alone
    is evaluated in the generated C.

    Parameters
    ----------
    use : casadi.SX
        True (non-zero) when the table is given.
    zs, zr, x, depth, use_table, constant, nodes, speeds :
        As :func:`first_arrival`.
    bounds : casadi.SX, shape (6, 1)
        The table's box (:data:`RAY_BOUNDS`) [m].
    grid : casadi.SX, shape (sum(RAY_GRID), 1)
        Its nodes (:func:`ray_grid`).
    values : casadi.SX, shape (5 RAY_TABLE_ROWS, 1)
        Its columns interleaved (:func:`ray_values`).

    Returns
    -------
    tau, launch, arrival, kind : casadi.SX
        As :func:`first_arrival`.
    """
    return _first_arrival_grid()(use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values)


def cell_corners(values) -> list[np.ndarray]:
    """The values at the eight corners of every cell of the table's grid, each array shaped as the cells
    (``RAY_GRID`` less one per axis; a cell indexed by its lower corner), from ``values`` (RAY_TABLE_ROWS,) at the
    nodes (the source depth fastest, as :func:`ray_grid`'s meshgrid in Fortran order)."""
    v = np.asarray(values).reshape(RAY_GRID, order="F")
    a, b, c = (n - 1 for n in RAY_GRID)
    return [v[i:i + a, j:j + b, k:k + c] for i in (0, 1) for j in (0, 1) for k in (0, 1)]


def _axes(bounds) -> list[np.ndarray]:
    """The grid's three axes [m] (source depth, receiver depth, horizontal distance) over ``bounds`` (6,)."""
    return np.split(ray_grid(np.asarray(bounds, dtype=float)), np.cumsum(RAY_GRID)[:-1])


def node_points(bounds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source depth, receiver depth and horizontal distance [m] of every node of the grid of ``bounds`` (6,), each
    (RAY_TABLE_ROWS,), the source depth fastest (:func:`ray_grid`'s meshgrid in Fortran order): where the table's
    builder solves."""
    return tuple(a.ravel(order="F") for a in np.meshgrid(*_axes(bounds), indexing="ij"))


def cell_centres(bounds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source depth, receiver depth and horizontal distance [m] of the centre of every cell of the grid of
    ``bounds`` (6,), each (cells,), in the order of :func:`cell_corners`' arrays raveled in Fortran order."""
    centres = [0.5 * (a[:-1] + a[1:]) for a in _axes(bounds)]
    return tuple(a.ravel(order="F") for a in np.meshgrid(*centres, indexing="ij"))


def exact_nodes(usable: np.ndarray, nodes=None) -> np.ndarray:
    """A table's exact-solve column: 1 at every node of a cell that is not ``usable`` (shaped as the cells), and
    at the nodes where ``nodes`` (RAY_TABLE_ROWS,) is true; (RAY_TABLE_ROWS,) of 0 and 1."""
    needs = np.zeros(RAY_GRID, bool) if nodes is None else np.asarray(nodes, bool).reshape(RAY_GRID, order="F")
    a, b, c = (n - 1 for n in RAY_GRID)
    for i in (0, 1):
        for j in (0, 1):
            for k in (0, 1):
                needs[i:i + a, j:j + b, k:k + c] |= ~usable
    return needs.ravel(order="F").astype(float)


def _in_box(use, zs, zr, x, bounds):
    """True when a table is given (``use``) and the geometry lies inside its box ``bounds`` (casadi)."""
    inside = use > 0
    for j, v in enumerate((zs, zr, x)):
        inside = ca.logic_and(inside, ca.logic_and(v >= bounds[2 * j], v <= bounds[2 * j + 1]))
    return inside


def eigenray_table(table, depth: float, bounds, exact: ca.Function | None = None) -> dict[str, np.ndarray]:
    """The eigenray table of a profile over a box of geometries, built once for a run (exact solves at its nodes).

    At each node of the grid :func:`ray_grid` the exact earliest eigenray (:func:`first_arrival`) gives the
    columns of :data:`RAY_TABLE`. ``ray_exact`` is 1 at a node without an arrival and at every node of a cell
    whose nodes have different paths, or whose interpolation misses the exact solve at the cell's centre by more
    than :data:`RAY_TABLE_TOLERANCE` (time or an angle): there the channel solves exactly.

    Parameters
    ----------
    table : array_like, shape (rows, 2)
        The sound-speed table: depth [m], speed [m/s] (1 ≤ rows ≤ MAX_PROFILE_ROWS).
    depth : float
        Water depth [m] (0: none).
    bounds : array_like, shape (6,)
        The box (:data:`RAY_BOUNDS`): source depth, receiver depth and horizontal distance [m], each min ≤ max.
    exact : casadi.Function, optional
        :func:`exact_points` as it is evaluated (e.g. compiled); default that function itself.

    Returns
    -------
    dict
        Column name -> (RAY_TABLE_ROWS,) values, and ``"exact_share"``: the share of cells solved exactly.
    """
    nodes, speeds = profile_arrays(table)
    exact = exact_points() if exact is None else exact
    bounds = np.asarray(bounds, dtype=float)
    grid = ray_grid(bounds)
    zs, zr, x = node_points(bounds)
    tau, launch, arrival, kind = _at_points(exact, (zs, zr, x, depth), (nodes, speeds))
    length, l0, a0 = _at_points(_image_function(), (kind, zs, zr, x, depth))
    c_source = np.interp(zs, nodes, speeds)
    slowness = np.where(length > 1e-9, tau / np.maximum(length, 1e-300), 1.0 / c_source)
    columns = [np.where(kind > 0, slowness, 0.0), np.where(kind > 0, launch - l0, 0.0),
               np.where(kind > 0, arrival - a0, 0.0), kind.astype(float)]
    # a cell is used when its 8 nodes share a path and its centre checks out
    corners = cell_corners(kind)
    uniform = np.all([c == corners[0] for c in corners], axis=0) & (corners[0] > 0)
    czs, czr, cx = cell_centres(bounds)
    values = np.asarray(ray_values([ca.DM(c) for c in columns + [np.zeros(RAY_TABLE_ROWS)]])).ravel()
    want = _at_points(exact, (czs, czr, cx, depth), (nodes, speeds))
    got = _at_points(_tabled(), (czs, czr, cx, depth), (grid, values))
    good = (want[3] == got[3]) & (np.abs(want[0] - got[0]) <= RAY_TABLE_TOLERANCE[0]) \
        & (np.abs(want[1] - got[1]) <= RAY_TABLE_TOLERANCE[1]) & (np.abs(want[2] - got[2]) <= RAY_TABLE_TOLERANCE[1])
    uniform &= good.reshape(uniform.shape, order="F")
    names = [c.name for c in RAY_TABLE.columns]
    out = dict(zip(names, columns + [exact_nodes(uniform, kind == 0)]))
    out["exact_share"] = float(np.mean(~uniform))
    return out


@lru_cache(maxsize=1)
def exact_points() -> ca.Function:
    """``(zs, zr, x, depth, nodes, speeds) -> (τ, launch, arrival, kind)``: :func:`first_arrival` through a profile
    table, as the table's builder evaluates it at its nodes (the local engine's library compiles it)."""
    args = [ca.MX.sym(n) for n in ("zs", "zr", "x", "depth")]
    nd, sp = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    return ca.Function("sblsim_ray_exact_points", args + [nd, sp], list(first_arrival(1, *args[:4], 1500.0, nd, sp)),
                       ["zs", "zr", "x", "depth", "nodes", "speeds"], ["tau", "launch", "arrival", "kind"])


def _at_points(f: ca.Function, points, shared=()):
    """``f`` at n geometries: ``points`` are its first arguments, each an array (n,) or a number (the same at every
    point), ``shared`` its others (the profile, the table); its outputs, each (n,)."""
    n = max(np.size(a) for a in points)
    columns = [np.broadcast_to(np.asarray(a, dtype=float), (n,))[None, :] for a in points]
    return tuple(np.asarray(o).ravel() for o in f.map(n)(*columns, *shared))


@lru_cache(maxsize=1)
def _tabled() -> ca.Function:
    """``(zs, zr, x, depth, grid, values) -> (τ, launch, arrival, kind)``: the table's interpolation inside its box
    (the check of :func:`eigenray_table`)."""
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    g, v = ca.MX.sym("grid", sum(RAY_GRID)), ca.MX.sym("values", len(RAY_TABLE.columns) * RAY_TABLE_ROWS)
    row = _interpolant()(ca.vertcat(zs, zr, x), g, v)
    return ca.Function("sblsim_ray_tabled_points", [zs, zr, x, depth, g, v], _row_eigenray()(zs, zr, x, depth, row))


# ------------------------------------------------------------------------ the eigenray table of every family

#: The eigenray families, in the row order of :func:`arrivals`.
FAMILIES = ("direct", "surface", "bottom")
#: The per-family table: at each node of the eigenray table's grid (the same nodes and box), each family's time over
#: the length of its isovelocity image (0: no eigenray of the family), its angles less the image's, its geometric
#: spreading less the image's spherical spreading and its length along the ray over the image's; then whether a
#: cell at the node needs the exact solve.
FAMILY_TABLE = Table(
    columns=tuple(
        Column(f"ray_{family}_{what}", unit, f"Family table: {family} eigenray's {text}", lo, hi)
        for family in FAMILIES
        for what, unit, text, lo, hi in (
            ("slowness", "s/m", "travel time over the image path's length (0: none)", 0.0, 1.0),
            ("launch_offset", "rad", "launch angle less the image path's", -4.0, 4.0),
            ("arrival_offset", "rad", "arrival angle less the image path's", -4.0, 4.0),
            ("spreading_offset", "dB", "spreading less the image path's spherical spreading", -100.0, 100.0),
            ("length_ratio", "1", "length along the ray over the image path's length", 0.0, 100.0)))
    + (Column("ray_family_exact", "1", "Family table: 1 where a cell at the node needs the exact solve", 0.0, 1.0),),
    max_rows=RAY_TABLE_ROWS)
#: Columns of :data:`FAMILY_TABLE` per family.
FAMILY_COLUMNS = 5


@lru_cache(maxsize=1)
def family_points() -> ca.Function:
    """``(zs, zr, x, depth, nodes, speeds) -> (tau, launch, arrival, valid, spreading, length)``, each (4, 1):
    :func:`arrivals` through a profile table, as the family table's builder evaluates it at its nodes (the local
    engine's library compiles it)."""
    args = [ca.MX.sym(n) for n in ("zs", "zr", "x", "depth")]
    nd, sp = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    return ca.Function("sblsim_ray_family_points", args + [nd, sp], list(arrivals(1, *args, 1500.0, nd, sp)),
                       ["zs", "zr", "x", "depth", "nodes", "speeds"],
                       ["tau", "launch", "arrival", "valid", "spreading", "length"])


@lru_cache(maxsize=1)
def _family_interpolant() -> ca.Function:
    return ca.interpolant("sblsim_ray_family_grid", "linear", list(RAY_GRID), len(FAMILY_TABLE.columns))


@lru_cache(maxsize=1)
def _family_row() -> ca.Function:
    """``(zs, zr, x, depth, row) -> (tau, launch, arrival, valid, spreading, length)``, each (4, 1): the families a
    row of :data:`FAMILY_TABLE` gives at a geometry (``τ / L``, ``S / L`` times the image's length ``L``, the
    image's angles plus the offsets, the image's spherical spreading plus the offset; valid where ``τ / L > 0``);
    the direct family's other eigenray is not tabled (row 4 invalid, zero: a cell where it exists is solved
    exactly, :func:`sblsim.models.acoustics.detection.level_table`)."""
    zs, zr, x, depth = (ca.SX.sym(n) for n in ("zs", "zr", "x", "depth"))
    row = ca.SX.sym("row", len(FAMILY_TABLE.columns))
    out = [[] for _ in range(6)]
    for j in range(len(FAMILIES)):
        length, launch, arrival = _images(j + 1.0, zs, zr, x, depth)
        slowness, d_launch, d_arrival, d_spreading, ratio = (row[FAMILY_COLUMNS * j + c] for c in range(5))
        for k, v in enumerate((slowness * length, launch + d_launch, arrival + d_arrival, slowness > 0,
                               spherical_spreading(length) + d_spreading, ratio * length)):
            out[k].append(v)
    for o in out:
        o.append(ca.SX(0.0))
    return ca.Function("sblsim_ray_family_row", [zs, zr, x, depth, row], [ca.vertcat(*o) for o in out])


@lru_cache(maxsize=1)
def _arrivals_grid() -> ca.Function:
    """``(use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values) -> (tau, launch, arrival,
    valid, spreading, length)``: the family table's interpolation inside its box where its cell allows, the exact
    :func:`arrivals` elsewhere."""
    zs, zr, x, depth, use_table, constant = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "use_table", "c"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    row = ca.MX.sym("row", len(FAMILY_TABLE.columns))
    args = [zs, zr, x, depth, use_table, constant, nodes, speeds, row]
    tabled = ca.Function("sblsim_ray_families_tabled", args, _family_row()(zs, zr, x, depth, row))
    exact = ca.Function("sblsim_ray_families_exact", args, list(arrivals(use_table, zs, zr, x, depth, constant,
                                                                          nodes, speeds)))
    chosen = switch("sblsim_ray_families_choice", [tabled, exact])
    use = ca.MX.sym("use")
    bounds, grid = ca.MX.sym("bounds", 6), ca.MX.sym("grid", sum(RAY_GRID))
    values = ca.MX.sym("values", len(FAMILY_TABLE.columns) * RAY_TABLE_ROWS)
    row_value = _family_interpolant()(ca.vertcat(zs, zr, x), grid, values)
    tabulate = ca.logic_and(_in_box(use, zs, zr, x, bounds),
                            row_value[len(FAMILY_TABLE.columns) - 1] == 0)  # false for NaN
    out = chosen(ca.logic_not(tabulate), zs, zr, x, depth, use_table, constant, nodes, speeds, row_value)
    return ca.Function("sblsim_arrivals_grid",
                       [use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values], out,
                       {"never_inline": True})


def arrivals_grid(use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values):
    """Every eigenray family as :func:`arrivals`, interpolated in a family table where it holds.

    Inside the table's box, in a cell whose nodes all carry ``ray_family_exact = 0`` (at every corner the same
    families exist, and the interpolation was checked against the exact solve at the cell's centre when the table
    was built, :func:`sblsim.models.acoustics.detection.level_table`), each family's time is the multilinear
    interpolation of ``τ / L`` times the length ``L`` of its isovelocity image (the chord, or its image in the
    surface or the bottom), its angles the image's plus the interpolated offsets, its spreading the image's
    ``20 log10 L`` plus the interpolated offset and its length ``L`` times the interpolated ratio; elsewhere, or
    without a table (``use`` false), the exact solve, which then alone is evaluated in the generated C.

    Parameters
    ----------
    use : casadi.SX
        True (non-zero) when the table is given.
    zs, zr, x, depth, use_table, constant, nodes, speeds :
        As :func:`arrivals`.
    bounds : casadi.SX, shape (6, 1)
        The table's box (:data:`RAY_BOUNDS`) [m].
    grid : casadi.SX, shape (sum(RAY_GRID), 1)
        Its nodes (:func:`ray_grid`).
    values : casadi.SX, shape (len(FAMILY_TABLE.columns) RAY_TABLE_ROWS, 1)
        Its columns interleaved (:func:`ray_values`).

    Returns
    -------
    tau, launch, arrival, valid, spreading, length : casadi.SX, each shape (4, 1)
        As :func:`arrivals` (an invalid family's other values are 0 where the table answers; the direct family's
        other eigenray is never tabled: invalid there).
    """
    return _arrivals_grid()(use, zs, zr, x, depth, use_table, constant, nodes, speeds, bounds, grid, values)


def family_nodes(table, depth: float, bounds, paths: ca.Function | None = None) -> dict[str, np.ndarray]:
    """The columns of :data:`FAMILY_TABLE` at the nodes of the grid of ``bounds`` (exact solves), but the last.

    Parameters
    ----------
    table : array_like, shape (rows, 2)
        The sound-speed table: depth [m], speed [m/s] (1 ≤ rows ≤ MAX_PROFILE_ROWS).
    depth : float
        Water depth [m] (0: none).
    bounds : array_like, shape (6,)
        The box (:data:`RAY_BOUNDS`) [m], each min ≤ max.
    paths : casadi.Function, optional
        :func:`family_points` as it is evaluated (e.g. compiled); default that function itself.

    Returns
    -------
    dict
        Column name -> (RAY_TABLE_ROWS,) values (every column of :data:`FAMILY_TABLE` but ``ray_family_exact``),
        and ``"valid"``: (4, RAY_TABLE_ROWS) whether each eigenray of :func:`arrivals` exists at each node (the
        fourth, the direct family's other, is not tabled).
    """
    nodes, speeds = profile_arrays(table)
    paths = family_points() if paths is None else paths
    zs, zr, x = node_points(bounds)
    n = zs.size
    tau, launch, arrival, valid, spreading, length = (
        np.asarray(o) for o in paths.map(n)(zs[None, :], zr[None, :], x[None, :], np.full((1, n), depth),
                                            nodes, speeds))
    c_source = np.interp(zs, nodes, speeds)
    out, exists = {}, valid > 0.5
    for j, family in enumerate(FAMILIES):
        image, l0, a0 = _at_points(_image_function(), (j + 1.0, zs, zr, x, depth))
        ok = exists[j]
        slowness = np.where(image > 1e-9, tau[j] / np.maximum(image, 1e-300), 1.0 / c_source)
        ratio = np.where(image > 1e-9, length[j] / np.maximum(image, 1e-300), 1.0)
        spherical = np.maximum(20.0 * np.log10(np.maximum(image, 1e-300)), 0.0)
        for what, value in (("slowness", slowness), ("launch_offset", launch[j] - l0),
                            ("arrival_offset", arrival[j] - a0), ("spreading_offset", spreading[j] - spherical),
                            ("length_ratio", ratio)):
            out[f"ray_{family}_{what}"] = np.where(ok, value, 0.0)
    out["valid"] = exists
    return out


__all__ = ["FAMILIES", "FAMILY_COLUMNS", "FAMILY_TABLE", "RAY_BOUNDS", "RAY_GRID", "RAY_TABLE", "RAY_TABLE_ROWS",
           "RAY_TABLE_TOLERANCE", "arrivals_grid", "cell_centres", "cell_corners", "eigenray_table", "exact_nodes",
           "exact_points", "family_nodes", "family_points", "first_arrival_grid", "node_points", "ray_grid",
           "ray_values"]
