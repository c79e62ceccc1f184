"""A calibration survey to solve (:class:`Survey`: its log, site and settings): the built-in surveys
(:data:`BUILTIN_SURVEYS`, TOML files of this package whose logs are its data files) and a log given on the command
line in one of :data:`FORMATS`, loaded by :func:`load_survey`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib.resources import as_file, files
from pathlib import Path

import numpy as np

from sblsim.models.calibration import SOUND_SPEED_RANGE
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.surveys.garpos import read_garpos
from sblsim.orchestrator.surveys.gnatss import community_editing, read_gnatss
from sblsim.orchestrator.surveys.log import LOG_COLUMNS, SurveyLog, check_frame, read_survey_log
from sblsim.orchestrator.surveys.seagap import NOMINAL_SIGMA_M, read_seagap
from sblsim.orchestrator.surveys.settings import apply_solver_overrides, check_solver, solver_defaults, solver_value
from sblsim.orchestrator.surveys.xie import origin as xie_origin
from sblsim.orchestrator.surveys.xie import read_xie

#: The log formats read: name -> reader of a log file (SeaGap's folder and GARPOS's three files have their own).
FORMATS = {"sblsim": read_survey_log, "xie": read_xie, "seagap": None, "garpos": None}
_FOLDER = files("sblsim.orchestrator.surveys")
#: The built-in surveys: name -> its TOML file's name in this package.
BUILTIN_SURVEYS = {name: f"{name}.toml" for name in (
    "xie-2021-07-23", "xie-2021-08-23-1065", "xie-2021-08-23-1063", "xie-2021-12-10", "xie-2022-03-21",
    "ncl1-2022-208", "seagap-example")}
#: The editing a built-in GNATSS survey may ask for (``survey.editing``).
EDITINGS = ("none", "community")
#: The units' check (:func:`check_track_units`): the ranges' spread allowed beyond the transducer's movement, as a
#: fraction of the transponder's depth [1], and the percentiles of the ranges whose difference is their spread.
TRACK_DEPTH_FRACTION = 0.01
RANGE_PERCENTILES = (5.0, 95.0)
#: Where a format's transducer positions come from (what the units' check names).
TRACK_FIELDS = {"seagap": "obsdata: the antenna's East, North, Up (fields 4-6 and 11-13) [m]",
                "garpos": "obs: ant_e0, ant_n0, ant_u0, ant_e1, ant_n1, ant_u1 [m]",
                "sblsim": "the log's tx_e_m, tx_n_m, tx_u_m, rx_e_m, rx_n_m, rx_u_m [m]",
                "xie": "the transducer's North, East, Up at transmit and at receive (fields 2-4 and 9-11) [m]"}
#: The site's keys of a transponder: name -> (allowed range, unit).
TRANSPONDER_KEYS = {"e_m": ((-1e5, 1e5), "m"), "n_m": ((-1e5, 1e5), "m"), "u_m": ((-1e5, 1e5), "m"),
                    "turnaround_s": ((0.0, 60.0), "s")}


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



def check_track_units(log: SurveyLog, ids: list[str], apriori: np.ndarray, field: str) -> None:
    """Refuse a log whose transducer positions cannot be in metres: the ranges its travel times give span more
    than the transducer moved.

    Two ranges to one transponder differ by no more than the distance between the points they are measured from
    (the triangle inequality; a reply's range, half its two legs, by no more than the larger of its transmit and
    receive points' moves). Per transponder, the ranges :math:`r_i = c_{\\min} T_i / 2` at the slowest sea water
    (:data:`~sblsim.models.calibration.SOUND_SPEED_RANGE`, the smallest spread any speed gives) spread between
    their :data:`RANGE_PERCENTILES` (a few gross outliers do not count) by at most the diagonal :math:`L` of the
    box holding the transducer's transmit and receive points plus :data:`TRACK_DEPTH_FRACTION` of the
    transponder's depth :math:`D` below the transducer's mean height (the ocean's change over a survey, parts in
    :math:`10^3` of a range of a few depths). Positions in km where metres are expected shrink :math:`L` a
    thousandfold; the ranges, from the travel times, do not.

    Parameters
    ----------
    log : SurveyLog
    ids : list of str
        The transponders.
    apriori : numpy.ndarray, shape (k, 3)
        Their a-priori positions [m] (their Up gives the depth).
    field : str
        Where the positions come from (the error names it).

    Raises
    ------
    ModelError
        One line naming ``field``, the transponder, the ranges' spread, the allowed maximum and the movement.
    """
    f = log.frame
    speed = SOUND_SPEED_RANGE[0]
    names = f["transponder"].to_numpy()
    twtt = f["twtt_s"].to_numpy()
    points = {w: f[[f"{w}_e_m", f"{w}_n_m", f"{w}_u_m"]].to_numpy() for w in ("tx", "rx")}
    for j, name in enumerate(ids):
        mine = names == name
        if mine.sum() < 2:
            continue
        low, high = np.percentile(0.5 * speed * twtt[mine], RANGE_PERCENTILES)
        both = np.vstack((points["tx"][mine], points["rx"][mine]))
        moved = float(np.linalg.norm(both.max(axis=0) - both.min(axis=0)))
        depth = abs(float(np.mean(both[:, 2])) - float(apriori[j, 2]))
        allowed = moved + TRACK_DEPTH_FRACTION * depth
        if high - low > allowed:
            raise ModelError(f"{field}: transponder {name}'s ranges (half its TWTT at {speed:g} m/s or more) span "
                             f"{high - low:.4g} m but the transducer moves within {moved:.4g} m: at most "
                             f"{allowed:.4g} m is possible (the movement plus {TRACK_DEPTH_FRACTION:.0%} of its "
                             f"{depth:.4g} m depth); are the positions in km where metres are expected?")


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
        check_track_units(log, ids, apriori, TRACK_FIELDS["seagap"])
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
    solver = check_solver(apply_solver_overrides(solver, overrides))
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
    solver = check_solver(apply_solver_overrides(solver_defaults(), overrides))
    path = Path(source)
    if fmt in ("seagap", "garpos"):  # their own transponders and profile; eigenrays unless --set says otherwise
        if not any(item.split("=", 1)[0].strip() == "solver.propagation" for item in overrides):
            solver["propagation"] = "ray"
        notes = [f"{fmt}'s files carry no GNSS sigma: every position takes {NOMINAL_SIGMA_M:g} m (immaterial with "
                 "the covariance scaled by the residuals)"]
        if fmt == "seagap":
            folder = read_seagap(path)
            check_track_units(folder.log, folder.ids, folder.apriori, TRACK_FIELDS["seagap"])
            return Survey(path.name or str(path), folder.log, folder.ids, folder.apriori, solver, None, fmt,
                          str(path), notes, profile=folder.profile)
        site = read_garpos(path, Path(initcfg), Path(svp))
        check_track_units(site.log, site.ids, site.apriori, TRACK_FIELDS["garpos"])
        left = site.left_out
        if left["flagged"] or left["unknown_transponder"]:
            notes.append(f"left out {left['flagged']} flagged replies and {left['unknown_transponder']} of "
                         "transponders that are not Stations")
        return Survey(site.name, site.log, site.ids, site.apriori, solver, site.origin, fmt, str(path), notes,
                      profile=site.profile)
    log = FORMATS[fmt](path)
    ids = sorted(log.counts["transponders"])
    apriori = guess_apriori(log, ids, solver["sound_speed_mps"])
    check_track_units(log, ids, apriori, TRACK_FIELDS[fmt])
    site_origin = None
    if fmt == "xie":
        found = xie_origin(path)
        site_origin = dict(zip(("lat_deg", "lon_deg", "height_m"), found)) if found else None
    notes = ["the a-priori positions are guessed from the log (under the mean transmit point, half the median "
             "TWTT deep): the offsets are from that guess"]
    return Survey(path.stem, log, ids, apriori, solver, site_origin, fmt, str(path), notes)


__all__ = ["BUILTIN_SURVEYS", "EDITINGS", "FORMATS", "RANGE_PERCENTILES", "Survey", "TRACK_DEPTH_FRACTION",
           "TRACK_FIELDS", "check_track_units", "guess_apriori", "load_survey"]
