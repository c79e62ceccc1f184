"""Range measurement model and its Jacobian, derived symbolically with casadi.

``h(x, b) = ‖p − b‖`` with ``p = (x[0], x[2], x[4])`` taken from the filter
state ``x = [posX, velX, posY, velY, posZ, velZ]`` and ``b`` a broadcast
beacon position. The Jacobian ``H = ∂h/∂x`` (1 × 6) is never written by
hand: casadi differentiates the expression, and the generated C evaluates
it. The same model in position coordinates, ``h(p, b)`` with ``∂h/∂p``,
serves the least-squares fixes.

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

STATE_SIZE = 6
POSITION_INDEX = (0, 2, 4)


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


__all__ = ["POSITION_INDEX", "STATE_SIZE", "position_range_function", "range_function"]
