"""Eigenrays in a range-independent sound-speed profile: direct, surface- and bottom-reflected.

The channel's eigenrays between two depths, each family solved exactly through the profile's c-linear layers
(:mod:`~sblsim.models.acoustics.ray_integrals`, after Jensen, Kuperman, Porter, Schmidt, *Computational Ocean
Acoustics*, 2nd ed., Springer 2011, ch. 3.3-3.4): the **direct** family (``arrival`` 1, and 4 for its earliest
other eigenray; :mod:`~sblsim.models.acoustics.direct_family`), the **surface-reflected** (2) and the
**bottom-reflected** (3) (:mod:`~sblsim.models.acoustics.reflected_families`), each eigenray with its geometric
spreading and arc length (:mod:`~sblsim.models.acoustics.spreading_loss`). This module assembles them: every
family's eigenray (:func:`eigenray_families`, :func:`eigenray_paths`), the earliest (:func:`first_arrival`) and
every one with its losses for the sonar equation (:func:`arrivals`), through the profile table or in water of one
speed (the straight line and its images); :func:`profile_arrays` pads a numeric table as the channel does. The
receivers' inversion of the direct eigenray (slant range, ray bending) is
:mod:`~sblsim.models.acoustics.ray_inversion`.

Angles are grazing angles [rad], positive when the ray travels downward (toward greater depth): the launch
angle at the source, the arrival angle at the receiver, in the direction of travel (Bellhop's sign).

What is not modelled: rays that turn more than once, or that pass over a local maximum of the speed beyond
the faster end and turn further away (they come back only after long excursions; not within the few km of
a positioning system in the profiles sblsim ships), reflected rays that turn otherwise than the surface duct's
(:mod:`~sblsim.models.acoustics.reflected_families`; a surface-reflected ray leaving the shallower end
downward, crossing ``[z_a, z_b]`` three times, or turning before it reaches the surface; a bottom-reflected ray
that turns), range-dependent profiles and bathymetry. Where ``X(q)`` is not monotonic (several eigenrays of
one family) the solve returns one of them.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.direct_family import _direct
from sblsim.models.acoustics.reflected_families import _reflected, _surface_family
from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS, NODES, node_speeds
from sblsim.models.acoustics.spreading_loss import _tube_loss, spherical_spreading
from sblsim.models.expressions import switch

#: Eigenray families: the ``arrival`` codes of the channel's time series (0: none); ``OTHER``: the earliest other
#: eigenray of the direct family (a ray turning beyond the faster end, or the straight one where the solve's own is
#: a turning ray), no boundary met.
DIRECT, SURFACE, BOTTOM, OTHER = 1, 2, 3, 4


@lru_cache(maxsize=1)
def eigenray_paths() -> ca.Function:
    """``(zs, zr, x, depth, nodes, speeds) -> (tau, launch, arrival, valid, spreading, length)``, each (3, 1): the
    eigenrays of :func:`eigenray_families` (the same first four outputs) with their geometric spreading and their
    length along the ray.

    Parameters (of the function)
    ----------------------------
    zs, zr, x, depth, nodes, speeds : as :func:`eigenray_families`.

    Returns (of the function)
    -------------------------
    tau, launch, arrival, valid : as :func:`eigenray_families`.
    spreading : the ray-tube geometric spreading loss [dB re 1 m] of each eigenray, ``−10 log10 |p/p0|²``
        (:func:`_tube_loss`: Jensen et al. 2011, ch. 3), capped at caustics (:data:`CAUSTIC_GAIN`), ≥ 0.
    length : its arc length along the ray [m] (closed form per c-linear layer).
    """
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    rows = [*_direct(zs, zr, x, depth, nodes, speeds, others=True), _reflected(zs, zr, x, depth, nodes, speeds, True)]
    rows = [r[:4] + _tube_loss(zs, zr, x, r[4], nodes, speeds) for r in rows]
    rows.insert(2, _surface_family(True)(zs, zr, x, depth, nodes, speeds))
    rows = [rows[0], rows[2], rows[3], rows[1]]
    out = [ca.vertcat(*[r[j] for r in rows]) for j in range(6)]
    return ca.Function("sblsim_eigenray_paths", [zs, zr, x, depth, nodes, speeds], out,
                       ["zs", "zr", "x", "depth", "nodes", "speeds"],
                       ["tau", "launch", "arrival", "valid", "spreading", "length"], {"never_inline": True})


@lru_cache(maxsize=1)
def eigenray_families() -> ca.Function:
    """``(zs, zr, x, depth, nodes, speeds) -> (tau, launch, arrival, valid)``, each (3, 1): the direct, the
    surface-reflected and the bottom-reflected eigenray (rows in that order).

    Parameters (of the function)
    ----------------------------
    zs, zr : depth of the source and of the receiver [m] (positive down).
    x : horizontal distance between them [m].
    depth : water depth [m]; 0: no boundary (the reflected rows are invalid).
    nodes, speeds : (NODES, 1) the padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).

    Returns (of the function)
    -------------------------
    tau [s], launch and arrival grazing angles [rad] (positive downward, in the direction of travel),
    valid (1: the eigenray exists; 0: shadow zone, or no boundary, and the other values are meaningless).
    """
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    direct, other = _direct(zs, zr, x, depth, nodes, speeds, others=True)
    rows = [direct, _surface_family(False)(zs, zr, x, depth, nodes, speeds),
            _reflected(zs, zr, x, depth, nodes, speeds, True), other]
    out = [ca.vertcat(*[r[j] for r in rows]) for j in range(4)]
    return ca.Function("sblsim_eigenray_families", [zs, zr, x, depth, nodes, speeds], out,
                       ["zs", "zr", "x", "depth", "nodes", "speeds"], ["tau", "launch", "arrival", "valid"],
                       {"never_inline": True})


def _first(tau, launch, arrival, valid):
    """The earliest valid arrival of (3, 1) families: ``(τ, launch, arrival, kind)``, kind 0 when none."""
    best_t, best_l, best_a, kind = ca.inf, 0.0, 0.0, 0.0
    for j in range(int(tau.numel())):
        better = ca.logic_and(valid[j] > 0.5, tau[j] < best_t)
        best_t = ca.if_else(better, tau[j], best_t)
        best_l = ca.if_else(better, launch[j], best_l)
        best_a = ca.if_else(better, arrival[j], best_a)
        kind = ca.if_else(better, j + 1.0, kind)
    return ca.if_else(kind > 0, best_t, 0.0), best_l, best_a, kind


@lru_cache(maxsize=1)
def _first_arrival_table() -> ca.Function:
    zs, zr, x, depth = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    direct, other = _direct(zs, zr, x, depth, nodes, speeds, others=True)
    # without boundaries: the direct family's two eigenrays (rows 1 and 4: the kinds DIRECT and OTHER)
    no_row = (0.0, 0.0, 0.0, 0.0)
    pair = [ca.vertcat(*v) for v in zip(direct[:4], no_row, no_row, other[:4])]
    direct_only = ca.Function("sblsim_ray_direct_only", [zs, zr, x, depth, nodes, speeds], list(_first(*pair)))
    families = eigenray_families()(zs, zr, x, depth, nodes, speeds)
    with_boundaries = ca.Function("sblsim_ray_bounded", [zs, zr, x, depth, nodes, speeds], list(_first(*families)))
    return switch("sblsim_ray_first", [direct_only, with_boundaries])


def _constant_rows(zs, zr, x, depth, c):
    """Isovelocity: the straight line and its images in the surface and the bottom, each ``(τ, launch, arrival,
    valid, L)`` with ``L`` the (image) path's length [m]."""
    rows = []
    for image, kind in ((zr - zs, DIRECT), (zs + zr, SURFACE), (2.0 * depth - zs - zr, BOTTOM)):
        length = ca.sqrt(x * x + image * image)
        angle = ca.atan2(image, x)
        # reflected: launched toward the boundary, arriving from it
        launch, arrival = (angle, angle) if kind == DIRECT else ((-angle, angle) if kind == SURFACE else
                                                                  (angle, -angle))
        valid = 1.0 if kind == DIRECT else ca.logic_and(depth > 0, ca.logic_and(
            zs >= 0, zr >= 0) if kind == SURFACE else ca.logic_and(depth >= zs, depth >= zr))
        rows.append((length / c, launch, arrival, valid, length))
    return rows


@lru_cache(maxsize=1)
def _first_arrival_constant() -> ca.Function:
    """Isovelocity: the straight line and its images in the surface and the bottom."""
    zs, zr, x, depth, c = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "c"))
    rows = _constant_rows(zs, zr, x, depth, c)
    out = _first(*[ca.vertcat(*[r[j] for r in rows]) for j in range(4)])
    return ca.Function("sblsim_ray_constant", [zs, zr, x, depth, c], list(out))


@lru_cache(maxsize=1)
def first_arrival_function() -> ca.Function:
    zs, zr, x, depth, c = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "c"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    args = [zs, zr, x, depth, c, nodes, speeds]
    const = ca.Function("sblsim_ray_isovelocity", args, _first_arrival_constant()(zs, zr, x, depth, c))
    table = ca.Function("sblsim_ray_table", args,
                        _first_arrival_table()(depth > 0, zs, zr, x, depth, nodes, speeds))
    return switch("sblsim_first_arrival", [const, table])


def first_arrival(use_table, zs, zr, x, depth, constant, nodes, speeds):
    """The earliest eigenray between two depths: ``(τ, launch, arrival, kind)``.

    Parameters
    ----------
    use_table : casadi.SX
        True (non-zero) for the table, false for the constant ``constant``.
    zs, zr : casadi.SX
        Depth of the source and of the receiver [m].
    x : casadi.SX
        Horizontal distance [m].
    depth : casadi.SX
        Water depth [m]; 0: no boundary, the direct eigenray only.
    constant : casadi.SX
        The sound speed of an empty table [m/s].
    nodes, speeds : casadi.SX, shape (NODES, 1)
        The padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).

    Returns
    -------
    tau : casadi.SX
        Travel time [s] of the earliest arrival (0 when none).
    launch, arrival : casadi.SX
        Its grazing angles [rad] at the source and at the receiver, positive downward.
    kind : casadi.SX
        1 direct, 2 surface-reflected, 3 bottom-reflected, 0 none (a shadow zone without boundaries).
    """
    return first_arrival_function()(use_table, zs, zr, x, depth, constant, nodes, speeds)


@lru_cache(maxsize=1)
def _arrivals() -> ca.Function:
    """``(use_table, zs, zr, x, depth, constant, nodes, speeds) -> (tau, launch, arrival, valid, spreading,
    length)``: see :func:`arrivals`."""
    zs, zr, x, depth, c = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "c"))
    nodes, speeds = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES)
    args = [zs, zr, x, depth, c, nodes, speeds]
    names = ["tau", "launch", "arrival", "valid", "spreading", "length"]
    rows = _constant_rows(zs, zr, x, depth, c)
    # isovelocity: one direct eigenray (the OTHER row invalid, zero)
    const = ca.Function("sblsim_arrivals_isovelocity", args,
                        [ca.vertcat(*[r[j] for r in rows], 0.0) for j in range(4)]
                        + [ca.vertcat(*[spherical_spreading(r[4]) for r in rows], 0.0),
                           ca.vertcat(*[r[4] for r in rows], 0.0)])
    # without a water depth the direct family alone is solved (the reflected rows: invalid, zero)
    direct, other = (list(r[:4]) + list(_tube_loss(zs, zr, x, r[4], nodes, speeds))
                     for r in _direct(zs, zr, x, depth, nodes, speeds, others=True))
    inner = [zs, zr, x, depth, nodes, speeds]
    direct_only = ca.Function("sblsim_arrivals_direct", inner, [ca.vertcat(v, 0.0, 0.0, w)
                                                                for v, w in zip(direct, other)])
    bounded = ca.Function("sblsim_arrivals_bounded", inner, eigenray_paths()(*inner))
    table = ca.Function("sblsim_arrivals_table", args,
                        switch("sblsim_arrivals_boundary", [direct_only, bounded])(depth > 0, *inner))
    chosen = switch("sblsim_arrivals_choice", [const, table])
    use = ca.MX.sym("use_table")
    return ca.Function("sblsim_arrivals", [use, *args], chosen(use, *args),
                       ["use_table", "zs", "zr", "x", "depth", "constant", "nodes", "speeds"], names,
                       {"never_inline": True})


def arrivals(use_table, zs, zr, x, depth, constant, nodes, speeds):
    """Every eigenray family between two depths with its geometric spreading and its length, for the sonar
    equation: ``(tau, launch, arrival, valid, spreading, length)``, each (4, 1), rows direct, surface-reflected,
    bottom-reflected and the direct family's earliest other eigenray (a ray turning in the water; the ``arrival``
    codes 1 to 4 less one; the fourth never valid in water of one speed).

    Through the profile table (``use_table``) the eigenrays of :func:`eigenray_paths` (only the direct one solved
    without a water depth); in water of the constant speed ``constant`` the straight line and its images in the
    surface and the bottom, spreading ``20 log10 L`` and length ``L`` (``L`` the image path's length), as
    :func:`first_arrival`'s isovelocity branch. Only the chosen branch runs in the generated C.

    Parameters
    ----------
    use_table : casadi.SX
        True (non-zero) for the table, false for the constant ``constant``.
    zs, zr : casadi.SX
        Depth of the source and of the receiver [m] (positive down).
    x : casadi.SX
        Horizontal distance [m].
    depth : casadi.SX
        Water depth [m]; 0: no boundary (the reflected rows invalid).
    constant : casadi.SX
        The sound speed of an empty table [m/s].
    nodes, speeds : casadi.SX, shape (NODES, 1)
        The padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).

    Returns
    -------
    tau : casadi.SX, shape (4, 1)
        Travel times [s].
    launch, arrival : casadi.SX, shape (4, 1)
        Grazing angles [rad] at the source and at the receiver, positive downward, in the direction of travel.
    valid : casadi.SX, shape (4, 1)
        1 where the eigenray exists (0: shadow zone or no boundary; the row's other values are then meaningless).
    spreading : casadi.SX, shape (4, 1)
        Geometric spreading loss [dB re 1 m], ``−10 log10 |p/p0|²`` of the ray tube (Jensen, Kuperman, Porter,
        Schmidt, *Computational Ocean Acoustics*, 2nd ed., 2011, ch. 3), at most :data:`CAUSTIC_GAIN` below the
        spherical spreading ``20 log10`` of the isovelocity image's length (caustics), and at least 0 dB.
    length : casadi.SX, shape (4, 1)
        Path length along the ray [m] (for absorption): per c-linear layer ``(θ_a − θ_b) / (ξ g)`` in a form that
        holds for a zero gradient too.
    """
    return _arrivals()(use_table, zs, zr, x, depth, constant, nodes, speeds)


def profile_arrays(table) -> tuple[np.ndarray, np.ndarray]:
    """The padded nodes and speeds of a numeric sound-speed table, as the channel builds them.

    Parameters
    ----------
    table : array_like, shape (rows, 2)
        Depth [m], sound speed [m/s], 1 ≤ rows ≤ MAX_PROFILE_ROWS, depths increasing.

    Returns
    -------
    nodes, speeds : ndarray, each (NODES,)
    """
    table = np.asarray(table, dtype=float)
    n = table.shape[0]
    depth, speed = np.zeros(MAX_PROFILE_ROWS), np.zeros(MAX_PROFILE_ROWS)
    depth[:n], speed[:n] = table[:, 0], table[:, 1]
    count, d, c = ca.MX.sym("n"), ca.MX.sym("d", MAX_PROFILE_ROWS), ca.MX.sym("c", MAX_PROFILE_ROWS)
    nodes, speeds = ca.Function("sblsim_ray_nodes", [count, d, c], list(node_speeds(count, d, c)))(n, depth, speed)
    return np.asarray(nodes).ravel(), np.asarray(speeds).ravel()



__all__ = ["BOTTOM", "DIRECT", "SURFACE", "arrivals", "eigenray_families", "eigenray_paths", "first_arrival",
           "first_arrival_function", "profile_arrays"]
