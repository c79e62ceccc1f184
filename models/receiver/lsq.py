"""Least-squares receiver: a per-slot Levenberg-Marquardt multilateration fix, no filter.

At every new slot (the packet handling of :mod:`sblsim.models.receiver.slots`) the
receiver fits its position to the held range of every beacon heard so far and
the depth reading by weighted least squares,

``F(p) = Σ_i ((r_i − ‖p − b_i‖) / σ_r)² + ((d − p_z) / σ_d)²``,

with the Levenberg-Marquardt iteration of :mod:`sblsim.models.receiver.multilateration`
(damped Gauss-Newton) started from the previous fix, to a tighter tolerance
than the instrumentation's (the fix is this receiver's estimate). Nothing is
filtered: the estimate is the latest valid fix of a slot that brought a fresh
range, and the velocity is the finite difference of the last two such fixes
over the time between their slots (a slot whose packet was lost refits the
same held ranges: it changes neither). Before the first fix the estimate is
undefined (NaN, position and velocity: :data:`~sblsim.models.receiver.core.NO_ESTIMATE`,
and ``est_valid`` false; true from the first fix on): the initial guess x0 only
starts the first iteration, it is never reported (the configuration ties it to
the diver's true start). With a USBL interface
the fix is the least-squares fix of the packet's range and direction and the
depth, with its covariance and its weighted residual (``nis``, one degree of
freedom: :func:`sblsim.models.systems.usbl_fix.packet_fix`), R with the transceiver's uncertainty of the beacon
parameters (:func:`~sblsim.models.receiver.interface.beacon_parameters`, declared last). The receiver is its own
instrumentation: ``instr_*`` is the same fix (0 when a slot has fewer than
three ranges, ``instr_valid`` false).

At the solution ``p̂`` it also reports the fit's weighted sum of squared
residuals ``F(p̂)`` (``nis``; chi-square with ``n + 1 − 3`` degrees of
freedom for correct σ and n ranges) and the Gauss-Newton position covariance
``(JᵀWJ)⁻¹`` through ``pos_std = sqrt(trace((JᵀWJ)⁻¹))``.

References
----------
Foy, "Position-location solutions by Taylor-series estimation", IEEE Trans.
Aerospace and Electronic Systems AES-12(2), 187-194, 1976.
Kay, Fundamentals of Statistical Signal Processing, Vol. 1: Estimation
Theory, Prentice Hall 1993: Chapter 8 (nonlinear least squares) and
Chapter 3 (the Fisher information ``JᵀWJ``).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.component import Component
from sblsim.models.declarations import SEED_PARAMETERS, Variable
from sblsim.models.program import ProgramBuilder
from sblsim.models.receiver.core import NO_ESTIMATE, RangesWithProfile, profile_derived, profile_prepare_of
from sblsim.models.receiver.instrument import lm_active, lm_begin, lm_idle, lm_states, lm_step
from sblsim.models.receiver.interface import (
    arrival_interface,
    beacon_parameters,
    clock_parameters,
    covariance_outputs,
    estimate_validity,
    filter_parameters,
    late_inputs,
    range_law_parameters,
    receiver_interface,
    system_interface,
)
from sblsim.models.receiver.multilateration import fix_covariance, weights
from sblsim.models.receiver.packets import fresh_packet, packet_init, packet_states, take_packet
from sblsim.models.receiver.profile import profile_parameters
from sblsim.models.receiver.ranging import range_law
from sblsim.models.receiver.slots import clock_due, clock_tick, slot_events
from sblsim.models.systems import interface_system

#: The Kalman receivers' parameters this receiver takes (declared once, in sblsim.models.receiver.core).
SHARED_PARAMETERS = ("sigma_range", "sigma_depth", "x0_x", "x0_y", "x0_z")
#: Iteration cap and step tolerance [standard deviations of the fix].
ITERATIONS, TOLERANCE = 50, 1e-6


class LeastSquaresReceiver(RangesWithProfile, Component):
    """Per-slot weighted least-squares (Levenberg-Marquardt) multilateration receiver."""

    name = "receiver_lsq"
    component_index = 3

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        shared = {v.name: v for v in filter_parameters()}
        return (tuple(shared[n] for n in SHARED_PARAMETERS) + SEED_PARAMETERS + receiver_interface()
                + clock_parameters() + system_interface(n_beacons) + arrival_interface() + profile_parameters()
                + beacon_parameters() + late_inputs(n_beacons) + range_law_parameters() + estimate_validity())

    @classmethod
    def build(cls, n_beacons: int):
        n = n_beacons
        b = ProgramBuilder(cls, n, states=packet_states(n) + [
            ("fix", 3), ("has_fix", 1), ("fix_time", 1), ("velocity", 3), ("instr", 3), ("instr_valid", 1),
            ("nis", 1), ("pos_std", 1), ("cov", 9), ("pending", 1), ("fresh", 1)] + lm_states(),
                           derived=profile_derived(cls, n))

        def init(p, d, w, t0):
            return {**packet_init(n, t0), "fix": ca.vertcat(p["x0_x"], p["x0_y"], p["x0_z"]), "has_fix": 0,
                    "fix_time": 0, "velocity": ca.SX.zeros(3), "instr": ca.SX.zeros(3), "instr_valid": 0, "nis": 0,
                    "pos_std": 0, "cov": ca.SX.zeros(9), "pending": 0, "fresh": 0, **lm_idle()}

        system = interface_system(n)

        def slot(x, u, p, d, w, t, h):
            held = {**x, **take_packet(x, u, n)}
            fresh = fresh_packet(u, n)
            if not system.takes_ranges:  # the system's fix of one packet and the depth (USBL): no LM iteration
                point, covariance, rss = system.packet_fix(u, p, u["depth"])
                return {**held, **lm_idle(), "lm_point": ca.if_else(fresh, point, x["lm_point"]),
                        "cov": ca.if_else(fresh, ca.vec(covariance), x["cov"]), "nis": ca.if_else(fresh, rss, x["nis"]),
                        "pending": 1, "fresh": fresh}
            return {**held, **lm_begin(held, x["fix"], u["depth"], p), "pending": 1, "fresh": fresh}

        def iterate(x, u, p, d, w, t, h):
            return lm_step(x, p, ITERATIONS, TOLERANCE)

        def finished(x, u, p, d, t, h):
            return ca.logic_and(x["pending"] > 0.5, x["lm_active"] < 0.5)

        def finish(x, u, p, d, w, t, h):
            """Fit statistics and finite-difference velocity of the slot's fix."""
            point = x["lm_point"]
            if not system.takes_ranges:  # the packet's fix (slot): its residual and covariance
                valid = x["heard"][0] > 0.5
                rss, covariance = x["nis"], ca.reshape(x["cov"], 3, 3)
            else:
                valid = ca.sum1(x["heard"]) >= 3
                w_r, w_d = weights(p["sigma_range"], p["sigma_depth"])
                rss, covariance, _ = fix_covariance(point, x["ranges"], x["beacons"], x["heard"], x["lm_depth"], w_r,
                                                    w_d, range_law(p))
            new = ca.logic_and(valid, x["fresh"])  # a fix with new information
            spread = ca.sqrt(ca.fmax(ca.trace(covariance), 0.0))
            elapsed = x["slot_time"] - x["fix_time"]
            differentiate = ca.logic_and(new, ca.logic_and(x["has_fix"], elapsed > 0.0))
            rate = (point - x["fix"]) / ca.if_else(differentiate, elapsed, 1.0)
            return {"pending": 0, "instr_valid": valid, "instr": ca.if_else(valid, point, ca.SX.zeros(3)),
                    "nis": ca.if_else(valid, rss, 0.0), "pos_std": ca.if_else(valid, spread, 0.0),
                    "cov": ca.if_else(valid, ca.vec(covariance), ca.SX.zeros(9)),
                    "velocity": ca.if_else(differentiate, rate, x["velocity"]),
                    "fix": ca.if_else(new, point, x["fix"]),
                    "fix_time": ca.if_else(new, x["slot_time"], x["fix_time"]),
                    "has_fix": ca.logic_or(x["has_fix"], new)}

        def output(x, p, d, t):
            fixed = x["has_fix"] > 0.5  # none yet: no estimate (never the starting guess)
            out = {f"est_{a}": ca.if_else(fixed, x["fix"][k], NO_ESTIMATE) for k, a in enumerate("xyz")}
            out.update({f"est_v{a}": ca.if_else(fixed, x["velocity"][k], NO_ESTIMATE) for k, a in enumerate("xyz")})
            out.update({f"instr_{a}": x["instr"][k] for k, a in enumerate("xyz")})
            out.update(instr_valid=x["instr_valid"], nis=x["nis"], pos_std=x["pos_std"], gated=0, est_valid=fixed,
                       **covariance_outputs(ca.reshape(x["cov"], 3, 3)))
            return out

        return b.program(b.prepare(profile_prepare_of(cls, n)), b.init(init), b.output(output),
                         events=[b.event("clock", clock_due, clock_tick), *slot_events(b, cls, n, slot),
                                 b.event("lm", lm_active, iterate),
                                 b.event("finish", finished, finish)])


__all__ = ["ITERATIONS", "LeastSquaresReceiver", "SHARED_PARAMETERS", "TOLERANCE"]
