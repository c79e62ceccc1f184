"""An inverted LBL's pings at the receiver: which of a new ping's arrivals sets its emission offset
(:func:`ping_anchor`), which held ranges belong to the ping (:func:`ping_heard`), a short arrival that re-anchors the
offset (:func:`reanchored`), and the depth reading used once per ping's burst (:func:`depth_fresh`).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.acoustics.channel.interface import LANES, TOA
from sblsim.models.acoustics.channel.lanes import lane_name
from sblsim.models.expressions import select
from sblsim.models.receiver.gate import gate_threshold
from sblsim.models.receiver.packets import fresh_packet
from sblsim.models.receiver.ranging import clock_scale, toa_ranging


def ping_anchor(model, x, u, p, t, h, n_beacons: int, due, first) -> ca.SX:
    """The lane an inverted LBL's receiver takes first of a new ping's arrivals delivered in one step: the one whose
    range is the shortest against the prediction (its innovation the least; the emission offset of the state,
    the ranges at the ping's emission), where ``first`` (the first due lane) is as said for any other slot.

    A ping's first update sets its emission offset (the jitter's step leaves it open) and cannot be judged; a
    multipath arrival is late, never early, so the arrival that is the least late against the others is the one
    to set it, whatever the order in which they arrived; the gate then judges the others against it (the same
    information as in the order of arrival, for a filter that takes every arrival: Kalman updates commute).

    Returns
    -------
    casadi.SX
        The lane (0-based).
    """
    field = [{name: u[lane_name(m, name)] for name in ("tx_time", "range", "beacon_id", "packet_valid", "beacon_x",
                                                        "beacon_y", "beacon_z")} for m in range(1, LANES + 1)]
    ping = select(first, [f["tx_time"] for f in field])
    state = x["x"]
    epoch = ping + model.motion.clock_offset(state)
    then = ca.mtimes(model.motion.transition(-ca.fmax(t + h - epoch, 0.0)), state)
    clock = clock_scale(p)
    best, least = first, ca.inf
    for m, f in enumerate(field):
        index = f["beacon_id"] - 1
        taken = ca.logic_and(ca.logic_and(due[m], f["tx_time"] == ping),
                             ca.logic_and(f["packet_valid"], ca.logic_and(index >= 0, index < n_beacons)))
        beacon = ca.vertcat(f["beacon_x"], f["beacon_y"], f["beacon_z"])
        y = f["range"] - model.measurement.range_row(then, beacon, clock)[0]
        better = ca.logic_and(taken, y < least)
        best, least = ca.if_else(better, m, best), ca.if_else(better, y, least)
    return ca.if_else(new_ping(x, {"tx_time": ping}, p), best, first)


def reanchored(motion, state, p: dict, fresh, innovation, H, S) -> tuple[ca.SX, ca.SX]:
    """An inverted LBL's arrival far shorter than predicted re-anchors its ping's emission offset.

    A multipath arrival is late, never early: an arrival whose innovation ``innovation`` [m] is negative beyond the
    NIS gate's threshold against its innovation variance ``S`` [m²], and within that threshold of the ping's jitter
    (the std of the offset's random step, ``ping_jitter``, times the sound speed: what the jitter could have made
    of the offset), says that the ping's earlier arrivals came late and set the emission offset wrong. The offset
    is moved so that this arrival has no innovation (``y / H_o``, ``H`` (1, n) the range's row, ``H_o`` the
    offset's entry: the sound speed) and the arrival is not taken as an update: as re-opening the offset (the
    ping's jitter step again) and updating with the arrival would do, the offset then set by this arrival and the
    position moved by a share ``P_pp / (c² σ_jitter²)`` of the innovation (little); its covariance is kept, that of
    an offset set by one arrival. Nothing for other ranging, or for a receiver without the pinger's parameter.

    Returns
    -------
    state : casadi.SX, (n, 1)
    short : casadi.SX
        The arrival re-anchored the offset (the update skips it).
    """
    if "ping_jitter" not in p:
        return state, 0
    o = motion.clock_index[0]
    q = gate_threshold(p["gate_probability"])
    # beyond the gate, and within what the ping's jitter could make of an emission's offset (a pinger on its
    # schedule, whose offset the state knows, has nothing to re-anchor: its short arrival updates as LBL's does)
    short = ca.logic_and(ca.logic_and(ca.logic_and(fresh, toa_ranging(p)), innovation < 0.0),
                         ca.logic_and(innovation * innovation > q * S,
                                      innovation * innovation < q * (H[o] * p["ping_jitter"]) ** 2))
    moved = ca.vertcat(*[state[i] + (innovation / H[o] if i == o else 0.0) for i in range(motion.state_size)])
    return ca.if_else(short, moved, state), short


def ping_heard(heard, x, u, p, n_beacons: int) -> ca.SX:
    """The held ranges' heard flags (n, 1) after a slot whose packet is the first of a new ping of an inverted LBL
    (:func:`new_ping`): that packet's beacon alone (the earlier ping's ranges carry another emission offset);
    ``heard`` where the slot's packet is not."""
    first, index = new_ping(x, u, p), u["beacon_id"] - 1
    mine = ca.vertcat(*[ca.logic_and(fresh_packet(u, n_beacons), index == j) for j in range(n_beacons)])
    return ca.if_else(first, mine, heard)


#: What the last depth reading a receiver used starts as: no reading (below every depth a sensor gives).
NO_DEPTH = -1e300


def depth_fresh(x: dict, u: dict, p: dict):
    """The slot may use the depth reading: always, but for an inverted LBL's times of arrival (``ranging =
    "toa"``), which arrive several in one sample of the depth sensor (a ping's burst): there a reading is used
    once, at the first slot it differs from the last one used (``depth_seen``); 1 for a receiver that declares no
    ranging."""
    if "ranging" not in p:
        return 1.0
    return ca.logic_or(p["ranging"] != TOA, u["depth"] != x["depth_seen"])


def new_ping(x: dict, u: dict, p: dict):
    """The slot's packet is the first the receiver takes of a new ping of an inverted LBL (its nominal epoch,
    ``tx_time``, is not the last slot's); 0 for other ranging."""
    return ca.logic_and(toa_ranging(p), u["tx_time"] != x["slot_time"]) if "ranging" in p else 0


__all__ = ["depth_fresh", "new_ping", "NO_DEPTH", "ping_anchor", "ping_heard", "reanchored"]
