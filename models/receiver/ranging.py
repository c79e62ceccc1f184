"""What a receiver's parameters say about its ranges: their noise law in R, whether they are an inverted LBL's
times of arrival, what the clock's offset adds to them, the error states the motion model carries, and the epoch a
USBL packet refers to.
"""

from __future__ import annotations

import casadi as ca

from sblsim.models.acoustics.channel.interface import TOA

#: The sound speed that dates a USBL packet's reply from its arrival and range (:func:`reply_epoch`; 3 % off
#: moves the epoch by 3 % of the two travel times) [m/s].
REFERENCE_SOUND_SPEED = 1500.0


def range_law(p: dict):
    """``(sigma_range, range_k)`` of a receiver that declares the range law, else None (a constant σ)."""
    return (p["sigma_range"], p["range_k"]) if "range_k" in p else None


def toa_ranging(p: dict):
    """Whether the receiver's packets are an inverted LBL's times of arrival (``ranging = "toa"``); None for a
    receiver that declares no ranging."""
    return p["ranging"] == TOA if "ranging" in p else None


def errors_of(p: dict) -> dict:
    """The ``errors`` mapping of :class:`~sblsim.models.receiver.motion.WithErrorStates` from a receiver's
    parameters (:func:`~sblsim.models.receiver.interface.error_parameters`,
    :func:`~sblsim.models.receiver.interface.beacon_parameters`): the GPS error as states where its
    correlation time is positive, the clock's drift where ``clock_states`` is on, the attitude error."""
    markov = p["gps_correlation_time"] > 0.0
    return {"gps_sigma": ca.if_else(markov, p["beacon_gps_sigma"], 0.0), "gps_tau": p["gps_correlation_time"],
            "clock_drift_sigma": ca.if_else(p["clock_states"], p["clock_drift_sigma_ppm"] * 1e-6, 0.0),
            "attitude_sigma": p["attitude_bias_sigma_deg"] * (ca.pi / 180.0)}


def clock_scale(p: dict):
    """What the clock's offset [s] adds to a range [m/s]: the assumed sound speed for a one-way range of a
    receiver with clock states and for an inverted LBL's time of arrival (the emission's offset), else 0."""
    if "clock_states" not in p:
        return 0.0
    one_way = p["ranging"] == 0  # the index of "owtt"
    # an inverted LBL's time of arrival carries the pinger's emission offset, whatever clock_states says
    offset = ca.logic_or(ca.logic_and(p["clock_states"], one_way), p["ranging"] == TOA)
    return ca.if_else(offset, p["sound_speed_assumed"], 0.0)


def reply_epoch(u: dict) -> ca.SX:
    """The epoch a USBL packet refers to [s]: the diver's reply, the reply's and the downlink's travel times
    (``2 r / c`` at :data:`REFERENCE_SOUND_SPEED`) before the packet's arrival."""
    return u["rx_time"] - 2.0 * u["range"] / REFERENCE_SOUND_SPEED


__all__ = ["clock_scale", "errors_of", "range_law", "REFERENCE_SOUND_SPEED", "reply_epoch", "toa_ranging"]
