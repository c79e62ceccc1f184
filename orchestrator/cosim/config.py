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

The work is one module per job, read bottom up: the sections' keys and declarations
(:mod:`~sblsim.orchestrator.cosim.config_keys`), the scenario's source and the files it names
(:mod:`~sblsim.orchestrator.cosim.config_sources`), the notes (:mod:`~sblsim.orchestrator.cosim.config_notes`), the
overrides (:mod:`~sblsim.orchestrator.cosim.config_overrides`), the checks and ties across keys
(:mod:`~sblsim.orchestrator.cosim.config_checks`), and here reading and resolving a configuration
(:func:`load_config`, :func:`resolve`). The names of those modules are importable from here too, as is
:class:`ConfigError` (defined in :mod:`sblsim.models.errors`).
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Iterable

import tomli_w

from sblsim.models import COMPONENTS
from sblsim.models.acoustics.channel.lanes import check_in_flight
from sblsim.models.declarations import ModelError, resolve_parameters
from sblsim.models.errors import ConfigError
from sblsim.models.platform.geometry import check_geometry, platform_offsets
from sblsim.orchestrator.cosim.config_checks import (
    MIN_SIGMA,
    _check_detection,
    _check_duration,
    _check_pinger,
    _check_receiver_step,
    _check_system,
    _check_trajectory_file,
    _check_water_depth,
    _orchestrator_receiver_keys,
    _receiver_ties,
    check_site_keys,
    turnaround,
    unread_site_keys,
)
from sblsim.orchestrator.cosim.config_keys import (
    BUILTIN_SCENARIOS,
    EXTERNAL_PREFIX,
    KEY_TIES,
    MODEL_PREFIX,
    RECEIVER_KEY_NAMES,
    RECEIVER_KEYS,
    RUN_VARIABLES,
    SAMPLING_TIES,
    SECTIONS,
    SIMULATION_VARIABLES,
    check_receiver,
    external_path,
    external_receiver_variables,
    receiver_label,
    receiver_model,
    section_variables,
)
from sblsim.orchestrator.cosim.config_notes import collected_notes, note, take_notes
from sblsim.orchestrator.cosim.config_overrides import apply_overrides, parse_compare, parse_override, switch_receiver
from sblsim.orchestrator.cosim.config_sources import (
    absolute_paths,
    file_keys,
    named_files,
    path_from,
    read_source,
    scenario_source,
    scenario_system,
)
from sblsim.orchestrator.cosim.systems import check_diver


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


def to_toml(cfg: dict[str, dict]) -> str:
    """The resolved configuration as TOML text (readable back by :func:`load_config`)."""
    header = "# sblsim resolved configuration: every parameter, the seed, Q, P0 and the initial state.\n"
    return header + tomli_w.dumps({section: dict(table) for section, table in cfg.items()})


__all__ = [
    "absolute_paths", "apply_overrides", "BUILTIN_SCENARIOS", "check_receiver", "check_site_keys", "collected_notes",
    "ConfigError", "external_path", "EXTERNAL_PREFIX", "external_receiver_variables", "file_keys", "KEY_TIES",
    "load_config", "load_raw", "MIN_SIGMA", "MODEL_PREFIX", "named_files", "note", "parse_compare", "parse_override",
    "path_from", "read_source", "RECEIVER_KEY_NAMES", "RECEIVER_KEYS", "receiver_label", "receiver_model", "resolve",
    "RUN_VARIABLES", "SAMPLING_TIES", "scenario_source", "scenario_system", "section_variables", "SECTIONS",
    "SIMULATION_VARIABLES", "switch_receiver", "take_notes", "to_toml", "turnaround", "unread_site_keys"
]
