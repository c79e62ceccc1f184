"""Measurement models: what a receiver measures, as objects the filters, the gate and the bound share.

A measurement model describes ``z = h(x, context) + v``, ``v ~ N(0, R)``
with R diagonal, for a filter state x laid out by a motion model
(:mod:`sblsim.models.receiver.motion`) and a *context*: what h needs besides
the state (the broadcast beacon positions of the ranges, the position of a
transceiver, ...). Like FilterPy's ``Hx``, ``HJacobian`` and ``residual``
arguments, or Stone Soup's measurement models, it gives (:class:`MeasurementModel`):

* ``dimension(context)``: m, the size of z;
* ``h(x, context)``: the predicted measurement, (m, 1);
* ``jacobian(x, context)`` and ``linearize(x, context)``: ``H = ∂h/∂x``,
  (m, n), never written by hand: casadi differentiates the expression, and
  the generated C evaluates it;
* ``variances(x, context, p)``: the diagonal of R, (m, 1), from the
  receiver's parameters ``p`` (a range's σ = ``sigma_range + range_k ‖p̂ − b‖`` at the predicted range:
  :meth:`RangeDepthModel.noise_variance`, the law of :mod:`sblsim.models.acoustics.range_law`);
* ``residual(z, h)``: ``z − h`` with the angle rows wrapped to (−π, π].

Two implementations: :class:`RangeDepthModel`, ranges to broadcast beacons
plus depth (every built-in receiver, the accuracy bound and the accuracy
maps), and :class:`~sblsim.models.receiver.range_direction.RangeDirectionModel`,
slant range and the direction cosines of the line of sight in a USBL array's frame. The variance a
range inherits from an uncertain beacon position is written once,
:meth:`RangeDepthModel.range_variance`; what an uncertain transceiver and attitude add to
a USBL packet's R, ``H_b Σ_b H_bᵀ + H_θ Σ_θ H_θᵀ``, likewise
(:meth:`~sblsim.models.receiver.range_direction.RangeDirectionModel.covariance`).

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Eqs. for the
EKF measurement model. Bar-Shalom, Li, Kirubarajan, Estimation with
Applications to Tracking and Navigation, Wiley 2001, Section 10.3.
Andersson, Gillis, Horn, Rawlings, Diehl, "CasADi: a software framework for
nonlinear optimization and optimal control", Math. Prog. Comp. 11, 2019.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca

from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.receiver.motion import CONSTANT_VELOCITY

#: State size and position entries of the receivers' motion model
#: (:data:`~sblsim.models.receiver.motion.CONSTANT_VELOCITY`).
STATE_SIZE = CONSTANT_VELOCITY.state_size
POSITION_INDEX = CONSTANT_VELOCITY.position_index


def wrap_angle(a):
    """Angle ``a`` [rad] wrapped to (−π, π]: ``a − 2π ⌈(a − π) / 2π⌉`` (numbers or casadi expressions)."""
    return a - 2.0 * math.pi * ca.ceil((a - math.pi) / (2.0 * math.pi))


class MeasurementModel:
    """Base of the measurement models (see the module documentation for the interface).

    Subclasses implement :meth:`dimension`, :meth:`h` and :meth:`variances`,
    and set :attr:`angles` (the rows that are angles); :meth:`linearize`
    defaults to casadi's Jacobian of :meth:`h`, which a subclass may replace
    by a cached casadi Function of both (the expression built once).

    Parameters
    ----------
    motion : ConstantVelocity, optional
        The motion model that lays out the state (default: the receivers').
    """

    #: Indices of the rows of z that are angles [rad] (wrapped by :meth:`residual`).
    angles: tuple[int, ...] = ()

    def __init__(self, motion=CONSTANT_VELOCITY) -> None:
        self.motion = motion

    @property
    def state_size(self) -> int:
        """n, the size of the state h reads (from the motion model)."""
        return self.motion.state_size

    def position(self, x) -> ca.SX:
        """The position part of a state, (3, 1) [m] (from the motion model)."""
        return self.motion.position(x)

    def dimension(self, context) -> int:
        """m, the size of z for this context."""
        raise NotImplementedError

    def h(self, x, context) -> ca.SX:
        """Predicted measurement, (m, 1)."""
        raise NotImplementedError

    def linearize(self, x, context) -> tuple[ca.SX, ca.SX]:
        """``h(x, context)`` (m, 1) and ``∂h/∂x`` (m, n) at ``x`` (casadi's derivative of :meth:`h`)."""
        s = ca.SX.sym("x", self.state_size)
        hs = self.h(s, context)
        h, H = ca.substitute([hs, ca.jacobian(hs, s)], [s], [ca.SX(x)])
        return h, H

    def jacobian(self, x, context) -> ca.SX:
        """``∂h/∂x``, (m, n)."""
        return self.linearize(x, context)[1]

    def variances(self, x, context, p: dict) -> ca.SX:
        """Diagonal of R, (m, 1), from the receiver's parameters ``p``."""
        raise NotImplementedError

    def covariance(self, x, context, p: dict) -> ca.SX:
        """R, (m, m), diagonal."""
        return ca.diag(self.variances(x, context, p))

    def residual(self, z, h):
        """``z − h``, (m, 1), the rows in :attr:`angles` wrapped to (−π, π] [rad]."""
        y = z - h
        if not self.angles:
            return y
        return ca.vertcat(*[wrap_angle(y[k]) if k in self.angles else y[k] for k in range(y.shape[0])])


def white_gps_sigma(p: dict):
    """The GPS error per axis a receiver puts in R [m]: ``beacon_gps_sigma``, or 0 where it carries the error as
    states (``gps_correlation_time`` > 0; a receiver that declares no such parameter: in R)."""
    if "gps_correlation_time" not in p:
        return p["beacon_gps_sigma"]
    return ca.if_else(p["gps_correlation_time"] > 0.0, 0.0, p["beacon_gps_sigma"])


def _range_model(name: str, size: int, position_index: tuple[int, ...]) -> ca.Function:
    """casadi Function ``(x[size], b[3]) -> (‖p(x) − b‖, ∂h/∂x [size])`` with ``p = x[position_index]``."""
    x = ca.SX.sym("x", size)
    b = ca.SX.sym("b", 3)
    p = ca.vertcat(*[x[i] for i in position_index])
    h = ca.norm_2(p - b)
    return ca.Function(name, [x, b], [h, ca.jacobian(h, x).T], ["x", "b"], ["h", "H"])


@lru_cache(maxsize=1)
def range_function() -> ca.Function:
    """casadi Function ``(x[6], b[3]) -> (h, Hᵀ[6])`` of one range, x the filter state."""
    return _range_model("sblsim_range", STATE_SIZE, POSITION_INDEX)


@lru_cache(maxsize=1)
def position_range_function() -> ca.Function:
    """casadi Function ``(p[3], b[3]) -> (h, ∂h/∂p [3])`` of one range, p a position."""
    return _range_model("sblsim_position_range", 3, (0, 1, 2))


@lru_cache(maxsize=1)
def beacon_range_function() -> ca.Function:
    """casadi Function ``(p[3], b[3]) -> ∂h/∂b [3]`` of one range: how a beacon position error moves it."""
    p, b = ca.SX.sym("p", 3), ca.SX.sym("b", 3)
    return ca.Function("sblsim_beacon_range", [p, b], [ca.jacobian(ca.norm_2(p - b), b).T], ["p", "b"], ["dh_db"])


@lru_cache(maxsize=None)
def error_range_function(motion) -> ca.Function:
    """casadi Function ``(x[n], b[3], clock) -> (h, ∂h/∂x [n])`` of one range at the state ``x`` of a motion model
    that carries error states: ``‖p − (b − e)‖ + clock · offset``, e the state's GPS error of the broadcast
    position and ``offset`` its clock offset [s] (``clock`` [m/s]: the assumed sound speed of a one-way range
    with clock states, else 0)."""
    x, b, clock = ca.SX.sym("x", motion.state_size), ca.SX.sym("b", 3), ca.SX.sym("clock")
    h = ca.norm_2(motion.position(x) - (b - motion.gps_error(x))) + clock * motion.clock_offset(x)
    return ca.Function("sblsim_error_range", [x, b, clock], [h, ca.jacobian(h, x).T], ["x", "b", "clock"],
                       ["h", "H"])


class RangeDepthModel(MeasurementModel):
    """Ranges to broadcast beacons plus depth: ``z = [‖p − b_1‖, …, ‖p − b_m‖, d]`` [m].

    The context is the sequence of beacon positions, each (3, 1) [m] NED, one
    per range; the depth reading measures the Down position. Methods take
    casadi values (SX) or numbers. R is ``diag(σ_r², …, σ_r², σ_d²)`` from
    the parameters ``sigma_range`` and ``sigma_depth`` (the paper's); the
    receivers that account for the broadcast beacons' uncertainty use
    :meth:`range_variance` for a range instead.

    Parameters
    ----------
    motion : ConstantVelocity, optional
        The state layout; only the built-in one (the range Function is
        compiled for :data:`~sblsim.models.receiver.motion.CONSTANT_VELOCITY`).

    Raises
    ------
    ValueError
        If ``motion`` lays the state out differently.

    References
    ----------
    Cario et al., Sensors 21(3):762, 2021, Section 4.3.
    """

    def __init__(self, motion=CONSTANT_VELOCITY) -> None:
        if motion.state_size < STATE_SIZE or tuple(motion.position_index) != POSITION_INDEX:
            raise ValueError(f"RangeDepthModel: the state must begin with the {STATE_SIZE} entries of the constant "
                             f"velocity, the position at {POSITION_INDEX}, got {motion.state_size} and "
                             f"{motion.position_index}")
        super().__init__(motion)
        self.depth_row = tuple(1.0 if i == POSITION_INDEX[2] else 0.0 for i in range(motion.state_size))

    @property
    def errors(self) -> bool:
        """The motion model carries error states (the GPS error, the clock) that a range reads."""
        return self.motion.state_size > STATE_SIZE

    def dimension(self, context) -> int:
        """m + 1: the ranges and the depth."""
        return len(context) + 1

    def depth(self, x) -> ca.SX:
        """Predicted depth reading: the Down position of the state [m]."""
        return x[self.motion.position_index[2]]

    def h(self, x, beacons) -> ca.SX:
        """Predicted measurement ``[‖p − b_i‖ …, p_z]``, (m + 1, 1) [m]."""
        return ca.vertcat(*[self.range_row(x, b)[0] for b in beacons], self.depth(x))

    def linearize(self, x, beacons) -> tuple[ca.SX, ca.SX]:
        """``h`` (m + 1, 1) and ``∂h/∂x`` (m + 1, 6): one casadi range Function call per beacon, the depth row."""
        rows = [self.range_row(x, b) for b in beacons]
        return (ca.vertcat(*[r[0] for r in rows], self.depth(x)),
                ca.vertcat(*[r[1] for r in rows], self.depth_jacobian()))

    def jacobian(self, x, beacons) -> ca.SX:
        """``∂h/∂x``, (m + 1, n): the casadi-derived range rows and the depth row."""
        return ca.vertcat(*[self.range_row(x, b)[1] for b in beacons], self.depth_jacobian())

    def range_row(self, x, beacon, clock=0.0) -> tuple[ca.SX, ca.SX]:
        """One range: its prediction [m] and its Jacobian row (1, n). With error states
        (:func:`error_range_function`) the broadcast position is corrected by the state's GPS error and ``clock``
        [m/s] times the state's clock offset is added (0: none)."""
        if not self.errors:
            h, H = range_function()(x, beacon)
        else:
            h, H = error_range_function(self.motion)(x, beacon, clock)
        return h, H.T

    def depth_jacobian(self) -> ca.SX:
        """``∂d/∂x``, (1, n)."""
        return ca.horzcat(*self.depth_row)

    def variances(self, x, beacons, p: dict) -> ca.SX:
        """``[σ_1², …, σ_m², σ_d²]``, (m + 1, 1) [m²]: each range's :meth:`noise_variance` at ``x`` and
        ``p["sigma_depth"]²``."""
        return ca.vertcat(*[self.noise_variance(x, b, p) for b in beacons], p["sigma_depth"] ** 2)

    def noise_variance(self, x, beacon, p: dict) -> ca.SX:
        """The variance of a range's own noise in R [m²] at the state ``x`` (n, 1) for the beacon ``beacon`` (3, 1)
        [m]: ``(σ₀ + k ‖p̂ − b‖)²``, the range-dependent law (:func:`~sblsim.models.acoustics.range_law.
        range_noise_sigma`: ``sigma_range`` σ₀ [m], ``range_k`` k [m/m]) at the predicted range, R state-dependent
        as the standard EKF takes it (Bar-Shalom, Li, Kirubarajan 2001, Section 10.3); ``σ₀²`` where the receiver
        does not declare ``range_k``.

        References
        ----------
        Quazi, IEEE Trans. ASSP 29(3):527–533, 1981 (the law's source).
        """
        if "range_k" not in p:
            return p["sigma_range"] ** 2
        return range_noise_sigma(p, ca.norm_2(self.position(x) - beacon)) ** 2

    @staticmethod
    def range_variance(position, beacon, noise_variance, position_variance=None, attitude_variance=None,
                       arm=None) -> ca.SX:
        """Variance of a range from a beacon whose broadcast position is uncertain [m²].

        A beacon position error δb moves the range by ``g δb``, ``g = ∂h/∂b``
        (casadi); the errors are an isotropic position error of
        ``position_variance`` per axis (GPS, or any isotropic stand-in) and a
        small platform rotation δθ of ``attitude_variance`` per axis, which
        moves the beacon at lever arm ``a`` by ``δθ × a``, so the range by
        ``δθ · (a × gᵀ)``:

        ``noise_variance + position_variance ‖g‖² + attitude_variance ‖a × gᵀ‖²``

        (a term whose variance is None is left out). ``‖g‖ = 1`` away from
        the beacon.

        Parameters
        ----------
        position, beacon : casadi.SX or array, (3, 1)
            Diver and beacon positions [m], NED.
        noise_variance : casadi.SX or float
            Variance of the range itself [m²] (σ_r², or σ_r² + σ_GPS² when the GPS term is folded in).
        position_variance : casadi.SX or float, optional
            Isotropic beacon-position variance per axis [m²].
        attitude_variance : casadi.SX or float, optional
            Attitude variance per axis [rad²]; needs ``arm``.
        arm : casadi.SX or array, (3, 1), optional
            The beacon's lever arm in NED [m].

        Returns
        -------
        casadi.SX
            The range's variance [m²].

        Raises
        ------
        ValueError
            If ``attitude_variance`` is given without ``arm``.
        """
        g = beacon_range_function()(position, beacon)
        total = noise_variance
        if position_variance is not None:
            total = total + position_variance * ca.dot(g, g)
        if attitude_variance is not None:
            if arm is None:
                raise ValueError("range_variance: an attitude variance needs the beacon's lever arm")
            moved = ca.cross(ca.vertcat(arm[0], arm[1], arm[2]), g)
            total = total + attitude_variance * ca.dot(moved, moved)
        return total

    def fresh_range_variance(self, x, beacon, p: dict) -> ca.SX:
        """A fresh range's variance in R [m²] from the receiver's parameters: :meth:`range_variance` with σ_r² of
        the range law at ``x`` (:meth:`noise_variance`) and an isotropic beacon error ``σ_GPS² + (σ_att · arm)²``
        per axis (``beacon_gps_sigma`` [m], ``beacon_attitude_sigma_deg`` [deg], ``beacon_arm`` [m]: the attitude
        error taken isotropic); the GPS term is left out where the receiver carries the GPS error as states
        (``gps_correlation_time`` > 0)."""
        attitude = p["beacon_attitude_sigma_deg"] * math.pi / 180.0
        return self.range_variance(self.position(x), beacon, self.noise_variance(x, beacon, p),
                                   white_gps_sigma(p) ** 2 + (attitude * p["beacon_arm"]) ** 2)


__all__ = ["beacon_range_function", "error_range_function", "MeasurementModel", "POSITION_INDEX",
           "position_range_function", "range_function", "RangeDepthModel", "STATE_SIZE", "white_gps_sigma",
           "wrap_angle"]
