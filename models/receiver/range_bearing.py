"""Range and bearing from a transceiver (USBL): slant range, azimuth and elevation of the diver.

For a transceiver at ``b`` (3, 1) [m] and the diver at ``p``, both NED (z
down), with ``d = p − b = (d_N, d_E, d_D)``:

* slant range ``r = ‖d‖`` [m];
* azimuth ``α = atan2(d_E, d_N)`` [rad], clockwise from North seen from
  above (0 North, π/2 East), in (−π, π];
* elevation ``ε = atan2(d_D, sqrt(d_N² + d_E²))`` [rad], the angle of the
  line of sight **below** the horizontal plane (positive: the diver is deeper
  than the transceiver; NED's z points down), in [−π/2, π/2].

``z = [r, α, ε]`` with independent noises ``R = diag(σ_r², σ_α², σ_ε²)``
from the parameters ``sigma_range`` [m], ``sigma_azimuth`` and
``sigma_elevation`` [rad]. The residual wraps the angle rows to (−π, π], so
a diver due South (α near ±π) is not seen 2π away. The Jacobian comes from
casadi; it is singular straight above or below the transceiver
(``d_N = d_E = 0``: the azimuth is undefined there, the derivatives not finite)
and at the transceiver itself. With ``floor = ρ_min > 0`` the derivatives are
taken at the point pushed out to ρ_min from the vertical (:func:`off_axis_point`),
finite there.

**The transceiver's uncertainty.** The packet is measured from the true
transceiver and predicted from the broadcast one: an error δb moves z by
``H_b δb``, ``H_b = ∂h/∂b`` (casadi, :meth:`RangeBearingModel.transceiver_jacobian`),
and R gains ``H_b Σ_b H_bᵀ`` (:meth:`RangeBearingModel.transceiver_covariance`),
``σ_b² [1, 1 / ρ², 1 / r²]`` on the diagonal for an isotropic ``Σ_b = σ_b² I``
(:meth:`RangeBearingModel.transceiver_variances`; the rows of ``H_b`` are
orthogonal), as a range's variance inherits a beacon's
(:meth:`sblsim.models.receiver.measurement.RangeDepthModel.range_variance`).

This module is the worked example of ``docs/measurement-models.md``: a
measurement model is one file, its test and its documentation.

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Section 10.3 (EKF with polar measurements). Vickery,
"Acoustic positioning systems. A practical overview of current systems",
Proc. IEEE AUV 1998 (USBL range and bearing).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca

from sblsim.models.receiver.measurement import MeasurementModel
from sblsim.models.receiver.motion import CONSTANT_VELOCITY


def _range_bearing(d: ca.SX) -> ca.SX:
    """``[r, α, ε]`` (3, 1) of the diver at ``d = p − b`` (3, 1) [m] from the transceiver."""
    return ca.vertcat(ca.norm_2(d), ca.atan2(d[1], d[0]), ca.atan2(d[2], ca.sqrt(d[0] ** 2 + d[1] ** 2)))


def off_axis_point(d, floor: float):
    """``d`` (3, 1) [m] with its horizontal part pushed out to at least ``floor`` [m] from the vertical axis: ``d``
    itself where ``ρ = sqrt(d_N² + d_E²) ≥ floor``, else the point at ``ρ = floor`` in the same azimuth (North at
    ``ρ = 0``, where ``atan2(0, 0) = 0``); the depth unchanged. Where the model's derivatives are taken
    (:func:`range_bearing_function`)."""
    rho = ca.sqrt(d[0] ** 2 + d[1] ** 2)
    k = ca.fmax(floor / ca.fmax(rho, 1e-300), 1.0)  # 1 off the floor; no 0 / 0 at ρ = 0
    north, east = d[0] * k, d[1] * k
    north = north + ca.fmax(floor - ca.sqrt(north ** 2 + east ** 2), 0.0)  # ρ = 0: to the North
    return ca.vertcat(north, east, d[2])


@lru_cache(maxsize=None)
def range_bearing_function(size: int, position_index: tuple[int, ...], floor: float = 0.0) -> ca.Function:
    """casadi Function ``(x[size], b[3]) -> (h [3], H [3, size], H_b [3, 3])`` of range, azimuth and elevation:
    ``h`` at ``d = p(x) − b``, ``H = ∂h/∂x`` and ``H_b = ∂h/∂b`` (casadi's derivatives) at ``d``, or, with
    ``floor`` > 0 [m], at :func:`off_axis_point` ``(d, floor)`` (finite straight above or below the
    transceiver; the same where ``ρ ≥ floor``)."""
    x, b = ca.SX.sym("x", size), ca.SX.sym("b", 3)
    d = ca.vertcat(*[x[i] for i in position_index]) - b
    h = _range_bearing(d)
    if floor <= 0.0:
        H, H_b = ca.jacobian(h, x), ca.jacobian(h, b)
    else:
        s = ca.SX.sym("d", 3)
        derivative = ca.Function("sblsim_range_bearing_derivative", [s], [ca.jacobian(_range_bearing(s), s)])
        H_d = derivative(off_axis_point(d, floor))  # ∂h/∂d; d = p(x) − b
        H = ca.SX.zeros(3, size)
        for k, i in enumerate(position_index):
            H[:, i] = H_d[:, k]
        H_b = -H_d
    return ca.Function("sblsim_range_bearing", [x, b], [h, H, H_b], ["x", "b"], ["h", "H", "H_b"])


class RangeBearingModel(MeasurementModel):
    """Slant range [m], azimuth and elevation [rad] of the diver from a transceiver; the context is its position.

    Parameters
    ----------
    motion : ConstantVelocity, optional
        The state layout (default: the receivers').
    floor : float, optional
        ρ_min [m], ≥ 0: the derivatives (:meth:`linearize`, :meth:`transceiver_jacobian`) are taken at least ρ_min
        from the vertical axis through the transceiver (:func:`off_axis_point`), so that they are finite straight
        above or below it; 0 (default): the exact derivatives, not finite there.

    Raises
    ------
    ValueError
        If the motion model's position is not three entries (North, East, Down), or ``floor`` is negative.
    """

    angles = (1, 2)

    def __init__(self, motion=CONSTANT_VELOCITY, floor: float = 0.0) -> None:
        if len(motion.position_index) != 3:
            raise ValueError(f"RangeBearingModel: the position must be 3 entries, got {motion.position_index}")
        if not floor >= 0.0:
            raise ValueError(f"RangeBearingModel: floor must be ≥ 0 m, got {floor!r}")
        super().__init__(motion)
        self.floor = float(floor)

    def _function(self) -> ca.Function:
        return range_bearing_function(self.motion.state_size, tuple(self.motion.position_index), self.floor)

    def dimension(self, context) -> int:
        """3: range, azimuth, elevation."""
        return 3

    def h(self, x, transceiver) -> ca.SX:
        """``[r [m], α [rad], ε [rad]]``, (3, 1), of the state ``x`` (n, 1) seen from ``transceiver`` (3, 1) [m]."""
        return self._function()(x, transceiver)[0]

    def linearize(self, x, transceiver) -> tuple[ca.SX, ca.SX]:
        """``h`` (3, 1) and ``∂h/∂x`` (3, n) from one call of the casadi Function."""
        h, H, _ = self._function()(x, transceiver)
        return h, H

    def variances(self, x, transceiver, p: dict) -> ca.SX:
        """``[σ_r², σ_α², σ_ε²]``, (3, 1) [m², rad², rad²], from the parameters ``sigma_range`` [m],
        ``sigma_azimuth`` and ``sigma_elevation`` [rad]."""
        return ca.vertcat(p["sigma_range"] ** 2, p["sigma_azimuth"] ** 2, p["sigma_elevation"] ** 2)

    def transceiver_jacobian(self, x, transceiver) -> ca.SX:
        """``H_b = ∂h/∂b`` (3, 3): how an error in the transceiver's position moves ``[r, α, ε]`` (casadi; at
        least :attr:`floor` off the vertical axis). Its rows are ``−u_r``, ``−u_α / ρ`` and ``−u_ε / r``, the
        unit vectors of the range, the azimuth (horizontal, across) and the elevation (up the vertical plane)
        over the distances that turn a displacement into an angle: orthogonal."""
        return self._function()(x, transceiver)[2]

    def transceiver_covariance(self, x, transceiver, covariance) -> ca.SX:
        """``H_b Σ_b H_bᵀ`` (3, 3) [m², m rad, rad²]: what an error of covariance ``Σ_b`` (3, 3) [m²] in the
        transceiver's position (GPS, lever arm) adds to R, to first order (the packet's measurement is ``h(p − b)``
        with the true ``b``, the receiver's prediction uses the one broadcast)."""
        H_b = self.transceiver_jacobian(x, transceiver)
        return ca.mtimes([H_b, ca.SX(covariance), H_b.T])

    def transceiver_variances(self, x, transceiver, variance) -> ca.SX:
        """The same for an isotropic ``Σ_b = σ_b² I`` [m²], whose ``H_b Σ_b H_bᵀ`` is diagonal (the rows of
        ``H_b`` are orthogonal, :meth:`transceiver_jacobian`): ``σ_b² [1, 1 / ρ², 1 / r²]`` (3, 1) [m², rad², rad²],
        ρ the horizontal distance (at least :attr:`floor`) and r the slant range; the squared row norms, from
        casadi's ``H_b``."""
        H_b = self.transceiver_jacobian(x, transceiver)
        return variance * ca.sum2(H_b * H_b)


__all__ = ["RangeBearingModel", "off_axis_point", "range_bearing_function"]
