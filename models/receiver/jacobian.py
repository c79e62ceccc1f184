"""Range measurement model and its Jacobian, derived symbolically with casadi.

``h(x, b) = ‖p − b‖`` with ``p = (x[0], x[2], x[4])`` taken from the EKF state
``x = [posX, velX, posY, velY, posZ, velZ]`` and ``b`` a broadcast beacon
position. The Jacobian ``H = ∂h/∂x`` (1 × 6) is never written by hand: casadi
differentiates the expression, and the function is mapped over all
beacon-replicate pairs of a batch in one call.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Eqs. for the
EKF measurement model. Andersson, Gillis, Horn, Rawlings, Diehl, "CasADi: a
software framework for nonlinear optimization and optimal control",
Math. Prog. Comp. 11, 2019.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

STATE_SIZE = 6
POSITION_INDEX = [0, 2, 4]


@lru_cache(maxsize=1)
def range_function() -> ca.Function:
    """casadi Function ``(x[6], b[3]) -> (h, Hᵀ[6])`` of one range."""
    x = ca.SX.sym("x", STATE_SIZE)
    b = ca.SX.sym("b", 3)
    p = ca.vertcat(x[0], x[2], x[4])
    h = ca.norm_2(p - b)
    jac = ca.jacobian(h, x)
    return ca.Function("range_model", [x, b], [h, jac.T], ["x", "b"], ["h", "H"])


@lru_cache(maxsize=64)
def _mapped(n: int) -> ca.Function:
    return range_function().map(n, "serial")


def range_and_jacobian(states: np.ndarray, beacons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted ranges and their Jacobians for a batch of states and beacons.

    Parameters
    ----------
    states : ndarray, shape (B, 6)
        EKF states ``[posX, velX, posY, velY, posZ, velZ]`` [m, m/s].
    beacons : ndarray, shape (B, n, 3)
        Broadcast beacon positions [m].

    Returns
    -------
    h : ndarray, shape (B, n)
        Predicted ranges ``‖p − b‖`` [m].
    H : ndarray, shape (B, n, 6)
        Jacobians ``∂h/∂x`` [1, 0 for the velocity columns].
    """
    batch, n, _ = beacons.shape
    x = np.repeat(states, n, axis=0).T
    b = beacons.reshape(batch * n, 3).T
    h, jac = _mapped(batch * n)(x, b)
    return np.asarray(h).reshape(batch, n), np.asarray(jac).T.reshape(batch, n, STATE_SIZE)
