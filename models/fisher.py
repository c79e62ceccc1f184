"""The Fisher information of one measurement about the position, and the ranging systems' accuracy map.

The Fisher information of the position from one round of
fresh ranges (one per beacon) plus depth, :func:`position_information` of
:data:`~sblsim.models.bound.MODEL` with the beacons as context,
``J = Σ_i g_i g_iᵀ / σ_i² + e_z e_zᵀ / σ_d²`` with ``g_i = ∂‖p − b_i‖/∂p``
(casadi) and σ_i² the effective variance of beacon i's range, gives the
horizontal standard deviation (DRMS)
``sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` of an unbiased fix at ``p``
(:func:`horizontal_drms`; Kay, Fundamentals of Statistical Signal
Processing: Estimation Theory, Prentice Hall 1993, Section 3.7).
A system's map is its object's (:meth:`sblsim.models.systems.System.horizontal_std`).

For any measurement model: :func:`fisher_information` is ``Hᵀ R⁻¹ H = Σ_k H_kᵀ H_k / r_k`` with H from
``model.jacobian`` (casadi's derivative of h), at the state :func:`~sblsim.models.bound.state_at` of a position; a
model with another context (a USBL transceiver's position,
:class:`~sblsim.models.receiver.range_direction.RangeDirectionModel`) goes through the same functions
(:func:`model_horizontal_std`).

References
----------
Kay, Fundamentals of Statistical Signal Processing: Estimation Theory, Prentice Hall 1993, Section 3.7.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from sblsim.models.bound import MODEL, effective_range_variance, state_at


def fisher_information(model, x, context, variances, weights=None) -> ca.SX:
    """Fisher information of one measurement of a model about the state: ``Σ_k H_kᵀ H_k / r_k = Hᵀ R⁻¹ H``.

    For ``z = h(x) + v``, ``v ~ N(0, R)`` with R diagonal, the information
    is ``Hᵀ R⁻¹ H`` with ``H = ∂h/∂x`` (Kay 1993, Section 3.7, the vector
    parameter, for a Gaussian whose covariance does not depend on x; the
    information of the linearized model); H is ``model.jacobian`` (casadi's
    derivative of h), the rows added in order. With ``weights`` each row's term
    is multiplied by its weight ``q_k``, the probability that the row is measured
    at all: the expected information of a measurement that is received with
    probability q_k (Niu, Willett, Bar-Shalom, "Matrix CRLB scaling due to
    measurements of uncertain origin", IEEE Trans. Signal Processing 49(7), 2001:
    the information reduction factor of a detection probability without clutter).

    Parameters
    ----------
    model : MeasurementModel
        The measurement model (:mod:`sblsim.models.receiver.measurement`); its
        motion model sets n.
    x : casadi.SX or array, (n, 1)
        The state at which H is taken (:func:`state_at` for a position).
    context
        What ``model.h`` needs besides the state (beacon positions, a transceiver position, ...).
    variances : casadi.SX or array, (m, 1)
        The diagonal of R [units of z squared]: ``model.variances(x, context, p)``
        or effective variances; all > 0.
    weights : casadi.SX or array, (m, 1), optional
        Per row, the probability that it is measured [0–1] (default: every row, unweighted).

    Returns
    -------
    casadi.SX, (n, n)
        The information matrix [1/units of x squared]; with numbers in,
        ``casadi.evalf`` gives its value.

    References
    ----------
    Kay, Fundamentals of Statistical Signal Processing: Estimation Theory,
    Prentice Hall 1993, Section 3.7. Niu, Willett, Bar-Shalom, IEEE Trans. Signal
    Processing 49(7), 2001.
    """
    H = model.jacobian(x, context)
    n = model.motion.state_size
    J = ca.SX.zeros(n, n)
    for k in range(H.shape[0]):
        term = ca.mtimes(H[k, :].T, H[k, :]) / variances[k]
        J += term if weights is None else weights[k] * term
    return J


def position_information(model, position, context, variances, weights=None) -> ca.SX:
    """Fisher information about the position, (3, 3) [1/m²]: the position block of :func:`fisher_information` at
    the state :func:`state_at` ``(model.motion, position)`` (the models read only the position, so the other
    entries do not enter).

    Parameters
    ----------
    model : MeasurementModel
    position : casadi.SX or array, (3, 1)
        North, East, Down [m].
    context, variances, weights
        As for :func:`fisher_information`.

    References
    ----------
    Kay 1993, Section 3.7.
    """
    index = list(model.motion.position_index)
    J = fisher_information(model, state_at(model.motion, position), context, variances, weights)
    return J[index, index]


def horizontal_drms(J):
    """Horizontal standard deviation (DRMS) of an unbiased fix with position information ``J`` (3, 3) [1/m²]:
    ``sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` [m] (Kay 1993, Section 3.7: ``cov ≥ J⁻¹``)."""
    inverse = ca.inv(J)
    return ca.sqrt(inverse[0, 0] + inverse[1, 1])


@lru_cache(maxsize=None)
def fix_information(n_beacons: int, model=MODEL) -> ca.Function:
    """casadi Function of the Fisher information of one round of fresh ranges plus depth.

    ``(p[3], beacons[3 n], arms[3 n], noise_variance, attitude_variance, depth_variance) -> (J (3, 3), drms)``,
    ``drms = sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` [m]: :func:`position_information` of
    ``model`` with the beacons as context and the variances
    ``[σ_1², …, σ_n², σ_d²]``, σ_i² the effective variance of beacon i's range
    (:func:`effective_range_variance`).

    Parameters
    ----------
    n_beacons : int
    model : RangeDepthModel, optional
        The measurement model (default the receivers').
    """
    p, b, a = ca.SX.sym("p", 3), ca.SX.sym("beacons", 3 * n_beacons), ca.SX.sym("arms", 3 * n_beacons)
    noise, attitude, d_var = ca.SX.sym("noise_variance"), ca.SX.sym("attitude_variance"), ca.SX.sym("depth_variance")
    beacons = [b[3 * i:3 * i + 3] for i in range(n_beacons)]
    variances = ca.vertcat(*[effective_range_variance(p, beacon, a[3 * i:3 * i + 3], noise, attitude, model)
                             for i, beacon in enumerate(beacons)], d_var)
    J = position_information(model, p, beacons, variances)
    return ca.Function(f"sblsim_fix_information_{n_beacons}", [p, b, a, noise, attitude, d_var],
                       [J, horizontal_drms(J)],
                       ["p", "beacons", "arms", "noise_variance", "attitude_variance", "depth_variance"],
                       ["J", "drms"])


def per_point(value: Any) -> Any:
    """A number of a mapped accuracy function: a float, or an array of one per point as a (1, M) row (the
    columns of a ``casadi.Function.map``)."""
    array = np.asarray(value, dtype=float)
    return float(array) if array.ndim == 0 else array.reshape(1, -1)


def horizontal_std(points: np.ndarray, beacons: np.ndarray, arms: np.ndarray, noise_variance: float,
                   attitude_variance: float, depth_variance: float, model=MODEL) -> np.ndarray:
    """Horizontal standard deviation (DRMS) of a fix from one round of fresh ranges plus depth.

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        Target positions [m].
    beacons, arms : ndarray, shape (n, 3)
        Beacon positions and their lever arms in NED [m].
    noise_variance : float or ndarray, shape (M,)
        ``σ_r² + σ_GPS²`` [m²] (an array: one per point).
    attitude_variance : float or ndarray, shape (M,)
        σ_att² [rad²].
    depth_variance : float or ndarray, shape (M,)
        σ_d² [m²], > 0.
    model : RangeDepthModel, optional
        The measurement model (:func:`fix_information`).

    Returns
    -------
    ndarray, shape (M,)
        ``sqrt((J⁻¹)_NN + (J⁻¹)_EE)`` [m]; infinite where J is singular (a
        point on a beacon).
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    beacons, arms = np.asarray(beacons, dtype=float), np.asarray(arms, dtype=float)
    f = fix_information(beacons.shape[0], model).map(points.shape[0])
    drms = np.asarray(f(points.T, beacons.reshape(-1, 1), arms.reshape(-1, 1), per_point(noise_variance),
                        per_point(attitude_variance), per_point(depth_variance))[1]).ravel()
    return np.where(np.isfinite(drms), drms, np.inf)


def model_horizontal_std(model, points: np.ndarray, context, variances) -> np.ndarray:
    """Horizontal DRMS [m] of a fix from one measurement of any model with a fixed context (an accuracy map).

    :func:`horizontal_drms` of :func:`position_information` at each point, the
    model's Jacobian from casadi. For the range + direction model
    (:class:`~sblsim.models.receiver.range_direction.RangeDirectionModel`) the
    context is the transceiver's position and attitude and ``variances`` ``[σ_r², σ_u², σ_u²]`` (the array's
    noise alone: the USBL map, :func:`sblsim.models.systems.usbl_map.fix_information`, takes its full R).

    Parameters
    ----------
    model : MeasurementModel
    points : ndarray, shape (M, 3)
        Target positions, NED [m].
    context
        The model's context, numbers (beacon positions, a transceiver position, ...).
    variances : array, (m,)
        The diagonal of R [units of z squared], > 0.

    Returns
    -------
    ndarray, shape (M,)
        Infinite where the information is singular.

    References
    ----------
    Kay 1993, Section 3.7.
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    p = ca.SX.sym("p", 3)
    J = position_information(model, p, context, ca.DM(np.asarray(variances, dtype=float).reshape(-1, 1)))
    f = ca.Function("sblsim_model_fix", [p], [horizontal_drms(J)]).map(points.shape[0])
    drms = np.asarray(f(points.T)).ravel()
    return np.where(np.isfinite(drms), drms, np.inf)


__all__ = ["fisher_information", "fix_information", "horizontal_drms", "horizontal_std", "model_horizontal_std",
           "per_point", "position_information"]
