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
arrives, up to a sampling time after the reply): a one-way range at its
reception, a two-way range at the mean of its legs. The state carries the
error states of :class:`~sblsim.models.receiver.motion.WithErrorStates`
(the GPS error as a Gauss-Markov process, the clock's offset and drift,
USBL's constant attitude error), each inert unless its parameter asks for it
(:func:`~sblsim.models.receiver.interface.error_parameters`). A χ² NIS gate (1 dof,
``gate_probability``) refuses a range that a multipath outlier lengthened;
the output ``gated`` says so, and a range that fails after a run of failures
is used again only if it agrees with its beacon's previous one
(:func:`~sblsim.models.receiver.gate.gate`). A lost packet leaves the depth
update only.

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
from sblsim.models.receiver.core import KalmanReceiver
from sblsim.models.receiver.gate import gate, gate_parameters
from sblsim.models.receiver.interface import beacon_parameters, filter_parameters
from sblsim.models.receiver.measurement import RangeDepthModel
from sblsim.models.receiver.motion import WITH_ERROR_STATES
from sblsim.models.receiver.packets import fresh_range, take_packet
from sblsim.models.receiver.pings import depth_fresh, reanchored
from sblsim.models.receiver.ranging import clock_scale, toa_ranging
from sblsim.models.receiver.reacquisition import earlier_innovation, remember_rejected


class SequentialReceiver(KalmanReceiver):
    """Sequential EKF: depth and the fresh range of each slot, beacon uncertainty in R, error states, NIS gate."""

    name = "receiver_ekf_seq"
    label = "ekf-seq"
    backdate = True
    motion = WITH_ERROR_STATES
    measurement = RangeDepthModel(WITH_ERROR_STATES)

    @classmethod
    def parameters(cls, n_beacons: int) -> tuple[Variable, ...]:
        return filter_parameters() + beacon_parameters() + gate_parameters(0.999)

    @classmethod
    def correct(cls, x: dict, u: dict, p: dict, n_beacons: int) -> dict:
        fresh, rng, beacon = fresh_range(x, u, n_beacons)
        m = cls.measurement
        depth = depth_fresh(x, u, p)  # an inverted LBL's burst of pings uses a depth reading once
        state, P, nis_depth = kalman.scalar_update(x["x"], x["P"], u["depth"] - m.depth(x["x"]), m.depth_jacobian(),
                                                   p["sigma_depth"] ** 2, depth)
        nis_depth = ca.if_else(depth, nis_depth, 0.0)
        epoch = cls.epoch(u, p, x)
        clock = clock_scale(p)

        def row(then, beacon):  # a range at the state ``then``: prediction, Jacobian row, variance
            return (*m.range_row(then, beacon, clock), m.fresh_range_variance(then, beacon, p))

        A = cls.reference(x, u, epoch)  # the range at the packet's reference epoch
        h, H, variance = row(ca.mtimes(A, state), beacon)
        H = ca.mtimes(H, A)
        y = rng - h
        S = ca.mtimes([H, P, H.T]) + variance
        nis_range = y * y / S
        toa = toa_ranging(p)
        checked = gate(y, S, fresh, x, u, p, earlier_innovation(cls, x, u, state, P, row, n_beacons, toa))
        # an inverted LBL's arrival far earlier than the ping's earlier ones said: they came late, re-anchor the epoch
        state, short = reanchored(cls.motion, state, p, fresh, y, H, S)
        use = ca.logic_and(checked["use"], ca.logic_not(short))
        state, P, _ = kalman.scalar_update(state, P, y, H, variance, use)
        return {**take_packet(x, u, n_beacons), "x": state, "P": P,
                "nis": nis_depth + ca.if_else(use, nis_range, 0.0), "gated": checked["gated"],
                "failed": checked["failed"],
                **remember_rejected(x, u, checked["rejecting"], ca.if_else(toa, y, rng), beacon, epoch, n_beacons)}


__all__ = ["SequentialReceiver"]
