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
``doa_y``: :func:`~sblsim.models.systems.usbl_packet.measurement`;
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
  least-squares fix of the packet and the depth reading (:func:`~sblsim.models.systems.usbl_fix.packet_fix`:
  Gauss-Newton from the packet's polar fix), with its covariance
  ``(Hᵀ R⁻¹ H + e_z e_zᵀ / σ_d²)⁻¹``.

R (:func:`~sblsim.models.systems.usbl_packet.covariance`, :meth:`RangeDirectionModel.covariance
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

**Bound** (:mod:`~sblsim.models.systems.usbl_bound`). :func:`~sblsim.models.systems.usbl_bound.bound_step`:
the receivers' prediction, then at a slot the depth row and, for a received packet, the three rows of
:data:`~sblsim.models.systems.usbl_bound.BOUND_MODEL` with the packet's transceiver and attitude, H at the true
position and R of the receivers at the true position, decorrelated. :func:`~sblsim.models.systems.usbl_bound.pcrb`
evaluates it with casadi's virtual machine; :func:`~sblsim.models.systems.usbl_bound.compiled_bound` is the same
step with the packed inputs of :data:`~sblsim.models.systems.usbl_bound.FIXED` and
:data:`~sblsim.models.systems.usbl_bound.STEPS`, which the local engine's library of the USBL interface compiles
(``sblsim.fmus.native``). **Map** (:mod:`~sblsim.models.systems.usbl_map`): one packet plus the depth
(:func:`~sblsim.models.systems.usbl_map.fix_information`), the Fisher information of the same rows for a level
array at the platform's heading; near the vertical in deep water, where the range–depth constraint binds, the fix's
own RMS error (:func:`~sblsim.models.systems.usbl_map.nadir_fix_rms`,
:data:`~sblsim.models.systems.usbl_map.NADIR_ZONE`).

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
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from sblsim.models.acoustics.channel.interface import ATTITUDE_ANGLES, DIRECTION, DOA_ARRAY
from sblsim.models.declarations import ModelError, Variable
from sblsim.models.platform.geometry import parse_offsets
from sblsim.models.systems import MIN_ANGLE_SIGMA_DEG, System, register
from sblsim.models.systems.usbl_bound import FIXED, STEPS, bound_step, compiled_bound
from sblsim.models.systems.usbl_fix import packet_fix
from sblsim.models.systems.usbl_map import fix_accuracy, seen_fix_offset
from sblsim.models.systems.usbl_packet import MODEL, context, covariance, measurement, model_of


def receiver_parameters() -> tuple[Variable, ...]:
    """The receivers' USBL parameter (declared after the clock, so that earlier value references stay)."""
    return (Variable("sigma_angle_deg", "parameter", "Real", 0.5, "deg",
                     "USBL: the array's direction-of-arrival std on its axis in R, the std of each direction cosine "
                     "(default: platform.usbl_angle_sigma_deg)", min=MIN_ANGLE_SIGMA_DEG, max=45.0),)


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


__all__ = ["receiver_parameters", "USBL"]
