"""The checks of a tracking's arguments (``sblsim.replay_toa``, ``sblsim replay --format toa``, ``sblsim track``):
the sound speed and the water, the motion model, the ping type, the tag's depth and the receivers' survey error, the
receivers' CRS and the time origin, each refused in one line naming the argument as the caller spells it, its value
and the allowed range; returned as :func:`~sblsim.orchestrator.tracks.track.track`'s keyword arguments
(:func:`toa_options`). The ping type's check is ``sblsim toa``'s too (:func:`ping_type_arguments`' ``stated``).
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

from sblsim.models.errors import ConfigError
from sblsim.models.tracking.schedule import PING_TYPES
from sblsim.models.tracking.sound_speed import SALINITY_RANGE, TEMPERATURE_RANGE
from sblsim.models.tracking.timing import TOA_SIGMA_RANGE
from sblsim.orchestrator.io.arguments import (
    MAX_SEED,
    check_seed,
    flag_argument,
    names_argument,
    path_argument,
    real_argument,
    text_argument,
)
from sblsim.orchestrator.io.frames import check_crs, check_metric
from sblsim.orchestrator.io.times import parse_instant
from sblsim.orchestrator.tracks.depth import MAX_WATER_DEPTH
from sblsim.orchestrator.tracks.track import MAX_DROP, MAX_TRUTH_SIGMA, MOTIONS
from sblsim.orchestrator.tracks.tracker import DEPTH_SIGMA

#: What ``receivers_kept`` names, as its refusals say.
RECEIVER_NAMES = "receiver names of the receivers file"
#: The ping types ``--ping-type`` takes (:data:`sblsim.models.tracking.schedule.PING_TYPES`).
PING_TYPE_NAMES = tuple(PING_TYPES)
#: The burst intervals ``--burst-interval`` takes [s].
BURST_LIMITS = (0.1, 86400.0)


def sound_speed_arguments(sound_speed: Any, sound_speed_file: Any, temperature: Any, salinity: Any,
                          names: tuple[str, str, str, str], temperature_file: Any = None,
                          file_name: str = "temperature_file") -> tuple:
    """The sound speed's arguments checked together (``names``: how the caller spells ``sound_speed``,
    ``sound_speed_file``, ``temperature``, ``salinity``; ``file_name`` ``temperature_file``): a constant [m/s] in
    [1300, 1700], a measured series, a water-temperature series (``temperature_file``, with the salinity), or a
    fallback's water (a temperature [°C] and a practical salinity, both or neither) where the speed is calibrated
    from the pings; returned as given, checked (the temperature file as the caller gives it on: ``path_argument``).

    Raises
    ------
    ConfigError
        A value outside its range, or options that exclude each other (one line).
    """
    speed = None if sound_speed is None else real_argument(sound_speed, names[0], 1300.0, 1700.0, "m/s")
    series = path_argument(sound_speed_file, names[1])
    if speed is not None and series is not None:
        raise ConfigError(f"{names[1]}: not with {names[0]} (one sound speed: given, or a measured series)")
    if path_argument(temperature_file, file_name) is not None:
        other = next((n for n, v in ((names[0], speed), (names[1], series), (names[2], temperature)) if v is not None),
                     None)
        if other is not None:
            raise ConfigError(f"{file_name}: not with {other} (one sound speed: a temperature series made the speed "
                              "by TEOS-10)")
        if salinity is None:
            raise ConfigError(f"{names[3]}: needed with {file_name} (the water's practical salinity: 0 for fresh "
                              "water, about 35 for the open sea)")
        return speed, series, None, real_argument(salinity, names[3], *SALINITY_RANGE, "(practical salinity)")
    if (temperature is None) != (salinity is None):
        raise ConfigError(f"{names[3] if salinity is None else names[2]}: needed with "
                          f"{names[2] if salinity is None else names[3]} (the fallback sound speed's water: "
                          "practical salinity 0 for fresh water, about 35 for the open sea)")
    if temperature is not None:
        if speed is not None or series is not None:
            raise ConfigError(f"{names[2]}: only where the sound speed is calibrated from the pings (its fallback); "
                              f"not with {names[0] if speed is not None else names[1]}")
        temperature = real_argument(temperature, names[2], *TEMPERATURE_RANGE, "°C")
        salinity = real_argument(salinity, names[3], *SALINITY_RANGE, "(practical salinity)")
    return speed, series, temperature, salinity


def water_arguments(temperature_file: Any, water_depth: Any, names: tuple[str, str]) -> dict[str, Any]:
    """A water-temperature series and the water's depth checked (``names``: how the caller spells them; the file's
    exclusions are :func:`sound_speed_arguments`'), as :func:`~sblsim.orchestrator.tracks.track.track`'s keyword
    arguments (``temperature_path``, ``water_depth`` [m]).

    Raises
    ------
    ConfigError
        A value outside its range (one line).
    """
    return {"temperature_path": path_argument(temperature_file, names[0]),
            "water_depth": None if water_depth is None else real_argument(water_depth, names[1], 0.0,
                                                                          MAX_WATER_DEPTH, "m", low_open=True)}


def medium_arguments(sound_speed: Any, sound_speed_file: Any, temperature: Any, salinity: Any, motion: Any,
                     acceleration_psd: Any, names: tuple[str, ...], temperature_file: Any = None,
                     file_name: str = "temperature_file") -> tuple:
    """The sound speed's and the motion model's arguments checked (``names``: how the caller spells
    ``sound_speed``, ``sound_speed_file``, ``temperature``, ``salinity``, ``motion``, ``acceleration_psd``; a
    ``temperature_file`` spelled ``file_name`` checked against them, :func:`water_arguments` takes it on): returns
    them as :func:`~sblsim.orchestrator.tracks.track.track` takes them.

    Raises
    ------
    ConfigError
        A value outside its range, or options that exclude each other (one line).
    """
    speed, series, temperature, salinity = sound_speed_arguments(sound_speed, sound_speed_file, temperature,
                                                                 salinity, names[:4], temperature_file, file_name)
    motion = "moving" if motion is None else motion
    if motion not in MOTIONS:
        raise ConfigError(f"{names[4]}: {str(motion)[:40]!r} is not allowed; allowed: {', '.join(MOTIONS)}")
    if acceleration_psd is not None:
        if motion == "stationary":
            raise ConfigError(f"{names[5]}: not with {names[4]} stationary (one position for all pings: no motion "
                              "model)")
        acceleration_psd = real_argument(acceleration_psd, names[5], 0.0, 1.0, "m²/s³", low_open=True)
    return speed, series, temperature, salinity, motion, acceleration_psd


def burst_interval_argument(value: Any, where: str, example: str = "20:40", any_pair: bool = False
                            ) -> tuple[float, float] | None:
    """A random burst interval: None, ``"MIN:MAX"`` [s] or a pair of numbers, 0.1 ≤ MIN ≤ MAX ≤ 86,400 s.

    ``example`` is the refusal's example interval [s] (as the caller's help gives one); with ``any_pair`` the pair
    may be any two items :class:`float` reads (a refusal then names the value itself, whatever its type).

    Raises
    ------
    ConfigError
        A value that is not such an interval (one line naming ``where``, the value and the allowed range).
    """
    if value is None:
        return None
    allowed = f"MIN:MAX [s] with {BURST_LIMITS[0]:g} <= MIN <= MAX <= {BURST_LIMITS[1]:g}, e.g. {example}"
    if isinstance(value, str) or any_pair:
        try:
            pair = tuple(float(p) for p in (value.split(":") if isinstance(value, str) else value))
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: {str(value)[:40]!r}; allowed: {allowed}") from None
    elif isinstance(value, (list, tuple)):
        pair = tuple(value)
    else:
        raise ConfigError(f"{where}: {type(value).__name__}; allowed: {allowed}")
    if len(pair) != 2 or not all(isinstance(p, (int, float)) and not isinstance(p, bool) for p in pair) or \
            not all(np.isfinite(pair)) or not BURST_LIMITS[0] <= pair[0] <= pair[1] <= BURST_LIMITS[1]:
        raise ConfigError(f"{where}: {str(value)[:40]!r}; allowed: {allowed}")
    return float(pair[0]), float(pair[1])


def burst_sequence_argument(value: Any, where: str, stated: bool = False) -> Path | None:
    """A pseudo-random tag's intervals file: None, a text or a path (:func:`path_argument`; with ``stated`` any
    text or path, refused only for its type, as ``sblsim toa`` takes it).

    Raises
    ------
    ConfigError
        A value that is not a file (one line naming ``where``).
    """
    if not stated:
        return path_argument(value, where)
    if value is not None and not isinstance(value, (str, os.PathLike)):
        raise ConfigError(f"{where}: {type(value).__name__}; allowed: a file (a text or a path)")
    return None if value is None else Path(value)


def ping_type_arguments(ping_type: Any, burst_interval: Any, burst_sequence: Any, names: tuple[str, str, str], *,
                        stated: bool = False, example: str = "20:40"
                        ) -> tuple[str | None, tuple[float, float] | None, Path | None]:
    """The ping type's arguments checked together (``names``: how the three are called where they were given):
    the tracking's (a burst interval or sequence may come without a ping type: the type is then inferred), or with
    ``stated`` ``sblsim toa``'s (a times-of-arrival matrix's echo limit is its stated interval: a burst interval or
    sequence only with its ping type named, :func:`burst_interval_argument`'s ``any_pair``, the refusals worded as
    that command words them); ``example`` the burst interval's refusal's example [s].

    Raises
    ------
    ConfigError
        A ping type not known, a burst interval or sequence refused or given with another ping type, pbi without
        its sequence (one line).
    """
    if ping_type is not None and ping_type not in PING_TYPE_NAMES:
        raise ConfigError(f"{names[0]}: {str(ping_type)[:40]!r}; allowed: {', '.join(PING_TYPE_NAMES)}")
    interval = burst_interval_argument(burst_interval, names[1], example, any_pair=stated)
    sequence = burst_sequence_argument(burst_sequence, names[2], stated)
    for given, name, kind, what in ((interval, names[1], "rbi", "a random burst interval"),
                                    (sequence, names[2], "pbi", "a pseudo-random burst interval")):
        if given is not None and ping_type != kind and (stated or ping_type is not None):
            raise ConfigError(f"{name}: only with {names[0]} {kind} ({what})" if stated
                              else f"{name}: only with {what} ({names[0]} {kind})")
    if interval is not None and sequence is not None:  # (stated: one of them refused above)
        raise ConfigError(f"{names[1]}: not with {names[2]} (one ping type: rbi or pbi)")
    if ping_type == "pbi" and sequence is None:
        raise ConfigError(f"{names[0]} pbi: needs {names[2]} (the tag's intervals [s], one per row)")
    return ping_type, interval, sequence


def geometry_arguments(tag_depth: Any, depth_sigma: Any, survey_sigma: Any, names: tuple[str, str, str]) -> dict:
    """The tag's depth and the receivers' survey error checked (``names``: how the caller spells ``tag_depth``,
    ``depth_sigma``, ``survey_sigma``), as :func:`~sblsim.orchestrator.tracks.track.track`'s keyword arguments.

    Raises
    ------
    ConfigError
        A value outside its range (one line).
    """
    from sblsim.orchestrator.readers.receivers_file import SURVEY_SIGMA_RANGE
    from sblsim.orchestrator.readers.toa_matrix import DEPTH_RANGE

    return {"fixed_depth": None if tag_depth is None else real_argument(tag_depth, names[0], *DEPTH_RANGE, "m"),
            "depth_sigma": DEPTH_SIGMA if depth_sigma is None else real_argument(depth_sigma, names[1], 0.0, 100.0,
                                                                                 "m", low_open=True),
            "survey_sigma": None if survey_sigma is None else real_argument(survey_sigma, names[2],
                                                                            *SURVEY_SIGMA_RANGE, "m")}


def place_arguments(crs: Any, frame: Any, time_origin: Any, names: tuple[str, str, str]) -> dict[str, Any]:
    """The receivers' CRS, the metric frame and the TOA file's time origin checked (``names``: how the caller spells
    them), as :func:`~sblsim.orchestrator.tracks.track.track`'s keyword arguments.

    Raises
    ------
    ConfigError, ModelError
        A CRS pyproj does not know, a frame that is not metric, a time that is neither ISO 8601 nor epoch seconds.
    """
    crs, frame = text_argument(crs, names[0]), text_argument(frame, names[1])
    return {"crs": None if crs is None else check_crs(crs, names[0]),
            "frame": None if frame is None else check_metric(frame, names[1]),
            "time_origin": None if time_origin is None else parse_instant(time_origin, names[2])}


def toa_sigma_argument(value: Any, where: str) -> float | None:
    """The timing noise given [s] checked (None: not given), in
    :data:`~sblsim.models.tracking.timing.TOA_SIGMA_RANGE`.

    Raises
    ------
    ConfigError
        A value outside it (one line).
    """
    return None if value is None else real_argument(value, where, *TOA_SIGMA_RANGE, "s")


def check_depth_sigma(toa: Path, tag_depth: Any, depth_sigma: Any, names: tuple[str, str]) -> None:
    """Refuse the tag's depth σ given without a depth to weigh (``names``: how the caller spells ``tag_depth`` and
    ``depth_sigma``): no ``tag_depth`` and no ``depth_m`` column in the times of arrival ``toa`` (a folder of tags:
    not checked, the σ applies to the tags with a depth).

    Raises
    ------
    ConfigError
        One line naming the option, its value and what it needs.
    """
    if depth_sigma is None or tag_depth is not None or Path(toa).is_dir():
        return
    from sblsim.orchestrator.readers.toa_matrix import read_toa

    if read_toa(toa).depth is None:
        raise ConfigError(f"{names[1]}: {float(depth_sigma):g} m has no effect: no depth of the tag is given (no "
                          f"{names[0]}, no depth_m column in {str(toa)!r}); allowed: with {names[0]} or a depth_m "
                          "column (the σ of that depth)")


def toa_options(smooth: Any = True, sound_speed: Any = None, receivers_kept: Any = None, drop_detections: Any = 0.0,
                seed: Any = 0, truth_sigma: Any = 0.0, ping_type: Any = None, burst_interval: Any = None,
                burst_sequence: Any = None, acceleration_psd: Any = None, sound_speed_file: Any = None,
                temperature: Any = None, salinity: Any = None, motion: Any = "moving", tag_depth: Any = None,
                depth_sigma: Any = None, survey_sigma: Any = None, crs: Any = None, frame: Any = None,
                time_origin: Any = None, toa_sigma: Any = None, temperature_file: Any = None,
                water_depth: Any = None, force_interval: Any = False, other_filters: Any = True, *,
                spell: Callable[[str], str] | None = None) -> dict[str, Any]:
    """:func:`~sblsim.orchestrator.tracks.replay.replay_toa`'s tracking arguments checked, as keyword arguments of
    :func:`~sblsim.orchestrator.tracks.track.track`; ``spell`` names an argument in a refusal as the caller spells
    it (default as the function names it; the command line: ``--sound-speed`` for ``sound_speed``).

    Raises
    ------
    ConfigError, ModelError
        One line naming the argument and the allowed values.
    """
    n = (lambda name: name) if spell is None else spell
    smooth = flag_argument(smooth, n("smooth"))
    sound_speed, series, temperature, salinity, motion, acceleration_psd = medium_arguments(
        sound_speed, sound_speed_file, temperature, salinity, motion, acceleration_psd,
        tuple(n(k) for k in ("sound_speed", "sound_speed_file", "temperature", "salinity", "motion",
                             "acceleration_psd")), temperature_file, n("temperature_file"))
    kept = names_argument(receivers_kept, n("receivers_kept"), RECEIVER_NAMES)
    drop = real_argument(drop_detections, n("drop_detections"), 0.0, MAX_DROP, "")
    seed = check_seed(seed, n("seed"))
    if seed is None:
        raise ConfigError(f"{n('seed')}: None is not allowed; allowed: an integer in [0, {MAX_SEED}]")
    truth_sigma = real_argument(truth_sigma, n("truth_sigma"), 0.0, MAX_TRUTH_SIGMA, "m")
    kind, interval, sequence = ping_type_arguments(ping_type, burst_interval, burst_sequence,
                                                   (n("ping_type"), n("burst_interval"), n("burst_sequence")))
    return {"smooth": smooth, "sound_speed": sound_speed, "receivers_kept": kept, "drop": drop, "seed": seed,
            "truth_sigma": truth_sigma, "ping_type": kind, "burst_interval": interval, "burst_sequence_path": sequence,
            "acceleration_psd": acceleration_psd, "sound_speed_path": series, "temperature": temperature,
            "salinity": salinity, "motion": motion, "toa_sigma": toa_sigma_argument(toa_sigma, n("toa_sigma")),
            "force_interval": flag_argument(force_interval, n("force_interval")),
            "other_filters": flag_argument(other_filters, n("other_filters"))} | geometry_arguments(
        tag_depth, depth_sigma, survey_sigma, (n("tag_depth"), n("depth_sigma"), n("survey_sigma"))) | place_arguments(
        crs, frame, time_origin, (n("crs"), n("frame"), n("time_origin"))) | water_arguments(
        temperature_file, water_depth, (n("temperature_file"), n("water_depth")))


#: The tracking arguments :func:`toa_options` takes (each tag's of a folder: all but ``truth_sigma``).
TOA_OPTIONS = tuple(k for k in inspect.signature(toa_options).parameters if k != "spell")


#: The tracking arguments true by default, which the command line turns off: ``--no-other-filters``.
NEGATED = ("other_filters",)


def option_spelling(name: str) -> str:
    """A tracking argument as the command line spells it: ``--sound-speed`` for ``sound_speed``,
    ``--no-other-filters`` for ``other_filters`` (:data:`NEGATED`)."""
    return ("--no-" if name in NEGATED else "--") + name.replace("_", "-")
