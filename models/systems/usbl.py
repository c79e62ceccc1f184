"""Ultra-short baseline (USBL): one transceiver on the platform measures the diver's range and direction.

**Geometry.** The transceiver sits at the lever arm ``(0, 0, h)`` below the GPS
antenna, ``h = platform.transducer_depth`` (a custom layout's one offset
instead), plus its installation error; ``platform.baseline`` does not apply
(the arm of an SBL beacon; a compared USBL ignores a ``--set
platform.baseline``). Its array is mounted with a misalignment
``μ ~ N(0, σ_μ² I)`` per axis, drawn once per run: the array's attitude is the
platform's plus μ (the platform's ``array_*`` outputs), while the surface
converts the array's angles with the IMU's measured attitude (``imu_*``). The
transceiver interrogates: ranging is always two-way (``acoustics.ranging`` is
forced to ``twtt``). The components' interface is that of one beacon.

**What a packet measures** (what every receiver does with it): the slant range
[m], the direction of arrival (azimuth and elevation, NED, [rad]) and the
transceiver's position (GPS and IMU) [m], the
:class:`~sblsim.models.receiver.range_bearing.RangeBearingModel` with the depth
reading:

* the Kalman receivers update with the depth and then with the three rows of
  the fresh packet (:meth:`KalmanReceiver.packet_update
  <sblsim.models.receiver.core.KalmanReceiver.packet_update>`: the EKF's,
  angle residuals wrapped; the UKF has its own), the range row through the
  NIS gate (multipath lengthens the range);
* the instrumentation fix, and the ``lsq`` receiver's estimate, is the polar
  fix ``b + r (cos ε cos α, cos ε sin α, sin ε)`` (:func:`polar_fix`), with
  the covariance ``(Hᵀ R⁻¹ H)⁻¹`` of the position (:func:`fix_covariance`).

R (:func:`variances`): the channel's noise, ``σ_r²`` on the range and
``σ_a² = (σ_θ / max(cos φ, floor))² + σ_att²`` on each angle (σ_θ =
``sigma_angle_deg`` on the array's axis, φ the predicted ray's angle off the
vertical, σ_att the attitude error; :mod:`sblsim.models.acoustics.core`), plus
the transceiver position's error ``H_b Σ_b H_bᵀ`` with ``Σ_b = σ_b² I``,
``σ_b² = σ_GPS² + (σ_att a)²`` (GPS, and the lever arm a turned by the
attitude error, as for an SBL range): ``σ_b²`` on the range, ``σ_b² / ρ²`` on
the azimuth, ``σ_b² / r²`` on the elevation
(:meth:`~sblsim.models.receiver.range_bearing.RangeBearingModel.transceiver_variances`).
Straight below the transceiver the azimuth is undefined: the derivatives and
ρ are taken at least :data:`RHO_FLOOR` off the vertical.

**Bound.** :func:`bound_step`: the receivers' prediction, then at a slot the
depth row and, for a received packet, the range, azimuth and elevation rows
of :data:`BOUND_MODEL` with the transceiver position the packet carries, H at
the true position, the variances of the receivers' R at the true position
(:func:`bound_variances`, the transceiver's error included). :func:`pcrb`
evaluates it with casadi's virtual machine; :func:`compiled_bound` is the same
step with the packed inputs of :data:`FIXED` and :data:`STEPS`, which the local
engine's library of the USBL interface compiles (``sblsim.fmus.native``). A
mounting misalignment (a bias) is not in it. **Map**: one packet plus the depth
(:func:`fix_information`), from the covariance of the packet's polar fix
(:func:`packet_covariance`, the same R in Cartesian form: finite everywhere).

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Section 10.3 (EKF with polar measurements).
Tichavský, Muravchik, Nehorai, "Posterior Cramér-Rao bounds for
discrete-time nonlinear filtering", IEEE Trans. Signal Processing 46(5),
1998, Eq. (21). Kay, Fundamentals of Statistical Signal Processing:
Estimation Theory, Prentice Hall 1993, Section 3.7.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from sblsim.models.acoustics.core import DIRECTION, USBL_COS_FLOOR
from sblsim.models.bound import (
    MOTION,
    information_update,
    measurement_information,
    per_point,
    predicted,
    stepped,
)
from sblsim.models.declarations import ModelError, Variable
from sblsim.models.platform.geometry import parse_offsets
from sblsim.models.receiver import kalman
from sblsim.models.receiver.range_bearing import RangeBearingModel
from sblsim.models.systems import System, register

#: The smallest direction-of-arrival std in R [deg] (the ``sigma_angle_deg`` parameter's minimum; the ties and
#: the bound floor the platform's value at it).
MIN_ANGLE_SIGMA_DEG = 1e-3
#: ρ_min [m]: the receivers' and the bound's derivatives of the packet and the azimuth's transceiver term of R
#: (``σ_b² / ρ²``) take the diver at least this far from the vertical through the transceiver
#: (:func:`~sblsim.models.receiver.range_bearing.off_axis_point`), where the azimuth is undefined: below any GPS
#: error, so that near the vertical R's ``σ_b² / ρ_min²`` leaves the azimuth without weight, and finite.
RHO_FLOOR = 1e-3
#: The USBL measurement model of the receivers.
MODEL_RB = RangeBearingModel(floor=RHO_FLOOR)
#: The measurement model of the bound: range, azimuth and elevation from the transceiver.
BOUND_MODEL = RangeBearingModel(MOTION, floor=RHO_FLOOR)


class _PositionState:
    """The layout of a bare position (for the fix's Jacobian)."""

    state_size = 3
    position_index = (0, 1, 2)

    @staticmethod
    def position(x):
        return x


_POSITION_MODEL = RangeBearingModel(_PositionState(), floor=RHO_FLOOR)


def receiver_parameters() -> tuple[Variable, ...]:
    """The receivers' USBL parameter (declared after the clock, so that earlier value references stay)."""
    return (Variable("sigma_angle_deg", "parameter", "Real", 0.5, "deg",
                     "USBL: direction-of-arrival std on the array's axis in R (default: platform.usbl_angle_sigma_deg)",
                     min=MIN_ANGLE_SIGMA_DEG, max=45.0),)


def transceiver(u: dict) -> ca.SX:
    """The transceiver position the packet carries, (3, 1) [m]."""
    return ca.vertcat(u["beacon_x"], u["beacon_y"], u["beacon_z"])


def measurement(u: dict) -> ca.SX:
    """``z = [r, α, ε]`` of the packet, (3, 1) [m, rad, rad]."""
    return ca.vertcat(u["range"], u["azimuth"], u["elevation"])


def polar_fix(u: dict) -> ca.SX:
    """The diver's position from one packet: ``b + r (cos ε cos α, cos ε sin α, sin ε)``, (3, 1) [m]."""
    r, a, e = u["range"], u["azimuth"], u["elevation"]
    return transceiver(u) + r * ca.vertcat(ca.cos(e) * ca.cos(a), ca.cos(e) * ca.sin(a), ca.sin(e))


def sensor_variances(position, beacon, range_variance, angle_sigma_deg, attitude_variance) -> ca.SX:
    """What the packet's own measurement adds to R, ``[σ_r², σ_a², σ_a²]`` (3, 1) [m², rad², rad²], at
    ``position`` (3, 1) [m] seen from ``beacon`` (3, 1) [m]: the range noise ``range_variance = σ_r²``, and for
    each angle ``σ_a² = (σ_θ / max(cos φ, 0.1))² + σ_att²`` (``angle_sigma_deg = σ_θ`` [deg] on the array's
    axis, φ the line of sight's angle off the vertical, ``attitude_variance = σ_att²`` [rad²] of the IMU that turns
    the array's angles into NED; the channel's model, :mod:`sblsim.models.acoustics.core`)."""
    d = position - beacon
    off_axis = ca.fmax(d[2] / ca.fmax(ca.norm_2(d), 1e-9), USBL_COS_FLOOR)  # cos of the angle off the vertical
    angle = (angle_sigma_deg * (math.pi / 180.0) / off_axis) ** 2 + attitude_variance
    return ca.vertcat(range_variance, angle, angle)


def packet_variances(position, beacon, range_variance, angle_sigma_deg, attitude_variance,
                     position_variance) -> ca.SX:
    """Diagonal of R of a USBL packet (3, 1) [m², rad², rad²] at ``position`` (3, 1) [m]: :func:`sensor_variances`
    plus what an isotropic error of ``position_variance = σ_b²`` [m²] per axis in the broadcast transceiver position
    adds, ``H_b σ_b² I H_bᵀ = σ_b² [1, 1 / ρ², 1 / r²]``
    (:meth:`~sblsim.models.receiver.range_bearing.RangeBearingModel.transceiver_variances`, ρ floored at
    :data:`RHO_FLOOR`):

    ``[σ_r² + σ_b², σ_a² + σ_b² / ρ², σ_a² + σ_b² / r²]``.
    """
    return (sensor_variances(position, beacon, range_variance, angle_sigma_deg, attitude_variance)
            + _POSITION_MODEL.transceiver_variances(position, beacon, position_variance))


def transceiver_variance(p: dict):
    """``σ_b² = σ_GPS² + (σ_att a)²`` [m²]: the receivers' isotropic per-axis variance of the broadcast transceiver
    position, the GPS error and the lever arm ``a`` turned by the attitude error (taken isotropic), as for a
    range (:meth:`~sblsim.models.receiver.measurement.RangeDepthModel.fresh_range_variance`); from
    ``beacon_gps_sigma`` [m], ``beacon_attitude_sigma_deg`` [deg] and ``beacon_arm`` [m], each 0 where the receiver
    does not declare it (``p`` is read with ``get``)."""
    attitude = p.get("beacon_attitude_sigma_deg", 0.0) * (math.pi / 180.0)
    return p.get("beacon_gps_sigma", 0.0) ** 2 + (attitude * p.get("beacon_arm", 0.0)) ** 2


def variances(position, beacon, p: dict) -> ca.SX:
    """Diagonal of the receivers' R (3, 1) at the predicted position (3, 1) [m]: :func:`packet_variances` with
    ``σ_r = sigma_range``, ``σ_θ = sigma_angle_deg``, ``σ_att = beacon_attitude_sigma_deg`` and
    ``σ_b² =`` :func:`transceiver_variance` (a receiver that declares no beacon uncertainty: σ_att = σ_b = 0)."""
    attitude = p.get("beacon_attitude_sigma_deg", 0.0) * (math.pi / 180.0)
    return packet_variances(position, beacon, p["sigma_range"] ** 2, p["sigma_angle_deg"], attitude ** 2,
                            transceiver_variance(p))


@lru_cache(maxsize=None)
def polar_jacobian() -> ca.Function:
    """casadi Function ``z[3] -> ∂f/∂z`` (3, 3) of the polar fix ``f = b + r (cos ε cos α, cos ε sin α, sin ε)``,
    ``z = [r, α, ε]`` (casadi's derivative; it does not depend on b): the columns ``u``,
    ``r cos ε (−sin α, cos α, 0)`` and ``r (−sin ε cos α, −sin ε sin α, cos ε)``, finite everywhere."""
    z = ca.SX.sym("z", 3)
    fix = polar_fix({"range": z[0], "azimuth": z[1], "elevation": z[2], "beacon_x": 0.0, "beacon_y": 0.0,
                     "beacon_z": 0.0})
    return ca.Function("sblsim_usbl_polar_jacobian", [z], [ca.jacobian(fix, z)], ["z"], ["J"])


def packet_covariance(position, beacon, range_variance, angle_sigma_deg, attitude_variance,
                      position_variance) -> ca.SX:
    """Covariance of the polar fix of one packet (3, 3) [m²] for a diver at ``position`` (3, 1) [m]:

    ``C = J diag(σ_r², σ_a², σ_a²) Jᵀ + σ_b² I``,

    J = :func:`polar_jacobian` at ``z = h(position)``, the :func:`sensor_variances` and the isotropic transceiver
    position error ``position_variance = σ_b²`` [m²]. Where ``H = ∂h/∂p`` is invertible ``J = H⁻¹`` and
    ``H_b = −H``, so C is ``(Hᵀ R⁻¹ H)⁻¹`` with the receivers' R (:func:`packet_variances`); unlike that inverse
    it is finite straight below the transceiver (the azimuth's column is ``∝ ρ``), where it tells that the
    azimuth carries nothing.
    """
    z = _POSITION_MODEL.h(position, beacon)
    J = polar_jacobian()(z)
    R = sensor_variances(position, beacon, range_variance, angle_sigma_deg, attitude_variance)
    return ca.mtimes([J, ca.diag(R), J.T]) + position_variance * ca.SX.eye(3)


def fix_covariance(position, beacon, p: dict) -> ca.SX:
    """Covariance of the polar fix (3, 3) [m²] at ``position``: :func:`packet_covariance` with the receivers'
    parameters (as :func:`variances`)."""
    attitude = p.get("beacon_attitude_sigma_deg", 0.0) * (math.pi / 180.0)
    return packet_covariance(position, beacon, p["sigma_range"] ** 2, p["sigma_angle_deg"], attitude ** 2,
                             transceiver_variance(p))


def bound_variances(position, transceiver, range_variance, position_variance, angle_sigma_deg,
                    attitude_variance) -> ca.SX:
    """Variances of a USBL packet's range, azimuth and elevation at ``position`` (3, 1) [m], (3, 1): the receivers'
    R (:func:`packet_variances`) with ``range_variance = σ_r²`` [m²], ``position_variance = σ_b²`` [m²] (the
    broadcast transceiver position's, per axis), the angle std on the array's axis ``angle_sigma_deg`` [deg] and
    ``attitude_variance = σ_att²`` [rad²]."""
    return packet_variances(position, transceiver, range_variance, angle_sigma_deg, attitude_variance,
                            position_variance)


@lru_cache(maxsize=None)
def bound_step(model=BOUND_MODEL) -> ca.Function:
    """One step of the USBL bound in covariance form, as a casadi Function.

    Inputs ``B (n², column-major), dt [s], q_h, q_v [m²/s³], position (3) [m], transceiver (3) [m],
    range_variance [m²], position_variance [m²], angle_sigma_deg [deg], attitude_variance [rad²],
    depth_variance [m²], slot, received (0 or 1)``; output the bound after the prediction over ``dt`` with
    ``model.motion`` and, at a slot, the depth row, then (for a received packet) the range, azimuth and elevation
    rows of ``model`` seen from the transceiver the packet carries
    (:func:`sblsim.models.bound.measurement_information`, H at the true position) with the variances
    :func:`bound_variances` at the true position: what :func:`sblsim.models.bound.bound_step` does for a range, for
    the three rows of a USBL packet.

    Parameters
    ----------
    model : RangeBearingModel, optional
        The measurement model (its motion model gives the state size and the prediction).

    References
    ----------
    Tichavský, Muravchik, Nehorai, IEEE Trans. Signal Processing 46(5), 1998, Eq. (21).
    """
    motion = model.motion
    (B, dt, qh, qv, position), x, P = predicted(motion)
    beacon = ca.SX.sym("transceiver", 3)
    noise, position_var, angle, attitude, d_var, slot, received = (
        ca.SX.sym(name) for name in ("range_variance", "position_variance", "angle_sigma_deg", "attitude_variance",
                                     "depth_variance", "slot", "received"))
    depth_row = ca.SX.zeros(1, motion.state_size)
    depth_row[motion.position_index[2]] = 1.0
    P = information_update(P, depth_row, d_var, slot)  # the depth first, as the receivers
    use = ca.logic_and(slot, received)
    P = measurement_information(P, model, x, beacon,
                                bound_variances(position, beacon, noise, position_var, angle, attitude), (use,) * 3)
    names = ["B", "dt", "q_h", "q_v", "position", "transceiver", "range_variance", "position_variance",
             "angle_sigma_deg", "attitude_variance", "depth_variance", "slot", "received"]
    return ca.Function("sblsim_usbl_bound_step", [B, dt, qh, qv, position, beacon, noise, position_var, angle,
                                                  attitude, d_var, slot, received], [ca.vec(P)], names, ["B_next"])


#: Per-replicate inputs of the USBL bound, in the order of :func:`pcrb`'s ``fixed`` columns (the compiled bound
#: numbers them from this tuple: :func:`compiled_bound`, :mod:`sblsim.fmus.contract`).
FIXED = ("dt", "q_horizontal", "q_vertical", "p0_position", "p0_velocity", "range_variance", "position_variance",
         "angle_sigma_deg", "attitude_variance", "depth_variance")
#: Per-step inputs of the USBL bound, in the order of :func:`pcrb`'s ``steps`` columns.
STEPS = ("true_x", "true_y", "true_z", "transceiver_x", "transceiver_y", "transceiver_z", "slot", "received")


def _step_inputs(f, s):
    """The inputs of :func:`bound_step` after ``(B, dt, q_h, q_v)`` from the fixed columns by name ``f`` and the
    step columns ``s`` (in :data:`STEPS` order)."""
    return (s[0:3], s[3:6], f["range_variance"], f["position_variance"], f["angle_sigma_deg"], f["attitude_variance"],
            f["depth_variance"], s[6:7], s[7:8])


def pcrb_inputs(truth: np.ndarray, slot: np.ndarray, received: np.ndarray, transceivers: np.ndarray,
                **fixed) -> tuple[np.ndarray, np.ndarray]:
    """Pack the inputs of :func:`pcrb`.

    Parameters
    ----------
    truth : ndarray, shape (N, B, 3)
        True positions at the steps t_1 … t_N [m].
    slot, received : ndarray of bool, shape (N, B)
        As for :func:`sblsim.models.bound.pcrb_inputs`.
    transceivers : ndarray, shape (N, B, 3)
        The transceiver position the packet carries [m] (used where received).
    **fixed : float or ndarray (B,)
        Every name of :data:`FIXED` (as for :func:`sblsim.models.bound.pcrb_inputs`; ``range_variance = σ_r²``
        [m²] the range noise alone, ``position_variance = σ_b²`` [m²] the broadcast transceiver position's error
        per axis (GPS and the lever arm turned by the attitude error, :func:`transceiver_variance`) and
        ``angle_sigma_deg`` the direction-of-arrival std on the array's axis [deg], > 0).

    Returns
    -------
    fixed : ndarray, shape (B, len(FIXED))
    steps : ndarray, shape (N, B, len(STEPS))
    """
    truth = np.asarray(truth, dtype=float)
    b = truth.shape[1]
    columns = np.stack([np.broadcast_to(np.asarray(fixed[k], dtype=float), (b,)) for k in FIXED], axis=1)
    steps = np.concatenate([truth, np.asarray(transceivers, dtype=float), np.asarray(slot, dtype=float)[..., None],
                            np.asarray(received, dtype=float)[..., None]], axis=-1)
    return np.ascontiguousarray(columns), np.ascontiguousarray(steps)


def pcrb(fixed: np.ndarray, steps: np.ndarray, model=BOUND_MODEL) -> np.ndarray:
    """Position PCRB of a USBL interface along B true trajectories: ``sqrt(trace)`` of the position block of
    ``J_k⁻¹`` (:func:`bound_step`, stepped with casadi's virtual machine, mapped over the B runs).

    Parameters
    ----------
    fixed, steps : ndarray
        From :func:`pcrb_inputs`.
    model : RangeBearingModel, optional
        The measurement model of :func:`bound_step`.

    Returns
    -------
    ndarray, shape (N, B)
        ``sqrt(B_xx + B_yy + B_zz)`` at each step [m].

    References
    ----------
    Tichavský, Muravchik, Nehorai, IEEE Trans. Signal Processing 46(5), 1998.
    """
    return stepped(bound_step(model), model.motion, FIXED, fixed, steps, _step_inputs)


@lru_cache(maxsize=None)
def compiled_bound() -> tuple[ca.Function, ca.Function]:
    """The USBL bound with packed inputs, for code generation: ``sblsim_system_bound_prior(fixed) -> B0`` (the
    prior's variances on the diagonal) and ``sblsim_system_bound_step(B, fixed, step) -> (B_next, error)``,
    ``fixed`` and ``step`` in :data:`FIXED` and :data:`STEPS` order, ``error = sqrt(trace)`` of the position
    block [m] (:func:`bound_step`; the same arithmetic as :func:`pcrb`)."""
    motion = BOUND_MODEL.motion
    n = motion.state_size
    step = bound_step()
    B, f, s = ca.SX.sym("B", n * n), ca.SX.sym("fixed", len(FIXED)), ca.SX.sym("step", len(STEPS))
    named = {k: f[i] for i, k in enumerate(FIXED)}
    B_next = step(B, named["dt"], named["q_horizontal"], named["q_vertical"], *_step_inputs(named, s))
    index = [i * (n + 1) for i in motion.position_index]
    error = ca.sqrt(B_next[index[0]] + B_next[index[1]] + B_next[index[2]])
    prior = ca.SX.zeros(n * n)
    for indices, key in ((motion.position_index, "p0_position"), (motion.velocity_index, "p0_velocity")):
        for i in indices:
            prior[i * (n + 1)] = named[key] ** 2
    return (ca.Function("sblsim_system_bound_prior", [f], [prior], ["fixed"], ["B0"]),
            ca.Function("sblsim_system_bound_step", [B, f, s], [B_next, error], ["B", "fixed", "step"],
                        ["B_next", "error"]))


@lru_cache(maxsize=None)
def fix_information() -> ca.Function:
    """casadi Function of the accuracy of one USBL packet (range, azimuth, elevation) plus the depth (the map).

    ``(p[3], transceiver[3], range_variance, position_variance, angle_sigma_deg, attitude_variance,
    depth_variance) -> (C (3, 3), drms)``: the covariance of the packet's polar fix with the receivers' R,
    :func:`packet_covariance` ``C_p = J diag(σ_r², σ_a², σ_a²) Jᵀ + σ_b² I`` (the Cartesian form of the Fisher
    information ``Hᵀ R⁻¹ H`` of :data:`BOUND_MODEL` with R = :func:`packet_variances`, Kay 1993, Section 3.7:
    ``C_p = (Hᵀ R⁻¹ H)⁻¹`` wherever H is invertible), the depth reading (variance σ_d²) added in covariance form,
    ``C = C_p − C_p e_z e_zᵀ C_p / (e_zᵀ C_p e_z + σ_d²)`` (the same as ``(C_p⁻¹ + e_z e_zᵀ / σ_d²)⁻¹``), and
    ``drms = sqrt(C_NN + C_EE)`` [m]. Finite everywhere, straight below the transceiver too (there the azimuth
    carries nothing and the transceiver's error remains: with a GPS error of σ per axis, DRMS ≥ √2 σ).

    References
    ----------
    Kay 1993, Section 3.7. Bar-Shalom, Li, Kirubarajan 2001, Section 10.3.
    """
    p, b = ca.SX.sym("p", 3), ca.SX.sym("transceiver", 3)
    names = ("range_variance", "position_variance", "angle_sigma_deg", "attitude_variance", "depth_variance")
    range_var, position_var, angle, attitude, d_var = (ca.SX.sym(n) for n in names)
    C = packet_covariance(p, b, range_var, angle, attitude, position_var)
    g = C[:, 2]
    C = kalman.symmetric(C - ca.mtimes(g, g.T) / (C[2, 2] + d_var))
    return ca.Function("sblsim_usbl_fix_information", [p, b, *(range_var, position_var, angle, attitude, d_var)],
                       [C, ca.sqrt(C[0, 0] + C[1, 1])], ["p", "transceiver", *names], ["C", "drms"])


def horizontal_std(points: np.ndarray, transceiver: np.ndarray, range_variance: float, position_variance: float,
                   angle_sigma_deg: float, attitude_variance: float, depth_variance: float) -> np.ndarray:
    """Horizontal standard deviation (DRMS) of a fix from one USBL packet plus depth (:func:`fix_information`).

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
        Direction-of-arrival std on the array's axis [deg].
    attitude_variance : float
        σ_att², the IMU attitude error [rad²].
    depth_variance : float
        σ_d² [m²], > 0.

    Returns
    -------
    ndarray, shape (M,)
        [m], finite everywhere (straight below the transceiver too).
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    f = fix_information().map(points.shape[0])
    return np.asarray(f(points.T, np.asarray(transceiver, dtype=float).reshape(3, 1), per_point(range_variance),
                        per_point(position_variance), per_point(angle_sigma_deg), per_point(attitude_variance),
                        per_point(depth_variance))[1]).ravel()


@register
class USBL(System):
    """Ultra-short baseline: one transceiver at ``(0, 0, transducer_depth)`` below the GPS antenna (module
    docstring; docs/model.md, "Systems")."""

    name = "usbl"
    code = 2
    title = "ultra-short baseline"
    words = "one transceiver, 0.5 deg on axis"
    fix_packets = 1
    compare_defaults = ("platform.layout=cross", "platform.usbl_angle_sigma_deg=0.5")  # the transceiver at (0, 0, h)
    marker = "transceiver"
    interface_beacons = 1
    ranging = ("twtt",)
    measures_direction = True
    takes_ranges = False
    #: The direction of arrival the packet carries and the true attitude of the transceiver's array (the
    #: platform's plus the mounting misalignment).
    timeseries_columns = {"azimuth": "acoustics.azimuth", "elevation": "acoustics.elevation",
                          **{f"array_{a}": f"platform.array_{a}" for a in ("roll", "pitch", "yaw")}}
    log_columns = {"azimuth_rad": "azimuth", "elevation_rad": "elevation"}
    bound_fixed = FIXED
    bound_steps = STEPS

    def offsets(self, platform: Mapping[str, Any]) -> np.ndarray:
        """The transceiver's body-frame lever arm (1, 3) [m]: ``(0, 0, transducer_depth)`` whatever
        ``baseline``, or a custom layout's one offset."""
        if platform["layout"] == "custom":
            return parse_offsets(platform["beacon_offsets"])
        return np.array([[0.0, 0.0, platform["transducer_depth"]]])

    def horizontal_spread(self, platform: Mapping[str, Any]) -> float:
        """Infinite: USBL measures a direction, not range differences across an aperture."""
        return math.inf

    def describe(self, platform: Mapping[str, Any]) -> str:
        return f"one transceiver, {platform['usbl_angle_sigma_deg']:g}° on axis"

    def body_offsets(self, p: Mapping[str, Any], n_beacons: int, layouts: Sequence[str]) -> list:
        """``(0, 0, transducer_depth)``, or the custom offset (``beacon1_offset_<a>``)."""
        custom = ca.vertcat(*[p[f"beacon1_offset_{a}"] for a in "xyz"])
        return [ca.if_else(p["layout"] == layouts.index("custom"), custom,
                           ca.vertcat(0.0, 0.0, p["transducer_depth"]))]

    def check(self, platform: dict[str, Any], given: set[str]) -> None:
        """One transceiver: the layout's count does not apply; a custom layout gives its one lever arm.

        Raises
        ------
        ModelError
            A custom layout of other than one offset.
        """
        if platform["layout"] == "custom" and parse_offsets(platform["beacon_offsets"]).shape[0] != 1:
            raise ModelError(f"platform.beacon_offsets: {parse_offsets(platform['beacon_offsets']).shape[0]} "
                             "offsets with platform.system = 'usbl'; give the transceiver's one lever arm 'x y z'")

    def horizontal_std(self, points: np.ndarray, platform: Mapping[str, Any], parameters: Mapping[str, float],
                       sigma_range: float, model=None) -> np.ndarray:
        """One packet (range, azimuth, elevation) plus the depth (:func:`horizontal_std`; ``model`` is not used:
        the packet's model is :data:`BOUND_MODEL`)."""
        return horizontal_std(points, self.lever_arms(platform)[0], sigma_range ** 2, parameters["position_variance"],
                              parameters["angle_sigma_deg"], parameters["attitude_variance"],
                              parameters["depth_variance"])

    def measurement_model(self):
        """Range, azimuth and elevation from the transceiver (:data:`MODEL_RB`), with the depth."""
        return MODEL_RB

    def bound_step(self):
        """:func:`bound_step` (module function)."""
        return bound_step()

    def bound_function(self):
        return compiled_bound()

    # ---- what the components ask ----
    def receiver_parameters(self) -> tuple[Variable, ...]:
        return receiver_parameters()

    def receiver_inputs(self) -> tuple[Variable, ...]:
        """The direction of arrival (the channel's ``azimuth`` and ``elevation``)."""
        return tuple(replace(v, causality="input") for v in DIRECTION)

    def polar_fix(self, u: dict) -> ca.SX:
        return polar_fix(u)

    def fix_covariance(self, position, beacon, p: dict) -> ca.SX:
        return fix_covariance(position, beacon, p)

    def receiver_update(self, receiver, x: dict, u: dict, p: dict, fresh) -> dict:
        """The receiver's update at a slot with this system's packet: ``receiver.packet_update`` with the
        range-bearing model, the transceiver as context, ``z = [r, α, ε]`` and R from :func:`variances`."""
        beacon = transceiver(u)
        return receiver.packet_update(x, u, p, fresh, MODEL_RB, beacon, measurement(u),
                                      lambda position: variances(position, beacon, p))


__all__ = ["BOUND_MODEL", "FIXED", "MIN_ANGLE_SIGMA_DEG", "MODEL_RB", "RHO_FLOOR", "STEPS", "USBL", "bound_step",
           "bound_variances", "compiled_bound", "fix_covariance", "fix_information", "horizontal_std", "measurement",
           "packet_covariance", "packet_variances", "pcrb", "pcrb_inputs", "polar_fix", "polar_jacobian",
           "receiver_parameters", "sensor_variances", "transceiver", "transceiver_variance", "variances"]
