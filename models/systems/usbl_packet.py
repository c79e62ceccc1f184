"""What one USBL packet measures: the slant range and the array's direction cosines seen from the transceiver.

The packet's measurement ``z = [r, a_x, a_y]`` (:func:`measurement`), its context ``(b, θ)``, the transceiver's
position and the attitude with which the surface turned the direction into NED (:func:`context`), its polar fix
and the receivers' R (:func:`covariance`): the channel's noise chain propagated by the model's Jacobians,
``diag(σ_r², σ_u², σ_u²)`` plus the broadcast transceiver position's error ``σ_b² H_b H_bᵀ`` and the attitude's
``σ_θ² H_θ H_θᵀ`` (:class:`~sblsim.models.receiver.range_direction.RangeDirectionModel`). The system is
:mod:`sblsim.models.systems.usbl`.

References
----------
Vickery, "Acoustic positioning systems. A practical overview of current systems", Proc. 1998 Workshop on
Autonomous Underwater Vehicles, IEEE, doi:10.1109/AUV.1998.744441.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca

from sblsim.models.acoustics.channel.interface import ATTITUDE_ANGLES
from sblsim.models.platform.geometry import unit_vector
from sblsim.models.receiver.range_direction import RangeDirectionModel

#: The USBL measurement model of the receivers.
MODEL = RangeDirectionModel()


@lru_cache(maxsize=None)
def model_of(motion) -> RangeDirectionModel:
    """The packet's model of a receiver's motion model (its state layout)."""
    return RangeDirectionModel(motion)


class _PositionState:
    """The layout of a bare position (the fix's Jacobians): no velocity, no error states."""

    state_size = 3
    position_index = (0, 1, 2)

    @staticmethod
    def position(x):
        return x


#: The packet's model of a bare position (the fix and the map).
POSITION_MODEL = RangeDirectionModel(_PositionState())


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


__all__ = ["attitude", "context", "covariance", "direction", "measurement", "MODEL", "model_of", "polar_fix",
           "POSITION_MODEL", "transceiver", "transceiver_variance"]
