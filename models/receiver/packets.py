"""The packets a receiver holds: per beacon the latest received range and the position it was broadcast from
(the state blocks, and what a slot's packet changes there).

At a slot a packet that was received (``packet_valid``) with a beacon id in ``1 … n`` is the *fresh* range; it
replaces its beacon's held range and position (:func:`take_packet`), which the instrumentation fix
(:mod:`sblsim.models.receiver.instrument`) and the least-squares receiver fit.
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.acoustics.channel.interface import LANES


def packet_states(n_beacons: int) -> list[tuple[str, int]]:
    """State blocks of the packet handling: held ranges and beacon positions, heard flags, the last slot, and the
    receiver's clock (ticks reached since ``tick_t0``)."""
    return [("ranges", n_beacons), ("beacons", 3 * n_beacons), ("heard", n_beacons), ("last_seq", 1),
            ("slot_time", 1), ("tick", 1), ("tick_t0", 1), ("lane_seq", LANES - 1)]


def packet_init(n_beacons: int, t0) -> dict[str, ca.SX]:
    return {"ranges": ca.SX.zeros(n_beacons), "beacons": ca.SX.zeros(3 * n_beacons),
            "heard": ca.SX.zeros(n_beacons), "last_seq": 0, "slot_time": 0, "tick": 0, "tick_t0": t0,
            "lane_seq": ca.SX.zeros(LANES - 1)}


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


def fresh_range(x: dict, u: dict, n_beacons: int) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The slot's fresh range: whether there is one, its value and its broadcast beacon position (3, 1)."""
    return fresh_packet(u, n_beacons), u["range"], ca.vertcat(u["beacon_x"], u["beacon_y"], u["beacon_z"])


__all__ = ["fresh_packet", "fresh_range", "packet_init", "packet_states", "take_packet"]
