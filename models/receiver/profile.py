"""A receiver that ranges with its own sound-speed profile: travel time to straight-line slant range by ray tracing.

A real LBL or USBL processor does not turn a travel time into a range with one speed: it traces the ray through
its measured sound-velocity profile. ``receiver.sound_speed_profile`` chooses what a receiver does:

* ``assumed`` (the default): the range the channel delivers, ``r = c_a τ``, with the single assumed speed
  ``c_a = acoustics.sound_speed_assumed``; nothing else is computed (the slot event of this choice is the one
  that always was, :func:`profile_when`);
* a profile: ``acoustics`` (the channel's own, the true one: ``acoustics.sound_speed_profile`` with its table,
  temperature and salinity; a constant channel gives a one-row table at ``acoustics.sound_speed_true``),
  ``munk``, ``ctd:NAME``,
  ``teos10`` (at ``acoustics.temperature`` and ``acoustics.salinity``), ``table``
  (``receiver.sound_speed_table``) or the path of a CSV cast, as for ``acoustics.sound_speed_profile``. At each
  slot the receiver recovers the one-way travel time ``τ = r / c_a`` (two-way ranging: the one-way equivalent,
  ``(Δt − t_ta) / 2``) and replaces the range by the slant range ``√(X² + Δz²)`` of the direct eigenray of
  time τ between the packet's beacon depth and its own depth reading, X found by Newton's iteration on the
  eigenray (:func:`sblsim.models.acoustics.ray_inversion.slant_range`). The filter, the bound and the map keep their
  range model: with the true profile the converted range is the geometric one plus the range noise (scaled by
  ``c/c_a``, within a few per mille).

The receiver's FMU carries the profile as the channel's does (``sound_speed_rows`` and the table's columns,
:data:`~sblsim.models.acoustics.sound_speed.PROFILE`), the choice as ``sound_speed_model`` (0 assumed,
1 profile) and ``sound_speed_assumed`` tied to ``acoustics.sound_speed_assumed``.

References
----------
Jensen, Kuperman, Porter, Schmidt, *Computational Ocean Acoustics*, 2nd ed., Springer 2011, ch. 3 (eigenrays);
Vickery, "Acoustic positioning systems. A practical overview of current systems", Proc. 1998 Workshop on
Autonomous Underwater Vehicles, IEEE, doi:10.1109/AUV.1998.744441 (ray-traced ranges from a sound-velocity
profile in LBL and USBL processing).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, Mapping

import casadi as ca

from sblsim.models.acoustics.ray_inversion import ray_bending, slant_range
from sblsim.models.acoustics.sound_speed import NODES, PROFILE, PROFILE_SOURCES, node_speeds, profile_table
from sblsim.models.declarations import FileKey, ModelError, Variable
from sblsim.models.platform.geometry import rotation_ned, unit_vector
from sblsim.models.table_text import format_table

#: ``receiver.sound_speed_profile``'s default: the single assumed speed.
ASSUMED = "assumed"
#: ``receiver.sound_speed_profile``: the channel's own profile (the true one).
CHANNEL = "acoustics"
#: The FMU's choice: the single assumed speed, or the profile's table.
SOUND_SPEED_MODELS = ("assumed", "profile")
_FIELD, _TABLE_FIELD = "receiver.sound_speed_profile", "receiver.sound_speed_table"
#: What a receiver's ``sound_speed_profile`` may be besides a CSV path (one-line errors list them).
ALLOWED = "assumed, acoustics, munk, teos10, table, ctd:NAME or a CSV cast path"
#: ``receiver.sound_speed_profile`` names a CSV cast unless it is one of the names of :data:`ALLOWED` (or
#: ``constant``, refused by name) or ``ctd:NAME``.
PROFILE_FILE = FileKey(names=("", ASSUMED, CHANNEL, *PROFILE_SOURCES), name_prefixes=("ctd:",))


def profile_parameters() -> tuple[Variable, ...]:
    """The receiver's profile parameters (declared last: the value references of every earlier variable stay)."""
    return (
        Variable("sound_speed_profile", "parameter", "String", ASSUMED, scope="config", file=PROFILE_FILE,
                 description="Travel time to range: assumed (the single assumed speed), or ray tracing through a "
                             "profile: acoustics (the true one), munk, teos10, table, ctd:NAME or a CSV cast path"),
        Variable("sound_speed_table", "parameter", "String", "", scope="config",
                 description="The receiver's sound-speed profile 'depth speed; ...' [m, m/s] (sound_speed_profile = "
                             "table)"),
        Variable("sound_speed_model", "parameter", "String", ASSUMED, choices=SOUND_SPEED_MODELS, scope="fmu",
                 description="Travel time to range: the single assumed speed, or the slant range of the direct "
                             "eigenray through the receiver's profile table"),
        Variable("sound_speed_assumed", "parameter", "Real", 1500.0, "m/s",
                 "The channel's assumed speed c_a: the packet's range is c_a times the travel time "
                 "(acoustics.sound_speed_assumed)", min=1300.0, max=1700.0, scope="fmu"),
        Variable("sound_speed_rows", "parameter", "Integer", 0, scope="fmu", table=PROFILE,
                 description="Rows of the receiver's sound-speed table (sound_speed_model = profile)",
                 min=0, max=PROFILE.max_rows),
    )


def resolve_channel_profile(values: Mapping[str, Any], acoustics: Mapping[str, Any]) -> dict[str, Any]:
    """A receiver section with ``sound_speed_profile = acoustics`` made the channel's profile (as a table).

    Parameters
    ----------
    values : mapping
        The receiver's configuration section.
    acoustics : mapping
        The resolved ``acoustics`` section (its profile keys, ``temperature``, ``salinity``,
        ``sound_speed_true``).

    Returns
    -------
    dict
        ``values`` with ``temperature`` and ``salinity`` of the channel (for ``teos10``) and, for ``acoustics``,
        ``sound_speed_profile = table`` and the channel's table as text (a constant channel: one row at its
        ``sound_speed_true``).

    Raises
    ------
    ModelError
        If the channel's profile cannot be read (naming ``acoustics.sound_speed_profile``).
    """
    out = dict(values)
    out["temperature"], out["salinity"] = acoustics.get("temperature", 15.0), acoustics.get("salinity", 35.0)
    if out.get("sound_speed_profile", ASSUMED) != CHANNEL:
        return out
    rows = profile_table(acoustics.get("sound_speed_profile", "constant"), acoustics.get("sound_speed_table", ""),
                         out["temperature"], out["salinity"])
    if rows.shape[0] == 0:
        rows = [[0.0, float(acoustics.get("sound_speed_true", 1500.0))]]
    out["sound_speed_profile"], out["sound_speed_table"] = "table", format_table(rows)
    return out


def profile_fmu_parameters(values: Mapping[str, Any]) -> dict[str, Any]:
    """The FMU parameters of a receiver's ``sound_speed_profile`` (after :func:`resolve_channel_profile`).

    Returns
    -------
    dict
        ``sound_speed_model`` and, for a profile, ``sound_speed_rows`` and the table's entries.

    Raises
    ------
    ModelError
        One line naming ``receiver.sound_speed_profile`` (or ``receiver.sound_speed_table``) and what is allowed:
        an unknown cast, an unreadable or malformed file, ``constant``, or ``acoustics`` left unresolved.
    """
    spec = values.get("sound_speed_profile", ASSUMED)
    if spec == ASSUMED:
        return {"sound_speed_model": ASSUMED, "sound_speed_rows": 0}
    if spec in ("", "constant", CHANNEL):
        raise ModelError(f"{_FIELD}: {spec!r} is not a receiver's profile; one of {ALLOWED}")
    rows = profile_table(spec, values.get("sound_speed_table", ""), values.get("temperature", 15.0),
                         values.get("salinity", 35.0), _FIELD, _TABLE_FIELD, ALLOWED)
    return {"sound_speed_model": "profile", **PROFILE.values(rows, "sound_speed_rows")}


def profile_config_values(values: Mapping[str, Any]) -> dict[str, Any]:
    """The configuration keys of a receiver's FMU parameters (the inverse of :func:`profile_fmu_parameters`): a
    profile becomes ``sound_speed_profile = table`` with its rows."""
    model = values.get("sound_speed_model", 0)
    model = SOUND_SPEED_MODELS[int(model)] if not isinstance(model, str) else model
    if model == ASSUMED:
        return {"sound_speed_profile": ASSUMED, "sound_speed_table": ""}
    return {"sound_speed_profile": "table", "sound_speed_table": format_table(PROFILE.rows(values, "sound_speed_rows"))}


def declares_profile(variables) -> bool:
    """Whether a receiver's FMU parameters ``variables`` hold the profile's choice (:func:`profile_parameters`)."""
    return any(v.name == "sound_speed_model" for v in variables)


def profile_when(variables) -> dict[str, dict[str, tuple[str, ...]]]:
    """The ``when`` of a receiver's slot events: ``{"assumed": ..., "profile": ...}``, or one event for every run
    (``{"assumed": None}``) when the receiver declares no ``sound_speed_model``."""
    if not declares_profile(variables):
        return {ASSUMED: None}
    return {m: {"sound_speed_model": (m,)} for m in SOUND_SPEED_MODELS}


@lru_cache(maxsize=1)
def _nodes() -> ca.Function:
    """``(rows, depth, speed) -> (nodes, speeds)``: the padded profile of the receiver's table."""
    n = PROFILE.max_rows
    count, depth, speed = ca.MX.sym("rows"), ca.MX.sym("depth", n), ca.MX.sym("speed", n)
    return ca.Function("sblsim_receiver_profile_nodes", [count, depth, speed], list(node_speeds(count, depth, speed)))


#: What a receiver that declares a profile derives once per run (its ``prepare``): the padded profile of its
#: table, the eigenrays' nodes [m] and speeds [m/s].
PROFILE_DERIVED = (("profile_nodes", NODES), ("profile_speeds", NODES))


def profile_prepare(p: dict) -> dict:
    """The derived blocks :data:`PROFILE_DERIVED` of a receiver's parameters ``p`` (MX, its ``prepare``)."""
    nodes, speeds = _nodes()(p["sound_speed_rows"], p[PROFILE.columns[0].name], p[PROFILE.columns[1].name])
    return {"profile_nodes": nodes, "profile_speeds": speeds}


def profile_range(u: dict, p: dict, d: dict) -> dict:
    """The packet with its range turned into the slant range of the receiver's profile (``sound_speed_model`` =
    profile): ``τ = range / c_a``, the direct eigenray between ``beacon_z`` and the depth reading ``depth``
    (:func:`~sblsim.models.acoustics.ray_inversion.slant_range`, from ``range``). A lost packet, or one whose
    eigenray lies in the profile's shadow, keeps the range it had. A USBL packet's direction (the reply's eigenray
    arriving) is turned in its vertical plane by the direct eigenray's bending between the transceiver and the
    depth reading at that slant range (:func:`~sblsim.models.acoustics.ray_inversion.ray_bending`: the chord's
    elevation minus the eigenray's grazing angle, from the range and the depth, not from the noisy measured
    elevation): its ``elevation`` and its direction cosines in the array's frame (``doa_x``, ``doa_y``) move as
    that direction moved.

    Parameters
    ----------
    u : dict
        The receiver's inputs (``range`` [m], ``beacon_z`` [m], ``depth`` [m], ``packet_valid``; USBL:
        ``elevation`` [rad]).
    p : dict
        The parameters (``sound_speed_assumed`` [m/s]).
    d : dict
        The derived data, with the padded profile of the table (:data:`PROFILE_DERIVED`, :func:`profile_prepare`).

    Returns
    -------
    dict
        ``u`` with ``range`` [m] (and ``elevation`` [rad]) replaced.
    """
    nodes, speeds = d["profile_nodes"], d["profile_speeds"]
    tau = u["range"] / p["sound_speed_assumed"]
    rho, found = slant_range(u["beacon_z"], u["depth"], tau, u["range"], nodes, speeds)
    use = ca.logic_and(ca.logic_and(u["packet_valid"], found), u["range"] > 0)
    out = {**u, "range": ca.if_else(use, rho, u["range"])}
    if "elevation" in u:  # USBL: the direction turned by the eigenray's bending to the chord
        bending, bent = ray_bending(u["beacon_z"], u["depth"], out["range"], nodes, speeds)
        valid = ca.logic_and(use, bent)
        chord = u["elevation"] + bending
        out["elevation"] = ca.if_else(valid, chord, u["elevation"])
        if "doa_x" in u:  # and the array's direction cosines moved as the direction moved
            array = rotation_ned(*[u[f"doa_{a}"] for a in ("roll", "pitch", "yaw")]).T
            moved = ca.mtimes(array, unit_vector(u["azimuth"], chord) - unit_vector(u["azimuth"], u["elevation"]))
            out.update(doa_x=ca.if_else(valid, u["doa_x"] + moved[0], u["doa_x"]),
                       doa_y=ca.if_else(valid, u["doa_y"] + moved[1], u["doa_y"]))
    return out



__all__ = ["ALLOWED", "ASSUMED", "CHANNEL", "PROFILE_DERIVED", "PROFILE_FILE", "SOUND_SPEED_MODELS", "declares_profile",
           "profile_config_values", "profile_fmu_parameters", "profile_parameters", "profile_prepare", "profile_range",
           "profile_when", "resolve_channel_profile"]
