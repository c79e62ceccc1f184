"""The base of the Kalman-type receivers, :class:`KalmanReceiver`, and the estimate before a receiver's first fix.

A Kalman-type receiver is one class: its parameter declarations, a
``predict`` and a ``correct`` step as casadi expressions
(:class:`KalmanReceiver`); the base class makes the program: a prediction
every step, the correction at every slot (:mod:`sblsim.models.receiver.slots`), the raw instrumentation fix (a
least-squares multilateration of the latest range of every beacon and the
depth, no filter: :mod:`sblsim.models.receiver.instrument`) at the same instants, and the outputs
(:mod:`sblsim.models.receiver.interface`). Before the first
update with a received packet the estimate ``est_*`` is undefined (NaN,
:data:`NO_ESTIMATE`, never the initial state) and ``est_valid`` is false (true
from that update on).

What every receiver shares is one module a job, read bottom up: what it declares
(:mod:`~sblsim.models.receiver.interface`), what its parameters say about its ranges
(:mod:`~sblsim.models.receiver.ranging`), the packets it holds (:mod:`~sblsim.models.receiver.packets`), the
instrumentation fix (:mod:`~sblsim.models.receiver.instrument`), an inverted LBL's pings
(:mod:`~sblsim.models.receiver.pings`), when it takes a packet (:mod:`~sblsim.models.receiver.slots`), the gate's
re-acquisition (:mod:`~sblsim.models.receiver.reacquisition`) and this base.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
"""

from __future__ import annotations

import math

import casadi as ca

from sblsim.models.acoustics.channel.interface import TOA
from sblsim.models.component import Component
from sblsim.models.declarations import Variable
from sblsim.models.program import ProgramBuilder
from sblsim.models.receiver import kalman
from sblsim.models.receiver.gate import gate
from sblsim.models.receiver.instrument import (
    INSTRUMENT_ITERATIONS,
    INSTRUMENT_TOLERANCE,
    lm_active,
    lm_begin,
    lm_idle,
    lm_states,
    lm_step,
)
from sblsim.models.receiver.interface import (
    STATE_NAMES,
    arrival_interface,
    clock_parameters,
    covariance_outputs,
    error_parameters,
    estimate_validity,
    late_inputs,
    ping_parameters,
    range_law_parameters,
    receiver_interface,
    system_interface,
)
from sblsim.models.receiver.measurement import RangeDepthModel
from sblsim.models.receiver.motion import CONSTANT_VELOCITY
from sblsim.models.receiver.packets import fresh_packet, packet_init, packet_states, take_packet
from sblsim.models.receiver.pings import NO_DEPTH, depth_fresh, new_ping, ping_heard
from sblsim.models.receiver.profile import (
    PROFILE_DERIVED,
    declares_profile,
    profile_config_values,
    profile_fmu_parameters,
    profile_parameters,
    profile_prepare,
)
from sblsim.models.receiver.ranging import errors_of, reply_epoch
from sblsim.models.receiver.reacquisition import (
    earlier_innovation,
    first_row,
    rejected_init,
    rejected_states,
    remember_rejected,
)
from sblsim.models.receiver.slots import clock_due, clock_step, clock_tick, slot_events
from sblsim.models.systems import interface_system

#: A receiver's estimate before its first fix (its first update with a received packet; the least-squares
#: receiver's first valid fix): undefined, never its starting guess (``x0_*``, tied to the diver's true start).
#: Every metric skips it (a step without an estimate).
NO_ESTIMATE = math.nan


class RangesWithProfile:
    """What a receiver that declares :func:`~sblsim.models.receiver.profile.profile_parameters` adds to a
    :class:`~sblsim.models.component.Component` (listed before it): its configuration's sound-speed profile
    becomes its FMU table and back."""

    @classmethod
    def fmu_parameters(cls, values, n_beacons: int = 4) -> dict:
        """FMU parameters of a configuration section: the receiver's sound-speed profile becomes its table
        (:func:`~sblsim.models.receiver.profile.profile_fmu_parameters`).

        Raises
        ------
        ModelError
            On a bad ``receiver.sound_speed_profile`` or ``receiver.sound_speed_table``.
        """
        params = super().fmu_parameters(values, n_beacons)
        if declares_profile(cls.fmu_parameters_declared(n_beacons)):
            params.update(profile_fmu_parameters(values))
        return params

    @classmethod
    def config_values(cls, values, n_beacons: int = 4) -> dict:
        """Configuration keys from FMU parameters: a profile table becomes ``sound_speed_profile = table``."""
        out = super().config_values(values, n_beacons)
        if declares_profile(cls.fmu_parameters_declared(n_beacons)):
            out.update(profile_config_values(values))
        return out


class KalmanReceiver(RangesWithProfile, Component):
    """Base of the Kalman-type receivers: a motion model, a measurement model, ``predict`` and ``correct``.

    Subclasses set :attr:`name` (the FMU's, ``receiver_*``) and :attr:`label`
    (what ``simulation.receiver`` and the reports call it), declare
    :meth:`parameters` and implement :meth:`correct`; :meth:`initial` and
    :meth:`predict` default to the :attr:`motion` model (constant velocity
    with white-noise acceleration,
    :class:`~sblsim.models.receiver.motion.ConstantVelocity`, state
    ``[posX, velX, posY, velY, posZ, velZ]``) and the
    :func:`~sblsim.models.receiver.interface.filter_parameters`. The state size, the state names and where the
    position sits come from :attr:`motion`. Everything else (the packet
    handling, the instrumentation fix, the outputs, the FMU, the batched
    engine, the embeddable C) comes from these.
    """

    component_index = 3
    #: The motion model (state layout, Φ, Q).
    motion = CONSTANT_VELOCITY
    #: The measurement model (ranges to broadcast beacons plus depth).
    measurement = RangeDepthModel(CONSTANT_VELOCITY)
    #: Evaluate a packet's rows at the position the motion model gives for the packet's reference epoch
    #: (:meth:`reference`) rather than at the state's own epoch (the paper's ``ekf`` does not).
    backdate = False

    @classmethod
    def epoch(cls, u: dict, p: dict, x: dict | None = None):
        """The reference epoch of a range packet [s]: where its range refers. A one-way range is the travel time
        to the diver where the packet arrives: its reception ``rx_time`` (a receiver that declares its
        ``ranging``); a two-way range is the mean of its two legs, to the diver at interrogation and at
        reception: the midpoint ``(tx_time + rx_time) / 2``, which equals the legs' mean to second order
        (``v² Δt² / (8 r)``: micrometres at a diver's speed); an inverted LBL's time of arrival is the one way
        from the diver's pinger at its emission: the ping's nominal epoch ``tx_time`` plus the emission offset the
        state ``x`` holds (its clock offset)."""
        middle = 0.5 * (u["tx_time"] + u["rx_time"])
        if "ranging" not in p:
            return middle
        epoch = ca.if_else(p["ranging"] == 0, u["rx_time"], middle)  # 0: "owtt"
        if x is None:
            return epoch
        return ca.if_else(p["ranging"] == TOA, u["tx_time"] + cls.motion.clock_offset(x["x"]), epoch)

    @classmethod
    def reference(cls, x: dict, u: dict, epoch) -> ca.SX | None:
        """The map ``A`` (n, n) from the state at the use ``x["now"]`` to the state at a packet's reference epoch
        ``epoch`` [s] (:meth:`epoch`; a USBL packet's reply, :func:`~sblsim.models.receiver.ranging.reply_epoch`), ``A
        = Φ(−(now − t_ref))`` of
        the motion model; the packet's rows are ``h(A x)`` with the Jacobian ``H(A x) A``. None when
        :attr:`backdate` is off."""
        if not cls.backdate:
            return None
        return cls.motion.transition(-ca.fmax(x["now"] - epoch, 0.0))

    @classmethod
    def parameters(cls, n_beacons: int) -> tuple[Variable, ...]:
        """The receiver's own parameters."""
        raise NotImplementedError

    @classmethod
    def late_parameters(cls) -> tuple[Variable, ...]:
        """Parameters declared after the profile's (default: the error states' and the ranging's where the
        motion model carries error states, :func:`~sblsim.models.receiver.interface.error_parameters`)."""
        return error_parameters() if cls.motion.state_size > CONSTANT_VELOCITY.state_size else ()

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        errors = cls.motion.state_size > CONSTANT_VELOCITY.state_size
        return (cls.parameters(n_beacons) + receiver_interface() + clock_parameters() + system_interface(n_beacons)
                + arrival_interface() + profile_parameters() + cls.late_parameters() + late_inputs(n_beacons)
                + (ping_parameters() if errors else ()) + range_law_parameters() + estimate_validity())

    @classmethod
    def errors(cls, p: dict) -> dict | None:
        """The motion model's ``errors`` mapping (:func:`~sblsim.models.receiver.ranging.errors_of`), or None where it
        carries no error states."""
        return errors_of(p) if cls.motion.state_size > CONSTANT_VELOCITY.state_size else None

    @classmethod
    def initial(cls, p: dict) -> tuple[ca.SX, ca.SX]:
        """State (n, 1) and covariance (n, n) at the start (default: ``x0_*``, ``p0_position``, ``p0_velocity``;
        error states at 0 with their priors)."""
        x0 = ca.vertcat(*[p[f"x0_{name}"] for name in STATE_NAMES],
                        ca.SX.zeros(cls.motion.state_size - len(STATE_NAMES)))
        errors = cls.errors(p)
        if errors is None:
            return x0, cls.motion.initial_covariance(p["p0_position"], p["p0_velocity"])
        return x0, cls.motion.initial_covariance(p["p0_position"], p["p0_velocity"], errors)

    @classmethod
    def predict(cls, x: ca.SX, P: ca.SX, h, p: dict) -> tuple[ca.SX, ca.SX]:
        """State and covariance after a step of ``h`` [s] (default: constant velocity, white-noise acceleration;
        the error states' own dynamics)."""
        errors = cls.errors(p)
        if errors is None:
            return cls.motion.predict(x, P, h, p["q_horizontal"], p["q_vertical"])
        return cls.motion.predict(x, P, h, p["q_horizontal"], p["q_vertical"], errors)

    @classmethod
    def correct(cls, x: dict, u: dict, p: dict, n_beacons: int) -> dict:
        """The update at a slot.

        Parameters
        ----------
        x : dict
            The state blocks before the slot: ``x`` (n), ``P`` (n, n), the held
            ranges (``ranges``, ``beacons``, ``heard``), ...
        u : dict
            The inputs (the packet and the depth reading).
        p : dict
            The parameters.

        Returns
        -------
        dict
            ``x``, ``P`` (n, n), ``nis``, ``gated``, ``failed``
            (:func:`~sblsim.models.receiver.gate.gate`), and the held ranges the
            instrumentation fix uses (``ranges``, ``beacons``, ``heard``,
            ``last_seq``, ``slot_time``: usually :func:`~sblsim.models.receiver.packets.take_packet`).
        """
        raise NotImplementedError

    @classmethod
    def packet_update(cls, x: dict, u: dict, p: dict, fresh, model, context, z, covariance) -> dict:
        """The update at a slot with a packet of a measurement model's rows (a system whose packet is not one range,
        :meth:`sblsim.models.systems.System.receiver_update`): the depth, then the rows of a fresh packet, the
        first through the NIS gate (default: the EKF's, the rows decorrelated by
        :func:`~sblsim.models.receiver.kalman.whiten`, the first one alone in its own NIS).

        Parameters
        ----------
        x : dict
            ``x`` (n, 1), ``P`` (n, n), ``failed`` and the held packet states.
        u, p : dict
            The inputs (packet, depth) and parameters (with ``gate_probability``).
        fresh : casadi.SX
            The packet is fresh (received, known beacon).
        model : MeasurementModel
            The packet's measurement model (:mod:`sblsim.models.receiver.measurement`).
        context
            What ``model.h`` needs besides the state (a transceiver's position and attitude).
        z : casadi.SX, (m, 1)
            The packet's measurement.
        covariance : callable
            R (m, m) at a state (n, 1) [units of z squared], symmetric positive definite.

        Returns
        -------
        dict
            What :meth:`correct` returns.
        """
        motion = cls.motion
        depth_row = ca.SX.zeros(1, motion.state_size)
        depth_row[motion.position_index[2]] = 1.0
        state, P, nis_depth = kalman.scalar_update(x["x"], x["P"], u["depth"] - motion.position(x["x"])[2],
                                                   depth_row, p["sigma_depth"] ** 2)
        epoch = reply_epoch(u)
        A = cls.reference(x, u, epoch)
        then = state if A is None else ca.mtimes(A, state)  # the state at the packet's reference epoch
        R = covariance(then)
        h, H = model.linearize(then, context)
        H = H if A is None else ca.mtimes(H, A)
        y = model.residual(z, h)
        checked = gate(y[0], ca.mtimes([H[0, :], P, H[0, :].T]) + R[0, 0], fresh, x, u, p,
                       earlier_innovation(cls, x, u, state, P, first_row(model, context, covariance), 1))
        y_w, H_w = kalman.whiten(y, H, R)
        updated, P_new, nis = kalman.update(state, P, y_w, H_w, ca.SX.ones(y.shape[0]))
        use = checked["use"]
        return {**take_packet(x, u, 1), "x": ca.if_else(use, updated, state), "P": ca.if_else(use, P_new, P),
                "nis": nis_depth + ca.if_else(use, nis, 0.0), "gated": checked["gated"], "failed": checked["failed"],
                **remember_rejected(x, u, checked["rejecting"], z[0], context[0], epoch, 1)}

    @classmethod
    def build(cls, n_beacons: int):
        n = n_beacons
        size, position = cls.motion.state_size, list(cls.motion.position_index)
        rejected = rejected_states(n)
        # a receiver with error states may take an inverted LBL's pings: the depth reading it used last
        pinged = [("depth_seen", 1)] if cls.motion.state_size > CONSTANT_VELOCITY.state_size else []
        b = ProgramBuilder(cls, n, states=[("x", size), ("P", size * size)] + packet_states(n) + [
            ("fix", 3), ("fix_valid", 1), ("nis", 1), ("gated", 1), ("failed", n), ("updated", 1)] + lm_states()
            + rejected + pinged,
                           derived=profile_derived(cls, n))

        def init(p, d, w, t0):
            x0, P0 = cls.initial(p)
            return {"x": x0, "P": ca.vec(P0), **packet_init(n, t0), "fix": ca.SX.zeros(3), "fix_valid": 0, "nis": 0,
                    "gated": 0, "failed": ca.SX.zeros(n), "updated": 0, **lm_idle(), **rejected_init(n),
                    **{name: NO_DEPTH for name, _ in pinged}}

        def remembered(out):
            """The re-acquisition's states a receiver's update returned (one that returns none keeps them)."""
            return {name: out[name] for name, _ in rejected if name in out}

        def step(x, u, p, d, w, t, h):
            state, P = cls.predict(x["x"], ca.reshape(x["P"], size, size), h, p)
            return {"x": state, "P": ca.vec(P), **clock_step(x, p, t, h)}

        system = interface_system(n)

        def slot(x, u, p, d, w, t, h):
            if not system.takes_ranges:
                return packet_slot(x, u, p, t, h)
            P = ca.reshape(x["P"], size, size)
            if "ping_jitter" in p:  # an inverted LBL's new ping: its emission offset's random step first
                P = cls.motion.new_ping(P, p["ping_jitter"], new_ping(x, u, p))
            out = cls.correct({**x, "P": P, "now": t + h}, u, p, n)
            held = {**x, **{k: out[k] for k in ("ranges", "beacons", "heard", "last_seq", "slot_time")}}
            if "ping_jitter" in p:  # an inverted LBL's fix takes one ping's ranges: a new ping's first alone
                held["heard"] = ping_heard(out["heard"], x, u, p, n)
            # the instrumentation fix: from the last fix, else from the filter's position (a start point only)
            guess = ca.if_else(x["fix_valid"], x["fix"], cls.motion.position(out["x"]))
            fix = lm_begin(held, guess, u["depth"], p)
            seen = {"depth_seen": ca.if_else(depth_fresh(x, u, p), u["depth"], x["depth_seen"])} if pinged else {}
            used = ca.logic_and(fresh_packet(u, n), out["gated"] < 0.5)  # a received packet the update took
            return {**held, "x": out["x"], "P": ca.vec(out["P"]), "nis": out["nis"], "gated": out["gated"],
                    "failed": out["failed"], "updated": ca.logic_or(x["updated"], used), **remembered(out), **fix,
                    **seen,
                    "fix": ca.if_else(fix["lm_active"], fix["lm_point"], x["fix"]), "fix_valid": fix["lm_active"]}

        def packet_slot(x, u, p, t, h):
            """A slot of a system whose packet is not one range (USBL): the receiver's update and the system's fix
            of a fresh packet and the depth (:meth:`~sblsim.models.systems.System.packet_fix`)."""
            fresh = fresh_packet(u, 1)
            out = system.receiver_update(cls, {**x, "P": ca.reshape(x["P"], size, size), "now": t + h}, u, p, fresh)
            used = ca.logic_and(fresh, out["gated"] < 0.5)
            return {**x, **out, "P": ca.vec(out["P"]), "updated": ca.logic_or(x["updated"], used),
                    "fix": ca.if_else(fresh, system.packet_fix(u, p, u["depth"])[0], x["fix"]),
                    "fix_valid": ca.logic_or(x["fix_valid"], fresh)}

        def iterate(x, u, p, d, w, t, h):
            out = lm_step(x, p, INSTRUMENT_ITERATIONS, INSTRUMENT_TOLERANCE)
            return {**out, "fix": out["lm_point"]}

        def output(x, p, d, t):
            P = ca.reshape(x["P"], size, size)[position, position]
            updated = x["updated"] > 0.5  # before the first update: no estimate (never the prior, x0_*)
            out = {f"est_{name}": ca.if_else(updated, x["x"][k], NO_ESTIMATE) for k, name in enumerate(STATE_NAMES)}
            out.update({f"instr_{a}": ca.if_else(x["fix_valid"], x["fix"][k], 0.0) for k, a in enumerate("xyz")})
            out.update(instr_valid=x["fix_valid"], nis=x["nis"], pos_std=ca.sqrt(P[0, 0] + P[1, 1] + P[2, 2]),
                       gated=x["gated"], est_valid=updated, **covariance_outputs(P))
            return out

        return b.program(b.prepare(profile_prepare_of(cls, n)), b.init(init), b.output(output), step=b.step(step),
                         events=[b.event("clock", clock_due, clock_tick), *slot_events(b, cls, n, slot),
                                 b.event("lm", lm_active, iterate)])


def profile_derived(model, n_beacons: int) -> list[tuple[str, int]]:
    """The derived blocks of a receiver's ``prepare``: the padded profile of its table where it declares one
    (:data:`~sblsim.models.receiver.profile.PROFILE_DERIVED`), else none."""
    return list(PROFILE_DERIVED) if declares_profile(model.fmu_parameters_declared(n_beacons)) else []


def profile_prepare_of(model, n_beacons: int):
    """The body of a receiver's ``prepare`` (:func:`~sblsim.models.receiver.profile.profile_prepare` where it
    declares a profile; None: nothing derived)."""
    return profile_prepare if profile_derived(model, n_beacons) else None


__all__ = ["KalmanReceiver", "NO_ESTIMATE", "profile_derived", "profile_prepare_of", "RangesWithProfile"]
