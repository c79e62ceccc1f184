"""``--set section.key=value`` overrides and ``--compare KEY=V1,V2,...``: parsed, and applied to a raw
configuration (:func:`apply_overrides`; a receiver's change keeps of the ``[receiver]`` section what that receiver
takes, :func:`switch_receiver`).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Iterable

from sblsim.models import RECEIVER_MODELS
from sblsim.models.declarations import ModelError
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.cosim.config_keys import SECTIONS, SIMULATION_VARIABLES, receiver_label, section_variables
from sblsim.orchestrator.cosim.config_notes import note
from sblsim.orchestrator.cosim.config_sources import absolute_paths
from sblsim.orchestrator.io import tomlfile


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
            note(line)
    for item in overrides:
        section, name, value = parse_override(item)
        if section != "receiver":  # the receiver's keys depend on the receiver: checked by resolve()
            names = {v.name for v in section_variables(section)}
            if name not in names:
                raise ConfigError(f"{section}.{name}: unknown key; known: {', '.join(sorted(names))}")
        raw.setdefault(section, {})[name] = value
    if seed is not None:
        raw.setdefault("run", {})["seed"] = seed
    absolute_paths(raw, Path.cwd())
    return raw
