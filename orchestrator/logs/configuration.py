"""The configuration a log's replay runs with (:func:`replay_config`): given (a built-in scenario or a TOML file),
the one an exported log carries, made plain data (a log names no program and no file a replay opens), or the
built-in :data:`DEFAULT_CONFIG` scenario's; another receiver takes the receiver keys that were chosen.
"""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Sequence

from sblsim.models import RECEIVER_MODELS
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import (
    BUILTIN_SCENARIOS,
    EXTERNAL_PREFIX,
    MODEL_PREFIX,
    ConfigError,
    apply_overrides,
    check_receiver,
    named_files,
    parse_override,
    read_source,
    section_variables,
    switch_receiver,
)
from sblsim.orchestrator.cosim.plan import RunPlan, make_plan
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.logs.receiver_log import log_config

#: The scenario whose configuration a replay takes when neither ``--config`` nor the log gives one.
DEFAULT_CONFIG = "semicircle"


def replay_config(log_path: Path | str, config: str | None = None, receiver: str | None = None,
                  overrides: Sequence[str] = (), notes: list[str] | None = None) -> tuple[RunPlan, str]:
    """The plan of a replay's configuration (resolved once) and where it came from.

    The source is ``config`` (a built-in scenario or a TOML file) when given, else the configuration an
    exported log carries, else the built-in scenario :data:`DEFAULT_CONFIG`. A ``receiver`` (or a
    ``--set receiver=...``) other than the configuration's takes the keys of the configuration's
    ``[receiver]`` section that it declares and that were set (differ from the old receiver's default; the
    keys it declares when the old receiver is not a built-in one, which is never imported to learn its
    defaults), and its own defaults and ties for the rest (a resolved ``config.toml`` holds every key of its
    receiver, e.g. the ekf's ``gate_probability = 1``, which is not a choice made for another receiver).

    A log is data (:func:`_as_data`): of the configuration it carries only plain numbers and names are
    used. A receiver it names as ``model:PATH.py`` or ``fmu:PATH`` is refused unless ``receiver`` replaces
    it, and the files it names (:func:`sblsim.orchestrator.cosim.config.named_files`) are neither opened nor kept.

    Parameters
    ----------
    notes : list of str, optional
        Gets one line for every key of the log's configuration that was not used, and one for the receiver keys
        of the configuration's receiver that ``receiver`` does not have.

    Returns
    -------
    plan : RunPlan
    source : str
        What the configuration is, for the messages.

    Raises
    ------
    ConfigError, ModelError
        As :func:`sblsim.orchestrator.cosim.config.load_config`; a log's configuration that does not resolve, or
        names a receiver program, is named as the log's.
    """
    overrides = list(overrides)
    where = "--receiver" if receiver is not None else "simulation.receiver"
    for item in overrides:
        section, name, value = parse_override(item)
        if (section, name) == ("simulation", "receiver") and receiver is None:
            receiver = str(value)
    if receiver is not None:
        check_receiver(receiver, where)
        overrides = [o for o in overrides if parse_override(o)[:2] != ("simulation", "receiver")]
    embedded = "" if config is not None else log_config(log_path)
    if config is not None:
        raw = copy.deepcopy(read_source(config))
        if str(config) in BUILTIN_SCENARIOS:
            raw.setdefault("run", {})["scenario"] = str(config)
        source = f"--config {config}"
    elif embedded:
        try:
            raw = tomlfile.loads(embedded)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"log: the configuration {str(log_path)!r} carries is not valid TOML "
                              f"({' '.join(str(exc).split())[:200]}); give --config") from None
        given = {parse_override(o)[:2] for o in overrides}
        said = _as_data(raw, str(log_path), receiver is not None, given)
        if notes is not None:
            notes.extend(said)
        source = "the log's own (its run's configuration)"
    else:
        raw = copy.deepcopy(read_source(DEFAULT_CONFIG))
        raw.setdefault("run", {})["scenario"] = DEFAULT_CONFIG
        source = f"the built-in {DEFAULT_CONFIG} scenario's (the log carries none; --config to choose)"
    if receiver is not None:
        named = config if config is not None else None if embedded else DEFAULT_CONFIG
        what = "the log's configuration's" if named is None else \
            f"the {named} scenario's" if str(named) in BUILTIN_SCENARIOS else f"{named}'s"
        said = _switch_receiver(raw, receiver, what)
        if notes is not None:
            notes.extend(said)
    raw = apply_overrides(raw, overrides)
    try:
        cfg = make_plan(raw)
    except ModelError as exc:
        if embedded:
            raise type(exc)(f"log: the configuration {str(log_path)!r} carries: {exc}; give --config") from None
        raise
    return cfg, source


#: What a replay uses instead of a file a log's configuration names: (section, key) -> (key, value) to set.
_INSTEAD = {("target", "trajectory_file"): ("trajectory", "semicircle"),
            ("acoustics", "sound_speed_profile"): ("sound_speed_profile", "constant")}


def _as_data(raw: dict, log: str, receiver_given: bool, given: set = frozenset()) -> list[str]:
    """Make the configuration a log carries plain data, in place (:func:`replay_config`); returns the notes.

    * ``simulation.receiver`` naming a program (``model:PATH.py``, ``fmu:PATH``: anything but a built-in
      receiver) is refused, unless the user's ``--receiver`` replaces it (it is then never imported);
    * a file named in a key declared to take one (:func:`sblsim.orchestrator.cosim.config.named_files`) is never
      opened: a replay needs neither the diver's track nor the channel (the log holds what the receiver was
      given), so ``target.trajectory = file`` becomes the semicircle (and the duration one pass of it) and the
      channel's profile file a constant sound speed, said in a note; a file the receiver would read (its own
      profile) is refused, unless the user's ``--set`` (``given``: its ``(section, key)`` pairs) replaces it.

    Raises
    ------
    ConfigError
        A receiver program without ``--receiver``, a file the receiver would read without ``--set``.
    """
    sim = raw.get("simulation")
    value = sim.get("receiver") if isinstance(sim, dict) else None
    if isinstance(value, str) and value not in RECEIVER_MODELS and not receiver_given:
        kind = "a Python file" if value.startswith(MODEL_PREFIX) else "an FMU" if value.startswith(EXTERNAL_PREFIX) \
            else "a receiver"
        raise ConfigError(f"log: the configuration {log!r} carries names simulation.receiver = {value[:80]!r}, "
                          f"{kind} a replay never imports or loads from a log; give --receiver (one of "
                          f"{', '.join(RECEIVER_MODELS)}, or model:PATH.py or fmu:PATH of your own) or --config")
    notes = []
    for (section, key), (switch, instead) in _INSTEAD.items():
        table = raw.get(section)
        if not isinstance(table, dict) or key not in table:
            continue
        named = table[key]
        if section == "target":
            del table[key]
            if not named:
                continue
            changed = f"{section}.{key} = ''"
            if table.get("trajectory") == "file":
                table["trajectory"] = instead
                changed = f"{section}.{switch} = {instead!r}"
                if isinstance(sim, dict):
                    sim["duration"] = 0.0  # one pass of it: a replay's length is the log's
        elif not named_files({section: {key: named}}):
            continue
        else:
            table[key] = instead
            changed = f"{section}.{switch} = {instead!r}"
        notes.append(f"the log's configuration names a file in {section}.{key}, which a replay does not open (it "
                     f"needs no {'diver track' if section == 'target' else 'sound-speed profile'}: the log holds "
                     f"what the receiver was given); its config.toml has {changed}")
    for section, key, _ in named_files(raw):
        if (section, key) == ("simulation", "receiver"):
            continue  # refused above, or replaced by --receiver
        if (section, key) not in given:
            raise ConfigError(f"log: the configuration {log!r} carries names a file in {section}.{key}, which a "
                              f"replay never opens from a log; give --set {section}.{key}=... or --config")
        del raw[section][key]  # the user's --set gives it
    return notes


def _switch_receiver(raw: dict, receiver: str, what: str) -> list[str]:
    """Set ``simulation.receiver`` of a raw configuration, keeping the receiver keys that were chosen
    (:func:`replay_config`): those the new receiver has (:func:`~sblsim.orchestrator.cosim.config.switch_receiver`,
    every command's rule; its note returned) and that are not at the old receiver's default. A receiver that is
    not a built-in one (a user's model or FMU, perhaps named by a log) is never imported to learn its defaults."""
    sim = raw.get("simulation")
    old = sim.get("receiver", "ekf") if isinstance(sim, dict) else "ekf"
    notes = switch_receiver(raw, receiver, what)
    if old == receiver or not isinstance(raw.get("receiver"), dict) or old not in RECEIVER_MODELS:
        return notes
    defaults = {v.name: v.start for v in section_variables("receiver", str(old))}
    raw["receiver"] = {k: v for k, v in raw["receiver"].items() if not (k in defaults and v == defaults[k])}
    return notes


__all__ = ["DEFAULT_CONFIG", "replay_config"]
