"""Reference trajectories of the diver (target), exact in continuous time (casadi expressions).

Every trajectory gives the position [m] and velocity [m/s] at any time t, so
the target does not depend on the communication step. Scenario geometry
(sblsim's choice, after the paper's scenarios): the semicircle and the spiral
are centred on the SBL cross; the diver swims at constant speed and holds
position once a finite path ends.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 5
(scenarios 1-3 and the harbour validation).
"""

from __future__ import annotations

import csv
import math
import re
from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np

from sblsim.models.declarations import ModelError, Table
from sblsim.models.table_text import check_entry, check_increasing

#: Simulated duration of the open-ended trajectories (spiral, random) [s].
OPEN_DURATION = 100.0
#: Newton iterations of the spiral's arc-length inversion (quadratic convergence from the asymptotic start).
SPIRAL_ITERATIONS = 8
#: The longest line of a trajectory file [characters] (four numbers and a comment fit many times over): a longer one
#: is refused before the csv module splits it into cells (a line of commas is a cell a character; the memory of its
#: cells, not the file's size, is what a hostile file inflates), and read no further than this.
MAX_LINE_CHARS = 4096
#: The most characters a trajectory file's lines hold [characters] (a row whose quoted cell spans lines gathers the
#: cells of all of them: bounded by the whole).
MAX_FILE_CHARS = 16 * 2**20


def semicircle(t, radius, speed, depth) -> tuple[ca.SX, ca.SX]:
    """Half circle of radius r around the origin, from (0, -r) through (r, 0) to (0, r), then holding.

    Returns position [m] and velocity [m/s], each (3, 1).
    """
    duration = math.pi * radius / speed
    theta = -0.5 * math.pi + speed * ca.fmin(t, duration) / radius
    moving = ca.if_else(t < duration, speed, 0.0)
    pos = ca.vertcat(radius * ca.cos(theta), radius * ca.sin(theta), depth)
    vel = ca.vertcat(-moving * ca.sin(theta), moving * ca.cos(theta), 0.0)
    return pos, vel


def spiral_arc(rho, k):
    """Arc length of the spiral ρ = ρ0 + kθ from the centre to radius ρ,
    ``(k/2)[u √(1+u²) + asinh u]`` with u = ρ/k [m]."""
    u = rho / k
    return 0.5 * k * (u * ca.sqrt(1.0 + u * u) + ca.asinh(u))


def spiral(t, start_radius, pitch, speed, depth) -> tuple[ca.SX, ca.SX]:
    """Archimedean spiral ``ρ = ρ0 + k θ`` (k = pitch / 2π), swum at constant speed from θ = 0.

    The radius reached after the arc length ``s = v t`` solves
    ``arc(ρ) − arc(ρ0) = s`` by Newton's method (``d arc / dρ = sqrt(1 + (ρ/k)²)``)
    from the large-radius solution ``ρ = sqrt(ρ0² + 2 k s)``.

    Returns position [m] and velocity [m/s], each (3, 1).
    """
    k = pitch / (2.0 * math.pi)
    target = spiral_arc(start_radius, k) + speed * t
    rho = ca.sqrt(start_radius * start_radius + 2.0 * k * speed * t)
    for _ in range(SPIRAL_ITERATIONS):
        rho = rho - (spiral_arc(rho, k) - target) / ca.sqrt(1.0 + (rho / k) ** 2)
    theta = (rho - start_radius) / k
    c, s = ca.cos(theta), ca.sin(theta)
    tx, ty = k * c - rho * s, k * s + rho * c
    scale = speed / ca.sqrt(tx * tx + ty * ty)
    return ca.vertcat(rho * c, rho * s, depth), ca.vertcat(scale * tx, scale * ty, 0.0)


def waypoint_interpolant(max_rows: int) -> ca.Function:
    """Parametric piecewise-linear interpolant ``(t, times[max_rows], points[3·max_rows]) -> (N, E, D)``."""
    return ca.interpolant("sblsim_waypoints", "linear", [max_rows], 3)


def waypoints(t, times, points, first, last) -> tuple[ca.SX, ca.SX]:
    """Piecewise-linear path through timed waypoints; before the first and after the last it holds.

    Parameters
    ----------
    t : casadi.SX
        Time [s].
    times : casadi.SX, shape (n, 1)
        Strictly increasing waypoint times [s] (padded beyond ``last``).
    points : casadi.SX, shape (3 n, 1)
        Waypoints (N, E, D) row after row [m].
    first, last : casadi.SX
        Times of the first and last waypoint in use [s].

    Returns
    -------
    position, velocity : casadi.SX, each (3, 1)
        The velocity is the slope of the segment t lies in (at a waypoint,
        the segment that starts there; the derivative of the casadi
        interpolant), zero outside [first, last).
    """
    pos, vel = _waypoint_function(times.numel())(t, times, points, first, last)
    return pos, vel


@lru_cache(maxsize=None)
def _waypoint_function(max_rows: int) -> ca.Function:
    f = waypoint_interpolant(max_rows)
    t, first, last = ca.SX.sym("t"), ca.SX.sym("first"), ca.SX.sym("last")
    times, points = ca.SX.sym("times", max_rows), ca.SX.sym("points", 3 * max_rows)
    pos = f(ca.fmin(ca.fmax(t, first), last), times, points)
    slope = ca.jacobian(f(t, times, points), t)
    vel = ca.if_else(ca.logic_and(t >= first, t < last), slope, ca.SX.zeros(3))
    return ca.Function("sblsim_waypoint_state", [t, times, points, first, last], [pos, vel])


def square_rows(side, speed, depth) -> list[list]:
    """Waypoints (t, N, E, D) of a square of the given side centred on the origin, from its SW corner N, E, S, W."""
    h = 0.5 * side
    corners = [(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)]
    return [[k * side / speed, n, e, depth] for k, (n, e) in enumerate(corners)]


def read_trajectory_file(path: str | Path, table: Table, field: str = "target.trajectory_file") -> np.ndarray:
    """Read a trajectory CSV with columns time [s], N [m], E [m], D [m].

    A first line is a header if it names the columns (``time, north, east,
    down``, or ``t, n, e, d``, ``x, y, z``; units in brackets allowed); a line
    starting with ``#`` is a comment. Every other cell must be a finite
    number inside its column's range (``table``), times strictly increasing.
    Reading stops at the first row beyond ``table.max_rows``: a huge file is
    refused after a few hundred lines, not parsed whole.

    Returns
    -------
    ndarray, shape (rows, 4)

    Raises
    ------
    ModelError
        If the file is missing or malformed; the message names the field,
        and the row and column of a bad cell.
    """
    if str(path) and Path(path).is_dir():
        raise ModelError(f"{field}: {str(path)!r} is a directory, not a CSV file")
    if not str(path) or not Path(path).is_file():
        raise ModelError(f"{field}: no such file {str(path)!r}")
    lines = []
    try:
        with open(path, newline="") as handle:
            for i, row in enumerate(csv.reader(_bounded_lines(handle, f"{field}: {str(path)!r}")), start=1):
                if row and not row[0].lstrip().startswith("#") and any(c.strip() for c in row):
                    lines.append((i, row))
                    if len(lines) > table.max_rows + 1:  # a header and max_rows + 1 rows: too many, stop reading
                        break
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ModelError(f"{field}: cannot read {str(path)!r} ({exc.__class__.__name__})") from None
    if lines and _is_header(lines[0][1], f"{field}: {str(path)!r}"):
        lines = lines[1:]
    if len(lines) > table.max_rows:
        raise ModelError(f"{field}: {str(path)!r} has at least {table.max_rows + 1} rows; at most {table.max_rows} "
                         f"(reading stopped at line {lines[table.max_rows][0]})")
    rows, numbers = [], []
    names = [c.name for c in table.columns]
    for i, row in lines:
        if len(row) != len(names):
            raise ModelError(f"{field}: {str(path)!r} line {i} has {len(row)} columns; expected {len(names)} "
                             "(time, N, E, D)")
        values = []
        for cell, col in zip(row, table.columns):
            try:
                number = float(cell)
            except ValueError:
                raise ModelError(f"{field}: {str(path)!r} line {i}, column {col.name}: {cell.strip()!r} "
                                 "is not a number") from None
            check_entry(number, col, f"{field}: {str(path)!r} line {i}, column {col.name}")
            values.append(number)
        rows.append(values)
        numbers.append(i)
    if len(rows) < 2:
        raise ModelError(f"{field}: {str(path)!r} needs at least 2 rows time, N, E, D")
    data = np.array(rows)
    check_increasing(data, table, f"{field}: {str(path)!r}", numbers, "line")
    return data


def _bounded_lines(handle, where: str):
    """The lines of a text file open with ``newline=""``, each read to at most :data:`MAX_LINE_CHARS` characters and
    its line end, at most :data:`MAX_FILE_CHARS` in all.

    Raises
    ------
    ModelError
        ``where line N is longer than ... characters; allowed at most ...`` for a longer line or file.
    """
    number = total = 0
    while line := handle.readline(MAX_LINE_CHARS + 1):
        number += 1
        total += len(line)
        if len(line) > MAX_LINE_CHARS and not line.endswith(("\n", "\r")):
            raise ModelError(f"{where} line {number} is longer than {MAX_LINE_CHARS:,} characters; allowed at most "
                             f"{MAX_LINE_CHARS:,} a line")
        if total > MAX_FILE_CHARS:
            raise ModelError(f"{where} is longer than {MAX_FILE_CHARS:,} characters (line {number}); allowed at most "
                             f"{MAX_FILE_CHARS:,} (the waypoints and comments)")
        yield line


#: Header names of the four columns of a trajectory file (case-insensitive; a unit in brackets is ignored).
HEADER_NAMES = ({"time", "t"}, {"north", "n", "x"}, {"east", "e", "y"}, {"down", "d", "z", "depth"})


def _is_header(row: list[str], where: str) -> bool:
    """Whether the first line is a header: it names the columns (time, north, east, down, see
    :data:`HEADER_NAMES`). A first line of names that are not these is an error, not a header.

    Raises
    ------
    ModelError
        If the first line holds no number and does not name the columns.
    """
    names = [re.sub(r"[\[(].*$", "", cell).strip().lower() for cell in row]
    if len(names) == len(HEADER_NAMES) and all(n in allowed for n, allowed in zip(names, HEADER_NAMES)):
        return True
    for cell in row:
        try:
            float(cell)
            return False  # a data line (its cells are checked one by one)
        except ValueError:
            continue
    # the line itself is not repeated: the file may be anyone's (a path a configuration names), its text a secret
    raise ModelError(f"{where} line 1 ({len(row)} fields, no number) is neither numbers nor a header naming the "
                     "columns time, north, east, down")


__all__ = ["OPEN_DURATION", "read_trajectory_file", "semicircle", "spiral", "spiral_arc", "square_rows",
           "waypoint_interpolant", "waypoints"]
