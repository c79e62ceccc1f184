"""Acoustic channel: round-robin OWTT or TWTT ranging with loss and multipath; USBL range and direction of arrival.

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

Delivery at arrival. The packet of slot k is computed at ``t_k`` (from the
inputs of the step that reaches ``t_k``) with its **arrival** ``a_k`` at the
diver: ``t_k + τ`` (OWTT), ``t_k`` plus the round trip the truth gives
(TWTT: up leg, turnaround with its jitter, down leg), and for USBL the reply's
arrival at the surface plus the downlink's travel time to the diver where it
is then. It is then **in flight**: the channel holds up to
:data:`FLIGHT_CAPACITY` packets sent and not yet arrived in its state. In
each step, after the slots the step reaches were sent, **every** packet in
flight that has arrived (``a ≤ t + h``) is delivered, on the **lanes** of
the delivery in the order of arrival (then of slot counter): the earliest
on the packet outputs themselves (lane 1, with ``rx_time = a_k``), the next
ones on ``lane2_*``, ``lane3_*``, … (:data:`LANES` = :data:`FLIGHT_CAPACITY`
lanes, so that every packet in flight fits; a lane left empty shows
``packet_seq`` 0). None is delivered before it arrives, none is held behind
another, and the outputs show the last delivery until the next. A step that
reaches several slot epochs sends each of them (each with its own random
numbers).
Every receiver uses each lane's packet at its first step end that reaches
its ``rx_time``, in lane order (:func:`sblsim.models.receiver.core.slot_events`). A packet that
finds every place taken is not dropped silently: ``overflow_travel_time``
keeps the longest arrival − transmit of it and of those in flight, and the
orchestrator refuses the run (:func:`check_in_flight`: a packet must arrive
within ``FLIGHT_CAPACITY − 1`` slots, so the turnaround alone is checked
before a run).

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

Times of arrival (``ranging = "toa"``, the inverted LBL: the roles turned round). The target's pinger emits
ping c at ``e_c = e_{c−1} + P (1 + δ) + j_c`` on its own clock (P = ``ping_interval``, 0 taking the cycle
``n T``; δ the drift ``clock_drift_ppm``; ``j_c`` uniform of zero mean and std ``ping_jitter``: the stable burst
interval, ``ping_type = "sbi"``; ``rbi`` draws ``e_c = e_{c−1} + U(min, max)(1 + δ)``, the same with P the uniform's
mean and ``j_c`` its zero-mean part, stretched too; ``pbi`` takes P_c from its table ``burst_sequence`` in turn,
cycled), from where the
target is then (its position input moved back along its velocity from the step's end); the fixed receivers (the
beacon inputs, up to :data:`FLIGHT_CAPACITY`) hear it one way, ``τ_i`` after the emission (the eigenray between
the two points is reciprocal). Each receiver's arrival is a packet of its own (slot counter ``(c − 1) n + i``),
all n sent when the step reaches the emission (an event run once per receiver) and delivered at their arrivals
on the lanes like every packet; it carries the ping's nominal epoch ``t0 + c P`` (``pbi``: ``t0 + Σ_{k≤c} P_k``)
as ``tx_time`` (the receivers
know the schedule, not the emission; the receivers' clocks are synchronized) and the pseudo-range
``r = c_assumed (e_c + τ_i − t0 − c P) + σ_r w + e_mp``: the range plus the emission's offset.

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

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4
(round-robin OWTT, range noise, packet loss). Eustice, Singh, Leonard,
"Synchronous-clock one-way-travel-time acoustic navigation for underwater
vehicles", J. Field Robotics 28(1), 2011 (OWTT with synchronized clocks).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from functools import lru_cache, partial
from typing import Any, Callable, Mapping, NamedTuple

import casadi as ca
import numpy as np

from sblsim.models.acoustics import sonar
from sblsim.models.acoustics.detection import (
    NO_SNR,
    SITE,
    family_levels,
    family_levels_grid,
    first_detected,
    level_table,
)
from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.acoustics.ray_tables import (
    FAMILY_TABLE,
    RAY_BOUNDS,
    RAY_GRID,
    RAY_TABLE,
    RAY_TABLE_ROWS,
    eigenray_table,
    first_arrival_grid,
    ray_grid,
    ray_values,
)
from sblsim.models.acoustics.rays import profile_arrays
from sblsim.models.acoustics.sound_speed import (
    NODES,
    PROFILE,
    PROFILE_FILE,
    harmonic_mean,
    node_speeds,
    profile_nodes,
    profile_table,
)
from sblsim.models.component import Component
from sblsim.models.declarations import (
    SEED_PARAMETERS,
    Column,
    Table,
    Variable,
    format_table,
    parse_table,
    shown,
    signal_range,
)
from sblsim.models.errors import ModelError
from sblsim.models.expressions import (
    NO_ROW,
    cumulative_sum,
    get_row,
    lookup,
    map_in_chunks,
    only_where,
    put_row,
    sample_due,
    select,
)
from sblsim.models.platform.core import (
    AXES,
    USBL_ATTITUDES,
    attitude_variables,
    beacon_names,
    beacon_variables,
)
from sblsim.models.platform.geometry import rotation_ned
from sblsim.models.platform.waves import WAVE_HEIGHT
from sblsim.models.program import ProgramBuilder, Stream
from sblsim.models.systems import interface_system

(_CHANNEL_UNIFORM, _RANGE_NOISE, _TURNAROUND, _ANGLE_NOISE, _DOWNLINK, _DETECTION, _OCEAN_FREQUENCY,
 _OCEAN_PHASE, _PING_JITTER) = range(9)
#: Random Fourier features of the moving ocean's travel-time perturbation (:func:`ocean_perturbation`).
OCEAN_FEATURES = 16
#: Ranging modes: one-way travel time (synchronized clocks), two-way (interrogation and reply), or the times of
#: arrival of the target's own pings at fixed receivers (``toa``: an inverted LBL, the emission epochs unknown).
RANGING = ("owtt", "twtt", "toa")
#: The index of ``toa`` in :data:`RANGING` (the ``ranging`` parameter's encoding).
TOA = RANGING.index("toa")
#: The packet a slot delivers: outputs of the channel, inputs of every receiver (whose FMUs refuse a value outside
#: the declared ranges, :data:`sblsim.models.declarations.SIGNAL_RANGES`).
PACKET: tuple[Variable, ...] = (
    Variable("packet_seq", "output", "Integer", 0, description="Slot counter k (0: no packet yet)",
             **signal_range("counter")),
    Variable("beacon_id", "output", "Integer", 0, description="Transmitting beacon (1-based; 0: none)",
             **signal_range("counter")),
    Variable("packet_valid", "output", "Boolean", False, description="Packet received (not lost)"),
    Variable("tx_time", "output", "Real", 0.0, "s", "Transmit epoch t_k of the packet", discrete=True,
             **signal_range("time")),
    Variable("range", "output", "Real", 0.0, "m", "Measured OWTT range (0 when the packet is lost)", discrete=True,
             **signal_range("range")),
    Variable("beacon_x", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, North (0 when lost)",
             discrete=True, **signal_range("position")),
    Variable("beacon_y", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, East (0 when lost)",
             discrete=True, **signal_range("position")),
    Variable("beacon_z", "output", "Real", 0.0, "m", "Broadcast beacon position in the packet, Down (0 when lost)",
             discrete=True, **signal_range("position")),
)
#: The truth of a packet's exchange: outputs of the channel only (what a receiver cannot know).
EXCHANGE: tuple[Variable, ...] = (
    Variable("travel_time", "output", "Real", 0.0, "s",
             "True travel time of the exchange: one way (ranging owtt), the beacon's leg to the target; two "
             "way (twtt), the target's interrogation, the transponder's turnaround and the reply; USBL, the "
             "transceiver's interrogation, the target's turnaround and its reply (not the downlink)",
             discrete=True),
    Variable("range_true", "output", "Real", 0.0, "m",
             "True distance from beacon at transmit to target at reception", discrete=True),
    Variable("outlier", "output", "Boolean", False, description="Range lengthened by multipath"),
)
#: The direction of arrival a USBL packet adds (outputs of the channel and inputs of the receivers of a USBL
#: interface).
DIRECTION: tuple[Variable, ...] = (
    Variable("azimuth", "output", "Real", 0.0, "rad",
             "USBL: measured azimuth of the diver from the transceiver, clockwise from North (0 when lost)",
             discrete=True, min=-10.0, max=10.0),
    Variable("elevation", "output", "Real", 0.0, "rad",
             "USBL: measured elevation of the diver below the horizontal (ray: the eigenray's at the transceiver) "
             "(0 when lost)", discrete=True,
             min=-10.0, max=10.0),
)
#: The moving ocean (declared after every other variable of the channel: their value references stay): the
#: sound speed's smooth change in time, the same on every path, as the nadir total delay (NTD) of GNSS-Acoustic
#: seafloor geodesy models it (docs/calibration.md).
OCEAN_VARIABLES: tuple[Variable, ...] = (
    Variable("ntd_sigma_ppm", "parameter", "Real", 0.0, "ppm",
             "Moving ocean: std of the travel times' relative change in time (the nadir total delay over the nadir "
             "travel time; 0: a steady ocean)", min=0.0, max=1e4),
    Variable("ntd_time_scale", "parameter", "Real", 1800.0, "s",
             "Moving ocean: time scale of the change (a Gaussian correlation exp(-dt^2 / (2 scale^2)))",
             min=1.0, max=1e7),
)


def ocean_perturbation(t, sigma, frequency, phase) -> ca.SX:
    """The moving ocean's relative travel-time change ε(t) at the epoch ``t`` [s]: a stationary Gaussian process of
    standard deviation ``sigma`` [1] and Gaussian correlation ``exp(−Δt² / (2 ℓ²))``, drawn as random Fourier
    features, ``ε(t) = σ √(2/M) Σ_m cos(ω_m t + φ_m)``, with ``ω_m ~ N(0, 1/ℓ²)`` (``frequency`` (M, 1) [rad/s])
    and ``φ_m ~ U(0, 2π)`` (``phase`` (M, 1) [rad]) drawn once per run; a path's travel time is multiplied by
    ``1 + ε``.

    References
    ----------
    Rahimi, Recht, "Random features for large-scale kernel machines", NIPS 2007. Tomita, Kido, "SeaGap", 2022
    (the nadir total delay of GNSS-A); Watanabe et al., Front. Earth Sci. 8:597532, 2020 (GARPOS).
    """
    m = frequency.shape[0]
    return sigma * math.sqrt(2.0 / m) * ca.sum1(ca.cos(frequency * t + phase))


#: The pinger's types (Baktoft et al. 2017, YAPS's names; the tracker's, :mod:`sblsim.models.tracking.schedule`): a
#: stable burst interval (``sbi``: every ``ping_interval``, plus a uniform jitter), a random one (``rbi``: each
#: interval a uniform draw ``U(burst_interval_min, burst_interval_max)``), a pseudo-random one (``pbi``: the intervals
#: of a known table, ``burst_sequence``, in turn, plus the jitter).
PING_TYPES = ("sbi", "rbi", "pbi")
#: The indices of ``rbi`` and ``pbi`` in :data:`PING_TYPES` (the ``ping_type`` parameter's encoding).
RBI, PBI = PING_TYPES.index("rbi"), PING_TYPES.index("pbi")
#: Most intervals of a ``pbi`` pinger's table.
MAX_BURSTS = 64
#: The longest interval between two pings [s].
MAX_PING_INTERVAL = 3600.0
#: A ``pbi`` pinger's intervals in the order it emits them (cycled), carried in FMU arrays as the sound-speed
#: table is: one column, ``burst_sequence_rows`` rows in use.
BURSTS = Table(columns=(Column("burst_sequence_interval", "s", "pbi: interval of the pinger's table", 1e-3,
                               MAX_PING_INTERVAL),),
               max_rows=MAX_BURSTS, min_rows=1, when=("ping_type", "pbi"))
#: The target's pinger of an inverted LBL (``ranging = "toa"``; declared after every other variable of the
#: channel, the lanes included: their value references stay; the ping types' after the first two, for the same
#: reason): its type, the pings' nominal interval and their jitter (``sbi``, the jitter also ``pbi``'s), a random
#: interval's bounds (``rbi``) and a pseudo-random interval's table (``pbi``).
PING_VARIABLES: tuple[Variable, ...] = (
    Variable("ping_interval", "parameter", "Real", 0.0, "s",
             "toa: the target pinger's nominal interval between pings on its own clock (0: the round-robin cycle, "
             "beacons x slot_period: one range per receiver per cycle, as SBL and LBL)", min=0.0,
             max=MAX_PING_INTERVAL),
    Variable("ping_jitter", "parameter", "Real", 0.0, "s",
             "toa: std of each interval's random part (uniform, zero mean: a tag's random delay; the emission "
             "epochs then walk away from the nominal schedule, unknown to the receivers)", min=0.0, max=600.0),
    Variable("ping_type", "parameter", "String", "sbi", choices=PING_TYPES,
             description="toa: the pinger's intervals: stable (sbi: ping_interval plus ping_jitter), random (rbi: "
                         "each a uniform draw between burst_interval_min and burst_interval_max) or pseudo-random "
                         "(pbi: burst_sequence's in turn, plus ping_jitter)"),
    Variable("burst_interval_min", "parameter", "Real", 0.0, "s",
             "toa, rbi: the shortest interval between pings on the pinger's clock (0: not set)", min=0.0,
             max=MAX_PING_INTERVAL),
    Variable("burst_interval_max", "parameter", "Real", 0.0, "s",
             "toa, rbi: the longest interval between pings on the pinger's clock (0: not set)", min=0.0,
             max=MAX_PING_INTERVAL),
    Variable("burst_sequence", "parameter", "String", "", scope="config",
             description=f"toa, pbi: the pinger's intervals in the order it emits them, cycled, 'interval; ...' "
                         f"or 'interval interval ...' [s] (1 to {MAX_BURSTS})"),
    Variable("burst_sequence_rows", "parameter", "Integer", 0, scope="fmu", table=BURSTS,
             description="toa, pbi: intervals of the pinger's table in use (burst_sequence)", min=0, max=MAX_BURSTS),
)

#: The hydrophones' own clocks and their sync tags (an inverted LBL's raw detections: ``sblsim run
#: --export-detections``). Configuration keys only, declared after every other variable: the channel and the
#: receivers never read them (their packets keep synchronised times), so no FMU and no number of a run changes.
#: The grade: a VR2-class telemetry receiver's clock drifts by up to 4 s a day (46 ppm) by its manufacturer's
#: specification (VEMCO, "VR2 Troubleshooting", http://www.vemco.com/support/vr2_troubleshoot.php); the default
#: ±20 ppm (1.7 s a day) is a common watch crystal's tolerance, inside that grade.
RECEIVER_CLOCK_VARIABLES: tuple[Variable, ...] = (
    Variable("receiver_clock_offset", "parameter", "Real", 2.0, "s",
             "ilbl raw detections: each hydrophone's clock offset at the run's start, uniform in +-this (drawn "
             "from the run's seed; a clock set by hand at deployment)", min=0.0, max=86400.0, scope="config"),
    Variable("receiver_clock_drift_ppm", "parameter", "Real", 20.0, "ppm",
             "ilbl raw detections: each hydrophone's clock drift, uniform in +-this (a VR2-class crystal: up to "
             "46 ppm, 4 s a day; 20 ppm is 1.7 s a day)", min=0.0, max=1000.0, scope="config"),
    Variable("sync_interval_min", "parameter", "Real", 540.0, "s",
             "ilbl raw detections: the shortest burst interval of the sync tag at each hydrophone (each interval "
             "uniform between sync_interval_min and sync_interval_max)", min=1.0, max=MAX_PING_INTERVAL,
             scope="config"),
    Variable("sync_interval_max", "parameter", "Real", 660.0, "s",
             "ilbl raw detections: the longest burst interval of the sync tags", min=1.0, max=MAX_PING_INTERVAL,
             scope="config"),
)


#: The Euler angles of an attitude, in the order of :func:`~sblsim.models.platform.geometry.rotation_ned`'s arguments.
ATTITUDE_ANGLES = ("roll", "pitch", "yaw")
#: What a USBL packet carries of the array's own measurement: the direction cosines of the reply across the array's
#: two axes as measured (``doa_x``, ``doa_y``, with their noise, before any conversion) and the attitude (the IMU's,
#: as sampled) with which the surface turned the direction into NED: outputs of the channel and inputs of the
#: receivers of a USBL interface, declared after every other variable (their value references stay).
DOA_ARRAY: tuple[Variable, ...] = tuple(
    Variable(f"doa_{a}", "output", "Real", 0.0, "1",
             f"USBL: measured direction cosine of the reply along the array's {a} axis (0 when lost)",
             discrete=True, min=-2.0, max=2.0) for a in ("x", "y")) + tuple(
    Variable(f"doa_{a}", "output", "Real", 0.0, "rad",
             f"USBL: the IMU {a} with which the surface turned the direction of arrival into NED (0 when lost)",
             discrete=True, min=-10.0, max=10.0) for a in ATTITUDE_ANGLES)
#: What a delivered packet adds at the end of the channel's declarations (after every earlier variable, so that
#: their value references stay): its arrival epoch, an input of every receiver too.
ARRIVAL: tuple[Variable, ...] = (
    Variable("rx_time", "output", "Real", 0.0, "s",
             "Arrival epoch of the packet at the diver (the receiver uses it at its first step end reaching it)",
             discrete=True, **signal_range("time")),
)
#: The channel's refusal signal (an output of the channel alone, declared last).
OVERFLOW: tuple[Variable, ...] = (
    Variable("overflow_travel_time", "output", "Real", 0.0, "s",
             "Longest arrival minus transmit epoch of a packet that found every in-flight place taken "
             "(0: none; the orchestrator refuses such a run)", discrete=True),
)
#: In-flight places of the channel: the packets transmitted and not yet arrived it holds (a packet that finds
#: them all taken is counted in ``overflow_travel_time``, never silently dropped).
FLIGHT_CAPACITY = 8
TARGET_INPUTS = ("target_x", "target_y", "target_z", "target_vx", "target_vy", "target_vz")
#: Lanes of a delivery: every packet in flight may arrive within one step, so the channel delivers up to
#: :data:`FLIGHT_CAPACITY` packets at a step's end, each on its lane (lane 1: the packet outputs themselves, the
#: earliest arrival; lane m: ``lane<m>_<name>``, the next ones in the order they arrived; an empty lane has
#: ``packet_seq`` 0).
LANES = FLIGHT_CAPACITY
#: Slack of the delivery test ``rx_time ≤ t + h + ARRIVAL_SLACK`` [s] (the receivers' slot test has the same).
ARRIVAL_SLACK = 1e-9
#: Fixed-point iterations of the travel time (before the final evaluation).
OWTT_ITERATIONS = 3
#: Propagation models: the straight line at the harmonic-mean speed (the paper's), or eigenrays through the
#: profile (:mod:`sblsim.models.acoustics.rays`).
PROPAGATION = ("straight", "ray")
#: Deepest water depth [m].
MAX_WATER_DEPTH = 11000.0
#: What the propagation adds to the channel's parameters and outputs (declared last: the value references
#: of the others stay what they were).
PROPAGATION_VARIABLES: tuple[Variable, ...] = (
    Variable("propagation", "parameter", "String", "straight", choices=PROPAGATION,
             description="Travel time: straight line at the profile's harmonic-mean speed, or eigenrays (ray)"),
    Variable("water_depth", "parameter", "Real", 0.0, "m",
             "ray: water depth of the surface- and bottom-reflected eigenrays (0: none, the direct eigenray only)",
             min=0.0, max=MAX_WATER_DEPTH),
    Variable("launch_angle", "output", "Real", 0.0, "rad",
             "Grazing angle of the ranging's last leg at its source, positive downward (straight: the chord's)",
             discrete=True, min=-2.0, max=2.0),
    Variable("arrival_angle", "output", "Real", 0.0, "rad",
             "Grazing angle of the ranging's last leg at its receiver, positive downward (straight: the chord's)",
             discrete=True, min=-2.0, max=2.0),
    Variable("arrival", "output", "Integer", 0,
             description="Path of the range: 1 direct, 2 surface-reflected, 3 bottom-reflected, 4 the direct "
                         "family's other eigenray (a refracted ray turning beyond the faster end; 0: none, lost)",
             min=0, max=4),
)
#: The eigenray table of a ``ray`` run (:func:`sblsim.models.acoustics.ray_tables.eigenray_table`), built once by the
#: orchestrator for the run's profile and geometry (declared after the rest: their value references stay). Without
#: it (0 rows, the default: a host that gives none) every eigenray is solved exactly.
RAY_TABLE_VARIABLES: tuple[Variable, ...] = (
    Variable("ray_table_rows", "parameter", "Integer", 0, scope="fmu", table=RAY_TABLE,
             description=f"ray: rows of the eigenray table ({RAY_TABLE_ROWS}: in use; 0: every eigenray solved)",
             min=0, max=RAY_TABLE_ROWS),
) + tuple(
    Variable(name, "parameter", "Real", 0.0, "m",
             f"ray: eigenray table's {what} {end} ({'the' if end == 'min' else 'its'} box)", scope="fmu",
             min=-MAX_WATER_DEPTH if name.startswith("ray_z") else 0.0, max=1e6 if name.startswith("ray_x") else
             MAX_WATER_DEPTH)
    for name, what, end in zip(RAY_BOUNDS, ("source depth",) * 2 + ("receiver depth",) * 2
                               + ("horizontal distance",) * 2, ("min", "max") * 3))

#: What is heard: the paper's fixed percentages and σ, or the sonar equation per eigenray (:mod:`.sonar`).
DETECTION = ("fixed", "snr")
#: Uniform numbers of a slot's detection draws (``snr``): three eigenray families per leg of up to three legs
#: (USBL: interrogation, reply, downlink), then the decoding of the packet's data.
DETECTION_DRAWS = 10
#: What detection by signal-to-noise adds to the channel (declared after the rest: their value references stay).
DETECTION_VARIABLES: tuple[Variable, ...] = (
    Variable("detection", "parameter", "String", "fixed", choices=DETECTION,
             description="What is heard: fixed loss_pct, outlier_pct and sigma_range (the paper's), or the sonar "
                         "equation's SNR per eigenray (snr; needs propagation = ray)"),
    Variable("frequency", "parameter", "Real", 25000.0, "Hz", "snr: centre frequency of the signal",
             min=200.0, max=1e6),
    Variable("bandwidth", "parameter", "Real", 5000.0, "Hz", "snr: bandwidth of the signal (the noise band)",
             min=1.0, max=1e6),
    Variable("source_level", "parameter", "Real", 190.0, "dB",
             "snr: source level of every transmitter [dB re 1 uPa at 1 m]", min=100.0, max=250.0),
    Variable("detection_threshold", "parameter", "Real", 12.0, "dB",
             "snr: SNR of a 50 % detection of an arrival", min=-30.0, max=60.0),
    Variable("directivity_index", "parameter", "Real", 0.0, "dB", "snr: receiving directivity index",
             min=0.0, max=40.0),
    Variable("shipping", "parameter", "Real", 0.5, "1", "snr: shipping activity of the ambient noise (Wenz)",
             min=0.0, max=1.0),
    Variable("bottom", "parameter", "String", "sand", choices=tuple(sonar.BOTTOMS),
             description="snr: sea-floor type of the bottom reflection (fluid half-space, docs/model.md)"),
    Variable("reference_snr", "parameter", "Real", 20.0, "dB",
             "snr: the SNR at which sigma_range and the USBL angle sigma hold (below it they grow as the "
             "Cramer-Rao bounds)", min=-30.0, max=100.0),
    Variable("fluctuation", "parameter", "Real", 3.0, "dB",
             "snr: std of the received level's log-normal fluctuation (0: a sharp threshold)", min=0.0, max=20.0),
    Variable("decoding_margin", "parameter", "Real", 3.0, "dB",
             "snr: SNR above the detection threshold the packet's data needs to be decoded", min=0.0, max=60.0),
    Variable("absorption", "parameter", "Real", 0.0, "dB/m",
             "snr: volume absorption of the site's water (Francois-Garrison at frequency, the cast's temperature, "
             "salinity, over the water column; filled by the "
             "orchestrator)", min=0.0, max=1.0, scope="fmu"),
    Variable("beaufort", "parameter", "Integer", 2,
             description="snr: sea state of the wind noise and the surface's roughness (platform.beaufort)",
             min=0, max=len(WAVE_HEIGHT) - 1, scope="fmu"),
    Variable("snr", "output", "Real", 0.0, "dB",
             "snr: SNR of the arrival the range came from (none heard: of the strongest; 0 with fixed detection)",
             discrete=True, min=NO_SNR, max=400.0),
    Variable("detection_probability", "output", "Real", 0.0, "1",
             "snr: detection probability of the arrival the range came from (none heard: of the strongest; "
             "0 with fixed detection)", discrete=True, min=0.0, max=1.0),
)
#: The keys of ``[acoustics]`` that only detection by signal-to-noise reads (the site), and those that only the
#: fixed detection reads (its percentages: not drawn with ``snr``); the channel's other keys are read by both.
SNR_KEYS: tuple[str, ...] = tuple(v.name for v in DETECTION_VARIABLES
                                  if v.causality == "parameter" and v.scope != "fmu" and v.name != "detection")
FIXED_KEYS: tuple[str, ...] = ("loss_pct", "outlier_pct", "outlier_excess")
#: The channel's refusal signal of detection by signal-to-noise (an output of the channel alone).
OVERRUN: tuple[Variable, ...] = (
    Variable("slot_overrun", "output", "Real", 0.0, "s",
             "snr: longest time from a slot's transmit epoch to the last heard arrival of its exchange (multipath "
             "included) beyond the slot (0: none; the next slot's packet overlaps it, which the channel does not "
             "model: the orchestrator flags the run)", discrete=True),
)
#: The family table of an ``snr`` run (:func:`sblsim.models.acoustics.detection.level_table`): every eigenray family
#: for the sonar equation at the eigenray table's nodes (its box), built once by the orchestrator for the run's
#: profile, geometry and site (declared after the rest: their value references stay). Without it (0 rows, the
#: default: a host that gives none) every family is solved exactly.
FAMILY_TABLE_VARIABLES: tuple[Variable, ...] = (
    Variable("ray_family_rows", "parameter", "Integer", 0, scope="fmu", table=FAMILY_TABLE,
             description=f"snr: rows of the family table ({RAY_TABLE_ROWS}: in use; 0: every family solved)",
             min=0, max=RAY_TABLE_ROWS),
)


def site_numbers(p: Mapping[str, Any]) -> Any:
    """The site's numbers (:data:`~sblsim.models.acoustics.detection.SITE`) from the channel's parameters ``p``
    (by name; casadi symbols or numbers): the ambient noise over the signal's band from the Beaufort number's
    wind and the shipping (Wenz), the probable wave height of the Beaufort number, the sea floor's row of
    :data:`~sblsim.models.acoustics.sonar.BOTTOMS` (``p["bottom"]`` its index).

    Returns
    -------
    casadi.SX or casadi.DM, shape (len(SITE), 1)
    """
    floor = [lookup(p["bottom"], [sonar.BOTTOMS[name][j] for name in sonar.BOTTOMS]) for j in range(3)]
    noise = sonar.noise_level(p["frequency"], p["bandwidth"], sonar.wind_speed(p["beaufort"]), p["shipping"])
    return ca.vertcat(p["source_level"], p["detection_threshold"], p["directivity_index"], p["fluctuation"],
                      p["frequency"], p["absorption"], noise, sonar.wave_height(p["beaufort"]), *floor)


def _site(parameters: Mapping[str, Any]) -> tuple[dict[str, Any], np.ndarray]:
    """The channel's parameters (missing ones: their declared start) and the site's numbers they give."""
    declared = {v.name: v for v in Acoustics.fmu_parameters_declared()}
    p = {name: v.start for name, v in declared.items() if not v.in_table} | dict(parameters)
    numeric = {**p, "bottom": float(declared["bottom"].choices.index(p["bottom"]))}
    return p, np.asarray(ca.evalf(site_numbers(numeric))).ravel()


def site_vector(parameters: Mapping[str, Any]) -> np.ndarray:
    """The site's numbers (:data:`~sblsim.models.acoustics.detection.SITE`) of the channel's FMU parameters
    ``parameters`` (missing ones take their declared start, String choices as text), as :func:`site_numbers`.

    Returns
    -------
    ndarray, shape (len(SITE),)
    """
    return _site(parameters)[1]


def site_levels(parameters: Mapping[str, Any], sources: Any, receivers: Any,
                levels: ca.Function | None = None) -> dict[str, np.ndarray]:
    """The eigenrays between pairs of points and what the channel's site makes of them (numbers, for maps).

    Parameters
    ----------
    parameters : mapping
        The channel's FMU parameters (a plan's ``component_parameters("acoustics")``; missing ones take their
        declared start, String choices as text).
    sources, receivers : array_like, shape (K, 3)
        NED positions [m] of each pair's ends.
    levels : casadi.Function, optional
        :func:`~sblsim.models.acoustics.detection.family_levels` as compiled code (default: casadi's own
        evaluation of it, the same numbers, far slower).

    Returns
    -------
    dict
        ``tau`` [s], ``launch`` (the grazing angle at the source [rad], positive downward), ``valid``,
        ``snr`` [dB], ``pd``, each (K, 4) (direct, surface, bottom, the direct family's other eigenray;
        :func:`~sblsim.models.acoustics.detection.family_levels`).
    """
    p, site = _site(parameters)
    rows = PROFILE.rows(p, "sound_speed_rows")
    nodes, speeds = profile_arrays(rows) if rows.shape[0] else (np.zeros(NODES), np.zeros(NODES))
    sources, receivers = np.atleast_2d(np.asarray(sources, float)), np.atleast_2d(np.asarray(receivers, float))
    horizontal = np.hypot(*(receivers[:, :2] - sources[:, :2]).T)
    # a range-independent site: pairs of the same depths and distance (a map's symmetric grid) are solved once
    geometry, pair = np.unique(np.column_stack([sources[:, 2], receivers[:, 2], horizontal]), axis=0,
                               return_inverse=True)
    # in calls of a fraction of a second (a large map is minutes of compiled code: Ctrl-C between two calls)
    out = map_in_chunks(family_levels() if levels is None else levels, geometry.T,
                        (float(p["water_depth"]), float(rows.shape[0] > 0), float(p["sound_speed_true"]), nodes,
                         speeds, site))
    return {name: out[k].T[pair.ravel()] for k, name in ((0, "tau"), (1, "launch"), (3, "valid"), (4, "snr"),
                                                          (5, "pd"))}

def lane_fields(n_beacons: int) -> tuple[Variable, ...]:
    """What a packet carries to a receiver (the channel's outputs a receiver reads): :data:`PACKET`, what the
    interface's system adds (USBL: :data:`DIRECTION`), its arrival (:data:`ARRIVAL`) and what the system adds last
    (USBL: :data:`DOA_ARRAY`)."""
    direction = interface_system(n_beacons).measures_direction
    return PACKET + (DIRECTION if direction else ()) + ARRIVAL + (DOA_ARRAY if direction else ())


def lane_name(lane: int, name: str) -> str:
    """The name of the field ``name`` of a packet on ``lane`` (1-based; lane 1: the name itself)."""
    return name if lane == 1 else f"lane{lane}_{name}"


_LANE_NAME = re.compile(r"^lane(\d+)_(.+)$")


def lane_of(name: str) -> tuple[int, str] | None:
    """The lane (2 … :data:`LANES`) and the field of a later lane's variable ``name`` (:func:`lane_name`'s
    inverse); None for any other name."""
    match = _LANE_NAME.match(name)
    return None if match is None else (int(match.group(1)), match.group(2))


def lane_variables(n_beacons: int, causality: str) -> tuple[Variable, ...]:
    """The fields of lanes 2 … :data:`LANES` (:func:`lane_fields`), as a receiver's inputs (``causality``
    ``"input"``) or the channel's outputs (``"output"``, with the truth of each exchange, :data:`EXCHANGE`):
    declared after every other variable of either, so that their value references stay what they were before the
    lanes existed."""
    def lanes(fields):
        return tuple(replace(v, name=lane_name(m, v.name), causality=causality,
                             description=f"Lane {m} of a delivery (the packets that arrived in a step, in order; "
                                         f"packet_seq 0: none): {v.description}")
                     for m in range(2, LANES + 1) for v in fields)
    # the receiver's fields of every lane first, in the receiver's order (a host copies them as one block)
    return lanes(lane_fields(n_beacons)) + (lanes(EXCHANGE) if causality == "output" else ())


def check_in_flight(slot_period: float, turnaround: float, elapsed: float | None = None,
                    jitter: float = 0.0) -> None:
    """Refuse a run whose packets stay in flight longer than the channel can hold them.

    A packet that arrives Δ after its transmit epoch is delivered in the step that reaches its arrival,
    ⌈Δ / T⌉ steps of T after the one that sent it, and the channel sends one packet per slot: with
    :data:`FLIGHT_CAPACITY` places C, a packet must arrive within ``Δ ≤ (C − 1) T``.

    Parameters
    ----------
    slot_period : float
        T = ``simulation.sampling_time`` [s].
    turnaround : float
        The nominal turnaround of two-way ranging (0 for one-way) [s].
    elapsed : float, optional
        The longest Δ a run saw (the channel's ``overflow_travel_time``; 0: nothing refused). None: the check
        before a run, of the turnaround alone (the travel time is not known yet).
    jitter : float
        The turnaround's jitter, ``acoustics.turnaround_sigma`` of two-way ranging (0 for one-way) [s]: part of
        Δ, named with it.

    Raises
    ------
    ModelError
        One line naming ``simulation.sampling_time``, what makes the flight long (the turnaround and its jitter
        where they are not 0, the travel time) and the shortest sampling time that holds it.
    """
    limit = (FLIGHT_CAPACITY - 1) * slot_period
    shorter = ["acoustics.turnaround"] if turnaround > 0.0 or elapsed is None else []
    if elapsed is None:
        if turnaround < limit:
            return
        late, causes = turnaround, f"acoustics.turnaround = {turnaround:g} s and the travel times on top"
    else:
        if not elapsed > 0.0:
            return
        late = elapsed
        causes = [f"acoustics.turnaround = {turnaround:g} s"] if turnaround > 0.0 else []
        if jitter > 0.0:
            causes.append(f"its jitter acoustics.turnaround_sigma = {jitter:g} s")
            shorter.append("acoustics.turnaround_sigma")
            travel = "the travel time"  # not told apart from the jitter's draw
        else:
            travel = f"a travel time of {max(elapsed - turnaround, 0.0):.4g} s"
        causes = ", ".join(causes + [travel]) if causes else travel
    raise ModelError(
        f"simulation.sampling_time: {slot_period:g} s is too short for {causes}: a packet arrives {late:.4g} s after "
        f"it is sent, {math.ceil(late / slot_period - 1e-9) + 1} packets in flight, and the channel holds "
        f"{FLIGHT_CAPACITY} (an arrival within {FLIGHT_CAPACITY - 1} sampling times); give a simulation.sampling_time "
        f"above {late / (FLIGHT_CAPACITY - 1):.4g} s" + "".join(f" or a smaller {key}" for key in shorter))


@lru_cache(maxsize=32)
def _ray_table(table: tuple, depth: float, box: tuple, exact_points: Callable) -> tuple:
    columns = eigenray_table(np.array(table), depth, box, exact_points())
    out = {name: float(value) for name, value in zip(RAY_BOUNDS, box)}
    out.update(RAY_TABLE.values(np.column_stack([columns[c.name] for c in RAY_TABLE.columns]), "ray_table_rows"))
    return tuple(out.items())


@lru_cache(maxsize=32)
def _family_table(table: tuple, depth: float, box: tuple, site: tuple, family_points: Callable,
                  family_levels: Callable) -> tuple:
    columns = level_table(np.array(table), depth, box, np.array(site), family_points(), family_levels())
    return tuple(FAMILY_TABLE.values(np.column_stack([columns[c.name] for c in FAMILY_TABLE.columns]),
                                     "ray_family_rows").items())


@dataclass(frozen=True)
class _Slot:
    """What the legs of a slot share: how travel times are computed, the slot's epoch ``t_k`` [s], the beacon
    (3, 1) [m, NED], the diver's position and velocity at the step's start (3, 1) [m, m/s], the channel's state,
    parameters and derived data, and the detection uniforms of an ``snr`` run (None: fixed detection)."""

    propagation: str
    t_k: Any
    beacon: Any
    position: Any
    velocity: Any
    x: Any
    p: Any
    d: Any
    draws: Any


def _leg(e: _Slot, offset, solve: bool, draw: int = 0):
    """A leg of the slot ``e``: travel time and length between the beacon and the diver at ``t_k + offset`` [s]
    (None: 0), plus the travel time itself when ``solve`` (fixed-point iterations), the eigenray's ``(launch,
    arrival, kind)`` from the beacon (``ray``; the chord's angles and 1 when straight) and the SNR and detection
    probability of that arrival (``snr``: the first **detected** of the leg's eigenrays with the uniforms
    ``draw … draw + 2``, kind 0 when none is; else 0, 0), and the travel time of its latest detected arrival
    (``snr``; else the travel time)."""
    x, p, d, beacon, position, velocity = e.x, e.p, e.d, e.beacon, e.position, e.velocity
    # the moving ocean at the leg's start: every travel time of the leg scaled by 1 + ε
    # (a steady ocean's ε, 0 · Σ cos = ±0, is an exact 0 without its cosines: 1 + ε is 1 either way)
    ppm = p["ntd_sigma_ppm"]
    slower = 1.0 + only_where("sblsim_ocean", ppm > 0,
                              lambda t: ocean_perturbation(t, ppm * 1e-6, x["ocean_frequency"], x["ocean_phase"]),
                              e.t_k - x["t0"] + (0.0 if offset is None else offset))

    def path(tau):
        receive = position + velocity * (tau if offset is None else offset + tau)
        distance = ca.norm_2(receive - beacon)
        horizontal = ca.norm_2(receive[:2] - beacon[:2])
        chord = ca.atan2(receive[2] - beacon[2], horizontal)
        speed = harmonic_mean(beacon[2], receive[2], p["sound_speed_true"], p["sound_speed_rows"],
                              d["nodes"], d["slowness"])
        if e.propagation == "straight":
            return distance / speed * slower, distance, receive, (chord, chord, 1.0)
        # ray: the earliest eigenray (interpolated in the run's eigenray table where it holds); a shadow zone (no
        # arrival) loses the packet, and the straight line keeps the rest finite
        r_tau, r_launch, r_arrival, r_kind = first_arrival_grid(
            p["ray_table_rows"] == RAY_TABLE_ROWS, beacon[2], receive[2], horizontal,
            p["water_depth"], p["sound_speed_rows"] > 0, p["sound_speed_true"], d["nodes"],
            d["speeds"], d["ray_bounds"], d["ray_grid"], d["ray_values"])
        found = r_kind > 0
        tau = ca.if_else(found, r_tau, distance / speed) * slower
        angles = (ca.if_else(found, r_launch, chord), ca.if_else(found, r_arrival, chord), r_kind)
        return tau, distance, receive, angles

    tau, distance, receive, angles = path(0.0)
    for _ in range(OWTT_ITERATIONS if solve else 0):
        tau, distance, receive, angles = path(tau)
    if e.draws is None:
        return tau, distance, receive, angles, 0.0, 0.0, tau
    heard = _hear(beacon, receive, p, d, e.draws[draw:draw + 3])
    return heard[0] * slower, distance, receive, heard[1:4], heard[4], heard[5], heard[6] * slower


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


#: The range noise's growth with distance (the law of :mod:`sblsim.models.acoustics.range_law`: ``σ = σ₀ + k d``,
#: d the range's true length, ``range_true``), declared after every other variable so that the value references of
#: every earlier one stay; 0 keeps every number a run prints.
RANGE_LAW: tuple[Variable, ...] = (
    Variable("range_k", "parameter", "Real", 0.0, "1",
             "range noise growth with distance: sigma = sigma_range + range_k * range (0: constant)",
             min=0.0, max=0.1),
)

def nominal_ping_interval(ping_interval: float, n_beacons: int, slot_period: float) -> float:
    """The pinger's nominal interval [s] of an inverted LBL's run (numbers): ``ping_interval``, or where it is 0 the
    round-robin cycle ``n T`` (the channel's ``prepare`` derives the same)."""
    return ping_interval if ping_interval > 0 else n_beacons * slot_period


#: The keys of ``[acoustics]`` each ping type reads beyond ``ping_type`` (a key of another type, given with a value
#: other than its default, is refused: :func:`check_pinger`).
PING_KEYS = {"sbi": ("ping_interval", "ping_jitter"), "rbi": ("burst_interval_min", "burst_interval_max"),
             "pbi": ("burst_sequence", "ping_jitter")}
_PING_DEFAULTS = {v.name: v.start for v in PING_VARIABLES}


def burst_sequence(text: str, where: str = "acoustics.burst_sequence") -> np.ndarray:
    """A ``pbi`` pinger's intervals from their text: values separated by ``;``, commas or blanks.

    Returns
    -------
    ndarray, shape (rows, 1)
        The intervals [s] (0 rows for a blank text).

    Raises
    ------
    ModelError
        Naming ``where``: a value that is not a number, outside ``[0.001, 3600]`` s, or more than
        :data:`MAX_BURSTS` of them.
    """
    return parse_table(";".join(s for s in re.split(r"[;,\s]+", text) if s), BURSTS, where)


def ping_intervals(acoustics: Mapping[str, Any], n_beacons: int, slot_period: float) -> np.ndarray:
    """The pinger's nominal intervals [s] in the order they repeat (numbers; the channel's ``prepare`` derives the
    same): ``sbi`` its one interval (:func:`nominal_ping_interval`), ``rbi`` the uniform's mean
    ``(min + max) / 2``, ``pbi`` its table.

    Returns
    -------
    ndarray, shape (L,)
    """
    kind = acoustics.get("ping_type", "sbi")
    if kind == "rbi":
        return np.array([0.5 * (acoustics["burst_interval_min"] + acoustics["burst_interval_max"])])
    if kind == "pbi":
        return burst_sequence(acoustics.get("burst_sequence", ""))[:, 0]
    return np.array([nominal_ping_interval(acoustics["ping_interval"], n_beacons, slot_period)])


def ping_spread(acoustics: Mapping[str, Any]) -> float:
    """The std [s] of the random step the emission's offset from the nominal schedule takes at each ping (numbers;
    the receivers' ``ping_jitter``): the uniform ``U(min, max)``'s ``(max − min) / √12`` for ``rbi``, the jitter
    ``ping_jitter`` for ``sbi`` and ``pbi``."""
    if acoustics.get("ping_type", "sbi") == "rbi":
        return (acoustics["burst_interval_max"] - acoustics["burst_interval_min"]) / math.sqrt(12.0)
    return float(acoustics["ping_jitter"])


def check_pinger(acoustics: Mapping[str, Any], given: set[str] | frozenset[str], n_beacons: int,
                 slot_period: float) -> None:
    """Refuse an inverted LBL's pinger the channel cannot emit (``acoustics`` the resolved section, ``given`` the
    keys the user set, the channel's ``n_beacons`` receivers and slot period [s]).

    Raises
    ------
    ModelError
        One line naming the key and what is allowed: a key of another ping type given with a value other than its
        default (:data:`PING_KEYS`), an ``rbi`` without ``0 < burst_interval_min < burst_interval_max``, a ``pbi``
        without a table (or a bad one, :func:`burst_sequence`), a jitter whose uniform (``±√3`` std) would reach
        the shortest interval.
    """
    kind = acoustics.get("ping_type", "sbi")
    own = PING_KEYS[kind]
    for key in sorted({key for keys in PING_KEYS.values() for key in keys} - set(own)):
        if key not in given or acoustics.get(key, _PING_DEFAULTS[key]) == _PING_DEFAULTS[key]:
            continue
        readers = " or ".join(repr(other) for other, keys in PING_KEYS.items() if key in keys)
        raise ModelError(f"acoustics.{key}: {shown(acoustics[key])} is read by acoustics.ping_type = {readers}, "
                         f"not by {kind!r} (which reads {', '.join(own)}); allowed: its default "
                         f"{shown(_PING_DEFAULTS[key])}, or ping_type = {readers}")
    if kind == "rbi":
        low, high = acoustics["burst_interval_min"], acoustics["burst_interval_max"]
        if low <= 0.0:
            upper = f"{high:g}" if high > 0.0 else "burst_interval_max"
            raise ModelError(f"acoustics.burst_interval_min: {low:g} s; ping_type = 'rbi' draws each interval "
                             f"from U(burst_interval_min, burst_interval_max): allowed (0, {upper}) s")
        if high <= low:
            raise ModelError(f"acoustics.burst_interval_max: {high:g} s; ping_type = 'rbi' draws each interval "
                             f"from U(burst_interval_min, burst_interval_max): allowed ({low:g}, "
                             f"{MAX_PING_INTERVAL:g}] s")
        return
    if kind == "pbi" and not burst_sequence(acoustics.get("burst_sequence", "")).shape[0]:
        raise ModelError(f"acoustics.burst_sequence: empty; ping_type = 'pbi' cycles a known table of intervals: "
                         f"allowed 1 to {MAX_BURSTS} intervals in [0.001, {MAX_PING_INTERVAL:g}] s, e.g. "
                         f"'0.6 0.9 0.7'")
    if acoustics.get("ranging") != "toa":
        return  # the pinger's interval is the inverted LBL's (another system does not read it)
    shortest = float(ping_intervals(acoustics, n_beacons, slot_period).min())
    limit = shortest / math.sqrt(3.0)
    if acoustics["ping_jitter"] >= limit:
        what = "ping interval" if kind == "sbi" else "shortest interval of burst_sequence"
        raise ModelError(f"acoustics.ping_jitter: {acoustics['ping_jitter']:g} s; a uniform jitter reaches "
                         f"sqrt(3) times its std, and the {what} ({shortest:g} s) must stay positive: "
                         f"allowed [0, {limit:.6g}) s")


def ping_nominal(x, d, ping) -> ca.SX:
    """The nominal epoch [s] of ping ``ping`` (1, 2, …; symbolic, whole), what the receivers know of the schedule:
    ``t0 + q S + Σ_{k<r} Δ_k`` with ``ping = q L + r`` (the pinger's derived intervals ``ping_steps`` Δ, ``L``
    of them in a cycle of ``S`` seconds: ``pbi``'s table; ``sbi`` and ``rbi`` one, ``t0 + c P``)."""
    rows = d["ping_rows"]
    cycles = ca.floor(ping / rows)
    return x["t0"] + cycles * d["ping_cycle"] + get_row([d["ping_prefix"]], ping - cycles * rows)[0]


def ping_interval_drawn(p, d, ping, uniform) -> ca.SX:
    """The pinger's interval [s] before ping ``ping`` (1, 2, …; symbolic), on its own clock, drawn with the uniform
    number ``uniform`` in [0, 1): its nominal interval Δ (:func:`ping_nominal`'s) stretched by the drift δ plus a
    uniform of zero mean and std σ (``ping_spread``): ``sbi`` and ``pbi`` ``Δ (1 + δ) + j``, ``j`` the jitter;
    ``rbi`` ``(Δ + j)(1 + δ)``, ``U(min, max)`` stretched (its mean Δ, its std ``(max − min) / √12``)."""
    rows = d["ping_rows"]
    r = ping - 1.0 - ca.floor((ping - 1.0) / rows) * rows
    drift = 1.0 + p["clock_drift_ppm"] * 1e-6
    jitter = d["ping_spread"] * math.sqrt(3.0) * (2.0 * uniform - 1.0)
    return get_row([d["ping_steps"]], r)[0] * drift + ca.if_else(p["ping_type"] == RBI, jitter * drift, jitter)


def ping_due(x, u, p, d, t, h):
    """Guard of a ping's legs (``ranging = "toa"``): the emission epoch has been reached by the end of the step."""
    return x["ping_epoch"] <= t + h + ARRIVAL_SLACK


def _hear(source, receive, p, d, draws):
    """The first detected eigenray from ``source`` to ``receive`` (3, 1) [m, NED] with the uniforms
    ``draws`` (3: one per family): :func:`~sblsim.models.acoustics.detection.first_detected` (the families
    interpolated in the run's family table where it holds)."""
    families = family_levels_grid()(
        p["ray_family_rows"] == RAY_TABLE_ROWS, source[2], receive[2], ca.norm_2(receive[:2] - source[:2]),
        p["water_depth"], p["sound_speed_rows"] > 0, p["sound_speed_true"], d["nodes"], d["speeds"],
        d["site"], d["ray_bounds"], d["ray_grid"], d["family_values"])
    return first_detected(*families, draws)


def sent_epoch(x, p, d, seq, n: int):
    """The transmit epoch a packet's slot counter ``seq`` gives [s]: slot k's ``t0 + k T``, or (``ranging =
    "toa"``) its ping's nominal epoch (:func:`ping_nominal`), ping c = ⌈seq / n⌉ of a channel of ``n``
    receivers."""
    ping = ca.floor((seq - 1) / n) + 1
    return ca.if_else(p["ranging"] == TOA, ping_nominal(x, d, ping), x["t0"] + seq * p["slot_period"])


def _send(queue, carried, x, p, out, elapsed):
    """The in-flight queue (state ``queue``: ``(name, size)``, the packet's ``carried`` outputs and ``q_used``)
    after a packet ``out`` (by output name) left ``elapsed`` before it arrives [s]: in the first
    free in-flight place; none free, the longest arrival − transmit of it and of those in flight is kept in
    ``overflow_travel_time`` (the run is refused, :func:`check_in_flight`)."""
    place = NO_ROW  # the first free place (none: nowhere)
    for j in reversed(range(FLIGHT_CAPACITY)):
        place = ca.if_else(x["q_used"][j] < 0.5, j, place)
    placed = place < FLIGHT_CAPACITY
    columns = put_row([x[name] for name, _ in queue], place, [*(out[name] for name in carried), 1.0])
    new = {name: column for (name, _), column in zip(queue, columns)}
    longest = elapsed  # the longest in flight then, for the refusal's message
    for j in range(FLIGHT_CAPACITY):
        sent_at = x["t0"] + x["q_packet_seq"][j] * p["slot_period"]
        # a ping's packet (toa) left at its emission, a travel time before it arrives
        flight = ca.if_else(p["ranging"] == TOA, x["q_travel_time"][j], x["q_rx_time"][j] - sent_at)
        longest = ca.fmax(longest, ca.if_else(x["q_used"][j] > 0.5, flight, 0.0))
    refused = ca.if_else(placed, x["overflow_travel_time"], ca.fmax(x["overflow_travel_time"], longest))
    return {**new, "overflow_travel_time": refused}


def _arrived(x, t, h):
    """Per in-flight place: it holds a packet whose arrival the end of the step has reached."""
    return [ca.logic_and(x["q_used"][j] > 0.5, x["q_rx_time"][j] <= t + h + ARRIVAL_SLACK)
            for j in range(FLIGHT_CAPACITY)]


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


class Acoustics(Component):
    """Acoustic channel: round-robin OWTT or TWTT ranging, USBL range and direction, inverted-LBL times of arrival.

    The timing and the exchanges are the module docstring's."""

    name = "acoustics"
    component_index = 1

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        params = (
            Variable("sound_speed_assumed", "parameter", "Real", 1500.0, "m/s",
                     "Sound speed the receiver assumes to turn travel time into range", min=1300.0, max=1700.0),
            Variable("sound_speed_true", "parameter", "Real", 1500.0, "m/s",
                     "True sound speed when the profile is constant", min=1300.0, max=1700.0),
            Variable("sound_speed_profile", "parameter", "String", "constant", scope="config", file=PROFILE_FILE,
                     description="True sound speed: constant, teos10, table, munk, ctd:NAME or a CSV cast path"),
            Variable("sound_speed_table", "parameter", "String", "", scope="config",
                     description="Sound-speed profile 'depth speed; ...' [m, m/s] (sound_speed_profile = table)"),
            Variable("temperature", "parameter", "Real", 15.0, "degC", "Water temperature for teos10",
                     min=-2.0, max=40.0, scope="config"),
            Variable("salinity", "parameter", "Real", 35.0, "g/kg", "Salinity for teos10", min=0.0, max=42.0,
                     scope="config"),
            Variable("sound_speed_rows", "parameter", "Integer", 0, scope="fmu", table=PROFILE,
                     description="Rows of the sound-speed table in use (0: constant sound_speed_true)",
                     min=0, max=PROFILE.max_rows),
            Variable("clock_drift_ppm", "parameter", "Real", 0.0, "ppm",
                     "Receiver clock drift after power-on synchronization", min=-1000.0, max=1000.0),
            Variable("sigma_range", "parameter", "Real", 0.1, "m", "Range noise standard deviation",
                     min=0.0, max=1000.0),
            Variable("loss_pct", "parameter", "Real", 0.0, "%", "Packet-loss probability", min=0.0, max=100.0),
            Variable("outlier_pct", "parameter", "Real", 0.0, "%", "Multipath-outlier probability",
                     min=0.0, max=100.0),
            Variable("outlier_excess", "parameter", "Real", 2.0, "m",
                     "Mean excess length of a multipath outlier (exponential)", min=0.0, max=1e4),
            Variable("slot_period", "parameter", "Real", 0.1, "s",
                     "Round-robin slot length T (the sampling time)", min=0.001, max=60.0, scope="fmu"),
        )
        inputs = beacon_variables(n_beacons, "input") + tuple(
            Variable(n, "input", "Real", 0.0, unit, f"True target {what}, {axis} [NED]", **signal_range(what))
            for n, unit, what, axis in zip(
                TARGET_INPUTS, ("m",) * 3 + ("m/s",) * 3, ("position",) * 3 + ("velocity",) * 3,
                ("North", "East", "Down") * 2))
        outputs = PACKET + EXCHANGE
        # declared after the OWTT ones, so that their value references stay what they were
        ranging = (
            Variable("ranging", "parameter", "String", "owtt",
                     description="Ranging of SBL and LBL: one-way or two-way travel time (USBL: always two-way; "
                                 "ilbl: always toa, the times of arrival of the target's pings)",
                     choices=RANGING),
            Variable("turnaround", "parameter", "Real", 0.05, "s",
                     "TWTT: the replying transponder's nominal turnaround time", min=0.0, max=10.0),
            Variable("turnaround_sigma", "parameter", "Real", 0.0, "s",
                     "TWTT: std of the turnaround's Gaussian jitter, the turnaround cut at 0 (no reply before its "
                     "interrogation)",
                     min=0.0, max=1.0),
        )
        if not interface_system(n_beacons).measures_direction:
            return (params + SEED_PARAMETERS + inputs + outputs + ranging + ARRIVAL + OVERFLOW + PROPAGATION_VARIABLES
                    + RAY_TABLE_VARIABLES + DETECTION_VARIABLES + OVERRUN + FAMILY_TABLE_VARIABLES + OCEAN_VARIABLES
                    + lane_variables(n_beacons, "output") + PING_VARIABLES + RECEIVER_CLOCK_VARIABLES + RANGE_LAW)
        usbl = (Variable("usbl_angle_sigma_deg", "parameter", "Real", 0.5, "deg",
                         "Direction-of-arrival error std on the array's axis (platform.usbl_angle_sigma_deg)",
                         min=0.0, max=45.0, scope="fmu"),) + tuple(
            v for prefix, what, discrete in USBL_ATTITUDES for v in attitude_variables(prefix, "input", what, discrete))
        return (params + SEED_PARAMETERS + inputs + outputs + ranging + usbl + DIRECTION + ARRIVAL + OVERFLOW
                + PROPAGATION_VARIABLES + RAY_TABLE_VARIABLES + DETECTION_VARIABLES + OVERRUN
                + FAMILY_TABLE_VARIABLES + DOA_ARRAY + OCEAN_VARIABLES + lane_variables(n_beacons, "output")
                + PING_VARIABLES + RECEIVER_CLOCK_VARIABLES + RANGE_LAW)

    @classmethod
    def uses_ray_table(cls, values: Mapping[str, Any], parameters: Mapping[str, Any]) -> bool:
        """Whether a run of the channel's section ``values`` (its FMU parameters ``parameters``) interpolates an
        eigenray table (:meth:`table_parameters`): a ``ray`` run through a sound-speed table."""
        return values.get("propagation") == "ray" and int(parameters.get("sound_speed_rows", 0)) > 0

    @classmethod
    def table_parameters(cls, values: Mapping[str, Any], parameters: Mapping[str, Any], box: tuple[float, ...],
                         exact_points: Callable[[], ca.Function | None],
                         family_points: Callable[[], ca.Function | None],
                         family_levels: Callable[[], ca.Function | None]) -> dict[str, Any]:
        """The FMU parameters of a run's eigenray table (:data:`RAY_TABLE`, its box :data:`RAY_BOUNDS`) and, for an
        ``snr`` run (``detection``), of its family table at the same nodes (:data:`FAMILY_TABLE`).

        Parameters
        ----------
        values : mapping
            The channel's resolved section (a run that :meth:`uses_ray_table`).
        parameters : mapping
            Its FMU parameters (:meth:`fmu_parameters`: the profile's table and the site).
        box : tuple of 6 float
            The geometries the table covers: source depth, receiver depth, horizontal distance, each (min, max)
            [m]; a geometry outside it is solved exactly.
        exact_points, family_points, family_levels : callable
            Give the compiled forms of :func:`~sblsim.models.acoustics.ray_tables.exact_points`,
            :func:`~sblsim.models.acoustics.ray_tables.family_points` and
            :func:`~sblsim.models.acoustics.detection.family_levels` (called when a table is built; None: casadi's
            own evaluation, the same numbers).

        Each table is built once per profile, water depth and box (and site), however many runs ask
        (:func:`~sblsim.models.acoustics.ray_tables.eigenray_table`,
        :func:`~sblsim.models.acoustics.detection.level_table`).
        """
        table = tuple(map(tuple, PROFILE.rows(parameters, "sound_speed_rows").tolist()))
        depth, box = float(values["water_depth"]), tuple(float(b) for b in box)
        out = dict(_ray_table(table, depth, box, exact_points))
        if values.get("detection") == "snr":
            site = tuple(float(v) for v in site_vector(parameters))
            out.update(_family_table(table, depth, box, site, family_points, family_levels))
        return out

    @classmethod
    def fmu_parameters(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """FMU parameters of a configuration section: the profile setting becomes the sound-speed table, a ``pbi``
        pinger's ``burst_sequence`` its table of intervals.

        Raises
        ------
        ModelError
            On an unknown cast or an unreadable or malformed profile, a malformed ``burst_sequence``.
        """
        out = super().fmu_parameters(values, n_beacons)
        rows = profile_table(values.get("sound_speed_profile", "constant"), values.get("sound_speed_table", ""),
                             values.get("temperature", 15.0), values.get("salinity", 35.0))
        out.update(PROFILE.values(rows, "sound_speed_rows"))
        # a pbi pinger's intervals (none: an empty table, what every other pinger has)
        out.update(BURSTS.values(burst_sequence(values.get("burst_sequence", "")), "burst_sequence_rows"))
        # volume absorption at the signal's frequency in the site's own water (the column's mean, each depth at
        # the temperature its cast gives)
        out["absorption"] = sonar.water_column_absorption(
            values.get("frequency", 25000.0), rows, values.get("temperature", 15.0), values.get("salinity", 35.0),
            values.get("water_depth", 0.0))
        return out

    @classmethod
    def config_values(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """Configuration keys from FMU parameters: a sound-speed table becomes ``sound_speed_profile = table``, a
        pinger's table of intervals ``burst_sequence``."""
        out = super().config_values(values, n_beacons)
        rows = PROFILE.rows(values, "sound_speed_rows")
        out["sound_speed_profile"] = "table" if rows.shape[0] else "constant"
        out["sound_speed_table"] = format_table(rows)
        out["burst_sequence"] = format_table(BURSTS.rows(values, "burst_sequence_rows"))
        return out

    @classmethod
    def build(cls, n_beacons: int):
        n = n_beacons
        packet = [v.name for v in cls.outputs(n)]
        lanes = {v.name for v in lane_variables(n, "output")}
        fields = [v.name for v in lane_fields(n) + EXCHANGE]
        # what a packet in flight carries: every output of lane 1 but the refusal signal and what its slot counter
        # gives (the beacon and the transmit epoch, computed again at delivery as the slot computed them)
        carried = [name for name in packet
                   if name not in {v.name for v in OVERFLOW + OVERRUN} | {"beacon_id", "tx_time"} | lanes]
        queue = [(f"q_{name}", FLIGHT_CAPACITY) for name in carried] + [("q_used", FLIGHT_CAPACITY)]
        b = ProgramBuilder(cls, n, states=[("t0", 1), ("k", 1)] + [(name, 1) for name in packet] + queue
                           + [("delivered_end", 1), ("lanes_used", 1), ("lanes_held", 1),
                              ("ocean_frequency", OCEAN_FEATURES),
                              ("ocean_phase", OCEAN_FEATURES), ("ping_epoch", 1), ("ping_count", 1),
                              ("ping_leg", 1)],
                           derived=[("nodes", NODES), ("slowness", NODES), ("speeds", NODES),
                                    ("ray_bounds", len(RAY_BOUNDS)), ("ray_grid", sum(RAY_GRID)),
                                    ("ray_values", len(RAY_TABLE.columns) * RAY_TABLE_ROWS), ("site", len(SITE)),
                                    ("family_values", len(FAMILY_TABLE.columns) * RAY_TABLE_ROWS),
                                    ("ping_steps", MAX_BURSTS), ("ping_prefix", MAX_BURSTS + 1),
                                    ("ping_rows", 1), ("ping_cycle", 1), ("ping_shortest", 1), ("ping_spread", 1)])
        true_names, sent_names = beacon_names(n, "true"), beacon_names(n, "broadcast")
        # the interface's system measures a direction of arrival (USBL): it interrogates, the array measures
        direction = interface_system(n).measures_direction

        def pinger(p):
            """toa: the pinger's nominal intervals (``ping_steps``: ``pbi``'s table, zeros past its rows; ``sbi``,
            ``rbi`` one, P or the uniform's mean), their count, the running sums from 0, the cycle's length, the
            shortest and the std of an interval's random part (:func:`ping_nominal`,
            :func:`ping_interval_drawn`)."""
            rbi, pbi = p["ping_type"] == RBI, p["ping_type"] == PBI
            # sbi: ping_interval, 0 taking the round-robin cycle of the n receivers
            single = ca.if_else(rbi, 0.5 * (p["burst_interval_min"] + p["burst_interval_max"]),
                                ca.if_else(p["ping_interval"] > 0, p["ping_interval"], n * p["slot_period"]))
            table, rows = p[BURSTS.columns[0].name], p["burst_sequence_rows"]
            in_use = ca.DM(list(range(MAX_BURSTS))) < rows
            first = ca.DM([1.0] + [0.0] * (MAX_BURSTS - 1))
            steps = ca.if_else(pbi, table * in_use, first * single)
            shortest = ca.if_else(pbi, ca.mmin(table + (1 - in_use) * 2.0 * MAX_PING_INTERVAL),
                                  ca.if_else(rbi, p["burst_interval_min"], single))
            return {"ping_steps": steps, "ping_prefix": ca.vertcat(0.0, cumulative_sum(steps)),
                    "ping_rows": ca.if_else(pbi, ca.fmax(rows, 1), 1), "ping_cycle": ca.sum1(steps),
                    "ping_shortest": shortest,
                    "ping_spread": ca.if_else(rbi, (p["burst_interval_max"] - p["burst_interval_min"])
                                              / math.sqrt(12.0), p["ping_jitter"])}

        def prepare(p):
            depth, speed = p[PROFILE.columns[0].name], p[PROFILE.columns[1].name]
            nodes, slowness = profile_nodes(p["sound_speed_rows"], depth, speed)
            speeds = node_speeds(p["sound_speed_rows"], depth, speed)[1]
            # a constant profile (no rows) never reads them: skip the table work (a short-circuit conditional)
            values = ca.vertcat(nodes, slowness, speeds)
            values = ca.if_else(p["sound_speed_rows"] > 0, values, ca.MX.zeros(values.shape), True)
            bounds = ca.vertcat(*[p[name] for name in RAY_BOUNDS])
            table = ray_values([p[c.name] for c in RAY_TABLE.columns])
            # a run without an eigenray table (every straight run) never reads it: skip its copy, as above
            table = ca.if_else(p["ray_table_rows"] > 0, table, ca.MX.zeros(table.shape), True)
            family = ray_values([p[c.name] for c in FAMILY_TABLE.columns])
            family = ca.if_else(p["ray_family_rows"] > 0, family, ca.MX.zeros(family.shape), True)  # (snr runs)
            return {"nodes": values[:NODES], "slowness": values[NODES:2 * NODES], "speeds": values[2 * NODES:],
                    "ray_bounds": bounds, "ray_grid": ray_grid([bounds[j] for j in range(len(RAY_BOUNDS))]),
                    "ray_values": table,
                    "site": site_numbers(p), "family_values": family, **pinger(p)}

        def init(p, d, w, t0):
            zero = {name: 0 for name in packet}
            empty = {name: ca.SX.zeros(size) for name, size in queue}
            return {"t0": t0, "k": 0, **zero, "tx_time": t0, "rx_time": t0, **empty,
                    "delivered_end": t0 - p["slot_period"], "lanes_used": 1, "lanes_held": 1,
                    # the moving ocean's features, drawn once per run (their own streams)
                    "ocean_frequency": w[_OCEAN_FREQUENCY] / p["ntd_time_scale"],
                    "ocean_phase": 2.0 * math.pi * w[_OCEAN_PHASE],
                    # toa: the first ping, an interval of the pinger's clock after the start
                    "ping_epoch": t0 + ping_interval_drawn(p, d, 1, w[_PING_JITTER][0]),
                    "ping_count": 0, "ping_leg": 0}

        def due(x, u, p, d, t, h):
            return sample_due(x["k"], x["t0"], p["slot_period"], t, h)

        slot = partial(_slot, n, true_names, sent_names, direction, queue, carried)

        def deliverable(x, u, p, d, t, h):
            """Guard of the delivery: a packet has arrived by the end of the step, and none was delivered in it
            (the last delivery's step end lies before this step's middle)."""
            any_arrived = 0
            for flag in _arrived(x, t, h):
                any_arrived = ca.logic_or(any_arrived, flag)
            return ca.logic_and(any_arrived, x["delivered_end"] < t + 0.5 * h)

        def earliest(x, p, d, t, h):
            """The in-flight place of the arrived packet of earliest arrival (then lowest slot counter), and its
            packet (carried outputs, the beacon and the transmit epoch) by output name."""
            best, best_rx, best_seq = 0, ca.inf, ca.inf
            for j, flag in enumerate(_arrived(x, t, h)):
                rx, seq = x["q_rx_time"][j], x["q_packet_seq"][j]
                better = ca.logic_and(flag, ca.logic_or(rx < best_rx, ca.logic_and(rx == best_rx, seq < best_seq)))
                best = ca.if_else(better, j, best)
                best_rx, best_seq = ca.if_else(better, rx, best_rx), ca.if_else(better, seq, best_seq)
            out = dict(zip(carried, get_row([x[f"q_{name}"] for name in carried], best)))
            seq = out["packet_seq"]
            out.update(beacon_id=ca.fmod(seq - 1, n) + 1, tx_time=sent_epoch(x, p, d, seq, n))
            used = ca.vertcat(*[ca.if_else(best == j, 0.0, x["q_used"][j]) for j in range(FLIGHT_CAPACITY)])
            return out, used

        def deliver(x, u, p, d, w, t, h):
            """The arrived packet of earliest arrival (then lowest slot counter) becomes the outputs (lane 1)."""
            out, used = earliest(x, p, d, t, h)
            return {**out, "q_used": used, "delivered_end": t + h, "lanes_used": 1}

        def another(x, u, p, d, t, h):
            """Guard of the later lanes: the step delivered (lane 1), another packet has arrived, a lane is free."""
            any_arrived = 0
            for flag in _arrived(x, t, h):
                any_arrived = ca.logic_or(any_arrived, flag)
            return ca.logic_and(ca.logic_and(any_arrived, x["delivered_end"] == t + h), x["lanes_used"] < LANES)

        def deliver_lane(x, u, p, d, w, t, h):
            """The next arrived packet (in the order of arrival) on the next lane of the delivery."""
            out, used = earliest(x, p, d, t, h)
            lane = x["lanes_used"] + 1
            placed = {lane_name(m, name): ca.if_else(lane == m, out[name], x[lane_name(m, name)])
                      for m in range(2, LANES + 1) for name in fields}
            return {**placed, "q_used": used, "lanes_used": lane, "lanes_held": ca.fmax(x["lanes_held"], lane)}

        def stale(x, u, p, d, t, h):
            """Guard of the clearing: lanes hold packets of an earlier delivery than this one's."""
            return x["lanes_held"] > x["lanes_used"]

        def clear(x, u, p, d, w, t, h):
            """Empty the lanes beyond this delivery's (packet_seq and every field 0)."""
            return {**{lane_name(m, name): ca.if_else(m > x["lanes_used"], 0.0, x[lane_name(m, name)])
                       for m in range(2, LANES + 1) for name in fields}, "lanes_held": x["lanes_used"]}

        def output(x, p, d, t):
            return {name: x[name] for name in packet}

        streams = (Stream(_CHANNEL_UNIFORM, "uniform", 3), Stream(_RANGE_NOISE, "normal", 1))
        events = []
        # a slot event per (ranging, propagation, detection): a run computes its own legs and what it hears
        modes = [(propagation, "fixed") for propagation in PROPAGATION] + [("ray", "snr")]
        for propagation, detection in modes:
            chosen = {"propagation": (propagation,), "detection": (detection,)}
            heard = (Stream(_DETECTION, "uniform", DETECTION_DRAWS),) if detection == "snr" else ()
            suffix = f"{propagation}" + ("_snr" if detection == "snr" else "")
            if direction:
                events.append(b.event(f"slot_{suffix}", due, slot("twtt", propagation, detection), streams + (
                    Stream(_TURNAROUND, "normal", 1), Stream(_ANGLE_NOISE, "normal", 2),
                    Stream(_DOWNLINK, "uniform", 1)) + heard, when=chosen))
                continue
            for ranging in RANGING[:TOA]:
                extra = (Stream(_TURNAROUND, "normal", 1),) if ranging == "twtt" else ()
                events.append(b.event(f"slot_{ranging}_{suffix}", due, slot(ranging, propagation, detection),
                                      streams + extra + heard, when={"ranging": (ranging,), **chosen}))
            # an inverted LBL: one leg per receiver of each of the target's pings
            events.append(b.event(f"ping_{suffix}", ping_due, partial(_ping, n, true_names, sent_names, queue,
                                                                      carried)(propagation, detection),
                                  streams + (Stream(_PING_JITTER, "uniform", 1),) + heard,
                                  when={"ranging": ("toa",), **chosen}))
        events.append(b.event("deliver", deliverable, deliver))  # after the slots: a packet is sent, then arrives
        events += [b.event("deliver_lane", another, deliver_lane), b.event("clear_lanes", stale, clear)]
        ocean = (Stream(_OCEAN_FREQUENCY, "normal", OCEAN_FEATURES), Stream(_OCEAN_PHASE, "uniform", OCEAN_FEATURES),
                 Stream(_PING_JITTER, "uniform", 1, when=("ranging", "toa")))
        return b.program(b.prepare(prepare), b.init(init, ocean), b.output(output), events=events)


__all__ = ["Acoustics", "ARRIVAL", "ARRIVAL_SLACK", "ATTITUDE_ANGLES", "BURSTS", "burst_sequence", "check_in_flight",
           "check_pinger", "MAX_BURSTS", "MAX_PING_INTERVAL", "PBI", "PING_KEYS", "PING_TYPES", "ping_interval_drawn",
           "ping_intervals", "ping_nominal", "ping_spread", "RBI", "DETECTION", "DIRECTION",
           "DOA_ARRAY", "EXCHANGE", "FAMILY_TABLE_VARIABLES", "FIXED_KEYS", "FLIGHT_CAPACITY", "LANES", "lane_fields",
           "lane_name", "lane_of", "lane_variables", "nominal_ping_interval", "OCEAN_FEATURES", "ocean_perturbation",
           "OCEAN_VARIABLES",
           "OVERFLOW", "OVERRUN", "OWTT_ITERATIONS", "PACKET", "PING_VARIABLES", "ping_due", "PROPAGATION", "RANGING",
           "RECEIVER_CLOCK_VARIABLES",
           "sent_epoch", "site_levels", "site_numbers", "site_vector", "SNR_KEYS", "TARGET_INPUTS", "TOA"]
