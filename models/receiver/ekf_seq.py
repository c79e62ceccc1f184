"""``ekf-seq``: a sequential EKF that uses only the fresh range of each slot, with a NIS gate.

At each slot it updates, one scalar measurement after the other, with the
depth reading and then with the **fresh range of the transmitting beacon**;
ranges held from earlier slots are never re-used (the paper's conclusion:
"an old measurement is not as effective as a new one"). The range's variance
adds the uncertainty of the broadcast beacon position, propagated through
``∂h/∂b`` by casadi (:meth:`RangeDepthModel.fresh_range_variance`): the GPS error
per axis and the attitude error times the beacon's arm, whose defaults come
from the platform's configured GPS and IMU errors. The range is predicted
from the position the constant-velocity state gives at the packet's
reference epoch (:meth:`KalmanReceiver.reference`: the packet is used when it
arrives, up to a sampling time after the reply). A χ² NIS gate (1 dof,
``gate_probability``) refuses a range that a multipath outlier lengthened;
the output ``gated`` says so. A lost packet leaves the depth update only.

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Sections 3.6 (sequential processing), 5.4 (NIS and
its gate: :mod:`sblsim.models.receiver.gate`).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.declarations import Variable
from sblsim.models.receiver import kalman
from sblsim.models.receiver.core import KalmanReceiver, beacon_parameters, filter_parameters, fresh_range, take_packet
from sblsim.models.receiver.gate import gate, gate_parameters


class SequentialReceiver(KalmanReceiver):
    """Sequential EKF: depth and the fresh range of each slot, beacon uncertainty in R, NIS gate."""

    name = "receiver_ekf_seq"
    label = "ekf-seq"
    backdate = True

    @classmethod
    def parameters(cls, n_beacons: int) -> tuple[Variable, ...]:
        return filter_parameters() + beacon_parameters() + gate_parameters(0.999)

    @classmethod
    def correct(cls, x: dict, u: dict, p: dict, n_beacons: int) -> dict:
        fresh, rng, beacon = fresh_range(x, u, n_beacons)
        m = cls.measurement
        state, P, nis_depth = kalman.scalar_update(x["x"], x["P"], u["depth"] - m.depth(x["x"]), m.depth_jacobian(),
                                                   p["sigma_depth"] ** 2)
        A = cls.reference(x, u)  # the range at the packet's reference epoch
        then = ca.mtimes(A, state)
        h, H = m.range_row(then, beacon)
        H = ca.mtimes(H, A)
        variance = m.fresh_range_variance(then, beacon, p)
        y = rng - h
        S = ca.mtimes([H, P, H.T]) + variance
        nis_range = y * y / S
        checked = gate(y, S, fresh, x, u, p)
        state, P, _ = kalman.scalar_update(state, P, y, H, variance, checked["use"])
        return {**take_packet(x, u, n_beacons), "x": state, "P": P,
                "nis": nis_depth + ca.if_else(checked["use"], nis_range, 0.0), "gated": checked["gated"],
                "failed": checked["failed"]}


__all__ = ["SequentialReceiver"]
