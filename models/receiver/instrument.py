"""The raw instrumentation fix: a least-squares (Levenberg-Marquardt) multilateration of the latest range of every
beacon and the depth, no filter, started at a slot and iterated by its own event until it stops moving
(:mod:`sblsim.models.receiver.multilateration`).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.receiver.multilateration import LM_STATE, lm_iteration, lm_start, weights
from sblsim.models.receiver.ranging import range_law, toa_ranging

#: Iteration cap and step tolerance [standard deviations of the fix] of the instrumentation fix.
INSTRUMENT_ITERATIONS, INSTRUMENT_TOLERANCE = 8, 1e-3


def lm_active(x, u, p, d, t, h) -> ca.SX:
    """Guard of the least-squares iteration event: a fix is still moving."""
    return x["lm_active"] > 0.5


def lm_step(x, p, iterations: int, tolerance: float) -> dict[str, ca.SX]:
    """One iteration of the least-squares fix in progress (after :func:`lm_begin`)."""
    w_r, w_d = weights(p["sigma_range"], p["sigma_depth"])
    return lm_iteration(x, x["ranges"], x["beacons"], x["heard"], x["lm_depth"], w_r, w_d, iterations, tolerance,
                        toa_ranging(p), range_law(p))


def lm_states() -> list[tuple[str, int]]:
    """State blocks of a least-squares fix in progress (:data:`LM_STATE` and the depth it uses)."""
    return list(LM_STATE) + [("lm_depth", 1)]


def lm_begin(x, guess, depth, p) -> dict[str, ca.SX]:
    """Start a least-squares fix of the held ranges (after :func:`~sblsim.models.receiver.packets.take_packet`) at a
    slot."""
    w_r, w_d = weights(p["sigma_range"], p["sigma_depth"])
    valid = ca.sum1(x["heard"]) >= 3
    return {**lm_start(guess, x["ranges"], x["beacons"], x["heard"], depth, w_r, w_d, valid, toa_ranging(p),
                       range_law(p)),
            "lm_depth": depth}


def lm_idle() -> dict[str, ca.SX]:
    return {"lm_point": ca.SX.zeros(3), "lm_cost": 0, "lm_mu": 1e-3, "lm_iter": 0, "lm_active": 0, "lm_depth": 0}


__all__ = ["INSTRUMENT_ITERATIONS", "INSTRUMENT_TOLERANCE", "lm_active", "lm_begin", "lm_idle", "lm_states", "lm_step"]
