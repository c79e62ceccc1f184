"""What a receiver declares: the inputs and outputs every receiver shares (the packet, the depth reading, the
estimate, the instrumentation fix, the covariance), its clock, what the interface's system and the channel's lanes
add, and the parameters of the Kalman-type receivers (R, the motion model, the error states, the pinger, the range
law), each block declared where the value references of every earlier variable stay what they were before it
existed.

Before the first update with a received packet the estimate ``est_*`` is undefined (NaN,
:data:`~sblsim.models.receiver.core.NO_ESTIMATE`, never the initial state) and ``est_valid`` is false (true from that
update on), ``nis`` is 0, and ``instr_valid`` is false with ``instr_*`` 0; every other output is finite.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca

from sblsim.models.acoustics.channel.interface import ARRIVAL, PACKET, RANGING
from sblsim.models.acoustics.channel.lanes import lane_variables
from sblsim.models.acoustics.channel.pinger import MAX_PING_INTERVAL
from sblsim.models.declarations import Variable, signal_range
from sblsim.models.receiver.motion import CONSTANT_VELOCITY
from sblsim.models.systems import MIN_R_SIGMA, SYSTEMS, interface_system

#: The state entries of the built-in motion model, as the ``x0_*`` parameters and ``est_*`` outputs name them.
STATE_NAMES = CONSTANT_VELOCITY.state_names
_AXES = {"x": "North", "y": "East", "z": "Down"}


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
    ``est_*`` are NaN (:data:`~sblsim.models.receiver.core.NO_ESTIMATE`), true from it on. Every built-in receiver
    declares it after every other
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


__all__ = ["arrival_interface", "beacon_parameters", "clock_parameters", "COVARIANCE", "covariance_outputs",
           "error_parameters", "estimate_validity", "filter_parameters", "late_inputs", "OPTIONAL_OUTPUTS",
           "ping_parameters", "range_law_parameters", "receiver_interface", "STATE_NAMES", "system_interface"]
