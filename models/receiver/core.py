"""Receivers fed by round-robin OWTT packets and depth; the paper's EKF receiver.

Every receiver runs at its own communication step Δt = T / (EKF rate ratio)
and shares the packet handling (:func:`packet_event`): a replicate has a new
*slot* when ``packet_seq`` differs from the last one it used and the end of
the step has reached the packet's transmit epoch, ``t + Δt ≥ tx_time − 1 ns``.
At a slot a packet that was received (``packet_valid``) with a beacon id in
``1 … n`` replaces the held range and broadcast beacon position of that
beacon; then the receiver uses the latest range of every beacon heard so far
plus the depth reading. Held ranges are re-used at later slots: their
staleness is part of the error, as in the paper.

:class:`Receiver` is the paper's EKF: a prediction every step, one update per
slot, and the raw instrumentation fix (a least-squares multilateration of the
same held ranges and depth, no filter) computed at the same instants.

No output is ever NaN: before its first update the filter reports its
initial state, ``nis`` is 0 and ``instr_valid`` is false with ``instr_*`` 0.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca

from models.acoustics.core import PACKET
from models.core import Component, ProgramBuilder, Variable
from models.receiver import ekf
from models.receiver.multilateration import LM_STATE, lm_iteration, lm_start, weights

STATE_NAMES = ("x", "vx", "y", "vy", "z", "vz")
_AXES = {"x": "North", "y": "East", "z": "Down"}
#: Iteration cap and step tolerance [standard deviations of the fix] of the instrumentation fix.
INSTRUMENT_ITERATIONS, INSTRUMENT_TOLERANCE = 8, 1e-3
#: Slack of the slot test ``t + Δt ≥ tx_time − SLOT_SLACK`` [s].
SLOT_SLACK = 1e-9


def receiver_interface() -> tuple[Variable, ...]:
    """Inputs and outputs every receiver shares (EKF, least squares, a user's FMU)."""
    inputs = tuple(replace(v, causality="input") for v in PACKET) + (
        Variable("depth", "input", "Real", 0.0, "m", "Depth-sensor reading", discrete=True),
    )
    outputs = tuple(
        Variable(f"est_{n}", "output", "Real", 0.0, "m" if n[0] != "v" else "m/s",
                 f"Estimated {'position' if n[0] != 'v' else 'velocity'}, {_AXES[n[-1]]}", discrete=True)
        for n in ("x", "y", "z", "vx", "vy", "vz")
    ) + tuple(
        Variable(f"instr_{a}", "output", "Real", 0.0, "m",
                 f"Instrumentation (multilateration) fix, {_AXES[a]} (0 without a fix)", discrete=True)
        for a in ("x", "y", "z")
    ) + (
        Variable("instr_valid", "output", "Boolean", False, description="Instrumentation fix available"),
        Variable("nis", "output", "Real", 0.0, "1", "Normalized innovation squared of the last update (0: none)",
                 discrete=True),
        Variable("pos_std", "output", "Real", 0.0, "m", "sqrt(trace) of the position covariance", discrete=True),
    )
    return inputs + outputs


def packet_states(n_beacons: int) -> list[tuple[str, int]]:
    """State blocks of the packet handling: held ranges and beacon positions, heard flags, the last slot."""
    return [("ranges", n_beacons), ("beacons", 3 * n_beacons), ("heard", n_beacons), ("last_seq", 1),
            ("slot_time", 1)]


def packet_init(n_beacons: int) -> dict[str, ca.SX]:
    return {"ranges": ca.SX.zeros(n_beacons), "beacons": ca.SX.zeros(3 * n_beacons),
            "heard": ca.SX.zeros(n_beacons), "last_seq": 0, "slot_time": 0}


def slot_due(x, u, t, h) -> ca.SX:
    """A new packet whose transmit epoch the end of the step has reached."""
    return ca.logic_and(u["packet_seq"] != x["last_seq"], t + h >= u["tx_time"] - SLOT_SLACK)


def fresh_packet(u, n_beacons: int) -> ca.SX:
    """The slot's packet was received and names a beacon of the array."""
    index = u["beacon_id"] - 1
    return ca.logic_and(u["packet_valid"], ca.logic_and(index >= 0, index < n_beacons))


def take_packet(x, u, n_beacons: int) -> dict[str, ca.SX]:
    """The held ranges after a slot: a received packet replaces its beacon's range and position."""
    index = u["beacon_id"] - 1
    fresh = fresh_packet(u, n_beacons)
    position = ca.vertcat(u["beacon_x"], u["beacon_y"], u["beacon_z"])
    ranges, beacons, heard = [], [], []
    for j in range(n_beacons):
        mine = ca.logic_and(fresh, index == j)
        ranges.append(ca.if_else(mine, u["range"], x["ranges"][j]))
        beacons.append(ca.if_else(mine, position, x["beacons"][3 * j:3 * j + 3]))
        heard.append(ca.if_else(mine, 1.0, x["heard"][j]))
    return {"ranges": ca.vertcat(*ranges), "beacons": ca.vertcat(*beacons), "heard": ca.vertcat(*heard),
            "last_seq": u["packet_seq"], "slot_time": u["tx_time"]}


def lm_active(x, u, p, d, t, h) -> ca.SX:
    """Guard of the least-squares iteration event: a fix is still moving."""
    return x["lm_active"] > 0.5


def lm_step(x, p, iterations: int, tolerance: float) -> dict[str, ca.SX]:
    """One iteration of the least-squares fix in progress (after :func:`lm_begin`)."""
    w_r, w_d = weights(p["sigma_range"], p["sigma_depth"])
    return lm_iteration(x, x["ranges"], x["beacons"], x["heard"], x["lm_depth"], w_r, w_d, iterations, tolerance)


def lm_states() -> list[tuple[str, int]]:
    """State blocks of a least-squares fix in progress (:data:`LM_STATE` and the depth it uses)."""
    return list(LM_STATE) + [("lm_depth", 1)]


def lm_begin(x, guess, depth, p) -> dict[str, ca.SX]:
    """Start a least-squares fix of the held ranges (after :func:`take_packet`) at a slot."""
    w_r, w_d = weights(p["sigma_range"], p["sigma_depth"])
    valid = ca.sum1(x["heard"]) >= 3
    return {**lm_start(guess, x["ranges"], x["beacons"], x["heard"], depth, w_r, w_d, valid), "lm_depth": depth}


def lm_idle() -> dict[str, ca.SX]:
    return {"lm_point": ca.SX.zeros(3), "lm_cost": 0, "lm_mu": 1e-3, "lm_iter": 0, "lm_active": 0, "lm_depth": 0}


class Receiver(Component):
    """The paper's EKF receiver with the raw instrumentation fix."""

    name = "receiver"
    component_index = 3

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

    @classmethod
    def build(cls, n_beacons: int):
        n = n_beacons
        b = ProgramBuilder(cls, n, states=[("x", 6), ("P", 36)] + packet_states(n) + [
            ("fix", 3), ("fix_valid", 1), ("nis", 1)] + lm_states())

        def init(p, d, w, t0):
            x0 = ca.vertcat(*[p[f"x0_{name}"] for name in ("x", "vx", "y", "vy", "z", "vz")])
            P0 = ca.diag(ca.vertcat(*[p["p0_position"] ** 2, p["p0_velocity"] ** 2] * 3))
            return {"x": x0, "P": ca.vec(P0), **packet_init(n), "fix": ca.SX.zeros(3), "fix_valid": 0, "nis": 0,
                    **lm_idle()}

        def step(x, u, p, d, w, t, h):
            state, P = ekf.predict(x["x"], ca.reshape(x["P"], 6, 6), h, p["q_horizontal"], p["q_vertical"])
            return {"x": state, "P": ca.vec(P)}

        def due(x, u, p, d, t, h):
            return slot_due(x, u, t, h)

        def slot(x, u, p, d, w, t, h):
            held = {**x, **take_packet(x, u, n)}
            state, P, nis = ekf.update(x["x"], ca.reshape(x["P"], 6, 6), held["ranges"], held["beacons"],
                                       held["heard"], u["depth"], p["sigma_range"], p["sigma_depth"])
            # start from the last fix, else from the filter's position (a start point only)
            guess = ca.if_else(x["fix_valid"], x["fix"], state[0::2])
            fix = lm_begin(held, guess, u["depth"], p)
            return {**held, "x": state, "P": ca.vec(P), "nis": nis, **fix,
                    "fix": ca.if_else(fix["lm_active"], fix["lm_point"], x["fix"]), "fix_valid": fix["lm_active"]}

        def iterate(x, u, p, d, w, t, h):
            out = lm_step(x, p, INSTRUMENT_ITERATIONS, INSTRUMENT_TOLERANCE)
            return {**out, "fix": out["lm_point"]}

        def output(x, p, d, t):
            P = ca.reshape(x["P"], 6, 6)
            out = {f"est_{name}": x["x"][k] for k, name in enumerate(STATE_NAMES)}
            out.update({f"instr_{a}": ca.if_else(x["fix_valid"], x["fix"][k], 0.0) for k, a in enumerate("xyz")})
            out.update(instr_valid=x["fix_valid"], nis=x["nis"], pos_std=ca.sqrt(P[0, 0] + P[2, 2] + P[4, 4]))
            return out

        return b.program(b.prepare(None), b.init(init), b.output(output), step=b.step(step),
                         events=[b.event("slot", due, slot), b.event("lm", lm_active, iterate)])


__all__ = ["INSTRUMENT_ITERATIONS", "INSTRUMENT_TOLERANCE", "Receiver", "STATE_NAMES", "fresh_packet", "lm_active", "lm_begin",
           "lm_idle", "lm_step", "lm_states", "packet_init", "packet_states", "receiver_interface", "slot_due", "take_packet"]
