"""When a receiver takes a packet: its own clock, the slots of a step and the lane each slot takes.

Every receiver runs at its own communication step Δt = T / (EKF rate ratio)
(the ``communication_step`` parameter, set by the orchestrator) and shares
the packet handling (:func:`slot_due`, :func:`~sblsim.models.receiver.packets.take_packet`): a replicate has
a new *slot* when a lane of the channel's delivery holds a packet other than
the last one it used there (lane 1, the packet inputs themselves: its
``packet_seq`` changed; lane m, ``lane<m>_*``: a ``packet_seq`` above 0), the end
of the step has reached the packet's arrival epoch,
``t + h ≥ rx_time − 1 ns`` (the channel delivers a packet in the step that
reaches its arrival, so a receiver stepping faster than the channel uses it
at its first step end after the arrival, never before), and the step has reached a new tick
``t0 + k·Δt`` of the receiver's own clock (:func:`clock_tick`). The last
condition changes nothing when a host steps at Δt, as every host of sblsim
does; it keeps the receiver on its own clock when a host takes other steps:
a host that adds its steps up in floating point ends a run a picosecond
short and then takes a step of 1e-12 s, in which no tick falls, so the
packet it shows then waits for the next tick instead of being used at once.
Packets that arrived in one step are slots of that step, one after the other
in the order they arrived (the lanes' order; :func:`slot_events`).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import lane_fields, lane_name
from sblsim.models.expressions import get_row, sample_due
from sblsim.models.program import ProgramBuilder
from sblsim.models.receiver.pings import new_ping, ping_anchor
from sblsim.models.receiver.profile import (
    profile_range,
    profile_when,
)

#: Slack of the slot test ``t + Δt ≥ rx_time − SLOT_SLACK`` [s] (the channel's delivery test has the same).
SLOT_SLACK = 1e-9


def clock_due(x, u, p, d, t, h) -> ca.SX:
    """Guard of the clock event: the end of the step has reached the receiver's next tick."""
    return sample_due(x["tick"], x["tick_t0"], p["communication_step"], t, h)


def clock_tick(x, u, p, d, w, t, h) -> dict[str, ca.SX]:
    """Handler of the clock event: one more tick reached."""
    return {"tick": x["tick"] + 1}


def clock_step(x, p, t, h) -> dict[str, ca.SX]:
    """The clock's first tick of a step, taken in the step function (the clock event, which runs first, then
    takes only the further ticks of a step longer than the receiver's: the same ticks, one handler call less)."""
    return {"tick": x["tick"] + clock_due(x, None, p, None, t, h)}


def lanes_due(x, u, p, t, h) -> list[ca.SX]:
    """Per lane of the channel's delivery (:data:`~sblsim.models.acoustics.core.LANES`): a new packet whose arrival
    epoch the end of the step has reached, in a step that reached a tick of the receiver's clock (the last tick lies
    after the step's start; the clock event runs first). Lane 1 is new when its ``packet_seq`` differs from the last
    one used there (``last_seq``), lane m when it holds a packet (``packet_seq`` > 0) other than the last one used
    there (``lane_seq``)."""
    ticked = _ticked(x, p, t)
    due = [_lane_one_due(x, u, t, h, ticked)]
    for m in range(2, LANES + 1):
        seq, rx = u[lane_name(m, "packet_seq")], u[lane_name(m, "rx_time")]
        new = ca.logic_and(ca.logic_and(seq > 0, seq != x["lane_seq"][m - 2]), t + h >= rx - SLOT_SLACK)
        due.append(ca.logic_and(new, ticked))
    return due


def _ticked(x, p, t) -> ca.SX:
    """The step reached a tick of the receiver's clock (its last tick lies after the step's start)."""
    return x["tick_t0"] + x["tick"] * p["communication_step"] > t + 1e-6 * p["communication_step"]


def _lane_one_due(x, u, t, h, ticked) -> ca.SX:
    """Lane 1 of the delivery (the packet inputs themselves) is due (:func:`lanes_due`)."""
    return ca.logic_and(ca.logic_and(u["packet_seq"] != x["last_seq"], t + h >= u["rx_time"] - SLOT_SLACK), ticked)


def lane_one_due(x, u, p, t, h) -> ca.SX:
    """Lane 1 holds a packet the receiver may use now and takes first (:func:`lanes_due`; not the first of an
    inverted LBL's new ping, whose lane :func:`~sblsim.models.receiver.pings.ping_anchor` chooses among the ping's
    arrivals)."""
    due = _lane_one_due(x, u, t, h, _ticked(x, p, t))
    return ca.logic_and(due, ca.logic_not(new_ping(x, u, p))) if "ping_jitter" in p else due


def slot_due(x, u, p, t, h) -> ca.SX:
    """A lane of the delivery holds a packet the receiver has not used and may use now (:func:`lanes_due`)."""
    due = lanes_due(x, u, p, t, h)
    any_due = due[0]
    for flag in due[1:]:
        any_due = ca.logic_or(any_due, flag)
    return any_due


def first_lane(due) -> ca.SX:
    """The first due lane (0-based) of the flags ``due`` (:func:`lanes_due`; the last lane where none is)."""
    lane = LANES - 1
    for m in reversed(range(LANES - 1)):
        lane = ca.if_else(due[m], m, lane)
    return lane


def next_lane(x, u, p, t, h, n_beacons: int, model=None) -> tuple[ca.SX, dict[str, ca.SX]]:
    """The lane a slot uses (0-based: the first due one, lanes being in the order of arrival; for an inverted LBL's
    new ping, the receiver ``model``'s :func:`~sblsim.models.receiver.pings.ping_anchor`) and the inputs with that
    lane's packet in place of lane
    1's (its fields :func:`~sblsim.models.acoustics.core.lane_fields`)."""
    due = lanes_due(x, u, p, t, h)
    lane = first_lane(due)
    if model is not None and "ping_jitter" in p:
        lane = ping_anchor(model, x, u, p, t, h, n_beacons, due, lane)
    names = [v.name for v in lane_fields(n_beacons)]  # read at the lane (a parametric index: no if_else per lane)
    chosen = get_row([ca.vertcat(*[u[lane_name(m, name)] for m in range(1, LANES + 1)]) for name in names], lane)
    return lane, {**u, **dict(zip(names, chosen))}


def lane_used(x, out, lane, seq) -> dict[str, ca.SX]:
    """The lanes' memory after a slot used the packet ``seq`` of ``lane`` (0-based; the slot's own ``out`` wrote
    ``last_seq``, kept for lane 1 alone)."""
    return {"last_seq": ca.if_else(lane == 0, out["last_seq"], x["last_seq"]),
            "lane_seq": ca.vertcat(*[ca.if_else(lane == m, seq, x["lane_seq"][m - 1]) for m in range(1, LANES)])}


def slot_update(b: ProgramBuilder, slot) -> ca.Function:
    """A receiver's ``slot`` as one casadi function, ``(x, u, p, d, t, h) -> x`` (the whole state; ``u`` the inputs
    with the packet the slot takes in lane 1's place), that the slot events call rather than inline: the update is
    generated and compiled once, not once per event (the compiler spent half of a receiver's time on the copy)."""
    values = slot(b.X.unpack(b.x), b.inputs(), b.params(), b.D.unpack(b.d), {}, b.t, b.h)
    return ca.Function(f"{b.prefix}_slot_update", [b.x, b.u, b.p, b.d, b.t, b.h],
                       [ca.densify(b.X.pack(values, b.X.unpack(b.x)))], ["x", "u", "p", "d", "t", "h"], ["x_next"],
                       {"never_inline": True})


def slot_events(b: ProgramBuilder, model, n_beacons: int, slot) -> list:
    """The slot events of a receiver: ``slot``, run when lane 1 of the delivery holds a packet it takes first
    (:func:`lane_one_due`: the packet inputs as they are, almost every slot), then ``slot_lanes``, run while a lane
    holds a packet it may use (:func:`slot_due`), each time with the first such lane's packet (:func:`next_lane`:
    the packets that arrived in the same step after lane 1's, and the anchor of an inverted LBL's new ping), in
    that order, as one event taking the first due lane each time would. They are for the single assumed speed;
    ``slot_profile`` and ``slot_profile_lanes`` (the packet's range turned into the slant range of the receiver's
    profile first, :func:`~sblsim.models.receiver.profile.profile_range`) for a run with a profile (a run of the
    assumed speed computes nothing of the profile's, not even its choice). Each calls the one :func:`slot_update`,
    and lane 1's reads its packet where it is rather than at a parametric lane (what every step of a run pays)."""
    update = slot_update(b, slot)

    def due(x, u, p, d, t, h):
        return slot_due(x, u, p, t, h)

    def due_one(x, u, p, d, t, h):
        return lane_one_due(x, u, p, t, h)

    def updated(x, packet, p, d, packet_of, lane):
        packet = packet_of(packet, p, d)
        out = b.X.unpack(update(b.x, ca.vertcat(*[packet[v.name] for v in b.input_vars]), b.p, b.d, b.t, b.h))
        return {**out, **lane_used(x, out, lane, packet["packet_seq"])}

    def on_lane_one(packet_of):
        def handler(x, u, p, d, w, t, h):
            return updated(x, u, p, d, packet_of, 0)
        return handler

    def on_lane(packet_of):
        def handler(x, u, p, d, w, t, h):
            lane, packet = next_lane(x, u, p, t, h, n_beacons, model)
            return updated(x, packet, p, d, packet_of, lane)
        return handler

    events = []
    for choice, when in profile_when(model.fmu_parameters_declared(n_beacons)).items():
        packet_of, name = ((lambda u, p, d: u), "slot") if choice == "assumed" else (profile_range, "slot_profile")
        events.append(b.event(name, due_one, on_lane_one(packet_of), when=when))
        events.append(b.event(f"{name}_lanes", due, on_lane(packet_of), when=when))
    return events


__all__ = ["clock_due", "clock_step", "clock_tick", "first_lane", "lane_one_due", "lane_used", "lanes_due", "next_lane",
           "slot_due", "slot_events", "SLOT_SLACK", "slot_update"]
