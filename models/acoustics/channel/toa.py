"""Times of arrival: a ping of the target's pinger heard at the fixed receivers of an inverted LBL (the
roles turned round).

Times of arrival (``ranging = "toa"``, the inverted LBL: the roles turned round). The target's pinger emits ping c
at ``e_c = e_{c−1} + P (1 + δ) + j_c`` on its own clock (P = ``ping_interval``, 0 taking the cycle ``n T``; δ the
drift ``clock_drift_ppm``; ``j_c`` uniform of zero mean and std ``ping_jitter``: the stable burst interval,
``ping_type = "sbi"``; ``rbi`` draws ``e_c = e_{c−1} + U(min, max)(1 + δ)``, the same with P the uniform's mean and
``j_c`` its zero-mean part, stretched too; ``pbi`` takes P_c from its table ``burst_sequence`` in turn, cycled),
from where the target is then (its position input moved back along its velocity from the step's end); the fixed
receivers (the beacon inputs, up to :data:`~sblsim.models.acoustics.channel.interface.FLIGHT_CAPACITY`) hear it one
way, ``τ_i`` after the emission (the eigenray between the two points is reciprocal). Each receiver's arrival is a
packet of its own (slot counter ``(c − 1) n + i``), all n sent when the step reaches the emission (an event run once
per receiver) and delivered at their arrivals on the lanes like every packet; it carries the ping's nominal epoch
``t0 + c P`` (``pbi``: ``t0 + Σ_{k≤c} P_k``) as ``tx_time`` (the receivers know the schedule, not the emission; the
receivers' clocks are synchronized) and the pseudo-range ``r = c_assumed (e_c + τ_i − t0 − c P) + σ_r w + e_mp``:
the range plus the emission's offset.

When the pinger emits is :mod:`~sblsim.models.acoustics.channel.pinger`'s; the leg is
:mod:`~sblsim.models.acoustics.channel.legs`', its packets travel in flight to the lanes
(:mod:`~sblsim.models.acoustics.channel.lanes`).
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.acoustics import sonar
from sblsim.models.acoustics.channel.interface import (
    _CHANNEL_UNIFORM,
    _DETECTION,
    _PING_JITTER,
    _RANGE_NOISE,
    DETECTION_DRAWS,
    TARGET_INPUTS,
)
from sblsim.models.acoustics.channel.lanes import _send
from sblsim.models.acoustics.channel.legs import _leg, _Slot
from sblsim.models.acoustics.channel.pinger import ping_interval_drawn, ping_nominal
from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.expressions import select
from sblsim.models.platform.core import AXES


def _ping(n: int, true_names: list[str], sent_names: list[str], queue: list, carried: list, propagation: str,
          detection: str):
    """The handler of one leg of a ping of an inverted LBL (``ranging = "toa"``, a channel of ``n`` fixed
    receivers): the target's pinger emits at ``ping_epoch`` (its own clock: the nominal interval stretched by its
    drift, plus the jitter: :func:`ping_interval_drawn`), and receiver ``ping_leg + 1`` (its input names
    ``true_names``, ``sent_names``) hears it a travel time later; the packet joins the in-flight ``queue``
    (:func:`_send`). The event runs once per receiver of the ping (``ping_leg`` 0 … n − 1), then draws the next
    ping's epoch.

    The travel time is the one way from the target where it is at the emission (its position input moved back
    along its velocity from the step's end) to the fixed receiver, by the travel times of ``propagation``
    (reciprocal: the eigenray between the two points) and what ``detection`` hears; the receivers' clocks are
    synchronized (GPS), the emission epoch is unknown to them: the packet carries the nominal epoch of the ping
    (:func:`ping_nominal`: ``t0 + c P`` of ping c, or its table's) as ``tx_time`` and the pseudo-range
    ``c_assumed (rx_time − tx_time)``, which holds the emission's offset from the nominal schedule."""
    snr_mode = detection == "snr"

    def handler(x, u, p, d, w, t, h):
        leg, count, emitted = x["ping_leg"], x["ping_count"], x["ping_epoch"]
        nominal = ping_nominal(x, d, count + 1)
        receiver = ca.vertcat(*[select(leg, [u[true_names[3 * j + a]] for j in range(n)]) for a in range(3)])
        sent = ca.vertcat(*[select(leg, [u[sent_names[3 * j + a]] for j in range(n)]) for a in range(3)])
        velocity = ca.vertcat(*[u[name] for name in TARGET_INPUTS[3:]])
        source = ca.vertcat(*[u[name] for name in TARGET_INPUTS[:3]]) + velocity * (emitted - (t + h))
        heard_draws = w[_DETECTION] if snr_mode else None
        # the leg between two fixed points: the target at the emission, the receiver (no iteration)
        e = _Slot(propagation, emitted, receiver, source, ca.SX.zeros(3), x, p, d, heard_draws)
        draws, noise = w[_CHANNEL_UNIFORM], w[_RANGE_NOISE][0]
        if snr_mode:
            valid, outlier, excess = 1, 0, 0.0
        else:
            valid = draws[0] >= p["loss_pct"] / 100.0
            outlier = draws[1] < p["outlier_pct"] / 100.0
            excess = ca.if_else(outlier, -p["outlier_excess"] * ca.log1p(-draws[2]), 0.0)
        one_way = _leg(e, None, False)
        tau, distance = one_way[0], one_way[1]
        launch, arrival_angle, kind = one_way[3]
        valid = ca.logic_and(valid, kind > 0)
        scale = 1.0
        if snr_mode:  # the ping's data (the tag's id) decoded, a reflected arrival's excess, the timing noise
            decoded = heard_draws[DETECTION_DRAWS - 1] < sonar.detection_probability(
                one_way[4], p["detection_threshold"] + p["decoding_margin"], p["fluctuation"])
            valid = ca.logic_and(valid, decoded)
            outlier = ca.logic_or(outlier, kind > 1.5)
            scale = sonar.accuracy_scale(one_way[4], p["reference_snr"])
        arrival = emitted + tau
        rng = (p["sound_speed_assumed"] * (arrival - nominal) + range_noise_sigma(p, distance) * scale * noise
               + excess)
        # the eigenray was traced from the receiver: reversed, it leaves the target
        out = {"launch_angle": -arrival_angle, "arrival_angle": -launch, "arrival": kind,
               "packet_seq": count * n + leg + 1, "beacon_id": leg + 1, "packet_valid": valid, "tx_time": nominal,
               "range": ca.if_else(valid, rng, 0.0), "travel_time": tau, "range_true": distance,
               "outlier": ca.logic_and(outlier, valid), "rx_time": arrival,
               "snr": one_way[4], "detection_probability": one_way[5]}
        out.update({f"beacon_{a}": ca.if_else(valid, sent[j], 0.0) for j, a in enumerate(AXES)})
        overrun = {}
        if snr_mode:  # the leg's last heard arrival after the next ping: flagged
            spread_end = one_way[6]
            overrun = {"slot_overrun": ca.if_else(spread_end > d["ping_shortest"], ca.fmax(
                x["slot_overrun"], spread_end), x["slot_overrun"])}
        # after the last receiver's leg, the next emission: the next ping's interval on the pinger's clock
        last = leg + 1 >= n
        interval = ping_interval_drawn(p, d, count + 2, w[_PING_JITTER][0])
        return {"ping_leg": ca.if_else(last, 0, leg + 1), "ping_count": ca.if_else(last, count + 1, count),
                "ping_epoch": ca.if_else(last, emitted + interval, emitted),
                **_send(queue, carried, x, p, out, tau), **overrun}
    return handler
