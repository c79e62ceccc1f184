"""Slant range and direction of arrival from a USBL transceiver: what a planar receiving array measures.

A USBL array of hydrophones in a plane measures, from the phase differences
between pairs of elements along its two axes, the **direction cosines** of the
arriving wavefront in its own frame: for a pair of spacing ``d`` along the
array's x axis the phase difference is ``Δψ = 2π d u_x / λ``, so each pair
measures one direction cosine ``u_x`` (``u_y`` likewise) with a noise of
standard deviation ``σ_u = λ σ_ψ / (2π d)`` that does not depend on the
direction. The angle off the pair's broadside, ``θ = asin u``, is then
measured with ``σ_θ = σ_u / cos θ``: the angle error grows off the array's
axis, as vendors' accuracy curves show, while the direction cosines stay
well defined everywhere, straight below the array included, where an azimuth
is not (Vickery 1998; the phase-difference form of the direction's
Cramér–Rao bound in docs/model.md).

So the measurement of a packet is ``z = [r, a_x, a_y]``: the slant range [m]
and the first two components of the unit vector of the line of sight in the
array's frame, ``a = Rᵀ (p − b) / ‖p − b‖`` with ``R = R(roll, pitch, yaw)``
the array's attitude (body to NED, ZYX, :func:`~sblsim.models.platform.geometry.rotation_ned`;
the array's axis is the body's Down) as the surface measured it (the IMU's)
and ``b`` the transceiver's position the packet carries. The third component
is not measured: a planar array cannot tell a wavefront from below its plane
from one above, and ``a_z = sqrt(1 − a_x² − a_y²)`` carries no information of
its own. The context of the model is ``(b, attitude)``, (3, 1) each.

**Noise.** R is the covariance of the channel's own noise chain propagated by
this model's Jacobians (:meth:`RangeDirectionModel.covariance`):

``R = diag(σ_r², σ_u², σ_u²) + H_b Σ_b H_bᵀ + H_θ Σ_θ H_θᵀ``,

the array's noise on each direction cosine (σ_u, on every direction), the
error of the broadcast transceiver position (``Σ_b``, GPS and lever arm) through
``H_b = ∂h/∂b`` and the error of the attitude the surface used against the
array's true one (``Σ_θ``: the IMU's white error per Euler angle, and the
array's mounting misalignment where a receiver does not carry it as a state)
through ``H_θ = ∂h/∂(roll, pitch, yaw)``, all from casadi. R is full (the
direction rows are correlated); :func:`~sblsim.models.receiver.kalman.whiten` turns a packet into rows of
unit variance for the sequential update and the bound.

**Error states.** Where the motion model carries them
(:class:`~sblsim.models.receiver.motion.WithErrorStates`), the
transceiver's position is corrected by the state's GPS error and the attitude
by the state's attitude bias before ``h`` is evaluated, so that ``H`` has their
columns too.

References
----------
Vickery, "Acoustic positioning systems. A practical overview of current
systems", Proc. 1998 Workshop on Autonomous Underwater Vehicles, IEEE,
doi:10.1109/AUV.1998.744441 (USBL: phase differences across the array).
Kay, Fundamentals of Statistical Signal Processing: Estimation Theory,
Prentice Hall 1993, Sections 3.7 (Fisher information) and 3.11 (the bound of a
phase difference). Bar-Shalom, Li, Kirubarajan, Estimation with Applications
to Tracking and Navigation, Wiley 2001, Section 10.3.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca

from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.platform.geometry import rotation_ned
from sblsim.models.receiver.measurement import MeasurementModel
from sblsim.models.receiver.motion import CONSTANT_VELOCITY


def line_of_sight(d, attitude) -> ca.SX:
    """The unit vector of ``d`` (3, 1) [m, NED] in the frame of an array of attitude ``attitude`` (3, 1)
    ``[roll, pitch, yaw]`` [rad], (3, 1): ``R(attitude)ᵀ d / ‖d‖`` (``‖d‖`` floored at 1 nm)."""
    return ca.mtimes(rotation_ned(attitude[0], attitude[1], attitude[2]).T, d / ca.fmax(ca.norm_2(d), 1e-9))


def _range_direction(d, attitude) -> ca.SX:
    """``[r, a_x, a_y]`` (3, 1) of the diver at ``d = p − b`` seen by an array of attitude ``attitude``."""
    a = line_of_sight(d, attitude)
    return ca.vertcat(ca.norm_2(d), a[0], a[1])


@lru_cache(maxsize=None)
def range_direction_function(motion) -> ca.Function:
    """casadi Function ``(x[n], b[3], attitude[3]) -> (h[3], H[3, n], H_b[3, 3], H_θ[3, 3])``: the measurement
    at the state ``x`` of ``motion`` (its position, and its GPS error and attitude bias where it carries them),
    its Jacobians with respect to the state, the transceiver's position and the attitude (casadi's)."""
    x, b, att = ca.SX.sym("x", motion.state_size), ca.SX.sym("b", 3), ca.SX.sym("attitude", 3)
    beacon, attitude = b, att
    if hasattr(motion, "gps_error"):  # a motion model that may carry error states (the receivers')
        beacon = b - motion.gps_error(x)  # the transceiver where the state's GPS error puts it
        attitude = att - motion.attitude_bias(x)
    h = _range_direction(motion.position(x) - beacon, attitude)
    return ca.Function("sblsim_range_direction", [x, b, att],
                       [h, ca.jacobian(h, x), ca.jacobian(h, b), ca.jacobian(h, att)],
                       ["x", "b", "attitude"], ["h", "H", "H_b", "H_attitude"])


class RangeDirectionModel(MeasurementModel):
    """Slant range [m] and the direction cosines ``a_x``, ``a_y`` [1] of the line of sight in the array's frame.

    The context is ``(transceiver, attitude)``: the transceiver's position (3, 1) [m, NED] and the array's
    attitude ``[roll, pitch, yaw]`` (3, 1) [rad] the surface turned the direction with.

    Parameters
    ----------
    motion : ConstantVelocity, optional
        The state layout (default: the receivers').

    Raises
    ------
    ValueError
        If the motion model's position is not three entries (North, East, Down).
    """

    def __init__(self, motion=CONSTANT_VELOCITY) -> None:
        if len(motion.position_index) != 3:
            raise ValueError(f"RangeDirectionModel: the position must be 3 entries, got {motion.position_index}")
        super().__init__(motion)

    def _function(self) -> ca.Function:
        return range_direction_function(self.motion)

    def dimension(self, context) -> int:
        """3: range and two direction cosines."""
        return 3

    def h(self, x, context) -> ca.SX:
        """``[r [m], a_x, a_y]``, (3, 1), of the state ``x`` (n, 1) for the context ``(transceiver, attitude)``."""
        return self._function()(x, *context)[0]

    def linearize(self, x, context) -> tuple[ca.SX, ca.SX]:
        """``h`` (3, 1) and ``∂h/∂x`` (3, n) from one call of the casadi Function."""
        h, H, _, _ = self._function()(x, *context)
        return h, H

    def transceiver_jacobian(self, x, context) -> ca.SX:
        """``H_b = ∂h/∂b`` (3, 3): how an error in the transceiver's broadcast position moves the packet."""
        return self._function()(x, *context)[2]

    def attitude_jacobian(self, x, context) -> ca.SX:
        """``H_θ = ∂h/∂(roll, pitch, yaw)`` (3, 3): how an error in the attitude the surface used moves the
        packet's direction (the range does not depend on it)."""
        return self._function()(x, *context)[3]

    def covariance(self, x, context, range_variance, angle_variance, position_variance,
                   attitude_variance) -> ca.SX:
        """R (3, 3) of a packet at the state ``x``: ``diag(σ_r², σ_u², σ_u²) + σ_b² H_b H_bᵀ + σ_θ² H_θ H_θᵀ``.

        Parameters
        ----------
        x : casadi.SX, (n, 1)
            The state at which the Jacobians are taken.
        context : tuple
            ``(transceiver, attitude)``.
        range_variance : casadi.SX or float
            σ_r², the range's own noise [m²].
        angle_variance : casadi.SX or float
            σ_u², the array's noise on each direction cosine [1] (σ_u is the angle's std on the array's axis
            [rad]).
        position_variance : casadi.SX or float
            σ_b², the isotropic error per axis of the broadcast transceiver position [m²].
        attitude_variance : casadi.SX or float
            σ_θ², the error per Euler angle of the attitude the surface used [rad²].
        """
        _, _, H_b, H_a = self._function()(x, *context)
        own = ca.diag(ca.vertcat(range_variance, angle_variance, angle_variance))
        return own + position_variance * ca.mtimes(H_b, H_b.T) + attitude_variance * ca.mtimes(H_a, H_a.T)

    def variances(self, x, context, p: dict) -> ca.SX:
        """The diagonal of R from the parameters ``sigma_range`` [m], ``range_k`` [m/m] (the range law at the
        predicted slant range: :func:`~sblsim.models.acoustics.range_law.range_noise_sigma`; σ₀ where ``range_k``
        is not declared), ``sigma_angle_deg`` [deg] (the array's noise only: :meth:`covariance` has the rest)."""
        angle = (p["sigma_angle_deg"] * ca.pi / 180.0) ** 2
        sigma = range_noise_sigma(p, self.h(x, context)[0]) if "range_k" in p else p["sigma_range"]
        return ca.vertcat(sigma ** 2, angle, angle)


__all__ = ["RangeDirectionModel", "line_of_sight", "range_direction_function"]
