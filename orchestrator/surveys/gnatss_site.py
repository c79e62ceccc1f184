"""A GNATSS survey's site: the site file (a small TOML file of ours, ``data/ncl1/site.toml`` for NCL1) read into the
local frame's origin, the transponders a priori in its east/north/up frame with their turnarounds and harmonic-mean
sound speeds, and the editing limits (:func:`read_site`).

The transponders' heights are orthometric (GNATSS's ``height``): the ellipsoidal height is
``height + geoid_undulation``, as GNATSS's solver takes it.

References
----------
GNATSS, GNSS-Acoustic Seafloor Positioning Software, https://github.com/seafloor-geodesy/gnatss (BSD-3).
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sblsim.models.errors import ModelError
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.tables import read_lines
from sblsim.orchestrator.surveys.harmonic_mean import harmonic_mean_speed
from sblsim.orchestrator.surveys.local_frame import geodetic_to_enu
from sblsim.orchestrator.surveys.log import POSITION_RANGE


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


__all__ = ["Site", "Transponder", "read_site"]
