"""The channel's declared interface: its variables (parameters and outputs, in the order their value references
keep) and the constants the other modules of :mod:`sblsim.models.acoustics.channel` share.

Here are the ranging modes (:data:`RANGING`), the packet a slot delivers (:data:`PACKET`) with the truth of its
exchange (:data:`EXCHANGE`), USBL's direction of arrival (:data:`DIRECTION`, :data:`DOA_ARRAY`), the arrival and
refusal signals (:data:`ARRIVAL`, :data:`OVERFLOW`, :data:`OVERRUN`), the in-flight places and delivery lanes
(:data:`FLIGHT_CAPACITY`, :data:`LANES`), the propagation (:data:`PROPAGATION_VARIABLES`, the eigenray table's
:data:`RAY_TABLE_VARIABLES`), the detection by signal-to-noise (:data:`DETECTION_VARIABLES`, the family table's
:data:`FAMILY_TABLE_VARIABLES`) and the range noise's growth with distance (:data:`RANGE_LAW`). The moving
ocean's variables are :mod:`~sblsim.models.acoustics.channel.ocean`'s, the pinger's
:mod:`~sblsim.models.acoustics.channel.pinger`'s; :meth:`Acoustics.variables
<sblsim.models.acoustics.channel.component.Acoustics.variables>` puts them all in their order.

The random streams of the channel (``_CHANNEL_UNIFORM`` … ``_PING_JITTER``, the indices of
:class:`~sblsim.models.program.Stream`) are the package's own: every module that draws names them from here.
"""

from __future__ import annotations

from sblsim.models.acoustics import boundary_loss
from sblsim.models.acoustics.detection import NO_SNR
from sblsim.models.acoustics.ray_tables import FAMILY_TABLE, RAY_BOUNDS, RAY_TABLE, RAY_TABLE_ROWS
from sblsim.models.declarations import Variable, signal_range
from sblsim.models.platform.waves import WAVE_HEIGHT

(_CHANNEL_UNIFORM, _RANGE_NOISE, _TURNAROUND, _ANGLE_NOISE, _DOWNLINK, _DETECTION, _OCEAN_FREQUENCY,
 _OCEAN_PHASE, _PING_JITTER) = range(9)
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
    Variable("bottom", "parameter", "String", "sand", choices=tuple(boundary_loss.BOTTOMS),
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


#: The range noise's growth with distance (the law of :mod:`sblsim.models.acoustics.range_law`: ``σ = σ₀ + k d``,
#: d the range's true length, ``range_true``), declared after every other variable so that the value references of
#: every earlier one stay; 0 keeps every number a run prints.
RANGE_LAW: tuple[Variable, ...] = (
    Variable("range_k", "parameter", "Real", 0.0, "1",
             "range noise growth with distance: sigma = sigma_range + range_k * range (0: constant)",
             min=0.0, max=0.1),
)


__all__ = ["ARRIVAL", "ARRIVAL_SLACK", "ATTITUDE_ANGLES", "DETECTION", "DETECTION_DRAWS", "DETECTION_VARIABLES",
           "DIRECTION", "DOA_ARRAY", "EXCHANGE", "FAMILY_TABLE_VARIABLES", "FIXED_KEYS", "FLIGHT_CAPACITY", "LANES",
           "MAX_WATER_DEPTH", "OVERFLOW", "OVERRUN", "OWTT_ITERATIONS", "PACKET", "PROPAGATION",
           "PROPAGATION_VARIABLES", "RANGE_LAW", "RANGING", "RAY_TABLE_VARIABLES", "SNR_KEYS", "TARGET_INPUTS", "TOA"]
