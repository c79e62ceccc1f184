"""The NIS gate's re-acquisition: per beacon the last range that failed the gate, the position it was broadcast from
and its reference epoch, and that range's innovation against the current state
(:func:`~sblsim.models.receiver.gate.gate`: two failed ranges that agree are taken as the diver having moved).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.expressions import select


def rejected_states(n_beacons: int) -> list[tuple[str, int]]:
    """State blocks of the gate's re-acquisition: per beacon its last range that failed the test, the position it
    was broadcast from and its reference epoch (:func:`~sblsim.models.receiver.gate.gate`)."""
    return [("rejected_range", n_beacons), ("rejected_beacon", 3 * n_beacons), ("rejected_epoch", n_beacons)]


def rejected_init(n_beacons: int) -> dict[str, ca.SX]:
    return {"rejected_range": ca.SX.zeros(n_beacons), "rejected_beacon": ca.SX.zeros(3 * n_beacons),
            "rejected_epoch": ca.SX.zeros(n_beacons)}


def _pick(u: dict, block, width: int, n_beacons: int) -> ca.SX:
    """The fresh beacon's ``width`` entries of a per-beacon state block."""
    index = u["beacon_id"] - 1
    return ca.vertcat(*[select(index, [block[width * j + a] for j in range(n_beacons)]) for a in range(width)])


def earlier_innovation(receiver, x: dict, u: dict, state, P, row, n_beacons: int, toa=None) -> tuple[ca.SX, ca.SX]:
    """The fresh beacon's last failed range predicted from the current state: its innovation [m] and innovation
    variance [m²] (the gate's re-acquisition).

    ``row(then, beacon)`` gives ``(h, H (1, n), variance)`` of a range from ``beacon`` (3, 1) at the state
    ``then``; the state is moved to the failed range's reference epoch
    (:meth:`~sblsim.models.receiver.core.KalmanReceiver.reference`). Where
    ``toa`` holds (an inverted LBL), the failed range belongs to an earlier ping, whose emission offset the state
    no longer holds: the innovation it had then is remembered instead (:func:`remember_rejected`), and compared
    as it is (two pings whose arrivals from one hydrophone miss alike say the position has drifted).
    """
    rng = _pick(u, x["rejected_range"], 1, n_beacons)
    beacon = _pick(u, x["rejected_beacon"], 3, n_beacons)
    A = receiver.reference(x, u, _pick(u, x["rejected_epoch"], 1, n_beacons))
    then = state if A is None else ca.mtimes(A, state)
    h, H, variance = row(then, beacon)
    H = H if A is None else ca.mtimes(H, A)
    innovation = rng - h if toa is None else ca.if_else(toa, rng, rng - h)
    return innovation, ca.mtimes([H, P, H.T]) + variance


def remember_rejected(x: dict, u: dict, rejecting, rng, beacon, epoch, n_beacons: int) -> dict[str, ca.SX]:
    """The re-acquisition's states after a slot: a fresh range that failed its test (``rejecting``) replaces its
    beacon's range (an inverted LBL's receiver gives its innovation instead: :func:`earlier_innovation`), position
    and epoch."""
    index = u["beacon_id"] - 1
    out = {"rejected_range": [], "rejected_beacon": [], "rejected_epoch": []}
    for j in range(n_beacons):
        mine = ca.logic_and(rejecting, index == j)
        out["rejected_range"].append(ca.if_else(mine, rng, x["rejected_range"][j]))
        out["rejected_beacon"].append(ca.if_else(mine, beacon, x["rejected_beacon"][3 * j:3 * j + 3]))
        out["rejected_epoch"].append(ca.if_else(mine, epoch, x["rejected_epoch"][j]))
    return {name: ca.vertcat(*values) for name, values in out.items()}


def first_row(model, context, covariance):
    """``row(then, transceiver)`` of :func:`earlier_innovation` for a packet whose first row is its range (USBL): the
    model's first row and R's first entry, the transceiver replaced (the rest of the context kept)."""
    def row(then, transceiver):
        ctx = (transceiver, *context[1:])
        h, H = model.linearize(then, ctx)
        return h[0], H[0, :], covariance(then)[0, 0]
    return row


__all__ = ["earlier_innovation", "first_row", "rejected_init", "rejected_states", "remember_rejected"]
