"""Read a GNATSS GNSS-Acoustic survey (``pxp_tt`` + ``POS_FREED_TRANS_TWTT`` + the site) into the calibration log.

GNATSS (the community GNSS-Acoustic software, seafloor-geodesy/gnatss) takes a survey as three inputs;
this module reads them as GNATSS documents and uses them (its ``docs/input.md``, ``gnatss/loaders.py``,
``gnatss/ops/data.py`` and ``gnatss/configs/`` at commit 44ca5389):

``pxp_tt``
    One line per interrogation (ping): the date and time of transmission (``27-JUL-22 17:37:45.00``, UTC),
    then one two-way travel time per transponder in microseconds, in the order of the site's transponders
    (a ``0`` is a missing reply), then columns GNATSS ignores. Each travel time includes that transponder's
    turnaround (internal delay): 0.20, 0.32 and 0.44 s at NCL1, so that replies only 0.12 s apart arrive in
    another order than the transponders' when the slant ranges differ. A reply is therefore paired with its
    transponder by its column (its identity), never by the order of arrival.
``POS_FREED_TRANS_TWTT``
    The surface transducer's position, one line per epoch: the time in seconds since J2000
    (2000-01-01T12:00:00, counted without leap seconds, like POSIX time), the ECEF x, y, z [m] and the
    ECEF covariance [m^2] as 9 numbers row by row (xx, xy, xz, yx, yy, yz, zx, zy, zz). There is a line
    at each transmission and at each reply's arrival, ``t_tx + TWTT`` (the turnaround included). A line is
    found by its time, not by its place in the file.
The site (:func:`read_site`, a small TOML file of ours, ``data/ncl1/site.toml`` for NCL1)
    The array centre (the local frame's origin), the transponders' a-priori latitude, longitude and
    orthometric height (GNATSS's ``height``, above the geoid: the ellipsoidal height is
    ``height + geoid_undulation``, as GNATSS's solver takes it), their turnarounds and their column in
    ``pxp_tt``, the start depth of the harmonic mean and the editing limits.

The log (one row per reply, the columns :data:`LOG_COLUMNS`) is in local east/north/up [m] at the array
centre (pymap3d's ECEF -> ENU on WGS84); the 1-sigma of each coordinate is the square root of the
diagonal of the covariance rotated to ENU (``R C Rᵀ``, R the ECEF -> ENU rotation at the array centre,
found by rotating the unit vectors with pymap3d). Times are POSIX seconds, UTC: the ``pxp_tt`` time is UTC
(GNATSS's ``docs/input.md``) and its J2000 seconds are ``POSIX − 946728000``, which the reader checks
against the transmit line of ``POS_FREED_TRANS_TWTT``. ``twtt_s`` is the travel time less the
transponder's turnaround (GNATSS's transducer delay and travel-time correction are 0 for NCL1).

:func:`community_editing` keeps the pings the community keeps at a site (every transponder replied, the 3-D
GNSS sigma of the transmit and every receive position at most ``gnss_sigma_limit_m``, the transmit point
within ``distance_limit_m`` of the array centre, horizontally). :func:`straight_ray_residuals` checks the
reading against the a-priori positions (or shifted ones) at each transponder's harmonic-mean sound speed of the
CTD. The survey is solved by the calibration solver (:mod:`sblsim.models.calibration`; the built-in survey
``ncl1-2022-208`` of ``sblsim calibrate``).

Every file is read as hostile (the helpers every log reader shares, :mod:`sblsim.orchestrator.io.tables`): a
regular file of ASCII text only, within the logs' documented size, every number checked with its file, line
and column named (:class:`~sblsim.models.errors.ModelError`, one line). No file names another file the reader opens.

References
----------
GNATSS, GNSS-Acoustic Seafloor Positioning Software, https://github.com/seafloor-geodesy/gnatss (BSD-3).
Chadwell, C. D., and Sweeney, A. D. (2010), Acoustic ray-trace equations for seafloor geodesy, Marine
Geodesy 33(2-3), 164-186 (the straight ray at the harmonic-mean speed).
IOGP, Geomatics Guidance Note 7-2, method 9836 (geocentric/topocentric conversions: the ENU rotation).
"""

from __future__ import annotations

import argparse
import calendar
import math
import re
import sys
import tomllib
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np
import pandas as pd
import pymap3d

from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS, harmonic_mean, profile_nodes, profile_table
from sblsim.models.errors import ModelError
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.output import write_atomic
from sblsim.orchestrator.io.tables import NUMBER, csv_cells, read_lines
from sblsim.orchestrator.io.tables import number as table_number
from sblsim.orchestrator.surveys.log import LOG_COLUMNS, POSITION_RANGE

#: POSIX time of J2000 (2000-01-01T12:00:00 UTC) [s]: GNATSS's J2000 seconds are POSIX seconds less this.
J2000_POSIX = 946728000
#: Range of a two-way travel time in pxp_tt [us] (0: no reply).
MAX_TWTT_US = 60e6
#: Range of an ECEF coordinate [m] and of a covariance entry [m^2].
MAX_ECEF_M, MAX_COV_M2 = 1e7, 1e4
#: Range of a J2000 time in POS_FREED_TRANS_TWTT [s] (1970 to 2100).
J2000_RANGE = (-float(J2000_POSIX), 3.2e9)
#: Columns of a POS_FREED_TRANS_TWTT line.
POS_FIELDS = 13
#: The vendored NCL1 data (orchestrator/surveys/data/ncl1/).
DATA = ("sblsim.orchestrator.surveys", "data/ncl1")
_MONTHS = {m.upper(): k for k, m in enumerate(calendar.month_abbr) if m}
_DATE = re.compile(r"([0-9]{2})-([A-Za-z]{3})-([0-9]{2})")
_TIME = re.compile(r"([0-9]{2}):([0-9]{2}):([0-9]{2}(?:\.[0-9]{1,6})?)")


@dataclass(frozen=True)
class Transponder:
    """A seafloor transponder of a site, a priori.

    Attributes
    ----------
    id : str
        Its id (the log's ``transponder``).
    column : int
        Its two-way travel time column in ``pxp_tt`` (1 = the first after date and time).
    e_m, n_m, u_m : float
        A-priori position [m], local ENU at the site's origin (ellipsoidal up).
    depth_m : float
        Depth below the sea surface [m] (minus its orthometric height): where its harmonic mean ends.
    turnaround_s : float
        Its turnaround (internal delay) [s], included in ``pxp_tt``'s travel times.
    sound_speed_mps : float
        Harmonic-mean sound speed of the CTD from the site's start depth to ``depth_m`` [m/s].
    """

    id: str
    column: int
    e_m: float
    n_m: float
    u_m: float
    depth_m: float
    turnaround_s: float
    sound_speed_mps: float


@dataclass(frozen=True)
class Site:
    """A survey's site: the local frame's origin, the transponders a priori, the editing limits.

    Attributes
    ----------
    name : str
        The site's code (``NCL1``).
    lat_deg, lon_deg, height_m : float
        The local ENU frame's origin (the array centre) [deg, deg, m WGS84 ellipsoidal].
    transponders : tuple of Transponder
        In ``pxp_tt`` column order.
    geoid_undulation_m : float
        Geoid height above the ellipsoid [m] (orthometric -> ellipsoidal heights).
    harmonic_mean_start_depth_m : float
        Depth where the harmonic mean of the sound speed starts [m].
    gnss_sigma_limit_m : float
        The editing's limit of the 3-D GNSS sigma [m].
    distance_limit_m : float
        The editing's limit of the transmit point's horizontal distance from the origin [m].
    """

    name: str
    lat_deg: float
    lon_deg: float
    height_m: float
    transponders: tuple[Transponder, ...]
    geoid_undulation_m: float
    harmonic_mean_start_depth_m: float
    gnss_sigma_limit_m: float
    distance_limit_m: float

    def as_dict(self) -> dict:
        """The site as the calibration log format gives it: ``lat_deg``, ``lon_deg``, ``height_m`` and per
        transponder ``id``, ``e_m``, ``n_m``, ``u_m``, ``turnaround_s``, ``sound_speed_mps``."""
        return {"lat_deg": self.lat_deg, "lon_deg": self.lon_deg, "height_m": self.height_m,
                "transponders": [{"id": t.id, "e_m": t.e_m, "n_m": t.n_m, "u_m": t.u_m,
                                  "turnaround_s": t.turnaround_s, "sound_speed_mps": t.sound_speed_mps}
                                 for t in self.transponders]}


# --------------------------------------------------------------------------- geodesy (pymap3d)

def ecef_to_enu(xyz: np.ndarray, lat_deg: float, lon_deg: float, height_m: float) -> np.ndarray:
    """ECEF positions to local east/north/up at an origin (WGS84, pymap3d.ecef2enu).

    Parameters
    ----------
    xyz : ndarray, shape (n, 3)
        ECEF x, y, z [m].
    lat_deg, lon_deg, height_m : float
        The origin [deg, deg, m ellipsoidal].

    Returns
    -------
    ndarray, shape (n, 3)
        East, north, up [m].
    """
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    e, n, u = pymap3d.ecef2enu(xyz[:, 0], xyz[:, 1], xyz[:, 2], lat_deg, lon_deg, height_m)
    return np.column_stack([e, n, u])


def geodetic_to_enu(lat_deg, lon_deg, height_m, lat0_deg: float, lon0_deg: float, height0_m: float) -> np.ndarray:
    """Geodetic positions to local east/north/up at an origin (WGS84, pymap3d.geodetic2enu).

    Returns
    -------
    ndarray, shape (n, 3)
        East, north, up [m].
    """
    e, n, u = pymap3d.geodetic2enu(np.atleast_1d(lat_deg), np.atleast_1d(lon_deg), np.atleast_1d(height_m),
                                   lat0_deg, lon0_deg, height0_m)
    return np.column_stack([e, n, u])


def enu_rotation(lat_deg: float, lon_deg: float) -> np.ndarray:
    """The rotation R from ECEF to local ENU axes at a latitude and longitude: ``v_enu = R v_ecef``.

    Its columns are pymap3d's ECEF -> ENU vector rotation (``ecef2enuv``) of the three ECEF unit vectors.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    eye = np.eye(3)
    return np.array(pymap3d.ecef2enuv(eye[0], eye[1], eye[2], lat_deg, lon_deg), dtype=float)


# --------------------------------------------------------------------------- reading files

def _utc(date: str, clock: str, where: str) -> float:
    """POSIX seconds of a ``pxp_tt`` date and time (``27-JUL-22``, ``17:37:45.00``; years 2000-2099)."""
    d, t = _DATE.fullmatch(date), _TIME.fullmatch(clock)
    if d is None or d.group(2).upper() not in _MONTHS:
        raise ModelError(f"{where}: column 1 (date): {date[:40]!r} is not a date DD-MON-YY")
    if t is None:
        raise ModelError(f"{where}: column 2 (time): {clock[:40]!r} is not a time HH:MM:SS.ss")
    year, month, day = 2000 + int(d.group(3)), _MONTHS[d.group(2).upper()], int(d.group(1))
    hour, minute, second = int(t.group(1)), int(t.group(2)), float(t.group(3))
    if not (1 <= day <= calendar.monthrange(year, month)[1]):
        raise ModelError(f"{where}: column 1 (date): {date!r} has no day {day} in that month")
    if hour > 23 or minute > 59 or second >= 60.0:
        raise ModelError(f"{where}: column 2 (time): {clock!r} is outside 00:00:00 to 23:59:59.999999")
    return calendar.timegm((year, month, day, hour, minute, 0, 0, 0, 0)) + second


def read_pxp_tt(path: Path | str, columns: int) -> pd.DataFrame:
    """Read a ``pxp_tt`` file: per ping, the transmit time and the two-way travel times.

    Parameters
    ----------
    path : path
        The file.
    columns : int
        Travel-time columns to read (the site's transponders); further columns are not read.

    Returns
    -------
    pandas.DataFrame
        Columns ``line`` (the line number), ``t_tx_s`` (POSIX, UTC) and ``twtt_us_1`` ... ``twtt_us_N``
        [us] (0 for no reply), one row per ping, in the file's order.

    Raises
    ------
    ModelError
        Naming file, line and column: a line with too few fields, a date or time that is not one, a travel
        time not a number within [0, :data:`MAX_TWTT_US`] us; a file that is missing, not a regular file,
        too large or not text; no pings.
    """
    path = Path(path)
    what = "pxp_tt"
    rows = []
    lines = [(number, line) for number, line in enumerate(read_lines(path, what, "ascii", delimiter=" "), start=1)
             if line.strip()]
    for number, fields in csv_cells(lines, f"{what}: {str(path)!r}", " "):  # whitespace-separated, by the csv module
        where = f"{what}: {str(path)!r} line {number}"
        if len(fields) < 2 + columns:
            raise ModelError(f"{where} has {len(fields)} fields; date, time and {columns} travel times [us] needed "
                             "(a truncated file?)")
        t_tx = _utc(fields[0], fields[1], where)
        twtt = [table_number(fields[2 + k], where, f"column {3 + k} (two-way travel time [us])", 0.0, MAX_TWTT_US)
                for k in range(columns)]
        rows.append([number, t_tx, *twtt])
    if not rows:
        raise ModelError(f"{what}: {str(path)!r} holds no pings")
    return pd.DataFrame(rows, columns=["line", "t_tx_s", *[f"twtt_us_{k + 1}" for k in range(columns)]])


def read_posfilter(path: Path | str) -> pd.DataFrame:
    """Read a ``POS_FREED_TRANS_TWTT`` file: the transducer's ECEF position and covariance at each epoch.

    Returns
    -------
    pandas.DataFrame
        Columns ``line``, ``t_j2000_s`` [s since J2000], ``x_m``, ``y_m``, ``z_m`` [m] and ``c0`` ... ``c8``,
        the covariance row by row [m^2], in the file's order.

    Raises
    ------
    ModelError
        Naming file, line and column: a line without :data:`POS_FIELDS` fields, a number that is not one or
        outside its range, a covariance that is not symmetric or not positive definite (its Cholesky
        factorisation by numpy fails).
    """
    path = Path(path)
    what = "POS_FREED_TRANS_TWTT"
    names = ["time [s since J2000]", "x [m]", "y [m]", "z [m]", *[f"covariance {a}{b} [m^2]" for a in "xyz"
                                                                  for b in "xyz"]]
    ranges = [J2000_RANGE] + [(-MAX_ECEF_M, MAX_ECEF_M)] * 3 + [(-MAX_COV_M2, MAX_COV_M2)] * 9
    lines = csv_cells([(number, line) for number, line in enumerate(read_lines(path, what, "ascii", delimiter=" "),
                                                                    start=1)
                       if line.strip()], f"{what}: {str(path)!r}", " ")  # whitespace-separated, by the csv module
    if not lines:
        raise ModelError(f"{what}: {str(path)!r} holds no positions")
    low, high = np.array(ranges).T
    values = None
    if all(len(fields) == POS_FIELDS and all(NUMBER.fullmatch(f) for f in fields) for _, fields in lines):
        values = np.array([fields for _, fields in lines], dtype=float)  # every line at once (a file of 10^6 lines)
        cov = values[:, 4:].reshape(-1, 3, 3)
        diagonal = np.diagonal(cov, axis1=1, axis2=2)
        asymmetry = np.max(np.abs(cov - cov.transpose(0, 2, 1)), axis=(1, 2))
        if not (np.all(np.isfinite(values) & (values >= low) & (values <= high)) and np.all(diagonal > 0.0)
                and np.all(asymmetry <= 1e-9 + 1e-6 * np.max(np.abs(cov), axis=(1, 2)))):
            values = None
    if values is None:  # a flaw: found and named, line by line
        for number, fields in lines:
            where = f"{what}: {str(path)!r} line {number}"
            if len(fields) != POS_FIELDS:
                raise ModelError(f"{where} has {len(fields)} fields, {POS_FIELDS} expected (time, x, y, z and 9 "
                                 "covariance entries; a truncated file?)")
            one = [table_number(f, where, f"column {k + 1} ({name})", lo, hi)
                   for k, (f, name, lo, hi) in enumerate(zip(fields, names, low, high))]
            cov = np.array(one[4:]).reshape(3, 3)
            if np.any(np.diag(cov) <= 0.0):
                raise ModelError(f"{where}: the covariance's diagonal (columns 5, 9, 13) must be > 0 m^2")
            if np.max(np.abs(cov - cov.T)) > 1e-9 + 1e-6 * np.max(np.abs(cov)):
                raise ModelError(f"{where}: the covariance (columns 5-13) is not symmetric")
    frame = pd.DataFrame(values, columns=["t_j2000_s", "x_m", "y_m", "z_m", *[f"c{k}" for k in range(9)]])
    frame.insert(0, "line", np.array([number for number, _ in lines], dtype=np.int64))
    cov = frame[[f"c{k}" for k in range(9)]].to_numpy().reshape(-1, 3, 3)
    try:
        np.linalg.cholesky(0.5 * (cov + cov.transpose(0, 2, 1)))
    except np.linalg.LinAlgError:  # which line: one at a time, only now
        for line, one in zip(frame["line"], cov):
            try:
                np.linalg.cholesky(0.5 * (one + one.T))
            except np.linalg.LinAlgError:
                raise ModelError(f"{what}: {str(path)!r} line {line}: the covariance (columns 5-13) is not positive "
                                 "definite (a covariance has positive variances and correlations within ±1)") \
                    from None
    return frame


def _settings_number(table: dict, key: str, where: str, low: float, high: float) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ModelError(f"{where}.{key}: give a number in [{low:g}, {high:g}]")
    if not low <= value <= high:
        raise ModelError(f"{where}.{key}: {value:.10g} is outside the allowed range [{low:g}, {high:g}]")
    return float(value)


def read_site(path: Path | str, profile: str = "ctd:NCL1") -> Site:
    """Read a site file (TOML: ``site``, ``[origin]``, ``[settings]``, ``[[transponders]]``; see
    ``data/ncl1/site.toml``) and place the transponders in the origin's ENU frame.

    Parameters
    ----------
    path : path
        The site file.
    profile : str
        The sound-speed profile of the harmonic means (an ``acoustics.sound_speed_profile`` value).

    Returns
    -------
    Site

    Raises
    ------
    ModelError
        ``site: key: ...`` for a missing key or a value outside its range (one line), a file that is not
        TOML, columns not 1 ... N each once, ids not unique.
    """
    path = Path(path)
    what = "site"
    lines = read_lines(path, what, "ascii")
    try:
        data = tomlfile.loads("\n".join(lines))
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(f"{what}: {str(path)!r} is not valid TOML ({exc})") from None
    name = data.get("site")
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]{1,32}", name):
        raise ModelError(f"{what}.site: give the site's code, 1-32 letters, digits, '_', '.' or '-'")
    origin, settings = data.get("origin"), data.get("settings")
    if not isinstance(origin, dict) or not isinstance(settings, dict):
        raise ModelError(f"{what}: {str(path)!r} needs the tables [origin] and [settings]")
    lat0 = _settings_number(origin, "lat_deg", "site.origin", -90.0, 90.0)
    lon0 = _settings_number(origin, "lon_deg", "site.origin", -180.0, 180.0)
    h0 = _settings_number(origin, "height_m", "site.origin", -11000.0, 9000.0)
    geoid = _settings_number(settings, "geoid_undulation_m", "site.settings", -120.0, 120.0)
    start = _settings_number(settings, "harmonic_mean_start_depth_m", "site.settings", 0.0, 11000.0)
    sigma = _settings_number(settings, "gnss_sigma_limit_m", "site.settings", 1e-6, 100.0)
    distance = _settings_number(settings, "distance_limit_m", "site.settings", 0.0, 1e6)
    entries = data.get("transponders")
    if not isinstance(entries, list) or not 1 <= len(entries) <= 32 or not all(isinstance(t, dict) for t in entries):
        raise ModelError(f"{what}.transponders: give 1 to 32 [[transponders]] tables")
    n = len(entries)
    parsed = []
    for k, entry in enumerate(entries):
        where = f"site.transponders[{k}]"
        tid = entry.get("id")
        if not isinstance(tid, str) or not re.fullmatch(r"[A-Za-z0-9_.-]{1,32}", tid):
            raise ModelError(f"{where}.id: give an id of 1-32 letters, digits, '_', '.' or '-'")
        column = entry.get("column")
        if isinstance(column, bool) or not isinstance(column, int) or not 1 <= column <= n:
            raise ModelError(f"{where}.column: give the pxp_tt travel-time column, an integer in [1, {n}]")
        parsed.append((tid, column, _settings_number(entry, "lat_deg", where, -90.0, 90.0),
                       _settings_number(entry, "lon_deg", where, -180.0, 180.0),
                       _settings_number(entry, "height_m", where, -11000.0, 0.0),
                       _settings_number(entry, "turnaround_s", where, 0.0, 10.0)))
    if len({p[0] for p in parsed}) != n:
        raise ModelError(f"{what}.transponders: every id must be different")
    if sorted(p[1] for p in parsed) != list(range(1, n + 1)):
        raise ModelError(f"{what}.transponders: the columns must be 1 ... {n}, each once")
    parsed.sort(key=lambda p: p[1])
    enu = geodetic_to_enu([p[2] for p in parsed], [p[3] for p in parsed], [p[4] + geoid for p in parsed],
                          lat0, lon0, h0)
    for (tid, *_), point in zip(parsed, enu):
        _near_origin(point, f"{what}.transponders: {tid}")
    transponders = []
    for (tid, column, _lat, _lon, height, turnaround), (e, nn, u) in zip(parsed, enu):
        depth = -height
        if depth <= start:
            raise ModelError(f"site.transponders: {tid} at {depth:g} m is not below the harmonic mean's start "
                             f"depth {start:g} m")
        speed = harmonic_mean_speed(start, depth, profile)
        transponders.append(Transponder(tid, column, float(e), float(nn), float(u), depth, turnaround, speed))
    return Site(name, lat0, lon0, h0, tuple(transponders), geoid, start, sigma, distance)


def _near_origin(enu: np.ndarray, where: str) -> None:
    """Refuse a position farther from the site's origin than a survey's frame spans (the log's
    :data:`~sblsim.orchestrator.surveys.log.POSITION_RANGE` on each axis): another site's or a wrong datum's."""
    limit = POSITION_RANGE[1]
    if np.all(np.abs(enu) <= limit):
        return
    raise ModelError(f"{where}: the position is {np.linalg.norm(enu) / 1e3:.6g} km from the site's origin (East "
                     f"{enu[0]:.6g}, North {enu[1]:.6g}, Up {enu[2]:.6g} m); allowed: within {limit / 1e3:g} km on "
                     "each axis (another site's file, or another datum?)")


# --------------------------------------------------------------------------- sound speed (the model's)

@lru_cache(maxsize=1)
def _harmonic_function():
    """The model's harmonic mean (sblsim.models.acoustics.sound_speed) as a function of a padded table."""
    count, z1, z2 = ca.MX.sym("count"), ca.MX.sym("z1"), ca.MX.sym("z2")
    depth, speed = ca.MX.sym("depth", MAX_PROFILE_ROWS), ca.MX.sym("speed", MAX_PROFILE_ROWS)
    nodes, slowness = profile_nodes(count, depth, speed)
    return ca.Function("gnatss_harmonic_mean", [count, depth, speed, z1, z2],
                       [harmonic_mean(z1, z2, 0.0, count, nodes, slowness)]), MAX_PROFILE_ROWS


def harmonic_mean_speed(z1: float, z2: float, profile: str | np.ndarray = "ctd:NCL1") -> float:
    """Harmonic-mean sound speed of a profile between two depths [m/s], by sblsim's acoustics model.

    Parameters
    ----------
    z1, z2 : float
        Depths [m, positive down].
    profile : str or numpy.ndarray
        An ``acoustics.sound_speed_profile`` value (``ctd:NCL1``: the NCL1 cast, resampled to the model's
        table of at most 256 rows), or a table (rows, 2) of depth [m] and speed [m/s].

    Returns
    -------
    float
        ``(z2 − z1) / ∫ dz / c(z)`` [m/s] (sblsim.models.acoustics.sound_speed.harmonic_mean).

    Raises
    ------
    ModelError
        An unknown or unreadable profile, or a constant one (no table).
    """
    table = profile if isinstance(profile, np.ndarray) else profile_table(profile, "", 15.0, 35.0)
    if table.shape[0] == 0:
        raise ModelError(f"profile: {profile!r} has no table; give a cast such as ctd:NCL1")
    function, rows = _harmonic_function()
    depth, speed = np.zeros(rows), np.zeros(rows)
    depth[:table.shape[0]], speed[:table.shape[0]] = table[:, 0], table[:, 1]
    return float(function(table.shape[0], depth, speed, z1, z2))


# --------------------------------------------------------------------------- the log

def read_gnatss(pxp_tt: Path | str, posfilter: Path | str, site: Site | Path | str) -> tuple[pd.DataFrame, Site]:
    """Read a GNATSS survey into the calibration log: one row per reply.

    Parameters
    ----------
    pxp_tt, posfilter : path
        The ``pxp_tt`` and ``POS_FREED_TRANS_TWTT`` files.
    site : Site or path
        The site, or its file (:func:`read_site`).

    Returns
    -------
    log : pandas.DataFrame
        The columns :data:`LOG_COLUMNS`, sorted by ping and the transponders' order; ``ping`` counts the
        pings in time order from 0 (a ping with no reply keeps its number; it has no row).
    site : Site

    Raises
    ------
    ModelError
        Any flaw of a file (see :func:`read_pxp_tt`, :func:`read_posfilter`, :func:`read_site`); two pings at
        one time; two different positions at one time; a position farther than 100 km from the site's origin on
        an axis (:data:`~sblsim.orchestrator.surveys.log.POSITION_RANGE`); no position at a transmit or a
        reply's time (naming the pxp_tt line); a travel time not longer than its transponder's turnaround; no
        reply at all.
    """
    site = site if isinstance(site, Site) else read_site(site)
    pings = read_pxp_tt(pxp_tt, len(site.transponders)).sort_values("t_tx_s", kind="stable")
    repeated = pings["t_tx_s"].duplicated(keep=False)
    if repeated.any():
        lines = pings.loc[repeated, "line"].tolist()[:2]
        raise ModelError(f"pxp_tt: {str(pxp_tt)!r} lines {lines[0]} and {lines[1]} are two pings at one time")
    positions = read_posfilter(posfilter)
    # the epoch of a line in whole microseconds: pxp_tt's resolution (reply = transmit + TWTT [us])
    keys = np.round(positions["t_j2000_s"].to_numpy() * 1e6).astype(np.int64)
    values = positions[["x_m", "y_m", "z_m", *[f"c{k}" for k in range(9)]]].to_numpy()
    order = np.argsort(keys, kind="stable")
    keys, values, lines = keys[order], values[order], positions["line"].to_numpy()[order]
    same = np.flatnonzero(keys[1:] == keys[:-1])
    clash = same[np.any(values[same] != values[same + 1], axis=1)]
    if clash.size:
        k = clash[0]
        raise ModelError(f"POS_FREED_TRANS_TWTT: {str(posfilter)!r} lines {lines[k]} and {lines[k + 1]} give two "
                         "different positions at one time")
    rotation = enu_rotation(site.lat_deg, site.lon_deg)
    enu = ecef_to_enu(values[:, :3], site.lat_deg, site.lon_deg, site.height_m)
    far = np.flatnonzero(np.any(np.abs(enu) > POSITION_RANGE[1], axis=1))
    if far.size:
        _near_origin(enu[far[0]], f"POS_FREED_TRANS_TWTT: {str(posfilter)!r} line {lines[far[0]]}")
    cov = values[:, 3:].reshape(-1, 3, 3)
    cov = 0.5 * (cov + cov.transpose(0, 2, 1))
    sigma = np.sqrt(np.einsum("ij,njk,ik->ni", rotation, cov, rotation))

    def lookup(key: int, line: int, what: str) -> int:
        k = int(np.searchsorted(keys, key))
        if k >= keys.size or keys[k] != key:
            raise ModelError(f"POS_FREED_TRANS_TWTT: {str(posfilter)!r} has no position at {key / 1e6:.6f} s "
                             f"since J2000, the {what} of pxp_tt line {line} (a truncated or another day's file?)")
        return k

    rows = []
    for ping, record in enumerate(pings.itertuples(index=False)):
        t_tx = float(record.t_tx_s)
        tx_key = int(round((t_tx - J2000_POSIX) * 1e6))
        tx = lookup(tx_key, record.line, "transmission")
        for transponder in site.transponders:
            us = float(getattr(record, f"twtt_us_{transponder.column}"))
            if us == 0.0:
                continue
            twtt = us * 1e-6 - transponder.turnaround_s
            if twtt <= 0.0:
                raise ModelError(f"pxp_tt: {str(pxp_tt)!r} line {record.line}: column {2 + transponder.column} "
                                 f"(two-way travel time [us]): {us:.0f} is not longer than {transponder.id}'s "
                                 f"turnaround {transponder.turnaround_s:g} s")
            rx = lookup(tx_key + int(round(us)), record.line, f"reply of {transponder.id}")
            rows.append((ping, transponder.id, t_tx, *enu[tx], *sigma[tx], t_tx + us * 1e-6, *enu[rx], *sigma[rx],
                         twtt))
    if not rows:
        raise ModelError(f"pxp_tt: {str(pxp_tt)!r} holds no reply (every two-way travel time is 0); at least one is "
                         "needed")
    log = pd.DataFrame(rows, columns=list(LOG_COLUMNS))
    return log.astype({"ping": np.int64, "transponder": str}), site


def community_editing(log: pd.DataFrame, site: Site) -> pd.DataFrame:
    """The pings the community keeps at a site: every transponder replied, the 3-D GNSS sigma of the transmit
    and of every receive position at most ``site.gnss_sigma_limit_m`` (``sqrt(σe² + σn² + σu²)``, the
    square root of the covariance's trace), the transmit point within ``site.distance_limit_m`` of the
    origin horizontally.

    Parameters
    ----------
    log : pandas.DataFrame
        A calibration log (:data:`LOG_COLUMNS`).
    site : Site

    Returns
    -------
    pandas.DataFrame
        The rows of the pings kept, in the log's order (index reset).
    """
    tx3 = np.sqrt(log["tx_sigma_e_m"] ** 2 + log["tx_sigma_n_m"] ** 2 + log["tx_sigma_u_m"] ** 2)
    rx3 = np.sqrt(log["rx_sigma_e_m"] ** 2 + log["rx_sigma_n_m"] ** 2 + log["rx_sigma_u_m"] ** 2)
    good = (tx3 <= site.gnss_sigma_limit_m) & (rx3 <= site.gnss_sigma_limit_m) & \
        (np.hypot(log["tx_e_m"], log["tx_n_m"]) <= site.distance_limit_m)
    ids = {t.id for t in site.transponders}
    per_ping = log.assign(good=good).groupby("ping").agg(good=("good", "all"), ids=("transponder", set))
    kept = per_ping.index[per_ping["good"] & per_ping["ids"].map(lambda s: s == ids)]
    return log[log["ping"].isin(kept)].reset_index(drop=True)


def _modelled(log: pd.DataFrame, site: Site, shift: np.ndarray) -> np.ndarray:
    """The straight-ray two-way travel time of each row with the array shifted by ``shift`` [s]."""
    by_id = {t.id: t for t in site.transponders}
    x = np.array([[by_id[i].e_m, by_id[i].n_m, by_id[i].u_m] for i in log["transponder"]]) + shift
    c = np.array([by_id[i].sound_speed_mps for i in log["transponder"]])
    a = x - log[["tx_e_m", "tx_n_m", "tx_u_m"]].to_numpy()
    b = x - log[["rx_e_m", "rx_n_m", "rx_u_m"]].to_numpy()
    ra, rb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    return (ra + rb) / c


def straight_ray_residuals(log: pd.DataFrame, site: Site, shift: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Observed minus modelled two-way travel time of each row [s]: the model is the straight two-leg path
    ``|p_tx − x| + |x − p_rx|`` from the a-priori transponder position x (plus ``shift`` [m, ENU]) at the
    transponder's harmonic-mean sound speed.

    Returns
    -------
    ndarray, shape (rows,)
    """
    modelled = _modelled(log, site, np.asarray(shift, dtype=float))
    return log["twtt_s"].to_numpy() - modelled


def ncl1_paths() -> tuple[Path, Path, Path]:
    """The vendored NCL1 day-208 files: ``pxp_tt``, ``POS_FREED_TRANS_TWTT``, ``site.toml``."""
    folder = resources.files(DATA[0]).joinpath(DATA[1])
    return tuple(Path(str(folder.joinpath(name))) for name in ("pxp_tt", "POS_FREED_TRANS_TWTT", "site.toml"))


def read_ncl1() -> tuple[pd.DataFrame, Site]:
    """The built-in survey B, GNATSS's NCL1 day 208 (2022-07-27): its log (all replies) and its site."""
    return read_gnatss(*ncl1_paths())


def main(argv: Sequence[str] | None = None) -> int:
    """Write a GNATSS survey as a calibration log (CSV): ``python -m sblsim.orchestrator.surveys.gnatss``.

    Returns
    -------
    int
        0, or 2 with one line on standard error for bad input (nothing written).
    """
    parser = argparse.ArgumentParser(prog="python -m sblsim.orchestrator.surveys.gnatss",
                                     description="Read a GNATSS survey (default: NCL1 day 208) into the "
                                                 "calibration log format.")
    pxp, pos, site = ncl1_paths()
    parser.add_argument("--pxp-tt", default=pxp, type=Path, help="the pxp_tt file")
    parser.add_argument("--posfilter", default=pos, type=Path, help="the POS_FREED_TRANS_TWTT file")
    parser.add_argument("--site", default=site, type=Path, help="the site file (TOML)")
    parser.add_argument("--edit", action="store_true", help="keep only the pings of the community editing")
    parser.add_argument("--out", required=True, type=Path, help="the log to write (.csv; must not exist)")
    args = parser.parse_args(argv)
    try:
        if args.out.suffix.lower() != ".csv":
            raise ModelError(f"--out: {str(args.out)!r} must be a .csv file")
        if args.out.exists() or args.out.is_symlink():
            raise ModelError(f"--out: {str(args.out)!r} exists; choose another file")
        log, site_ = read_gnatss(args.pxp_tt, args.posfilter, args.site)
        if args.edit:
            log = community_editing(log, site_)
        write_atomic(args.out, lambda tmp: log.to_csv(tmp, index=False))
    except ModelError as exc:
        print(f"sblsim: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"sblsim: error: --out: {str(args.out)!r} cannot be written ({exc.strerror})", file=sys.stderr)
        return 2
    print(f"{len(log)} replies of {log['ping'].nunique()} pings written to {args.out}")
    return 0


__all__ = ["Site", "Transponder", "community_editing", "ecef_to_enu", "enu_rotation",
           "geodetic_to_enu", "harmonic_mean_speed", "ncl1_paths", "read_gnatss", "read_ncl1", "read_posfilter",
           "read_pxp_tt", "read_site", "straight_ray_residuals"]

if __name__ == "__main__":
    sys.exit(main())
