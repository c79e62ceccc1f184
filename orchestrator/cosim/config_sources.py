"""Where a configuration comes from and the files it names: a built-in scenario's table, a TOML file read
(:func:`read_source`), the keys declared to name a file (:func:`file_keys`) and their paths made absolute
(:func:`path_from`; a configuration file's confined to its folder).
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

from sblsim.models import COMPONENTS, RECEIVER_MODELS
from sblsim.models.declarations import FileKey, ModelError
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.cosim.config_keys import BUILTIN_SCENARIOS, SECTIONS, section_variables
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.paths import inside


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


def absolute_paths(raw: dict[str, Any], base: Path, confined: bool = False) -> None:
    """Make every file a raw configuration names absolute (in place, :func:`path_from`; ``confined`` for a
    configuration file's own paths)."""
    keys = file_keys()
    for section, name, path in named_files(raw):
        value = raw[section][name]
        raw[section][name] = keys[section, name].with_path(value, path_from(base, path, f"{section}.{name}",
                                                                            confined))


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
        absolute_paths(raw, path.resolve().parent, confined=True)
        return raw
    return scenario_source(str(source))


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
