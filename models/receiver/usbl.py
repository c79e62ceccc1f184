"""What every receiver does with a USBL packet: range, azimuth and elevation from the surface transceiver.

A USBL system's interface has one "beacon", the platform's transceiver; its
packet carries the slant range [m], the direction of arrival (azimuth and
elevation, NED, [rad]) the surface measured, and the transceiver's position
(GPS and IMU) [m]. A receiver of a USBL interface
(:func:`sblsim.models.platform.core.is_usbl`) uses the
:class:`~sblsim.models.receiver.range_bearing.RangeBearingModel` with the
depth reading:

* the Kalman receivers (:class:`~sblsim.models.receiver.core.KalmanReceiver`)
  update with the depth and then with the three rows of the fresh packet
  (:func:`kalman_correct`: the EKF's, angle residuals wrapped; the UKF
  has its own), the range row through the NIS gate (multipath lengthens the
  range);
* the instrumentation fix, and the ``lsq`` receiver's estimate, is the polar
  fix ``b + r (cos ε cos α, cos ε sin α, sin ε)`` (:func:`polar_fix`), with
  the covariance ``(Hᵀ R⁻¹ H)⁻¹`` of the position (:func:`fix_covariance`).

R: ``σ_r² + σ_GPS²`` for the range (the transceiver's position error along
the line of sight) and ``(σ_θ / max(cos φ, floor))² + σ_att²`` for each
angle (σ_θ = ``sigma_angle_deg`` on the array's axis, φ the predicted ray's
angle off the vertical, σ_att the attitude error; the channel's model,
:mod:`sblsim.models.acoustics.core`).

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Section 10.3 (EKF with polar measurements).
"""

from __future__ import annotations

import math

import casadi as ca

from sblsim.models.acoustics.core import USBL_COS_FLOOR
from sblsim.models.declarations import Variable
from sblsim.models.receiver import kalman
from sblsim.models.receiver.gate import gate
from sblsim.models.receiver.range_bearing import RangeBearingModel

#: The smallest direction-of-arrival std in R [deg] (the ``sigma_angle_deg`` parameter's minimum; the ties and
#: the bound floor the platform's value at it).
MIN_ANGLE_SIGMA_DEG = 1e-3
#: The USBL measurement model of the receivers.
MODEL = RangeBearingModel()


class _PositionState:
    """The layout of a bare position (for the fix's Jacobian)."""

    state_size = 3
    position_index = (0, 1, 2)

    @staticmethod
    def position(x):
        return x


_POSITION_MODEL = RangeBearingModel(_PositionState())


def usbl_parameters() -> tuple[Variable, ...]:
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


def variances(position, beacon, p: dict) -> ca.SX:
    """Diagonal of R, ``[σ_r² + σ_GPS², σ_α², σ_ε²]`` (3, 1), at the predicted position (3, 1) [m].

    ``beacon_gps_sigma`` and ``beacon_attitude_sigma_deg`` count where the
    receiver declares them (``p`` is read with ``get``).
    """
    gps = p.get("beacon_gps_sigma", 0.0)
    attitude = p.get("beacon_attitude_sigma_deg", 0.0) * (math.pi / 180.0)
    d = position - beacon
    off_axis = ca.fmax(d[2] / ca.fmax(ca.norm_2(d), 1e-9), USBL_COS_FLOOR)  # cos of the angle off the vertical
    angle = (p["sigma_angle_deg"] * (math.pi / 180.0) / off_axis) ** 2 + attitude ** 2
    return ca.vertcat(p["sigma_range"] ** 2 + gps ** 2, angle, angle)


def kalman_correct(x: dict, u: dict, p: dict, fresh, motion) -> dict:
    """The EKF update at a USBL slot: the depth, then range, azimuth and elevation of a fresh packet.

    Parameters
    ----------
    x : dict
        ``x`` (n, 1), ``P`` (n, n) and ``failed`` (1, 1) of the receiver.
    u, p : dict
        The inputs (packet, depth) and parameters (with ``gate_probability``).
    fresh : casadi.SX
        The packet is fresh (received, known beacon).
    motion : ConstantVelocity
        The state layout.

    Returns
    -------
    dict
        ``x``, ``P``, ``nis``, ``gated``, ``failed``.
    """
    depth_row = ca.SX.zeros(1, motion.state_size)
    depth_row[motion.position_index[2]] = 1.0
    state, P, nis_depth = kalman.scalar_update(x["x"], x["P"], u["depth"] - motion.position(x["x"])[2], depth_row,
                                               p["sigma_depth"] ** 2)
    beacon = transceiver(u)
    R = variances(motion.position(state), beacon, p)
    h, H = MODEL.linearize(state, beacon)
    y = MODEL.residual(measurement(u), h)
    checked = gate(y[0], ca.mtimes([H[0, :], P, H[0, :].T]) + R[0], fresh, x, u, p)
    updated, P_new, nis = kalman.update(state, P, y, H, R)
    use = checked["use"]
    return {"x": ca.if_else(use, updated, state), "P": ca.if_else(use, P_new, P),
            "nis": nis_depth + ca.if_else(use, nis, 0.0), "gated": checked["gated"], "failed": checked["failed"]}


def fix_covariance(position, beacon, p: dict) -> ca.SX:
    """Covariance of the polar fix, ``(Hᵀ R⁻¹ H)⁻¹`` (3, 3) [m²], H = ∂[r, α, ε]/∂p at ``position``."""
    H = _POSITION_MODEL.linearize(position, beacon)[1]
    information = ca.mtimes([H.T, ca.diag(1.0 / variances(position, beacon, p)), H])
    return ca.solve(information, ca.SX.eye(3))




__all__ = ["MIN_ANGLE_SIGMA_DEG", "MODEL", "fix_covariance", "kalman_correct", "measurement", "polar_fix",
           "transceiver", "usbl_parameters", "variances"]
