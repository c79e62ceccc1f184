"""A design problem's keys checked together (after each key alone,
:func:`sblsim.orchestrator.design.problem.check_problem`): the candidates, grades and costs, the work area and the
prescription against one another, a telemetry array's site, tag and depths; each refusal one line naming
``section.key`` and what is allowed.
"""

from __future__ import annotations

import re
from typing import Any, Mapping

import numpy as np

from sblsim.models.declarations import shown
from sblsim.models.errors import ConfigError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.config import BUILTIN_SCENARIOS, named_files, parse_override
from sblsim.orchestrator.design.area import area_origin, existing_devices, polygon
from sblsim.orchestrator.design.curves import receiver_curves
from sblsim.orchestrator.design.keys import (
    DESIGN_KEYS,
    GRADES,
    MULTIPATH_KEYS,
    SNR_KEYS,
    SYSTEM_NAMES,
    TELEMETRY,
    defaults,
)

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


def is_telemetry(problem: Mapping[str, Mapping[str, Any]]) -> bool:
    """Whether a checked problem designs a telemetry array (``candidates.systems = ["ilbl"]``)."""
    return TELEMETRY in problem["candidates"]["systems"]


def _check_telemetry(problem: dict[str, dict[str, Any]]) -> None:
    """An ilbl design's keys together: alone among the systems, its water given once, its detection curve."""
    if problem["candidates"]["systems"] != [TELEMETRY]:
        raise ConfigError(f"candidates.systems: {', '.join(problem['candidates']['systems'])}; ilbl (a telemetry "
                          f"array) is designed alone: allowed ['ilbl'] or any of {', '.join(SYSTEM_NAMES)}")
    for name, empty in (("scenario", ""), ("set", [])):
        if problem["design"][name] != empty:
            raise ConfigError(f"design.{name}: an ilbl design (a telemetry array) reads no base scenario; allowed "
                              f"{empty!r} (the site is [site.area] and [detection])")
    low, high = problem["candidates"]["receivers"]
    if low > high:
        raise ConfigError(f"candidates.receivers: the fewest ({low}) is above the most ({high})")
    area = problem["site.area"]
    if bool(area["polygon"]) == bool(area["file"]):
        raise ConfigError("site.area: give the water as site.area.polygon or site.area.file (one of them)")
    if area["polygon"]:
        polygon(area["polygon"], "site.area.polygon")
    if area["origin"]:
        area_origin(area["origin"])
    if area["max_shore_m"] and area["max_shore_m"] < area["min_shore_m"]:
        raise ConfigError(f"site.area.max_shore_m: {area['max_shore_m']:g} m is below site.area.min_shore_m "
                          f"({area['min_shore_m']:g} m); allowed 0 (any) or at least it")
    if problem["work_area"]["shape"] == "polygon":
        polygon(problem["work_area"]["polygon"], "work_area.polygon")
    elif problem["work_area"]["shape"] != "site":
        raise ConfigError(f"work_area.shape: {problem['work_area']['shape']!r} for an ilbl design; allowed site or "
                          "polygon")
    receiver_curves(problem)


def _check_together(problem: dict[str, dict[str, Any]], scenario_given: bool) -> None:
    """What one key cannot check alone (module docstring of
    :func:`~sblsim.orchestrator.design.problem.check_problem`)."""
    design, candidates = problem["design"], problem["candidates"]
    if not _NAME.fullmatch(design["name"]):
        raise ConfigError(f"design.name: {design['name'][:40]!r} is not a name of 1 to 64 letters, digits, '.', '_' "
                          "or '-' (starting with a letter or digit)")
    if is_telemetry(problem):
        _check_telemetry(problem)
    elif problem["site.area"] != defaults()["site.area"]:  # the water places receivers of a telemetry array only
        given = next(k for k, v in problem["site.area"].items() if v != defaults()["site.area"][k])
        raise ConfigError(f"site.area.{given}: no effect in a design of {', '.join(candidates['systems'])} "
                          f"([site.area] is the water of an {TELEMETRY} design, candidates.systems = "
                          f"['{TELEMETRY}']); allowed: no [site.area] (where transponders may go: [seafloor] shape, "
                          "polygon, avoid; the work area: [work_area])")
    elif problem["work_area"]["shape"] == "site":
        raise ConfigError("work_area.shape: site is the water of an ilbl design (candidates.systems = ['ilbl']); "
                          "allowed circle or polygon")
    telemetry = is_telemetry(problem)
    if problem["detection"]["per_receiver"].strip() and not telemetry:
        raise ConfigError(f"detection.per_receiver: for {', '.join(candidates['systems'])}; a curve per receiver "
                          f"applies to an {TELEMETRY} design only; allowed ''")
    _check_noise_and_depth(problem, telemetry)
    # a file names no file to read
    if not scenario_given and not telemetry and design["scenario"] not in BUILTIN_SCENARIOS:
        given = f"{design['scenario'][:60]!r} is not a built-in scenario" if design["scenario"] else "missing"
        raise ConfigError(f"design.scenario: {given}; give one of {', '.join(BUILTIN_SCENARIOS)} (a CONFIG.toml: "
                          "--scenario)")
    for item in design["set"]:
        key = item.split("=", 1)[0].strip()
        if "=" not in item or not key:
            raise ConfigError(f"design.set: expected 'section.key=value', got {item[:60]!r}")
        try:
            section, name, value = parse_override(item)
        except ConfigError:
            continue  # the scenario's overrides name it when they are applied
        if named_files({section: {name: value}}):  # a declared file key naming a file (or code): never opened
            raise ConfigError(f"design.set: {section}.{name} names a file or code, which a design file may not (give "
                              "a configuration with --scenario)")
    low, high = candidates["transponders"]
    if low > high:
        raise ConfigError(f"candidates.transponders: the fewest ({low}) is above the most ({high})")
    short, long = candidates["sbl_baseline_m"]
    if short > long:
        raise ConfigError(f"candidates.sbl_baseline_m: the shortest ({short:g} m) is above the longest ({long:g} m)")
    for category in GRADES:
        grades, costs = candidates[category], candidates[f"{category}_cost"]
        if costs and len(costs) != len(grades):
            raise ConfigError(f"candidates.{category}_cost: {len(costs)} costs for {len(grades)} grades in "
                              f"candidates.{category}")
        if len(set(grades)) != len(grades):
            raise ConfigError(f"candidates.{category}: a grade is listed twice")
    if len(set(candidates["systems"])) != len(candidates["systems"]):
        raise ConfigError("candidates.systems: a system is listed twice")
    for section in ("work_area", "seafloor"):
        if problem[section]["shape"] == "polygon" and not is_telemetry(problem):
            polygon(problem[section]["polygon"], f"{section}.polygon")
    for k, text in enumerate(problem["seafloor"]["avoid"]):
        polygon(text, f"seafloor.avoid[{k}]")
    _check_kept(problem)


def _check_kept(problem: dict[str, dict[str, Any]]) -> None:
    """``candidates.existing_m`` and ``footprint_m`` against the systems and the counts (the places against the
    region or the water: when they are resolved)."""
    c = problem["candidates"]
    if not c["existing_m"] and not c["footprint_m"]:
        return
    telemetry = is_telemetry(problem)
    placed = telemetry or any(SYSTEMS[s].design_layout == "seafloor" for s in c["systems"])
    for name in ("existing_m", "footprint_m"):
        if c[name] and not placed:
            raise ConfigError(f"candidates.{name}: the systems {', '.join(c['systems'])} place no device (an SBL's "
                              "beacons and a USBL's transceiver stand on the platform: the SBL's arm is "
                              "candidates.sbl_baseline_m); allowed with an LBL's transponders or an ilbl array's "
                              "receivers")
    kept = existing_devices(c["existing_m"])
    if telemetry and np.isfinite(kept[:, 2]).any() and not c["receiver_depth_m"]:
        raise ConfigError("candidates.existing_m: an ilbl array's receivers are placed in the plane without "
                          "candidates.receiver_depth_m; allowed 'north east; north east; ...' [m] without a depth "
                          "(or the added receivers' depths in candidates.receiver_depth_m: 3-D)")
    most = c["receivers" if telemetry else "transponders"][1]
    if len(kept) > most:
        raise ConfigError(f"candidates.existing_m: {len(kept)} devices exist, more than the most designed "
                          f"(candidates.{'receivers' if telemetry else 'transponders'}: {most}); allowed at most "
                          f"{most}")
    spread = float(np.max(np.hypot(*(kept[:, None, :2] - kept[None, :, :2]).transpose(2, 0, 1)))) if len(kept) else 0.0
    if c["footprint_m"] and spread > c["footprint_m"]:
        raise ConfigError(f"candidates.footprint_m: {c['footprint_m']:g} m is below the existing devices' own "
                          f"spread ({spread:.6g} m, candidates.existing_m); allowed 0 (any) or at least it")


def _check_noise_and_depth(problem: dict[str, dict[str, Any]], telemetry: bool) -> None:
    """The keys that apply to some systems only (no depth sensor, an echo margin, ...), each refused in one line
    naming it and the systems where it cannot apply (a range-dependent noise, ``detection.range_k``, applies to
    every system)."""
    systems = ", ".join(problem["candidates"]["systems"])
    if telemetry:
        _check_telemetry_depths(problem)
        _check_tag(problem)
    else:
        _refuse_tag(problem, systems)
    if not telemetry and problem["candidates"]["receiver_depth_m"]:
        raise ConfigError(f"candidates.receiver_depth_m: for {systems}; the receivers' depths apply to an "
                          f"{TELEMETRY} design only; allowed []")
    if telemetry and problem["prescription"]["echo_margin_pct"] > 0.0:
        raise ConfigError(f"prescription.echo_margin_pct: {problem['prescription']['echo_margin_pct']:g} % for "
                          f"{systems}; an {TELEMETRY} design's detection curve has no reflections to keep a margin "
                          "from; allowed 0")


def _refuse_tag(problem: dict[str, dict[str, Any]], systems: str) -> None:
    """The tag's keys (``[tag]``), the site's SNR model (:data:`~sblsim.orchestrator.design.keys.SNR_KEYS`) and the
    confirmation's multipath
    (:data:`~sblsim.orchestrator.design.keys.MULTIPATH_KEYS`) changed for other systems than an ilbl design: refused
    in one line naming the first."""
    start = defaults()
    for section, names in (("tag", [k.name for k in DESIGN_KEYS["tag"]]), ("detection", SNR_KEYS)):
        for name in names:
            if problem[section][name] != start[section][name]:
                raise ConfigError(f"{section}.{name}: {shown(problem[section][name])} for {systems}; a tag's ping "
                                  f"type, burst interval, power class and the site's SNR model apply to an "
                                  f"{TELEMETRY} design only; allowed {shown(start[section][name])}")
    for name in MULTIPATH_KEYS:
        if problem["detection"][name] != start["detection"][name]:
            raise ConfigError(f"detection.{name}: {shown(problem['detection'][name])} for {systems}; the "
                              f"confirmation's multipath applies to an {TELEMETRY} design only (the others' channel "
                              f"has its own: design.set acoustics.outlier_pct, outlier_excess); allowed "
                              f"{shown(start['detection'][name])}")


def _check_tag(problem: dict[str, dict[str, Any]]) -> None:
    """An ilbl design's tag: its burst interval as its ping type takes it (``rbi`` [min, max] with min <= max or
    empty, ``sbi`` [D] or [D, D], ``pbi`` empty and a ``burst_sequence`` file), and the detection curve's source
    (a range test's curve or the site's SNR model, not both).

    Raises
    ------
    ConfigError
        In one line naming ``tag.burst_interval_s``, ``tag.burst_sequence`` or ``tag.source_level_db``; or a key of
        the SNR model (:data:`~sblsim.orchestrator.design.keys.SNR_KEYS`) changed where the curve is the range test's
        (it has no effect).
    """
    tag = problem["tag"]
    kind, interval, sequence = tag["ping_type"], tag["burst_interval_s"], tag["burst_sequence"]
    given = f"[{', '.join(f'{v:g}' for v in interval)}] s"
    if kind == "rbi" and len(interval) == 2 and interval[0] > interval[1]:
        raise ConfigError(f"tag.burst_interval_s: {given}, the shortest above the longest; allowed [min, max] with "
                          "0.1 <= min <= max <= 86400 s")
    if kind == "rbi" and len(interval) == 1:
        raise ConfigError(f"tag.burst_interval_s: {given} for rbi; allowed [min, max] [s] (empty: [20, 40])")
    if kind == "sbi" and (not interval or interval[0] != interval[-1]):
        raise ConfigError(f"tag.burst_interval_s: {given} for sbi; allowed its one interval [D] or [D, D] [s]")
    if kind == "pbi" and interval:
        raise ConfigError(f"tag.burst_interval_s: {given} for pbi; allowed [] (the intervals: tag.burst_sequence)")
    if kind == "pbi" and not sequence:
        raise ConfigError("tag.burst_sequence: missing for pbi; allowed a file of the tag's intervals [s], one per "
                          "row")
    if kind != "pbi" and sequence:
        raise ConfigError(f"tag.burst_sequence: given for {kind}; allowed '' (a sequence is pbi's)")
    detection = problem["detection"]
    if tag["source_level_db"] > 0.0 and (detection["range_50_m"] > 0.0 or detection["table"]):
        raise ConfigError(f"tag.source_level_db: {tag['source_level_db']:g} dB with a range test's curve "
                          "(detection.range_50_m or detection.table); allowed one of them: 0 (the range test's "
                          "curve) or the site's SNR model without range_50_m and table")
    if tag["source_level_db"] <= 0.0:  # the range test's curve: the SNR model's keys are read by nothing
        start = defaults()["detection"]
        for name in SNR_KEYS:
            if detection[name] != start[name]:
                raise ConfigError(f"detection.{name}: {shown(detection[name])} has no effect: the detection curve "
                                  "is the range test's (detection.range_50_m or detection.table), not the site's SNR "
                                  f"model, which alone reads it; allowed its default {shown(start[name])}, or "
                                  "tag.source_level_db without range_50_m and table (the SNR model)")


def is_three_d(problem: Mapping[str, Mapping[str, Any]]) -> bool:
    """Whether a checked ilbl problem is in 3-D (``candidates.receiver_depth_m`` given)."""
    return bool(problem["candidates"]["receiver_depth_m"])


def _check_telemetry_depths(problem: dict[str, dict[str, Any]]) -> None:
    """An ilbl design's depths: planar (no receiver depth, no tag depth, a depth sensor implied) or 3-D (both);
    without a depth sensor in 3-D, a fix of four unknowns and receivers at more than one depth.

    Raises
    ------
    ConfigError
        In one line naming the key: ``work_area.depth_sensor`` false or ``work_area.depths_m`` given in a planar
        design; ``work_area.depths_m`` empty in 3-D; ``prescription.fix_receivers`` below 4 without a sensor;
        ``candidates.receiver_depth_m`` at one depth (the receivers in place too) without a sensor.
    """
    c, work = problem["candidates"], problem["work_area"]
    if not is_three_d(problem):
        if not work["depth_sensor"]:
            raise ConfigError(f"work_area.depth_sensor: false for a planar {TELEMETRY} design; its tag and receivers "
                              "are in one plane (no depth to sense): allowed true, or the receivers' depths "
                              "(candidates.receiver_depth_m) and the tag's (work_area.depths_m) for a 3-D design")
        if work["depths_m"]:
            raise ConfigError(f"work_area.depths_m: the tag's depths for a planar {TELEMETRY} design; allowed [] or "
                              "with the receivers' depths (candidates.receiver_depth_m: 3-D)")
        return
    if not work["depths_m"]:
        raise ConfigError(f"work_area.depths_m: empty for a 3-D {TELEMETRY} design (candidates.receiver_depth_m "
                          "given); allowed 1 to 10 depths of the tag [m]")
    if work["depth_sensor"]:
        return
    if problem["prescription"]["fix_receivers"] < 4:
        raise ConfigError(f"prescription.fix_receivers: {problem['prescription']['fix_receivers']} without a depth "
                          "sensor in 3-D (a fix of north, east, depth and the emission); allowed 4 to 10")
    kept = existing_devices(c["existing_m"])
    depths = set(c["receiver_depth_m"]) | {d if np.isfinite(d) else c["receiver_depth_m"][0] for d in kept[:, 2]}
    if len(depths) < 2:
        raise ConfigError(f"candidates.receiver_depth_m: every receiver at {min(depths):g} m without a depth sensor "
                          "(work_area.depth_sensor = false): a planar array cannot fix a tag's depth (no information "
                          "about it at the receivers' depth, a mirror solution elsewhere); allowed two depths or "
                          "more, or a depth sensor")


__all__ = ["is_telemetry", "is_three_d"]
