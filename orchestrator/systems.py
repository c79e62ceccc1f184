"""The positioning systems side by side: where each starts when systems are compared.

``sblsim compare --systems sbl,lbl,usbl`` and ``sblsim map --compare
platform.system=sbl,lbl,usbl`` run (or map) each system from the starting
point a designer would take, :data:`SYSTEM_DEFAULTS`, one table:

* ``sbl``: the scenario's own platform (the paper's cross for the built-in scenarios);
* ``lbl``: 4 transponders on a circle of 50 m radius (``platform.layout=circle``,
  ``platform.beacons=4``, ``platform.baseline=50``) on the seafloor at
  ``platform.seafloor_depth`` (default 50 m, deeper than every built-in
  scenario's diver; a diver at or below it is refused, :func:`check_seafloor`),
  surveyed with ``platform.survey_sigma``;
* ``usbl``: one transceiver at ``(0, 0, platform.transducer_depth)`` below the
  platform reference (``platform.layout=cross``: a custom SBL layout's
  offsets do not apply), 0.5° on the array's axis
  (``platform.usbl_angle_sigma_deg=0.5``).

The overrides apply in this order: the scenario, the system's defaults, the
user's ``--set`` (:func:`system_overrides`): the user's word wins, and for
every system (``--set platform.baseline=30`` makes the LBL circle 30 m, and
the SBL cross 30 m too). Everything else (diver path, seeds, error levels,
receiver) is the scenario's for every system.

This module holds no simulation code, so that the command line's help can show the table.
"""

from __future__ import annotations

from typing import Sequence

from sblsim.models.declarations import ModelError
from sblsim.models.platform.core import SYSTEMS
from sblsim.models.target.core import file_waypoints

#: Where each positioning system starts when systems are compared (``sblsim compare --systems``, ``sblsim map
#: --compare platform.system=...``): the ``--set`` overrides applied over the scenario, before the user's own.
SYSTEM_DEFAULTS: dict[str, tuple[str, ...]] = {
    "sbl": (),  # the scenario's own platform (the paper's cross)
    "lbl": ("platform.layout=circle", "platform.beacons=4", "platform.baseline=50"),  # at platform.seafloor_depth
    "usbl": ("platform.layout=cross", "platform.usbl_angle_sigma_deg=0.5"),  # the transceiver at (0, 0, h)
}
#: What :data:`SYSTEM_DEFAULTS` give, in words (help, tables, figures).
SYSTEM_WORDS = {
    "sbl": "the scenario's platform",
    "lbl": "4 transponders on a 50 m circle at platform.seafloor_depth",
    "usbl": "one transceiver, 0.5 deg on axis",
}


def describe_defaults(systems: Sequence[str] = SYSTEMS) -> str:
    """The defaults of ``systems`` in one line (the command's help, the table's heading)."""
    return "; ".join(f"{s}: {SYSTEM_WORDS[s]}" + (f" ({', '.join(SYSTEM_DEFAULTS[s])})" if SYSTEM_DEFAULTS[s] else "")
                     for s in systems)


def parse_systems(text: str, option: str = "--systems") -> list[str]:
    """``sbl,lbl,usbl`` -> the list, each checked.

    Raises
    ------
    ModelError
        Naming ``option`` and what is allowed.
    """
    systems = [s.strip() for s in text.split(",") if s.strip()]
    if not systems:
        raise ModelError(f"{option}: expected a comma-separated list of {', '.join(SYSTEMS)}")
    for s in systems:
        if s not in SYSTEMS:
            raise ModelError(f"{option}: {s!r} is not one of {', '.join(SYSTEMS)}")
    if len(set(systems)) != len(systems):
        raise ModelError(f"{option}: {text!r} names a system twice")
    return systems


def system_overrides(system: str, overrides: Sequence[str] = (), option: str = "--systems") -> list[str]:
    """The overrides of one compared system: ``platform.system``, its :data:`SYSTEM_DEFAULTS`, then the user's
    (which win).

    Raises
    ------
    ModelError
        If the user's overrides set ``platform.system`` themselves (``option`` sets it).
    """
    from sblsim.orchestrator.config import parse_override

    for item in overrides:
        if parse_override(item)[:2] == ("platform", "system"):
            raise ModelError(f"--set {item}: the system is set by {option}, not by --set")
    return [f"platform.system={system}", *SYSTEM_DEFAULTS[system], *overrides]


def compared(key: str, values: Sequence[str], overrides: Sequence[str] = ()) -> list[list[str]]:
    """The overrides of each value of ``--compare KEY=V1,V2,...`` (``sblsim map``, ``sblsim budget``): a compared
    ``platform.system`` starts from its :data:`SYSTEM_DEFAULTS` with ``overrides`` over them
    (:func:`system_overrides`), as ``sblsim compare --systems`` does; any other key is set over ``overrides``.

    Raises
    ------
    ModelError
        A compared system that is not one of :data:`~sblsim.models.platform.core.SYSTEMS`, named twice, or
        ``overrides`` that set ``platform.system`` themselves.
    """
    if key != "platform.system":
        return [[*overrides, f"{key}={value}"] for value in values]
    option = "--compare platform.system"
    return [system_overrides(s, overrides, option) for s in parse_systems(",".join(values), option)]


def check_seafloor(cfg: dict, depth: float | None = None) -> None:
    """Refuse an LBL configuration whose diver is not above its seafloor transponders.

    The diver's depth is ``depth`` (a map's) when given, else ``target.depth`` (the start of a random walk),
    or the deepest waypoint of a trajectory file.

    Raises
    ------
    ModelError
        Naming ``platform.seafloor_depth``, the diver's depth and what to do.
    """
    platform, target = cfg["platform"], cfg["target"]
    if platform["system"] != "lbl" or platform["layout"] == "custom":
        return
    if depth is not None:
        where = "the map's depth"
    elif target["trajectory"] == "file":
        depth, where = float(file_waypoints(target)[:, 3].max()), "the deepest waypoint of target.trajectory_file"
    else:
        depth, where = float(target["depth"]), "target.depth"
    if depth >= platform["seafloor_depth"]:
        raise ModelError(f"platform.seafloor_depth: {platform['seafloor_depth']:g} m is not below the diver "
                         f"({depth:g} m, {where}); the LBL transponders stand on the seafloor: set it to the "
                         "site's depth, below the diver")


__all__ = ["SYSTEMS", "SYSTEM_DEFAULTS", "SYSTEM_WORDS", "check_seafloor", "compared", "describe_defaults",
           "parse_systems", "system_overrides"]
