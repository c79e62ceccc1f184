"""``sblsim calibrate``: a survey's definition, its solution and its outputs.

A survey is a log (:mod:`sblsim.orchestrator.surveys.log`, or a public format it is read from), a *site* (the
local frame's origin and the transponders' ids and a-priori positions) and the solver's settings
(:data:`SOLVER_KEYS`). A built-in survey is a TOML file of this package (:data:`BUILTIN_SURVEYS`) whose log is
one of the package's data files (a text file of survey A, or a GNATSS folder with its own site, edited as
``survey.editing`` says); a log given on the command line comes with the default settings, the
transponders it names and a-priori positions guessed from it (:func:`guess_apriori`), and ``--set
solver.KEY=VALUE``. Each segment ``[start, end)`` of transmit times is solved alone
(:func:`sblsim.models.calibration.solve`), and the segments are combined as Xie et al. (2023) combine them
(:func:`sblsim.models.calibration.combine`); without segments the whole log is one.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib.resources import as_file, files
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.fmus.native import compiled_exact_points
from sblsim.models.acoustics.sound_speed import profile_table
from sblsim.models.calibration import (
    EARTH_RADIUS_RANGE,
    OUTLIER_FACTOR_RANGE,
    PASSES_RANGE,
    PRIOR_SIGMA_M,
    PRIOR_SIGMA_RANGE,
    RUNNING_AGREEMENT_SIGMA,
    SOUND_SPEED_RANGE,
    TRANSDUCER_DEPTH_RANGE,
    EigenRay,
    LegModel,
    Perturbation,
    Solution,
    StraightRay,
    combine,
    running,
    running_disagreement,
    select,
    solve,
)
from sblsim.models.calibration.perturbation import (
    BASES_RANGE,
    CRITERIA,
    GRADIENTS,
    KNOT_INTERVAL_RANGE,
    PERTURBATIONS,
    effective_scale,
)
from sblsim.models.declarations import ModelError, Variable
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.surveys.garpos import read_garpos
from sblsim.orchestrator.surveys.gnatss import community_editing, harmonic_mean_speed, read_gnatss
from sblsim.orchestrator.surveys.log import LOG_COLUMNS, SurveyLog, check_frame, read_survey_log
from sblsim.orchestrator.surveys.seagap import NOMINAL_SIGMA_M, read_seagap
from sblsim.orchestrator.surveys.xie import origin as xie_origin
from sblsim.orchestrator.surveys.xie import read_xie

#: The log formats read: name -> reader of a log file (SeaGap's folder and GARPOS's three files have their own).
FORMATS = {"sblsim": read_survey_log, "xie": read_xie, "seagap": None, "garpos": None}
_FOLDER = files("sblsim.orchestrator.surveys")
#: The built-in surveys: name -> its TOML file's name in this package.
BUILTIN_SURVEYS = {name: f"{name}.toml" for name in (
    "xie-2021-07-23", "xie-2021-08-23-1065", "xie-2021-08-23-1063", "xie-2021-12-10", "xie-2022-03-21",
    "ncl1-2022-208", "seagap-example")}
#: The legs' models of ``solver.propagation``.
PROPAGATIONS = ("straight", "ray")
#: The editing a built-in GNATSS survey may ask for (``survey.editing``).
EDITINGS = ("none", "community")


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
                "the perturbation's horizontal gradients: none, deep, shallow+deep", choices=GRADIENTS),
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
#: The files of a perturbation: ``ntd.csv`` and ``ntd.png``; of a search, ``criterion.csv`` and ``criterion.png``.
PERTURBATION_FILES = ("ntd.csv", "ntd.png")
SEARCH_FILES = ("criterion.csv", "criterion.png")
#: Columns of ``ntd.csv``: one row per reply (its segment, ping, transponder, mid-time [s, POSIX], the nadir angle's
#: cosine, the nadir-normalised TWTT residual of the legs less the gradients' part [s], the perturbation's nadir
#: delay [s] and what remains [s], the sound speed's change the delay means [m/s], used).
NTD_COLUMNS = ("segment", "ping", "transponder", "t_s", "nadir_cosine", "observed_s", "ntd_s", "residual_s",
               "sound_speed_change_mps", "used")
#: The site's keys of a transponder: name -> (allowed range, unit).
TRANSPONDER_KEYS = {"e_m": ((-1e5, 1e5), "m"), "n_m": ((-1e5, 1e5), "m"), "u_m": ((-1e5, 1e5), "m"),
                    "turnaround_s": ((0.0, 60.0), "s")}
#: The files ``sblsim calibrate`` writes.
OUTPUT_FILES = ("solution.json", "residuals.csv", "track.png", "residuals_time.png", "residuals_elevation.png")
#: The files of the running solution, written unless ``solver.running = false``.
RUNNING_FILES = ("running.csv", "running.png")
#: Columns of ``running.csv``: one row per reply the running solution takes and per transponder (the
#: estimate after that reply: offsets from the a-priori position [m], local frame of the a-priori point, and
#: their 1-sigma; the reply's innovation [m], its 1-sigma [m] and its NIS [1]).
RUNNING_COLUMNS = ("segment", "reply", "ping", "transponder", "t_tx_s", "id", "e_m", "n_m", "u_m", "sigma_e_m",
                   "sigma_n_m", "sigma_u_m", "sound_speed_mps", "innovation_m", "innovation_sigma_m", "nis")


@dataclass
class Survey:
    """A survey to solve: its log, site and settings."""

    name: str
    log: SurveyLog
    ids: list[str]
    apriori: np.ndarray
    solver: dict
    origin: dict | None = None
    format: str = "sblsim"
    title: str = ""
    notes: list[str] = field(default_factory=list)
    #: Each transponder's depth below the sea surface [m] when the site gives it (GNATSS: minus its orthometric
    #: height); else ``solver.surface_u_m`` less its a-priori Up.
    depth_m: np.ndarray | None = None
    #: The survey's own sound-speed profile (depth [m], speed [m/s]) when its format carries one (SeaGap): taken
    #: unless ``solver.sound_speed_profile`` names another.
    profile: np.ndarray | None = None


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


def solver_defaults() -> dict:
    """Every solver setting at its default (:data:`SOLVER_KEYS`; a list default a new list)."""
    return {v.name: list(v.start) if isinstance(v.start, list) else v.start for v in SOLVER_VARIABLES}


def guess_apriori(log: SurveyLog, ids: list[str], sound_speed: float) -> np.ndarray:
    """A-priori positions from the log alone: under the mean transmit point of each transponder's replies, at
    half the median TWTT times the sound speed below the mean transducer height [m, ENU]."""
    f = log.frame
    out = []
    for name in ids:
        mine = f[f["transponder"] == name]
        out.append([mine["tx_e_m"].mean(), mine["tx_n_m"].mean(),
                    mine["tx_u_m"].mean() - 0.5 * sound_speed * mine["twtt_s"].median()])
    return np.asarray(out, dtype=float)


def _gnatss_log(folder, editing: str, name: str) -> tuple[SurveyLog, list[str], np.ndarray, dict, np.ndarray]:
    """A GNATSS survey folder of the package (``pxp_tt``, ``POS_FREED_TRANS_TWTT``, ``site.toml``) as a log, its
    transponders' ids, a-priori positions, the site's origin and the transponders' depths."""
    with as_file(folder.joinpath("pxp_tt")) as pxp, as_file(folder.joinpath("POS_FREED_TRANS_TWTT")) as pos, \
            as_file(folder.joinpath("site.toml")) as site_file:
        frame, site = read_gnatss(pxp, pos, site_file)
    if editing == "community":
        frame = community_editing(frame, site)
    where = [f"ping {p} transponder {t}" for p, t in zip(frame["ping"], frame["transponder"])]
    log = check_frame(frame[list(LOG_COLUMNS)].copy(), where, name)
    log.counts["ignored_columns"] = []
    ids = [t.id for t in site.transponders]
    apriori = np.array([[t.e_m, t.n_m, t.u_m] for t in site.transponders], dtype=float)
    origin = {"lat_deg": site.lat_deg, "lon_deg": site.lon_deg, "height_m": site.height_m}
    return log, ids, apriori, origin, np.array([t.depth_m for t in site.transponders])


def _builtin(name: str, overrides: list[str]) -> Survey:
    raw = tomlfile.loads(_FOLDER.joinpath(BUILTIN_SURVEYS[name]).read_text(encoding="utf-8"))
    meta = raw["survey"]
    data = _FOLDER.joinpath("data")
    for part in meta["log"].split("/"):
        data = data.joinpath(part)
    fmt = meta["format"]
    profile = None
    if fmt == "gnatss":
        editing = meta.get("editing", "none")
        if editing not in EDITINGS:
            raise ModelError(f"survey.editing: {str(editing)[:40]!r} is not one of {', '.join(EDITINGS)}")
        log, ids, apriori, origin, depth = _gnatss_log(data, editing, name)
    elif fmt == "seagap":  # the folder's own transponders and profile; the site's origin from the TOML
        depth = None
        with as_file(data) as path:
            folder = read_seagap(path)
        log, ids, apriori, profile = folder.log, folder.ids, folder.apriori, folder.profile
        origin = {k: raw["site"][k] for k in ("lat_deg", "lon_deg", "height_m")}
    else:
        depth = None
        site = raw["site"]
        with as_file(data) as path:
            log = FORMATS[fmt](path)
        ids = [t["id"] for t in site["transponders"]]
        apriori = np.array([[t["e_m"], t["n_m"], t["u_m"]] for t in site["transponders"]], dtype=float)
        origin = {k: site[k] for k in ("lat_deg", "lon_deg", "height_m")}
    solver = solver_defaults()
    for key, value in raw.get("solver", {}).items():
        solver[key] = solver_value(key, value)
    solver = apply_solver_overrides(solver, overrides)
    return Survey(name, log, ids, apriori, solver, origin, fmt, meta.get("title", name), depth_m=depth,
                  profile=profile)


def load_survey(source: str, fmt: str | None = None, overrides: list[str] | None = None,
                initcfg: str | None = None, svp: str | None = None) -> Survey:
    """A built-in survey by name, or a log file with the default settings.

    Parameters
    ----------
    source : str
        A name of :data:`BUILTIN_SURVEYS`, or a log (``.csv``/``.parquet`` in the sblsim format, any text file with
        ``fmt="xie"``).
    fmt : str or None
        The log's format, one of :data:`FORMATS` (default: sblsim; a built-in survey's own): ``seagap`` takes a
        folder (:mod:`~sblsim.orchestrator.surveys.seagap`), ``garpos`` the observation CSV with ``initcfg`` and
        ``svp`` (:mod:`~sblsim.orchestrator.surveys.garpos`); both take ``propagation = "ray"`` through the
        survey's own profile unless ``--set`` says otherwise.
    overrides : list of str
        ``solver.KEY=VALUE`` items (:func:`apply_solver_overrides`).
    initcfg, svp : str or None
        GARPOS's initial site-parameter file and sound-speed profile (``fmt="garpos"`` only, both needed).

    Raises
    ------
    ModelError
        An unknown format, a simulated survey (not available yet), a log that cannot be read, a bad override.
    """
    overrides = overrides or []
    if fmt is not None and fmt not in FORMATS:
        raise ModelError(f"--format: {fmt[:40]!r} is not one of {', '.join(FORMATS)}")
    if fmt == "garpos" and (initcfg is None or svp is None):
        raise ModelError("--format garpos: give the site-parameter file (--initcfg FILE) and the sound-speed profile "
                         "(--svp FILE); the paths written in GARPOS's files are not followed")
    if fmt != "garpos" and (initcfg is not None or svp is not None):
        raise ModelError("--initcfg, --svp: GARPOS's files go with --format garpos")
    if source in BUILTIN_SURVEYS:
        if fmt is not None:
            raise ModelError(f"--format: the built-in survey {source} has its own format; give --format with a log")
        return _builtin(source, overrides)
    if source.lower().endswith(".toml"):
        raise ModelError(f"calibrate: {source[:80]!r} is a simulated survey (CONFIG.toml): "
                         "sblsim.orchestrator.surveys.simulate.load_simulated reads it")
    fmt = fmt or "sblsim"
    solver = apply_solver_overrides(solver_defaults(), overrides)
    path = Path(source)
    if fmt in ("seagap", "garpos"):  # their own transponders and profile; eigenrays unless --set says otherwise
        if not any(item.split("=", 1)[0].strip() == "solver.propagation" for item in overrides):
            solver["propagation"] = "ray"
        notes = [f"{fmt}'s files carry no GNSS sigma: every position takes {NOMINAL_SIGMA_M:g} m (immaterial with "
                 "the covariance scaled by the residuals)"]
        if fmt == "seagap":
            folder = read_seagap(path)
            return Survey(path.name or str(path), folder.log, folder.ids, folder.apriori, solver, None, fmt,
                          str(path), notes, profile=folder.profile)
        site = read_garpos(path, Path(initcfg), Path(svp))
        left = site.left_out
        if left["flagged"] or left["unknown_transponder"]:
            notes.append(f"left out {left['flagged']} flagged replies and {left['unknown_transponder']} of "
                         "transponders that are not Stations")
        return Survey(site.name, site.log, site.ids, site.apriori, solver, site.origin, fmt, str(path), notes,
                      profile=site.profile)
    log = FORMATS[fmt](path)
    ids = sorted(log.counts["transponders"])
    apriori = guess_apriori(log, ids, solver["sound_speed_mps"])
    site_origin = None
    if fmt == "xie":
        found = xie_origin(path)
        site_origin = dict(zip(("lat_deg", "lon_deg", "height_m"), found)) if found else None
    notes = ["the a-priori positions are guessed from the log (under the mean transmit point, half the median "
             "TWTT deep): the offsets are from that guess"]
    return Survey(path.stem, log, ids, apriori, solver, site_origin, fmt, str(path), notes)


@dataclass
class Calibration:
    """A solved survey: its segments' solutions, the combination, the tables and numbers written."""

    survey: Survey
    segments: list[tuple[str, str, np.ndarray, Solution]]
    solution: dict
    residuals: pd.DataFrame
    #: The running solution, :data:`RUNNING_COLUMNS` (None with ``solver.running = false``).
    running: pd.DataFrame | None = None
    #: The perturbation of each reply, :data:`NTD_COLUMNS` (None without one).
    ntd: pd.DataFrame | None = None
    #: The search's candidates (:func:`sblsim.models.calibration.select`, with their ``segment``; None without).
    search: pd.DataFrame | None = None
    #: What the user must know about the solution (one line each; ``sblsim calibrate`` prints them as warnings).
    warnings: list[str] = field(default_factory=list)


def _windows(survey: Survey) -> list[tuple[str, str, np.ndarray]]:
    f = survey.log.frame
    t = f["t_tx_s"].to_numpy()
    near = np.hypot(f["tx_e_m"].to_numpy(), f["tx_n_m"].to_numpy()) <= survey.solver["distance_limit_m"]
    if not survey.solver["segments"]:
        return [("", "", np.flatnonzero(near))]
    out = []
    for k, (a, b) in enumerate(survey.solver["segments"]):
        start, end = _instant(a, f"solver.segments[{k}]"), _instant(b, f"solver.segments[{k}]")
        out.append((a, b, np.flatnonzero((t >= start) & (t < end) & near)))
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")


def leg_model(survey: Survey) -> tuple[LegModel | None, np.ndarray | None]:
    """The legs' model of a survey's settings and, for a straight ray through a profile, each transponder's
    harmonic-mean speed [m/s].

    ``propagation = "straight"`` without a profile: None (a straight ray at ``sound_speed_mps``); with one:
    :class:`~sblsim.models.calibration.StraightRay` at each transponder's harmonic mean of the profile from
    ``harmonic_mean_start_depth_m`` to its depth (:attr:`Survey.depth_m`, or ``surface_u_m`` less its Up), the
    model's
    :func:`~sblsim.orchestrator.surveys.gnatss.harmonic_mean_speed`; ``propagation = "ray"``:
    :class:`~sblsim.models.calibration.EigenRay` through the profile (its solve compiled in the local engine's
    library when a C compiler can build it; else evaluated by casadi, some 15 times slower).

    Returns
    -------
    legs : LegModel or None
        The leg model for :func:`~sblsim.models.calibration.solve` (None: its default straight ray).
    speeds : numpy.ndarray, shape (k,), or None
        Each transponder's harmonic-mean speed [m/s] (straight rays through a profile only).

    Raises
    ------
    ModelError
        ``ray`` without a profile, an unknown or unreadable profile, a transponder not below the start depth.
    """
    s = survey.solver
    table = profile_of(survey)
    if table is None:
        if s["propagation"] == "ray":
            raise ModelError("solver.sound_speed_profile: propagation = \"ray\" needs a profile (e.g. ctd:NCL1)")
        return None, None
    if s["propagation"] == "ray":
        # the eigenray solve compiled in the local engine's library when a compiler builds it (once per cache)
        return EigenRay(table, s["sound_speed_mps"], s["surface_u_m"], compiled_exact_points(),
                        earth_radius=s["earth_radius_m"], transducer_depth=s["transducer_depth_m"]), None
    start = s["harmonic_mean_start_depth_m"]
    speeds = []
    depths = survey.depth_m if survey.depth_m is not None else s["surface_u_m"] - survey.apriori[:, 2]
    for name, depth in zip(survey.ids, depths):
        if depth <= start:
            raise ModelError(f"solver.harmonic_mean_start_depth_m: transponder {name} at {depth:g} m is not below "
                             f"the start depth {start:g} m")
        speeds.append(harmonic_mean_speed(start, depth, s["sound_speed_profile"] or table))
    speeds = np.array(speeds)
    return StraightRay(s["sound_speed_mps"] / speeds), speeds


def profile_of(survey: Survey) -> np.ndarray | None:
    """The profile of a survey's settings: ``solver.sound_speed_profile``'s table, else the survey's own (SeaGap),
    else None.

    Raises
    ------
    ModelError
        An unknown or unreadable profile, or one without a table.
    """
    profile = survey.solver["sound_speed_profile"]
    if not profile:
        return survey.profile
    table = profile_table(profile, "", 15.0, 35.0, field="solver.sound_speed_profile")
    if table.shape[0] == 0:
        raise ModelError(f"solver.sound_speed_profile: {profile[:40]!r} has no table; give a cast such as ctd:NCL1")
    return table


def calibrate(survey: Survey) -> Calibration:
    """Solve every segment of a survey and combine them.

    Returns
    -------
    Calibration

    Raises
    ------
    ModelError
        A segment without enough replies (named), or replies that do not determine the unknowns.
    """
    s = survey.solver
    f = survey.log.frame
    legs, harmonic = leg_model(survey)
    candidates = perturbations(survey)
    segments, tables, runs, nis, apart, searches = [], [], [], [], [], []
    for k, (a, b, rows) in enumerate(_windows(survey)):
        what = f"segment {k + 1} [{a}, {b})" if a else "the log"
        replies = survey.log.replies(survey.ids, rows)
        if len(candidates) > 1:
            sol, table = select(replies, survey.apriori, s["sound_speed_mps"], candidates, rigid=s["rigid"],
                                outlier_factor=s["outlier_factor"], legs=legs, what=what, criterion=s["criterion"])
            searches.append(pd.DataFrame(table).assign(segment=k + 1))
        else:
            sol = solve(replies, survey.apriori, s["sound_speed_mps"], rigid=s["rigid"],
                        solve_sound_speed=s["solve_sound_speed"], outlier_factor=s["outlier_factor"],
                        twtt_sigma=s["twtt_sigma_s"], legs=legs, what=what,
                        perturbation=candidates[0] if candidates else None)
        segments.append((a, b, rows, sol))
        if s["running"] and not candidates:  # the running solution has no perturbation model
            frame, distance, sigmas = _running(survey, k + 1, rows, replies, sol, legs, what)
            runs.append(frame)
            nis.append(frame["nis"].to_numpy()[::len(survey.ids)])
            j = int(np.argmax(sigmas))
            apart.append((float(sigmas[j]), float(np.max(distance)), survey.ids[j], what, float(np.mean(nis[-1]))))
        part = f.iloc[rows][["ping", "transponder", "t_tx_s", "tx_e_m", "tx_n_m", "rx_e_m", "rx_n_m"]].copy()
        part.insert(0, "segment", k + 1)
        part["residual_s"] = sol.residual_s
        part["residual_m"] = sol.residual_m
        part["weight_per_m2"] = sol.weight
        part["elevation_deg"] = np.degrees(sol.elevation)
        part["azimuth_deg"] = np.degrees(sol.azimuth) % 360.0
        part["used"] = sol.used
        tables.append(part)
    residuals = pd.concat(tables, ignore_index=True)
    combined = combine([seg[3] for seg in segments])
    used = residuals[residuals["used"]]
    rejected = residuals[~residuals["used"]]
    w = used["weight_per_m2"].to_numpy()
    speeds = [seg[3].sound_speed for seg in segments]
    solution = {
        "survey": survey.name,
        "title": survey.title,
        "format": survey.format,
        "origin": survey.origin,
        "sound_speed_mps": float(np.mean(speeds)),
        "solver": {k: (list(map(list, v)) if k == "segments" else v) for k, v in s.items()},
        "transponders": [
            {"id": name,
             "n_m": float(combined.position[j, 1] - survey.apriori[j, 1]),
             "e_m": float(combined.position[j, 0] - survey.apriori[j, 0]),
             "u_m": float(combined.position[j, 2] - survey.apriori[j, 2]),
             "sigma_n_m": float(combined.sigma[j, 1]), "sigma_e_m": float(combined.sigma[j, 0]),
             "sigma_u_m": float(combined.sigma[j, 2]),
             "scatter_n_m": _finite(combined.scatter[j, 1]), "scatter_e_m": _finite(combined.scatter[j, 0]),
             "scatter_u_m": _finite(combined.scatter[j, 2]),
             "apriori_e_m": float(survey.apriori[j, 0]), "apriori_n_m": float(survey.apriori[j, 1]),
             "apriori_u_m": float(survey.apriori[j, 2]),
             **({"sound_speed_mps": float(harmonic[j])} if harmonic is not None else {})}
            for j, name in enumerate(survey.ids)],
        "segments": [
            {"start": a, "end": b, "id": name,
             "n_m": float(sol.offset[j, 1]), "e_m": float(sol.offset[j, 0]), "u_m": float(sol.offset[j, 2]),
             "sigma_n_m": float(sol.sigma[j, 1]), "sigma_e_m": float(sol.sigma[j, 0]),
             "sigma_u_m": float(sol.sigma[j, 2]),
             "pings_used": int(f.iloc[rows[sol.used]]["ping"].nunique()),
             "pings_rejected": int(f.iloc[rows[~sol.used]]["ping"].nunique()),
             "sound_speed_mps": sol.sound_speed,
             "twtt_residual_rms_s": _rms(sol.residual_s[sol.used]),
             "variance_factor": sol.variance_factor, "converged": sol.converged}
            for a, b, rows, sol in segments for j, name in enumerate(survey.ids)],
        "twtt_residual_rms_s": _rms(used["residual_s"].to_numpy()),
        "twtt_residual_wrms_s": float(np.sqrt(np.sum(w * used["residual_s"].to_numpy() ** 2) / np.sum(w))),
        "pings_used": int(used["ping"].nunique()),
        "pings_rejected": int(rejected["ping"].nunique()),
        "replies_used": len(used),
        "replies_rejected": len(rejected),
        "log": {"rows": survey.log.counts["rows"], "pings": survey.log.counts["pings"],
                "replies_per_transponder": survey.log.counts["transponders"],
                "replies_in_no_segment": int(len(f) - residuals.drop_duplicates(["ping", "transponder"]).shape[0]),
                "ignored_columns": survey.log.counts.get("ignored_columns", [])},
    }
    warnings = []
    if runs:
        values = np.concatenate(nis)
        worst = max(apart)
        solution["running"] = {"replies": len(values), "nis_mean": float(np.mean(values)),
                               "prior_sigma_m": s["running_prior_sigma_m"], "iterated": s["running_iterated"],
                               "passes": s["running_passes"],
                               "largest_distance_from_least_squares_m": max(a[1] for a in apart),
                               "agrees_with_least_squares": worst[0] <= RUNNING_AGREEMENT_SIGMA}
        if worst[0] > RUNNING_AGREEMENT_SIGMA:
            warnings.append(f"the running solution of {worst[3]} ends {worst[1]:.4g} m from the least-squares "
                            f"solution (transponder {worst[2]} {worst[0]:.3g} sigma apart, more than "
                            f"{RUNNING_AGREEMENT_SIGMA:g}; mean NIS {worst[4]:.3g}, 1 when consistent): it did not "
                            "converge from the a-priori positions, so running.csv is no solution (solution.json "
                            "is); give it more passes (solver.running_passes) or a-priori positions nearer the truth")
    solution.update(_perturbation_keys(survey, segments, combined))
    ntd = _ntd_table(survey, segments) if candidates else None
    search = pd.concat(searches, ignore_index=True) if searches else None
    return Calibration(survey, segments, solution, residuals, pd.concat(runs, ignore_index=True) if runs else None,
                       ntd=ntd, search=search, warnings=warnings)


def perturbations(survey: Survey) -> list[Perturbation]:
    """The perturbations a survey's settings solve: none (``solver.perturbation = "none"``), one, or the candidates
    of a search (the product of the lists among :data:`SEARCH_KEYS`).

    GARPOS's characteristic travel time is twice the transponders' mean depth (:attr:`Survey.depth_m`, or
    ``surface_u_m`` less their Up) over the profile's depth-averaged speed (its trapezoidal mean over its rows;
    ``sound_speed_mps`` without a profile), as GARPOS takes it.

    Raises
    ------
    ModelError
        A list among GARPOS's keys with ``perturbation = "ntd"``, more than 500 candidates, or the profile's errors.
    """
    s = survey.solver
    if s["perturbation"] == "none":
        return []
    lists = {k: (s[k] if isinstance(s[k], list) else [s[k]]) for k in SEARCH_KEYS}
    if s["perturbation"] == "ntd":
        for key in SEARCH_KEYS[1:]:
            if len(lists[key]) > 1:
                raise ModelError(f"solver.{key}: a list searches GARPOS's hyperparameters (perturbation = garpos); "
                                 "SeaGap's NTD searches n_bases")
    count = math.prod(len(v) for v in lists.values())
    if count > 500:
        raise ModelError(f"solver: {count} candidates in the search (the product of the lists of "
                         f"{', '.join(SEARCH_KEYS)}); at most 500")
    t0 = 0.0
    if s["perturbation"] == "garpos":
        table = profile_of(survey)
        depths = survey.depth_m if survey.depth_m is not None else s["surface_u_m"] - survey.apriori[:, 2]
        speed = s["sound_speed_mps"] if table is None or len(table) < 2 else \
            float(np.sum(0.5 * (table[1:, 1] + table[:-1, 1]) * np.diff(table[:, 0])) / (table[-1, 0] - table[0, 0]))
        t0 = 2.0 * float(np.mean(depths)) / speed
    common = {"kind": s["perturbation"], "knot_interval": s["knot_interval"], "gradient": s["gradient"],
              "reject_sigma": s["reject_sigma"], "earth_radius": s["earth_radius_m"], "t0": t0}
    return [Perturbation(n_bases=n, log_lambda0=l0, log_grad_lambda=lg, mu_t=mt, mu_mt=mm, **common)
            for n in lists["n_bases"] for l0 in lists["log_lambda0"] for lg in lists["log_grad_lambda"]
            for mt in lists["mu_t"] for mm in lists["mu_mt"]]


def _perturbation_keys(survey: Survey, segments: list, combined) -> dict:
    """``solution.json``'s keys of the array and the perturbation: ``array_displacement`` (the rigid shift, or the
    transponders' mean offset with their sigmas taken as independent; the formal and the realistic 1-sigma),
    ``n_bases``, ``aic``, ``bic``, ``abic`` (summed over segments: the criteria of their joint model), ``gradient``
    (the deep gradient's East and North: SeaGap's constants [s], the mean of GARPOS's coefficients [1/km]) and
    ``shallow_gradient``."""
    fits = [seg[3].perturbation for seg in segments]
    offset = combined.position - survey.apriori
    scales = [_realistic(seg[3]) for seg in segments]
    scale = float(np.sqrt(np.mean(np.square(scales))))
    if survey.solver["rigid"]:
        mean, sd = offset[0], combined.sigma[0]
    else:
        mean, sd = offset.mean(axis=0), np.sqrt(np.sum(combined.sigma**2, axis=0)) / len(offset)
    out = {"array_displacement": {**{f"{a}_m": float(mean[j]) for j, a in enumerate("enu")},
                                  **{f"sigma_{a}_m": float(sd[j]) for j, a in enumerate("enu")},
                                  **{f"sigma_realistic_{a}_m": float(sd[j] * scale) for j, a in enumerate("enu")}},
           "realistic_sigma_scale": scale}
    if fits[0] is None:
        return {**out, "n_bases": None, "aic": None, "bic": None, "abic": None, "gradient": None}

    def total(name: str) -> float | None:
        values = [getattr(fit, name) for fit in fits]
        return None if values[0] is None else float(np.sum(values))

    def gradient(name: str) -> dict | None:
        if name not in fits[0].gradient:
            return None
        values = np.mean([np.mean(fit.gradient[name].reshape(2, -1), axis=1) for fit in fits], axis=0)
        return {"e": float(values[0]), "n": float(values[1])}

    bases = [fit.n_bases for fit in fits]
    return {**out, "n_bases": bases[0] if len(set(bases)) == 1 else bases, "aic": total("aic"), "bic": total("bic"),
            "abic": total("abic"), "gradient": gradient("deep"), "shallow_gradient": gradient("shallow"),
            "perturbation": {"kind": fits[0].settings.kind, "parameters": [fit.parameters for fit in fits]}}


def _realistic(sol: Solution) -> float:
    """The realistic sigma's factor of a segment (:func:`~sblsim.models.calibration.perturbation.effective_scale` of
    its used residuals in time order)."""
    if sol.perturbation is not None:
        return sol.perturbation.effective_scale
    return effective_scale(sol.residual_s[sol.used])


def _ntd_table(survey: Survey, segments: list) -> pd.DataFrame:
    """The rows of :data:`NTD_COLUMNS`, every segment's replies.

    The sound speed's change of a reply's delay :math:`\\delta` is that of a uniform water column,
    :math:`\\delta V = -V\\,\\delta/T_v`, :math:`T_v = T\\cos\\xi` its nadir two-way time, :math:`V` the solver's
    speed (for GARPOS this is its :math:`\\gamma V`)."""
    f = survey.log.frame
    parts = []
    for k, (_, _, rows, sol) in enumerate(segments, start=1):
        fit = sol.perturbation
        src = f.iloc[rows]
        nadir = src["twtt_s"].to_numpy() * fit.mapping
        parts.append(pd.DataFrame({
            "segment": k, "ping": src["ping"].to_numpy(), "transponder": src["transponder"].to_numpy(),
            "t_s": fit.mid_time, "nadir_cosine": fit.mapping, "observed_s": fit.observed, "ntd_s": fit.delay,
            "residual_s": fit.observed - fit.delay, "sound_speed_change_mps": -sol.sound_speed * fit.delay / nadir,
            "used": sol.used}))
    return pd.concat(parts, ignore_index=True)[list(NTD_COLUMNS)]


def _running(survey: Survey, segment: int, rows: np.ndarray, replies, sol: Solution, legs: LegModel | None,
             what: str) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """The running solution of a segment's replies that :func:`~sblsim.models.calibration.solve` kept, in
    transmit-time order, as rows of :data:`RUNNING_COLUMNS`, and how far it ends from ``sol``
    (:func:`~sblsim.models.calibration.running_disagreement`)."""
    s = survey.solver
    f = survey.log.frame
    kept = np.flatnonzero(sol.used)
    kept = kept[np.argsort(f["t_tx_s"].to_numpy()[rows[kept]], kind="stable")]
    run = running(replies.subset(kept), survey.apriori, s["sound_speed_mps"], rigid=s["rigid"],
                  solve_sound_speed=s["solve_sound_speed"], twtt_sigma=s["twtt_sigma_s"], legs=legs,
                  prior_sigma=s["running_prior_sigma_m"], iterated=s["running_iterated"],
                  passes=s["running_passes"], what=what)
    n, k = len(kept), len(survey.ids)
    source = f.iloc[rows[kept]]
    offset = run.position - survey.apriori[None]
    rep = np.repeat
    frame = pd.DataFrame({
        "segment": segment, "reply": rep(np.arange(n), k), "ping": rep(source["ping"].to_numpy(), k),
        "transponder": rep(source["transponder"].to_numpy(), k), "t_tx_s": rep(source["t_tx_s"].to_numpy(), k),
        "id": np.tile(np.asarray(survey.ids, dtype=object), n),
        "e_m": offset[:, :, 0].ravel(), "n_m": offset[:, :, 1].ravel(), "u_m": offset[:, :, 2].ravel(),
        "sigma_e_m": run.position_sigma[:, :, 0].ravel(), "sigma_n_m": run.position_sigma[:, :, 1].ravel(),
        "sigma_u_m": run.position_sigma[:, :, 2].ravel(), "sound_speed_mps": rep(run.sound_speed, k),
        "innovation_m": rep(run.innovation, k), "innovation_sigma_m": rep(np.sqrt(run.innovation_variance), k),
        "nis": rep(run.nis, k)}, columns=list(RUNNING_COLUMNS))
    return (frame, *running_disagreement(run, sol))


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def write_calibration(result: Calibration, out: Path | str, extra: dict | None = None) -> Path:
    """Write :data:`OUTPUT_FILES` into ``out`` atomically (nothing changes there if a write fails).

    ``extra`` maps further files' names to functions writing them (given the file's path), written in the same
    step (a simulated survey's log and replicates)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    r = result.residuals
    title = result.solution["title"] or result.survey.name
    with staged_directory(out) as tmp:
        (tmp / "solution.json").write_text(json.dumps(result.solution, indent=2, allow_nan=False) + "\n")
        r.to_csv(tmp / "residuals.csv", index=False)
        used = r[r["used"]]
        rejected = r[~r["used"]]
        scale = float(np.nanpercentile(np.abs(used["residual_s"]) * 1e6, 98)) if len(used) else 1.0
        fig, ax = plt.subplots(figsize=(6.5, 6))
        dots = ax.scatter(used["rx_e_m"], used["rx_n_m"], c=used["residual_s"] * 1e6, cmap="coolwarm", s=8,
                          vmin=-scale, vmax=scale)
        ax.scatter(rejected["rx_e_m"], rejected["rx_n_m"], marker="x", c="k", s=16, label="rejected")
        for j, name in enumerate(result.survey.ids):
            t = result.solution["transponders"][j]
            ax.plot(t["apriori_e_m"] + t["e_m"], t["apriori_n_m"] + t["n_m"], "k^", ms=9)
            ax.annotate(f"transponder {name}", (t["apriori_e_m"] + t["e_m"], t["apriori_n_m"] + t["n_m"]),
                        textcoords="offset points", xytext=(6, 6))
        fig.colorbar(dots, ax=ax, label="TWTT residual [µs]")
        ax.set(xlabel="East [m]", ylabel="North [m]", aspect="equal", title=f"Track, {title}")
        ax.legend(loc="lower right")
        fig.savefig(tmp / "track.png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        for name, column, label in (("residuals_time.png", "t_tx_s", "transmit time [s from the first ping]"),
                                    ("residuals_elevation.png", "elevation_deg", "elevation angle [deg]")):
            fig, ax = plt.subplots(figsize=(7, 3.5))
            x0 = float(r["t_tx_s"].min()) if column == "t_tx_s" else 0.0
            for k, part in used.groupby("segment"):
                ax.plot(part[column] - x0, part["residual_s"] * 1e6, ".", ms=3, label=f"segment {k}")
            ax.plot(rejected[column] - x0, rejected["residual_s"] * 1e6, "kx", ms=5, label="rejected")
            ax.set(xlabel=label, ylabel="TWTT residual [µs]", title=title)
            ax.grid(True, lw=0.3)
            ax.legend(fontsize=7, ncol=3)
            fig.savefig(tmp / name, dpi=110, bbox_inches="tight")
            plt.close(fig)
        if result.running is not None:
            result.running.to_csv(tmp / "running.csv", index=False)
            _running_figure(result, tmp / "running.png", plt)
        if result.ntd is not None:
            result.ntd.to_csv(tmp / "ntd.csv", index=False)
            _ntd_figure(result, tmp / "ntd.png", plt)
        if result.search is not None:
            result.search.to_csv(tmp / "criterion.csv", index=False)
            _criterion_figure(result, tmp / "criterion.png", plt)
        for name, write in (extra or {}).items():
            write(tmp / name)
    return out


def _ntd_figure(result: Calibration, path: Path, plt) -> None:
    """SeaGap's figure of the perturbation: each transponder's nadir-normalised residual of the legs (less the
    gradients) and the solved delay against time, and what remains."""
    r = result.ntd
    title = result.solution["title"] or result.survey.name
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True)
    t0 = float(r["t_s"].min())
    used = r[r["used"]]
    for j, tid in enumerate(result.survey.ids):
        mine = used[used["transponder"] == tid]
        hours = (mine["t_s"] - t0) / 3600.0
        top.plot(hours, mine["observed_s"] * 1e3, "+", ms=3, color=f"C{j % 10}", label=f"transponder {tid}")
        bottom.plot(hours, mine["residual_s"] * 1e3, "+", ms=3, color=f"C{j % 10}")
    for k, part in r.groupby("segment"):
        part = part.sort_values("t_s")
        top.plot((part["t_s"] - t0) / 3600.0, part["ntd_s"] * 1e3, "k-", lw=1.2,
                 label="perturbation (nadir delay)" if k == 1 else None)
    top.set(ylabel="nadir-normalised delay [ms]", title=f"Sound-speed perturbation, {title}")
    bottom.set(xlabel="time [h from the first reply]", ylabel="residual [ms]")
    for ax in (top, bottom):
        ax.grid(True, lw=0.3)
    top.legend(fontsize=7, ncol=3)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _criterion_figure(result: Calibration, path: Path, plt) -> None:
    """The search's criteria against the number of bases (SeaGap's AIC and BIC) or the smoothness (GARPOS's ABIC),
    the chosen candidate marked."""
    table = result.search
    garpos = table["abic"].notna().any()
    names = ["abic"] if garpos else ["aic", "bic"]
    chosen = "abic" if garpos else result.survey.solver["criterion"]
    axis = "log_lambda0" if garpos and table["log_lambda0"].nunique() > 1 else "n_bases"
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for k, part in table.groupby("segment"):
        others = [c for c in ("log_grad_lambda", "mu_t", "mu_mt") if part[c].nunique() > 1]
        for values, line in (part.groupby(others) if others else [((), part)]):
            line = line.sort_values(axis)
            for name in names:
                label = ", ".join([name.upper()] + [f"{c} {v:g}" for c, v in zip(others, np.atleast_1d(values))])
                ax.plot(line[axis], line[name], "+-", label=label + (f", segment {k}" if k > 1 else ""))
        best = part[part["chosen"]]
        ax.axvline(float(best[axis].iloc[0]), color="r", lw=0.8)
        ax.annotate(f"{best[axis].iloc[0]:g} ({chosen.upper()})", (float(best[axis].iloc[0]),
                                                                      float(best[chosen].iloc[0])),
                    textcoords="offset points", xytext=(4, -12), color="r")
    ax.set(xlabel={"n_bases": "number of B-spline bases", "log_lambda0": "log10 lambda0^2"}[axis],
           ylabel="criterion", title=f"Model selection, {result.solution['title'] or result.survey.name}")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _running_figure(result: Calibration, path: Path, plt) -> None:
    """The running estimate of each transponder's East, North, Up offsets with its +-1-sigma band, beside each
    segment's weighted least-squares solution (dashed)."""
    r = result.running
    title = result.solution["title"] or result.survey.name
    ids = result.survey.ids
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    t0 = float(r["t_tx_s"].min())
    for axis, (ax, name) in enumerate(zip(axes, ("e", "n", "u"))):
        limits = []
        for j, tid in enumerate(ids):
            for segment, part in r[r["id"] == tid].groupby("segment"):
                t = part["t_tx_s"].to_numpy() - t0
                x, sd = part[f"{name}_m"].to_numpy(), part[f"sigma_{name}_m"].to_numpy()
                colour = f"C{j % 10}"
                label = f"transponder {tid}" if segment == 1 else None
                ax.plot(t, x, "-", color=colour, lw=1, label=label)
                ax.fill_between(t, x - sd, x + sd, color=colour, alpha=0.2, lw=0)
                sol = result.segments[segment - 1][3]
                ax.hlines(sol.offset[j, axis], t[0], t[-1], colors="k", linestyles="--", lw=0.8,
                          label="least squares" if (j, segment) == (0, 1) else None)
                # the band is metres wide at the start (the prior): show the last nine tenths
                tail = x[len(x) // 10:]
                spread = max(float(np.max(np.abs(tail - x[-1]))), 4.0 * sd[-1], 1e-3)
                limits += [x[-1] - 1.5 * spread, x[-1] + 1.5 * spread]
        ax.set_ylim(min(limits), max(limits))
        ax.set_ylabel(f"{name.upper()} offset [m]")
        ax.grid(True, lw=0.3)
    axes[0].set_title(f"Running solution (static Kalman filter, ±1σ), {title}")
    axes[0].legend(fontsize=7, ncol=3)
    axes[-1].set_xlabel("transmit time [s from the first ping]")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


__all__ = ["BUILTIN_SURVEYS", "Calibration", "EDITINGS", "FORMATS", "NTD_COLUMNS", "OUTPUT_FILES", "PERTURBATION_FILES",
           "PROPAGATIONS", "RUNNING_COLUMNS", "RUNNING_FILES", "SEARCH_FILES", "SEARCH_KEYS", "SOLVER_KEYS",
           "SOLVER_VARIABLES", "Survey", "apply_solver_overrides", "calibrate", "guess_apriori", "leg_model",
           "load_survey", "perturbations", "profile_of", "solver_defaults", "solver_value", "write_calibration"]
