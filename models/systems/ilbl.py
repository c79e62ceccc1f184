"""Inverted long baseline (ILBL): fixed receivers (hydrophones) at surveyed positions hear the target's own pinger.

The configuration acoustic telemetry and diver or vehicle pinger tracking use: the **target emits** on its own
clock and a **fixed array listens** with synchronized clocks (GPS); the position comes from the times of arrival
of each ping at the receivers, whose emission epoch the receivers do not know. Receiver i stands where an LBL's
transponder would (the layout's points at ``platform.seafloor_depth``, or a custom layout's NED positions), its
surveyed position ``b_i + s_i`` is the one the packets carry (:mod:`sblsim.models.systems.lbl`), and the channel
runs in ``ranging = "toa"`` (:mod:`sblsim.models.acoustics.core`): the pinger emits on its clock (drift
``acoustics.clock_drift_ppm``) at the intervals of its type, ``acoustics.ping_type`` (Baktoft et al.'s): ``sbi``
every ``acoustics.ping_interval`` with a uniform jitter of std ``acoustics.ping_jitter``, ``rbi`` each interval a
uniform draw between ``acoustics.burst_interval_min`` and ``burst_interval_max`` (the nominal schedule their mean),
``pbi`` the intervals of a known table ``acoustics.burst_sequence`` in turn, with the jitter; each ping reaches
every receiver one way. A packet is one receiver's time of arrival
as a pseudo-range ``c (t_arrival − t_nominal)`` against the ping's nominal epoch: the true range plus ``c`` times
the emission's offset from the nominal schedule, a random walk of the jitter plus the drift.

The receivers that carry the clock's error states (``ekf-seq``, ``ukf``) take that offset as their clock offset
state and the interval's drift as its drift, the std of the interval's random part (the jitter; ``rbi``'s
``(max − min) / √12``) as the offset's process noise at each new ping, and the
range at the emission epoch (:mod:`sblsim.models.receiver.core`); the paper's EKF and ``lsq`` have no such state
and are refused. The bound is the ranging systems' bound with error states, the same process noise at each
ping (:func:`sblsim.models.error_bound.error_bound_step`); the accuracy map is one ping heard by every receiver plus the
depth, the emission epoch removed as a nuisance parameter
(:func:`sblsim.models.design.information.layout_information`).

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017,
doi:10.1038/s41598-017-14278-z (the emission epoch as a state, the pinger's random interval). Kay, Fundamentals of
Statistical Signal Processing: Estimation Theory, Prentice Hall 1993, Section 3.7 (a nuisance parameter's bound).
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from sblsim.models.acoustics.channel.interface import FLIGHT_CAPACITY
from sblsim.models.acoustics.channel.pinger import ping_spread
from sblsim.models.bound import MODEL
from sblsim.models.declarations import ModelError
from sblsim.models.design.information import layout_values
from sblsim.models.systems import register
from sblsim.models.systems.lbl import LBL
from sblsim.models.systems.sbl import _layout_words

#: The receivers that carry the emission epoch as a state (the clock's offset and drift): the built-in receivers an
#: inverted LBL takes.
EMISSION_RECEIVERS = ("ekf-seq", "ukf")


@register
class InvertedLBL(LBL):
    """Inverted long baseline: N fixed receivers hear the target's pinger (docs/model.md, "Systems")."""

    name = "ilbl"
    code = 3
    title = "inverted long baseline"
    words = ("4 hydrophones on a 50 m circle at platform.seafloor_depth hear the diver's pinger (one ping per "
             "cycle), tracked by ekf-seq")
    compare_defaults = ("platform.layout=circle", "platform.beacons=4", "platform.baseline=50",
                        "simulation.receiver=ekf-seq")
    marker = "hydrophones"
    ranging = ("toa",)
    designed = False

    def describe(self, platform: Mapping[str, Any]) -> str:
        return (f"{len(self.offsets(platform))} hydrophones, {_layout_words(platform)}, at "
                f"{platform['seafloor_depth']:g} m")

    def check(self, platform: dict[str, Any], given: set[str]) -> None:
        """LBL's checks, and at most :data:`~sblsim.models.acoustics.core.FLIGHT_CAPACITY` receivers: the channel
        holds every arrival of a ping in flight at once.

        Raises
        ------
        ModelError
            Naming ``platform.beacons`` and the allowed count.
        """
        super().check(platform, given)
        if platform["beacons"] > FLIGHT_CAPACITY:
            raise ModelError(f"platform.beacons: {platform['beacons']} hydrophones; an inverted LBL (platform.system "
                             f"= 'ilbl') holds every arrival of a ping in flight at once: allowed [3, "
                             f"{FLIGHT_CAPACITY}]")

    def check_receiver(self, receiver: str, field: str = "simulation.receiver") -> None:
        """Refuse a built-in receiver without the emission epoch as a state (the paper's EKF, ``lsq``).

        Raises
        ------
        ModelError
            Naming ``field`` and the receivers that take an inverted LBL.
        """
        builtin = {"ekf": "the paper's EKF", "lsq": "the least-squares fix"}
        if receiver in builtin:
            raise ModelError(f"{field}: {receiver!r} ({builtin[receiver]}) has no state for the pinger's emission "
                             f"epoch, which platform.system = 'ilbl' needs; use {' or '.join(EMISSION_RECEIVERS)}")

    def bound_errors(self, cfg: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
        """The emission's offset: the pinger's interval drift (``acoustics.clock_drift_ppm``) and the std of its
        random step per ping (:func:`~sblsim.models.acoustics.core.ping_spread`: the jitter ``acoustics.ping_jitter``,
        or ``rbi``'s uniform interval's), the offset adding ``c_assumed`` times itself to every range; surveyed
        receivers have no GPS or attitude error."""
        acoustics = cfg["acoustics"]
        return {**super().bound_errors(cfg), "clock_drift_sigma": abs(acoustics["clock_drift_ppm"]) * 1e-6,
                "clock": acoustics["sound_speed_assumed"], "ping_jitter": ping_spread(acoustics)}

    def own_bound(self, parameters: Mapping[str, float]) -> bool:
        """The bound with error states wherever the emission's offset is not known (a jitter or a drift)."""
        return super().own_bound(parameters) or parameters["ping_jitter"] > 0.0

    def fix_accuracy(self, points: np.ndarray, platform: Mapping[str, Any], parameters: Mapping[str, float],
                     sigma_range: float, model=None, heard: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """One ping heard by every receiver plus the depth, the emission epoch unknown
        (:func:`~sblsim.models.design.information.layout_values` with ``emission``); ``heard`` as LBL's."""
        arms = self.lever_arms(platform)
        return layout_values(points, arms, arms, 1.0 if heard is None else heard, parameters["noise_variance"],
                             parameters["attitude_variance"], parameters["depth_variance"],
                             MODEL if model is None else model, emission=True)


__all__ = ["EMISSION_RECEIVERS", "InvertedLBL"]
