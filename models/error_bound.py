"""The PCRB of a ranging system with error states: the broadcast positions' GPS error, the clock and a constant
attitude error carried as states beside the position and the velocity.

:func:`error_bound_step` predicts the error states with their own dynamics
(:class:`~sblsim.models.receiver.motion.WithErrorStates`) and adds, at a slot, the depth row and a received
packet's range row (:func:`error_range`) with the white part of its variance; :func:`error_pcrb` steps it with
casadi's virtual machine, :func:`compiled_error_bound` with the packed inputs of :data:`ERROR_FIXED` and
:data:`ERROR_STEPS`, which the local engine's library of the ranging interface compiles. The shared pieces (the
prediction, the prior, the stepping, the packing) are :mod:`sblsim.models.bound`'s.

References
----------
Tichavský, Muravchik, Nehorai, "Posterior Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans.
Signal Processing 46(5), 1998, Eq. (21). Van Trees, Bell, Bayesian Bounds for Parameter Estimation and Nonlinear
Filtering/Tracking, Wiley 2007.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.bound import (
    ERROR_NAMES,
    effective_range_variance,
    error_symbols,
    information_update,
    law_variance,
    packed_bound,
    predicted,
    stepped,
)
from sblsim.models.receiver.motion import WITH_ERROR_STATES

#: The motion model of the bound with error states: the receivers' that carry them.
ERROR_MOTION = WITH_ERROR_STATES


def error_range(x, beacon, arm, clock) -> ca.SX:
    """A range at the state ``x`` of :data:`ERROR_MOTION` [m]: from the true beacon, the broadcast one ``beacon``
    (3, 1) less the state's GPS error and less its attitude error turned through the beacon's lever arm ``arm``
    (3, 1, NED) [m] (``β × a``, a small rotation), plus ``clock`` [m/s] times the clock's offset."""
    motion = ERROR_MOTION
    true = beacon - motion.gps_error(x) - ca.cross(motion.attitude_bias(x), arm)
    return ca.norm_2(motion.position(x) - true) + clock * motion.clock_offset(x)


@lru_cache(maxsize=None)
def error_bound_step() -> ca.Function:
    """One step of the bound of a ranging system with error states, as a casadi Function.

    The state is :data:`ERROR_MOTION`'s (the position, the velocity, the broadcast positions' GPS error, a
    Gauss-Markov process, the clock's offset and drift, a constant attitude error), predicted with their own
    dynamics; the range row is :func:`error_range`'s at the true position (the error states at 0), with the
    white part of its variance (the range noise, the white GPS error, the white attitude error through the
    lever arm: :func:`effective_range_variance`): a bound on the mean squared error of an estimator that knows
    these error sources as well as the receivers that carry them do (Tichavský et al. 1998, Eq. (21), the
    error states as random parameters with their priors; Van Trees, Bell, Bayesian Bounds for Parameter
    Estimation and Nonlinear Filtering/Tracking, Wiley 2007).

    At a slot whose packet is the first of a new ping of an inverted LBL (``new_ping``), the clock offset (the
    pinger's emission offset) first takes its random step of std ``ping_jitter``
    (:meth:`~sblsim.models.receiver.motion.WithErrorStates.new_ping`), as the receivers do.

    Inputs ``B (n²), dt, q_h, q_v, position (3), beacon (3), arm (3), noise_variance, attitude_variance,
    depth_variance, gps_sigma [m], gps_tau [s], clock_drift_sigma [1], attitude_sigma [rad], clock [m/s], slot,
    received, ping_jitter [s], new_ping, sigma_range [m], range_k [m/m]`` (the range law, as :func:`bound_step`);
    output ``B_next``.
    """
    motion = ERROR_MOTION
    errors = error_symbols()
    (B, dt, qh, qv, position), x, P = predicted(motion, errors)
    beacon, arm = ca.SX.sym("beacon", 3), ca.SX.sym("arm", 3)
    noise, attitude, d_var, clock, slot, received = (
        ca.SX.sym(name) for name in ("noise_variance", "attitude_variance", "depth_variance", "clock", "slot",
                                     "received"))
    jitter, new_ping = ca.SX.sym("ping_jitter"), ca.SX.sym("new_ping")
    P = motion.new_ping(P, jitter, ca.logic_and(slot, new_ping))  # a new ping's emission offset, before its rows
    depth_row = ca.SX.zeros(1, motion.state_size)
    depth_row[motion.position_index[2]] = 1.0
    P = information_update(P, depth_row, d_var, slot)  # the depth first, as the receivers
    s = ca.SX.sym("x", motion.state_size)
    H = ca.substitute(ca.jacobian(error_range(s, beacon, arm, clock), s), s, x)
    sigma0, growth = ca.SX.sym("sigma_range"), ca.SX.sym("range_k")
    variance = effective_range_variance(position, beacon, arm, noise + law_variance(position, beacon, sigma0, growth),
                                        attitude)
    P = information_update(P, H, variance, ca.logic_and(slot, received))
    names = ["B", "dt", "q_h", "q_v", "position", "beacon", "arm", "noise_variance", "attitude_variance",
             "depth_variance", *ERROR_NAMES, "clock", "slot", "received", "ping_jitter", "new_ping", "sigma_range",
             "range_k"]
    return ca.Function("sblsim_error_bound_step", [B, dt, qh, qv, position, beacon, arm, noise, attitude, d_var,
                                                   *errors.values(), clock, slot, received, jitter, new_ping, sigma0,
                                                   growth], [ca.vec(P)], names, ["B_next"])


#: Per-replicate inputs of the bound with error states, in the order of its ``fixed`` columns (the compiled bound
#: numbers them: :func:`compiled_error_bound`, :mod:`sblsim.fmus.contract`).
ERROR_FIXED = ("dt", "q_horizontal", "q_vertical", "p0_position", "p0_velocity", "noise_variance",
               "attitude_variance", "depth_variance", *ERROR_NAMES, "clock", "ping_jitter", "sigma_range", "range_k")
#: Per-step inputs of the bound with error states: the true position, the transmitting beacon's broadcast
#: position and lever arm (NED), the slot, the packet's reception and whether it is the first of a new ping (an
#: inverted LBL's).
ERROR_STEPS = ("true_x", "true_y", "true_z", "beacon_x", "beacon_y", "beacon_z", "arm_x", "arm_y", "arm_z", "slot",
               "received", "new_ping")


def _error_inputs(f, s):
    """The inputs of :func:`error_bound_step` after ``(B, dt, q_h, q_v)`` from the fixed columns by name and a
    step's columns (:data:`ERROR_STEPS` order)."""
    return (s[0:3], s[3:6], s[6:9], f["noise_variance"], f["attitude_variance"], f["depth_variance"],
            *(f[k] for k in ERROR_NAMES), f["clock"], s[9:10], s[10:11], f["ping_jitter"], s[11:12], f["sigma_range"],
            f["range_k"])


def error_pcrb(fixed: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Position PCRB with error states along B runs (:func:`error_bound_step`, casadi's virtual machine), as
    :func:`pcrb` (``fixed`` (B, len(ERROR_FIXED)), ``steps`` (N, B, len(ERROR_STEPS))); (N, B) [m]."""
    return stepped(error_bound_step(), ERROR_MOTION, ERROR_FIXED, fixed, steps, _error_inputs)


@lru_cache(maxsize=None)
def compiled_error_bound() -> tuple[ca.Function, ca.Function]:
    """The bound with error states with packed inputs (:func:`packed_bound` of :func:`error_bound_step`): what
    the local engine's library of the ranging interface compiles as its system's own bound."""
    return packed_bound(error_bound_step(), ERROR_MOTION, ERROR_FIXED, ERROR_STEPS, _error_inputs)


__all__ = ["compiled_error_bound", "error_bound_step", "ERROR_FIXED", "ERROR_MOTION", "error_pcrb", "error_range",
           "ERROR_STEPS"]
