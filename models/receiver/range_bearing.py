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
and at the transceiver itself.

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


@lru_cache(maxsize=None)
def range_bearing_function(size: int, position_index: tuple[int, ...]) -> ca.Function:
    """casadi Function ``(x[size], b[3]) -> (h [3], H [3, size])`` of range, azimuth and elevation."""
    x, b = ca.SX.sym("x", size), ca.SX.sym("b", 3)
    d = ca.vertcat(*[x[i] for i in position_index]) - b
    h = ca.vertcat(ca.norm_2(d), ca.atan2(d[1], d[0]), ca.atan2(d[2], ca.sqrt(d[0] ** 2 + d[1] ** 2)))
    return ca.Function("sblsim_range_bearing", [x, b], [h, ca.jacobian(h, x)], ["x", "b"], ["h", "H"])


class RangeBearingModel(MeasurementModel):
    """Slant range [m], azimuth and elevation [rad] of the diver from a transceiver; the context is its position.

    Parameters
    ----------
    motion : ConstantVelocity, optional
        The state layout (default: the receivers').

    Raises
    ------
    ValueError
        If the motion model's position is not three entries (North, East, Down).
    """

    angles = (1, 2)

    def __init__(self, motion=CONSTANT_VELOCITY) -> None:
        if len(motion.position_index) != 3:
            raise ValueError(f"RangeBearingModel: the position must be 3 entries, got {motion.position_index}")
        super().__init__(motion)

    def _function(self) -> ca.Function:
        return range_bearing_function(self.motion.state_size, tuple(self.motion.position_index))

    def dimension(self, context) -> int:
        """3: range, azimuth, elevation."""
        return 3

    def h(self, x, transceiver) -> ca.SX:
        """``[r [m], α [rad], ε [rad]]``, (3, 1), of the state ``x`` (n, 1) seen from ``transceiver`` (3, 1) [m]."""
        return self._function()(x, transceiver)[0]

    def linearize(self, x, transceiver) -> tuple[ca.SX, ca.SX]:
        """``h`` (3, 1) and ``∂h/∂x`` (3, n) from one call of the casadi Function."""
        h, H = self._function()(x, transceiver)
        return h, H

    def variances(self, x, transceiver, p: dict) -> ca.SX:
        """``[σ_r², σ_α², σ_ε²]``, (3, 1) [m², rad², rad²], from the parameters ``sigma_range`` [m],
        ``sigma_azimuth`` and ``sigma_elevation`` [rad]."""
        return ca.vertcat(p["sigma_range"] ** 2, p["sigma_azimuth"] ** 2, p["sigma_elevation"] ** 2)


__all__ = ["RangeBearingModel", "range_bearing_function"]
