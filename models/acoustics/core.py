"""Acoustic channel: round-robin OWTT ranging with loss and multipath.

Timing model (sblsim's documented choice). Slot k (k = 1, 2, ...) ends at
``t_k = t0 + k T`` of the component's own clock (T = ``slot_period``,
whatever the host's communication steps): beacon ``((k - 1) mod n) + 1``
transmits at epoch ``t_k`` from its true position ``b_i`` as the channel's
input holds it in the step that reaches ``t_k``. The packet reaches the diver
at ``t_k + τ``; the one-way travel time τ solves
``τ = ‖p + v τ − b_i‖ / c̄`` (three fixed-point iterations; c̄ the
harmonic-mean sound speed along the path, p and v the target's position and
velocity inputs), so **the true range refers to the target's position at
reception**. The receiver, synchronized to GPS time at power-on (the start
time t0), measures ``τ_m = τ + δ (t_k − t0 + τ)`` with clock drift δ and turns it into a range with
the assumed sound speed, ``r = c_assumed τ_m + σ_r w + e_mp``, where
``e_mp > 0`` (exponential, mean ``outlier_excess``) is added with probability
``p_out`` (reflected path) and the packet is lost with probability
``p_loss``. The packet carries the slot counter, the beacon id, ``t_k`` and
the beacon's broadcast position; a lost packet has ``packet_valid = false``
and range and position 0. A step that reaches several slot epochs emits each
of them in turn (the outputs show the last).

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4
(round-robin OWTT, range noise, packet loss). Eustice, Singh, Leonard,
"Synchronous-clock one-way-travel-time acoustic navigation for underwater
vehicles", J. Field Robotics 28(1), 2011 (OWTT with synchronized clocks).
"""

from __future__ import annotations

from typing import Any, Mapping

import casadi as ca

from sblsim.models.acoustics.sound_speed import NODES, PROFILE, harmonic_mean, profile_nodes, profile_table
from sblsim.models.component import Component
from sblsim.models.declarations import SEED_PARAMETERS, Variable, format_table, signal_range
from sblsim.models.expressions import sample_due, select
from sblsim.models.platform.core import AXES, beacon_names, beacon_variables
from sblsim.models.program import ProgramBuilder, Stream

_CHANNEL_UNIFORM, _RANGE_NOISE = range(2)
#: The packet a slot delivers: outputs of the channel, inputs of every receiver (whose FMUs refuse a value outside
#: the declared ranges, :data:`sblsim.models.declarations.SIGNAL_RANGES`).
PACKET: tuple[Variable, ...] = (
    Variable("packet_seq", "output", "Integer", 0, description="Slot counter k (0: no packet yet)",
             **signal_range("counter")),
    Variable("beacon_id", "output", "Integer", 0, description="Transmitting beacon (1-based; 0: none)",
             **signal_range("counter")),
    Variable("packet_valid", "output", "Boolean", False, description="Packet received (not lost)"),
    Variable("tx_time", "output", "Real", 0.0, "s", "Transmit epoch t_k of the packet", discrete=True,
             **signal_range("time")),
    Variable("range", "output", "Real", 0.0, "m", "Measured OWTT range (0 when the packet is lost)", discrete=True,
             **signal_range("range")),
    Variable("beacon_x", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, North (0 when lost)",
             discrete=True, **signal_range("position")),
    Variable("beacon_y", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, East (0 when lost)",
             discrete=True, **signal_range("position")),
    Variable("beacon_z", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, Down (0 when lost)",
             discrete=True, **signal_range("position")),
)
TARGET_INPUTS = ("target_x", "target_y", "target_z", "target_vx", "target_vy", "target_vz")
#: Fixed-point iterations of the travel time (before the final evaluation).
OWTT_ITERATIONS = 3


class Acoustics(Component):
    """Round-robin one-way-travel-time acoustic channel."""

    name = "acoustics"
    component_index = 1

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("sound_speed_assumed", "parameter", "Real", 1500.0, "m/s",
                     "Sound speed the receiver assumes to turn travel time into range", min=1300.0, max=1700.0),
            Variable("sound_speed_true", "parameter", "Real", 1500.0, "m/s",
                     "True sound speed when the profile is constant", min=1300.0, max=1700.0),
            Variable("sound_speed_profile", "parameter", "String", "constant", scope="config",
                     description="True sound speed: constant, teos10, table, ctd:NAME or a CSV cast path"),
            Variable("sound_speed_table", "parameter", "String", "", scope="config",
                     description="Sound-speed profile 'depth speed; ...' [m, m/s] (sound_speed_profile = table)"),
            Variable("temperature", "parameter", "Real", 15.0, "degC", "Water temperature for teos10",
                     min=-2.0, max=40.0, scope="config"),
            Variable("salinity", "parameter", "Real", 35.0, "g/kg", "Salinity for teos10", min=0.0, max=42.0,
                     scope="config"),
            Variable("sound_speed_rows", "parameter", "Integer", 0, scope="fmu", table=PROFILE,
                     description="Rows of the sound-speed table in use (0: constant sound_speed_true)",
                     min=0, max=PROFILE.max_rows),
            Variable("clock_drift_ppm", "parameter", "Real", 0.0, "ppm",
                     "Receiver clock drift after power-on synchronization", min=-1000.0, max=1000.0),
            Variable("sigma_range", "parameter", "Real", 0.1, "m", "Range noise standard deviation",
                     min=0.0, max=1000.0),
            Variable("loss_pct", "parameter", "Real", 0.0, "%", "Packet-loss probability", min=0.0, max=100.0),
            Variable("outlier_pct", "parameter", "Real", 0.0, "%", "Multipath-outlier probability",
                     min=0.0, max=100.0),
            Variable("outlier_excess", "parameter", "Real", 2.0, "m",
                     "Mean excess length of a multipath outlier (exponential)", min=0.0, max=1e4),
            Variable("slot_period", "parameter", "Real", 0.1, "s",
                     "Round-robin slot length T (the sampling time)", min=0.001, max=60.0, scope="fmu"),
        )
        inputs = beacon_variables(n_beacons, "input") + tuple(
            Variable(n, "input", "Real", 0.0, unit, f"True target {what}, {axis} [NED]", **signal_range(what))
            for n, unit, what, axis in zip(
                TARGET_INPUTS, ("m",) * 3 + ("m/s",) * 3, ("position",) * 3 + ("velocity",) * 3,
                ("North", "East", "Down") * 2))
        outputs = PACKET + (
            Variable("travel_time", "output", "Real", 0.0, "s", "True one-way travel time", discrete=True),
            Variable("range_true", "output", "Real", 0.0, "m",
                     "True distance from beacon at transmit to target at reception", discrete=True),
            Variable("outlier", "output", "Boolean", False, description="Range lengthened by multipath"),
        )
        return params + SEED_PARAMETERS + inputs + outputs

    @classmethod
    def fmu_parameters(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """FMU parameters of a configuration section: the profile setting becomes the sound-speed table.

        Raises
        ------
        ModelError
            On an unknown cast or an unreadable or malformed profile.
        """
        out = super().fmu_parameters(values, n_beacons)
        rows = profile_table(values.get("sound_speed_profile", "constant"), values.get("sound_speed_table", ""),
                             values.get("temperature", 15.0), values.get("salinity", 35.0))
        out.update(PROFILE.values(rows, "sound_speed_rows"))
        return out

    @classmethod
    def config_values(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """Configuration keys from FMU parameters: a sound-speed table becomes ``sound_speed_profile = table``."""
        out = super().config_values(values, n_beacons)
        rows = PROFILE.rows(values, "sound_speed_rows")
        out["sound_speed_profile"] = "table" if rows.shape[0] else "constant"
        out["sound_speed_table"] = format_table(rows)
        return out

    @classmethod
    def build(cls, n_beacons: int):
        n = n_beacons
        packet = [v.name for v in cls.outputs(n)]
        b = ProgramBuilder(cls, n, states=[("t0", 1), ("k", 1)] + [(name, 1) for name in packet],
                           derived=[("nodes", NODES), ("slowness", NODES)])
        true_names, sent_names = beacon_names(n, "true"), beacon_names(n, "broadcast")

        def prepare(p):
            depth, speed = p[PROFILE.columns[0].name], p[PROFILE.columns[1].name]
            nodes, slowness = profile_nodes(p["sound_speed_rows"], depth, speed)
            # a constant profile (no rows) never reads them: skip the table work (a short-circuit conditional)
            values = ca.vertcat(nodes, slowness)
            values = ca.if_else(p["sound_speed_rows"] > 0, values, ca.MX.zeros(values.shape), True)
            return {"nodes": values[:NODES], "slowness": values[NODES:]}

        def init(p, d, w, t0):
            zero = {name: 0 for name in packet}
            return {"t0": t0, "k": 0, **zero, "tx_time": t0}

        def due(x, u, p, d, t, h):
            return sample_due(x["k"], x["t0"], p["slot_period"], t, h)

        def slot(x, u, p, d, w, t, h):
            k = x["k"] + 1
            t_k = x["t0"] + k * p["slot_period"]
            i = ca.fmod(k - 1, n)
            beacon = ca.vertcat(*[select(i, [u[true_names[3 * j + a]] for j in range(n)]) for a in range(3)])
            sent = ca.vertcat(*[select(i, [u[sent_names[3 * j + a]] for j in range(n)]) for a in range(3)])
            position = ca.vertcat(*[u[name] for name in TARGET_INPUTS[:3]])
            velocity = ca.vertcat(*[u[name] for name in TARGET_INPUTS[3:]])

            def path(tau):
                receive = position + velocity * tau
                distance = ca.norm_2(receive - beacon)
                speed = harmonic_mean(beacon[2], receive[2], p["sound_speed_true"], p["sound_speed_rows"],
                                      d["nodes"], d["slowness"])
                return distance / speed, distance

            tau = 0.0
            for _ in range(OWTT_ITERATIONS):
                tau, _ = path(tau)
            tau, distance = path(tau)

            draws, noise = w[_CHANNEL_UNIFORM], w[_RANGE_NOISE][0]
            valid = draws[0] >= p["loss_pct"] / 100.0
            outlier = draws[1] < p["outlier_pct"] / 100.0
            excess = ca.if_else(outlier, -p["outlier_excess"] * ca.log1p(-draws[2]), 0.0)
            measured = tau + p["clock_drift_ppm"] * 1e-6 * (t_k - x["t0"] + tau)
            rng = p["sound_speed_assumed"] * measured + p["sigma_range"] * noise + excess
            out = {"k": k, "packet_seq": k, "beacon_id": i + 1, "packet_valid": valid, "tx_time": t_k,
                   "range": ca.if_else(valid, rng, 0.0), "travel_time": tau, "range_true": distance,
                   "outlier": ca.logic_and(outlier, valid)}
            out.update({f"beacon_{a}": ca.if_else(valid, sent[j], 0.0) for j, a in enumerate(AXES)})
            return out

        def output(x, p, d, t):
            return {name: x[name] for name in packet}

        streams = (Stream(_CHANNEL_UNIFORM, "uniform", 3), Stream(_RANGE_NOISE, "normal", 1))
        return b.program(b.prepare(prepare), b.init(init), b.output(output),
                         events=[b.event("slot", due, slot, streams)])


__all__ = ["Acoustics", "OWTT_ITERATIONS", "PACKET", "TARGET_INPUTS"]
