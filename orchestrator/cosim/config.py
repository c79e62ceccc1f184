"""Run configuration: built-in scenarios, TOML files, ``--set`` overrides, validation.

A configuration has one table per section: ``run`` (scenario name and the
seed tree keys), ``simulation`` (sampling time T, EKF rate ratio, duration),
and one table per component whose keys are exactly that component's declared
parameters (:mod:`models`). Every value is validated against its declaration,
so errors name the field and its allowed range. The resolved configuration
holds every parameter explicitly and reproduces a run on its own.

The ``receiver`` section also holds the keys the orchestrator implements for
every receiver (:data:`RECEIVER_KEYS`: ``latency``); they are never passed to
the receiver component.

Ties (applied only where the user did not set the key):
``receiver.sigma_range`` ← ``acoustics.sigma_range``, ``receiver.range_k`` ← ``acoustics.range_k`` and
``receiver.sigma_depth`` ← ``target.depth_sigma`` (both floored at 1 mm: R must
be positive), ``receiver.x0_*`` ← the diver's start state, and
``simulation.duration`` ← one pass of the trajectory. The FMU parameters the
orchestrator fills (:data:`SAMPLING_TIES`: the slot and sensor sampling
periods ← ``simulation.sampling_time``; tables from files) are not
configuration keys.
"""

from __future__ import annotations

import copy
import math
import os
import tomllib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any, Iterable

import tomli_w

from sblsim.models import COMPONENTS, RECEIVER_MODELS
from sblsim.models.acoustics.channel.interface import FIXED_KEYS, MAX_WATER_DEPTH, SNR_KEYS
from sblsim.models.acoustics.channel.lanes import check_in_flight
from sblsim.models.acoustics.channel.pinger import check_pinger, ping_spread
from sblsim.models.declarations import (
    SEED_NAMES,
    SEED_PARAMETERS,
    UNITS,
    FileKey,
    ModelError,
    Variable,
    resolve_parameters,
)
from sblsim.models.errors import ConfigError
from sblsim.models.platform.geometry import check_geometry, platform_offsets
from sblsim.models.receiver.interface import clock_parameters
from sblsim.models.systems import SYSTEMS
from sblsim.models.target import natural_duration, start_state
from sblsim.models.target.core import file_waypoints
from sblsim.orchestrator.cosim.fmu_files import read_description
from sblsim.orchestrator.cosim.limits import check_steps
from sblsim.orchestrator.cosim.master import ALGORITHMS
from sblsim.orchestrator.cosim.plugins import user_model
from sblsim.orchestrator.cosim.systems import check_diver
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.paths import inside

BUILTIN_SCENARIOS = ("semicircle", "spiral", "random", "square", "harbour", "random-walk", "usbl-deep", "lbl-field")
SECTIONS = ("run", "simulation", *COMPONENTS)
MIN_SIGMA = 1e-3  # floor of the tied R standard deviations [m]


EXTERNAL_PREFIX = "fmu:"
MODEL_PREFIX = "model:"


RUN_VARIABLES: tuple[Variable, ...] = (
    Variable("scenario", "parameter", "String", "custom", description="Scenario name", scope="config"),
) + SEED_PARAMETERS

SIMULATION_VARIABLES: tuple[Variable, ...] = (
    Variable("sampling_time", "parameter", "Real", 0.1, "s",
             "Sampling time T: round-robin slot and communication step of the physics", min=0.001, max=60.0),
    Variable("ekf_rate_ratio", "parameter", "Integer", 1, description="EKF steps per measurement slot",
             min=1, max=1000),
    Variable("duration", "parameter", "Real", 0.0, "s", "Simulated time (0: one pass of the trajectory)",
             min=0.0, max=1e6),
    Variable("master", "parameter", "String", "gauss-seidel",
             description="Master algorithm: gauss-seidel, jacobi as FMI hosts step an SSP, or event (FMI 3.0 "
                         "FMUs: a step ends at each acoustic arrival)",
             choices=ALGORITHMS, scope="config"),
    Variable("receiver", "parameter", "String", "ekf", scope="config",
             file=FileKey(prefixes=(MODEL_PREFIX, EXTERNAL_PREFIX)),
             description="Receiver component: ekf (the paper's), ekf-seq, ukf, lsq, model:PATH.py or fmu:PATH"),
    Variable("fmi_version", "parameter", "Integer", 2, scope="config", min=2, max=3,
             description="FMI version of the fmu engine's FMUs: 2, or 3 (the fmi3 folder of the FMU folder; "
                         "the same numbers)"),
)

#: Keys of the ``receiver`` section that the orchestrator implements for every receiver (built-in, a user's model
#: or FMU): configuration keys only, never parameters of the receiver component
#: (:meth:`sblsim.orchestrator.cosim.plan.RunPlan.component_parameters`).
RECEIVER_KEYS: tuple[Variable, ...] = (
    Variable("latency", "parameter", "Real", 0.0, "s",
             "Processing latency: the estimate a diver sees is the one the receiver computed this long ago "
             "(a whole number of sampling times)", min=0.0, max=60.0, scope="config"),
)
RECEIVER_KEY_NAMES = frozenset(v.name for v in RECEIVER_KEYS)

#: FMU parameters filled with ``simulation.sampling_time``: (component, parameter).
SAMPLING_TIES = (("platform", "sample_period"), ("target", "sample_period"), ("acoustics", "slot_period"))
#: FMU parameters filled from a configuration key of another section: (component, parameter) <- (section, key).
KEY_TIES = ((("acoustics", "usbl_angle_sigma_deg"), ("platform", "usbl_angle_sigma_deg")),
            (("receiver", "sound_speed_assumed"), ("acoustics", "sound_speed_assumed")),
            (("receiver", "ranging"), ("acoustics", "ranging")),
            (("acoustics", "beaufort"), ("platform", "beaufort")))


def external_path(value: Any, prefix: str = EXTERNAL_PREFIX) -> str:
    """The path of ``fmu:PATH`` (or of ``model:PATH`` with that prefix); empty for any other value."""
    return value[len(prefix):] if isinstance(value, str) and value.startswith(prefix) else ""


def receiver_model(value: str) -> type | Path:
    """What a ``simulation.receiver`` value names: a model class (built-in or a user's file), or an FMU path."""
    if value in RECEIVER_MODELS:
        return RECEIVER_MODELS[value]
    if external_path(value, MODEL_PREFIX):
        return user_model(external_path(value, MODEL_PREFIX))
    return Path(external_path(value))


def section_variables(section: str, receiver: str = "ekf") -> tuple[Variable, ...]:
    """Declarations of a configuration section (component parameters without the seed keys).

    Parameters
    ----------
    section : str
    receiver : str
        The ``simulation.receiver`` whose declarations the ``receiver`` section holds.

    Raises
    ------
    ConfigError
        If the section is unknown, or the receiver declares a parameter named like one of
        :data:`RECEIVER_KEYS`.
    """
    if section == "run":
        return RUN_VARIABLES
    if section == "simulation":
        return SIMULATION_VARIABLES
    if section == "receiver":
        model = receiver_model(receiver)
        if isinstance(model, Path):
            own = external_receiver_variables(model)
        else:
            own = tuple(v for v in model.config_parameters() if v.name not in SEED_NAMES)
        clash = sorted(RECEIVER_KEY_NAMES & {v.name for v in own})
        if clash:
            raise ConfigError(f"receiver.{clash[0]}: the {receiver} receiver declares a parameter {clash[0]!r}, "
                              "a key the orchestrator keeps for every receiver; rename the receiver's parameter")
        return own + RECEIVER_KEYS
    if section in COMPONENTS:
        return tuple(v for v in COMPONENTS[section].config_parameters() if v.name not in SEED_NAMES)
    raise ConfigError(f"{section}: unknown section; one of {', '.join(SECTIONS)}")


@lru_cache(maxsize=1)
def _declared_file_keys() -> tuple[tuple[tuple[str, str], FileKey], ...]:
    found: dict[tuple[str, str], FileKey] = {}
    for section in SECTIONS:
        for receiver in (RECEIVER_MODELS if section == "receiver" else ("ekf",)):
            found.update({(section, v.name): v.file for v in section_variables(section, receiver) if v.file})
    return tuple(found.items())


def file_keys() -> dict[tuple[str, str], FileKey]:
    """Every configuration key declared to name a file (:attr:`sblsim.models.declarations.Variable.file`), by
    ``(section, key)``: the one list every rule for files reads. The ``receiver`` section's are those of every
    built-in receiver (a user's receiver is never imported to learn its keys: its own are taken as given).

    Returns
    -------
    dict
        ``(section, key)`` -> its :class:`~sblsim.models.declarations.FileKey`.
    """
    return dict(_declared_file_keys())


def named_files(raw: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    """The files a raw configuration names: ``(section, key, path)`` of every declared file key (:func:`file_keys`)
    whose value names a file, in the order of the sections.

    Returns
    -------
    list of tuple
        Section, key and the path as written (``fmu:``/``model:`` left out).
    """
    out = []
    for (section, name), key in file_keys().items():
        table = raw.get(section)
        path = key.path(table.get(name)) if isinstance(table, Mapping) else ""
        if path:
            out.append((section, name, path))
    return out


def path_from(base: Path, path: str, where: str, confined: bool = False) -> str:
    """A file a configuration names, absolute: a relative ``path`` is taken from ``base``, the folder of the file
    that gives it (the working directory for ``--set`` and the API). ``confined`` (a configuration file's own
    paths): a path that leaves ``base`` (absolute, ``..`` or through a symbolic link) is refused
    (:func:`sblsim.orchestrator.io.paths.inside`: a file given to us names what its folder holds; the user names
    another file with ``--set``).

    Raises
    ------
    ConfigError
        One line naming ``where`` (the key), the path as written and the folder.
    """
    if confined:
        try:
            return str(inside(base, path, where, "file"))
        except ModelError as exc:
            raise ConfigError(str(exc)) from None
    return str(Path(os.path.normpath(base / Path(path).expanduser())).resolve())


def _absolute_paths(raw: dict[str, Any], base: Path, confined: bool = False) -> None:
    """Make every file a raw configuration names absolute (in place, :func:`path_from`; ``confined`` for a
    configuration file's own paths)."""
    keys = file_keys()
    for section, name, path in named_files(raw):
        value = raw[section][name]
        raw[section][name] = keys[section, name].with_path(value, path_from(base, path, f"{section}.{name}",
                                                                            confined))


def external_receiver_variables(path: Path) -> tuple[Variable, ...]:
    """The parameters of a user's receiver FMU as declarations (name, type, unit, start, range).

    Raises
    ------
    ConfigError
        If the FMU cannot be read.
    ArchiveError
        If the FMU's archive is not safe to read (checked before fmpy reads it).
    """
    try:
        md = read_description("receiver", Path(path))
    except ModelError as exc:  # it names the FMU and what is wrong with it
        raise ConfigError(str(exc)) from None

    def number(x):
        return None if x is None else float(x)

    out = []
    for v in md.modelVariables:
        if v.causality != "parameter" or v.type not in ("Real", "Integer", "Boolean") or v.name in SEED_NAMES:
            continue
        start = {"Real": float, "Integer": int, "Boolean": lambda x: str(x).lower() in ("true", "1")}[v.type](
            v.start if v.start is not None else 0)
        out.append(Variable(v.name, "parameter", v.type, start, v.unit or ("1" if v.type == "Real" else "")
                            if (v.unit or "1") in UNITS else "1", v.description or "",
                            min=number(v.min), max=number(v.max)))
    return tuple(out)


def check_receiver(receiver: str, where: str = "simulation.receiver") -> str:
    """A ``simulation.receiver`` value: a built-in receiver, ``model:PATH.py`` of a user's receiver model,
    or ``fmu:PATH`` of an existing FMU file.

    Raises
    ------
    ConfigError
        Naming ``where``, the value and what is allowed.
    """
    if receiver in RECEIVER_MODELS:
        return receiver
    if external_path(receiver, MODEL_PREFIX):
        try:
            user_model(external_path(receiver, MODEL_PREFIX))
        except ConfigError as exc:
            raise ConfigError(str(exc).replace("simulation.receiver", where, 1)) from None
        return receiver
    path = external_path(receiver)
    if not path:
        raise ConfigError(f"{where}: {receiver!r} is not allowed; one of {', '.join(RECEIVER_MODELS)}, "
                          "model:PATH.py or fmu:PATH")
    if Path(path).is_dir():
        raise ConfigError(f"{where}: {path!r} is a directory, not an FMU file")
    if not Path(path).is_file():
        raise ConfigError(f"{where}: no FMU file at {path!r}")
    return receiver


def receiver_label(cfg: dict[str, dict]) -> str:
    """What a figure or table calls the receiver that ran: ``ekf``, ``ekf-seq``, ``ukf``, ``lsq``, a user
    model's ``label`` (else its name) or the FMU's file name."""
    value = cfg["simulation"]["receiver"]
    if value in RECEIVER_MODELS:
        return value
    model = receiver_model(value)
    return Path(model).stem if isinstance(model, Path) else str(getattr(model, "label", model.name))


def scenario_source(name: str) -> dict[str, Any]:
    """Raw table of a built-in scenario.

    Raises
    ------
    ConfigError
        If ``name`` is not a built-in scenario.
    """
    if name not in BUILTIN_SCENARIOS:
        raise ConfigError(f"scenario: unknown scenario {name!r}; one of {', '.join(BUILTIN_SCENARIOS)} "
                          "or a path to a .toml file")
    text = (resources.files("sblsim.orchestrator") / "scenarios" / f"{name}.toml").read_text()
    return tomlfile.loads(text)


def read_source(source: str | Path) -> dict[str, Any]:
    """Raw table from a built-in scenario name or a TOML file path.

    Raises
    ------
    ConfigError
        Unknown scenario, missing file or invalid TOML.
    """
    if str(source) in BUILTIN_SCENARIOS:  # built-in names win over files of the same name
        return scenario_source(str(source))
    path = Path(source)
    if path.suffix == ".toml" or path.exists():
        if path.is_dir():
            raise ConfigError(f"config: {str(source)!r} is a directory; give a configuration file (.toml) or a "
                              f"built-in scenario ({', '.join(BUILTIN_SCENARIOS)})")
        if not path.is_file():
            if path.exists():  # a pipe or a device: never opened (reading a FIFO would wait for a writer)
                raise ConfigError(f"config: {str(source)!r} is not a regular file; give a configuration file (.toml)")
            raise ConfigError(f"config: no such file {str(source)!r}")
        try:
            raw = tomlfile.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"config: {str(source)!r} is not valid TOML ({exc})") from None
        _absolute_paths(raw, path.resolve().parent, confined=True)
        return raw
    return scenario_source(str(source))


def parse_override(item: str) -> tuple[str, str, Any]:
    """Split ``section.key=value``; the value is read as a TOML value, else as text.

    A key without a section names a key of the ``simulation`` section, so
    ``receiver=lsq`` is ``simulation.receiver=lsq``.

    Raises
    ------
    ConfigError
        If the item has no ``=``, or a key is neither dotted nor a simulation key.
    """
    if "=" not in item:
        raise ConfigError(f"--set: expected key=value, got {item!r}")
    key, text = (s.strip() for s in item.split("=", 1))
    if "." not in key and key in {v.name for v in SIMULATION_VARIABLES}:
        key = f"simulation.{key}"
    if key.count(".") != 1:
        raise ConfigError(f"--set: expected a dotted key section.name (or a simulation key), got {key!r}; "
                          f"sections: {', '.join(SECTIONS)}")
    section, name = key.split(".")
    try:
        value = tomlfile.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text
    return section, name, value


def parse_compare(text: str, example: str = "platform.baseline=0.4,1,3") -> tuple[str, list[str]]:
    """``--compare KEY=V1,V2,...`` -> the key and its values (as text, checked when each configuration loads).

    Raises
    ------
    ModelError
        Naming ``--compare`` and the expected form (with ``example``), or a value given twice.
    """
    key, _, values = text.partition("=")
    key = key.strip()
    items = [v.strip() for v in values.split(",") if v.strip()]
    if not items or key.count(".") != 1:
        raise ModelError(f"--compare: expected SECTION.KEY=V1,V2,..., e.g. {example}; got {text!r}")
    if len(set(items)) != len(items):
        raise ModelError(f"--compare: {text!r} names a value twice")
    return key, items


def load_config(source: str | Path, overrides: Iterable[str] = (), seed: int | None = None) -> dict[str, dict]:
    """Resolved configuration of a scenario or file with ``--set`` overrides and seed.

    Parameters
    ----------
    source : str or Path
        Built-in scenario name or TOML file.
    overrides : iterable of str
        ``section.key=value`` items.
    seed : int, optional
        Campaign seed (``run.seed``).

    Returns
    -------
    dict
        Section -> parameter -> value, every parameter present.

    Raises
    ------
    ConfigError, ModelError
        On any invalid input; nothing has been written.
    """
    return resolve(load_raw(source, overrides, seed))


def load_raw(source: str | Path, overrides: Iterable[str] = (), seed: int | None = None) -> dict[str, Any]:
    """The raw configuration of a scenario or file with ``--set`` overrides and seed, not yet validated
    (:func:`resolve`, or :func:`sblsim.orchestrator.cosim.plan.make_plan` for a run's plan).

    Raises
    ------
    ConfigError
        Unknown scenario, missing file, invalid TOML, an unknown section or key of an override.
    """
    raw = copy.deepcopy(read_source(source))
    builtin = str(source) in BUILTIN_SCENARIOS
    if builtin:
        raw.setdefault("run", {})["scenario"] = str(source)
    return apply_overrides(raw, overrides, seed, f"the {source} scenario's" if builtin else f"{source}'s")


def switch_receiver(raw: dict[str, Any], receiver: Any, what: str) -> list[str]:
    """Make ``receiver`` the ``simulation.receiver`` of a raw configuration (in place), keeping of its ``[receiver]``
    section what that receiver takes; the one rule of every command (a run's ``config.toml``, a configuration
    given to the API, a replay's).

    A configuration's ``[receiver]`` keys are those of its own receiver (a run's ``config.toml`` holds every one):
    the keys of its own receiver that ``receiver`` does not have are dropped, and said in the note returned
    (``what``, e.g. ``"config.toml's"``, names the configuration). Nothing changes with its own receiver (a key
    it does not have is refused by :func:`resolve`), nor a key neither has. A receiver that is not a built-in
    one is never imported here to learn its keys: an old one's are taken to be all of the section's, a new one
    (or a value that names no receiver) leaves the section for :func:`resolve` to check.

    Returns
    -------
    list of str
        The note, one line (none when nothing was dropped).
    """
    sim = raw.setdefault("simulation", {})
    if not isinstance(sim, dict):
        return []  # resolve() names it
    own = sim.get("receiver", next(v.start for v in SIMULATION_VARIABLES if v.name == "receiver"))
    sim["receiver"] = receiver
    table = raw.get("receiver")
    if receiver == own or not isinstance(table, dict) or not table or not isinstance(receiver, str):
        return []
    try:
        declared = {v.name for v in section_variables("receiver", receiver)}
        owned = {v.name for v in section_variables("receiver", own)} if own in RECEIVER_MODELS else set(table)
    except ModelError:
        return []  # a receiver that is none: resolve() names it
    dropped = [k for k in table if k not in declared and k in owned]
    if not dropped:
        return []
    raw["receiver"] = {k: v for k, v in table.items() if k not in dropped}
    keys = ", ".join(f"receiver.{k}" for k in dropped)
    label = receiver_label({"simulation": {"receiver": receiver}})
    verb = "is not a key" if len(dropped) == 1 else "are not keys"
    return [f"{what} {keys} {verb} of the {label} receiver: not used"]


#: The notes of the configurations read while :func:`collected_notes` collects them (None: not collected, as the
#: API is silent).
_NOTES: ContextVar[dict[str, bool] | None] = ContextVar("sblsim_configuration_notes", default=None)


@contextmanager
def collected_notes() -> Iterator[None]:
    """Collect the one-line notes of the configurations read meanwhile (:func:`switch_receiver`'s), each once, for
    :func:`take_notes` (the command line prints them; without this they are dropped)."""
    token = _NOTES.set({})
    try:
        yield
    finally:
        _NOTES.reset(token)


def _note(line: str) -> None:
    notes = _NOTES.get()
    if notes is not None:
        notes.setdefault(line, False)


def note(line: str) -> None:
    """Add a one-line note for the command line to print (:func:`collected_notes`; dropped where none collects)."""
    _note(line)


def take_notes() -> list[str]:
    """The notes collected (:func:`collected_notes`) and not taken yet, in order."""
    notes = _NOTES.get() or {}
    fresh = [line for line, taken in notes.items() if not taken]
    for line in fresh:
        notes[line] = True
    return fresh


def apply_overrides(raw: dict[str, Any], overrides: Iterable[str] = (), seed: int | None = None,
                    what: str = "the configuration's") -> dict[str, Any]:
    """Apply ``section.key=value`` overrides and the seed to a raw configuration (in place).

    A ``simulation.receiver`` override other than the configuration's own receiver first takes its ``[receiver]``
    keys as :func:`switch_receiver` says (a run's ``config.toml`` runs with any receiver), its note naming the
    configuration as ``what`` (``"config.toml's"``) and going to :func:`collected_notes`.

    Returns
    -------
    dict
        ``raw``, with paths made absolute (from the working directory).

    Raises
    ------
    ConfigError
        On an unknown section or key.
    """
    overrides = list(overrides)
    chosen = None
    for item in overrides:
        try:
            section, name, value = parse_override(item)
        except ConfigError:
            continue  # named below
        if (section, name) == ("simulation", "receiver"):
            chosen = value
    if chosen is not None:
        for line in switch_receiver(raw, chosen, what):
            _note(line)
    for item in overrides:
        section, name, value = parse_override(item)
        if section != "receiver":  # the receiver's keys depend on the receiver: checked by resolve()
            names = {v.name for v in section_variables(section)}
            if name not in names:
                raise ConfigError(f"{section}.{name}: unknown key; known: {', '.join(sorted(names))}")
        raw.setdefault(section, {})[name] = value
    if seed is not None:
        raw.setdefault("run", {})["seed"] = seed
    _absolute_paths(raw, Path.cwd())
    return raw


def resolve(raw: dict[str, Any]) -> dict[str, dict]:
    """Validate a raw configuration and fill defaults and ties.

    Raises
    ------
    ConfigError, ModelError
        Unknown section or key, or a value outside its allowed range.
    """
    for section, table in raw.items():
        if section not in SECTIONS:
            raise ConfigError(f"{section}: unknown section; one of {', '.join(SECTIONS)}")
        if not isinstance(table, dict):
            raise ConfigError(f"{section}: expected a table of keys, got {table!r}")
    sim = resolve_parameters(SIMULATION_VARIABLES, raw.get("simulation", {}), "simulation")
    _check_receiver_step(sim)
    receiver = check_receiver(sim["receiver"])
    receiver_keys = section_variables("receiver", receiver)
    unknown = sorted(set(raw.get("receiver", {})) - {v.name for v in receiver_keys})
    if unknown:
        raise ConfigError(f"receiver.{unknown[0]}: not a parameter of the {receiver_label({'simulation': sim})} "
                          f"receiver; its keys: {', '.join(sorted(v.name for v in receiver_keys))}")
    given = raw.get("receiver", {})
    own = tuple(v for v in receiver_keys if v.name not in RECEIVER_KEY_NAMES)
    cfg: dict[str, dict] = {}
    for s in SECTIONS:
        if s == "simulation":
            cfg[s] = sim
        elif s == "receiver":  # the receiver's own parameters, then the orchestrator's keys
            cfg[s] = resolve_parameters(own, {k: v for k, v in given.items() if k not in RECEIVER_KEY_NAMES}, s)
            cfg[s].update(_orchestrator_receiver_keys(given, sim))
        else:
            cfg[s] = resolve_parameters(section_variables(s, receiver), raw.get(s, {}), s)
    _check_trajectory_file(cfg["target"])
    _check_system(cfg, set(raw.get("platform", {})))
    _check_pinger(cfg, set(raw.get("acoustics", {})))
    try:  # a turnaround the channel cannot hold in flight, whatever the travel time (that one is checked in a run)
        check_in_flight(sim["sampling_time"], turnaround(cfg))
    except ModelError as exc:
        raise ConfigError(str(exc)) from None
    _receiver_ties(cfg, set(raw.get("receiver", {})))
    for name, model in COMPONENTS.items():  # files and tables are read and checked now
        if name != "receiver":
            model.fmu_parameters(cfg[name], platform_offsets(cfg["platform"]).shape[0])
    check_geometry(cfg["platform"])
    check_diver(cfg)
    _check_water_depth(cfg)
    _check_detection(cfg["acoustics"])
    _check_duration(sim, cfg["target"])
    return cfg


def scenario_system(source: str | Path | Mapping) -> str:
    """The positioning system a scenario, configuration file or configuration configures itself (its
    ``platform.system``, without overrides; the interface's default when it names none): the system that keeps
    the scenario's platform when systems are compared. The file is read, not resolved (each configuration of a
    comparison is resolved once, with its system's overrides).

    Raises
    ------
    ConfigError
        As :func:`read_source`.
    """
    platform = (source if isinstance(source, Mapping) else read_source(source)).get("platform", {})
    named = platform.get("system") if isinstance(platform, dict) else None
    if isinstance(named, str):
        return named
    return next(v.start for v in COMPONENTS["platform"].variables() if v.name == "system")


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


def turnaround(cfg: dict[str, dict]) -> float:
    """The nominal turnaround a packet of a resolved configuration waits for [s]: ``acoustics.turnaround`` in
    two-way ranging, 0 in one-way."""
    return float(cfg["acoustics"]["turnaround"]) if cfg["acoustics"]["ranging"] == "twtt" else 0.0



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
        _note(f"{what}'s {keys}: no effect at this site (only acoustics.detection = {left[0][2]} reads "
              f"{'it' if len(left) == 1 else 'them'}; the site has {configs[0]['acoustics']['detection']})")


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


def to_toml(cfg: dict[str, dict]) -> str:
    """The resolved configuration as TOML text (readable back by :func:`load_config`)."""
    header = "# sblsim resolved configuration: every parameter, the seed, Q, P0 and the initial state.\n"
    return header + tomli_w.dumps({section: dict(table) for section, table in cfg.items()})
