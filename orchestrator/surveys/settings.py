"""The solver's settings of a calibration survey (``[solver]``, ``--set solver.KEY=VALUE``): each declared once as
a configuration key (:data:`SOLVER_VARIABLES`), checked (:func:`solver_value`), taken from the command line
(:func:`apply_solver_overrides`), checked together (:func:`check_solver`) and at its default
(:func:`solver_defaults`).
"""

from __future__ import annotations

import math
import tomllib
from datetime import datetime, timezone
from typing import Any

from sblsim.models.calibration import (
    EARTH_RADIUS_RANGE,
    OUTLIER_FACTOR_RANGE,
    PASSES_RANGE,
    PRIOR_SIGMA_M,
    PRIOR_SIGMA_RANGE,
    SOUND_SPEED_RANGE,
    TRANSDUCER_DEPTH_RANGE,
)
from sblsim.models.calibration.perturbation import BASES_RANGE, CRITERIA, GRADIENTS, KNOT_INTERVAL_RANGE, PERTURBATIONS
from sblsim.models.declarations import ModelError, Variable
from sblsim.orchestrator.io import tomlfile

#: The legs' models of ``solver.propagation``.
PROPAGATIONS = ("straight", "ray")


def _solver_key(name: str, type_: str, start: Any, unit: str, description: str, **allowed: Any) -> Variable:
    """A solver setting declared as a configuration key (``scope='config'``: never an FMU variable)."""
    return Variable(name, "parameter", type_, start, unit, description, scope="config", **allowed)


#: The solver's settings (``[solver]`` of a survey, ``--set solver.KEY=VALUE``), declared as every configuration key
#: is: name, type, default, unit, meaning, allowed range or choices (a key of :data:`SEARCH_KEYS` also takes a list
#: of candidates; ``segments`` a list of [start, end] pairs); checked by :func:`solver_value`.
SOLVER_VARIABLES: tuple[Variable, ...] = (
    _solver_key("sound_speed_mps", "Real", 1500.0, "m/s",
                "the sound speed of the straight ray (the harmonic mean of the water column)",
                min=SOUND_SPEED_RANGE[0], max=SOUND_SPEED_RANGE[1]),
    _solver_key("solve_sound_speed", "Boolean", False, "",
                "also estimate a sound-speed scale"),
    _solver_key("rigid", "Boolean", False, "",
                "solve one common shift of all transponders (a known array)"),
    _solver_key("outlier_factor", "Real", 3.0, "1",
                "drop the worst reply while its residual exceeds this many weighted RMS",
                min=OUTLIER_FACTOR_RANGE[0], max=OUTLIER_FACTOR_RANGE[1]),
    _solver_key("twtt_sigma_s", "Real", 0.0, "s",
                "a TWTT noise added to the weights", min=0.0, max=1.0),
    _solver_key("segments", "String", [], "",
                "[start, end) windows of transmit times, ISO 8601 UTC; empty: the whole log"),
    _solver_key("distance_limit_m", "Real", 1e5, "m",
                "use only the replies whose transmit point is within this horizontal distance of the frame's origin",
                min=0.0, max=1e5),
    _solver_key("propagation", "String", "straight", "",
                "straight: a straight ray at sound_speed_mps, or with sound_speed_profile at each transponder's "
                "harmonic mean; ray: the direct eigenray through sound_speed_profile", choices=PROPAGATIONS),
    _solver_key("sound_speed_profile", "String", "", "",
                "a sound-speed profile (an acoustics.sound_speed_profile value: ctd:NAME, munk, a CSV cast); empty: "
                "none"),
    _solver_key("harmonic_mean_start_depth_m", "Real", 0.0, "m",
                "depth where each transponder's harmonic mean of the profile starts", min=0.0, max=11000.0),
    _solver_key("surface_u_m", "Real", 0.0, "m",
                "Up of the sea surface in the survey's frame (depth 0 of the profile)", min=-1e4, max=1e4),
    _solver_key("running", "Boolean", True, "",
                "also compute the running solution (a static Kalman filter, running.csv and running.png)"),
    _solver_key("running_prior_sigma_m", "Real", PRIOR_SIGMA_M, "m",
                "the running solution's prior 1-sigma of the a-priori positions per axis",
                min=PRIOR_SIGMA_RANGE[0], max=PRIOR_SIGMA_RANGE[1]),
    _solver_key("running_iterated", "Boolean", True, "",
                "the running solution's updates iterated (the iterated extended Kalman filter); false: the extended "
                "Kalman filter"),
    _solver_key("running_passes", "Integer", 1, "",
                "the running solution's passes: 1 the extended Kalman filter, more re-linearised at the previous "
                "pass's last state", min=PASSES_RANGE[0], max=PASSES_RANGE[1]),
    _solver_key("earth_radius_m", "Real", 0.0, "m",
                f"the eigenrays through spherical layers of this radius (0: flat layers; else in "
                f"[{EARTH_RADIUS_RANGE[0]:g}, {EARTH_RADIUS_RANGE[1]:g}]), as SeaGap",
                min=0.0, max=EARTH_RADIUS_RANGE[1]),
    _solver_key("transducer_depth_m", "Real", 0.0, "m",
                "the profile hung from each transducer at this depth, as SeaGap's XDUCER_DEPTH (0: the sea surface "
                "fixed at surface_u_m)", min=0.0, max=TRANSDUCER_DEPTH_RANGE[1]),
    _solver_key("perturbation", "String", "none", "",
                "the sound speed's change in time solved with the positions: none, ntd (SeaGap's nadir total delay), "
                "garpos (GARPOS's correction of the log travel time)", choices=PERTURBATIONS),
    _solver_key("n_bases", "Integer", 0, "",
                "the perturbation's cubic B-spline bases over the survey (0: one knot every knot_interval); a list: "
                "the candidates of the search by criterion", min=BASES_RANGE[0], max=BASES_RANGE[1]),
    _solver_key("knot_interval", "Real", 300.0, "s",
                "the perturbation's knot spacing when n_bases is 0",
                min=KNOT_INTERVAL_RANGE[0], max=KNOT_INTERVAL_RANGE[1]),
    _solver_key("criterion", "String", "bic", "",
                "the criterion of the search over n_bases (ntd; garpos takes ABIC)", choices=CRITERIA),
    _solver_key("gradient", "String", "none", "",
                "the perturbation's horizontal gradients: none, deep, shallow+deep (deep and shallow+deep need "
                "a perturbation)", choices=GRADIENTS),
    _solver_key("log_lambda0", "Real", -2.0, "1",
                "GARPOS's smoothness, log10 of lambda0 squared; a list: the candidates of the ABIC search",
                min=-10.0, max=10.0),
    _solver_key("log_grad_lambda", "Real", -1.0, "1",
                "GARPOS's gradients' smoothness over the background's, log10; a list: candidates", min=-10.0, max=10.0),
    _solver_key("mu_t", "Real", 0.0, "s",
                "GARPOS's data correlation length (0: independent replies); a list: candidates", min=0.0, max=86400.0),
    _solver_key("mu_mt", "Real", 0.5, "1",
                "GARPOS's data correlation between transponders; a list: candidates", min=0.0, max=1.0),
    _solver_key("reject_sigma", "Real", 0.0, "1",
                "with a perturbation, drop the replies beyond this many standard deviations of the residuals' mean "
                "(GARPOS's rejection; 0: none)", min=0.0, max=100.0),
)
SOLVER_KEYS: dict[str, Variable] = {v.name: v for v in SOLVER_VARIABLES}
#: The perturbation's keys a list may search (product of the lists).
SEARCH_KEYS = ("n_bases", "log_lambda0", "log_grad_lambda", "mu_t", "mu_mt")


def solver_value(key: str, value: Any) -> Any:
    """The solver setting ``key`` (:data:`SOLVER_KEYS`) checked against its declaration and returned as its type: a
    number in its range (a key of :data:`SEARCH_KEYS`: or a list of 1 to 200 candidates), true or false, one of its
    choices or a text of at most 200 characters, ``segments`` a list of [start, end] pairs (ISO 8601 UTC).

    Raises
    ------
    ModelError
        ``solver.KEY: ...`` naming the value and the allowed range (and the unit).
    """
    v = SOLVER_KEYS[key]
    allowed = (v.min, v.max)
    units = f" {v.unit}" if v.unit not in ("", "1") else ""
    if key in SEARCH_KEYS:  # a number, or a list of candidates
        one = int if v.type == "Integer" else float
        if isinstance(value, list):
            if not 1 <= len(value) <= 200:
                raise ModelError(f"solver.{key}: a list of 1 to 200 candidates, got {len(value)}")
            return [_number(key, x, one, allowed, units) for x in value]
        return _number(key, value, one, allowed, units)
    if v.type == "Boolean":
        if not isinstance(value, bool):
            raise ModelError(f"solver.{key}: {value!r} is not true or false")
        return value
    if key == "segments":
        return _segments(value)
    if v.type == "String":
        if v.choices is not None and value not in v.choices:
            raise ModelError(f"solver.{key}: {str(value)[:40]!r} is not one of {', '.join(v.choices)}")
        if not isinstance(value, str) or len(value) > 200:
            raise ModelError(f"solver.{key}: {str(value)[:40]!r} is not a text of at most 200 characters")
        return value
    if v.type == "Integer":
        if isinstance(value, bool) or not isinstance(value, int) or not allowed[0] <= value <= allowed[1]:
            raise ModelError(f"solver.{key}: {value!r} is outside the allowed range [{allowed[0]}, {allowed[1]}] "
                             "(an integer)")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not allowed[0] <= value <= allowed[1]:
        raise ModelError(f"solver.{key}: {value!r} is outside the allowed range [{allowed[0]:g}, "
                         f"{allowed[1]:g}]{units}")
    return float(value)


def _number(key: str, value: Any, kind: type, allowed: tuple, units: str) -> Any:
    """One number of a key that takes a list of candidates (``n_bases``: 0 or in the range)."""
    whole = kind is int
    low = allowed[0]
    fine = not isinstance(value, bool) and isinstance(value, int if whole else (int, float)) \
        and math.isfinite(value) and (allowed[0] <= value <= allowed[1] or (whole and value == 0))
    if not fine:
        zero = "0 or " if whole else ""
        raise ModelError(f"solver.{key}: {value!r} is outside the allowed range {zero}[{low:g}, {allowed[1]:g}]{units}"
                         + (" (an integer)" if whole else ""))
    return kind(value)


def _instant(text: Any, key: str) -> float:
    if not isinstance(text, str) or len(text) > 40:
        raise ModelError(f"{key}: {str(text)[:40]!r} is not an ISO 8601 UTC time like \"2021-07-23T19:34:30Z\"")
    try:
        moment = datetime.fromisoformat(text)
    except ValueError:
        raise ModelError(f"{key}: {text!r} is not an ISO 8601 UTC time like \"2021-07-23T19:34:30Z\"") from None
    if moment.tzinfo is None or moment.utcoffset().total_seconds() != 0:
        raise ModelError(f"{key}: {text!r} must be UTC (end it with Z)")
    return moment.replace(tzinfo=timezone.utc).timestamp()


def _segments(value: Any) -> list[tuple[str, str]]:
    if not isinstance(value, list) or len(value) > 1000:
        raise ModelError("solver.segments: expected a list of [start, end] pairs (ISO 8601 UTC), at most 1000")
    out = []
    for k, pair in enumerate(value):
        if not isinstance(pair, list) or len(pair) != 2:
            raise ModelError(f"solver.segments[{k}]: expected [start, end] (ISO 8601 UTC)")
        start, end = (_instant(t, f"solver.segments[{k}]") for t in pair)
        if not start < end:
            raise ModelError(f"solver.segments[{k}]: the end {pair[1]!r} is not after the start {pair[0]!r}")
        out.append((pair[0], pair[1]))
    return out


def apply_solver_overrides(solver: dict, overrides: list[str]) -> dict:
    """The solver's settings with ``--set solver.KEY=VALUE`` items applied (the value read as TOML; a text key also
    takes a bare word).

    Raises
    ------
    ModelError
        An item without ``=``, a key other than ``solver.`` + one of :data:`SOLVER_KEYS`, or a value outside its
        range.
    """
    solver = dict(solver)
    for item in overrides:
        if "=" not in item:
            raise ModelError(f"--set: expected solver.KEY=VALUE, got {item[:60]!r}")
        key, text = (s.strip() for s in item.split("=", 1))
        name = key.removeprefix("solver.")
        if not key.startswith("solver.") or name not in SOLVER_KEYS:
            raise ModelError(f"--set: {key[:60]!r} is not a calibration key; the keys: "
                             + ", ".join(f"solver.{k}" for k in SOLVER_KEYS))
        try:
            value = tomlfile.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            if SOLVER_KEYS[name].type != "String" or name == "segments":
                raise ModelError(f"--set: solver.{name}: {text[:40]!r} is not a TOML value") from None
            value = text  # a text key takes a bare word too (solver.propagation=ray)
        solver[name] = solver_value(name, value)
    return solver


def check_solver(solver: dict) -> dict:
    """The solver's settings checked together (each is checked alone by :func:`solver_value`): a setting that
    another one leaves unused is refused, not recorded and ignored.

    Returns
    -------
    dict
        ``solver``, unchanged.

    Raises
    ------
    ModelError
        ``solver.gradient`` other than none without ``solver.perturbation`` (the gradients are the
        perturbation's).
    """
    if solver["gradient"] != "none" and solver["perturbation"] == "none":
        solved = " or ".join(p for p in PERTURBATIONS if p != "none")
        raise ModelError(f"solver.gradient: {solver['gradient']} needs solver.perturbation ({solved}): the "
                         "gradients are the perturbation's; without one it is none")
    return solver


def solver_defaults() -> dict:
    """Every solver setting at its default (:data:`SOLVER_KEYS`; a list default a new list)."""
    return {v.name: list(v.start) if isinstance(v.start, list) else v.start for v in SOLVER_VARIABLES}


__all__ = ["PROPAGATIONS", "SEARCH_KEYS", "SOLVER_KEYS", "SOLVER_VARIABLES", "apply_solver_overrides",
           "check_solver", "solver_defaults", "solver_value"]
