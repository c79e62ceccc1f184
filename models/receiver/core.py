"""Receiver cores fed by round-robin OWTT packets and depth; the paper's EKF receiver.

:class:`PacketReceiverCore` is the packet handling every built-in receiver
shares. The receiver runs at its own communication step Δt = T / (EKF rate
ratio): every step it calls :meth:`~PacketReceiverCore._predict`; when a new
packet whose transmit epoch it has reached arrives (``packet_seq`` changed and
``t + Δt ≥ tx_time``), it stores the range and broadcast beacon position of
that beacon (if the packet was not lost) and calls
:meth:`~PacketReceiverCore._update` with the latest range of every beacon
heard so far plus the depth reading. Held ranges are re-used at later slots:
their staleness is part of the error, as in the paper.

:class:`ReceiverCore` is the paper's EKF: one update per slot, and the raw
instrumentation fix (multilateration of the same held ranges and depth, no
filter) computed at the same instants.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from models.acoustics.core import PACKET
from models.core import ComponentCore, Variable
from models.receiver.ekf import ExtendedKalmanFilter
from models.receiver.multilateration import multilaterate

STATE_NAMES = ("x", "vx", "y", "vy", "z", "vz")
_AXES = {"x": "North", "y": "East", "z": "Down"}


def receiver_interface() -> tuple[Variable, ...]:
    """Inputs and outputs every receiver shares (EKF, least squares, a user's FMU)."""
    inputs = tuple(replace(v, causality="input") for v in PACKET) + (
        Variable("depth", "input", "Real", 0.0, "m", "Depth-sensor reading"),
    )
    outputs = tuple(
        Variable(f"est_{n}", "output", "Real", 0.0, "m" if n[0] != "v" else "m/s",
                 f"Estimated {'position' if n[0] != 'v' else 'velocity'}, {_AXES[n[-1]]}")
        for n in ("x", "y", "z", "vx", "vy", "vz")
    ) + tuple(
        Variable(f"instr_{a}", "output", "Real", 0.0, "m", f"Instrumentation (multilateration) fix, {_AXES[a]}")
        for a in ("x", "y", "z")
    ) + (
        Variable("instr_valid", "output", "Boolean", False, description="Instrumentation fix available"),
        Variable("nis", "output", "Real", 0.0, "1", "Normalized innovation squared of the last update"),
        Variable("pos_std", "output", "Real", 0.0, "m", "sqrt(trace) of the position covariance"),
    )
    return inputs + outputs


class PacketReceiverCore(ComponentCore):
    """Base of the receivers: slot detection and the held range of each beacon.

    Every step calls :meth:`_predict`; a replicate has a new *slot* when
    ``packet_seq`` differs from the last one it used and the end of the step
    has reached the packet's transmit epoch, ``t + Δt ≥ tx_time − 1e-9`` [s].
    At a slot a packet that was received (``packet_valid``) with a beacon id
    in ``1 … n`` replaces the held range and broadcast beacon position of that
    beacon; then, if any replicate of the batch has a new slot,
    :meth:`_update` runs with the mask of those replicates. :meth:`_outputs`
    refreshes :attr:`outputs` after initialization and after every step.

    Subclasses declare :meth:`~models.core.ComponentCore.variables` (with
    :func:`receiver_interface` among them) and implement
    :meth:`_initial_state`, :meth:`_update` and :meth:`_outputs`;
    :meth:`_predict` is optional.

    Attributes
    ----------
    ranges : ndarray, shape (B, n)
        Latest range of each beacon [m] (NaN: not heard yet).
    beacons : ndarray, shape (B, n, 3)
        Broadcast beacon positions carried with those ranges [m].
    last_seq : ndarray of int, shape (B,)
        ``packet_seq`` of the latest slot (0: none yet).
    slot_time : ndarray, shape (B,)
        Transmit epoch ``tx_time`` of the latest slot [s] (NaN: none yet).
    """

    def _initialize(self, t0: float) -> None:
        self._initial_state(t0)
        self.ranges = np.full((self.batch, self.n_beacons), np.nan)
        self.beacons = np.full((self.batch, self.n_beacons, 3), np.nan)
        self.last_seq = np.zeros(self.batch, dtype=np.int64)
        self.slot_time = np.full(self.batch, np.nan)
        self._outputs()

    def _step(self, t: float, dt: float) -> None:
        u = self.inputs
        self._predict(dt)
        seq = np.asarray(u["packet_seq"], dtype=np.int64)
        tx_time = np.asarray(u["tx_time"], float)
        slot = (seq != self.last_seq) & (t + dt >= tx_time - 1e-9)
        if np.any(slot):
            self.last_seq = np.where(slot, seq, self.last_seq)
            self.slot_time = np.where(slot, tx_time, self.slot_time)
            ids = np.asarray(u["beacon_id"], dtype=np.int64) - 1
            fresh = slot & np.asarray(u["packet_valid"], bool) & (ids >= 0) & (ids < self.n_beacons)
            rows = np.flatnonzero(fresh)
            self.ranges[rows, ids[rows]] = np.asarray(u["range"], float)[rows]
            self.beacons[rows, ids[rows]] = np.column_stack(
                [np.asarray(u[f"beacon_{a}"], float) for a in ("x", "y", "z")])[rows]
            self._update(slot, np.asarray(u["depth"], float))
        self._outputs()

    def _initial_state(self, t0: float) -> None:
        """Set the receiver's own initial state at ``t0`` [s] (before the first :meth:`_outputs`)."""
        raise NotImplementedError

    def _predict(self, dt: float) -> None:
        """Advance the receiver's own state by one step ``dt`` [s]; called every step (default: nothing)."""

    def _update(self, slot: np.ndarray, depth: np.ndarray) -> None:
        """Use the held ranges at a slot.

        Parameters
        ----------
        slot : ndarray of bool, shape (B,)
            Replicates with a new slot this step; the others must keep their state.
        depth : ndarray, shape (B,)
            Depth reading [m] (NaN: missing).
        """
        raise NotImplementedError

    def _outputs(self) -> None:
        """Refresh :attr:`outputs` from the state (after initialization and every step)."""
        raise NotImplementedError


class ReceiverCore(PacketReceiverCore):
    """The paper's EKF receiver with the raw instrumentation fix.

    Attributes
    ----------
    ekf : ExtendedKalmanFilter
        The filter (batched).
    fix : ndarray, shape (B, 3)
        Instrumentation fix of the latest slot [m] (NaN: none).
    fix_valid : ndarray of bool, shape (B,)
        The latest slot gave a fix.

    The held ranges and slot bookkeeping are those of :class:`PacketReceiverCore`.
    """

    name = "receiver"
    component_index = 3
    batched_parameters = frozenset({"sigma_range", "sigma_depth", "q_horizontal", "q_vertical", "p0_position",
                                    "p0_velocity", *(f"x0_{n}" for n in STATE_NAMES)})

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("sigma_range", "parameter", "Real", 0.1, "m", "Range standard deviation in R",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("sigma_depth", "parameter", "Real", 0.01, "m", "Depth standard deviation in R",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("q_horizontal", "parameter", "Real", 0.01, "m2/s3",
                     "Process noise: horizontal acceleration spectral density", min=0.0, max=1e6),
            Variable("q_vertical", "parameter", "Real", 0.001, "m2/s3",
                     "Process noise: vertical acceleration spectral density", min=0.0, max=1e6),
            Variable("p0_position", "parameter", "Real", 1.0, "m", "Initial position standard deviation",
                     min=0.0, max=1e6, min_exclusive=True),
            Variable("p0_velocity", "parameter", "Real", 0.5, "m/s", "Initial velocity standard deviation",
                     min=0.0, max=1e6, min_exclusive=True),
        ) + tuple(
            Variable(f"x0_{n}", "parameter", "Real", 0.0, "m" if n[0] != "v" else "m/s",
                     f"Initial {'position' if n[0] != 'v' else 'velocity'} estimate, {_AXES[n[-1]]}",
                     min=-1e6, max=1e6)
            for n in ("x", "y", "z", "vx", "vy", "vz"))
        return params + receiver_interface()

    def _initial_state(self, t0: float) -> None:
        p = self.params
        x0 = np.column_stack([np.broadcast_to(p[f"x0_{n}"], self.batch) for n in STATE_NAMES])
        variances = np.broadcast_arrays(np.asarray(p["p0_position"], float) ** 2,
                                        np.asarray(p["p0_velocity"], float) ** 2)
        P0 = np.zeros(variances[0].shape + (6, 6))
        for k in range(6):
            P0[..., k, k] = variances[k % 2]
        self.ekf = ExtendedKalmanFilter(x0, P0, p["q_horizontal"], p["q_vertical"],
                                        p["sigma_range"], p["sigma_depth"])
        self.fix = np.full((self.batch, 3), np.nan)
        self.fix_valid = np.zeros(self.batch, dtype=bool)

    def _predict(self, dt: float) -> None:
        self.ekf.predict(dt)

    def _update(self, slot: np.ndarray, depth: np.ndarray) -> None:
        """EKF update and instrumentation fix for the replicates with a new slot."""
        keep = ~slot  # replicates without a new slot keep their state
        before = (self.ekf.x[keep], self.ekf.P[keep], self.ekf.nis[keep]) if keep.any() else None
        self.ekf.update(self.ranges, self.beacons, depth)
        if before is not None:
            self.ekf.x[keep], self.ekf.P[keep], self.ekf.nis[keep] = before
        p = self.params
        # start from the last fix, else from the filter's position (a start point only)
        guess = np.where(self.fix_valid[:, None], self.fix, self.ekf.x[:, ::2])
        fix, valid = multilaterate(self.ranges, self.beacons, depth, guess, p["sigma_range"], p["sigma_depth"])
        self.fix = np.where(slot[:, None], fix, self.fix)
        self.fix_valid = np.where(slot, valid, self.fix_valid)

    def _outputs(self) -> None:
        x = self.ekf.x
        self.outputs = {f"est_{n}": x[:, k] for k, n in enumerate(STATE_NAMES)}
        self.outputs.update({f"instr_{a}": self.fix[:, k] for k, a in enumerate(("x", "y", "z"))})
        self.outputs["instr_valid"] = self.fix_valid.copy()
        self.outputs["nis"] = self.ekf.nis.copy()
        self.outputs["pos_std"] = np.sqrt(np.trace(self.ekf.P[:, ::2, ::2], axis1=1, axis2=2))
