"""The positioning systems side by side: where each starts when systems are compared.

``sblsim compare --systems sbl,lbl,usbl`` and ``sblsim map --compare
platform.system=sbl,lbl,usbl`` run (or map) each system from the starting
point a designer would take, its object's
:attr:`~sblsim.models.systems.System.compare_defaults` (the registry
:data:`sblsim.models.systems.SYSTEMS`; docs/systems.md):

* the system the scenario configures itself (``platform.system``: SBL for the paper's scenarios, LBL for the
  ``lbl-field`` site, USBL for ``usbl-deep``): the scenario's own platform;
* a system whose transducers stand where the scenario's system's do (the same
  :attr:`~sblsim.models.systems.System.design_layout`: LBL's transponders and the inverted LBL's hydrophones on
  the seafloor): the scenario's layout (its ``platform.layout``, ``beacons``, ``baseline``), the rest of its
  defaults over it (the inverted LBL's receiver);
* ``sbl``: the paper's cross at 3 m (``platform.layout=cross``, ``platform.baseline=3``);
* ``lbl``: 4 transponders on a circle of 50 m radius (``platform.layout=circle``,
  ``platform.beacons=4``, ``platform.baseline=50``) on the seafloor at
  ``platform.seafloor_depth`` (default 50 m, deeper than every built-in
  scenario's diver; a diver at or below it is refused, :func:`check_diver`),
  surveyed with ``platform.survey_sigma``;
* ``usbl``: one transceiver at ``(0, 0, platform.transducer_depth)`` below the
  platform reference whatever ``platform.baseline`` (``platform.layout=cross``:
  a custom SBL layout's offsets do not apply), 0.5° on the array's axis
  (``platform.usbl_angle_sigma_deg=0.5``).

The overrides apply in this order: the scenario, the system's defaults, the
user's ``--set`` (:func:`system_overrides`): the user's word wins, and for
every system (``--set platform.baseline=30`` makes the LBL circle 30 m, and
the SBL cross 30 m too; the USBL transceiver stays below the antenna). Everything
else (diver path, seeds, error levels, receiver) is the scenario's for every system.

This module holds no simulation code and names no system: it asks the registry.
"""

from __future__ import annotations

from typing import Sequence

from sblsim.models.declarations import ModelError
from sblsim.models.systems import SYSTEMS, system

#: The keys of a system's compare defaults that place its transducers (kept from the scenario by a system that
#: places them where the scenario's system does, :func:`system_overrides`).
LAYOUT_KEYS = ("platform.layout", "platform.beacons", "platform.baseline")


def _defaults(name: str, own: str | None, option: str = "--systems") -> tuple[str, ...]:
    """The compare defaults of ``name`` against the scenario's system ``own`` (:func:`system_overrides`)."""
    if name == own:
        return ()
    compared_system = system(name, option)
    defaults = tuple(compared_system.compare_defaults)
    if own is not None and own in SYSTEMS and compared_system.design_layout \
            and compared_system.design_layout == system(own).design_layout:
        defaults = tuple(d for d in defaults if d.split("=", 1)[0].strip() not in LAYOUT_KEYS)
    return defaults


def describe_defaults(systems: Sequence[str] | None = None, own: str | None = None) -> str:
    """The compare defaults of ``systems`` (default every registered one) in one line (the command's help, the
    table's heading); ``own``, the scenario's system, keeps the scenario's platform."""
    objects = [system(s) for s in (SYSTEMS if systems is None else systems)]
    words = []
    for s in objects:
        defaults = _defaults(s.name, own)
        if s.name == own:
            words.append(f"{s.name}: the scenario's platform")
            continue
        kept = " on the scenario's layout" if len(defaults) < len(s.compare_defaults) else ""
        words.append(f"{s.name}: {s.words}{kept}" + (f" ({', '.join(defaults)})" if defaults else ""))
    return "; ".join(words)


def parse_systems(text: str, option: str = "--systems") -> list[str]:
    """``sbl,lbl,usbl`` -> the list, each checked against the registry.

    Raises
    ------
    ModelError
        Naming ``option`` and what is allowed.
    """
    systems = [s.strip() for s in text.split(",") if s.strip()]
    if not systems:
        raise ModelError(f"{option}: expected a comma-separated list of {', '.join(SYSTEMS)}")
    for s in systems:
        system(s, option)
    if len(set(systems)) != len(systems):
        raise ModelError(f"{option}: {text!r} names a system twice")
    return systems


def system_overrides(name: str, overrides: Sequence[str] = (), option: str = "--systems",
                     own: str | None = None) -> list[str]:
    """The overrides of one compared system: ``platform.system``, its
    :attr:`~sblsim.models.systems.System.compare_defaults` (not for ``own``, the system the scenario configures
    itself: it keeps the scenario's platform, e.g. a site's LBL field; without their :data:`LAYOUT_KEYS` for a
    system that places its transducers where ``own`` does: the inverted LBL on an LBL scenario's layout, and the
    reverse), then the user's (which win).

    Raises
    ------
    ModelError
        If the system is not registered, or the user's overrides set ``platform.system`` themselves (``option``
        sets it).
    """
    defaults = _defaults(name, own, option)
    for item in overrides:
        if item.split("=", 1)[0].strip() == "platform.system":
            raise ModelError(f"--set {item}: the system is set by {option}, not by --set")
    return [f"platform.system={name}", *defaults, *overrides]


def compared(key: str, values: Sequence[str], overrides: Sequence[str] = (), own: str | None = None
             ) -> list[list[str]]:
    """The overrides of each value of ``--compare KEY=V1,V2,...`` (``sblsim map``, ``sblsim budget``): a compared
    ``platform.system`` starts from its compare defaults with ``overrides`` over them (:func:`system_overrides`;
    ``own``, the scenario's system, from the scenario's platform), as ``sblsim compare --systems`` does; any other
    key is set over ``overrides``.

    Raises
    ------
    ModelError
        A compared system that is not registered, named twice, or ``overrides`` that set ``platform.system``
        themselves.
    """
    if key != "platform.system":
        return [[*overrides, f"{key}={value}"] for value in values]
    option = "--compare platform.system"
    return [system_overrides(s, overrides, option, own) for s in parse_systems(",".join(values), option)]


def check_diver(cfg: dict, depth: float | None = None) -> None:
    """Check the diver against the configuration's system (:meth:`~sblsim.models.systems.System.check_diver`:
    LBL refuses a diver not above its seafloor transponders). ``depth`` is a map's diver depth [m].

    Raises
    ------
    ModelError
        Naming the field, the diver's depth and what to do.
    """
    system(cfg["platform"]["system"]).check_diver(cfg, depth)


__all__ = ["LAYOUT_KEYS", "check_diver", "compared", "describe_defaults", "parse_systems", "system_overrides"]
