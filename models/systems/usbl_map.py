"""The USBL accuracy map: the accuracy of a fix from one packet plus the depth, at every point of a grid.

The Fisher information of one packet's rows and the depth reading for a level array at the platform's heading
(:func:`fix_information`, :func:`fix_accuracy`); near the vertical in deep water, where the range–depth
constraint binds, the fix's own RMS error by quasi-Monte Carlo integration over the errors (:func:`nadir_fix_rms`,
:data:`NADIR_ZONE`); and the offset of the fix a reflected arrival gives (:func:`seen_fix_offset`).

References
----------
Kay, Fundamentals of Statistical Signal Processing: Estimation Theory, Prentice Hall 1993, Sections 3.7 and 8.9.
Owen, "Scrambling Sobol' and Niederreiter-Xing points", Journal of Complexity 14(4), 1998.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Sequence

import casadi as ca
import numpy as np

from sblsim.models.fisher import per_point
from sblsim.models.platform.geometry import rotation_ned
from sblsim.models.receiver import kalman
from sblsim.models.systems import MIN_R_SIGMA
from sblsim.models.systems.usbl_fix import gauss_newton, position_information
from sblsim.models.systems.usbl_packet import POSITION_MODEL


@lru_cache(maxsize=None)
def fix_information() -> ca.Function:
    """casadi Function of the accuracy of one USBL packet plus the depth (the map).

    ``(p[3], transceiver[3], attitude[3], range_variance, position_variance, angle_sigma_deg, attitude_variance,
    depth_variance) -> (C (3, 3), drms)``: ``C = J⁻¹``, J the Fisher information of the packet's range and
    direction cosines with the receivers' R and of the depth reading (:func:`position_information`), and
    ``drms = sqrt(C_NN + C_EE)`` [m]. Finite everywhere, straight below the transceiver too.

    References
    ----------
    Kay 1993, Section 3.7.
    """
    p, b, att = ca.SX.sym("p", 3), ca.SX.sym("transceiver", 3), ca.SX.sym("attitude", 3)
    names = ("range_variance", "position_variance", "angle_sigma_deg", "attitude_variance", "depth_variance")
    range_var, position_var, angle, attitude_var, d_var = (ca.SX.sym(n) for n in names)
    ctx = (b, att)
    R = POSITION_MODEL.covariance(p, ctx, range_var, (angle * (math.pi / 180.0)) ** 2, position_var, attitude_var)
    C = kalman.solve_spd(position_information(p, ctx, R, d_var), ca.SX.eye(3))
    C = kalman.symmetric(C)
    return ca.Function("sblsim_usbl_fix_information", [p, b, att, range_var, position_var, angle, attitude_var,
                                                       d_var], [C, ca.sqrt(C[0, 0] + C[1, 1])],
                       ["p", "transceiver", "attitude", *names], ["C", "drms"])


#: Where a point is within this many of its Fisher DRMS of the vertical below the transceiver, and the range–depth
#: constraint binds there (the offset it allows, ``√(2 z σ)``, below twice that DRMS), the map is the one-packet fix's
#: own RMS error (:func:`nadir_fix_rms`): there the range carries horizontal information at second order only
#: (``r − z ≈ ρ² / 2z``), which the fix uses and the Fisher information at the point does not.
NADIR_ZONE = 5.0
#: The most points near the vertical whose fix's RMS :func:`fix_accuracy` computes (the others interpolate).
NADIR_POINTS = 48
#: log2 of the quasi-random noise draws of :func:`nadir_fix_rms` (scrambled Sobol' points, a fixed seed).
QUADRATURE_LOG2 = 10


@lru_cache(maxsize=None)
def fix_of_measurement() -> ca.Function:
    """casadi Function of the one-packet fix a receiver makes (:func:`packet_fix`), from the measurement:
    ``(z[3], depth, transceiver[3], attitude[3], range_variance, position_variance, angle_sigma_deg,
    attitude_variance, depth_variance) -> fix[3]``: Gauss-Newton from the packet's polar fix (the direction
    cosines turned into NED by the attitude), R of :data:`POSITION_MODEL` at that start, as the receivers do (their
    range and depth std at least :data:`~sblsim.models.systems.MIN_R_SIGMA`)."""
    z, b, att = ca.SX.sym("z", 3), ca.SX.sym("transceiver", 3), ca.SX.sym("attitude", 3)
    depth = ca.SX.sym("depth")
    names = ("range_variance", "position_variance", "angle_sigma_deg", "attitude_variance", "depth_variance")
    range_var, position_var, angle, attitude_var, d_var = (ca.SX.sym(n) for n in names)
    ctx = (b, att)
    a_z = ca.sqrt(ca.fmax(1.0 - z[1] ** 2 - z[2] ** 2, 0.0))
    start = b + z[0] * ca.mtimes(rotation_ned(att[0], att[1], att[2]), ca.vertcat(z[1], z[2], a_z))
    floor = MIN_R_SIGMA ** 2  # the receivers' R: sigma_range and sigma_depth at least their declared minimum
    R = POSITION_MODEL.covariance(start, ctx, ca.fmax(range_var, floor), (angle * (math.pi / 180.0)) ** 2,
                                  position_var, attitude_var)
    fix, _ = gauss_newton(z, depth, ctx, start, R, ca.fmax(d_var, floor))
    return ca.Function("sblsim_usbl_fix_of_measurement", [z, depth, b, att, range_var, position_var, angle,
                                                          attitude_var, d_var], [fix],
                       ["z", "depth", "transceiver", "attitude", *names], ["fix"])


@lru_cache(maxsize=None)
def _packet() -> ca.Function:
    """``(p, transceiver, attitude) -> z``: the packet ``[r, a_x, a_y]`` a diver at ``p`` gives a transceiver at
    ``transceiver`` whose array has the attitude ``attitude``, without noise."""
    p, b, att = ca.SX.sym("p", 3), ca.SX.sym("transceiver", 3), ca.SX.sym("attitude", 3)
    return ca.Function("sblsim_usbl_packet", [p, b, att], [POSITION_MODEL.h(p, (b, att))])


@lru_cache(maxsize=None)
def _normal_draws() -> np.ndarray:
    """The 2^:data:`QUADRATURE_LOG2` standard normal draws (10 dimensions) of :func:`nadir_fix_rms`, their mean 0
    and covariance the identity exactly, read-only."""
    from scipy.stats import norm, qmc

    draws = norm.ppf(qmc.Sobol(d=10, scramble=True, seed=20261125).random_base2(QUADRATURE_LOG2))
    draws = draws - draws.mean(axis=0)
    # their sample covariance made exactly the identity: where the fix is linear in the noise, its RMS is then the
    # Fisher information's value to rounding
    draws = np.linalg.solve(np.linalg.cholesky(np.cov(draws, rowvar=False, bias=True)), draws.T).T
    draws.flags.writeable = False
    return draws


def nadir_fix_rms(points: np.ndarray, transceiver: np.ndarray, attitude: np.ndarray, variances: Sequence
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The RMS error of the one-packet fix (:func:`fix_of_measurement`) of a static diver at each point, over the
    errors R linearizes, each where it arises: the range's noise σ_r, the array's σ_u on each direction cosine,
    the broadcast transceiver's error σ_b per axis and the attitude's σ_θ per angle (the packet is the true
    transceiver's and array's, the fix uses the broadcast transceiver and the attitude the surface used), and the
    depth's σ_d; by quasi-Monte Carlo
    integration over these 10 dimensions: 2^:data:`QUADRATURE_LOG2` scrambled Sobol' points turned into normal
    draws (a fixed seed, their sample mean and covariance made exactly 0 and I: the map is the same at every call,
    and where the fix is linear in the errors it is the Fisher information's value). The horizontal and the 3-D
    RMS [m], each (M,). (Near the vertical the fix is a discontinuous function of the noise, two minima
    competing, where a product Gauss-Hermite rule converges badly.)

    This is what the map holds near the vertical (:data:`NADIR_ZONE`): there the fix's error is not the inverse
    of the Fisher information at the point, because the range constrains the horizontal position at second
    order (the slant range minus the depth is ``ρ² / 2z``). Away from it the fix is linear in the noise and the
    two agree.

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        NED [m].
    transceiver, attitude : ndarray, shape (3,)
        The transceiver's position [m] and the array's attitude [rad].
    variances : sequence of 5 ndarray, each (M,)
        σ_r² [m²], σ_b² [m²], the array's direction std [deg], σ_θ² [rad²], σ_d² [m²] per point.

    References
    ----------
    Owen, "Scrambling Sobol' and Niederreiter-Xing points", Journal of Complexity 14(4), 1998 (scipy's
    ``stats.qmc.Sobol``); Kay 1993, Section 8.9 (the fix).
    """
    m = points.shape[0]
    if m == 0:
        return np.zeros(0), np.zeros(0)
    grid = _normal_draws()  # (K, 10) standard normal: range, a_x, a_y, transceiver (3), attitude (3), depth
    weight = np.full(grid.shape[0], 1.0 / grid.shape[0])
    k = grid.shape[0]
    range_var, position_var, angle, attitude_var, depth_var = (np.broadcast_to(np.asarray(v, float), (m,))
                                                               for v in variances)
    b, att = np.asarray(transceiver, float).reshape(3, 1), np.asarray(attitude, float).reshape(3, 1)
    clean = np.asarray(_packet().map(m)(points.T, b, att)).T  # (M, 3): the true transceiver's and array's packet
    own = np.stack([np.sqrt(range_var)[:, None] * grid[None, :, 0],
                    np.radians(angle)[:, None] * grid[None, :, 1], np.radians(angle)[:, None] * grid[None, :, 2]],
                   axis=-1)  # (M, K, 3)
    z = (clean[:, None, :] + own).reshape(-1, 3)  # (M K, 3)
    depth = (points[:, 2:3] + np.sqrt(depth_var)[:, None] * grid[None, :, 9]).ravel()
    # the fix's transceiver and attitude: the broadcast ones, off the true ones by their errors
    broadcast = b.T[None, :, :] + np.sqrt(position_var)[:, None, None] * grid[None, :, 3:6]  # (M, K, 3)
    used = att.T[None, :, :] + np.sqrt(attitude_var)[:, None, None] * grid[None, :, 6:9]
    repeat = [np.repeat(v, k) for v in (range_var, position_var, angle, attitude_var, depth_var)]
    fix = np.asarray(fix_of_measurement().map(m * k)(z.T, depth, broadcast.reshape(-1, 3).T, used.reshape(-1, 3).T,
                                                     *repeat)).T.reshape(m, k, 3)
    error = fix - points[:, None, :]
    horizontal = np.sqrt(np.einsum("k,mk->m", weight, np.sum(error[:, :, :2] ** 2, axis=2)))
    total = np.sqrt(np.einsum("k,mk->m", weight, np.sum(error ** 2, axis=2)))
    return horizontal, total


def fix_accuracy(points: np.ndarray, transceiver: np.ndarray, range_variance: float, position_variance: float,
                 angle_sigma_deg: float, attitude_variance: float, depth_variance: float,
                 heading: float = 0.0) -> dict[str, np.ndarray]:
    """The accuracy of a fix from one USBL packet plus depth (:func:`fix_information`), the array level at the
    heading ``heading``: ``drms`` (horizontal) and ``drms_3d`` [m], ``log_det`` (``log det J = −log det C``).

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        Target positions, NED [m].
    transceiver : ndarray, shape (3,)
        The transceiver's position, NED [m].
    range_variance, position_variance : float or ndarray, shape (M,)
        σ_r², the range noise, and σ_b², the broadcast transceiver position's error per axis [m²] (an array:
        one per point, as the other numbers may be).
    angle_sigma_deg : float or ndarray, shape (M,)
        The array's direction std on its axis [deg].
    attitude_variance : float
        σ_θ², the error per Euler angle of the attitude the surface uses [rad²].
    depth_variance : float
        σ_d² [m²], > 0.
    heading : float, optional
        The array's yaw [rad].

    Returns
    -------
    dict
        ``drms``, ``drms_3d``, ``log_det``, each (M,); finite everywhere (straight below the transceiver too).
        Within :data:`NADIR_ZONE` of the vertical where the range–depth constraint binds, ``drms`` and ``drms_3d``
        are the fix's own RMS error
        (:func:`nadir_fix_rms`; on a grid with more points there than :data:`NADIR_POINTS`, at that many of them,
        evenly spread over the offset from the vertical, and each other point's Fisher value scaled by the ratio
        interpolated at its offset: the ratio depends on the offset, hardly on the azimuth); ``log_det`` is the
        Fisher information's everywhere.
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    m = points.shape[0]
    f = fix_information().map(m)
    attitude = np.array([0.0, 0.0, heading])
    variances = [np.broadcast_to(np.asarray(v, float).ravel(), (m,)) for v in (
        range_variance, position_variance, angle_sigma_deg, attitude_variance, depth_variance)]
    C, drms = f(points.T, np.asarray(transceiver, dtype=float).reshape(3, 1), attitude,
                *(per_point(v) for v in variances))
    C = np.asarray(C).reshape(3, m, 3).transpose(1, 0, 2)
    out = {"drms": np.asarray(drms).ravel(), "drms_3d": np.sqrt(np.trace(C, axis1=1, axis2=2)),
           "log_det": -np.linalg.slogdet(C)[1]}
    offset = np.hypot(points[:, 0] - transceiver[0], points[:, 1] - transceiver[1])
    # where the range–depth constraint binds: the horizontal offset it allows, √(2 z σ) (σ of the slant range minus
    # the depth), below twice the direction's error
    below = points[:, 2] - transceiver[2]
    allowed = np.sqrt(2.0 * np.abs(below) * np.sqrt(variances[0] + variances[4]))
    near = np.flatnonzero((offset < NADIR_ZONE * out["drms"]) & (below > 0.0) & (allowed < 2.0 * out["drms"]))
    if near.size:
        # a fine grid near the vertical: the fix's RMS at up to NADIR_POINTS of its points (evenly spread over
        # the offset from the vertical), each point's Fisher value scaled by the ratio at its offset, interpolated
        order = near[np.argsort(offset[near], kind="stable")]
        chosen = order
        if order.size > NADIR_POINTS:
            wanted = np.linspace(offset[order[0]], offset[order[-1]], NADIR_POINTS)
            chosen = order[np.unique(np.clip(np.searchsorted(offset[order], wanted), 0, order.size - 1))]
        rms = nadir_fix_rms(points[chosen], transceiver, attitude, [v[chosen] for v in variances])
        for key, value in zip(("drms", "drms_3d"), rms):
            out[key] = out[key].copy()
            if chosen.size < order.size:
                out[key][near] *= np.interp(offset[near], offset[chosen], value / out[key][chosen])
            out[key][chosen] = value  # each point computed: its own value
    return out


def horizontal_std(points: np.ndarray, transceiver: np.ndarray, range_variance: float, position_variance: float,
                   angle_sigma_deg: float, attitude_variance: float, depth_variance: float,
                   heading: float = 0.0) -> np.ndarray:
    """Horizontal standard deviation (DRMS) of a fix from one USBL packet plus depth [m], (M,): the ``drms`` of
    :func:`fix_accuracy` (its parameters)."""
    return fix_accuracy(points, transceiver, range_variance, position_variance, angle_sigma_deg, attitude_variance,
                        depth_variance, heading)["drms"]


def seen_fix_offset(points: np.ndarray, seen: np.ndarray, transceiver: np.ndarray, range_variance,
                    position_variance, angle_sigma_deg, attitude_variance, depth_variance,
                    heading: float = 0.0) -> np.ndarray:
    """The offset of the one-packet fix (:func:`fix_of_measurement`) from a diver at each of ``points`` whose
    packet, without noise, is the one a diver at ``seen`` would give by the direct path (its range and direction
    of arrival), while its depth reading is its own: what a reflected arrival does to the fix, ``seen`` being where
    the receiver's processing of the reflection's travel time and direction places it (the array level at the
    heading ``heading``).

    Parameters
    ----------
    points, seen : ndarray, shape (M, 3)
        The divers and where their packets place them, NED [m].
    transceiver : ndarray, shape (3,)
        The transceiver's position, NED [m].
    range_variance, position_variance, angle_sigma_deg, attitude_variance, depth_variance : float or ndarray (M,)
        As for :func:`fix_accuracy` (the R the fix weighs the packet with).
    heading : float, optional
        The array's yaw [rad].

    Returns
    -------
    ndarray, shape (M, 3)
        The fix minus the diver's position, NED [m] (0 where ``seen`` is the diver).

    References
    ----------
    Kay 1993, Section 8.9 (the fix).
    """
    points, seen = np.atleast_2d(np.asarray(points, float)), np.atleast_2d(np.asarray(seen, float))
    m = points.shape[0]
    if m == 0:
        return np.zeros((0, 3))
    b, att = np.asarray(transceiver, float).reshape(3, 1), np.array([[0.0], [0.0], [heading]])
    z = _packet().map(m)(seen.T, b, att)
    variances = [per_point(np.broadcast_to(np.asarray(v, float).ravel(), (m,))) for v in (
        range_variance, position_variance, angle_sigma_deg, attitude_variance, depth_variance)]
    fix = fix_of_measurement().map(m)(z, points[:, 2].reshape(1, m), b, att, *variances)
    return np.asarray(fix).T - points


__all__ = ["fix_accuracy", "fix_information", "fix_of_measurement", "horizontal_std", "NADIR_POINTS", "NADIR_ZONE",
           "nadir_fix_rms", "QUADRATURE_LOG2", "seen_fix_offset"]
