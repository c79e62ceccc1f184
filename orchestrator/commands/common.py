"""What the commands' functions share: the checks of their scenario, overrides, engine and comparison arguments (each
error names the argument and its allowed range; the plain checks of a number, path, flag or text are
:mod:`sblsim.orchestrator.io.arguments`') and the one resolution of a scenario, file or configuration into a plan
(:func:`resolve_plan`), or into a validated configuration (:func:`load`, ``sblsim.load``).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Callable, Union

import numpy as np
import tomli_w

from sblsim.models import RECEIVER_MODELS
from sblsim.models.declarations import shown
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
from sblsim.orchestrator.io.arguments import check_seed

#: What a ``progress`` argument may be: False or None (silent, the default), True (a tqdm bar on standard
#: error), or a callable ``progress(done, total)`` called as the work advances.
Progress = Union[bool, None, Callable[[float, float], object]]
#: What a ``set`` argument may be: a mapping ``{"section.key": value}`` (e.g. ``{"platform.baseline": 0.4,
#: "receiver": "lsq"}``) or a sequence of ``"section.key=value"`` texts as ``--set`` takes them.
Overrides = Union[Mapping[str, Any], Sequence[str], None]


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


def add_water_arguments(p: argparse.ArgumentParser, prefix: str = "", times: str = "time_s, or time_utc / epo with "
                        "--time-origin", depth: str = "") -> None:
    """A command's ``--temperature-file`` and ``--water-depth``
    (:func:`~sblsim.orchestrator.tracks.options.water_arguments` checks them): ``prefix``
    begins their help (where they hold), ``times`` says the file's time column, ``depth`` where the depth may come
    from without the option."""
    p.add_argument("--temperature-file", type=Path, default=None, metavar="CSV",
                   help=f"{prefix}a water-temperature series ({times}; temperature_c [°C]), or the receivers' own "
                        "records (their Fathom CSV or VUE receiver events, in UTC), made the sound speed by TEOS-10 at "
                        "--salinity")
    p.add_argument("--water-depth", type=float, default=None, metavar="M",
                   help=f"{prefix}the water's depth [m] (receivers with z_m): the tag's depth kept within the water "
                        f"column, at mid-water where the receivers lie in one plane{depth}")
