"""The channel's delivery: the packets in flight and the lanes they are delivered on at their arrival.

The packet of slot k is computed at ``t_k`` (from the
inputs of the step that reaches ``t_k``) with its **arrival** ``a_k`` at the
diver: ``t_k + τ`` (OWTT), ``t_k`` plus the round trip the truth gives
(TWTT: up leg, turnaround with its jitter, down leg), and for USBL the reply's
arrival at the surface plus the downlink's travel time to the diver where it
is then. It is then **in flight**: the channel holds up to
:data:`FLIGHT_CAPACITY` packets sent and not yet arrived in its state. In
each step, after the slots the step reaches were sent, **every** packet in
flight that has arrived (``a ≤ t + h``) is delivered, on the **lanes** of
the delivery in the order of arrival (then of slot counter): the earliest
on the packet outputs themselves (lane 1, with ``rx_time = a_k``), the next
ones on ``lane2_*``, ``lane3_*``, … (:data:`LANES` = :data:`FLIGHT_CAPACITY`
lanes, so that every packet in flight fits; a lane left empty shows
``packet_seq`` 0). None is delivered before it arrives, none is held behind
another, and the outputs show the last delivery until the next. A step that
reaches several slot epochs sends each of them (each with its own random
numbers).
Every receiver uses each lane's packet at its first step end that reaches
its ``rx_time``, in lane order (:func:`sblsim.models.receiver.slots.slot_events`). A packet that
finds every place taken is not dropped silently: ``overflow_travel_time``
keeps the longest arrival − transmit of it and of those in flight, and the
orchestrator refuses the run (:func:`check_in_flight`: a packet must arrive
within ``FLIGHT_CAPACITY − 1`` slots, so the turnaround alone is checked
before a run).

The queue in flight is the channel's state (``q_<output>`` per place and ``q_used``): :func:`_send` puts a packet
in its first free place, :func:`_arrived` tells the places whose packet the step's end has reached; the
component's ``deliver`` events empty them onto the lanes (:func:`lane_name`, :func:`lane_variables`).
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import casadi as ca

from sblsim.models.acoustics.channel.interface import (
    ARRIVAL,
    ARRIVAL_SLACK,
    DIRECTION,
    DOA_ARRAY,
    EXCHANGE,
    FLIGHT_CAPACITY,
    LANES,
    PACKET,
    TOA,
)
from sblsim.models.declarations import Variable
from sblsim.models.errors import ModelError
from sblsim.models.expressions import NO_ROW, put_row
from sblsim.models.systems import interface_system


def lane_fields(n_beacons: int) -> tuple[Variable, ...]:
    """What a packet carries to a receiver (the channel's outputs a receiver reads): :data:`PACKET`, what the
    interface's system adds (USBL: :data:`DIRECTION`), its arrival (:data:`ARRIVAL`) and what the system adds last
    (USBL: :data:`DOA_ARRAY`)."""
    direction = interface_system(n_beacons).measures_direction
    return PACKET + (DIRECTION if direction else ()) + ARRIVAL + (DOA_ARRAY if direction else ())


def lane_name(lane: int, name: str) -> str:
    """The name of the field ``name`` of a packet on ``lane`` (1-based; lane 1: the name itself)."""
    return name if lane == 1 else f"lane{lane}_{name}"


_LANE_NAME = re.compile(r"^lane(\d+)_(.+)$")


def lane_of(name: str) -> tuple[int, str] | None:
    """The lane (2 … :data:`LANES`) and the field of a later lane's variable ``name`` (:func:`lane_name`'s
    inverse); None for any other name."""
    match = _LANE_NAME.match(name)
    return None if match is None else (int(match.group(1)), match.group(2))


def lane_variables(n_beacons: int, causality: str) -> tuple[Variable, ...]:
    """The fields of lanes 2 … :data:`LANES` (:func:`lane_fields`), as a receiver's inputs (``causality``
    ``"input"``) or the channel's outputs (``"output"``, with the truth of each exchange, :data:`EXCHANGE`):
    declared after every other variable of either, so that their value references stay what they were before the
    lanes existed."""
    def lanes(fields):
        return tuple(replace(v, name=lane_name(m, v.name), causality=causality,
                             description=f"Lane {m} of a delivery (the packets that arrived in a step, in order; "
                                         f"packet_seq 0: none): {v.description}")
                     for m in range(2, LANES + 1) for v in fields)
    # the receiver's fields of every lane first, in the receiver's order (a host copies them as one block)
    return lanes(lane_fields(n_beacons)) + (lanes(EXCHANGE) if causality == "output" else ())


def check_in_flight(slot_period: float, turnaround: float, elapsed: float | None = None,
                    jitter: float = 0.0) -> None:
    """Refuse a run whose packets stay in flight longer than the channel can hold them.

    A packet that arrives Δ after its transmit epoch is delivered in the step that reaches its arrival,
    ⌈Δ / T⌉ steps of T after the one that sent it, and the channel sends one packet per slot: with
    :data:`FLIGHT_CAPACITY` places C, a packet must arrive within ``Δ ≤ (C − 1) T``.

    Parameters
    ----------
    slot_period : float
        T = ``simulation.sampling_time`` [s].
    turnaround : float
        The nominal turnaround of two-way ranging (0 for one-way) [s].
    elapsed : float, optional
        The longest Δ a run saw (the channel's ``overflow_travel_time``; 0: nothing refused). None: the check
        before a run, of the turnaround alone (the travel time is not known yet).
    jitter : float
        The turnaround's jitter, ``acoustics.turnaround_sigma`` of two-way ranging (0 for one-way) [s]: part of
        Δ, named with it.

    Raises
    ------
    ModelError
        One line naming ``simulation.sampling_time``, what makes the flight long (the turnaround and its jitter
        where they are not 0, the travel time) and the shortest sampling time that holds it.
    """
    limit = (FLIGHT_CAPACITY - 1) * slot_period
    shorter = ["acoustics.turnaround"] if turnaround > 0.0 or elapsed is None else []
    if elapsed is None:
        if turnaround < limit:
            return
        late, causes = turnaround, f"acoustics.turnaround = {turnaround:g} s and the travel times on top"
    else:
        if not elapsed > 0.0:
            return
        late = elapsed
        causes = [f"acoustics.turnaround = {turnaround:g} s"] if turnaround > 0.0 else []
        if jitter > 0.0:
            causes.append(f"its jitter acoustics.turnaround_sigma = {jitter:g} s")
            shorter.append("acoustics.turnaround_sigma")
            travel = "the travel time"  # not told apart from the jitter's draw
        else:
            travel = f"a travel time of {max(elapsed - turnaround, 0.0):.4g} s"
        causes = ", ".join(causes + [travel]) if causes else travel
    raise ModelError(
        f"simulation.sampling_time: {slot_period:g} s is too short for {causes}: a packet arrives {late:.4g} s after "
        f"it is sent, {math.ceil(late / slot_period - 1e-9) + 1} packets in flight, and the channel holds "
        f"{FLIGHT_CAPACITY} (an arrival within {FLIGHT_CAPACITY - 1} sampling times); give a simulation.sampling_time "
        f"above {late / (FLIGHT_CAPACITY - 1):.4g} s" + "".join(f" or a smaller {key}" for key in shorter))


def _send(queue, carried, x, p, out, elapsed):
    """The in-flight queue (state ``queue``: ``(name, size)``, the packet's ``carried`` outputs and ``q_used``)
    after a packet ``out`` (by output name) left ``elapsed`` before it arrives [s]: in the first
    free in-flight place; none free, the longest arrival − transmit of it and of those in flight is kept in
    ``overflow_travel_time`` (the run is refused, :func:`check_in_flight`)."""
    place = NO_ROW  # the first free place (none: nowhere)
    for j in reversed(range(FLIGHT_CAPACITY)):
        place = ca.if_else(x["q_used"][j] < 0.5, j, place)
    placed = place < FLIGHT_CAPACITY
    columns = put_row([x[name] for name, _ in queue], place, [*(out[name] for name in carried), 1.0])
    new = {name: column for (name, _), column in zip(queue, columns)}
    longest = elapsed  # the longest in flight then, for the refusal's message
    for j in range(FLIGHT_CAPACITY):
        sent_at = x["t0"] + x["q_packet_seq"][j] * p["slot_period"]
        # a ping's packet (toa) left at its emission, a travel time before it arrives
        flight = ca.if_else(p["ranging"] == TOA, x["q_travel_time"][j], x["q_rx_time"][j] - sent_at)
        longest = ca.fmax(longest, ca.if_else(x["q_used"][j] > 0.5, flight, 0.0))
    refused = ca.if_else(placed, x["overflow_travel_time"], ca.fmax(x["overflow_travel_time"], longest))
    return {**new, "overflow_travel_time": refused}


def _arrived(x, t, h):
    """Per in-flight place: it holds a packet whose arrival the end of the step has reached."""
    return [ca.logic_and(x["q_used"][j] > 0.5, x["q_rx_time"][j] <= t + h + ARRIVAL_SLACK)
            for j in range(FLIGHT_CAPACITY)]


__all__ = ["check_in_flight", "lane_fields", "lane_name", "lane_of", "lane_variables"]
