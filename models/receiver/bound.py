"""The accuracy limit: the posterior Cramér-Rao bound (PCRB) along a trajectory, and the
Fisher information of one round of fresh ranges plus depth (the accuracy maps).

**PCRB.** For the receivers' motion model, a constant velocity driven by
white-noise acceleration (``x_k+1 = Φ x_k + w_k``, ``w_k ~ N(0, Q(Δt))`` with
densities q_h, q_v, :mod:`sblsim.models.receiver.kalman`), and measurements
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

The measurement model is the fresh-range-plus-depth model of ``ekf-seq``
(:class:`~sblsim.models.receiver.measurement.RangeDepthModel`): at every slot the
depth (variance σ_d²), and the fresh range of a received packet with its
effective variance (:func:`effective_range_variance`)
``σ_r² + σ_GPS² ‖∂h/∂b‖² + σ_att² ‖a × ∂h/∂b‖²``, a the transmitting beacon's
lever arm in NED, the derivatives from casadi. Error sources that are not
white noise (a sound-speed mismatch, clock drift, a Gauss-Markov GPS error,
multipath outliers, platform motion between a sample and a transmission,
the staleness of held ranges) are not in the bound.

**Accuracy map.** The Fisher information of the position from one round of
fresh ranges (one per beacon) plus depth,
``J = Σ_i g_i g_iᵀ / σ_i² + e_z e_zᵀ / σ_d²`` with ``g_i = ∂‖p − b_i‖/∂p``
(casadi) and σ_i² the effective variance of beacon i's range, gives the
horizontal standard deviation (DRMS)
``sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` of an unbiased fix at ``p``
(Kay, Fundamentals of Statistical Signal Processing: Estimation Theory,
Prentice Hall 1993, Section 3.7).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.receiver import kalman
from sblsim.models.receiver.measurement import STATE_SIZE, RangeDepthModel, position_range_function

MODEL = RangeDepthModel()


def effective_range_variance(position, beacon, arm, noise_variance, attitude_variance):
    """Variance of a fresh range from a beacon whose position is broadcast with GPS and attitude errors [m²].

    ``noise_variance`` is ``σ_r² + σ_GPS²`` (an isotropic GPS error adds σ_GPS²
    whatever the direction), ``attitude_variance`` σ_att² [rad²] per axis, ``arm``
    (3) the beacon's lever arm in NED [m].
    """
    return noise_variance + MODEL.attitude_variance(position, beacon, arm, attitude_variance)


def information_update(P: ca.SX, H: ca.SX, variance, use) -> ca.SX:
    """``(P⁻¹ + Hᵀ H / variance)⁻¹ = P − g gᵀ / (H g + variance)``, ``g = P Hᵀ``, for a scalar measurement
    (where ``use`` is 0, P unchanged): the bound's information added, in covariance form (its upper triangle
    computed, mirrored; no gain is applied to an estimate, so the Joseph form's robustness is not needed)."""
    g = ca.mtimes(P, H.T)
    return ca.if_else(use > 0.5, kalman.symmetric(P - ca.mtimes(g, g.T) / (ca.mtimes(H, g) + variance)), P)


@lru_cache(maxsize=1)
def bound_step() -> ca.Function:
    """One step of the bound in covariance form, as a casadi Function.

    Inputs ``B (36: the 6 × 6 bound, column-major), dt [s], q_h, q_v [m²/s³],
    position (3) [m], beacon (3) [m], arm (3) [m], noise_variance [m²],
    attitude_variance [rad²], depth_variance [m²], slot, received (0 or 1)``;
    output the bound after the prediction over ``dt`` and, at a slot, the depth
    update and (for a received packet) the range update with H at the true
    position.
    """
    B = ca.SX.sym("B", STATE_SIZE * STATE_SIZE)
    dt, qh, qv = ca.SX.sym("dt"), ca.SX.sym("q_h"), ca.SX.sym("q_v")
    position, beacon, arm = ca.SX.sym("position", 3), ca.SX.sym("beacon", 3), ca.SX.sym("arm", 3)
    noise, attitude, d_var, slot, received = (ca.SX.sym(n) for n in ("noise_variance", "attitude_variance",
                                                                       "depth_variance", "slot", "received"))
    x = ca.SX.zeros(STATE_SIZE)
    for k, i in enumerate((0, 2, 4)):
        x[i] = position[k]
    _, P = kalman.predict(x, ca.reshape(B, STATE_SIZE, STATE_SIZE), dt, qh, qv)
    P = information_update(P, MODEL.depth_jacobian(), d_var, slot)
    _, H = MODEL.range_row(x, beacon)
    r_var = effective_range_variance(position, beacon, arm, noise, attitude)
    P = information_update(P, H, r_var, ca.logic_and(slot, received))
    names = ["B", "dt", "q_h", "q_v", "position", "beacon", "arm", "noise_variance", "attitude_variance",
             "depth_variance", "slot", "received"]
    return ca.Function("sblsim_bound_step", [B, dt, qh, qv, position, beacon, arm, noise, attitude, d_var, slot,
                                             received], [ca.vec(P)], names, ["B_next"])


#: Per-replicate inputs of the bound, in the order of :func:`pcrb`'s ``fixed`` columns (the compiled metrics pass
#: numbers them from this tuple: :mod:`sblsim.fmus.contract`).
FIXED = ("dt", "q_horizontal", "q_vertical", "p0_position", "p0_velocity", "noise_variance", "attitude_variance",
         "depth_variance")


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
        [rad²] and ``depth_variance = σ_d²`` [m²] (> 0).

    Returns
    -------
    fixed : ndarray, shape (B, 8)
    steps : ndarray, shape (N, B, 11)
    """
    truth = np.asarray(truth, dtype=float)
    b = truth.shape[1]
    columns = np.stack([np.broadcast_to(np.asarray(fixed[k], dtype=float), (b,)) for k in FIXED], axis=1)
    steps = np.concatenate([truth, np.asarray(beacons, dtype=float), np.asarray(arms, dtype=float),
                            np.asarray(slot, dtype=float)[..., None], np.asarray(received, dtype=float)[..., None]],
                           axis=-1)
    return np.ascontiguousarray(columns), np.ascontiguousarray(steps)


def pcrb(fixed: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Position PCRB along B true trajectories: ``sqrt(trace)`` of the position block of ``J_k⁻¹``.

    The reference evaluation (casadi's virtual machine); the local engine runs
    the same function compiled, in the metrics pass (``sblsim.fmus.native.run_metrics``).

    Parameters
    ----------
    fixed, steps : ndarray
        From :func:`pcrb_inputs`.

    Returns
    -------
    ndarray, shape (N, B)
        ``sqrt(B_xx + B_yy + B_zz)`` at each step [m].

    References
    ----------
    Tichavský, Muravchik, Nehorai, IEEE Trans. Signal Processing 46(5), 1998.
    """
    n, b = steps.shape[:2]
    f = {k: fixed[:, i][None, :] for i, k in enumerate(FIXED)}
    step = bound_step().map(b)
    bound = np.zeros((STATE_SIZE * STATE_SIZE, b))
    bound[np.arange(STATE_SIZE) * (STATE_SIZE + 1)] = np.concatenate([f["p0_position"] ** 2,
                                                                      f["p0_velocity"] ** 2] * 3)
    out = np.empty((n, b))
    for k in range(n):
        s = steps[k].T
        bound = step(bound, f["dt"], f["q_horizontal"], f["q_vertical"], s[0:3], s[3:6], s[6:9], f["noise_variance"],
                     f["attitude_variance"], f["depth_variance"], s[9:10], s[10:11]).full()
        out[k] = np.sqrt(bound[0] + bound[2 * STATE_SIZE + 2] + bound[4 * STATE_SIZE + 4])
    return out


@lru_cache(maxsize=None)
def fix_information(n_beacons: int) -> ca.Function:
    """casadi Function of the Fisher information of one round of fresh ranges plus depth.

    ``(p[3], beacons[3 n], arms[3 n], noise_variance, attitude_variance, depth_variance) -> (J (3, 3), drms)``,
    ``drms = sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` [m].
    """
    p, b, a = ca.SX.sym("p", 3), ca.SX.sym("beacons", 3 * n_beacons), ca.SX.sym("arms", 3 * n_beacons)
    noise, attitude, d_var = ca.SX.sym("noise_variance"), ca.SX.sym("attitude_variance"), ca.SX.sym("depth_variance")
    J = ca.SX.zeros(3, 3)
    for i in range(n_beacons):
        beacon = b[3 * i:3 * i + 3]
        g = position_range_function()(p, beacon)[1]
        J += ca.mtimes(g, g.T) / effective_range_variance(p, beacon, a[3 * i:3 * i + 3], noise, attitude)
    J[2, 2] += 1.0 / d_var
    inverse = ca.inv(J)
    return ca.Function(f"sblsim_fix_information_{n_beacons}", [p, b, a, noise, attitude, d_var],
                       [J, ca.sqrt(inverse[0, 0] + inverse[1, 1])],
                       ["p", "beacons", "arms", "noise_variance", "attitude_variance", "depth_variance"],
                       ["J", "drms"])


def horizontal_std(points: np.ndarray, beacons: np.ndarray, arms: np.ndarray, noise_variance: float,
                   attitude_variance: float, depth_variance: float) -> np.ndarray:
    """Horizontal standard deviation (DRMS) of a fix from one round of fresh ranges plus depth.

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        Target positions [m].
    beacons, arms : ndarray, shape (n, 3)
        Beacon positions and their lever arms in NED [m].
    noise_variance : float
        ``σ_r² + σ_GPS²`` [m²].
    attitude_variance : float
        σ_att² [rad²].
    depth_variance : float
        σ_d² [m²], > 0.

    Returns
    -------
    ndarray, shape (M,)
        ``sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` [m]; infinite where J is singular (a
        point on a beacon).
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    beacons, arms = np.asarray(beacons, dtype=float), np.asarray(arms, dtype=float)
    f = fix_information(beacons.shape[0]).map(points.shape[0])
    drms = np.asarray(f(points.T, beacons.reshape(-1, 1), arms.reshape(-1, 1), float(noise_variance),
                        float(attitude_variance), float(depth_variance))[1]).ravel()
    return np.where(np.isfinite(drms), drms, np.inf)


__all__ = ["FIXED", "bound_step", "effective_range_variance", "fix_information", "horizontal_std",
           "information_update", "pcrb", "pcrb_inputs"]
