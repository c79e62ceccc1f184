"""What the commands' functions share: the checks of the API's arguments (each error names the argument and
its allowed range) and the one resolution of a scenario, file or configuration into a plan (:func:`resolve_plan`),
or into a validated configuration (:func:`load`, ``sblsim.load``).
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Mapping, Sequence
from numbers import Real
from pathlib import Path
from typing import Any, Callable, Union

import numpy as np
import tomli_w

from sblsim.models import RECEIVER_MODELS
from sblsim.models.declarations import shown
from sblsim.models.tracking.sound_speed import SALINITY_RANGE, TEMPERATURE_RANGE
from sblsim.orchestrator.cosim.config import (
    BUILTIN_SCENARIOS,
    ConfigError,
    apply_overrides,
    check_site_keys,
    load_config,
    parse_compare,
    parse_override,
    resolve,
    section_variables,
)
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.plan import Config, RunPlan, load_plan, make_plan, thaw
from sblsim.orchestrator.io.output import check_output
from sblsim.orchestrator.tracks.depth import MAX_WATER_DEPTH

#: What a ``progress`` argument may be: False or None (silent, the default), True (a tqdm bar on standard
#: error), or a callable ``progress(done, total)`` called as the work advances.
Progress = Union[bool, None, Callable[[float, float], object]]
#: What a ``set`` argument may be: a mapping ``{"section.key": value}`` (e.g. ``{"platform.baseline": 0.4,
#: "receiver": "lsq"}``) or a sequence of ``"section.key=value"`` texts as ``--set`` takes them.
Overrides = Union[Mapping[str, Any], Sequence[str], None]
#: The largest seed (``run.seed``, ``seed=``, ``--seed``): a 31-bit integer.
MAX_SEED = 2**31 - 1


def whole(value: Any) -> int | None:
    """``value`` as a Python integer when it is one or a numpy integer scalar (``numpy.int64(3)``); else None (a
    bool is not one)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return int(value)
    return None


def check_seed(seed: Any, where: str = "seed") -> int | None:
    """A seed argument: None or an integer (a numpy one too) in [0, :data:`MAX_SEED`] (``where`` names it in the
    error), returned as a Python integer."""
    if seed is None:
        return None
    number = whole(seed)
    if number is None or not 0 <= number <= MAX_SEED:
        raise ConfigError(f"{where}: {shown(seed if number is None else number)} is outside the allowed range "
                          f"[0, {MAX_SEED}] (an integer)")
    return number


def override_items(overrides: Overrides) -> list[str]:
    """``set`` as the ``section.key=value`` items of ``--set``: a mapping's values written as TOML values
    (a text stays a text, a number keeps every digit), but a text that the command line reads as a number
    (``"105.0"``, ``"3"``, ``"1e3"``) given to a key declared as a number, which is that number, as
    ``--set KEY=105.0`` is."""
    if overrides is None:
        return []
    if isinstance(overrides, str):
        raise ConfigError(f"set: expected a mapping {{'section.key': value}} or a list of 'section.key=value', "
                          f"got the text {overrides!r}")
    if isinstance(overrides, Mapping):
        items = []
        for key, value in overrides.items():
            if not isinstance(key, str) or "=" in key:
                raise ConfigError(f"set: a key must be a text 'section.key', got {shown(key)}")
            if isinstance(value, str) and _number_text(key, value):
                items.append(f"{key}={value.strip()}")  # read as --set reads it
                continue
            try:
                text = tomli_w.dumps({"v": _plain(value)}).split("=", 1)[1].strip()
            except TypeError:
                raise ConfigError(f"set: {key}: {shown(value)} is not a number, text, boolean or list") from None
            items.append(f"{key}={text}")
        return items
    if not isinstance(overrides, Sequence):
        raise ConfigError(f"set: expected a mapping {{'section.key': value}} or a list of 'section.key=value', got "
                          f"{shown(overrides)}")
    items = list(overrides)
    for item in items:
        if not isinstance(item, str):
            raise ConfigError(f"set: expected 'section.key=value' texts, got {shown(item)}")
    return items


def _number_text(key: str, text: str) -> bool:
    """Whether ``--set key=text`` reads ``text`` as a number (an integer or a float of TOML, not a boolean) for a
    key declared as a number (a built-in receiver's key for ``receiver.*``); a key not found: False (its value
    stays a text, and the configuration names the key)."""
    try:
        section, name, value = parse_override(f"{key}={text}")
    except ConfigError:
        return False
    if isinstance(value, bool) or not isinstance(value, (int, float)) or "\n" in text:
        return False
    try:
        if section == "receiver":
            declared = [v for model in RECEIVER_MODELS.values() for v in model.config_parameters() if v.name == name]
            declared += [v for v in section_variables("receiver") if v.name == name]
        else:
            declared = [v for v in section_variables(section) if v.name == name]
    except (ConfigError, KeyError):
        return False
    return bool(declared) and all(v.type in ("Real", "Integer") for v in declared)


def _plain(value: Any) -> Any:
    """A ``set`` value with numpy scalars (``numpy.int64(3)``, ``numpy.float32(0.5)``, ``numpy.bool_``) as the
    Python numbers they hold, in a list too; anything else as it is."""
    if isinstance(value, (np.number, np.bool_)):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def resolve_config(source: Any, seed: int | None = None, overrides: Overrides = None) -> Config:
    """A :class:`Config` from a scenario name, a TOML file or a configuration (re-validated with the
    overrides and seed)."""
    seed = check_seed(seed)
    items = override_items(overrides)
    if isinstance(source, Mapping):
        return Config(resolve(apply_overrides(thaw(source), items, seed)))
    check_source(source)
    return Config(load_config(source, items, seed))


def check_source(source: Any) -> None:
    """A scenario argument that is not a configuration: a built-in scenario's name or a TOML file (text or path)."""
    if not isinstance(source, (str, Path)):
        raise ConfigError(f"scenario: expected a built-in scenario ({', '.join(BUILTIN_SCENARIOS)}), a TOML file "
                          f"or a configuration, got {type(source).__name__}")


def resolve_plan(source: Any, seed: int | None = None, overrides: Overrides = None) -> RunPlan:
    """The plan of a run of a scenario name, a TOML file or a configuration with the overrides and seed: the one
    resolution of a call (:func:`sblsim.orchestrator.cosim.plan.make_plan`); a plan without overrides or seed is
    taken as it is."""
    seed = check_seed(seed)
    items = override_items(overrides)
    if isinstance(source, RunPlan) and not items and seed is None:
        return source
    if isinstance(source, Mapping):
        plan = make_plan(apply_overrides(thaw(source), items, seed))
    else:
        check_source(source)
        plan = load_plan(source, items, seed)
    check_site_keys([plan], items, "the configuration" if isinstance(source, Mapping) else str(source))
    return plan


def load(scenario_or_path: str | Path | Mapping, *, seed: int | None = None, set: Overrides = None) -> Config:
    """The resolved, validated configuration of a scenario (``sblsim run``'s first step).

    Parameters
    ----------
    scenario_or_path : str, Path or mapping
        A built-in scenario (:data:`BUILTIN_SCENARIOS`), a configuration file ``CONFIG.toml`` (its relative
        paths taken from its own folder), or a configuration (e.g. a :class:`Config`; validated again).
    seed : int, optional
        The campaign seed ``run.seed`` [0, 2147483647]; default the configuration's (0).
    set : mapping or sequence of str, optional
        Overrides, ``{"platform.baseline": 0.4, "receiver": "lsq"}`` or ``["platform.baseline=0.4"]`` (as
        ``--set``; a key without a section is a ``simulation`` key).

    Returns
    -------
    Config

    Raises
    ------
    ConfigError, SblsimError
        An unknown scenario, section or key, a value outside its range (the message names it and the range),
        a file that is not valid TOML.
    """
    return resolve_config(scenario_or_path, seed, set)


def check_engine(engine: str) -> None:
    """An engine argument: one of :data:`~sblsim.orchestrator.cosim.engines.ENGINES`."""
    if not isinstance(engine, str) or engine not in ENGINES:
        raise ConfigError(f"engine: {engine!r} is not one of {', '.join(ENGINES)}")


def check_count(value: Any, where: str, low: int, high: int) -> int:
    """An integer argument (a numpy one too; a bool is not one) in [low, high], returned as a Python integer."""
    number = whole(value)
    if number is None or not low <= number <= high:
        raise ConfigError(f"{where}: {shown(value) if number is None else number} is outside the allowed range "
                          f"[{low}, {high}] (an integer)")
    return number


def check_integer(value: Any, where: str) -> int | None:
    """An integer argument (a numpy one too) or None, whose range the work it sets checks; returned as a Python
    integer."""
    if value is None:
        return None
    number = whole(value)
    if number is None:
        raise ConfigError(f"{where}: {shown(value)} is not an integer or None")
    return number


def path_argument(value: Any, where: str, optional: bool = True) -> Path | None:
    """A file or folder argument (a text or a path; None where it is optional) as a :class:`Path`."""
    if value is None and optional:
        return None
    text = os.fspath(value) if isinstance(value, (str, os.PathLike)) else None
    if not isinstance(text, str) or not text or "\0" in text:
        allowed = "a file or folder: a text or a pathlib.Path" + (", or None" if optional else "")
        raise ConfigError(f"{where}: {shown(value)} is not {allowed}")
    return Path(text)


def flag_argument(value: Any, where: str) -> bool:
    """A true-or-false argument (``force=\"no\"`` would replace an earlier result)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{where}: {shown(value)} is not True or False")
    return bool(value)


def real_argument(value: Any, where: str, low: float, high: float, unit: str, low_open: bool = False) -> float:
    """A finite real number argument in ``[low, high]`` (``(low, high]`` with ``low_open``)."""
    allowed = f"{'(' if low_open else '['}{low:g}, {high:g}] {unit}".rstrip()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Real):
        raise ConfigError(f"{where}: {shown(value)} is not a number; allowed: {allowed}")
    if not math.isfinite(value) or not (value > low if low_open else value >= low) or not value <= high:
        raise ConfigError(f"{where}: {shown(value)} is outside the allowed range {allowed}")
    return float(value)


def text_argument(value: Any, where: str, optional: bool = True) -> str | None:
    """A text argument (None where it is optional)."""
    if value is None and optional:
        return None
    if not isinstance(value, str):
        raise ConfigError(f"{where}: {shown(value)} is not a text" + (" or None" if optional else ""))
    return value


def prepare_out(out: str | Path | None, force: bool, marker: str, what: str) -> Path | None:
    """``out`` checked before any work (writable; an earlier result only with ``force``)."""
    out = path_argument(out, "out")
    force = flag_argument(force, "force")
    if out is None:
        return None
    check_output(out, force, marker, what, "out")
    return out


def scenario_source(scenario: Any, configuration: bool = False) -> str | Path | Mapping:
    """A scenario argument of the functions that take a name or file, or (``configuration``) a configuration
    too (a :class:`Config` or mapping, taken as it is)."""
    if isinstance(scenario, Mapping):
        if configuration:
            return scenario
        raise ConfigError("scenario: this function takes a built-in scenario or a CONFIG.toml; write a "
                          "configuration with Config.to_toml() and give the file")
    if not isinstance(scenario, (str, Path)):
        raise ConfigError(f"scenario: expected a built-in scenario or a TOML file, got {type(scenario).__name__}")
    return str(scenario)


def compared(compare: str | tuple[str, Sequence[Any]] | None) -> tuple[str, list[str]] | None:
    """A ``compare`` argument (``"KEY=V1,V2"`` or ``(key, [values])``, None: no comparison) as ``--compare``
    takes it, checked (:func:`~sblsim.orchestrator.cosim.config.parse_compare`)."""
    if compare is None:
        return None
    if isinstance(compare, str):
        return parse_compare(compare)
    try:
        key, values = compare
    except (TypeError, ValueError):
        raise ConfigError(f"compare: expected 'KEY=V1,V2' or (key, [values]), got {shown(compare)}") from None
    if not isinstance(key, str):
        raise ConfigError(f"compare: the key must be a text 'section.key', got {shown(key)}")
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
        raise ConfigError(f"compare: the values of {key} must be a list of at least one value, got {shown(values)}")
    return parse_compare(f"{key}={','.join(str(v) for v in values)}")


def names_argument(value: Any, where: str, what: str) -> list[str] | None:
    """A list of names: None, a text of names separated by commas, or a sequence of texts; each named once.

    Raises
    ------
    ConfigError
        Naming ``where`` and ``what`` the names are (one line).
    """
    if value is None:
        return None
    names = value.split(",") if isinstance(value, str) else value
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise ConfigError(f"{where}: expected {what} (a list, or separated by commas), got {type(value).__name__}")
    names = [n.strip() for n in names]
    if not names or not all(names) or len(set(names)) != len(names):
        raise ConfigError(f"{where}: {','.join(names)[:80]!r}: allowed: distinct, non-empty {what}, separated by "
                          "commas")
    return names


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


def add_water_arguments(p: argparse.ArgumentParser, prefix: str = "", times: str = "time_s, or time_utc / epo with "
                        "--time-origin", depth: str = "") -> None:
    """A command's ``--temperature-file`` and ``--water-depth`` (:func:`water_arguments` checks them): ``prefix``
    begins their help (where they hold), ``times`` says the file's time column, ``depth`` where the depth may come
    from without the option."""
    p.add_argument("--temperature-file", type=Path, default=None, metavar="CSV",
                   help=f"{prefix}a water-temperature series ({times}; temperature_c [°C]) made the sound speed by "
                        "TEOS-10 at --salinity")
    p.add_argument("--water-depth", type=float, default=None, metavar="M",
                   help=f"{prefix}the water's depth [m] (receivers with z_m): the tag's depth kept within the water "
                        f"column, at mid-water where the receivers lie in one plane{depth}")
