"""A design problem as data: ``DESIGN.toml`` (or the keyword arguments of :func:`sblsim.design`) read
(:func:`read_problem`) and checked (:func:`check_problem`); its declared keys and the hardware grades a design
chooses among are :mod:`~sblsim.orchestrator.design.keys`, the keys' checks together
:mod:`~sblsim.orchestrator.design.checks`, the work area and seafloor region as geometry
:mod:`~sblsim.orchestrator.design.area`, the detection curves :mod:`~sblsim.orchestrator.design.curves`.

A problem names a base scenario (its site: profile, water depth, sea state, source level, frequency), a **work
area** (a circle or polygon at one or several vehicle depths), a **prescription** (a horizontal or 3-D DRMS at a
share of the work area, a fix in a share of the cycles, an update interval), the **candidates** (systems, the
LBL transponders' count and the seafloor region where they may go with the areas to avoid, the SBL's arm length,
the hardware grades with their costs) and the **search** (its criterion, seed and effort). Every key is a
:class:`~sblsim.models.declarations.Variable` (:data:`~sblsim.orchestrator.design.keys.DESIGN_KEYS`: type, default,
unit, meaning, range or choices), checked by :func:`check_problem` with one-line errors naming ``section.key`` and
the allowed range; the docs' table of keys is made from the same declarations (docs/design.md).

A design file is data: it never names a file that is read or written (the base scenario is a built-in one, or the
command line's ``--scenario``) but the water's outline of a telemetry array (``site.area.file``, a declared file
key read by :mod:`~sblsim.orchestrator.design.area_file`, bounded), and the overrides it gives refuse a value
that names a file or code in any key declared to take one (:func:`sblsim.orchestrator.cosim.config.file_keys`).
"""

from __future__ import annotations

import tomllib
from importlib.resources import files
from pathlib import Path
from typing import Any, Mapping

from sblsim.models.declarations import ModelError, shown
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.cosim.config import path_from
from sblsim.orchestrator.design.checks import _check_together
from sblsim.orchestrator.design.keys import DESIGN_KEYS, SECTIONS, Key, defaults
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.tables import regular_file

#: The largest design file read [bytes].
MAX_BYTES = 1 << 20
_FOLDER = files("sblsim.orchestrator") / "designs"
#: The built-in design problems: name -> its TOML file in this package.
BUILTIN_DESIGNS = {name: f"{name}.toml" for name in ("lbl-field-2km", "usbl-deep-head", "lake-hald-array")}


def _value(section: str, key: Key, value: Any) -> Any:
    """One key's value checked against its declaration (a list item by item); returned as its type."""
    try:
        return _checked(section, key, value)
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def _checked(section: str, key: Key, value: Any) -> Any:
    where = f"{section}.{key.name}"
    if key.length is None:
        if isinstance(value, (list, tuple, dict)):
            raise ConfigError(f"{where}: expected one value ({key.allowed()}), got a {type(value).__name__}")
        value = key.variable.coerce(value, where)
        if key.variable.type == "String" and (len(value) > 20000 or "\0" in value):
            raise ConfigError(f"{where}: a text of at most 20,000 characters, got {len(value):,}")
        return value
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{where}: expected {key.allowed()}, got {shown(value)}")
    low, high = key.length
    if not low <= len(value) <= high:
        raise ConfigError(f"{where}: {len(value)} values; expected {key.allowed()}")
    out = [key.variable.coerce(item, f"{where}[{k}]") for k, item in enumerate(value)]
    if key.variable.type == "String" and any(len(v) > 20000 or "\0" in v for v in out):
        raise ConfigError(f"{where}: each text at most 20,000 characters")
    return out


def check_problem(raw: Mapping[str, Any], scenario_given: bool = False) -> dict[str, dict[str, Any]]:
    """A design problem's sections checked against :data:`DESIGN_KEYS` and completed with the defaults.

    Parameters
    ----------
    raw : mapping
        Section -> key -> value, as read from ``DESIGN.toml`` (or given to :func:`sblsim.design`).
    scenario_given : bool
        The base scenario is given apart (``--scenario``): ``design.scenario`` may be empty.

    Returns
    -------
    dict
        Every section and key (the problem as resolved, before the scenario's defaults fill what depends on it).

    Raises
    ------
    ConfigError
        One line naming ``section.key`` and what is allowed: an unknown section or key, a value of the wrong type,
        outside its range or not one of its choices, a list of the wrong length, lists of grades and costs of
        different lengths, an invalid polygon, a name that is not a file name, a scenario that is not built in, an
        override that names a file or code.
    """
    if not isinstance(raw, Mapping):
        raise ConfigError(f"design: expected sections {', '.join(SECTIONS)}, got {shown(raw)}")
    problem = defaults()
    raw = _nested_sections(raw)
    for section, values in raw.items():
        if section not in DESIGN_KEYS:
            raise ConfigError(f"design: unknown section [{str(section)[:40]}]; the sections: {', '.join(SECTIONS)}")
        if not isinstance(values, Mapping):
            raise ConfigError(f"[{section}]: expected a table of keys, got {shown(values)}")
        keys = {k.name: k for k in DESIGN_KEYS[section]}
        for name, value in values.items():
            if name not in keys:
                raise ConfigError(f"{section}.{str(name)[:40]}: not a key of [{section}]; its keys: "
                                  f"{', '.join(keys)}")
            problem[section][name] = _value(section, keys[name], value)
    _check_together(problem, scenario_given)
    return problem


def _nested_sections(raw: Mapping[str, Any]) -> dict[str, Any]:
    """TOML's ``[site.area]`` (``{"site": {"area": {...}}}``) as the section ``site.area``."""
    out = dict(raw)
    site = out.get("site")
    if isinstance(site, Mapping):
        del out["site"]
        for name, values in site.items():
            if not isinstance(values, Mapping):
                raise ConfigError(f"site.{str(name)[:40]}: expected the table [site.area], got {shown(values)}")
            out[f"site.{name}"] = values
    return out


def read_problem(source: str | Path) -> dict[str, Any]:
    """The raw sections of a built-in design problem (:data:`BUILTIN_DESIGNS`) or a ``DESIGN.toml`` file.

    Raises
    ------
    ConfigError
        A file that is missing, not a regular file, larger than :data:`MAX_BYTES`, not UTF-8 or not valid TOML.
    """
    name = str(source)
    if name in BUILTIN_DESIGNS:
        return tomlfile.loads((_FOLDER / BUILTIN_DESIGNS[name]).read_text(encoding="utf-8"))
    path = Path(source)
    if path.suffix != ".toml" and not path.exists():
        raise ConfigError(f"design: {name[:80]!r} is neither a built-in design ({', '.join(BUILTIN_DESIGNS)}) nor a "
                          "DESIGN.toml file")
    try:
        size = regular_file(path, "design")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None
    if size > MAX_BYTES:
        raise ConfigError(f"design: {name[:80]!r} is {size:,} bytes; a design file is at most {MAX_BYTES:,}")
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_BYTES + 1)
        raw = tomlfile.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"design: {name[:80]!r} is not valid TOML ({' '.join(str(exc).split())[:160]})") from None
    except OSError as exc:
        raise ConfigError(f"design: {name[:80]!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    area = raw.get("site", {}).get("area") if isinstance(raw.get("site"), Mapping) else None
    if isinstance(area, dict) and isinstance(area.get("file"), str) and area["file"]:  # from the file's folder
        area["file"] = path_from(path.resolve().parent, area["file"], "site.area.file", confined=True)
    tag = raw.get("tag")
    if isinstance(tag, dict) and isinstance(tag.get("burst_sequence"), str) and tag["burst_sequence"]:
        tag["burst_sequence"] = path_from(path.resolve().parent, tag["burst_sequence"], "tag.burst_sequence",
                                          confined=True)
    return raw


__all__ = ["BUILTIN_DESIGNS", "check_problem", "read_problem"]
