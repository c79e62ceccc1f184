"""What every receiver shares: the interface, the packet handling, the instrumentation fix,
and :class:`KalmanReceiver`, the base of the Kalman-type receivers.

Every receiver runs at its own communication step Δt = T / (EKF rate ratio)
(the ``communication_step`` parameter, set by the orchestrator) and shares
the packet handling (:func:`slot_due`, :func:`take_packet`): a replicate has
a new *slot* when a lane of the channel's delivery holds a packet other than
the last one it used there (lane 1, the packet inputs themselves: its
``packet_seq`` changed; lane m, ``lane<m>_*``: a ``packet_seq`` above 0), the end
of the step has reached the packet's arrival epoch,
``t + h ≥ rx_time − 1 ns`` (the channel delivers a packet in the step that
reaches its arrival, so a receiver stepping faster than the channel uses it
at its first step end after the arrival, never before), and the step has reached a new tick
``t0 + k·Δt`` of the receiver's own clock (:func:`clock_tick`). The last
condition changes nothing when a host steps at Δt, as every host of sblsim
does; it keeps the receiver on its own clock when a host takes other steps:
a host that adds its steps up in floating point ends a run a picosecond
short and then takes a step of 1e-12 s, in which no tick falls, so the
packet it shows then waits for the next tick instead of being used at once.
Packets that arrived in one step are slots of that step, one after the other
in the order they arrived (the lanes' order; :func:`slot_events`). At a slot
a packet that was received (``packet_valid``) with a beacon id in
``1 … n`` is the *fresh* range.

A Kalman-type receiver is one class: its parameter declarations, a
``predict`` and a ``correct`` step as casadi expressions
(:class:`KalmanReceiver`); the base class makes the program: a prediction
every step, the correction at every slot, the raw instrumentation fix (a
least-squares multilateration of the latest range of every beacon and the
depth, no filter) at the same instants, and the outputs. Before the first
update with a received packet the estimate ``est_*`` is undefined (NaN,
:data:`NO_ESTIMATE`, never the initial state) and ``est_valid`` is false (true
from that update on), ``nis`` is 0, and ``instr_valid`` is false with
``instr_*`` 0; every other output is finite.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
"""

from __future__ import annotations

import math
from dataclasses import replace

import casadi as ca

from sblsim.models.acoustics.channel.interface import ARRIVAL, LANES, PACKET, RANGING, TOA
from sblsim.models.acoustics.channel.lanes import lane_fields, lane_name, lane_variables
from sblsim.models.acoustics.channel.pinger import MAX_PING_INTERVAL
from sblsim.models.component import Component
from sblsim.models.declarations import Variable, signal_range
from sblsim.models.expressions import get_row, sample_due, select
from sblsim.models.program import ProgramBuilder
from sblsim.models.receiver import kalman
from sblsim.models.receiver.gate import gate, gate_threshold
from sblsim.models.receiver.measurement import RangeDepthModel
from sblsim.models.receiver.motion import CONSTANT_VELOCITY
from sblsim.models.receiver.multilateration import LM_STATE, lm_iteration, lm_start, weights
from sblsim.models.receiver.profile import (
    PROFILE_DERIVED,
    declares_profile,
    profile_config_values,
    profile_fmu_parameters,
    profile_parameters,
    profile_prepare,
    profile_range,
    profile_when,
)
from sblsim.models.systems import MIN_R_SIGMA, SYSTEMS, interface_system

#: The state entries of the built-in motion model, as the ``x0_*`` parameters and ``est_*`` outputs name them.
STATE_NAMES = CONSTANT_VELOCITY.state_names
_AXES = {"x": "North", "y": "East", "z": "Down"}
#: Iteration cap and step tolerance [standard deviations of the fix] of the instrumentation fix.
INSTRUMENT_ITERATIONS, INSTRUMENT_TOLERANCE = 8, 1e-3
#: The sound speed that dates a USBL packet's reply from its arrival and range (:func:`reply_epoch`; 3 % off
#: moves the epoch by 3 % of the two travel times) [m/s].
REFERENCE_SOUND_SPEED = 1500.0
#: Slack of the slot test ``t + Δt ≥ rx_time − SLOT_SLACK`` [s] (the channel's delivery test has the same).
SLOT_SLACK = 1e-9


def receiver_interface() -> tuple[Variable, ...]:
    """Inputs and outputs every receiver shares (EKF, least squares, a user's FMU)."""
    inputs = tuple(replace(v, causality="input") for v in PACKET) + (
        Variable("depth", "input", "Real", 0.0, "m", "Depth-sensor reading", discrete=True,
                 **signal_range("depth")),
    )
    outputs = tuple(
        Variable(f"est_{n}", "output", "Real", 0.0, "m" if n[0] != "v" else "m/s",
                 f"Estimated {'position' if n[0] != 'v' else 'velocity'}, {_AXES[n[-1]]} (NaN before the first fix: "
                 "est_valid false)", discrete=True)
        for n in ("x", "y", "z", "vx", "vy", "vz")
    ) + tuple(
        Variable(f"instr_{a}", "output", "Real", 0.0, "m",
                 f"Instrumentation (multilateration) fix, {_AXES[a]} (0 without a fix)", discrete=True)
        for a in ("x", "y", "z")
    ) + (
        Variable("instr_valid", "output", "Boolean", False, description="Instrumentation fix available"),
        Variable("nis", "output", "Real", 0.0, "1", "Normalized innovation squared of the last update (0: none)",
                 discrete=True),
        Variable("pos_std", "output", "Real", 0.0, "m", "sqrt(trace) of the position covariance", discrete=True),
    ) + tuple(
        Variable(f"cov_{ab}", "output", "Real", 0.0, "m2", f"Position covariance, {_AXES[ab[0]]}-{_AXES[ab[1]]}",
                 discrete=True) for ab in COVARIANCE
    ) + (
        Variable("gated", "output", "Boolean", False, description="The last slot's range was rejected by the NIS gate"),
    )
    return inputs + outputs


#: The six unique entries of the position covariance, by axis pair.
COVARIANCE = ("xx", "xy", "xz", "yy", "yz", "zz")


def estimate_validity() -> tuple[Variable, ...]:
    """``est_valid``, what says whether the estimate ``est_*`` is defined: false before the receiver's first fix (a
    Kalman-type receiver's first update with a received packet, the least-squares receiver's first valid fix), when
    ``est_*`` are NaN (:data:`NO_ESTIMATE`), true from it on. Every built-in receiver declares it after every other
    variable (so that the value references of every earlier one stay what they were before it existed); a user's
    FMU may lack it (:data:`OPTIONAL_OUTPUTS`)."""
    return (Variable("est_valid", "output", "Boolean", False,
                     description="The receiver has made its first fix: est_* defined from then on (false: no fix "
                                 "yet, est_* NaN)"),)


#: The receiver's outputs a user's FMU may lack (written before they existed): a run records them where the
#: receiver has them.
OPTIONAL_OUTPUTS = tuple(v.name for v in estimate_validity())


def covariance_outputs(P) -> dict[str, ca.SX]:
    """The ``cov_*`` outputs of a 3 × 3 position covariance [m²]."""
    index = {"x": 0, "y": 1, "z": 2}
    return {f"cov_{ab}": P[index[ab[0]], index[ab[1]]] for ab in COVARIANCE}


def system_interface(n_beacons: int) -> tuple[Variable, ...]:
    """What a receiver of ``n_beacons`` declares after its clock: every system's receiver parameters (configuration
    keys whatever the system: the USBL angle std), then the inputs the interface's system adds to the packet (the
    USBL direction of arrival)."""
    parameters = tuple(v for s in SYSTEMS.values() for v in s.receiver_parameters())
    return parameters + interface_system(n_beacons).receiver_inputs()


def arrival_interface() -> tuple[Variable, ...]:
    """The packet's arrival epoch ``rx_time`` (the channel's :data:`~sblsim.models.acoustics.core.ARRIVAL`), an
    input of every receiver: declared last, so that the value references of every earlier variable stay what
    they were before it existed."""
    return tuple(replace(v, causality="input") for v in ARRIVAL)


def late_inputs(n_beacons: int) -> tuple[Variable, ...]:
    """What the interface's system adds to a receiver's inputs after every other variable (the attitude of a USBL
    packet's direction, :meth:`~sblsim.models.systems.System.receiver_late_inputs`), so that the value references
    of every earlier variable stay what they were before it existed; then the lanes 2 … of a delivery (the
    packets that arrived in the same step after lane 1's,
    :func:`~sblsim.models.acoustics.core.lane_variables`), last of all."""
    return interface_system(n_beacons).receiver_late_inputs() + lane_variables(n_beacons, "input")


def clock_parameters() -> tuple[Variable, ...]:
    """The receiver's own clock: declared after the receiver interface, so that the value references of every
    earlier variable stay what they were before the clock existed."""
    return (Variable("communication_step", "parameter", "Real", 0.1, "s",
                     "The receiver's own communication step T / EKF rate ratio: new packets are taken at its ticks "
                     "t0 + k*step, whatever steps a host takes", min=1e-6, max=60.0, min_exclusive=True,
                     scope="fmu"),)


def packet_states(n_beacons: int) -> list[tuple[str, int]]:
    """State blocks of the packet handling: held ranges and beacon positions, heard flags, the last slot, and the
    receiver's clock (ticks reached since ``tick_t0``)."""
    return [("ranges", n_beacons), ("beacons", 3 * n_beacons), ("heard", n_beacons), ("last_seq", 1),
            ("slot_time", 1), ("tick", 1), ("tick_t0", 1), ("lane_seq", LANES - 1)]


def packet_init(n_beacons: int, t0) -> dict[str, ca.SX]:
    return {"ranges": ca.SX.zeros(n_beacons), "beacons": ca.SX.zeros(3 * n_beacons),
            "heard": ca.SX.zeros(n_beacons), "last_seq": 0, "slot_time": 0, "tick": 0, "tick_t0": t0,
            "lane_seq": ca.SX.zeros(LANES - 1)}


def clock_due(x, u, p, d, t, h) -> ca.SX:
    """Guard of the clock event: the end of the step has reached the receiver's next tick."""
    return sample_due(x["tick"], x["tick_t0"], p["communication_step"], t, h)


def clock_tick(x, u, p, d, w, t, h) -> dict[str, ca.SX]:
    """Handler of the clock event: one more tick reached."""
    return {"tick": x["tick"] + 1}


def clock_step(x, p, t, h) -> dict[str, ca.SX]:
    """The clock's first tick of a step, taken in the step function (the clock event, which runs first, then
    takes only the further ticks of a step longer than the receiver's: the same ticks, one handler call less)."""
    return {"tick": x["tick"] + clock_due(x, None, p, None, t, h)}


def lanes_due(x, u, p, t, h) -> list[ca.SX]:
    """Per lane of the channel's delivery (:data:`~sblsim.models.acoustics.core.LANES`): a new packet whose arrival
    epoch the end of the step has reached, in a step that reached a tick of the receiver's clock (the last tick lies
    after the step's start; the clock event runs first). Lane 1 is new when its ``packet_seq`` differs from the last
    one used there (``last_seq``), lane m when it holds a packet (``packet_seq`` > 0) other than the last one used
    there (``lane_seq``)."""
    ticked = _ticked(x, p, t)
    due = [_lane_one_due(x, u, t, h, ticked)]
    for m in range(2, LANES + 1):
        seq, rx = u[lane_name(m, "packet_seq")], u[lane_name(m, "rx_time")]
        new = ca.logic_and(ca.logic_and(seq > 0, seq != x["lane_seq"][m - 2]), t + h >= rx - SLOT_SLACK)
        due.append(ca.logic_and(new, ticked))
    return due


def _ticked(x, p, t) -> ca.SX:
    """The step reached a tick of the receiver's clock (its last tick lies after the step's start)."""
    return x["tick_t0"] + x["tick"] * p["communication_step"] > t + 1e-6 * p["communication_step"]


def _lane_one_due(x, u, t, h, ticked) -> ca.SX:
    """Lane 1 of the delivery (the packet inputs themselves) is due (:func:`lanes_due`)."""
    return ca.logic_and(ca.logic_and(u["packet_seq"] != x["last_seq"], t + h >= u["rx_time"] - SLOT_SLACK), ticked)


def lane_one_due(x, u, p, t, h) -> ca.SX:
    """Lane 1 holds a packet the receiver may use now and takes first (:func:`lanes_due`; not the first of an
    inverted LBL's new ping, whose lane :func:`ping_anchor` chooses among the ping's arrivals)."""
    due = _lane_one_due(x, u, t, h, _ticked(x, p, t))
    return ca.logic_and(due, ca.logic_not(new_ping(x, u, p))) if "ping_jitter" in p else due


def slot_due(x, u, p, t, h) -> ca.SX:
    """A lane of the delivery holds a packet the receiver has not used and may use now (:func:`lanes_due`)."""
    due = lanes_due(x, u, p, t, h)
    any_due = due[0]
    for flag in due[1:]:
        any_due = ca.logic_or(any_due, flag)
    return any_due


def first_lane(due) -> ca.SX:
    """The first due lane (0-based) of the flags ``due`` (:func:`lanes_due`; the last lane where none is)."""
    lane = LANES - 1
    for m in reversed(range(LANES - 1)):
        lane = ca.if_else(due[m], m, lane)
    return lane


def next_lane(x, u, p, t, h, n_beacons: int, model=None) -> tuple[ca.SX, dict[str, ca.SX]]:
    """The lane a slot uses (0-based: the first due one, lanes being in the order of arrival; for an inverted LBL's
    new ping, the receiver ``model``'s :func:`ping_anchor`) and the inputs with that lane's packet in place of lane
    1's (its fields :func:`~sblsim.models.acoustics.core.lane_fields`)."""
    due = lanes_due(x, u, p, t, h)
    lane = first_lane(due)
    if model is not None and "ping_jitter" in p:
        lane = ping_anchor(model, x, u, p, t, h, n_beacons, due, lane)
    names = [v.name for v in lane_fields(n_beacons)]  # read at the lane (a parametric index: no if_else per lane)
    chosen = get_row([ca.vertcat(*[u[lane_name(m, name)] for m in range(1, LANES + 1)]) for name in names], lane)
    return lane, {**u, **dict(zip(names, chosen))}


def ping_anchor(model, x, u, p, t, h, n_beacons: int, due, first) -> ca.SX:
    """The lane an inverted LBL's receiver takes first of a new ping's arrivals delivered in one step: the one whose
    range is the shortest against the prediction (its innovation the least; the emission offset of the state,
    the ranges at the ping's emission), where ``first`` (the first due lane) is as said for any other slot.

    A ping's first update sets its emission offset (the jitter's step leaves it open) and cannot be judged; a
    multipath arrival is late, never early, so the arrival that is the least late against the others is the one
    to set it, whatever the order in which they arrived; the gate then judges the others against it (the same
    information as in the order of arrival, for a filter that takes every arrival: Kalman updates commute).

    Returns
    -------
    casadi.SX
        The lane (0-based).
    """
    field = [{name: u[lane_name(m, name)] for name in ("tx_time", "range", "beacon_id", "packet_valid", "beacon_x",
                                                        "beacon_y", "beacon_z")} for m in range(1, LANES + 1)]
    ping = select(first, [f["tx_time"] for f in field])
    state = x["x"]
    epoch = ping + model.motion.clock_offset(state)
    then = ca.mtimes(model.motion.transition(-ca.fmax(t + h - epoch, 0.0)), state)
    clock = clock_scale(p)
    best, least = first, ca.inf
    for m, f in enumerate(field):
        index = f["beacon_id"] - 1
        taken = ca.logic_and(ca.logic_and(due[m], f["tx_time"] == ping),
                             ca.logic_and(f["packet_valid"], ca.logic_and(index >= 0, index < n_beacons)))
        beacon = ca.vertcat(f["beacon_x"], f["beacon_y"], f["beacon_z"])
        y = f["range"] - model.measurement.range_row(then, beacon, clock)[0]
        better = ca.logic_and(taken, y < least)
        best, least = ca.if_else(better, m, best), ca.if_else(better, y, least)
    return ca.if_else(new_ping(x, {"tx_time": ping}, p), best, first)


def lane_used(x, out, lane, seq) -> dict[str, ca.SX]:
    """The lanes' memory after a slot used the packet ``seq`` of ``lane`` (0-based; the slot's own ``out`` wrote
    ``last_seq``, kept for lane 1 alone)."""
    return {"last_seq": ca.if_else(lane == 0, out["last_seq"], x["last_seq"]),
            "lane_seq": ca.vertcat(*[ca.if_else(lane == m, seq, x["lane_seq"][m - 1]) for m in range(1, LANES)])}


def fresh_packet(u, n_beacons: int) -> ca.SX:
    """The slot's packet was received and names a beacon of the array."""
    index = u["beacon_id"] - 1
    return ca.logic_and(u["packet_valid"], ca.logic_and(index >= 0, index < n_beacons))


def take_packet(x, u, n_beacons: int) -> dict[str, ca.SX]:
    """The held ranges after a slot: a received packet replaces its beacon's range and position."""
    index = u["beacon_id"] - 1
    fresh = fresh_packet(u, n_beacons)
    position = ca.vertcat(u["beacon_x"], u["beacon_y"], u["beacon_z"])
    ranges, beacons, heard = [], [], []
    for j in range(n_beacons):
        mine = ca.logic_and(fresh, index == j)
        ranges.append(ca.if_else(mine, u["range"], x["ranges"][j]))
        beacons.append(ca.if_else(mine, position, x["beacons"][3 * j:3 * j + 3]))
        heard.append(ca.if_else(mine, 1.0, x["heard"][j]))
    return {"ranges": ca.vertcat(*ranges), "beacons": ca.vertcat(*beacons), "heard": ca.vertcat(*heard),
            "last_seq": u["packet_seq"], "slot_time": u["tx_time"]}


def reanchored(motion, state, p: dict, fresh, innovation, H, S) -> tuple[ca.SX, ca.SX]:
    """An inverted LBL's arrival far shorter than predicted re-anchors its ping's emission offset.

    A multipath arrival is late, never early: an arrival whose innovation ``innovation`` [m] is negative beyond the
    NIS gate's threshold against its innovation variance ``S`` [m²], and within that threshold of the ping's jitter
    (the std of the offset's random step, ``ping_jitter``, times the sound speed: what the jitter could have made
    of the offset), says that the ping's earlier arrivals came late and set the emission offset wrong. The offset
    is moved so that this arrival has no innovation (``y / H_o``, ``H`` (1, n) the range's row, ``H_o`` the
    offset's entry: the sound speed) and the arrival is not taken as an update: as re-opening the offset (the
    ping's jitter step again) and updating with the arrival would do, the offset then set by this arrival and the
    position moved by a share ``P_pp / (c² σ_jitter²)`` of the innovation (little); its covariance is kept, that of
    an offset set by one arrival. Nothing for other ranging, or for a receiver without the pinger's parameter.

    Returns
    -------
    state : casadi.SX, (n, 1)
    short : casadi.SX
        The arrival re-anchored the offset (the update skips it).
    """
    if "ping_jitter" not in p:
        return state, 0
    o = motion.clock_index[0]
    q = gate_threshold(p["gate_probability"])
    # beyond the gate, and within what the ping's jitter could make of an emission's offset (a pinger on its
    # schedule, whose offset the state knows, has nothing to re-anchor: its short arrival updates as LBL's does)
    short = ca.logic_and(ca.logic_and(ca.logic_and(fresh, toa_ranging(p)), innovation < 0.0),
                         ca.logic_and(innovation * innovation > q * S,
                                      innovation * innovation < q * (H[o] * p["ping_jitter"]) ** 2))
    moved = ca.vertcat(*[state[i] + (innovation / H[o] if i == o else 0.0) for i in range(motion.state_size)])
    return ca.if_else(short, moved, state), short


def ping_heard(heard, x, u, p, n_beacons: int) -> ca.SX:
    """The held ranges' heard flags (n, 1) after a slot whose packet is the first of a new ping of an inverted LBL
    (:func:`new_ping`): that packet's beacon alone (the earlier ping's ranges carry another emission offset);
    ``heard`` where the slot's packet is not."""
    first, index = new_ping(x, u, p), u["beacon_id"] - 1
    mine = ca.vertcat(*[ca.logic_and(fresh_packet(u, n_beacons), index == j) for j in range(n_beacons)])
    return ca.if_else(first, mine, heard)


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
    """Start a least-squares fix of the held ranges (after :func:`take_packet`) at a slot."""
    w_r, w_d = weights(p["sigma_range"], p["sigma_depth"])
    valid = ca.sum1(x["heard"]) >= 3
    return {**lm_start(guess, x["ranges"], x["beacons"], x["heard"], depth, w_r, w_d, valid, toa_ranging(p),
                       range_law(p)),
            "lm_depth": depth}


def lm_idle() -> dict[str, ca.SX]:
    return {"lm_point": ca.SX.zeros(3), "lm_cost": 0, "lm_mu": 1e-3, "lm_iter": 0, "lm_active": 0, "lm_depth": 0}


def filter_parameters() -> tuple[Variable, ...]:
    """The parameters every Kalman-type receiver takes: R, the motion model, the initial state and covariance."""
    return (
        Variable("sigma_range", "parameter", "Real", 0.1, "m",
                 "Range standard deviation in R (at least 1 mm: below, R no longer regularizes the update)",
                 min=MIN_R_SIGMA, max=1000.0),
        Variable("sigma_depth", "parameter", "Real", 0.01, "m", "Depth standard deviation in R (at least 1 mm)",
                 min=MIN_R_SIGMA, max=1000.0),
        Variable("q_horizontal", "parameter", "Real", 0.01, "m2/s3",
                 "Process noise: horizontal acceleration spectral density", min=0.0, max=1e6),
        Variable("q_vertical", "parameter", "Real", 0.001, "m2/s3",
                 "Process noise: vertical acceleration spectral density", min=0.0, max=1e6),
        Variable("p0_position", "parameter", "Real", 1.0, "m", "Initial position standard deviation",
                 min=1e-3, max=1e6),
        Variable("p0_velocity", "parameter", "Real", 0.5, "m/s", "Initial velocity standard deviation",
                 min=1e-3, max=1e6),
    ) + tuple(
        Variable(f"x0_{n}", "parameter", "Real", 0.0, "m" if n[0] != "v" else "m/s",
                 f"Initial {'position' if n[0] != 'v' else 'velocity'} estimate, {_AXES[n[-1]]}",
                 min=-1e6, max=1e6)
        for n in ("x", "y", "z", "vx", "vy", "vz"))


def beacon_parameters() -> tuple[Variable, ...]:
    """The uncertainty of the broadcast beacon positions a receiver adds to R (defaults from the platform)."""
    return (
        Variable("beacon_gps_sigma", "parameter", "Real", 0.1, "m",
                 "Beacon position error from GPS, per axis (default: platform.gps_sigma)", min=0.0, max=1000.0),
        Variable("beacon_attitude_sigma_deg", "parameter", "Real", 1.0, "deg",
                 "Beacon attitude error (default: platform.imu_sigma_deg)", min=0.0, max=180.0),
        Variable("beacon_arm", "parameter", "Real", 1.0, "m",
                 "Distance of a beacon from the platform reference (default: from the layout)", min=0.0, max=1000.0),
    )


def error_parameters() -> tuple[Variable, ...]:
    """What a receiver that carries error states (:class:`~sblsim.models.receiver.motion.WithErrorStates`) and
    dates its ranges declares: the ranging, the GPS error's correlation time, the clock's states and the constant
    attitude error (declared after the profile's: the value references of every earlier variable stay)."""
    return (
        Variable("ranging", "parameter", "String", "owtt", choices=RANGING, scope="fmu",
                 description="The channel's ranging (acoustics.ranging): a one-way range refers to its reception "
                             "and carries the clock's offset; a two-way one refers to the mean of its legs; a "
                             "time of arrival (toa, an inverted LBL) refers to the ping's emission and carries the "
                             "emission's offset as the clock's"),
        Variable("gps_correlation_time", "parameter", "Real", 0.0, "s",
                 "0: the GPS error of the broadcast positions is white, in R; > 0: carried as three Gauss-Markov "
                 "states of this correlation time (default: platform.gps_tau with platform.gps_model = "
                 "gauss-markov)", min=0.0, max=1e6),
        Variable("clock_states", "parameter", "Boolean", False,
                 description="Carry the receiver clock's offset and drift as states (one-way ranging; default: on "
                             "when acoustics.clock_drift_ppm is not 0)"),
        Variable("clock_drift_sigma_ppm", "parameter", "Real", 1.0, "ppm",
                 "Prior std of the clock's drift (clock_states; default: |acoustics.clock_drift_ppm|)",
                 min=0.0, max=1000.0),
        Variable("attitude_bias_sigma_deg", "parameter", "Real", 0.0, "deg",
                 "USBL: prior std per Euler angle of the constant error of the attitude the surface turns the "
                 "direction with (the IMU's bias and misalignment, the array's mounting misalignment), carried "
                 "as three states; 0: none (default: from platform.imu_bias_deg, imu_misalignment_deg and "
                 "usbl_misalignment_deg)", min=0.0, max=180.0),
    )


def ping_parameters() -> tuple[Variable, ...]:
    """What a receiver that carries error states declares for an inverted LBL's pinger, after every other variable
    (so that the value references of every earlier one stay what they were before it existed)."""
    return (Variable("ping_jitter", "parameter", "Real", 0.0, "s",
                     "toa: std of the random step the emission offset (the clock offset state) takes at each new "
                     "ping, the std of the pinger's interval's random part (default: acoustics.ping_jitter; "
                     "ping_type rbi: (burst_interval_max - burst_interval_min) / sqrt(12))", min=0.0,
                     max=MAX_PING_INTERVAL),)


def range_law_parameters() -> tuple[Variable, ...]:
    """The range law every built-in receiver takes in R (:mod:`sblsim.models.acoustics.range_law`), declared after
    every other variable (so that the value references of every earlier one stay what they were before it
    existed)."""
    return (Variable("range_k", "parameter", "Real", 0.0, "1",
                     "Range noise growth with distance in R: sigma = sigma_range + range_k * predicted range "
                     "(default: acoustics.range_k)", min=0.0, max=0.1),)


def range_law(p: dict):
    """``(sigma_range, range_k)`` of a receiver that declares the range law, else None (a constant σ)."""
    return (p["sigma_range"], p["range_k"]) if "range_k" in p else None


def toa_ranging(p: dict):
    """Whether the receiver's packets are an inverted LBL's times of arrival (``ranging = "toa"``); None for a
    receiver that declares no ranging."""
    return p["ranging"] == TOA if "ranging" in p else None


#: What the last depth reading a receiver used starts as: no reading (below every depth a sensor gives).
NO_DEPTH = -1e300
#: A receiver's estimate before its first fix (its first update with a received packet; the least-squares
#: receiver's first valid fix): undefined, never its starting guess (``x0_*``, tied to the diver's true start).
#: Every metric skips it (a step without an estimate).
NO_ESTIMATE = math.nan


def depth_fresh(x: dict, u: dict, p: dict):
    """The slot may use the depth reading: always, but for an inverted LBL's times of arrival (``ranging =
    "toa"``), which arrive several in one sample of the depth sensor (a ping's burst): there a reading is used
    once, at the first slot it differs from the last one used (``depth_seen``); 1 for a receiver that declares no
    ranging."""
    if "ranging" not in p:
        return 1.0
    return ca.logic_or(p["ranging"] != TOA, u["depth"] != x["depth_seen"])


def new_ping(x: dict, u: dict, p: dict):
    """The slot's packet is the first the receiver takes of a new ping of an inverted LBL (its nominal epoch,
    ``tx_time``, is not the last slot's); 0 for other ranging."""
    return ca.logic_and(toa_ranging(p), u["tx_time"] != x["slot_time"]) if "ranging" in p else 0


def errors_of(p: dict) -> dict:
    """The ``errors`` mapping of :class:`~sblsim.models.receiver.motion.WithErrorStates` from a receiver's
    parameters (:func:`error_parameters`, :func:`beacon_parameters`): the GPS error as states where its
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
    ``then``; the state is moved to the failed range's reference epoch (:meth:`KalmanReceiver.reference`). Where
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
    :func:`filter_parameters`. The state size, the state names and where the
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
        ``epoch`` [s] (:meth:`epoch`; a USBL packet's reply, :func:`reply_epoch`), ``A = Φ(−(now − t_ref))`` of
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
        motion model carries error states, :func:`error_parameters`)."""
        return error_parameters() if cls.motion.state_size > CONSTANT_VELOCITY.state_size else ()

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        errors = cls.motion.state_size > CONSTANT_VELOCITY.state_size
        return (cls.parameters(n_beacons) + receiver_interface() + clock_parameters() + system_interface(n_beacons)
                + arrival_interface() + profile_parameters() + cls.late_parameters() + late_inputs(n_beacons)
                + (ping_parameters() if errors else ()) + range_law_parameters() + estimate_validity())

    @classmethod
    def errors(cls, p: dict) -> dict | None:
        """The motion model's ``errors`` mapping (:func:`errors_of`), or None where it carries no error states."""
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
            ``last_seq``, ``slot_time``: usually :func:`take_packet`).
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


def slot_update(b: ProgramBuilder, slot) -> ca.Function:
    """A receiver's ``slot`` as one casadi function, ``(x, u, p, d, t, h) -> x`` (the whole state; ``u`` the inputs
    with the packet the slot takes in lane 1's place), that the slot events call rather than inline: the update is
    generated and compiled once, not once per event (the compiler spent half of a receiver's time on the copy)."""
    values = slot(b.X.unpack(b.x), b.inputs(), b.params(), b.D.unpack(b.d), {}, b.t, b.h)
    return ca.Function(f"{b.prefix}_slot_update", [b.x, b.u, b.p, b.d, b.t, b.h],
                       [ca.densify(b.X.pack(values, b.X.unpack(b.x)))], ["x", "u", "p", "d", "t", "h"], ["x_next"],
                       {"never_inline": True})


def slot_events(b: ProgramBuilder, model, n_beacons: int, slot) -> list:
    """The slot events of a receiver: ``slot``, run when lane 1 of the delivery holds a packet it takes first
    (:func:`lane_one_due`: the packet inputs as they are, almost every slot), then ``slot_lanes``, run while a lane
    holds a packet it may use (:func:`slot_due`), each time with the first such lane's packet (:func:`next_lane`:
    the packets that arrived in the same step after lane 1's, and the anchor of an inverted LBL's new ping), in
    that order, as one event taking the first due lane each time would. They are for the single assumed speed;
    ``slot_profile`` and ``slot_profile_lanes`` (the packet's range turned into the slant range of the receiver's
    profile first, :func:`~sblsim.models.receiver.profile.profile_range`) for a run with a profile (a run of the
    assumed speed computes nothing of the profile's, not even its choice). Each calls the one :func:`slot_update`,
    and lane 1's reads its packet where it is rather than at a parametric lane (what every step of a run pays)."""
    update = slot_update(b, slot)

    def due(x, u, p, d, t, h):
        return slot_due(x, u, p, t, h)

    def due_one(x, u, p, d, t, h):
        return lane_one_due(x, u, p, t, h)

    def updated(x, packet, p, d, packet_of, lane):
        packet = packet_of(packet, p, d)
        out = b.X.unpack(update(b.x, ca.vertcat(*[packet[v.name] for v in b.input_vars]), b.p, b.d, b.t, b.h))
        return {**out, **lane_used(x, out, lane, packet["packet_seq"])}

    def on_lane_one(packet_of):
        def handler(x, u, p, d, w, t, h):
            return updated(x, u, p, d, packet_of, 0)
        return handler

    def on_lane(packet_of):
        def handler(x, u, p, d, w, t, h):
            lane, packet = next_lane(x, u, p, t, h, n_beacons, model)
            return updated(x, packet, p, d, packet_of, lane)
        return handler

    events = []
    for choice, when in profile_when(model.fmu_parameters_declared(n_beacons)).items():
        packet_of, name = ((lambda u, p, d: u), "slot") if choice == "assumed" else (profile_range, "slot_profile")
        events.append(b.event(name, due_one, on_lane_one(packet_of), when=when))
        events.append(b.event(f"{name}_lanes", due, on_lane(packet_of), when=when))
    return events


def profile_derived(model, n_beacons: int) -> list[tuple[str, int]]:
    """The derived blocks of a receiver's ``prepare``: the padded profile of its table where it declares one
    (:data:`~sblsim.models.receiver.profile.PROFILE_DERIVED`), else none."""
    return list(PROFILE_DERIVED) if declares_profile(model.fmu_parameters_declared(n_beacons)) else []


def profile_prepare_of(model, n_beacons: int):
    """The body of a receiver's ``prepare`` (:func:`~sblsim.models.receiver.profile.profile_prepare` where it
    declares a profile; None: nothing derived)."""
    return profile_prepare if profile_derived(model, n_beacons) else None


def first_row(model, context, covariance):
    """``row(then, transceiver)`` of :func:`earlier_innovation` for a packet whose first row is its range (USBL): the
    model's first row and R's first entry, the transceiver replaced (the rest of the context kept)."""
    def row(then, transceiver):
        ctx = (transceiver, *context[1:])
        h, H = model.linearize(then, ctx)
        return h[0], H[0, :], covariance(then)[0, 0]
    return row


def reply_epoch(u: dict) -> ca.SX:
    """The epoch a USBL packet refers to [s]: the diver's reply, the reply's and the downlink's travel times
    (``2 r / c`` at :data:`REFERENCE_SOUND_SPEED`) before the packet's arrival."""
    return u["rx_time"] - 2.0 * u["range"] / REFERENCE_SOUND_SPEED


def fresh_range(x: dict, u: dict, n_beacons: int) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The slot's fresh range: whether there is one, its value and its broadcast beacon position (3, 1)."""
    return fresh_packet(u, n_beacons), u["range"], ca.vertcat(u["beacon_x"], u["beacon_y"], u["beacon_z"])


__all__ = ["arrival_interface", "beacon_parameters", "clock_due", "clock_parameters", "clock_scale", "clock_step",
           "clock_tick", "COVARIANCE", "covariance_outputs", "depth_fresh", "earlier_innovation", "error_parameters",
           "errors_of", "estimate_validity", "filter_parameters", "first_lane", "first_row", "fresh_packet",
           "fresh_range",
           "INSTRUMENT_ITERATIONS", "INSTRUMENT_TOLERANCE", "KalmanReceiver", "late_inputs", "lm_active", "lm_begin",
           "lm_idle", "lm_states", "lm_step", "lane_one_due", "lanes_due", "lane_used", "new_ping", "next_lane",
           "NO_DEPTH", "NO_ESTIMATE", "OPTIONAL_OUTPUTS", "packet_init", "packet_states", "ping_anchor", "ping_heard",
           "ping_parameters",
           "profile_derived", "profile_prepare_of", "range_law",
           "range_law_parameters", "RangesWithProfile", "reanchored", "receiver_interface",
           "REFERENCE_SOUND_SPEED", "rejected_init", "rejected_states", "remember_rejected", "reply_epoch", "slot_due",
           "slot_events", "slot_update", "STATE_NAMES", "system_interface", "take_packet", "toa_ranging"]
