"""The checks across keys of a configuration being resolved, and the ties that fill one key from others
(:func:`sblsim.orchestrator.cosim.config.resolve` calls them in turn): the receiver's step, latency and ties, the
trajectory file, the system's keys and ranging, the pinger, the water depth, the detection and the duration; the
site keys that a detection does not read (:func:`check_site_keys`).

Ties (applied only where the user did not set the key):
``receiver.sigma_range`` ← ``acoustics.sigma_range``, ``receiver.range_k`` ← ``acoustics.range_k`` and
``receiver.sigma_depth`` ← ``target.depth_sigma`` (both floored at 1 mm: R must
be positive), ``receiver.x0_*`` ← the diver's start state, and
``simulation.duration`` ← one pass of the trajectory.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Iterable

from sblsim.models.acoustics.channel.interface import FIXED_KEYS, MAX_WATER_DEPTH, SNR_KEYS
from sblsim.models.acoustics.channel.pinger import check_pinger, ping_spread
from sblsim.models.declarations import ModelError, resolve_parameters
from sblsim.models.errors import ConfigError
from sblsim.models.receiver.interface import clock_parameters
from sblsim.models.systems import SYSTEMS
from sblsim.models.target import natural_duration, start_state
from sblsim.models.target.core import file_waypoints
from sblsim.orchestrator.cosim.config_keys import RECEIVER_KEY_NAMES, RECEIVER_KEYS, section_variables
from sblsim.orchestrator.cosim.config_notes import note
from sblsim.orchestrator.cosim.config_overrides import parse_override
from sblsim.orchestrator.cosim.limits import check_steps

MIN_SIGMA = 1e-3  # floor of the tied R standard deviations [m]


def turnaround(cfg: dict[str, dict]) -> float:
    """The nominal turnaround a packet of a resolved configuration waits for [s]: ``acoustics.turnaround`` in
    two-way ranging, 0 in one-way."""
    return float(cfg["acoustics"]["turnaround"]) if cfg["acoustics"]["ranging"] == "twtt" else 0.0


def _check_receiver_step(sim: dict[str, Any]) -> None:
    """Refuse a sampling time and rate ratio whose receiver step T / ratio is outside the receiver clock's
    range (:func:`sblsim.models.receiver.interface.clock_parameters`), naming the two keys the user sets.

    Raises
    ------
    ConfigError
        Naming ``simulation.ekf_rate_ratio``, ``simulation.sampling_time`` and the largest ratio allowed.
    """
    clock = clock_parameters()[0]
    T, ratio = sim["sampling_time"], sim["ekf_rate_ratio"]
    if T / ratio > clock.min:
        return
    largest = max(1, math.ceil(T / clock.min) - 1)
    while largest > 1 and not T / largest > clock.min:
        largest -= 1
    raise ConfigError(f"simulation.ekf_rate_ratio: {ratio} at simulation.sampling_time = {T:g} s gives the receiver "
                      f"steps of T / ratio = {T / ratio:.3g} s; they must be longer than {clock.min:g} s: a ratio of "
                      f"at most {largest} at this sampling time, or a longer sampling time")


def _orchestrator_receiver_keys(given: dict[str, Any], sim: dict[str, Any]) -> dict[str, Any]:
    """The :data:`RECEIVER_KEYS` of a receiver section, validated: ``latency`` within [0, 60] s and a whole
    number of sampling times T (:attr:`sblsim.orchestrator.cosim.plan.RunPlan.latency_steps`).

    Raises
    ------
    ConfigError
        Naming ``receiver.latency``, its allowed range or the nearest multiples of T.
    """
    try:
        keys = resolve_parameters(RECEIVER_KEYS, {k: v for k, v in given.items() if k in RECEIVER_KEY_NAMES},
                                  "receiver")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None
    latency, T = keys["latency"], sim["sampling_time"]
    ratio = latency / T
    if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
        below = math.floor(ratio) * T
        nearest = [f"{v:.10g}" for v in (below, below + T) if float(f"{v:.10g}") <= RECEIVER_KEYS[0].max]
        ekf = sim["ekf_rate_ratio"]
        note = f"; the record holds the receiver's outputs once per T, not per T / {ekf}" if ekf > 1 else ""
        raise ConfigError(f"receiver.latency: {latency:g} s is not a whole number of sampling times "
                          f"(T = {T:g} s{note}); give {' or '.join(nearest)} s")
    return keys


def _check_trajectory_file(target: dict[str, Any]) -> None:
    """Refuse a ``target.trajectory_file`` that the trajectory would not read (``trajectory`` is not ``file``):
    it would be ignored without a word.

    Raises
    ------
    ConfigError
        Naming both keys.
    """
    if target.get("trajectory_file") and target["trajectory"] != "file":
        raise ConfigError(f"target.trajectory_file: given, but target.trajectory = {target['trajectory']!r} does "
                          "not read a file; set target.trajectory = 'file' as well (--set target.trajectory=file), "
                          "or leave trajectory_file out")


def _check_system(cfg: dict[str, dict], given: set[str]) -> None:
    """The system's checks of the ``[platform]`` section (:meth:`sblsim.models.systems.System.check`: the
    beacons' count against the layout, a USBL custom layout's one lever arm), and its ranging: a system that
    allows one ranging has it whatever ``acoustics.ranging`` says (USBL interrogates: ``twtt``; the key chooses
    between one- and two-way ranging of SBL and LBL, so a study that crosses it with the system sees no effect
    of it on USBL).

    Raises
    ------
    ConfigError
        Naming the field and what is allowed.
    """
    system = SYSTEMS[cfg["platform"]["system"]]
    try:
        system.check(cfg["platform"], given)
    except ConfigError:
        raise
    except ModelError as exc:
        raise ConfigError(str(exc)) from None
    if len(system.ranging) == 1:
        cfg["acoustics"]["ranging"] = system.ranging[0]
    elif cfg["acoustics"]["ranging"] not in system.ranging:
        takes = [s.name for s in SYSTEMS.values() if cfg["acoustics"]["ranging"] in s.ranging]
        raise ConfigError(f"acoustics.ranging: {cfg['acoustics']['ranging']!r} is the ranging of platform.system = "
                          f"{' or '.join(map(repr, takes))}; platform.system = {system.name!r} allows "
                          f"{', '.join(system.ranging)}")
    try:
        system.check_receiver(cfg["simulation"]["receiver"])
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def _check_pinger(cfg: dict[str, dict], given: set[str]) -> None:
    """The pinger's keys (an inverted LBL's, ``acoustics.ping_type`` and the keys of its type; ``given`` the
    ``[acoustics]`` keys the user set): :func:`sblsim.models.acoustics.core.check_pinger`, after the system set the
    ranging.

    Raises
    ------
    ConfigError
        Naming the key and what is allowed.
    """
    try:
        check_pinger(cfg["acoustics"], given, cfg["platform"]["beacons"], cfg["simulation"]["sampling_time"])
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def _receiver_ties(cfg: dict[str, dict], given: set[str]) -> None:
    """Fill the receiver keys the user did not set from the rest of the configuration (where it declares them).

    ``sigma_range`` ← ``acoustics.sigma_range``, ``range_k`` ← ``acoustics.range_k`` (the range law) and
    ``sigma_depth`` ← ``target.depth_sigma`` (floored at 1 mm: R must be positive); ``x0_*`` ←
    the diver's start state; ``beacon_gps_sigma`` ← ``platform.gps_sigma``,
    ``beacon_attitude_sigma_deg`` ← ``platform.imu_sigma_deg``,
    ``beacon_arm`` ← the largest distance of a beacon from the platform
    reference (the system's :meth:`~sblsim.models.systems.System.receiver_ties`; LBL:
    ``beacon_gps_sigma`` ← ``platform.survey_sigma``, no attitude: 0 and 0); ``sigma_angle_deg`` ←
    ``platform.usbl_angle_sigma_deg`` (floored at 1 mdeg); for the ``random-walk`` trajectory, ``q_horizontal``,
    ``q_vertical``, ``p0_position``, ``p0_velocity`` ← the walk's.
    """
    rx, platform = cfg["receiver"], cfg["platform"]
    pos, vel = start_state(cfg["target"])
    ties = {"sigma_range": max(cfg["acoustics"]["sigma_range"], MIN_SIGMA),
            "sigma_depth": max(cfg["target"]["depth_sigma"], MIN_SIGMA),
            "range_k": cfg["acoustics"].get("range_k", 0.0),
            **{f"x0_{a}": float(pos[k]) for k, a in enumerate("xyz")},
            **{f"x0_v{a}": float(vel[k]) for k, a in enumerate("xyz")},
            **SYSTEMS[platform["system"]].receiver_ties(platform),
            "sigma_angle_deg": SYSTEMS[platform["system"]].angle_sigma_deg(platform)}
    acoustics = cfg["acoustics"]
    if acoustics["clock_drift_ppm"] != 0.0 and acoustics["ranging"] == "owtt":  # the clock's states, its prior
        ties.update(clock_states=True, clock_drift_sigma_ppm=abs(acoustics["clock_drift_ppm"]))
    if acoustics["ranging"] == "toa":  # an inverted LBL: the pinger's emission offset and its interval's drift
        ties.update(clock_states=True, clock_drift_sigma_ppm=abs(acoustics["clock_drift_ppm"]),
                    ping_jitter=ping_spread(acoustics))
    target = cfg["target"]
    if target["trajectory"] == "random-walk":  # the receiver's motion model and prior are the walk's
        ties.update({k: target[f"walk_{k}"] for k in ("q_horizontal", "q_vertical", "p0_position", "p0_velocity")})
    for key, value in ties.items():
        if key in rx and key not in given:
            rx[key] = value


def _check_water_depth(cfg: dict[str, dict]) -> None:
    """Refuse a water depth (``acoustics.water_depth``, 0: none) above a transducer or not below the diver.

    The transducers' depths are the system's lever arms at the mean heading (LBL: its transponders at
    ``platform.seafloor_depth``), the diver's the deepest waypoint of a trajectory file or ``target.depth`` (the
    start of the other trajectories: a diver that a random walk takes below a given water depth later in a run is
    not refused; its reflected eigenrays are then those of the depths the solve is given).

    Raises
    ------
    ConfigError
        Naming ``acoustics.water_depth``, the depth it must exceed and the allowed range.
    """
    depth = cfg["acoustics"]["water_depth"]
    if depth <= 0.0:
        return
    platform, target = cfg["platform"], cfg["target"]
    deepest = [(float(SYSTEMS[platform["system"]].lever_arms(platform)[:, 2].max()), "the deepest transducer")]
    if target["trajectory"] == "file":
        source = "target.trajectory_file" if target.get("trajectory_file") else "target.waypoints"
        deepest.append((float(file_waypoints(target)[:, 3].max()), f"the diver, the deepest waypoint of {source}"))
    else:
        deepest.append((float(target["depth"]), "the diver, target.depth"))
    below, what = max(deepest)
    if depth < below or (depth == below and what.startswith("the diver")):
        bracket = "(" if what.startswith("the diver") else "["
        raise ConfigError(f"acoustics.water_depth: {depth:g} m is above {what} ({below:g} m); allowed: 0 "
                          f"(no surface or bottom reflection) or a depth in {bracket}{below:g}, {MAX_WATER_DEPTH:g}] m")


def _check_detection(acoustics: dict[str, Any]) -> None:
    """Refuse detection by signal-to-noise (``acoustics.detection = "snr"``) without eigenrays.

    Raises
    ------
    ConfigError
        Naming ``acoustics.detection`` and ``acoustics.propagation``.
    """
    if acoustics["detection"] == "snr" and acoustics["propagation"] != "ray":
        raise ConfigError(f"acoustics.detection: snr needs acoustics.propagation = ray (the transmission loss along "
                          f"each eigenray), got propagation = {acoustics['propagation']!r}; allowed: fixed, or snr "
                          "with ray")


def _check_duration(sim: dict[str, Any], target: dict[str, Any]) -> None:
    """Fill ``simulation.duration`` = 0 with one pass of the trajectory (cut to whole sampling times, as
    documented; a resolved configuration holds that duration, which is accepted again as one pass), and
    refuse any other duration that is not a whole number of sampling times (it would be cut without a word)
    or whose record would not fit in memory (:func:`sblsim.orchestrator.cosim.limits.check_steps`; a trajectory
    file's natural duration too).

    Raises
    ------
    ConfigError
        Naming ``simulation.duration``, the nearest multiples of T, or the most steps that fit.
    """
    T = sim["sampling_time"]
    what = ""
    if sim["duration"] == 0.0:
        sim["duration"] = natural_duration(target)
        if target["trajectory"] == "file":
            what = f"0 (one pass of target.trajectory_file, {sim['duration']:.10g} s)"
    elif sim["duration"] >= T:
        ratio = sim["duration"] / T
        one_pass = math.isclose(sim["duration"], natural_duration(target), rel_tol=1e-12)  # a resolved config's
        if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio) and not one_pass:
            below = math.floor(ratio) * T
            raise ConfigError(f"simulation.duration: {sim['duration']:g} s is not a whole number of sampling "
                              f"times (T = {T:g} s; the run would stop at {below:.10g} s); give "
                              f"{below:.10g} or {below + T:.10g} s")
    if sim["duration"] < T:
        raise ConfigError(f"simulation.duration: {sim['duration']!r} s is shorter than one sampling time "
                          f"({T} s); allowed [sampling_time, 1e6] s")
    try:
        check_steps(sim["duration"], T, what=what)
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def unread_site_keys(cfg: Mapping[str, Mapping[str, Any]]) -> list[tuple[str, Any, str]]:
    """The ``[acoustics]`` keys of a resolved configuration that its detection does not read and that are not at
    their default: the fixed percentages (:data:`~sblsim.models.acoustics.core.FIXED_KEYS`) with detection by
    signal-to-noise, the site's keys (:data:`~sblsim.models.acoustics.core.SNR_KEYS`) with the fixed detection.

    Returns
    -------
    list of (str, object, str)
        Each key's name, its value and the detection that would read it.
    """
    acoustics = cfg["acoustics"]
    detection = acoustics["detection"]
    unread, reads = (FIXED_KEYS, "fixed") if detection == "snr" else (SNR_KEYS, "snr")
    defaults = {v.name: v.start for v in section_variables("acoustics")}
    return [(name, acoustics[name], reads) for name in unread
            if name in acoustics and acoustics[name] != defaults[name]]


def check_site_keys(configs: Iterable[Mapping[str, Mapping[str, Any]]], overrides: Iterable[str] = (),
                    what: str = "the scenario") -> None:
    """Refuse an override of a key that no configuration of a command reads at its site (``acoustics.loss_pct`` with
    detection by signal-to-noise, ``acoustics.frequency`` with the fixed detection: :func:`unread_site_keys`), and
    note (:func:`note`) such keys that the scenario itself gives: a value that changes nothing is never taken
    silently. ``sblsim run``, ``compare``, ``map`` and ``design`` call it with their configurations (a map's
    panels: a key read by one of them is read).

    Parameters
    ----------
    configs : iterable of mapping
        The command's resolved configurations (or plans).
    overrides : iterable of str
        The user's ``section.key=value`` overrides.
    what : str
        The scenario's name in the note.

    Raises
    ------
    ConfigError
        One line naming the key, the site's detection and what is allowed.
    """
    configs = list(configs)
    unread = [{name: (value, reads) for name, value, reads in unread_site_keys(cfg)} for cfg in configs]
    if not configs:
        return
    given = set()
    for item in overrides:
        try:
            section, name, _ = parse_override(item)
        except ConfigError:
            continue
        if section == "acoustics" and all(name in keys for keys in unread):
            value, reads = unread[0][name]
            detection = configs[0]["acoustics"]["detection"]
            default = next(v.start for v in section_variables("acoustics") if v.name == name)
            raise ConfigError(f"acoustics.{name}: {value!r} has no effect at this site: only acoustics.detection = "
                              f"{reads} reads it, and the site has {detection}; allowed: its default {default!r}, or "
                              f"acoustics.detection = {reads}")
        given.add(name)
    left = [(name, value, reads) for name, (value, reads) in unread[0].items()
            if name not in given and all(name in keys for keys in unread)]
    if left:
        keys = ", ".join(f"acoustics.{name} = {value!r}" for name, value, _ in left)
        note(f"{what}'s {keys}: no effect at this site (only acoustics.detection = {left[0][2]} reads "
              f"{'it' if len(left) == 1 else 'them'}; the site has {configs[0]['acoustics']['detection']})")
