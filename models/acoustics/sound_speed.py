"""Sound-speed profiles and the effective sound speed of a straight acoustic path.

Along a straight ray between depths z1 and z2 (ray bending is negligible over
the tens of metres of an SBL system) the travel time is
``τ = (ρ / |z2 - z1|) ∫ dz / c(z)``: the range ρ over the harmonic mean of
c(z) between the two depths. The model holds the profile as a table of
depths and speeds (at most :data:`MAX_PROFILE_ROWS` rows; an empty table is
the constant ``sound_speed_true``), extends it to the surface and far below
with its end speeds, integrates the slowness ``S(z) = ∫ dz / c`` at the
table's depths by the trapezoid rule, and interpolates S linearly between
them (:func:`harmonic_mean`, a casadi expression).

The configuration's ``acoustics.sound_speed_profile`` chooses where the table
comes from (:func:`profile_table`): ``constant``, ``teos10`` (uniform water
of the given temperature and salinity through TEOS-10), ``ctd:NAME`` (a real
cast shipped with sblsim), ``table`` (``acoustics.sound_speed_table`` as
text), or a path to a CSV cast.

References
----------
Jensen, Kuperman, Porter, Schmidt, Computational Ocean Acoustics, 2nd ed.,
Springer 2011, ch. 3 (ray travel time). IOC, SCOR, IAPSO, The international
thermodynamic equation of seawater - 2010 (TEOS-10), via the ``gsw`` package.
"""

from __future__ import annotations

import csv
import os
import stat
from functools import lru_cache
from importlib import resources
from pathlib import Path

import casadi as ca
import gsw
import numpy as np

from sblsim.models.declarations import Column, FileKey, ModelError, Table
from sblsim.models.expressions import cumulative_sum, padded_rows, switch
from sblsim.models.table_text import check_entry, check_increasing, parse_table

#: Real CTD casts shipped with sblsim (see models/acoustics/data/README.md): the two coastal Castaway casts
#: (CSV files of that name) and ``NCL1``, the 1220 m deep cast of GNATSS's NCL1 test site (its file
#: ``CTD_NCL1_Ch_Mi`` as published: elevation [m, negative down] and sound speed [m/s] per line).
BUILTIN_CASTS = ("11E101663_20120821_122817", "11E101663_20120821_145912", "NCL1")
_CAST_FILES = {"NCL1": "CTD_NCL1_Ch_Mi"}
#: The Munk canonical profile (Munk 1974; Jensen et al. 2011): axis depth [m], scale depth B [m],
#: axis speed [m/s], ε, and the table that samples it (rows, deepest depth [m]).
MUNK_AXIS, MUNK_SCALE, MUNK_SPEED, MUNK_EPSILON = 1300.0, 1300.0, 1500.0, 0.00737
MUNK_ROWS, MUNK_DEPTH = 256, 5000.0
#: The missing-value mark of a GNATSS sound-speed file [m/s].
MISSING_SPEED = -9.99e-29
#: Largest number of rows of a sound-speed table.
MAX_PROFILE_ROWS = 256
#: The largest CSV cast read [bytes] (checked before it is opened) and the most data rows (counted while it is
#: read, before anything is kept beyond them): a 24 Hz CTD lowered 5 km at 1 m/s records some 120,000 rows. A
#: cast within both is read in about a second and some 100 MB and resampled to :data:`MAX_PROFILE_ROWS` rows
#: (:func:`fit_rows`); a larger one is refused in one line.
MAX_CAST_BYTES = 16 * 2**20
MAX_CAST_ROWS = 200_000
#: How far above the first and below the last depth the end speeds are extended [m].
EXTENSION = 1e4
PROFILE = Table(
    columns=(Column("sound_speed_depth", "m", "Sound-speed table depth", 0.0, 11000.0),
             Column("sound_speed", "m/s", "Sound-speed table speed", 1300.0, 1700.0)),
    max_rows=MAX_PROFILE_ROWS, increasing=True)
#: Sizes of the padded profile the model derives: depths, speeds and cumulative slowness at each node.
NODES = MAX_PROFILE_ROWS + 2


def profile_nodes(count, depth, speed) -> tuple[ca.MX, ca.MX]:
    """The padded profile: nodes at the table's depths, extended above and below, and the slowness integral.

    Nodes: ``z_1 − 10 km``, the table's depths, ``z_n + 10 km``, then one
    metre apart (padding, never reached); the speeds outside the table are
    its end speeds. ``S(z) = ∫_{z_1}^{z} dz / c`` at each node by the
    trapezoid rule, counted from the first depth of the table, so that S
    stays small near the table and a difference ``S(z2) − S(z1)`` keeps its
    precision for nearly level paths.

    Parameters
    ----------
    count : casadi.MX
        Rows in use, n ≥ 1 (0 gives a finite, unused profile).
    depth, speed : casadi.MX, shape (MAX_PROFILE_ROWS, 1)
        The table columns [m, m/s] (rows beyond n ignored).

    Returns
    -------
    nodes, slowness : casadi.MX, each (NODES, 1)
        Depth [m] and ``S`` [s/m · m] at each node.
    """
    nodes, speeds = node_speeds(count, depth, speed)
    steps = 0.5 * (1.0 / speeds[1:] + 1.0 / speeds[:-1]) * (nodes[1:] - nodes[:-1])
    slowness = ca.vertcat(0.0, cumulative_sum(steps))
    return nodes, slowness - slowness[1]


def node_speeds(count, depth, speed) -> tuple[ca.MX, ca.MX]:
    """The padded profile's nodes and the speed at each: the table's rows, its end speeds 10 km beyond.

    Parameters
    ----------
    count : casadi.MX
        Rows in use, n ≥ 1 (0 gives a finite, unused profile).
    depth, speed : casadi.MX, shape (MAX_PROFILE_ROWS, 1)
        The table columns [m, m/s] (rows beyond n ignored).

    Returns
    -------
    nodes, speeds : casadi.MX, each (NODES, 1)
        Depth [m] and speed [m/s] at each node (see :func:`profile_nodes`; speeds floored at 1 m/s).
    """
    (pad_depth, pad_speed), (last_depth, last_speed) = padded_rows(count, [depth, speed], EXTENSION)
    final = ca.if_else(count >= MAX_PROFILE_ROWS, last_depth + EXTENSION, pad_depth[MAX_PROFILE_ROWS - 1] + 1.0)
    nodes = ca.vertcat(depth[0] - EXTENSION, pad_depth, final)
    # an empty table (speeds 0) stays finite; it is not used
    speeds = ca.fmax(ca.vertcat(speed[0], pad_speed, last_speed), 1.0)
    return nodes, speeds


def harmonic_mean(z1, z2, constant, count, nodes, slowness) -> ca.SX:
    """Harmonic-mean sound speed between depths ``z1`` and ``z2`` [m/s].

    Parameters
    ----------
    z1, z2 : casadi.SX
        End depths of the path [m].
    constant : casadi.SX
        The sound speed when the table is empty [m/s].
    count : casadi.SX
        Rows of the table in use.
    nodes, slowness : casadi.SX, shape (NODES, 1)
        Node depths [m] and the slowness integral at them (:func:`profile_nodes`).

    Returns
    -------
    casadi.SX
        ``(z2 − z1) / (S(z2) − S(z1))`` with S interpolated linearly between
        the nodes; where the path is level (|z2 − z1| < 1 nm) its limit,
        ``1 / S'`` at the mid depth; the constant for an empty table.
    """
    return _harmonic_mean()(count > 0, z1, z2, constant, nodes, slowness)


@lru_cache(maxsize=1)
def _harmonic_mean() -> ca.Function:
    """``(use_table, z1, z2, constant, nodes, slowness) -> speed``: the table's harmonic mean or the constant,
    only the one in use evaluated (a constant profile costs no table lookup)."""
    level_speed, f = _profile_functions()
    z1, z2, constant = ca.SX.sym("z1"), ca.SX.sym("z2"), ca.SX.sym("constant")
    nodes, slowness = ca.SX.sym("nodes", NODES), ca.SX.sym("slowness", NODES)
    dz = z2 - z1
    level = ca.fabs(dz) < 1e-9
    slanted = dz / ca.if_else(level, 1.0, f(z2, nodes, slowness) - f(z1, nodes, slowness))
    table = ca.if_else(level, level_speed(0.5 * (z1 + z2), nodes, slowness), slanted)
    args, names = [z1, z2, constant, nodes, slowness], ["z1", "z2", "constant", "nodes", "slowness"]
    return switch("sblsim_harmonic_mean", [ca.Function("sblsim_harmonic_constant", args, [constant], names, ["c"]),
                                           ca.Function("sblsim_harmonic_table", args, [table], names, ["c"])])


@lru_cache(maxsize=1)
def _profile_functions() -> tuple[ca.Function, ca.Function]:
    """The slowness interpolant S(z) and the speed 1 / S'(z) of a level path."""
    f = ca.interpolant("sblsim_slowness", "linear", [NODES], 1)
    z, nodes, slowness = ca.SX.sym("z"), ca.SX.sym("nodes", NODES), ca.SX.sym("slowness", NODES)
    speed = 1.0 / ca.jacobian(f(z, nodes, slowness), z)
    return ca.Function("sblsim_level_speed", [z, nodes, slowness], [speed]), f


def read_cast_csv(path: str | Path, field: str = "acoustics.sound_speed_profile",
                  allowed: str = "constant, teos10, table, ctd:NAME or a CSV path") -> np.ndarray:
    """Read a sound-speed cast: a Castaway CTD processed file or a plain CSV ``depth, sound_speed``.

    Lines starting with ``%`` or ``#`` are comments. The first other line
    is the header: the depth column is the one whose name starts with
    ``depth``; the speed column is the one whose name contains ``sound``
    or ``velocity``. Every cell of those columns must be a finite number
    inside the table's ranges; the depths must not decrease down the file
    (one downcast; a row above the one before it is refused, not sorted);
    repeated depths are averaged. A file larger than :data:`MAX_CAST_BYTES`
    or with more than :data:`MAX_CAST_ROWS` data rows is refused before it
    is read whole.

    Returns
    -------
    ndarray, shape (rows, 2)
        Depth [m], sound speed [m/s], depths strictly increasing.

    Raises
    ------
    ModelError
        If the file is missing, a directory or not a regular file, too large,
        has no such columns, a cell is not a valid number or a depth is above
        the one before it (naming the line and column).
    """
    path = Path(path)
    try:
        info = os.stat(path)
    except OSError:
        raise ModelError(f"{field}: no such file {str(path)!r}; use {allowed}") from None
    if stat.S_ISDIR(info.st_mode):
        raise ModelError(f"{field}: {str(path)!r} is a directory, not a CSV file")
    if not stat.S_ISREG(info.st_mode):  # a pipe would block the reader
        raise ModelError(f"{field}: {str(path)!r} is not a regular file (a pipe, a device or a socket); give a CSV "
                         "file")
    if info.st_size > MAX_CAST_BYTES:
        raise ModelError(f"{field}: {str(path)!r} is {info.st_size / 2**20:.0f} MiB; a cast is at most "
                         f"{MAX_CAST_BYTES // 2**20} MiB and {MAX_CAST_ROWS:,} rows (decimate it: sblsim resamples "
                         f"it to {MAX_PROFILE_ROWS} rows anyway)")
    lines = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            for i, row in enumerate(csv.reader(handle), start=1):
                if row and not row[0].lstrip().startswith(("%", "#")) and any(c.strip() for c in row):
                    lines.append((i, row))
                    if len(lines) > MAX_CAST_ROWS + 1:  # the header and the rows allowed
                        raise ModelError(f"{field}: {str(path)!r} has more than {MAX_CAST_ROWS:,} rows; a cast is "
                                         f"at most {MAX_CAST_BYTES // 2**20} MiB and {MAX_CAST_ROWS:,} rows "
                                         f"(decimate it: sblsim resamples it to {MAX_PROFILE_ROWS} rows anyway)")
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ModelError(f"{field}: cannot read {str(path)!r} ({exc.__class__.__name__})") from None
    if not lines:
        raise ModelError(f"{field}: {str(path)!r} holds no header and no data")
    header = [c.strip().lower() for c in lines[0][1]]
    depth_col = next((k for k, c in enumerate(header) if c.startswith("depth")), None)
    speed_col = next((k for k, c in enumerate(header) if "sound" in c or "velocity" in c), None)
    if depth_col is None or speed_col is None:
        raise ModelError(f"{field}: {str(path)!r} needs a header line naming a depth column and a sound-speed "
                         "column (e.g. 'depth,sound_speed')")
    data = lines[1:]
    if not data:
        raise ModelError(f"{field}: {str(path)!r} holds no data rows")
    columns = ((depth_col, PROFILE.columns[0]), (speed_col, PROFILE.columns[1]))
    cells = [[row[k].strip() if k < len(row) else "" for _, row in data] for k, _ in columns]
    try:  # every cell at once; a bad one is found and named below
        values = np.array(cells, dtype=float)
        good = all(np.all(np.isfinite(v) & (v >= col.min) & (v <= col.max)) for v, (_, col) in zip(values, columns))
    except ValueError:
        good = False
    if not good:
        for n, (i, _) in enumerate(data):
            for (k, col), column in zip(columns, cells):
                where = f"{field}: {str(path)!r} line {i}, column {lines[0][1][k].strip()!r}"
                try:
                    number = float(column[n])
                except ValueError:
                    raise ModelError(f"{where}: {column[n]!r} is not a number") from None
                check_entry(number, col, where)
    depth, speed = values
    up = np.flatnonzero(np.diff(depth) < 0.0)
    if up.size:
        k = int(up[0])
        raise ModelError(f"{field}: {str(path)!r} line {data[k + 1][0]}, column {lines[0][1][depth_col].strip()!r}: "
                         f"depth {depth[k + 1]:g} m is above line {data[k][0]}'s {depth[k]:g} m; a cast's depths must "
                         "not decrease (one downcast, from the surface down)")
    depths, first, counts = np.unique(depth, return_index=True, return_counts=True)
    speeds = speed[first]
    for g in np.flatnonzero(counts > 1):  # repeated depths (adjacent: the depths do not decrease) averaged
        speeds[g] = np.mean(speed[first[g]:first[g] + counts[g]])
    table = np.column_stack([depths, speeds])
    return fit_rows(table, field, str(path))


def fit_rows(table: np.ndarray, field: str, what: str) -> np.ndarray:
    """A profile within :data:`MAX_PROFILE_ROWS` rows: a longer one is resampled linearly on evenly spaced depths.

    Raises
    ------
    ModelError
        If depths are not strictly increasing.
    """
    check_increasing(table, PROFILE, f"{field}: {what}")
    if table.shape[0] <= MAX_PROFILE_ROWS:
        return table
    depths = np.linspace(table[0, 0], table[-1, 0], MAX_PROFILE_ROWS)
    return np.column_stack([depths, np.interp(depths, table[:, 0], table[:, 1])])


def teos10_table(temperature: float, salinity: float, max_depth: float = 100.0,
                 latitude: float = 43.0) -> np.ndarray:
    """Sound-speed table of a uniform water column from TEOS-10 (``gsw``).

    Parameters
    ----------
    temperature : float
        In-situ temperature [degC].
    salinity : float
        Practical salinity [g/kg] (PSS-78, taken as absolute salinity).
    max_depth : float
        Deepest depth of the table [m].
    latitude : float
        Latitude for the depth-to-pressure conversion [deg].

    Returns
    -------
    ndarray, shape (101, 2)
        Depth [m], sound speed [m/s].
    """
    depth = np.linspace(0.0, max_depth, 101)
    pressure = gsw.p_from_z(-depth, latitude)
    conservative = gsw.CT_from_t(salinity, temperature, pressure)
    return np.column_stack([depth, gsw.sound_speed(salinity, conservative, pressure)])


def temperature_from_speed(depth: np.ndarray, speed: np.ndarray, salinity: float,
                           latitude: float = 43.0) -> np.ndarray:
    """In-situ temperature of a cast that gives only its sound speed: TEOS-10's sound speed (``gsw``) solved
    for the temperature at each depth, at the salinity ``salinity`` (Newton's iteration on the conservative
    temperature, derivative by central differences; 8 steps reach 1e-9 °C).

    Parameters
    ----------
    depth, speed : ndarray, shape (n,)
        Depth [m] and sound speed [m/s] of the cast.
    salinity : float
        Salinity of the water [g/kg] (taken as absolute salinity).
    latitude : float
        Latitude of the depth-to-pressure conversion [deg].

    Returns
    -------
    ndarray, shape (n,)
        In-situ temperature [°C] (clipped to TEOS-10's range, −2 to 40 °C).

    References
    ----------
    IOC, SCOR, IAPSO, The international thermodynamic equation of seawater – 2010 (TEOS-10), 2010; McDougall,
    Barker, Getting started with TEOS-10 and the Gibbs Seawater (GSW) Oceanographic Toolbox, 2011.
    """
    depth, speed = np.asarray(depth, dtype=float), np.asarray(speed, dtype=float)
    pressure = gsw.p_from_z(-np.maximum(depth, 0.0), latitude)
    conservative = np.full(depth.shape, 10.0)
    for _ in range(8):
        slope = (gsw.sound_speed(salinity, conservative + 0.01, pressure)
                 - gsw.sound_speed(salinity, conservative - 0.01, pressure)) / 0.02
        conservative = np.clip(conservative - (gsw.sound_speed(salinity, conservative, pressure) - speed) / slope,
                               -2.0, 40.0)
    return np.clip(gsw.t_from_CT(salinity, conservative, pressure), -2.0, 40.0)


PROFILE_SOURCES = ("constant", "teos10", "table", "munk")
#: ``acoustics.sound_speed_profile`` names a CSV cast unless it is one of :data:`PROFILE_SOURCES` or ``ctd:NAME``.
PROFILE_FILE = FileKey(names=("", *PROFILE_SOURCES), name_prefixes=("ctd:",))


def munk_speed(z):
    """The Munk canonical profile ``c(z) = c_1 [1 + ε (η − 1 + e^(−η))]``, ``η = 2 (z − z_1) / B`` [m/s].

    Parameters
    ----------
    z : array_like
        Depth [m].

    References
    ----------
    W. H. Munk, "Sound channel in an exponentially stratified ocean, with application to SOFAR",
    J. Acoust. Soc. Am. 55(2), 220-226, 1974; Jensen, Kuperman, Porter, Schmidt, Computational Ocean
    Acoustics, 2nd ed., 2011, sec. 1.6.2 and the Munk test cases of ch. 3 (z_1 = 1300 m, B = 1300 m,
    c_1 = 1500 m/s, ε = 0.00737).
    """
    eta = 2.0 * (np.asarray(z, dtype=float) - MUNK_AXIS) / MUNK_SCALE
    return MUNK_SPEED * (1.0 + MUNK_EPSILON * (eta - 1.0 + np.exp(-eta)))


def munk_table() -> np.ndarray:
    """The Munk profile sampled into the table: :data:`MUNK_ROWS` evenly spaced depths from 0 to
    :data:`MUNK_DEPTH` (19.6 m apart), the speed linear between them.

    Returns
    -------
    ndarray, shape (MUNK_ROWS, 2)
        Depth [m], sound speed [m/s].
    """
    depth = np.linspace(0.0, MUNK_DEPTH, MUNK_ROWS)
    return np.column_stack([depth, munk_speed(depth)])


def read_gnatss_ctd(path: str | Path, field: str = "acoustics.sound_speed_profile") -> np.ndarray:
    """Read a GNATSS sound-speed file: per line, elevation [m] (negative below the surface) and speed [m/s].

    A line whose speed is the file's missing-value mark :data:`MISSING_SPEED` is left out (the NCL1 cast
    has one, at 1201.59 m).

    Returns
    -------
    ndarray, shape (rows, 2)
        Depth [m], sound speed [m/s] (at most :data:`MAX_PROFILE_ROWS` rows: a longer cast is resampled by
        :func:`fit_rows`).

    Raises
    ------
    ModelError
        If a line does not hold two finite numbers inside the table's ranges.
    """
    try:
        data = np.loadtxt(path, dtype=float, ndmin=2)
    except (OSError, ValueError) as exc:
        raise ModelError(f"{field}: cannot read {str(path)!r} ({exc.__class__.__name__})") from None
    if data.shape[1] != 2 or data.shape[0] == 0:
        raise ModelError(f"{field}: {str(path)!r} needs lines 'elevation speed'")
    data = data[data[:, 1] != MISSING_SPEED]  # samples the cast marks missing
    table = np.column_stack([-data[:, 0], data[:, 1]])
    table = table[::-1] if table.shape[0] > 1 and table[0, 0] > table[-1, 0] else table
    for i, row in enumerate(table):
        for value, col in zip(row, PROFILE.columns):
            check_entry(float(value), col, f"{field}: {str(path)!r} row {i + 1}")
    return fit_rows(table, field, str(path))


def profile_table(spec: str, text: str, temperature: float, salinity: float,
                  field: str = "acoustics.sound_speed_profile",
                  table_field: str = "acoustics.sound_speed_table", allowed: str | None = None) -> np.ndarray:
    """The sound-speed table of an ``acoustics.sound_speed_profile`` setting (read once per file version).

    See :func:`_profile_table` for the parameters; ``field`` and ``table_field`` are the keys an error names
    (``receiver.sound_speed_profile`` and ``receiver.sound_speed_table`` for a receiver's own profile) and
    ``allowed`` what the error of a missing file lists (default the channel's sources).
    """
    stamp = None
    if PROFILE_FILE.path(spec) and Path(spec).is_file():
        info = Path(spec).stat()
        stamp = (info.st_size, info.st_mtime_ns)
    return _profile_table(spec, text, float(temperature), float(salinity), stamp, field, table_field,
                          allowed).copy()


@lru_cache(maxsize=64)
def _profile_table(spec: str, text: str, temperature: float, salinity: float, stamp,
                   field: str = "acoustics.sound_speed_profile",
                   table_field: str = "acoustics.sound_speed_table", allowed: str | None = None) -> np.ndarray:
    """The sound-speed table of an ``acoustics.sound_speed_profile`` setting.

    Parameters
    ----------
    spec : str
        ``constant`` (0 rows: the constant true speed), ``teos10``, ``munk`` (:func:`munk_table`),
        ``table`` (the text ``text``), ``ctd:NAME`` (:data:`BUILTIN_CASTS`)
        or a path to a CSV cast.
    text : str
        ``acoustics.sound_speed_table``: rows ``depth speed; ...`` [m, m/s].
    temperature, salinity : float
        Water properties for ``teos10`` [degC, g/kg].

    Returns
    -------
    ndarray, shape (rows, 2)

    Raises
    ------
    ModelError
        On an unknown built-in cast, an unreadable or malformed file or text.
    """
    if spec in ("", "constant"):
        return np.zeros((0, 2))
    if spec == "teos10":
        return teos10_table(temperature, salinity)
    if spec == "munk":
        return munk_table()
    if spec == "table":
        rows = parse_table(text, PROFILE, table_field)
        if rows.shape[0] == 0:
            raise ModelError(f"{table_field}: sound_speed_profile = table needs rows 'depth speed; ...'")
        return rows
    if spec.startswith("ctd:"):
        name = spec[4:]
        if name not in BUILTIN_CASTS:
            raise ModelError(f"{field}: unknown cast {name!r}; one of " + ", ".join(f"ctd:{c}" for c in BUILTIN_CASTS))
        if name in _CAST_FILES:
            with resources.as_file(resources.files("sblsim.models.acoustics") / "data" / _CAST_FILES[name]) as path:
                return read_gnatss_ctd(path, field)
        with resources.as_file(resources.files("sblsim.models.acoustics") / "data" / f"{name}.csv") as path:
            return read_cast_csv(path, field)
    return read_cast_csv(spec, field) if allowed is None else read_cast_csv(spec, field, allowed)


__all__ = ["BUILTIN_CASTS", "harmonic_mean", "MAX_CAST_BYTES", "MAX_CAST_ROWS", "MAX_PROFILE_ROWS", "munk_speed",
           "munk_table", "node_speeds", "NODES", "PROFILE", "profile_nodes", "PROFILE_FILE", "PROFILE_SOURCES",
           "profile_table", "read_cast_csv", "read_gnatss_ctd", "temperature_from_speed", "teos10_table"]
