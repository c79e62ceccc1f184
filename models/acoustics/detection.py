"""What is heard at a site: the SNR and detection probability of every eigenray between two depths.

For each eigenray of :func:`sblsim.models.acoustics.rays.arrivals` (direct, surface-reflected, bottom-reflected,
and the earliest other eigenray of the direct family: a refracted ray that turns beyond the faster end), the
transmission loss is the ray tube's geometric spreading plus the volume absorption along
the path plus the boundary's reflection loss (the surface's roughness at the grazing angle where the ray meets
it, the sea floor's Rayleigh coefficient likewise; Snell's invariant gives those angles from the launch angle),
and the sonar equation gives the arrival's SNR and its detection probability (:mod:`sblsim.models.acoustics.sonar`).
The channel draws which arrivals are detected and ranges on the first detected one; the availability map takes
the probabilities themselves (:func:`packet_probability`).

Every transmitter has the same source level and every receiver the same directivity index and ambient noise:
a site's, not a device's, numbers. The fluctuations of the arrivals are independent.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics import boundary_loss, sonar
from sblsim.models.acoustics.ray_integrals import sound_speed_at
from sblsim.models.acoustics.ray_inversion import _ray_bending, _slant_range
from sblsim.models.acoustics.ray_tables import (
    FAMILY_TABLE,
    RAY_GRID,
    RAY_TABLE_ROWS,
    _arrivals_grid,
    _first_arrival_grid,
    arrivals_grid,
    cell_centres,
    cell_corners,
    exact_nodes,
    family_nodes,
    ray_grid,
    ray_values,
)
from sblsim.models.acoustics.rays import arrivals, profile_arrays
from sblsim.models.acoustics.sound_speed import NODES

#: The site's numbers :func:`family_levels` takes, in this order (units: dB, dB, dB, dB, Hz, dB/m, dB, m, 1, m/s,
#: dB/λ): source level [dB re 1 µPa at 1 m], detection threshold, receiving directivity index, fluctuation std,
#: frequency, absorption, ambient noise level over the band [dB re 1 µPa], probable wave height, and the sea
#: floor's density ratio, compressional speed and attenuation (:data:`~sblsim.models.acoustics.boundary_loss.BOTTOMS`).
SITE = ("source_level", "detection_threshold", "directivity_index", "fluctuation", "frequency", "absorption",
        "noise", "wave_height", "bottom_density", "bottom_speed", "bottom_attenuation")
#: SNR [dB] reported for an eigenray that does not exist.
NO_SNR = -200.0


@lru_cache(maxsize=1)
def family_levels() -> ca.Function:
    """``(zs, zr, x, depth, profile, constant, nodes, speeds, site) -> (tau, launch, arrival, valid, snr, pd)``.

    Parameters (of the function)
    ----------------------------
    zs, zr : depth of the source and of the receiver [m] (positive down).
    x : horizontal distance between them [m].
    depth : water depth [m]; 0: no boundary (the reflected rows are invalid).
    profile : 1 to use the table ``nodes``, ``speeds``; 0 for the constant speed ``constant`` [m/s].
    nodes, speeds : (NODES, 1) the padded profile (:func:`~sblsim.models.acoustics.sound_speed.node_speeds`).
    site : (len(SITE), 1) the site's numbers (:data:`SITE`).

    Returns (of the function)
    -------------------------
    Each (4, 1), rows direct, surface-reflected, bottom-reflected and the direct family's other eigenray
    (:data:`~sblsim.models.acoustics.rays.OTHER`): travel time [s], launch and arrival grazing
    angles [rad] (positive downward), valid (1: the eigenray exists), SNR [dB] (floored at :data:`NO_SNR`, which
    it is when the eigenray does not exist) and detection probability (0 when it does not).
    """
    zs, zr, x, depth, profile, constant = (ca.MX.sym(n) for n in ("zs", "zr", "x", "depth", "profile", "constant"))
    nodes, speeds, site = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES), ca.MX.sym("site", len(SITE))
    families = arrivals(profile, zs, zr, x, depth, constant, nodes, speeds)
    return ca.Function("sblsim_family_levels", [zs, zr, x, depth, profile, constant, nodes, speeds, site],
                       _levels(families, zs, depth, profile, constant, nodes, speeds, site),
                       ["zs", "zr", "x", "depth", "profile", "constant", "nodes", "speeds", "site"],
                       ["tau", "launch", "arrival", "valid", "snr", "pd"], {"never_inline": True})


def _levels(families, zs, depth, profile, constant, nodes, speeds, site):
    """``[tau, launch, arrival, valid, snr, pd]`` of the families ``(tau, launch, arrival, valid, spreading,
    length)`` (:func:`~sblsim.models.acoustics.rays.arrivals`) at the site ``site``: the sonar equation per family."""
    s = {name: site[j] for j, name in enumerate(SITE)}
    tau, launch, arrive, valid, spreading, length = families

    def speed(z):
        return ca.if_else(profile > 0.5, sound_speed_at(z, nodes, speeds), constant)

    # where a reflected ray meets its boundary: Snell's invariant from its launch angle
    source_speed, surface_speed, bottom_speed = speed(zs), speed(0.0), speed(depth)
    at_surface = ca.acos(ca.fmin(ca.cos(launch[1]) * surface_speed / source_speed, 1.0))
    at_bottom = ca.acos(ca.fmin(ca.cos(launch[2]) * bottom_speed / source_speed, 1.0))
    boundary = (0.0, boundary_loss.surface_loss(at_surface, s["frequency"], s["wave_height"], surface_speed),
                boundary_loss.half_space_loss(at_bottom, s["bottom_density"], s["bottom_speed"] / bottom_speed,
                                              s["bottom_attenuation"]), 0.0)  # the direct family's other ray meets none
    levels, chances = [], []
    for j in range(tau.shape[0]):
        loss = spreading[j] + s["absorption"] * length[j] + boundary[j]
        level = sonar.snr(s["source_level"], loss, s["noise"], s["directivity_index"])
        exists = valid[j] > 0.5
        levels.append(ca.if_else(exists, ca.fmax(level, NO_SNR), NO_SNR))
        chances.append(ca.if_else(exists, sonar.detection_probability(level, s["detection_threshold"],
                                                                      s["fluctuation"]), 0.0))
    return [tau, launch, arrive, valid, ca.vertcat(*levels), ca.vertcat(*chances)]


@lru_cache(maxsize=1)
def family_levels_grid() -> ca.Function:
    """``(use, zs, zr, x, depth, profile, constant, nodes, speeds, site, bounds, grid, values) -> (tau, launch,
    arrival, valid, snr, pd)``: :func:`family_levels` with the eigenrays interpolated in the run's family table
    where it holds (:func:`~sblsim.models.acoustics.ray_tables.arrivals_grid`; ``use`` true when the table is given),
    the exact solve elsewhere.

    Parameters (of the function)
    ----------------------------
    use : 1 when the family table (:func:`level_table`) is given; 0: every eigenray solved exactly.
    zs, zr, x, depth, profile, constant, nodes, speeds, site : as :func:`family_levels`.
    bounds, grid, values : the table's box [m], its nodes [m] and its columns interleaved
        (:func:`~sblsim.models.acoustics.ray_tables.arrivals_grid`).

    Returns (of the function)
    -------------------------
    As :func:`family_levels`, each (4, 1).
    """
    names = ["use", "zs", "zr", "x", "depth", "profile", "constant"]
    use, zs, zr, x, depth, profile, constant = (ca.MX.sym(n) for n in names)
    nodes, speeds, site = ca.MX.sym("nodes", NODES), ca.MX.sym("speeds", NODES), ca.MX.sym("site", len(SITE))
    bounds, grid = ca.MX.sym("bounds", 6), ca.MX.sym("grid", sum(RAY_GRID))
    values = ca.MX.sym("values", len(FAMILY_TABLE.columns) * RAY_TABLE_ROWS)
    families = arrivals_grid(use, zs, zr, x, depth, profile, constant, nodes, speeds, bounds, grid, values)
    return ca.Function("sblsim_family_levels_grid",
                       [use, zs, zr, x, depth, profile, constant, nodes, speeds, site, bounds, grid, values],
                       _levels(families, zs, depth, profile, constant, nodes, speeds, site),
                       names + ["nodes", "speeds", "site", "bounds", "grid", "values"],
                       ["tau", "launch", "arrival", "valid", "snr", "pd"], {"never_inline": True})


#: What the interpolated family table must reproduce of the exact solve at the centre of every cell it is used in,
#: for every family that exists there: travel time [s] (0.1 µs), angles [rad] (1e-4 rad: 0.006°, a twenty-fourth
#: of the 0.14° of the best USBL; the reflected families' launch angles near the surface miss 1e-5) and SNR [dB]
#: (a cell beyond it is solved exactly).
LEVEL_TABLE_TOLERANCE = (1e-7, 1e-4, 0.01)


def level_table(table, depth: float, bounds, site, paths: ca.Function | None = None,
                levels: ca.Function | None = None) -> dict[str, np.ndarray]:
    """The family table of a run (:data:`~sblsim.models.acoustics.ray_tables.FAMILY_TABLE`), built once for its profile,
    water depth, box and site from exact solves at the eigenray table's nodes.

    ``ray_family_exact`` is 1 at every node of a cell whose nodes differ in which families exist, where the direct
    family's other eigenray (not tabled) exists at a node or at its centre, or whose
    interpolation misses the exact :func:`family_levels` at the cell's centre, for a family that exists, by more
    than :data:`LEVEL_TABLE_TOLERANCE` (time, an angle or the SNR) or differs in which exist: there the channel
    solves exactly.

    Parameters
    ----------
    table : array_like, shape (rows, 2)
        The sound-speed table: depth [m], speed [m/s] (1 ≤ rows ≤ MAX_PROFILE_ROWS).
    depth : float
        Water depth [m] (0: none).
    bounds : array_like, shape (6,)
        The box (:data:`~sblsim.models.acoustics.ray_tables.RAY_BOUNDS`) [m], each min ≤ max.
    site : array_like, shape (len(SITE),)
        The site's numbers (:data:`SITE`).
    paths, levels : casadi.Function, optional
        :func:`~sblsim.models.acoustics.ray_tables.family_points` and :func:`family_levels` as they are evaluated (e.g.
        compiled); default those functions themselves.

    Returns
    -------
    dict
        Column name -> (RAY_TABLE_ROWS,) values, and ``"exact_share"``: the share of cells solved exactly.
    """
    nodes, speeds = profile_arrays(table)
    bounds = np.asarray(bounds, dtype=float)
    site = np.asarray(site, dtype=float).ravel()
    columns = family_nodes(table, depth, bounds, paths)
    valid = columns.pop("valid")
    corners = cell_corners(valid[0] + 2 * valid[1] + 4 * valid[2])  # which families exist
    uniform = np.all([c == corners[0] for c in corners], axis=0)
    # the direct family's other eigenray is not tabled: a cell where it exists at a node is solved exactly
    uniform &= ~np.any(cell_corners(valid[3]), axis=0)
    grid = ray_grid(bounds)
    czs, czr, cx = cell_centres(bounds)
    n = czs.size
    names = [c.name for c in FAMILY_TABLE.columns]
    values = np.asarray(ray_values([ca.DM(columns[c]) for c in names[:-1]]
                                   + [ca.DM(np.zeros(RAY_TABLE_ROWS))])).ravel()
    points = (czs[None, :], czr[None, :], cx[None, :], np.full((1, n), depth), np.ones((1, n)),
              np.full((1, n), 1500.0))
    want = [np.asarray(o) for o in (family_levels() if levels is None else levels).map(n)(
        *points, nodes, speeds, site)]
    got = [np.asarray(o) for o in family_levels_grid().map(n)(1.0, *points, nodes, speeds, site, bounds, grid,
                                                              values)]
    exists = want[3] > 0.5
    good = np.all((got[3] > 0.5) == exists, axis=0)
    for k, tolerance in ((0, LEVEL_TABLE_TOLERANCE[0]), (1, LEVEL_TABLE_TOLERANCE[1]),
                         (2, LEVEL_TABLE_TOLERANCE[1]), (4, LEVEL_TABLE_TOLERANCE[2])):
        good &= np.all(~exists | (np.abs(got[k] - want[k]) <= tolerance), axis=0)  # false for NaN
    uniform &= good.reshape(uniform.shape, order="F")
    out = {name: columns[name] for name in names[:-1]}
    out[names[-1]] = exact_nodes(uniform)
    out["exact_share"] = float(np.mean(~uniform))
    return out


#: The direct family's other eigenray (row 4) is detected with the fraction of ``2^24`` times the direct ray's
#: uniform: the 29 low bits of a 53-bit uniform, independent of the 24 high bits that decide the direct ray (to
#: 6e-8 in probability), so that a leg takes the three uniforms it always took and every stream stays as it was.
OTHER_DRAW_SCALE = 16777216.0


def other_draw(u):
    """The uniform on [0, 1) that decides the direct family's other eigenray from the direct ray's ``u``
    (:data:`OTHER_DRAW_SCALE`): ``frac(2^24 u)``, exact in binary floating point."""
    scaled = u * OTHER_DRAW_SCALE
    return scaled - ca.floor(scaled)


def first_detected(tau, launch, arrive, valid, snr, pd, draws):
    """The first detected arrival of a leg: ``(τ, launch, arrival, kind, SNR, P_d)``.

    Parameters
    ----------
    tau, launch, arrive, valid, snr, pd : casadi.SX, shape (4, 1)
        The eigenrays of :func:`family_levels` (direct, surface, bottom, the direct family's other).
    draws : casadi.SX, shape (3, 1)
        Uniform numbers on [0, 1): eigenray j (of the first three) is detected when it exists and
        ``draws[j] < pd[j]``; the fourth with :func:`other_draw` of ``draws[0]``.

    Returns
    -------
    tuple of casadi.SX
        The earliest detected arrival's travel time [s], launch and arrival angles [rad], kind (1 direct,
        2 surface, 3 bottom, 4 the direct family's other eigenray; 0 when none is detected), SNR [dB] and
        detection probability; when none is detected, τ of the earliest eigenray (0 without any), and the SNR and
        P_d of the strongest. Last, the travel time of the latest detected arrival [s] (the end of the leg's
        multipath spread; 0 when none).
    """
    best_tau, best, strongest, earliest, latest = ca.inf, [0.0] * 5, [NO_SNR, 0.0], ca.inf, 0.0
    uniforms = [draws[0], draws[1], draws[2], other_draw(draws[0])]
    for j in range(tau.shape[0]):
        exists = valid[j] > 0.5
        found = ca.logic_and(exists, uniforms[j] < pd[j])
        latest = ca.if_else(found, ca.fmax(latest, tau[j]), latest)
        better = ca.logic_and(found, tau[j] < best_tau)
        best_tau = ca.if_else(better, tau[j], best_tau)
        best = [ca.if_else(better, v, b) for v, b in zip((launch[j], arrive[j], j + 1.0, snr[j], pd[j]), best)]
        louder = ca.logic_and(exists, snr[j] > strongest[0])
        strongest = [ca.if_else(louder, snr[j], strongest[0]), ca.if_else(louder, pd[j], strongest[1])]
        earliest = ca.if_else(ca.logic_and(exists, tau[j] < earliest), tau[j], earliest)
    heard = best[2] > 0
    first = ca.if_else(heard, best_tau, ca.if_else(earliest < ca.inf, earliest, 0.0))
    return (first, best[0], best[1], best[2], ca.if_else(heard, best[3], strongest[0]),
            ca.if_else(heard, best[4], strongest[1]), latest)


def packet_probability(tau, pd, snr, threshold, margin, fluctuation) -> np.ndarray:
    """Probability that a leg's packet is received: its first detected arrival's data decoded.

    With the arrivals sorted by travel time, arrival j is the first detected with probability
    ``P_j Π_{i before j} (1 − P_i)``; its data is decoded with the detection probability of its SNR at the
    threshold plus the decoding margin.

    Parameters
    ----------
    tau, pd, snr : ndarray, shape (..., F)
        Travel times [s], detection probabilities and SNRs [dB] of the eigenrays (:func:`family_levels`' four;
        an absent one: pd 0).
    threshold, margin, fluctuation : float
        Detection threshold, decoding margin and fluctuation std [dB].

    Returns
    -------
    ndarray, shape (...)
    """
    tau, pd, snr = (np.asarray(v, dtype=float) for v in (tau, pd, snr))
    order = np.argsort(np.where(pd > 0, tau, np.inf), axis=-1)
    pd, snr = np.take_along_axis(pd, order, -1), np.take_along_axis(snr, order, -1)
    missed_before = np.cumprod(np.concatenate([np.ones(pd.shape[:-1] + (1,)), 1.0 - pd[..., :-1]], -1), -1)
    decoded = np.vectorize(lambda v: float(sonar.detection_probability(v, threshold + margin, fluctuation)))(snr)
    return np.sum(pd * missed_before * decoded, axis=-1)


def first_shares(tau, pd) -> np.ndarray:
    """Per family, the probability that it is a leg's first detected arrival: ``P_j Π_{i before j} (1 − P_i)``
    (the arrivals in order of travel time, an absent one never detected), the terms of
    :func:`packet_probability` before decoding.

    Parameters
    ----------
    tau, pd : ndarray, shape (..., F)
        Travel times [s] and detection probabilities of the eigenrays (direct, surface, bottom, the direct family's
        other; an absent one: pd 0).

    Returns
    -------
    ndarray, shape (..., F)
        Their sum is the probability that the leg is heard at all.
    """
    tau, pd = np.asarray(tau, dtype=float), np.asarray(pd, dtype=float)
    arrives = np.where(pd > 0, tau, np.inf)
    before = arrives[..., None, :] < arrives[..., :, None]  # [..., j, i]: family i arrives before family j
    return pd * np.prod(np.where(before, 1.0 - pd[..., None, :], 1.0), axis=-1)


def direct_first(tau, pd, snr=None, threshold: float = 0.0, margin: float = 0.0, fluctuation: float = 0.0
                 ) -> np.ndarray:
    """Probability that a leg's first detected arrival is the direct one (family 0), and (with ``snr``) that its
    data is decoded too: ``P_0 Π_{i before 0} (1 − P_i)`` times the decoding probability at the threshold plus the
    margin (:func:`packet_probability`'s term of the direct arrival; the share of the received packets whose range
    is the direct ray's is its ratio to :func:`packet_probability`).

    Parameters
    ----------
    tau, pd : ndarray, shape (..., F)
        Travel times [s] and detection probabilities of the eigenrays (direct, surface, bottom, the direct family's
        other; an absent one: pd 0).
    snr : ndarray, shape (..., F), optional
        SNRs [dB]; None: the detection alone (a leg whose data is not decoded, an interrogation).
    threshold, margin, fluctuation : float
        As for :func:`packet_probability`.

    Returns
    -------
    ndarray, shape (...)
    """
    share = first_shares(tau, pd)[..., 0]
    if snr is None:
        return share
    decoded = np.vectorize(lambda v: float(sonar.detection_probability(v, threshold + margin, fluctuation)))(
        np.asarray(snr, dtype=float)[..., 0])
    return share * decoded


def eigenray_functions() -> list[ca.Function]:
    """The eigenray functions the components' programs call: the channel's first arrival, its arrivals and its
    families (interpolated in the run's tables where they hold), the receivers' slant range and bending. None of
    them depends on a component or a beacon count, so their generated C (and that of what they call) is compiled
    once, in a file of its own, and every component's code calls it there (:mod:`sblsim.fmus.codegen`)."""
    return [_first_arrival_grid(), _arrivals_grid(), family_levels_grid(), _slant_range(), _ray_bending()]


__all__ = ["LEVEL_TABLE_TOLERANCE", "NO_SNR", "OTHER_DRAW_SCALE", "SITE", "direct_first", "eigenray_functions",
           "family_levels", "family_levels_grid", "first_detected", "first_shares", "level_table", "other_draw",
           "packet_probability"]
