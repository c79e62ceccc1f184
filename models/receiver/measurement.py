"""The measurement model of the receivers: ranges to broadcast beacons plus depth.

``h(x, b) = ‖p − b‖`` with ``p = (x[0], x[2], x[4])`` taken from the filter
state ``x = [posX, velX, posY, velY, posZ, velZ]`` and ``b`` a broadcast
beacon position; the depth reading measures ``x[4]``. The Jacobians
``H = ∂h/∂x`` and ``∂h/∂b`` are never written by hand: casadi differentiates
the expression, and the generated C evaluates it. The same model in position
coordinates, ``h(p, b)`` with ``∂h/∂p``, serves the least-squares fixes.

:class:`RangeDepthModel` gathers it as the object the Kalman-type receivers,
the accuracy bound and the accuracy maps share (as FilterPy passes ``Hx`` and
``HJacobian``, or Stone Soup a measurement model): ``h``, its Jacobian and R,
including the variance a range inherits from an uncertain beacon position.

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


@lru_cache(maxsize=1)
def beacon_range_function() -> ca.Function:
    """casadi Function ``(p[3], b[3]) -> ∂h/∂b [3]`` of one range: how a beacon position error moves it."""
    p, b = ca.SX.sym("p", 3), ca.SX.sym("b", 3)
    return ca.Function("sblsim_beacon_range", [p, b], [ca.jacobian(ca.norm_2(p - b), b).T], ["p", "b"], ["dh_db"])


class RangeDepthModel:
    """Ranges to broadcast beacons plus depth: ``z = [‖p − b_1‖, …, ‖p − b_m‖, d]``.

    Methods take casadi values (SX or MX) or numbers; beacons are (3, 1)
    vectors, one per range.
    """

    state_size = STATE_SIZE
    depth_row = (0.0, 0.0, 0.0, 0.0, 1.0, 0.0)

    @staticmethod
    def position(x):
        """The position part of a filter state, (3, 1)."""
        return ca.vertcat(*[x[i] for i in POSITION_INDEX])

    def h(self, x, beacons) -> ca.SX:
        """Predicted measurement ``[‖p − b_i‖ …, p_z]``, (m + 1, 1) [m]."""
        return ca.vertcat(*[range_function()(x, b)[0] for b in beacons], x[4])

    def jacobian(self, x, beacons) -> ca.SX:
        """``∂h/∂x``, (m + 1, 6): the casadi-derived range rows and the depth row."""
        return ca.vertcat(*[range_function()(x, b)[1].T for b in beacons], self.depth_jacobian())

    def range_row(self, x, beacon) -> tuple[ca.SX, ca.SX]:
        """One range: its prediction and its Jacobian row (1, 6)."""
        h, H = range_function()(x, beacon)
        return h, H.T

    def depth_jacobian(self) -> ca.SX:
        """``∂d/∂x``, (1, 6)."""
        return ca.horzcat(*self.depth_row)

    @staticmethod
    def beacon_variance(position, beacon, variance) -> ca.SX:
        """Variance a range inherits from an isotropic beacon-position error of ``variance`` per axis [m²]:
        ``(∂h/∂b) (variance I) (∂h/∂b)ᵀ``, the Jacobian from casadi (= variance, for a unit vector)."""
        g = beacon_range_function()(position, beacon)
        return variance * ca.dot(g, g)

    @staticmethod
    def attitude_variance(position, beacon, arm, variance) -> ca.SX:
        """Variance a range inherits from an attitude error of ``variance`` [rad²] per axis, the beacon at
        lever arm ``arm`` (3, 1) [m] from the platform reference: the beacon moves by ``δθ × arm``, so
        ``variance · ‖arm × (∂h/∂b)ᵀ‖²`` (small angles; ∂h/∂b from casadi)."""
        g = beacon_range_function()(position, beacon)
        moved = ca.cross(ca.vertcat(arm[0], arm[1], arm[2]), g)
        return variance * ca.dot(moved, moved)

    @staticmethod
    def range_variance(sigma_range, position, beacon, gps_sigma, attitude_sigma, arm) -> ca.SX:
        """Effective variance of a range from an uncertain broadcast beacon [m²].

        ``σ_r² + (∂h/∂b) Σ_b (∂h/∂b)ᵀ`` with ``Σ_b = (σ_GPS² + (σ_att · arm)²) I``:
        the GPS error of the platform and the attitude error (small angles, [rad])
        times the beacon's arm, taken isotropic per axis.
        """
        return sigma_range**2 + RangeDepthModel.beacon_variance(position, beacon,
                                                                gps_sigma**2 + (attitude_sigma * arm) ** 2)


__all__ = ["POSITION_INDEX", "RangeDepthModel", "STATE_SIZE", "beacon_range_function", "position_range_function",
           "range_function"]
