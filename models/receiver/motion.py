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

    def clock_offset(self, x) -> ca.SX:
        """The receiver clock's offset the state carries [s]: none here (0)."""
        return ca.SX(0.0)

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


class WithErrorStates(ConstantVelocity):
    """Constant velocity plus the error states of the broadcast positions and of the receiver's clock.

    The state is ``[posX, velX, posY, velY, posZ, velZ, gps_x, gps_y, gps_z, clock_offset, clock_drift,
    attitude_roll, attitude_pitch, attitude_yaw]``:

    * ``gps_*`` [m]: the GPS error of the positions the platform broadcasts (North, East, Down), a first-order
      Gauss-Markov process of standard deviation σ_g and correlation time τ, exactly discretized,
      ``e_k+1 = φ e_k + w_k``, ``φ = exp(−Δt / τ)``, ``var(w) = σ_g² (1 − φ²)`` (the platform's
      ``gps_model = "gauss-markov"``): the broadcast position is the true one plus it;
    * ``clock_offset`` [s] and ``clock_drift`` [1]: the receiver clock's error after its power-on
      synchronization, ``offset_k+1 = offset_k + Δt drift_k``, the drift constant (a one-way travel time is
      measured late by the offset at reception); of an inverted LBL, the target pinger's emission offset from its
      nominal schedule and its interval's drift, the offset taking a random step of the pinger's jitter at each
      ping (:meth:`new_ping`);
    * ``attitude_*`` [rad]: a constant error of the attitude the surface turns directions with (the IMU's
      bias, a USBL array's mounting misalignment), per Euler angle.

    Each block is inert with a zero prior (its rows of P stay zero): a receiver that models none of them
    computes what it computes with :class:`ConstantVelocity`. The ``errors`` mapping of :meth:`predict` and
    :meth:`initial_covariance` holds ``gps_sigma`` (σ_g, 0: none) [m], ``gps_tau`` (τ) [s],
    ``clock_drift_sigma`` (the drift's prior std, 0: none) [1] and ``attitude_sigma`` (the attitude error's
    prior std per angle, 0: none) [rad].

    References
    ----------
    Brown, Hwang, Introduction to Random Signals and Applied Kalman Filtering, 4th ed., Wiley 2012, Sections
    2.9 (Gauss-Markov process) and 9.3 (clock model, augmented states). Bar-Shalom, Li, Kirubarajan 2001,
    Section 6.2.2.
    """

    state_names = ConstantVelocity.state_names + ("gps_x", "gps_y", "gps_z", "clock_offset", "clock_drift",
                                                  "attitude_roll", "attitude_pitch", "attitude_yaw")
    state_size = 14
    gps_index = (6, 7, 8)
    clock_index = (9, 10)
    attitude_index = (11, 12, 13)

    def gps_error(self, x) -> ca.SX:
        """The GPS error of the broadcast positions, (3, 1) [m]."""
        return ca.vertcat(*[x[i] for i in self.gps_index])

    def clock_offset(self, x) -> ca.SX:
        """The receiver clock's offset [s]."""
        return x[self.clock_index[0]]

    def attitude_bias(self, x) -> ca.SX:
        """The constant attitude error (roll, pitch, yaw), (3, 1) [rad]."""
        return ca.vertcat(*[x[i] for i in self.attitude_index])

    def transition(self, dt, gps_decay=1.0) -> ca.SX:
        """Φ (14, 14) for a step ``dt`` [s]: constant velocity, ``gps_decay`` = φ on the GPS error (1: the map of
        a packet's reference epoch, where the error does not change over the packet's age), the clock's offset
        moved by its drift, the attitude error constant."""
        phi = ca.SX.eye(self.state_size)
        phi[:6, :6] = ConstantVelocity().transition(dt)
        for i in self.gps_index:
            phi[i, i] = gps_decay
        phi[self.clock_index[0], self.clock_index[1]] = dt
        return phi

    def process_noise(self, dt, q_horizontal, q_vertical, gps_variance=0.0) -> ca.SX:
        """Q (14, 14): the constant velocity's, and ``gps_variance`` = σ_g² (1 − φ²) [m²] on the GPS error."""
        q = ca.SX.zeros(self.state_size, self.state_size)
        q[:6, :6] = ConstantVelocity().process_noise(dt, q_horizontal, q_vertical)
        for i in self.gps_index:
            q[i, i] = gps_variance
        return q

    def predict(self, x, P, dt, q_horizontal, q_vertical, errors=None) -> tuple[ca.SX, ca.SX]:
        """``x ← Φx``, ``P ← ΦPΦᵀ + Q`` for a step ``dt`` [s] with the ``errors`` mapping (class docstring; None:
        the error states inert)."""
        if errors is None:
            return linear_predict(x, P, self.transition(dt, 0.0), self.process_noise(dt, q_horizontal, q_vertical))
        decay = ca.exp(-dt / ca.fmax(errors["gps_tau"], 1e-9))
        return linear_predict(x, P, self.transition(dt, decay), self.process_noise(
            dt, q_horizontal, q_vertical, errors["gps_sigma"] ** 2 * (1.0 - decay * decay)))

    def new_ping(self, P, jitter, new) -> ca.SX:
        """P (14, 14) after the clock offset's random step ``jitter`` [s] (its std) where ``new`` is 1: the emission
        offset of an inverted LBL's pinger, whose every interval is the nominal one plus an independent jitter
        (the offset from the nominal schedule a random walk of one step per ping); unchanged where ``new`` is 0."""
        o = self.clock_index[0]
        step = ca.SX.zeros(self.state_size, self.state_size)
        step[o, o] = jitter * jitter * new
        return P + step

    def initial_covariance(self, position_std, velocity_std, errors=None) -> ca.SX:
        """Diagonal initial covariance (14, 14): the constant velocity's, the GPS error's stationary σ_g², the
        clock's offset 0 (synchronized at power-on) and its drift's prior, the attitude error's prior."""
        if errors is None:
            errors = {"gps_sigma": 0.0, "clock_drift_sigma": 0.0, "attitude_sigma": 0.0}
        diagonal = [position_std**2, velocity_std**2] * 3 + [errors["gps_sigma"] ** 2] * 3 + [
            0.0, errors["clock_drift_sigma"] ** 2] + [errors["attitude_sigma"] ** 2] * 3
        return ca.diag(ca.vertcat(*diagonal))


#: The motion model of the built-in Kalman receivers and of the accuracy bound.
CONSTANT_VELOCITY = ConstantVelocity()
#: The motion model of the receivers that carry error states (``ekf-seq``, ``ukf``) and of their bound.
WITH_ERROR_STATES = WithErrorStates()

__all__ = ["CONSTANT_VELOCITY", "ConstantVelocity", "WITH_ERROR_STATES", "WithErrorStates"]
