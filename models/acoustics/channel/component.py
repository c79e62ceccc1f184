"""The acoustic channel component, :class:`Acoustics`: its variables in their order, its FMU parameters from a
configuration section (the sound-speed and pinger tables, the site's absorption), the eigenray and family tables of a
run, and its program: the slot and ping events, the delivery on the lanes, the derived data and the random streams.

What each event computes is its module's: a slot's exchange :mod:`~sblsim.models.acoustics.channel.exchange`, a ping
:mod:`~sblsim.models.acoustics.channel.toa` and :mod:`~sblsim.models.acoustics.channel.pinger`, the delivery
:mod:`~sblsim.models.acoustics.channel.lanes`.
"""

from __future__ import annotations

import math
from functools import lru_cache, partial
from typing import Any, Callable, Mapping

import casadi as ca
import numpy as np

from sblsim.models.acoustics import volume_absorption
from sblsim.models.acoustics.channel.exchange import _slot
from sblsim.models.acoustics.channel.interface import (
    _ANGLE_NOISE,
    _CHANNEL_UNIFORM,
    _DETECTION,
    _DOWNLINK,
    _OCEAN_FREQUENCY,
    _OCEAN_PHASE,
    _PING_JITTER,
    _RANGE_NOISE,
    _TURNAROUND,
    ARRIVAL,
    DETECTION_DRAWS,
    DETECTION_VARIABLES,
    DIRECTION,
    DOA_ARRAY,
    EXCHANGE,
    FAMILY_TABLE_VARIABLES,
    FLIGHT_CAPACITY,
    LANES,
    OVERFLOW,
    OVERRUN,
    PACKET,
    PROPAGATION,
    PROPAGATION_VARIABLES,
    RANGE_LAW,
    RANGING,
    RAY_TABLE_VARIABLES,
    TARGET_INPUTS,
    TOA,
)
from sblsim.models.acoustics.channel.lanes import _arrived, lane_fields, lane_name, lane_variables
from sblsim.models.acoustics.channel.ocean import OCEAN_FEATURES, OCEAN_VARIABLES
from sblsim.models.acoustics.channel.pinger import (
    BURSTS,
    MAX_BURSTS,
    PING_VARIABLES,
    RECEIVER_CLOCK_VARIABLES,
    burst_sequence,
    ping_due,
    ping_interval_drawn,
    ping_schedule,
    sent_epoch,
)
from sblsim.models.acoustics.channel.site import site_from, site_numbers
from sblsim.models.acoustics.channel.toa import _ping
from sblsim.models.acoustics.detection import SITE, level_table
from sblsim.models.acoustics.ray_tables import (
    FAMILY_TABLE,
    RAY_BOUNDS,
    RAY_GRID,
    RAY_TABLE,
    RAY_TABLE_ROWS,
    eigenray_table,
    ray_grid,
    ray_values,
)
from sblsim.models.acoustics.sound_speed import (
    NODES,
    PROFILE,
    PROFILE_FILE,
    node_speeds,
    profile_nodes,
    profile_table,
)
from sblsim.models.component import Component
from sblsim.models.declarations import SEED_PARAMETERS, Variable, signal_range
from sblsim.models.expressions import get_row, sample_due
from sblsim.models.platform.core import USBL_ATTITUDES, attitude_variables, beacon_names, beacon_variables
from sblsim.models.program import ProgramBuilder, Stream
from sblsim.models.systems import interface_system
from sblsim.models.table_text import format_table


@lru_cache(maxsize=32)
def _ray_table(table: tuple, depth: float, box: tuple, exact_points: Callable) -> tuple:
    columns = eigenray_table(np.array(table), depth, box, exact_points())
    out = {name: float(value) for name, value in zip(RAY_BOUNDS, box)}
    out.update(RAY_TABLE.values(np.column_stack([columns[c.name] for c in RAY_TABLE.columns]), "ray_table_rows"))
    return tuple(out.items())


@lru_cache(maxsize=32)
def _family_table(table: tuple, depth: float, box: tuple, site: tuple, family_points: Callable,
                  family_levels: Callable) -> tuple:
    columns = level_table(np.array(table), depth, box, np.array(site), family_points(), family_levels())
    return tuple(FAMILY_TABLE.values(np.column_stack([columns[c.name] for c in FAMILY_TABLE.columns]),
                                     "ray_family_rows").items())


class Acoustics(Component):
    """Acoustic channel: round-robin OWTT or TWTT ranging, USBL range and direction, inverted-LBL times of arrival.

    The timing and the exchanges are those of the channel's modules (:mod:`sblsim.models.acoustics.channel`)."""

    name = "acoustics"
    component_index = 1

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("sound_speed_assumed", "parameter", "Real", 1500.0, "m/s",
                     "Sound speed the receiver assumes to turn travel time into range", min=1300.0, max=1700.0),
            Variable("sound_speed_true", "parameter", "Real", 1500.0, "m/s",
                     "True sound speed when the profile is constant", min=1300.0, max=1700.0),
            Variable("sound_speed_profile", "parameter", "String", "constant", scope="config", file=PROFILE_FILE,
                     description="True sound speed: constant, teos10, table, munk, ctd:NAME or a CSV cast path"),
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
        outputs = PACKET + EXCHANGE
        # declared after the OWTT ones, so that their value references stay what they were
        ranging = (
            Variable("ranging", "parameter", "String", "owtt",
                     description="Ranging of SBL and LBL: one-way or two-way travel time (USBL: always two-way; "
                                 "ilbl: always toa, the times of arrival of the target's pings)",
                     choices=RANGING),
            Variable("turnaround", "parameter", "Real", 0.05, "s",
                     "TWTT: the replying transponder's nominal turnaround time", min=0.0, max=10.0),
            Variable("turnaround_sigma", "parameter", "Real", 0.0, "s",
                     "TWTT: std of the turnaround's Gaussian jitter, the turnaround cut at 0 (no reply before its "
                     "interrogation)",
                     min=0.0, max=1.0),
        )
        if not interface_system(n_beacons).measures_direction:
            return (params + SEED_PARAMETERS + inputs + outputs + ranging + ARRIVAL + OVERFLOW + PROPAGATION_VARIABLES
                    + RAY_TABLE_VARIABLES + DETECTION_VARIABLES + OVERRUN + FAMILY_TABLE_VARIABLES + OCEAN_VARIABLES
                    + lane_variables(n_beacons, "output") + PING_VARIABLES + RECEIVER_CLOCK_VARIABLES + RANGE_LAW)
        usbl = (Variable("usbl_angle_sigma_deg", "parameter", "Real", 0.5, "deg",
                         "Direction-of-arrival error std on the array's axis (platform.usbl_angle_sigma_deg)",
                         min=0.0, max=45.0, scope="fmu"),) + tuple(
            v for prefix, what, discrete in USBL_ATTITUDES for v in attitude_variables(prefix, "input", what, discrete))
        return (params + SEED_PARAMETERS + inputs + outputs + ranging + usbl + DIRECTION + ARRIVAL + OVERFLOW
                + PROPAGATION_VARIABLES + RAY_TABLE_VARIABLES + DETECTION_VARIABLES + OVERRUN
                + FAMILY_TABLE_VARIABLES + DOA_ARRAY + OCEAN_VARIABLES + lane_variables(n_beacons, "output")
                + PING_VARIABLES + RECEIVER_CLOCK_VARIABLES + RANGE_LAW)

    @classmethod
    def uses_ray_table(cls, values: Mapping[str, Any], parameters: Mapping[str, Any]) -> bool:
        """Whether a run of the channel's section ``values`` (its FMU parameters ``parameters``) interpolates an
        eigenray table (:meth:`table_parameters`): a ``ray`` run through a sound-speed table."""
        return values.get("propagation") == "ray" and int(parameters.get("sound_speed_rows", 0)) > 0

    @classmethod
    def table_parameters(cls, values: Mapping[str, Any], parameters: Mapping[str, Any], box: tuple[float, ...],
                         exact_points: Callable[[], ca.Function | None],
                         family_points: Callable[[], ca.Function | None],
                         family_levels: Callable[[], ca.Function | None]) -> dict[str, Any]:
        """The FMU parameters of a run's eigenray table (:data:`RAY_TABLE`, its box :data:`RAY_BOUNDS`) and, for an
        ``snr`` run (``detection``), of its family table at the same nodes (:data:`FAMILY_TABLE`).

        Parameters
        ----------
        values : mapping
            The channel's resolved section (a run that :meth:`uses_ray_table`).
        parameters : mapping
            Its FMU parameters (:meth:`fmu_parameters`: the profile's table and the site).
        box : tuple of 6 float
            The geometries the table covers: source depth, receiver depth, horizontal distance, each (min, max)
            [m]; a geometry outside it is solved exactly.
        exact_points, family_points, family_levels : callable
            Give the compiled forms of :func:`~sblsim.models.acoustics.ray_tables.exact_points`,
            :func:`~sblsim.models.acoustics.ray_tables.family_points` and
            :func:`~sblsim.models.acoustics.detection.family_levels` (called when a table is built; None: casadi's
            own evaluation, the same numbers).

        Each table is built once per profile, water depth and box (and site), however many runs ask
        (:func:`~sblsim.models.acoustics.ray_tables.eigenray_table`,
        :func:`~sblsim.models.acoustics.detection.level_table`).
        """
        table = tuple(map(tuple, PROFILE.rows(parameters, "sound_speed_rows").tolist()))
        depth, box = float(values["water_depth"]), tuple(float(b) for b in box)
        out = dict(_ray_table(table, depth, box, exact_points))
        if values.get("detection") == "snr":
            site = tuple(float(v) for v in site_from(cls.fmu_parameters_declared(), parameters)[1])
            out.update(_family_table(table, depth, box, site, family_points, family_levels))
        return out

    @classmethod
    def fmu_parameters(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """FMU parameters of a configuration section: the profile setting becomes the sound-speed table, a ``pbi``
        pinger's ``burst_sequence`` its table of intervals.

        Raises
        ------
        ModelError
            On an unknown cast or an unreadable or malformed profile, a malformed ``burst_sequence``.
        """
        out = super().fmu_parameters(values, n_beacons)
        rows = profile_table(values.get("sound_speed_profile", "constant"), values.get("sound_speed_table", ""),
                             values.get("temperature", 15.0), values.get("salinity", 35.0))
        out.update(PROFILE.values(rows, "sound_speed_rows"))
        # a pbi pinger's intervals (none: an empty table, what every other pinger has)
        out.update(BURSTS.values(burst_sequence(values.get("burst_sequence", "")), "burst_sequence_rows"))
        # volume absorption at the signal's frequency in the site's own water (the column's mean, each depth at
        # the temperature its cast gives)
        out["absorption"] = volume_absorption.water_column_absorption(
            values.get("frequency", 25000.0), rows, values.get("temperature", 15.0), values.get("salinity", 35.0),
            values.get("water_depth", 0.0))
        return out

    @classmethod
    def config_values(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """Configuration keys from FMU parameters: a sound-speed table becomes ``sound_speed_profile = table``, a
        pinger's table of intervals ``burst_sequence``."""
        out = super().config_values(values, n_beacons)
        rows = PROFILE.rows(values, "sound_speed_rows")
        out["sound_speed_profile"] = "table" if rows.shape[0] else "constant"
        out["sound_speed_table"] = format_table(rows)
        out["burst_sequence"] = format_table(BURSTS.rows(values, "burst_sequence_rows"))
        return out

    @classmethod
    def build(cls, n_beacons: int):
        n = n_beacons
        packet = [v.name for v in cls.outputs(n)]
        lanes = {v.name for v in lane_variables(n, "output")}
        fields = [v.name for v in lane_fields(n) + EXCHANGE]
        # what a packet in flight carries: every output of lane 1 but the refusal signal and what its slot counter
        # gives (the beacon and the transmit epoch, computed again at delivery as the slot computed them)
        carried = [name for name in packet
                   if name not in {v.name for v in OVERFLOW + OVERRUN} | {"beacon_id", "tx_time"} | lanes]
        queue = [(f"q_{name}", FLIGHT_CAPACITY) for name in carried] + [("q_used", FLIGHT_CAPACITY)]
        b = ProgramBuilder(cls, n, states=[("t0", 1), ("k", 1)] + [(name, 1) for name in packet] + queue
                           + [("delivered_end", 1), ("lanes_used", 1), ("lanes_held", 1),
                              ("ocean_frequency", OCEAN_FEATURES),
                              ("ocean_phase", OCEAN_FEATURES), ("ping_epoch", 1), ("ping_count", 1),
                              ("ping_leg", 1)],
                           derived=[("nodes", NODES), ("slowness", NODES), ("speeds", NODES),
                                    ("ray_bounds", len(RAY_BOUNDS)), ("ray_grid", sum(RAY_GRID)),
                                    ("ray_values", len(RAY_TABLE.columns) * RAY_TABLE_ROWS), ("site", len(SITE)),
                                    ("family_values", len(FAMILY_TABLE.columns) * RAY_TABLE_ROWS),
                                    ("ping_steps", MAX_BURSTS), ("ping_prefix", MAX_BURSTS + 1),
                                    ("ping_rows", 1), ("ping_cycle", 1), ("ping_shortest", 1), ("ping_spread", 1)])
        true_names, sent_names = beacon_names(n, "true"), beacon_names(n, "broadcast")
        # the interface's system measures a direction of arrival (USBL): it interrogates, the array measures
        direction = interface_system(n).measures_direction

        def prepare(p):
            depth, speed = p[PROFILE.columns[0].name], p[PROFILE.columns[1].name]
            nodes, slowness = profile_nodes(p["sound_speed_rows"], depth, speed)
            speeds = node_speeds(p["sound_speed_rows"], depth, speed)[1]
            # a constant profile (no rows) never reads them: skip the table work (a short-circuit conditional)
            values = ca.vertcat(nodes, slowness, speeds)
            values = ca.if_else(p["sound_speed_rows"] > 0, values, ca.MX.zeros(values.shape), True)
            bounds = ca.vertcat(*[p[name] for name in RAY_BOUNDS])
            table = ray_values([p[c.name] for c in RAY_TABLE.columns])
            # a run without an eigenray table (every straight run) never reads it: skip its copy, as above
            table = ca.if_else(p["ray_table_rows"] > 0, table, ca.MX.zeros(table.shape), True)
            family = ray_values([p[c.name] for c in FAMILY_TABLE.columns])
            family = ca.if_else(p["ray_family_rows"] > 0, family, ca.MX.zeros(family.shape), True)  # (snr runs)
            return {"nodes": values[:NODES], "slowness": values[NODES:2 * NODES], "speeds": values[2 * NODES:],
                    "ray_bounds": bounds, "ray_grid": ray_grid([bounds[j] for j in range(len(RAY_BOUNDS))]),
                    "ray_values": table,
                    "site": site_numbers(p), "family_values": family, **ping_schedule(p, n)}

        def init(p, d, w, t0):
            zero = {name: 0 for name in packet}
            empty = {name: ca.SX.zeros(size) for name, size in queue}
            return {"t0": t0, "k": 0, **zero, "tx_time": t0, "rx_time": t0, **empty,
                    "delivered_end": t0 - p["slot_period"], "lanes_used": 1, "lanes_held": 1,
                    # the moving ocean's features, drawn once per run (their own streams)
                    "ocean_frequency": w[_OCEAN_FREQUENCY] / p["ntd_time_scale"],
                    "ocean_phase": 2.0 * math.pi * w[_OCEAN_PHASE],
                    # toa: the first ping, an interval of the pinger's clock after the start
                    "ping_epoch": t0 + ping_interval_drawn(p, d, 1, w[_PING_JITTER][0]),
                    "ping_count": 0, "ping_leg": 0}

        def due(x, u, p, d, t, h):
            return sample_due(x["k"], x["t0"], p["slot_period"], t, h)

        slot = partial(_slot, n, true_names, sent_names, direction, queue, carried)

        def deliverable(x, u, p, d, t, h):
            """Guard of the delivery: a packet has arrived by the end of the step, and none was delivered in it
            (the last delivery's step end lies before this step's middle)."""
            any_arrived = 0
            for flag in _arrived(x, t, h):
                any_arrived = ca.logic_or(any_arrived, flag)
            return ca.logic_and(any_arrived, x["delivered_end"] < t + 0.5 * h)

        def earliest(x, p, d, t, h):
            """The in-flight place of the arrived packet of earliest arrival (then lowest slot counter), and its
            packet (carried outputs, the beacon and the transmit epoch) by output name."""
            best, best_rx, best_seq = 0, ca.inf, ca.inf
            for j, flag in enumerate(_arrived(x, t, h)):
                rx, seq = x["q_rx_time"][j], x["q_packet_seq"][j]
                better = ca.logic_and(flag, ca.logic_or(rx < best_rx, ca.logic_and(rx == best_rx, seq < best_seq)))
                best = ca.if_else(better, j, best)
                best_rx, best_seq = ca.if_else(better, rx, best_rx), ca.if_else(better, seq, best_seq)
            out = dict(zip(carried, get_row([x[f"q_{name}"] for name in carried], best)))
            seq = out["packet_seq"]
            out.update(beacon_id=ca.fmod(seq - 1, n) + 1, tx_time=sent_epoch(x, p, d, seq, n))
            used = ca.vertcat(*[ca.if_else(best == j, 0.0, x["q_used"][j]) for j in range(FLIGHT_CAPACITY)])
            return out, used

        def deliver(x, u, p, d, w, t, h):
            """The arrived packet of earliest arrival (then lowest slot counter) becomes the outputs (lane 1)."""
            out, used = earliest(x, p, d, t, h)
            return {**out, "q_used": used, "delivered_end": t + h, "lanes_used": 1}

        def another(x, u, p, d, t, h):
            """Guard of the later lanes: the step delivered (lane 1), another packet has arrived, a lane is free."""
            any_arrived = 0
            for flag in _arrived(x, t, h):
                any_arrived = ca.logic_or(any_arrived, flag)
            return ca.logic_and(ca.logic_and(any_arrived, x["delivered_end"] == t + h), x["lanes_used"] < LANES)

        def deliver_lane(x, u, p, d, w, t, h):
            """The next arrived packet (in the order of arrival) on the next lane of the delivery."""
            out, used = earliest(x, p, d, t, h)
            lane = x["lanes_used"] + 1
            placed = {lane_name(m, name): ca.if_else(lane == m, out[name], x[lane_name(m, name)])
                      for m in range(2, LANES + 1) for name in fields}
            return {**placed, "q_used": used, "lanes_used": lane, "lanes_held": ca.fmax(x["lanes_held"], lane)}

        def stale(x, u, p, d, t, h):
            """Guard of the clearing: lanes hold packets of an earlier delivery than this one's."""
            return x["lanes_held"] > x["lanes_used"]

        def clear(x, u, p, d, w, t, h):
            """Empty the lanes beyond this delivery's (packet_seq and every field 0)."""
            return {**{lane_name(m, name): ca.if_else(m > x["lanes_used"], 0.0, x[lane_name(m, name)])
                       for m in range(2, LANES + 1) for name in fields}, "lanes_held": x["lanes_used"]}

        def output(x, p, d, t):
            return {name: x[name] for name in packet}

        streams = (Stream(_CHANNEL_UNIFORM, "uniform", 3), Stream(_RANGE_NOISE, "normal", 1))
        events = []
        # a slot event per (ranging, propagation, detection): a run computes its own legs and what it hears
        modes = [(propagation, "fixed") for propagation in PROPAGATION] + [("ray", "snr")]
        for propagation, detection in modes:
            chosen = {"propagation": (propagation,), "detection": (detection,)}
            heard = (Stream(_DETECTION, "uniform", DETECTION_DRAWS),) if detection == "snr" else ()
            suffix = f"{propagation}" + ("_snr" if detection == "snr" else "")
            if direction:
                events.append(b.event(f"slot_{suffix}", due, slot("twtt", propagation, detection), streams + (
                    Stream(_TURNAROUND, "normal", 1), Stream(_ANGLE_NOISE, "normal", 2),
                    Stream(_DOWNLINK, "uniform", 1)) + heard, when=chosen))
                continue
            for ranging in RANGING[:TOA]:
                extra = (Stream(_TURNAROUND, "normal", 1),) if ranging == "twtt" else ()
                events.append(b.event(f"slot_{ranging}_{suffix}", due, slot(ranging, propagation, detection),
                                      streams + extra + heard, when={"ranging": (ranging,), **chosen}))
            # an inverted LBL: one leg per receiver of each of the target's pings
            events.append(b.event(f"ping_{suffix}", ping_due, partial(_ping, n, true_names, sent_names, queue,
                                                                      carried)(propagation, detection),
                                  streams + (Stream(_PING_JITTER, "uniform", 1),) + heard,
                                  when={"ranging": ("toa",), **chosen}))
        events.append(b.event("deliver", deliverable, deliver))  # after the slots: a packet is sent, then arrives
        events += [b.event("deliver_lane", another, deliver_lane), b.event("clear_lanes", stale, clear)]
        ocean = (Stream(_OCEAN_FREQUENCY, "normal", OCEAN_FEATURES), Stream(_OCEAN_PHASE, "uniform", OCEAN_FEATURES),
                 Stream(_PING_JITTER, "uniform", 1, when=("ranging", "toa")))
        return b.program(b.prepare(prepare), b.init(init, ocean), b.output(output), events=events)


__all__ = ["Acoustics"]
