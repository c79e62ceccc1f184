"""The USBL position PCRB: the receivers' prediction, then the depth row and a received packet's three rows.

:func:`bound_step`, at a slot, adds the depth row and, for a received packet, the three rows of
:data:`BOUND_MODEL` with the packet's transceiver and attitude, H at the true position and R of the receivers at
the true position, decorrelated. :func:`pcrb` evaluates it with casadi's virtual machine; :func:`compiled_bound`
is the same step with the packed inputs of :data:`FIXED` and :data:`STEPS`, which the local engine's library of
the USBL interface compiles (``sblsim.fmus.native``). The range bound and its shared pieces are
:mod:`sblsim.models.bound`'s.

References
----------
Tichavský, Muravchik, Nehorai, "Posterior Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans.
Signal Processing 46(5), 1998, Eq. (21).
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.channel.interface import ATTITUDE_ANGLES
from sblsim.models.bound import (
    LAW_DEFAULTS,
    information_update,
    law_variance,
    packed_bound,
    packed_fixed,
    predicted,
    stepped,
)
from sblsim.models.error_bound import ERROR_MOTION
from sblsim.models.receiver import kalman
from sblsim.models.receiver.range_direction import RangeDirectionModel
from sblsim.models.systems.usbl_fix import _depth_row

#: The measurement model of the bound: the packet's for the receivers' state with error states.
BOUND_MODEL = RangeDirectionModel(ERROR_MOTION)


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


__all__ = ["BOUND_MODEL", "bound_step", "compiled_bound", "FIXED", "pcrb", "pcrb_inputs", "STEPS"]
