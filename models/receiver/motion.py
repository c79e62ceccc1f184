"""Motion models of the Kalman-type receivers: the state, its transition Φ and its process noise Q.

A motion model says what the filter state is (its size, the names of its
entries, where the position sits in it) and how it moves between two
instants. Everything that depends on the state layout (the measurement
models, the receivers' covariance outputs, the accuracy bound) asks the
motion model instead of assuming six entries.

:class:`ConstantVelocity` is the model of every built-in Kalman receiver and
of the bound: per axis (North, East, Down) a position and a velocity,
``x = [posX, velX, posY, velY, posZ, velZ]`` [m, m/s] (NED, z down), a
constant velocity driven by white-noise acceleration of spectral density
q_h (North, East) and q_v (Down) [m²/s³]:

``Φ(Δt) = blockdiag([[1, Δt], [0, 1]] × 3)``,
``Q(Δt) = q · [[Δt³/3, Δt²/2], [Δt²/2, Δt]]`` per axis.

It composes exactly: two steps of Δt/2 equal one step of Δt.

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Section 6.2.2 (continuous white-noise acceleration
model). Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762,
Section 4.3.
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.receiver.kalman import linear_predict


class ConstantVelocity:
    """Constant velocity with white-noise acceleration, state ``[posX, velX, posY, velY, posZ, velZ]``.

    Attributes
    ----------
    state_names : tuple of str
        Names of the state entries (the receivers' ``x0_*`` parameters and ``est_*`` outputs).
    state_size : int
        6.
    position_index, velocity_index : tuple of int
        Where North, East, Down position [m] and velocity [m/s] sit in the state.
    """

    state_names = ("x", "vx", "y", "vy", "z", "vz")
    state_size = 6
    position_index = (0, 2, 4)
    velocity_index = (1, 3, 5)

    def position(self, x) -> ca.SX:
        """The position part of a state ``x`` (6, 1): (3, 1) [m], NED."""
        return ca.vertcat(*[x[i] for i in self.position_index])

    def gps_error(self, x) -> ca.SX:
        """The GPS error of the broadcast positions the state carries, (3, 1) [m]: none here (zeros)."""
        return ca.SX.zeros(3)

    def attitude_bias(self, x) -> ca.SX:
        """The constant attitude error (roll, pitch, yaw) the state carries, (3, 1) [rad]: none here (zeros)."""
        return ca.SX.zeros(3)

    def transition(self, dt) -> ca.SX:
        """Transition matrix Φ, (6, 6), for a step ``dt`` [s]."""
        phi = ca.SX.eye(self.state_size)
        for k in self.position_index:
            phi[k, k + 1] = dt
        return phi

    def process_noise(self, dt, q_horizontal, q_vertical) -> ca.SX:
        """Process noise Q, (6, 6) [m², m²/s, m²/s²], for a step ``dt`` [s] and densities [m²/s³]."""
        q = ca.SX.zeros(self.state_size, self.state_size)
        block = ca.vertcat(ca.horzcat(dt**3 / 3.0, dt**2 / 2.0), ca.horzcat(dt**2 / 2.0, dt))
        for axis, density in enumerate((q_horizontal, q_horizontal, q_vertical)):
            q[2 * axis:2 * axis + 2, 2 * axis:2 * axis + 2] = density * block
        return q

    def predict(self, x, P, dt, q_horizontal, q_vertical) -> tuple[ca.SX, ca.SX]:
        """``x ← Φx``, ``P ← ΦPΦᵀ + Q`` for a step ``dt`` [s] (:func:`~sblsim.models.receiver.kalman.linear_predict`).

        Parameters
        ----------
        x : casadi.SX, (6, 1)
        P : casadi.SX, (6, 6)
            Symmetric.
        dt : casadi.SX or float
            Step [s].
        q_horizontal, q_vertical : casadi.SX or float
            Acceleration spectral densities [m²/s³].

        Returns
        -------
        x, P : casadi.SX
            (6, 1) and (6, 6), P exactly symmetric.
        """
        return linear_predict(x, P, self.transition(dt), self.process_noise(dt, q_horizontal, q_vertical))

    def initial_covariance(self, position_std, velocity_std) -> ca.SX:
        """Diagonal initial covariance, (6, 6): ``position_std`` [m] and ``velocity_std`` [m/s] on every axis."""
        return ca.diag(ca.vertcat(*[position_std**2, velocity_std**2] * 3))


#: The motion model of the built-in Kalman receivers and of the accuracy bound.
CONSTANT_VELOCITY = ConstantVelocity()

__all__ = ["CONSTANT_VELOCITY", "ConstantVelocity"]
