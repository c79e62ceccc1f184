"""The accuracy limit: the posterior Cramér-Rao bound (PCRB) along a trajectory, over a measurement model.

**PCRB.** For the receivers' motion model, a constant velocity driven by
white-noise acceleration (``x_k+1 = Φ x_k + w_k``, ``w_k ~ N(0, Q(Δt))`` with
densities q_h, q_v, :class:`~sblsim.models.receiver.motion.ConstantVelocity`), and measurements
``z = h(x) + v`` with Gaussian ``v``, the information matrix ``J_k`` of any
estimator's error obeys (Tichavský, Muravchik, Nehorai, "Posterior
Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans.
Signal Processing 46(5), 1998, Eq. (21) with a linear transition):

``J_k+1 = (Q + Φ J_k⁻¹ Φᵀ)⁻¹ + E[H_k+1ᵀ R⁻¹ H_k+1]``,  ``J_0 = P_0⁻¹``,

and ``E[(x̂_k − x_k)(x̂_k − x_k)ᵀ] ≥ J_k⁻¹``, the expectation over the
measurement noise **and over trajectories drawn from the motion model**. In
covariance form ``B_k = J_k⁻¹`` this is the Kalman filter's covariance
recursion with the Jacobian ``H`` taken at the true state; :func:`pcrb`
evaluates it along one true trajectory, replacing the expectation over
trajectories by that trajectory (the usual evaluation for a given path).
It is a true bound on a trajectory drawn from the model (``random-walk``
with the receiver's q and P0 equal to the walk's); on a deterministic path it
is the accuracy of an ideal filter using the same motion model.

**Written over models.** The bound and the maps take the measurement model
as an object (:mod:`sblsim.models.receiver.measurement`), and its motion
model (``model.motion``) sets the state size, the prediction and where the
position sits. :func:`measurement_information` adds a model's rows (H from
``model.jacobian``, casadi's derivative of h) to the bound in covariance form,
one scalar row at a time (:func:`information_update`), with H at the true
state (:func:`state_at`); the Fisher information of the same rows, the maps',
is :mod:`sblsim.models.fisher`.

The bound's measurement model is the fresh-range-plus-depth model of ``ekf-seq``
(:class:`~sblsim.models.receiver.measurement.RangeDepthModel`, :data:`MODEL`):
at every slot the depth row (variance σ_d²), then, for a received packet, the
range row of the transmitting beacon with its effective variance
(:func:`effective_range_variance`)
``σ_r² + σ_GPS² ‖∂h/∂b‖² + σ_att² ‖a × ∂h/∂b‖²``, a the transmitting beacon's
lever arm in NED, the derivatives from casadi. Error sources that are not
white noise (a sound-speed mismatch, clock drift, a Gauss-Markov GPS error,
multipath outliers, platform motion between a sample and a transmission,
the staleness of held ranges) are not in the bound; the bound with error
states, :mod:`sblsim.models.error_bound`, carries the GPS error, the clock
and a constant attitude error as states.

**Other systems.** These are the bounds of the ranging systems (SBL, LBL);
a system whose packet measures something else brings its own step built from
the same functions (:func:`predicted`, :func:`measurement_information`,
:func:`stepped`): the USBL one, :mod:`sblsim.models.systems.usbl_bound`.

References
----------
Tichavský, Muravchik, Nehorai, "Posterior Cramér-Rao bounds for
discrete-time nonlinear filtering", IEEE Trans. Signal Processing 46(5),
1998.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.receiver import kalman
from sblsim.models.receiver.measurement import RangeDepthModel
from sblsim.models.receiver.motion import CONSTANT_VELOCITY

#: The motion model of the bound (the receivers').
MOTION = CONSTANT_VELOCITY
#: The measurement model of the bound and the maps: fresh ranges and the depth.
MODEL = RangeDepthModel(MOTION)
#: n, the size of the bound's state (from its motion model).
STATE_SIZE = MOTION.state_size


def effective_range_variance(position, beacon, arm, noise_variance, attitude_variance, model=MODEL):
    """Variance of a fresh range from a beacon whose position is broadcast with GPS and attitude errors [m²]:
    :meth:`RangeDepthModel.range_variance` with the GPS term folded into ``noise_variance``.

    ``noise_variance`` is ``σ_r² + σ_GPS²`` (an isotropic GPS error adds σ_GPS²
    whatever the direction: ``‖∂h/∂b‖ = 1``), ``attitude_variance`` σ_att² [rad²] per axis, ``arm``
    (3) the beacon's lever arm in NED [m]; ``model`` the range model (default the bound's).
    """
    return model.range_variance(position, beacon, noise_variance, attitude_variance=attitude_variance, arm=arm)


def law_variance(position, beacon, sigma_range, range_k):
    """What the range-dependent noise law adds to a range's variance at its true length [m²]:
    ``(σ₀ + k d)² − σ₀² = k d (2 σ₀ + k d)``, ``d = ‖position − beacon‖`` [m] (exactly 0 with ``k = 0``: the
    constant noise's bound unchanged to the last bit).

    ``sigma_range`` σ₀ [m] and ``range_k`` k [m/m] are ``acoustics.sigma_range`` and ``acoustics.range_k``
    (:func:`~sblsim.models.acoustics.range_law.range_noise_sigma`: the law the channel draws and the receivers'
    R weighs, Quazi, IEEE Trans. ASSP 29(3), 1981). The information a position gets from the variance's own
    dependence on it, ``2 k² / σ²`` per range (Kay 1993, Eq. 3.31), is left out: at most 2 k² (2 % at the
    largest k, 0.1) of the range's own ``1 / σ²``.
    """
    d = ca.norm_2(position - beacon)
    return range_k * d * (2.0 * sigma_range + range_k * d)


def information_update(P: ca.SX, H: ca.SX, variance, use) -> ca.SX:
    """``(P⁻¹ + Hᵀ H / variance)⁻¹ = P − g gᵀ / (H g + variance)``, ``g = P Hᵀ``, for a scalar measurement
    (where ``use`` is 0, P unchanged): the bound's information added, in covariance form (its upper triangle
    computed, mirrored; no gain is applied to an estimate, so the Joseph form's robustness is not needed)."""
    g = ca.mtimes(P, H.T)
    return ca.if_else(use > 0.5, kalman.symmetric(P - ca.mtimes(g, g.T) / (ca.mtimes(H, g) + variance)), P)


def state_at(motion, position) -> ca.SX:
    """A state of ``motion`` with ``position`` (3) [m] at its position entries and zeros elsewhere, (n, 1).

    The bound and the maps evaluate the Jacobians at the true position; the
    measurement models read only the position (a model whose h depends on the
    velocity would need the true velocity here).
    """
    x = ca.SX.zeros(motion.state_size)
    for k, i in enumerate(motion.position_index):
        x[i] = position[k]
    return x


def measurement_information(P: ca.SX, model, x, context, variances, use, rows=None) -> ca.SX:
    """The information of a measurement model's rows added to a bound in covariance form, one scalar row at a time.

    ``P ← (P⁻¹ + H_kᵀ H_k / r_k)⁻¹`` (:func:`information_update`) for each row k
    in ``rows``, ``H = model.jacobian(x, context)`` taken at the true state;
    with R diagonal this is the Fisher term ``E[Hᵀ R⁻¹ H]`` of the PCRB
    recursion added row by row (Tichavský et al. 1998, Eq. (21)).

    Parameters
    ----------
    P : casadi.SX, (n, n)
        The bound after the prediction [m², m²/s, m²/s²], n from ``model.motion``.
    model : MeasurementModel
        The measurement model (:mod:`sblsim.models.receiver.measurement`).
    x : casadi.SX, (n, 1)
        The true state (:func:`state_at`).
    context
        What ``model.h`` needs besides the state (the beacons of the ranges, a transceiver, ...).
    variances : casadi.SX, (m, 1)
        The rows' noise variances, the diagonal of R [units of z squared]:
        ``model.variances(x, context, p)``, or effective variances (the bound's
        ranges, :func:`effective_range_variance`).
    use : sequence of casadi.SX, length m
        Per row, 1 where the row is measured, 0 where it is not (then it changes nothing).
    rows : sequence of int, optional
        The order in which the rows are added (default 0 … m − 1). The order
        does not change the result in exact arithmetic; it fixes the rounding.

    Returns
    -------
    casadi.SX, (n, n)
    """
    H = model.jacobian(x, context)
    for k in range(H.shape[0]) if rows is None else rows:
        P = information_update(P, H[k, :], variances[k], use[k])
    return P


def predicted(motion, errors=None) -> tuple[tuple[ca.SX, ...], ca.SX, ca.SX]:
    """What every bound step shares: its first inputs ``(B (n²), dt, q_h, q_v, position (3))`` as symbols, the
    state at the true position, and the bound after the prediction over ``dt`` with ``motion``, (n, n) (with the
    ``errors`` mapping of a motion model that carries error states,
    :class:`~sblsim.models.receiver.motion.WithErrorStates`)."""
    n = motion.state_size
    B = ca.SX.sym("B", n * n)
    dt, qh, qv = ca.SX.sym("dt"), ca.SX.sym("q_h"), ca.SX.sym("q_v")
    position = ca.SX.sym("position", 3)
    x = state_at(motion, position)
    if errors is None:
        _, P = motion.predict(x, ca.reshape(B, n, n), dt, qh, qv)
    else:
        _, P = motion.predict(x, ca.reshape(B, n, n), dt, qh, qv, errors)
    return (B, dt, qh, qv, position), x, P


#: The names of the error sources of a bound with error states (the ``errors`` mapping of
#: :class:`~sblsim.models.receiver.motion.WithErrorStates`), in the order of its per-run inputs.
ERROR_NAMES = ("gps_sigma", "gps_tau", "clock_drift_sigma", "attitude_sigma")


def error_symbols() -> dict[str, ca.SX]:
    """The ``errors`` mapping as symbols, by :data:`ERROR_NAMES`."""
    return {name: ca.SX.sym(name) for name in ERROR_NAMES}


def error_prior(motion, named: dict) -> ca.SX:
    """The prior of a bound (n², column-major) from per-run inputs by name: ``p0_position``, ``p0_velocity`` and,
    for a motion model with error states, the priors of :data:`ERROR_NAMES` (0 where not named)
    (:meth:`~sblsim.models.receiver.motion.WithErrorStates.initial_covariance`)."""
    if motion.state_size == STATE_SIZE:
        prior = motion.initial_covariance(named["p0_position"], named["p0_velocity"])
    else:
        prior = motion.initial_covariance(named["p0_position"], named["p0_velocity"],
                                          {k: named.get(k, 0.0) for k in ERROR_NAMES})
    return ca.densify(ca.vec(prior))  # dense: generated code writes every entry, in order


@lru_cache(maxsize=None)
def bound_step(model=MODEL) -> ca.Function:
    """One step of the bound in covariance form, as a casadi Function.

    Inputs ``B (n²: the n × n bound, column-major; n = 6 for the receivers'
    motion model), dt [s], q_h, q_v [m²/s³], position (3) [m], beacon (3) [m],
    arm (3) [m], noise_variance [m²], attitude_variance [rad²],
    depth_variance [m²], slot, received (0 or 1), sigma_range [m], range_k [m/m]``
    (the range law's σ₀ and k: :func:`law_variance` added to ``noise_variance`` at the true range); output the
    bound after the
    prediction over ``dt`` with ``model.motion`` and, at a slot, the
    information of ``model``'s rows for the transmitting beacon
    (:func:`measurement_information`): the depth row, then (for a received
    packet) the range row with its effective variance, H at the true position.

    Parameters
    ----------
    model : RangeDepthModel, optional
        The measurement model (its motion model gives the state size and the prediction).

    References
    ----------
    Tichavský, Muravchik, Nehorai, IEEE Trans. Signal Processing 46(5), 1998, Eq. (21).
    """
    (B, dt, qh, qv, position), x, P = predicted(model.motion)
    beacon, arm = ca.SX.sym("beacon", 3), ca.SX.sym("arm", 3)
    noise, attitude, d_var, slot, received = (ca.SX.sym(name) for name in ("noise_variance", "attitude_variance",
                                                                          "depth_variance", "slot", "received"))
    sigma0, growth = ca.SX.sym("sigma_range"), ca.SX.sym("range_k")
    noise_at = noise + law_variance(position, beacon, sigma0, growth)  # the range law at the true range
    variances = ca.vertcat(effective_range_variance(position, beacon, arm, noise_at, attitude, model), d_var)
    # rows of the model for one beacon: 0 the range, 1 the depth; the depth is added first
    P = measurement_information(P, model, x, [beacon], variances, (ca.logic_and(slot, received), slot), rows=(1, 0))
    names = ["B", "dt", "q_h", "q_v", "position", "beacon", "arm", "noise_variance", "attitude_variance",
             "depth_variance", "slot", "received", "sigma_range", "range_k"]
    return ca.Function("sblsim_bound_step", [B, dt, qh, qv, position, beacon, arm, noise, attitude, d_var, slot,
                                             received, sigma0, growth], [ca.vec(P)], names, ["B_next"])


def packed_bound(step: ca.Function, motion, fixed_names: Sequence[str], step_names: Sequence[str],
                 inputs) -> tuple[ca.Function, ca.Function]:
    """A bound step with packed inputs, for code generation: ``sblsim_system_bound_prior(fixed) -> B0``
    (:func:`error_prior`) and ``sblsim_system_bound_step(B, fixed, step) -> (B_next, error)``, ``fixed`` and
    ``step`` in ``fixed_names`` and ``step_names`` order, ``inputs(f, s)`` the step's inputs after
    ``(B, dt, q_h, q_v)``, ``error = sqrt(trace)`` of the position block [m]."""
    n = motion.state_size
    B, f, s = ca.SX.sym("B", n * n), ca.SX.sym("fixed", len(fixed_names)), ca.SX.sym("step", len(step_names))
    named = {k: f[i] for i, k in enumerate(fixed_names)}
    B_next = step(B, named["dt"], named["q_horizontal"], named["q_vertical"], *inputs(named, s))
    index = [i * (n + 1) for i in motion.position_index]
    error = ca.sqrt(B_next[index[0]] + B_next[index[1]] + B_next[index[2]])
    return (ca.Function("sblsim_system_bound_prior", [f], [error_prior(motion, named)], ["fixed"], ["B0"]),
            ca.Function("sblsim_system_bound_step", [B, f, s], [B_next, error], ["B", "fixed", "step"],
                        ["B_next", "error"]))


#: Per-replicate inputs of the bound, in the order of :func:`pcrb`'s ``fixed`` columns (the compiled metrics pass
#: numbers them from this tuple: :mod:`sblsim.fmus.contract`).
FIXED = ("dt", "q_horizontal", "q_vertical", "p0_position", "p0_velocity", "noise_variance", "attitude_variance",
         "depth_variance", "sigma_range", "range_k")
#: The per-run inputs of the bounds that may be left out of their packing: the range law's σ₀ and k
#: (:func:`law_variance`), 0 (a constant range noise) unless given.
LAW_DEFAULTS = {"sigma_range": 0.0, "range_k": 0.0}


def pcrb_inputs(truth: np.ndarray, slot: np.ndarray, received: np.ndarray, beacons: np.ndarray, arms: np.ndarray,
                **fixed) -> tuple[np.ndarray, np.ndarray]:
    """Pack the inputs of :func:`pcrb`.

    Parameters
    ----------
    truth : ndarray, shape (N, B, 3)
        True positions at the steps t_1 … t_N [m].
    slot : ndarray of bool, shape (N, B)
        A new acoustic slot at the step (the depth is used).
    received : ndarray of bool, shape (N, B)
        The slot's packet was received (its fresh range is used).
    beacons, arms : ndarray, shape (N, B, 3)
        Position [m] and lever arm in NED [m] of the transmitting beacon (used where received).
    **fixed : float or ndarray (B,)
        Every name of :data:`FIXED`: the step between rows ``dt`` [s] (the
        prediction over it is exact for any sub-stepping: the
        white-noise-acceleration model composes), the acceleration spectral
        densities [m²/s³], the prior standard deviations at t_0 [m], [m/s],
        ``noise_variance = σ_r² + σ_GPS²`` [m²], ``attitude_variance = σ_att²``
        [rad²] and ``depth_variance = σ_d²`` [m²] (> 0); ``sigma_range`` σ₀ [m] and ``range_k`` k [m/m], the
        range law (:func:`law_variance`), may be left out (0: a constant noise).

    Returns
    -------
    fixed : ndarray, shape (B, len(FIXED))
    steps : ndarray, shape (N, B, 11)
    """
    truth = np.asarray(truth, dtype=float)
    b = truth.shape[1]
    columns = packed_fixed({**LAW_DEFAULTS, **fixed}, FIXED, b)
    steps = np.concatenate([truth, np.asarray(beacons, dtype=float), np.asarray(arms, dtype=float),
                            np.asarray(slot, dtype=float)[..., None], np.asarray(received, dtype=float)[..., None]],
                           axis=-1)
    return np.ascontiguousarray(columns), np.ascontiguousarray(steps)


def packed_fixed(fixed: dict, names: Sequence[str], b: int) -> np.ndarray:
    """The per-run inputs ``fixed`` (by name: a float or a (b,) array each) as columns in ``names``' order, (b,
    len(names)), C-contiguous."""
    return np.ascontiguousarray(np.stack([np.broadcast_to(np.asarray(fixed[k], dtype=float), (b,)) for k in names],
                                         axis=1))


def pcrb(fixed: np.ndarray, steps: np.ndarray, model=MODEL) -> np.ndarray:
    """Position PCRB along B true trajectories: ``sqrt(trace)`` of the position block of ``J_k⁻¹``.

    The reference evaluation (casadi's virtual machine); the local engine runs
    the same function compiled, in the metrics pass (``sblsim.fmus.compiled_metrics.run_metrics``).

    Parameters
    ----------
    fixed, steps : ndarray
        From :func:`pcrb_inputs`.
    model : RangeDepthModel, optional
        The measurement model of :func:`bound_step` (default the receivers'); its
        motion model gives the state size and where the position and velocity sit.

    Returns
    -------
    ndarray, shape (N, B)
        ``sqrt(B_xx + B_yy + B_zz)`` at each step [m].

    References
    ----------
    Tichavský, Muravchik, Nehorai, IEEE Trans. Signal Processing 46(5), 1998.
    """
    return stepped(bound_step(model), model.motion, FIXED, fixed, steps,
                    lambda f, s: (s[0:3], s[3:6], s[6:9], f["noise_variance"], f["attitude_variance"],
                                  f["depth_variance"], s[9:10], s[10:11], f["sigma_range"], f["range_k"]))


def stepped(step: ca.Function, motion, names: Sequence[str], fixed: np.ndarray, steps: np.ndarray,
             inputs) -> np.ndarray:
    """A bound step Function stepped along B runs (casadi's virtual machine, mapped over B): the prior
    (:func:`error_prior`), then at each row ``step(B, dt, q_h, q_v, *inputs(f, s))`` with ``f`` the fixed columns
    by name (``names``) and ``s`` the row's step columns (transposed, (columns, B)); ``sqrt(trace)`` of the
    position block at each step, (N, B) [m]."""
    n, b = steps.shape[:2]
    size = motion.state_size
    f = {k: fixed[:, i][None, :] for i, k in enumerate(names)}
    step = step.map(b)
    symbols = {k: ca.SX.sym(k) for k in names}
    prior = ca.Function("prior", list(symbols.values()), [error_prior(motion, symbols)]).map(b)
    bound = np.asarray(prior(*[f[k] for k in names]))
    out = np.empty((n, b))
    for k in range(n):
        s = steps[k].T
        bound = step(bound, f["dt"], f["q_horizontal"], f["q_vertical"], *inputs(f, s)).full()
        out[k] = np.sqrt(sum(bound[i * (size + 1)] for i in motion.position_index))
    return out


__all__ = ["bound_step", "effective_range_variance", "ERROR_NAMES", "error_prior", "error_symbols", "FIXED",
           "information_update", "LAW_DEFAULTS", "law_variance", "measurement_information", "MODEL", "MOTION",
           "packed_bound", "packed_fixed", "pcrb", "pcrb_inputs", "predicted", "state_at", "stepped"]
