"""Read a GARPOS survey (``sblsim calibrate OBS.csv --format garpos --initcfg FILE --svp FILE``) into the
calibration log.

GARPOS (S. Watanabe, T. Ishikawa, Y. Yokota, Y. Nakamura, Front. Earth Sci. 8:597532, 2020; repository
s-watanabe-jhod/garpos, its README's table of ``obs.csv`` and ``bin/garpos_v102``) takes a survey as three files,
each named here by the user (the paths GARPOS's configuration writes, ``SoundSpeed`` and ``datacsv``, are never
followed):

the observation CSV (``*-obs.csv``)
    One row per reply, by column name: ``MT`` the transponder's id, ``TT`` the two-way travel time without the
    transponder's delay [s], ``flag`` (``True``: not used), ``ST`` and ``RT`` the transmit and receive times [s
    since 00:00 UTC of the survey's date], ``ant_e0``, ``ant_n0``, ``ant_u0`` the GNSS antenna at transmit [m,
    ENU], ``head0``, ``pitch0``, ``roll0`` the attitude at transmit [deg], the same six with ``1`` at receive;
    other columns (``SET``, ``LN``, GARPOS's results) are ignored.
the initial site-parameter file (``*-initcfg.ini``)
    ``[Obs-parameter] Date(UTC)``; ``[Site-parameter] Latitude0, Longitude0, Height0`` (the ENU frame's origin)
    and ``Stations``; ``[Model-parameter]`` each station's ``<MT>_dPos`` (East, North, Up [m], then sigmas and
    covariances not used here), ``dCentPos`` (the array centre's offset, added to every station) and
    ``ATDoffset`` (the transducer's offset from the antenna: forward, rightward, downward [m]).
the sound-speed profile (``*-svp.csv``)
    Columns ``depth`` [m] and ``speed`` [m/s], linear between rows (GARPOS's ray tracing, ``sub_raytrace.f90``).

The transducer is the antenna plus the offset turned by the attitude, :math:`R_z(\\mathrm{heading})\\,R_y(
\\mathrm{pitch})\\,R_x(\\mathrm{roll})` in North-East-Down (GARPOS's ``corr_attitude``): the platform's own
rotation (:func:`sblsim.models.calibration.boxin.lever_enu`). The log's pings are the distinct transmit times; the
replies flagged ``True`` and those of transponders that are not ``Stations`` (GARPOS's ``M00``) are left out and
counted.
GARPOS's files carry no GNSS sigma: the log takes :data:`NOMINAL_SIGMA_M`. GARPOS's surface is the frame's Up 0
and its layers flat (``solver.surface_u_m = 0``, ``earth_radius_m = 0``).
"""

from __future__ import annotations

import configparser
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.acoustics.sound_speed import fit_rows
from sblsim.models.calibration import SOUND_SPEED_RANGE
from sblsim.models.calibration.boxin import lever_enu
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.limits import MEMORY_SHARE, available_memory
from sblsim.orchestrator.io.log_tables import check_fits, columns, read_table, table_chunks, table_length
from sblsim.orchestrator.io.tables import number, read_lines
from sblsim.orchestrator.surveys.log import COLUMNS, LOG_COLUMNS, ROW_BYTES, TRANSPONDER_ID, SurveyLog, check_frame
from sblsim.orchestrator.surveys.seagap import HEADING_RANGE, NOMINAL_SIGMA_M, OFFSET_RANGE, TILT_RANGE

#: The observation CSV's columns read (by name): name -> allowed range (None: text).
OBS_COLUMNS = {"MT": None, "TT": COLUMNS["twtt_s"][2], "flag": None, "ST": (-86400.0, 864000.0),
               "RT": (-86400.0, 864000.0), **{f"ant_{a}{w}": COLUMNS["tx_e_m"][2] for w in "01" for a in "enu"},
               **{f"head{w}": HEADING_RANGE for w in "01"},
               **{f"{k}{w}": TILT_RANGE for k in ("pitch", "roll") for w in "01"}}
#: The stations a site may hold.
MAX_STATIONS = 32
_DATE = re.compile(r"\d{4}-\d{2}-\d{2}")


@dataclass
class GarposSurvey:
    """A GARPOS survey read.

    Attributes
    ----------
    log : SurveyLog
    ids : list of str
        The stations, in ``Stations``' order.
    apriori : numpy.ndarray, shape (k, 3)
        Each station's ``dPos`` plus ``dCentPos`` [m, ENU].
    profile : numpy.ndarray, shape (rows, 2)
        Depth [m], speed [m/s].
    origin : dict
        ``lat_deg``, ``lon_deg``, ``height_m``.
    name : str
        ``Site_name.Campaign``.
    offset : numpy.ndarray, shape (3,)
        The transducer from the antenna: forward, rightward, downward [m].
    left_out : dict
        Replies left out: ``flagged``, ``unknown_transponder``.
    """

    log: SurveyLog
    ids: list[str]
    apriori: np.ndarray
    profile: np.ndarray
    origin: dict
    name: str
    offset: np.ndarray
    left_out: dict = field(default_factory=dict)


def _numbers(parser: configparser.ConfigParser, section: str, key: str, count: int, where: str,
             bounds: tuple[float, float]) -> list[float]:
    if not parser.has_option(section, key):
        raise ModelError(f"{where}: [{section}] {key} is missing")
    cells = parser.get(section, key).split()
    if len(cells) < count:
        raise ModelError(f"{where}: [{section}] {key}: {len(cells)} numbers, at least {count}")
    return [number(c, f"{where}: [{section}] {key}", f"value {j + 1}", *bounds) for j, c in enumerate(cells[:count])]


def read_initcfg(path: Path | str) -> tuple[dict, list[str], np.ndarray, np.ndarray, str, float]:
    """The initial site-parameter file: origin, stations, a-priori positions, the offset, the site's name and the
    survey date's POSIX time at 00:00 UTC [s].

    Raises
    ------
    ModelError
        Not INI text, a missing section or key, a number outside its range, stations not ids or more than
        :data:`MAX_STATIONS`, a date that is not ``YYYY-MM-DD``.
    """
    path = Path(path)
    where = f"initcfg: {str(path)!r}"
    parser = configparser.ConfigParser(interpolation=None, strict=True)
    try:
        parser.read_string("\n".join(read_lines(path, "initcfg")), source=str(path))
    except configparser.Error as exc:
        raise ModelError(f"{where} is not an INI file ({' '.join(str(exc).split())[:160]})") from None
    date = parser.get("Obs-parameter", "Date(UTC)", fallback="").strip()
    if not _DATE.fullmatch(date):
        raise ModelError(f"{where}: [Obs-parameter] Date(UTC): {date[:40]!r} is not a date YYYY-MM-DD")
    try:
        midnight = datetime.strptime(date, "%Y-%m-%d").replace(tzinfo=timezone.utc).timestamp()
    except ValueError:
        raise ModelError(f"{where}: [Obs-parameter] Date(UTC): {date!r} is not a date") from None
    lat, = _numbers(parser, "Site-parameter", "Latitude0", 1, where, (-90.0, 90.0))
    lon, = _numbers(parser, "Site-parameter", "Longitude0", 1, where, (-180.0, 360.0))
    height, = _numbers(parser, "Site-parameter", "Height0", 1, where, (-11000.0, 9000.0))
    stations = parser.get("Site-parameter", "Stations", fallback="").split()
    if not 1 <= len(stations) <= MAX_STATIONS or not all(TRANSPONDER_ID.fullmatch(s) for s in stations) \
            or len(set(stations)) != len(stations):
        raise ModelError(f"{where}: [Site-parameter] Stations: give 1 to {MAX_STATIONS} different ids (letters, "
                         "digits, _, - or .)")
    bounds = COLUMNS["tx_e_m"][2]
    centre = np.array(_numbers(parser, "Model-parameter", "dCentPos", 3, where, bounds))
    apriori = np.array([_numbers(parser, "Model-parameter", f"{s}_dPos", 3, where, bounds) for s in stations]) + centre
    offset = np.array(_numbers(parser, "Model-parameter", "ATDoffset", 3, where, OFFSET_RANGE))
    name = ".".join(parser.get("Obs-parameter", k, fallback="").strip() for k in ("Site_name", "Campaign")).strip(".")
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", name)[:64] or path.stem
    return {"lat_deg": lat, "lon_deg": lon, "height_m": height}, stations, apriori, offset, name, midnight


def read_svp(path: Path | str) -> np.ndarray:
    """GARPOS's sound-speed profile: depth [m] and speed [m/s] (one longer than the model's table of 256 rows is
    resampled, :func:`~sblsim.models.acoustics.sound_speed.fit_rows`).

    Raises
    ------
    ModelError
        Not a CSV with ``depth`` and ``speed``, a number outside its range, depths not increasing.
    """
    path = Path(path)
    table = read_table(path, "svp")
    index = columns(table, "svp")
    if "depth" not in index or "speed" not in index:
        raise ModelError(f"svp: {str(path)!r} needs the columns depth and speed")
    rows = [(number(cells[index["depth"]], f"svp: {str(path)!r} {place}", "depth", 0.0, 12000.0),
             number(cells[index["speed"]], f"svp: {str(path)!r} {place}", "speed", *SOUND_SPEED_RANGE))
            for place, cells in table.rows]
    if len(rows) < 2:
        raise ModelError(f"svp: {str(path)!r} holds fewer than two rows")
    return fit_rows(np.array(rows), "svp", str(path))


def read_garpos(obs: Path | str, initcfg: Path | str, svp: Path | str) -> GarposSurvey:
    """Read a GARPOS survey (module docstring).

    Parameters
    ----------
    obs, initcfg, svp : path
        The observation CSV, the initial site-parameter file, the sound-speed profile.

    Returns
    -------
    GarposSurvey

    Raises
    ------
    ModelError
        One line naming the file, the line and the column: any flaw of a file, no reply left, or the log's
        (:func:`~sblsim.orchestrator.surveys.log.check_frame`).
    """
    origin, stations, apriori, offset, name, midnight = read_initcfg(initcfg)
    profile = read_svp(svp)
    obs = Path(obs)
    check_fits(obs, "obs", table_length(obs, "obs"), ROW_BYTES, MEMORY_SHARE * available_memory())
    parts, where, flagged, unknown = [], [], 0, 0
    known = set(stations)
    header: list[str] = []
    for table in table_chunks(obs, "obs"):  # in pieces: an observation file of any length in bounded memory
        if not header:
            header, index = table.header, columns(table, "obs")
            missing = [c for c in OBS_COLUMNS if c not in index]
            if missing:
                raise ModelError(f"obs: {str(obs)!r} lacks the column{'s' if len(missing) > 1 else ''} "
                                 f"{', '.join(missing)}")
        data = []
        for place, cells in table.rows:
            here = f"obs: {str(obs)!r} {place}"
            flag = cells[index["flag"]].strip()
            if flag not in ("True", "False"):
                raise ModelError(f"{here}: flag: {flag[:40]!r} is not True or False")
            mt = cells[index["MT"]].strip()
            if not TRANSPONDER_ID.fullmatch(mt):
                raise ModelError(f"{here}: MT: {mt[:40]!r} is not an id (1-32 letters, digits, _, - or .)")
            values = {c: number(cells[index[c]], here, c, *b) for c, b in OBS_COLUMNS.items() if b is not None}
            if flag == "True":
                flagged += 1
                continue
            if mt not in known:
                unknown += 1
                continue
            data.append({"MT": mt, **values})
            where.append(place)
        if data:
            parts.append(pd.DataFrame(data))
    if not where:
        raise ModelError(f"obs: {str(obs)!r} holds no reply of the stations {', '.join(stations)} that is not flagged")
    f = pd.concat(parts, ignore_index=True)
    del parts
    points = {}
    for w, prefix in (("0", "tx"), ("1", "rx")):
        antenna = f[[f"ant_e{w}", f"ant_n{w}", f"ant_u{w}"]].to_numpy()
        angles = np.radians(f[[f"roll{w}", f"pitch{w}", f"head{w}"]].to_numpy())
        points[prefix] = antenna + lever_enu(angles, offset)
    frame = pd.DataFrame({"ping": np.unique(f["ST"].to_numpy(), return_inverse=True)[1].astype(np.int64),
                          "transponder": f["MT"].to_numpy(), "t_tx_s": midnight + f["ST"].to_numpy(),
                          "t_rx_s": midnight + f["RT"].to_numpy(), "twtt_s": f["TT"].to_numpy()})
    for prefix, p in points.items():
        for j, axis in enumerate("enu"):
            frame[f"{prefix}_{axis}_m"] = p[:, j]
            frame[f"{prefix}_sigma_{axis}_m"] = NOMINAL_SIGMA_M
    log = check_frame(frame[list(LOG_COLUMNS)], where, str(obs))
    log.counts["ignored_columns"] = [c for c in header if c and c not in OBS_COLUMNS]
    return GarposSurvey(log, stations, apriori, profile, origin, name, offset,
                        {"flagged": flagged, "unknown_transponder": unknown})


__all__ = ["GarposSurvey", "MAX_STATIONS", "OBS_COLUMNS", "read_garpos", "read_initcfg", "read_svp"]
