"""Ultra-short baseline (USBL): one transceiver on the platform measures the diver's range and direction.

**Geometry.** The transceiver sits at the lever arm ``(0, 0, h)`` below the GPS
antenna, ``h = platform.transducer_depth`` (a custom layout's one offset
instead), plus its installation error; ``platform.baseline`` does not apply
(the arm of an SBL beacon; a compared USBL ignores a ``--set
platform.baseline``). Its array is mounted with a misalignment
``μ ~ N(0, σ_μ² I)`` per axis, drawn once per run: the array's attitude is the
platform's plus μ (the platform's ``array_*`` outputs), while the surface
converts the array's direction with the IMU's measured attitude (``imu_*``). The
transceiver interrogates: ranging is always two-way (``acoustics.ranging`` is
forced to ``twtt``). The components' interface is that of one beacon.

**What a packet measures** (what every receiver does with it): the slant range
[m] and the direction of arrival as the array measures it, its direction
cosines ``a_x``, ``a_y`` in the array's frame (the packet's ``doa_x``,
``doa_y``: :func:`measurement`;
:class:`~sblsim.models.receiver.range_direction.RangeDirectionModel`, the
context ``(b, θ)``: the transceiver's position ``b`` [m] and the attitude ``θ``
[rad] with which the surface turned the direction into NED, ``doa_roll``,
``doa_pitch``, ``doa_yaw``, both in the packet besides the NED azimuth and
elevation). No coordinate of z is undefined anywhere, straight below the
transceiver included.

* the Kalman receivers update with the depth and then with the three rows of
  the fresh packet (:meth:`KalmanReceiver.packet_update
  <sblsim.models.receiver.core.KalmanReceiver.packet_update>`: the EKF's rows
  decorrelated by :func:`~sblsim.models.receiver.kalman.whiten`; the UKF has its
  own), the range row through the NIS gate (multipath lengthens the range);
* the instrumentation fix, and the ``lsq`` receiver's estimate, is the
  least-squares fix of the packet and the depth reading (:func:`packet_fix`:
  Gauss-Newton from the packet's polar fix), with its covariance
  ``(Hᵀ R⁻¹ H + e_z e_zᵀ / σ_d²)⁻¹``.

R (:func:`covariance`, :meth:`RangeDirectionModel.covariance
<sblsim.models.receiver.range_direction.RangeDirectionModel.covariance>`): the channel's noise
chain propagated by the model's Jacobians, ``diag(σ_r², σ_u², σ_u²)`` (the
range noise; the array's noise on each direction cosine, ``σ_u`` =
``sigma_angle_deg`` in radians, the angle's std on the array's axis) plus the
broadcast transceiver position's error ``σ_b² H_b H_bᵀ``, ``σ_b² = σ_GPS² +
(σ_att a)²`` (GPS, and the lever arm a turned by the attitude error), plus the
error of the attitude the surface used, ``σ_θ² H_θ H_θᵀ``, ``σ_θ² = σ_att²``
(the IMU's white error per Euler angle). The channel adds the array's noise in
its own frame, tilted by the waves: the direction cosines are exactly that
frame's, whatever the tilt.

**Bound.** :func:`bound_step`: the receivers' prediction, then at a slot the
depth row and, for a received packet, the three rows of :data:`BOUND_MODEL`
with the packet's transceiver and attitude, H at the true position and R of
the receivers at the true position, decorrelated. :func:`pcrb` evaluates it with
casadi's virtual machine; :func:`compiled_bound` is the same step with the
packed inputs of :data:`FIXED` and :data:`STEPS`, which the local engine's
library of the USBL interface compiles (``sblsim.fmus.native``). **Map**: one
packet plus the depth (:func:`fix_information`), the Fisher information of the
same rows for a level array at the platform's heading; near the vertical in deep
water, where the range–depth constraint binds, the fix's own RMS error
(:func:`nadir_fix_rms`, :data:`NADIR_ZONE`).

References
----------
Vickery, "Acoustic positioning systems. A practical overview of current
systems", Proc. 1998 Workshop on Autonomous Underwater Vehicles, IEEE,
doi:10.1109/AUV.1998.744441. Tichavský, Muravchik, Nehorai, "Posterior
Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans. Signal
Processing 46(5), 1998, Eq. (21). Kay, Fundamentals of Statistical Signal
Processing: Estimation Theory, Prentice Hall 1993, Sections 3.7 and 8.9
(Gauss-Newton).
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from sblsim.models.acoustics.channel.interface import ATTITUDE_ANGLES, DIRECTION, DOA_ARRAY
from sblsim.models.bound import (
    ERROR_MOTION,
    LAW_DEFAULTS,
    information_update,
    law_variance,
    packed_bound,
    packed_fixed,
    per_point,
    predicted,
    stepped,
)
from sblsim.models.declarations import ModelError, Variable
from sblsim.models.platform.geometry import parse_offsets, rotation_ned, unit_vector
from sblsim.models.receiver import kalman
from sblsim.models.receiver.range_direction import RangeDirectionModel
from sblsim.models.systems import MIN_ANGLE_SIGMA_DEG, MIN_R_SIGMA, System, register

#: The USBL measurement model of the receivers.
MODEL = RangeDirectionModel()
@lru_cache(maxsize=None)
def model_of(motion) -> RangeDirectionModel:
    """The packet's model of a receiver's motion model (its state layout)."""
    return RangeDirectionModel(motion)


#: The measurement model of the bound: the packet's for the receivers' state with error states.
BOUND_MODEL = RangeDirectionModel(ERROR_MOTION)
#: Gauss-Newton iterations of the packet's least-squares fix from its polar fix (:func:`packet_fix`).
FIX_ITERATIONS = 5


class _PositionState:
    """The layout of a bare position (the fix's Jacobians): no velocity, no error states."""

    state_size = 3
    position_index = (0, 1, 2)

    @staticmethod
    def position(x):
        return x


#: The packet's model of a bare position (the fix and the map).
POSITION_MODEL = RangeDirectionModel(_PositionState())


def receiver_parameters() -> tuple[Variable, ...]:
    """The receivers' USBL parameter (declared after the clock, so that earlier value references stay)."""
    return (Variable("sigma_angle_deg", "parameter", "Real", 0.5, "deg",
                     "USBL: the array's direction-of-arrival std on its axis in R, the std of each direction cosine "
                     "(default: platform.usbl_angle_sigma_deg)", min=MIN_ANGLE_SIGMA_DEG, max=45.0),)


def transceiver(u: dict) -> ca.SX:
    """The transceiver position the packet carries, (3, 1) [m]."""
    return ca.vertcat(u["beacon_x"], u["beacon_y"], u["beacon_z"])


def attitude(u: dict) -> ca.SX:
    """The attitude ``[roll, pitch, yaw]`` (3, 1) [rad] with which the surface turned the packet's direction."""
    return ca.vertcat(*[u[f"doa_{a}"] for a in ATTITUDE_ANGLES])


def context(u: dict) -> tuple[ca.SX, ca.SX]:
    """The packet's context of :data:`MODEL`: ``(transceiver, attitude)``."""
    return transceiver(u), attitude(u)


def direction(u: dict) -> ca.SX:
    """The packet's direction in NED, the unit vector of its azimuth and elevation (3, 1)."""
    return unit_vector(u["azimuth"], u["elevation"])


def measurement(u: dict) -> ca.SX:
    """``z = [r, a_x, a_y]`` of the packet, (3, 1) [m, 1, 1]: the slant range and the direction cosines the array
    measured (``doa_x``, ``doa_y``)."""
    return ca.vertcat(u["range"], u["doa_x"], u["doa_y"])


def polar_fix(u: dict) -> ca.SX:
    """The diver's position from the packet alone: ``b + r n(α, ε)``, (3, 1) [m]."""
    return transceiver(u) + u["range"] * direction(u)


def transceiver_variance(p: dict, states: bool = True):
    """``σ_b² = σ_GPS² + (σ_att a)²`` [m²]: the receivers' isotropic per-axis variance of the broadcast transceiver
    position, the GPS error and the lever arm ``a`` turned by the attitude error (taken isotropic), as for a
    range (:meth:`~sblsim.models.receiver.measurement.RangeDepthModel.fresh_range_variance`); from
    ``beacon_gps_sigma`` [m], ``beacon_attitude_sigma_deg`` [deg] and ``beacon_arm`` [m], each 0 where the receiver
    does not declare it (``p`` is read with ``get``). With ``states``, the GPS error is left out where the receiver
    carries it as states (``gps_correlation_time`` > 0)."""
    att = p.get("beacon_attitude_sigma_deg", 0.0) * (math.pi / 180.0)
    gps = p.get("beacon_gps_sigma", 0.0)
    if states and "gps_correlation_time" in p:
        gps = ca.if_else(p["gps_correlation_time"] > 0.0, 0.0, gps)
    return gps ** 2 + (att * p.get("beacon_arm", 0.0)) ** 2


def covariance(x, ctx, p: dict, model: RangeDirectionModel = MODEL, states: bool = True) -> ca.SX:
    """The receivers' R (3, 3) at the state ``x`` (n, 1) of ``model``: :meth:`RangeDirectionModel.covariance
    <sblsim.models.receiver.range_direction.RangeDirectionModel.covariance>` with ``σ_r = sigma_range + range_k r̂``
    at the predicted slant range r̂ (:meth:`~sblsim.models.receiver.range_direction.RangeDirectionModel.variances`),
    ``σ_u = sigma_angle_deg`` [rad], ``σ_b² =`` :func:`transceiver_variance` and ``σ_θ = beacon_attitude_sigma_deg``
    (a receiver that declares no beacon uncertainty: σ_b = σ_θ = 0). With ``states`` (a filter that carries the
    error states), what they carry is left out: the GPS error of a positive ``gps_correlation_time`` and the
    constant attitude error; without (one packet's fix), the constant attitude error's prior
    ``attitude_bias_sigma_deg`` joins the white one."""
    att = (p.get("beacon_attitude_sigma_deg", 0.0) * (math.pi / 180.0)) ** 2
    if not states:
        att = att + (p.get("attitude_bias_sigma_deg", 0.0) * (math.pi / 180.0)) ** 2
    return model.covariance(x, ctx, model.variances(x, ctx, p)[0], (p["sigma_angle_deg"] * (math.pi / 180.0)) ** 2,
                            transceiver_variance(p, states), att)


def _depth_row(n: int, index: int) -> ca.SX:
    row = ca.SX.zeros(1, n)
    row[index] = 1.0
    return row


def position_information(position, ctx, R, depth_variance) -> ca.SX:
    """Fisher information (3, 3) [1/m²] of one packet of covariance ``R`` (3, 3) and a depth reading of variance
    ``depth_variance`` [m²] about a diver at ``position`` (3, 1) [m]: ``Hᵀ R⁻¹ H + e_z e_zᵀ / σ_d²``, H of
    :data:`POSITION_MODEL` (Kay 1993, Section 3.7)."""
    H = POSITION_MODEL.jacobian(position, ctx)
    _, Hw = kalman.whiten(ca.SX.zeros(3), H, R)
    e_z = _depth_row(3, 2)
    return ca.mtimes(Hw.T, Hw) + ca.mtimes(e_z.T, e_z) / depth_variance


def packet_fix(u: dict, p: dict, depth) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The least-squares fix of one packet and the depth reading ``depth`` [m], its covariance and its residual.

    Gauss-Newton (:data:`FIX_ITERATIONS` steps) on ``[r, a_x, a_y, d]`` weighted by the receivers' R
    (:func:`covariance` at the polar fix) and ``σ_d² = sigma_depth²``, from the polar fix ``b + r n(α, ε)``;
    the covariance is ``(Hᵀ R⁻¹ H + e_z e_zᵀ / σ_d²)⁻¹`` at the fix (Kay 1993, Section 8.9).

    Returns
    -------
    point : casadi.SX, (3, 1)
        The fix [m].
    covariance : casadi.SX, (3, 3)
        Its covariance [m²].
    rss : casadi.SX
        The weighted sum of squared residuals at the fix [1] (chi-square with 1 degree of freedom: four
        measurements, three unknowns).
    """
    ctx, z = context(u), measurement(u)
    point = polar_fix(u)
    depth_variance = p["sigma_depth"] ** 2
    point, rss = gauss_newton(z, depth, ctx, point, covariance(point, ctx, p, POSITION_MODEL, states=False),
                              depth_variance)
    J = position_information(point, ctx, covariance(point, ctx, p, POSITION_MODEL, states=False), depth_variance)
    return point, kalman.symmetric(kalman.solve_spd(J, ca.SX.eye(3))), rss


def gauss_newton(z, depth, ctx, point, R, depth_variance) -> tuple[ca.SX, ca.SX]:
    """The least-squares position of a packet ``z = [r, a_x, a_y]`` (3, 1) of covariance ``R`` (3, 3) and a depth
    reading ``depth`` [m] of variance ``depth_variance`` [m²]: :data:`FIX_ITERATIONS` Gauss-Newton steps from
    ``point`` (3, 1) [m] (Kay 1993, Section 8.9); the position and its weighted sum of squared residuals."""
    e_z = _depth_row(3, 2)

    def normal(point):
        h, H = POSITION_MODEL.linearize(point, ctx)
        yw, Hw = kalman.whiten(z - h, H, R)
        J = ca.mtimes(Hw.T, Hw) + ca.mtimes(e_z.T, e_z) / depth_variance
        g = ca.mtimes(Hw.T, yw) + e_z.T * (depth - point[2]) / depth_variance
        return J, g, ca.dot(yw, yw) + (depth - point[2]) ** 2 / depth_variance

    for _ in range(FIX_ITERATIONS):
        J, g, _ = normal(point)
        point = point + kalman.solve_spd(J, g)
    _, _, rss = normal(point)
    return point, rss


@lru_cache(maxsize=None)
def bound_step(model=BOUND_MODEL) -> ca.Function:
    """One step of the USBL bound in covariance form, as a casadi Function.

    Inputs ``B (n², column-major), dt [s], q_h, q_v [m²/s³], position (3) [m], transceiver (3) [m], attitude (3)
    [rad], range_variance [m²], position_variance [m²], angle_sigma_deg [deg], attitude_variance [rad²],
    depth_variance [m²], gps_sigma [m], gps_tau [s], attitude_sigma [rad], slot, received (0 or 1), sigma_range
    [m], range_k [m/m]`` (the range law: :func:`sblsim.models.bound.law_variance` added to ``range_variance`` at
    the true range); output the
    bound after the prediction over ``dt`` with ``model.motion`` (its error states: the GPS error a Gauss-Markov
    process of std ``gps_sigma`` and correlation time ``gps_tau`` where that is positive, a constant attitude
    error of prior std ``attitude_sigma``) and, at a slot, the depth row, then (for a received packet) the three
    rows of ``model`` seen from the transceiver and attitude the packet carries, H and R
    (:meth:`RangeDirectionModel.covariance <sblsim.models.receiver.range_direction.RangeDirectionModel.covariance>`:
    the white errors) at the true position, decorrelated (:func:`~sblsim.models.receiver.kalman.whiten`) and added
    one at a time (:func:`sblsim.models.bound.information_update`): what :func:`sblsim.models.bound.bound_step`
    does for a range, for a USBL packet.

    Parameters
    ----------
    model : RangeDirectionModel, optional
        The measurement model (its motion model gives the state size and the prediction).

    References
    ----------
    Tichavský, Muravchik, Nehorai, IEEE Trans. Signal Processing 46(5), 1998, Eq. (21).
    """
    motion = model.motion
    gps_sigma, gps_tau, attitude_sigma = ca.SX.sym("gps_sigma"), ca.SX.sym("gps_tau"), ca.SX.sym("attitude_sigma")
    errors = {"gps_sigma": gps_sigma, "gps_tau": gps_tau, "clock_drift_sigma": 0.0, "attitude_sigma": attitude_sigma}
    (B, dt, qh, qv, position), x, P = predicted(motion, errors)
    beacon, att = ca.SX.sym("transceiver", 3), ca.SX.sym("attitude", 3)
    noise, position_var, angle, attitude_var, d_var, slot, received = (
        ca.SX.sym(name) for name in ("range_variance", "position_variance", "angle_sigma_deg", "attitude_variance",
                                     "depth_variance", "slot", "received"))
    P = information_update(P, _depth_row(motion.state_size, motion.position_index[2]), d_var, slot)  # depth first
    use = ca.logic_and(slot, received)
    ctx = (beacon, att)
    sigma0, growth = ca.SX.sym("sigma_range"), ca.SX.sym("range_k")
    noise_at = noise + law_variance(position, beacon, sigma0, growth)  # the range law at the true range
    R = model.covariance(x, ctx, noise_at, (angle * (math.pi / 180.0)) ** 2, position_var, attitude_var)
    _, Hw = kalman.whiten(ca.SX.zeros(3), model.jacobian(x, ctx), R)
    for k in range(3):
        P = information_update(P, Hw[k, :], 1.0, use)
    names = ["B", "dt", "q_h", "q_v", "position", "transceiver", "attitude", "range_variance", "position_variance",
             "angle_sigma_deg", "attitude_variance", "depth_variance", "gps_sigma", "gps_tau", "attitude_sigma",
             "slot", "received", "sigma_range", "range_k"]
    return ca.Function("sblsim_usbl_bound_step", [B, dt, qh, qv, position, beacon, att, noise, position_var, angle,
                                                  attitude_var, d_var, gps_sigma, gps_tau, attitude_sigma, slot,
                                                  received, sigma0, growth], [ca.vec(P)], names, ["B_next"])


#: Per-replicate inputs of the USBL bound, in the order of :func:`pcrb`'s ``fixed`` columns (the compiled bound
#: numbers them from this tuple: :func:`compiled_bound`, :mod:`sblsim.fmus.contract`); the error states' priors
#: (of :data:`sblsim.models.bound.ERROR_NAMES`, not the clock's: the USBL ranges two-way) after the rest.
FIXED = ("dt", "q_horizontal", "q_vertical", "p0_position", "p0_velocity", "range_variance", "position_variance",
         "angle_sigma_deg", "attitude_variance", "depth_variance", "gps_sigma", "gps_tau", "attitude_sigma",
         "sigma_range", "range_k")
#: Per-step inputs of the USBL bound, in the order of :func:`pcrb`'s ``steps`` columns: the true position, the
#: transceiver and the attitude the packet carries, the slot and the packet's reception.
STEPS = ("true_x", "true_y", "true_z", "transceiver_x", "transceiver_y", "transceiver_z",
         *(f"doa_{a}" for a in ATTITUDE_ANGLES), "slot", "received")


def _step_inputs(f, s):
    """The inputs of :func:`bound_step` after ``(B, dt, q_h, q_v)`` from the fixed columns by name ``f`` and the
    step columns ``s`` (in :data:`STEPS` order)."""
    return (s[0:3], s[3:6], s[6:9], f["range_variance"], f["position_variance"], f["angle_sigma_deg"],
            f["attitude_variance"], f["depth_variance"], f["gps_sigma"], f["gps_tau"], f["attitude_sigma"],
            s[9:10], s[10:11], f["sigma_range"], f["range_k"])


def pcrb_inputs(truth: np.ndarray, slot: np.ndarray, received: np.ndarray, transceivers: np.ndarray,
                attitudes: np.ndarray, **fixed) -> tuple[np.ndarray, np.ndarray]:
    """Pack the inputs of :func:`pcrb`.

    Parameters
    ----------
    truth : ndarray, shape (N, B, 3)
        True positions at the steps t_1 … t_N [m].
    slot, received : ndarray of bool, shape (N, B)
        As for :func:`sblsim.models.bound.pcrb_inputs`.
    transceivers, attitudes : ndarray, shape (N, B, 3)
        The transceiver position [m] and the attitude ``[roll, pitch, yaw]`` [rad] the packet carries (used where
        received).
    **fixed : float or ndarray (B,)
        Every name of :data:`FIXED` (as for :func:`sblsim.models.bound.pcrb_inputs`; ``range_variance = σ_r²``
        [m²] the range noise alone, ``position_variance = σ_b²`` [m²] the broadcast transceiver position's error
        per axis (GPS and the lever arm turned by the attitude error, :func:`transceiver_variance`),
        ``angle_sigma_deg`` the array's direction std on its axis [deg], > 0, and ``attitude_variance`` the
        attitude error per Euler angle [rad²]; the range law's ``sigma_range`` and ``range_k`` may be left out).

    Returns
    -------
    fixed : ndarray, shape (B, len(FIXED))
    steps : ndarray, shape (N, B, len(STEPS))
    """
    truth = np.asarray(truth, dtype=float)
    b = truth.shape[1]
    columns = packed_fixed({**LAW_DEFAULTS, **fixed}, FIXED, b)
    steps = np.concatenate([truth, np.asarray(transceivers, dtype=float), np.asarray(attitudes, dtype=float),
                            np.asarray(slot, dtype=float)[..., None], np.asarray(received, dtype=float)[..., None]],
                           axis=-1)
    return np.ascontiguousarray(columns), np.ascontiguousarray(steps)


def pcrb(fixed: np.ndarray, steps: np.ndarray, model=BOUND_MODEL) -> np.ndarray:
    """Position PCRB of a USBL interface along B true trajectories: ``sqrt(trace)`` of the position block of
    ``J_k⁻¹`` (:func:`bound_step`, stepped with casadi's virtual machine, mapped over the B runs).

    Parameters
    ----------
    fixed, steps : ndarray
        From :func:`pcrb_inputs`.
    model : RangeDirectionModel, optional
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
    """The USBL bound with packed inputs, for code generation (:func:`sblsim.models.bound.packed_bound` of
    :func:`bound_step`, ``fixed`` and ``step`` in :data:`FIXED` and :data:`STEPS` order; the same arithmetic as
    :func:`pcrb`)."""
    return packed_bound(bound_step(), BOUND_MODEL.motion, FIXED, STEPS, _step_inputs)


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
    design_grades = ("gps", "imu", "usbl_head", "ranging")
    interface_beacons = 1
    ranging = ("twtt",)
    measures_direction = True
    takes_ranges = False
    #: The direction of arrival the packet carries, the true attitude of the transceiver's array (the platform's
    #: plus the mounting misalignment) and the attitude the surface turned the direction with.
    timeseries_columns = {"azimuth": "acoustics.azimuth", "elevation": "acoustics.elevation",
                          **{f"array_{a}": f"platform.array_{a}" for a in ATTITUDE_ANGLES},
                          **{f"doa_{a}": f"acoustics.doa_{a}" for a in ("x", "y", *ATTITUDE_ANGLES)}}
    log_columns = {"azimuth_rad": "azimuth", "elevation_rad": "elevation", "doa_x": "doa_x", "doa_y": "doa_y",
                   **{f"doa_{a}_rad": f"doa_{a}" for a in ATTITUDE_ANGLES}}
    bound_fixed = FIXED
    bound_steps = STEPS
    bound_columns = {f"doa_{a}": f"acoustics.doa_{a}" for a in ATTITUDE_ANGLES}

    def receiver_ties(self, platform: Mapping[str, Any]) -> dict[str, float]:
        """The ranging systems' ties (GPS, lever arm, the GPS error's correlation time), the IMU's white error
        in R and its constant errors with the array's mounting misalignment as the attitude states' prior
        (``attitude_bias_sigma_deg``)."""
        constant = (platform["imu_bias_deg"], platform["imu_misalignment_deg"], platform["usbl_misalignment_deg"])
        return {**super().receiver_ties(platform), "beacon_attitude_sigma_deg": platform["imu_sigma_deg"],
                "attitude_bias_sigma_deg": math.hypot(*constant)}

    def bound_errors(self, cfg: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
        """The GPS error where it is a Gauss-Markov process, the constant attitude error (the IMU's bias and axis
        misalignment, the array's mounting misalignment); no clock (two-way)."""
        platform = cfg["platform"]
        constant = (platform["imu_bias_deg"], platform["imu_misalignment_deg"], platform["usbl_misalignment_deg"])
        return {**super().bound_errors(cfg), "clock_drift_sigma": 0.0, "clock": 0.0,
                "attitude_sigma": math.radians(math.hypot(*constant))}

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

    def fix_accuracy(self, points: np.ndarray, platform: Mapping[str, Any], parameters: Mapping[str, float],
                     sigma_range: float, model=None, heard: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """One packet (range and direction) plus the depth, the array level at the platform's heading
        (:func:`fix_accuracy`; ``model`` is not used: the packet's model is :data:`POSITION_MODEL`; nor is
        ``heard``: a fix is the one packet's, and the availability says how often it is heard). What a
        static vehicle's fixes scatter by over runs: the attitude's error adds the array's misalignment, drawn
        once per run, and the IMU's constant bias to the bound's white attitude noise."""
        constant = math.radians(platform["usbl_misalignment_deg"]) ** 2 + math.radians(platform["imu_bias_deg"]) ** 2
        return fix_accuracy(points, self.lever_arms(platform)[0], sigma_range ** 2, parameters["position_variance"],
                            parameters["angle_sigma_deg"], parameters["attitude_variance"] + constant,
                            parameters["depth_variance"], math.radians(platform["heading_deg"]))

    def seen_offsets(self, points: np.ndarray, seen: np.ndarray, platform: Mapping[str, Any],
                     parameters: Mapping[str, float], sigma_range) -> np.ndarray:
        """The one-packet fix's offset from divers at ``points`` whose packets place them at ``seen`` (a reflected
        arrival's range and direction, :func:`seen_fix_offset`), with the R of :meth:`fix_accuracy`, (M, 3) [m]."""
        constant = math.radians(platform["usbl_misalignment_deg"]) ** 2 + math.radians(platform["imu_bias_deg"]) ** 2
        return seen_fix_offset(points, seen, self.lever_arms(platform)[0], np.asarray(sigma_range, float) ** 2,
                               parameters["position_variance"], parameters["angle_sigma_deg"],
                               parameters["attitude_variance"] + constant, parameters["depth_variance"],
                               math.radians(platform["heading_deg"]))

    def measurement_model(self):
        """Range and direction cosines from the transceiver (:data:`MODEL`), with the depth."""
        return MODEL

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

    def receiver_late_inputs(self) -> tuple[Variable, ...]:
        """The array's direction cosines and the attitude the surface turned the direction with (the channel's
        ``doa_*``)."""
        return tuple(replace(v, causality="input") for v in DOA_ARRAY)

    def packet_fix(self, u: dict, p: dict, depth) -> tuple[ca.SX, ca.SX, ca.SX]:
        return packet_fix(u, p, depth)

    def receiver_update(self, receiver, x: dict, u: dict, p: dict, fresh) -> dict:
        """The receiver's update at a slot with this system's packet: ``receiver.packet_update`` with the packet's
        model of the receiver's state (:func:`model_of`), its context, ``z = [r, a_x, a_y]`` and R from
        :func:`covariance`."""
        ctx, model = context(u), model_of(receiver.motion)
        return receiver.packet_update(x, u, p, fresh, model, ctx, measurement(u),
                                      lambda state: covariance(state, ctx, p, model))


__all__ = ["attitude", "BOUND_MODEL", "bound_step", "compiled_bound", "context", "covariance", "direction",
           "fix_accuracy", "fix_information", "FIX_ITERATIONS", "FIXED", "horizontal_std", "measurement", "MODEL",
           "model_of", "packet_fix", "pcrb", "pcrb_inputs", "polar_fix", "position_information",
           "POSITION_MODEL", "receiver_parameters", "seen_fix_offset", "STEPS", "transceiver", "transceiver_variance",
           "USBL"]
