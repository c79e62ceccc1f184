"""A slot's exchange: how the round-robin slot's one-way, two-way or USBL exchange is timed and what it measures.

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
and range and position 0.

The range noise's std ``σ_r`` of every system (below: ``σ_r w``) is ``σ_r = sigma_range + range_k · d`` with d the
range's true length (``range_true``; :mod:`sblsim.models.acoustics.range_law`, after Quazi 1981: a time delay's
bound ∝ 1/√SNR, the SNR ∝ 1/d² with spherical spreading); ``range_k = 0`` (the default) keeps it constant.

Two-way travel time (``ranging = "twtt"``, SBL and LBL). At ``t_k`` the
diver's transceiver interrogates the beacon of the slot from its position
``p`` then (the up leg, ``τ_u = ‖p − b_i‖ / c̄``); the beacon replies after
its turnaround ``t'_ta = max(t_ta + σ_ta w, 0)`` (never before it heard the interrogation, so that no
reply arrives before its interrogation; without jitter ``t_ta``); the reply reaches the diver at
``t_k + τ_u + t'_ta + τ_d`` (the down leg to the diver's position at
reception, solved as above). The receiver measures the round trip
``Δt_m = (τ_u + t'_ta + τ_d)(1 + δ)`` on its own clock and
subtracts the nominal turnaround: ``r = c_assumed (Δt_m − t_ta) / 2 +
σ_r w + e_mp``. Clock offsets cancel and a drift acts only over Δt; the
turnaround jitter enters the range as ``c σ_ta / 2`` (a jitter comparable to ``t_ta`` is cut at 0: the range
then errs long on average); the range is the mean
of the two legs (``range_true``), so it refers to the diver's positions at
interrogation and at reception (their mean, to first order).

USBL (the interface of one beacon: the platform's transceiver). At ``t_k``
the transceiver interrogates the diver's transponder (up leg to the diver at
reception), which replies after its turnaround from where it is then; the
slant range is the TWTT range above, and the array measures the reply's
**direction of arrival** in its own frame (attitude ``array_*``: the
platform's plus the mounting misalignment, tilted by the waves) as a planar
phase-difference array does: the direction cosines ``a_x``, ``a_y`` of the
line of sight across its two axes, each with noise ``σ_u``
(``usbl_angle_sigma_deg`` in radians: the angle's std on the array's axis,
body down; off the axis the angle error grows as ``σ_u / cos θ``, the
direction cosines' does not), the wavefront taken as arriving from below the
array's plane (a pair outside the unit circle put in it). The surface turns
the measured direction into NED with the IMU's attitude (``imu_*``) and sends
range, azimuth, elevation (NED: azimuth clockwise from North, elevation below
the horizontal), the direction cosines as the array measured them (``doa_x``,
``doa_y``) with the attitude it used (``doa_roll``, ``doa_pitch``, ``doa_yaw``:
what a receiver measures,
:class:`~sblsim.models.receiver.range_direction.RangeDirectionModel`) and its
transceiver position (GPS and IMU) down to the diver on
the acoustic link: the packet is lost when the reply or the downlink is lost
(two draws of ``p_loss``), and it reaches the diver a downlink travel time
after the reply reached the surface (delivered at its arrival like every
packet); the measurement refers to the diver's position at the reply.

Each packet then travels in flight to its arrival and is delivered on a lane
(:mod:`~sblsim.models.acoustics.channel.lanes`); its legs are :mod:`~sblsim.models.acoustics.channel.legs`'.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4
(round-robin OWTT, range noise, packet loss). Eustice, Singh, Leonard,
"Synchronous-clock one-way-travel-time acoustic navigation for underwater
vehicles", J. Field Robotics 28(1), 2011 (OWTT with synchronized clocks).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import casadi as ca

from sblsim.models.acoustics import sonar
from sblsim.models.acoustics.channel.interface import (
    _ANGLE_NOISE,
    _CHANNEL_UNIFORM,
    _DETECTION,
    _DOWNLINK,
    _RANGE_NOISE,
    _TURNAROUND,
    ATTITUDE_ANGLES,
    DETECTION_DRAWS,
    TARGET_INPUTS,
)
from sblsim.models.acoustics.channel.lanes import _send
from sblsim.models.acoustics.channel.legs import _leg, _Slot
from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.expressions import select
from sblsim.models.platform.core import AXES
from sblsim.models.platform.geometry import rotation_ned


def _two_way(p, up, down, turnaround, drift):
    """Range, true range and round trip of a two-way exchange: ``up`` and ``down`` are the legs (:func:`_leg`),
    ``turnaround`` the transponder's [s], ``drift`` the clock's [1]."""
    trip = up[0] + turnaround + down[0]
    measured = trip * (1.0 + drift)
    return p["sound_speed_assumed"] * (measured - p["turnaround"]) / 2.0, (up[1] + down[1]) / 2.0, trip


class _Exchange(NamedTuple):
    """A slot's exchange (:func:`_exchange`): the measured range [m], the true range [m] and travel time [s]
    the packet reports, its arrival at the diver [s], whether it is still valid, its timing legs and the leg that
    carries its data (:func:`_leg`'s tuples), when its last heard arrival ends after the slot's start [s], the
    last leg (its eigenray: from the beacon to the diver, or the diver's reply to the transceiver) and the first
    leg's path (1 for one way)."""

    rng: Any
    distance: Any
    tau: Any
    arrival: Any
    valid: Any
    timing: tuple
    data: tuple
    spread_end: Any
    last: tuple
    up_kind: Any


def _exchange(e: _Slot, w, ranging: str, direction: bool, valid) -> _Exchange:
    """The legs of the slot ``e``'s exchange and what they measure: the interface's system's when it measures a
    ``direction`` (USBL: the transceiver interrogates, the diver replies, the surface sends the fix down), else
    one way (``owtt``) or two way (``twtt``, the diver interrogates); ``valid``: the packet before the legs."""
    p, x, t_k = e.p, e.x, e.t_k
    drift = p["clock_drift_ppm"] * 1e-6
    if ranging == "twtt":  # the replying transponder's turnaround: never before it heard the interrogation
        # (a draw below 0 replies at once; without jitter the nominal turnaround, >= 0, is kept as it is)
        turnaround = ca.fmax(p["turnaround"] + p["turnaround_sigma"] * w[_TURNAROUND][0], 0.0)
    if direction:  # the transceiver interrogates; the diver replies from where it is then
        up = _leg(e, None, True)
        reply = _leg(e, up[0] + turnaround, False, 3)
        up_kind = up[3][2]
        rng, distance, tau = _two_way(p, up, reply, turnaround, drift)
        # the surface measures at the reply's arrival and sends the fix down to the diver
        downlink = _leg(e, tau, True, 6)
        arrival = t_k + tau + downlink[0]
        if e.draws is not None:  # snr: the fix reaches the diver when the downlink is heard
            valid = downlink[3][2] > 0
        else:
            valid = ca.logic_and(valid, w[_DOWNLINK][0] >= p["loss_pct"] / 100.0)  # reply, downlink
        timing, data, last = (up, reply), downlink, reply
        spread_end = tau + downlink[6]  # the downlink's multipath ends the exchange
    elif ranging == "owtt":
        owtt_leg = _leg(e, None, True)
        tau, distance, up_kind = owtt_leg[0], owtt_leg[1], 1.0
        measured = tau + drift * (t_k - x["t0"] + tau)
        rng = p["sound_speed_assumed"] * measured
        arrival = t_k + tau
        timing, data, last = (owtt_leg,), owtt_leg, owtt_leg
        spread_end = owtt_leg[6]
    else:  # TWTT: the diver interrogates from where it is at t_k, the reply reaches it later
        up = _leg(e, None, False)
        down = _leg(e, up[0] + turnaround, True, 3)
        up_kind = up[3][2]
        rng, distance, tau = _two_way(p, up, down, turnaround, drift)
        arrival = t_k + tau
        timing, data, last = (up, down), down, down
        spread_end = up[0] + turnaround + down[6]
    return _Exchange(rng, distance, tau, arrival, valid, timing, data, spread_end, last, up_kind)


def _direction_of_arrival(direction, u, p, w_angle, scale=1.0):
    """Measured azimuth and elevation (NED) [rad] of a reply arriving along ``direction`` (3, 1), and the
    direction cosines the array measured: the array (attitude ``array_*``) measures the direction cosines
    of the line of sight across its two axes, each with the noise ``scale`` σ_u (σ_u =
    ``usbl_angle_sigma_deg`` [rad], the angle's std on the array's axis), takes the wavefront as
    arriving from below its plane, and the surface turns the direction into NED with the IMU's attitude
    (``imu_*``)."""
    array = rotation_ned(*[u[f"array_{a}"] for a in ("roll", "pitch", "yaw")])
    # in the array's frame (axis = body down); a diver at the transceiver is seen on the axis, not as NaN
    seen = ca.mtimes(array.T, direction / ca.fmax(ca.norm_2(direction), 1e-9))
    sigma = scale * p["usbl_angle_sigma_deg"] * (ca.pi / 180.0)
    ux, uy = seen[0] + sigma * w_angle[0], seen[1] + sigma * w_angle[1]
    across = ca.sqrt(ux ** 2 + uy ** 2)
    shrink = 1.0 / ca.fmax(across, 1.0)  # a measured pair beyond the unit circle: in the array's plane
    measured = ca.vertcat(ux * shrink, uy * shrink, ca.sqrt(ca.fmax(1.0 - across ** 2, 0.0)))
    ned = ca.mtimes(rotation_ned(*[u[f"imu_{a}"] for a in ATTITUDE_ANGLES]), measured)
    return ca.atan2(ned[1], ned[0]), ca.atan2(ned[2], ca.sqrt(ned[0] ** 2 + ned[1] ** 2)), ux, uy


def _slot(n: int, true_names: list[str], sent_names: list[str], direction: bool, queue: list, carried: list,
          ranging: str, propagation: str, detection: str):
    """The handler of a slot of a channel of ``n`` beacons (their input names ``true_names``, ``sent_names``): of
    the interface's system when it measures a ``direction`` (USBL) or of ``ranging`` (SBL and LBL), with the
    travel times of ``propagation`` and what ``detection`` hears; the packet joins the in-flight ``queue``
    (:func:`_send`)."""
    snr_mode = detection == "snr"

    def handler(x, u, p, d, w, t, h):
        k = x["k"] + 1
        t_k = x["t0"] + k * p["slot_period"]
        i = ca.fmod(k - 1, n)
        beacon = ca.vertcat(*[select(i, [u[true_names[3 * j + a]] for j in range(n)]) for a in range(3)])
        sent = ca.vertcat(*[select(i, [u[sent_names[3 * j + a]] for j in range(n)]) for a in range(3)])
        position = ca.vertcat(*[u[name] for name in TARGET_INPUTS[:3]])
        velocity = ca.vertcat(*[u[name] for name in TARGET_INPUTS[3:]])
        heard_draws = w[_DETECTION] if snr_mode else None
        e = _Slot(propagation, t_k, beacon, position, velocity, x, p, d, heard_draws)

        draws, noise = w[_CHANNEL_UNIFORM], w[_RANGE_NOISE][0]
        if snr_mode:  # what is heard decides loss and multipath (the percentages are not drawn)
            valid, outlier, excess = 1, 0, 0.0
        else:
            valid = draws[0] >= p["loss_pct"] / 100.0
            outlier = draws[1] < p["outlier_pct"] / 100.0
            excess = ca.if_else(outlier, -p["outlier_excess"] * ca.log1p(-draws[2]), 0.0)

        rng, distance, tau, arrival, valid, timing, data, spread_end, last, up_kind = _exchange(
            e, w, ranging, direction, valid)
        launch, arrival_angle, kind = last[3]
        if direction:  # reversed: the reply leaves the diver and arrives at the transceiver
            launch, arrival_angle = -arrival_angle, -launch
        kind = ca.if_else(ca.logic_and(kind > 0, up_kind > 0), kind, 0.0)
        valid = ca.logic_and(valid, kind > 0)  # a shadow zone (or nothing heard): the packet is lost
        scale, angle_scale = 1.0, 1.0
        if snr_mode:
            # the packet's data needs its margin above the threshold (its own draw); a range from a
            # reflected arrival on any leg carries that path's excess
            decoded = heard_draws[DETECTION_DRAWS - 1] < sonar.detection_probability(
                data[4], p["detection_threshold"] + p["decoding_margin"], p["fluctuation"])
            valid = ca.logic_and(valid, decoded)
            for part in timing:
                outlier = ca.logic_or(outlier, part[3][2] > 1.5)
            # the timing noise of each leg grows below the reference SNR (their mean variance)
            scales = [sonar.accuracy_scale(part[4], p["reference_snr"]) for part in timing]
            scale = ca.sqrt(sum(s_ * s_ for s_ in scales) / len(scales))
            angle_scale = scales[-1]
        rng = rng + range_noise_sigma(p, distance) * scale * noise + excess
        out = {"launch_angle": launch, "arrival_angle": arrival_angle, "arrival": kind,
               "packet_seq": k, "beacon_id": i + 1, "packet_valid": valid, "tx_time": t_k,
               "range": ca.if_else(valid, rng, 0.0), "travel_time": tau, "range_true": distance,
               "outlier": ca.logic_and(outlier, valid), "rx_time": arrival,
               "snr": last[4], "detection_probability": last[5]}
        out.update({f"beacon_{a}": ca.if_else(valid, sent[j], 0.0) for j, a in enumerate(AXES)})
        overrun = {}
        if snr_mode:  # the exchange's last heard arrival after the next slot began: flagged
            overrun = {"slot_overrun": ca.if_else(spread_end > p["slot_period"], ca.fmax(
                x["slot_overrun"], spread_end), x["slot_overrun"])}
        if direction:
            arrives = last[2] - beacon  # the reply's leg
            if propagation == "ray":  # along the reply's eigenray: the chord's azimuth (a range-independent
                # profile), the eigenray's grazing angle at the transceiver (reciprocal: its launch toward
                # the diver, the reply's −arrival_angle) as the elevation
                level = ca.norm_2(arrives[:2])
                east, north = ca.if_else(level > 0, arrives[1] / level, 0.0), ca.if_else(level > 0,
                                                                                       arrives[0] / level, 1.0)
                grazing = last[3][0]
                arrives = ca.vertcat(north * ca.cos(grazing), east * ca.cos(grazing), ca.sin(grazing))
            measured = _direction_of_arrival(arrives, u, p, w[_ANGLE_NOISE], angle_scale)
            out.update({name: ca.if_else(valid, value, 0.0) for name, value in zip(
                ("azimuth", "elevation", "doa_x", "doa_y"), measured)})
            out.update({f"doa_{a}": ca.if_else(valid, u[f"imu_{a}"], 0.0) for a in ATTITUDE_ANGLES})
        return {"k": k, **_send(queue, carried, x, p, out, arrival - t_k), **overrun}
    return handler
