"""Read a SeaGap survey folder (``sblsim calibrate FOLDER --format seagap``) into the calibration log.

SeaGap (F. Tomita and M. Kido, GNSS-Acoustic analysis in Julia, repository f-tommy/SeaGap, MIT; its
``docs/src/Dataformat``) keeps a survey in four text files of whitespace-separated numbers, found here by their
names inside the folder the user gives (a file never names another file that is read):

``obsdata.inp``
    One line per reply: the transponder's number (its line in ``pxp-ini``), the two-way travel time without the
    transponder's delay [s], the transmit time [s since 2000-01-01T12:00:00 UTC, SeaGap's ``date2sec`` default],
    the GNSS antenna's East, North, Up [m] and the platform's heading, pitch, roll [deg] at transmit, the same five
    at the reply's receive time, a shot group and (SeaGap 1.1) a platform flag, both not used here.
``pxp-ini.xyh`` (or ``pxp-ini.inp``)
    One line per transponder: its a-priori East, North, Up [m] (further columns are not used).
``tr-ant.inp``
    The transducer's offset from the GNSS antenna in the platform's frame [m]: starboard, bow, up.
``ss_prof.zv`` (or ``ss_prof.inp``)
    The sound-speed profile: depth [m], speed [m/s]; SeaGap's ray tracing takes each row's speed over the
    layer down to the next row (``traveltime.jl``).

The transducer is the antenna plus the offset turned by the attitude: SeaGap turns the offset by minus the
heading about Up, then by the pitch about the turned starboard axis, then by the roll about the turned bow axis
(``anttena2tr.jl``), which is the yaw-pitch-roll rotation of the platform
(:func:`sblsim.models.calibration.boxin.lever_enu`, :func:`sblsim.models.platform.geometry.rotation_ned`) of the
offset in the body's forward, right, down axes.
The profile's layers (a speed constant down to the next row) become the model's table of at most
:data:`~sblsim.models.acoustics.sound_speed.MAX_PROFILE_ROWS` rows, linear between them, by
:func:`stair_table`: the slowness projected on the table's evenly spaced rows in the least-squares sense
(the column's travel time kept: a vertical ray's within 0.1 microsecond over 3 km).

The log's pings are the distinct transmit times; the transponders are ``"1"``, ``"2"``, ... (SeaGap's numbers);
the antenna's positions carry no sigma in SeaGap's files, so the log takes :data:`NOMINAL_SIGMA_M` for each
(the solution's covariance is scaled by its residuals, which makes a constant immaterial).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.linalg import solve_banded

from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS
from sblsim.models.calibration import SOUND_SPEED_RANGE
from sblsim.models.calibration.boxin import lever_enu
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.tables import csv_cells, number, read_lines
from sblsim.orchestrator.surveys.gnatss_files import J2000_POSIX, J2000_RANGE
from sblsim.orchestrator.surveys.log import COLUMNS, LOG_COLUMNS, SurveyLog, check_frame

#: The files of a SeaGap folder: role -> the names it may have (one of them, not two).
FILES = {"obsdata": ("obsdata.inp",), "transponders": ("pxp-ini.xyh", "pxp-ini.inp"), "offset": ("tr-ant.inp",),
         "profile": ("ss_prof.zv", "ss_prof.inp")}
#: The fields of an ``obsdata.inp`` line, in order (a 18th, SeaGap 1.1's platform flag, is allowed and not used).
FIELDS = ("transponder", "twtt_s", "t_tx", "ant_e_tx", "ant_n_tx", "ant_u_tx", "heading_tx", "pitch_tx", "roll_tx",
          "t_rx", "ant_e_rx", "ant_n_rx", "ant_u_rx", "heading_rx", "pitch_rx", "roll_rx", "group")
#: The antenna's 1-sigma the log takes (SeaGap's files carry none) [m].
NOMINAL_SIGMA_M = 0.01
#: The transponders a folder may hold.
MAX_TRANSPONDERS = 32
#: Headings accepted [deg] (SeaGap allows a heading made continuous beyond 360) and pitch and roll [deg].
HEADING_RANGE = (-3600.0, 3600.0)
TILT_RANGE = (-90.0, 90.0)
#: The offset's components accepted [m] and the profile's depths [m].
OFFSET_RANGE = (-100.0, 100.0)
DEPTH_RANGE = (0.0, 12000.0)
_BOUNDS = {"transponder": (1, MAX_TRANSPONDERS), "twtt_s": COLUMNS["twtt_s"][2], "t_tx": J2000_RANGE,
           "t_rx": J2000_RANGE, "group": (0, 2**53), **{f"ant_{a}_{w}": COLUMNS["tx_e_m"][2] for a in "enu"
                                                        for w in ("tx", "rx")},
           **{f"heading_{w}": HEADING_RANGE for w in ("tx", "rx")},
           **{f"{k}_{w}": TILT_RANGE for k in ("pitch", "roll") for w in ("tx", "rx")}}


@dataclass
class SeagapSurvey:
    """A SeaGap folder read: the log, the transponders, the profile as the model's table.

    Attributes
    ----------
    log : SurveyLog
        One row per reply (transducer positions, ENU of SeaGap's frame [m]).
    ids : list of str
        ``"1"`` ... ``"k"``.
    apriori : numpy.ndarray, shape (k, 3)
        The transponders' a-priori East, North, Up [m].
    profile : numpy.ndarray, shape (rows, 2)
        Depth [m], speed [m/s], linear between rows (:func:`stair_table`).
    offset : numpy.ndarray, shape (3,)
        The transducer's offset from the antenna: starboard, bow, up [m].
    files : dict
        Role -> the file's name read.
    """

    log: SurveyLog
    ids: list[str]
    apriori: np.ndarray
    profile: np.ndarray
    offset: np.ndarray
    files: dict


def _file(folder: Path, role: str) -> Path:
    names = [name for name in FILES[role] if (folder / name).exists() or (folder / name).is_symlink()]
    if not names:
        raise ModelError(f"seagap: {str(folder)!r} holds no {' or '.join(FILES[role])} (the {role} file)")
    if len(names) > 1:
        raise ModelError(f"seagap: {str(folder)!r} holds both {names[0]} and {names[1]}; keep one")
    return folder / names[0]


def _rows(path: Path, what: str, width: tuple[int, int]) -> list[tuple[int, list[str]]]:
    """The non-blank, non-comment lines of a file, each as (line number, fields), with a field count in
    ``width``."""
    out = []
    lines = [(k, line) for k, line in enumerate(read_lines(path, what, "ascii", delimiter=" ", comments=True), start=1)
             if line.strip() and not line.lstrip().startswith("#")]
    for k, cells in csv_cells(lines, f"{what}: {str(path)!r}", " "):  # whitespace-separated, parsed by the csv module
        if not width[0] <= len(cells) <= width[1]:
            count = f"{width[0]}" if width[0] == width[1] else f"{width[0]} to {width[1]}"
            raise ModelError(f"{what}: {str(path)!r} line {k} has {len(cells)} fields, the format {count}")
        out.append((k, cells))
    if not out:
        raise ModelError(f"{what}: {str(path)!r} holds no data line")
    return out


def read_offset(path: Path | str) -> np.ndarray:
    """``tr-ant.inp``: the transducer's offset from the antenna, starboard, bow, up [m], shape (3,).

    Raises
    ------
    ModelError
        Not one line of three numbers within :data:`OFFSET_RANGE`.
    """
    path = Path(path)
    rows = _rows(path, "tr-ant", (3, 3))
    if len(rows) != 1:
        raise ModelError(f"tr-ant: {str(path)!r} holds {len(rows)} lines; the offset is one line of 3 numbers")
    k, cells = rows[0]
    return np.array([number(c, f"tr-ant: {str(path)!r} line {k}", name, *OFFSET_RANGE)
                     for c, name in zip(cells, ("starboard", "bow", "up"))])


def read_transponders(path: Path | str) -> np.ndarray:
    """``pxp-ini``: the transponders' a-priori East, North, Up [m], shape (k, 3), one line each (further columns
    ignored).

    Raises
    ------
    ModelError
        A line with fewer than 3 numbers or a number outside the log's position range, more than
        :data:`MAX_TRANSPONDERS` lines.
    """
    path = Path(path)
    rows = _rows(path, "pxp-ini", (3, 12))
    if len(rows) > MAX_TRANSPONDERS:
        raise ModelError(f"pxp-ini: {str(path)!r} holds {len(rows)} transponders, at most {MAX_TRANSPONDERS}")
    bounds = COLUMNS["tx_e_m"][2]
    return np.array([[number(c, f"pxp-ini: {str(path)!r} line {k}", name, *bounds)
                      for c, name in zip(cells[:3], ("east", "north", "up"))] for k, cells in rows])


def read_profile(path: Path | str) -> np.ndarray:
    """``ss_prof``: SeaGap's profile rows, depth [m] and speed [m/s], shape (rows, 2), depths increasing.

    Raises
    ------
    ModelError
        A line that is not two numbers, a depth outside :data:`DEPTH_RANGE` or not increasing, a speed outside
        :data:`~sblsim.models.calibration.SOUND_SPEED_RANGE`, fewer than two rows.
    """
    path = Path(path)
    rows = _rows(path, "ss_prof", (2, 2))
    out = []
    for k, cells in rows:
        here = f"ss_prof: {str(path)!r} line {k}"
        out.append((number(cells[0], here, "depth", *DEPTH_RANGE), number(cells[1], here, "speed",
                                                                           *SOUND_SPEED_RANGE)))
        if len(out) > 1 and out[-1][0] <= out[-2][0]:
            raise ModelError(f"{here}: depth: {out[-1][0]:g} is not deeper than the line before ({out[-2][0]:g})")
    if len(out) < 2:
        raise ModelError(f"ss_prof: {str(path)!r} holds one row; a profile needs two or more")
    return np.array(out)


def stair_table(profile: np.ndarray, rows: int = MAX_PROFILE_ROWS) -> np.ndarray:
    """SeaGap's layered profile as the model's table: the best least-squares fit of its slowness by a function
    linear between evenly spaced depths (``rows``, or the profile's own count if smaller).

    SeaGap's speed of row :math:`k` holds from its depth :math:`z_k` to the next row's; the slowness
    :math:`s(z) = 1/c_k` is piecewise constant. Its :math:`L^2` projection on the hat functions :math:`\\phi_i`
    of nodes :math:`n_i` solves :math:`M g = b` with the tridiagonal :math:`M_{ij} = \\int\\phi_i\\phi_j\\,dz` and
    :math:`b_i = \\int s\\,\\phi_i\\,dz` (exact for piecewise-constant :math:`s`), which keeps the travel time
    through the whole column; the table's speeds are :math:`1/g_i` (linear speed and linear slowness between
    rows differ to second order in the rows' spacing).

    Parameters
    ----------
    profile : numpy.ndarray, shape (m, 2)
        SeaGap's rows: depth [m, increasing], speed [m/s].
    rows : int
        The table's rows at most.

    Returns
    -------
    numpy.ndarray, shape (r, 2)
        Depth [m], speed [m/s], linear between rows (the last layer's speed below the last row).

    Source: the :math:`L^2` projection on piecewise-linear elements, e.g. G. Strang, G. Fix, *An Analysis of the
    Finite Element Method*, 1973, ch. 1.
    """
    z, c = profile[:, 0], profile[:, 1]
    rows = min(rows, len(z))
    nodes = np.linspace(z[0], z[-1], rows)
    h = np.diff(nodes)
    banded = np.zeros((3, rows))
    banded[1, :-1] += h / 3.0
    banded[1, 1:] += h / 3.0
    banded[0, 1:] = h / 6.0
    banded[2, :-1] = h / 6.0

    def antiderivative(i: int, at: np.ndarray) -> np.ndarray:
        """:math:`\\int_{-\\infty}^{at} \\phi_i`."""
        out = np.zeros_like(at)
        if i > 0:
            a, b = nodes[i - 1], nodes[i]
            u = np.clip(at, a, b) - a
            out += u * u / (2.0 * (b - a))
        if i < rows - 1:
            a, b = nodes[i], nodes[i + 1]
            u = np.clip(at, a, b) - a
            out += u - u * u / (2.0 * (b - a))
        return out

    slowness = 1.0 / c[:-1]
    load = np.array([np.sum(slowness * np.diff(antiderivative(i, z))) for i in range(rows)])
    return np.column_stack((nodes, 1.0 / solve_banded((1, 1), banded, load)))


def antenna_to_transducer(antenna: np.ndarray, heading: np.ndarray, pitch: np.ndarray, roll: np.ndarray,
                          offset: np.ndarray) -> np.ndarray:
    """The transducer's East, North, Up [m] from the antenna's and the attitude (SeaGap's convention).

    Parameters
    ----------
    antenna : numpy.ndarray, shape (n, 3)
        The antenna, ENU [m].
    heading, pitch, roll : numpy.ndarray, shape (n,)
        Heading clockwise from North, pitch bow up, roll starboard down [deg].
    offset : numpy.ndarray, shape (3,)
        Starboard, bow, up [m] (``tr-ant.inp``).

    Returns
    -------
    numpy.ndarray, shape (n, 3)
    """
    angles = np.radians(np.column_stack((roll, pitch, heading)))
    body = np.array([offset[1], offset[0], -offset[2]])  # forward, right, down
    return antenna + lever_enu(angles, body)


def read_obsdata(path: Path | str, count: int) -> pd.DataFrame:
    """``obsdata.inp`` as a table of :data:`FIELDS` (numbers checked, transponders in 1 ... ``count``).

    Raises
    ------
    ModelError
        Naming the line and the field: a line without 17 or 18 fields, a field that is not a number or outside
        its range, a transponder number that is not a whole number of ``pxp-ini``.
    """
    path = Path(path)
    data = []
    for k, cells in _rows(path, "obsdata", (17, 18)):
        here = f"obsdata: {str(path)!r} line {k}"
        values = [number(text, here, name, *_BOUNDS[name]) for name, text in zip(FIELDS, cells)]
        if values[0] != int(values[0]) or values[0] > count:
            raise ModelError(f"{here}: transponder: {cells[0][:40]!r} is not a transponder of pxp-ini (1 to "
                             f"{count})")
        data.append(values + [k])
    return pd.DataFrame(data, columns=[*FIELDS, "line"])


def read_seagap(folder: Path | str) -> SeagapSurvey:
    """Read a SeaGap folder (module docstring) into the calibration log.

    Parameters
    ----------
    folder : path
        The folder holding ``obsdata.inp``, ``pxp-ini``, ``tr-ant.inp`` and ``ss_prof``.

    Returns
    -------
    SeagapSurvey

    Raises
    ------
    ModelError
        One line naming the file, the line and the field: a missing folder or file, two files of one role, any
        flaw of a file (:func:`read_obsdata`, :func:`read_transponders`, :func:`read_offset`,
        :func:`read_profile`), or of the log (:func:`~sblsim.orchestrator.surveys.log.check_frame`).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ModelError(f"seagap: {str(folder)[:200]!r} is not a folder; give the folder holding obsdata.inp, "
                         "pxp-ini, tr-ant.inp and ss_prof")
    paths = {role: _file(folder, role) for role in FILES}
    apriori = read_transponders(paths["transponders"])
    offset = read_offset(paths["offset"])
    raw = read_profile(paths["profile"])
    obs = read_obsdata(paths["obsdata"], len(apriori))
    tx = antenna_to_transducer(obs[["ant_e_tx", "ant_n_tx", "ant_u_tx"]].to_numpy(), obs["heading_tx"].to_numpy(),
                               obs["pitch_tx"].to_numpy(), obs["roll_tx"].to_numpy(), offset)
    rx = antenna_to_transducer(obs[["ant_e_rx", "ant_n_rx", "ant_u_rx"]].to_numpy(), obs["heading_rx"].to_numpy(),
                               obs["pitch_rx"].to_numpy(), obs["roll_rx"].to_numpy(), offset)
    ids = [str(k + 1) for k in range(len(apriori))]
    frame = pd.DataFrame({"ping": np.unique(obs["t_tx"].to_numpy(), return_inverse=True)[1].astype(np.int64),
                          "transponder": obs["transponder"].astype(int).astype(str),
                          "t_tx_s": obs["t_tx"].to_numpy() + J2000_POSIX,
                          "t_rx_s": obs["t_rx"].to_numpy() + J2000_POSIX,
                          "twtt_s": obs["twtt_s"].to_numpy()})
    for prefix, points in (("tx", tx), ("rx", rx)):
        for j, axis in enumerate("enu"):
            frame[f"{prefix}_{axis}_m"] = points[:, j]
            frame[f"{prefix}_sigma_{axis}_m"] = NOMINAL_SIGMA_M
    log = check_frame(frame[list(LOG_COLUMNS)], [f"line {k}" for k in obs["line"]], str(paths["obsdata"]))
    log.counts["ignored_columns"] = []
    return SeagapSurvey(log, ids, apriori, stair_table(raw), offset, {k: p.name for k, p in paths.items()})


__all__ = ["FIELDS", "FILES", "NOMINAL_SIGMA_M", "SeagapSurvey", "antenna_to_transducer", "read_obsdata",
           "read_offset", "read_profile", "read_seagap", "read_transponders", "stair_table"]
