"""Reading the receivers' positions, as hostile input (:mod:`.input_rows`): a CSV with a name column and ``x_m``,
``y_m`` [, ``z_m``] [, ``status``] (or ``x``, ``y``, ``z``), a receiver without a position not used (Lake Hald's
``hydrophones.csv``), or a TOML file of ``[[receiver]]`` tables with ``name``, ``x_m``, ``y_m`` [, ``z_m``]; in a CSV
the positions may be ``lat``, ``lon`` (or ``latitude``, ``longitude``) instead, WGS 84 degrees (or the geographic
``crs`` given), projected to a metric frame (:mod:`sblsim.orchestrator.io.frames`: the UTM zone of the array's
centre, or the ``frame`` given), and x, y may be given in a projected ``crs`` (kept in it): then every output has
latitude and longitude too.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.sync.resolution import ROUNDING_SIGMA_RANGE
from sblsim.models.tracking.timing import CLOCK_SIGMA_RANGE, TOA_SIGMA_RANGE
from sblsim.orchestrator.io.frames import (
    CHOSEN_INPUT,
    Frame,
    check_crs,
    check_latlon,
    check_metric,
    frame_for,
    is_geographic,
    transform,
)
from sblsim.orchestrator.io.tables import number
from sblsim.orchestrator.readers.input_rows import MAX_COORDINATE, MAX_RECEIVERS, MISSING, _lines, _rows, _stripped


@dataclass
class Receivers:
    """The receivers: ``names`` (n,), ``positions`` (n, dim) [m], NaN rows where a receiver has no position
    (not used), ``sigma`` (n,) each one's survey error per axis [m] (a ``sigma_m`` column; NaN where not given,
    None without the column), ``frame`` the metric frame of the positions (None: a local frame without a
    CRS), and ``toa_sigma`` (n,) each one's timing noise [s] (a ``toa_sigma_s`` column, as ``sblsim toa`` writes
    it from a synchronisation's residuals; NaN where not given, None without the column), ``clock_sigma`` (n,) its
    clock offset's own uncertainty [s] (a ``clock_sigma_s`` column, as ``sblsim toa`` writes it from the
    synchronisation's offsets; likewise), ``clock_mean`` (n,) that error averaged over the tag's arrivals at it [s]
    (a ``clock_mean_sigma_s`` column, as ``sblsim toa`` writes it for a tag's matrix; likewise), ``rounding`` (n,)
    its logged times' rounding σ [s] (a ``rounding_sigma_s`` column, likewise: a still tag's verdict takes it)."""

    names: list[str]
    positions: np.ndarray
    sigma: np.ndarray | None = None
    frame: Frame | None = None
    toa_sigma: np.ndarray | None = None
    clock_sigma: np.ndarray | None = None
    clock_mean: np.ndarray | None = None
    rounding: np.ndarray | None = None


#: The survey errors a receivers file's ``sigma_m`` column may give [m] (a standard deviation per axis).
SURVEY_SIGMA_RANGE = (0.0, 1000.0)


#: The header names of latitude and longitude (a receivers file's, a track's).
LATITUDE, LONGITUDE = ("lat", "latitude"), ("lon", "long", "longitude")


def read_receivers(path: Path | str, crs: str | None = None, frame: str | None = None) -> Receivers:
    """Read the receivers' positions: a CSV (a name column, ``x_m``/``x``, ``y_m``/``y`` [, ``z_m``/``z``], or
    ``lat``, ``lon`` [°] [, ``z_m``]; [, ``sigma_m``] [, ``toa_sigma_s``] [, ``clock_sigma_s``]
    [, ``clock_mean_sigma_s``] [, ``rounding_sigma_s``] [, ``status``]) or a
    TOML file
    (``[[receiver]]`` with ``name``, ``x_m``, ``y_m`` [, ``z_m``] [, ``sigma_m``]); ``sigma_m`` the survey's standard
    deviation per axis [m] (:data:`SURVEY_SIGMA_RANGE`), ``toa_sigma_s`` the receiver's timing noise [s]
    (:data:`~sblsim.models.tracking.timing.TOA_SIGMA_RANGE`; empty: not known), ``clock_sigma_s`` its clock
    offset's own uncertainty [s] (:data:`~sblsim.models.tracking.timing.CLOCK_SIGMA_RANGE`; empty: not known),
    ``clock_mean_sigma_s`` that error averaged over a tag's arrivals at the receiver [s] (likewise),
    ``rounding_sigma_s`` the rounding σ of its logged times [s] (``q / √12``:
    :data:`~sblsim.models.sync.resolution.ROUNDING_SIGMA_RANGE`; empty: not known).
    A receiver whose coordinates
    are empty is kept without a position (its column of the TOA matrix is not used). Latitude and longitude (WGS 84,
    or the geographic ``crs``) are projected to ``frame`` (a metric CRS; default the UTM zone of their centre); x and
    y in a projected ``crs`` stay in it.

    Raises
    ------
    ModelError
        One line naming the file, its row or key, and the allowed range; a CRS that does not fit the columns.
    """
    path, what = Path(path), "receivers"
    name = str(path)
    if crs is not None:
        check_crs(crs, "crs")
    if path.suffix.lower() == ".toml":
        if crs is not None or frame is not None:
            raise ModelError("crs: not with a TOML receivers file (x_m, y_m in a local frame); allowed: a CSV")
        return _receivers_toml(path, what)
    parsed = _rows(path, what)
    if len(parsed) < 2:
        raise ModelError(f"{what}: {name!r} holds no receivers; allowed: a header (name, x_m, y_m[, z_m]) and rows")
    header = [h.lower() for h in _stripped(parsed[0][1])]
    rows = [(lineno, _stripped(cells)) for lineno, cells in parsed[1:]]
    if len(rows) > MAX_RECEIVERS:
        raise ModelError(f"{what}: {name!r} has {len(rows)} receivers; allowed at most {MAX_RECEIVERS}")
    axes = []
    geographic = any(h in LATITUDE for h in header) and any(h in LONGITUDE for h in header) and \
        (crs is None or is_geographic(crs))
    horizontal = (LONGITUDE, LATITUDE) if geographic else (("x_m", "x"), ("y_m", "y"))
    for aliases in (*horizontal, ("z_m", "z")):
        found = [k for k, h in enumerate(header) if h in aliases]
        axes.append(found[0] if found else None)
    if axes[0] is None or axes[1] is None:
        raise ModelError(f"{what}: {name!r}: the header needs x_m and y_m (or x, y; or lat, lon) columns, got "
                         f"{','.join(header)[:120]}")
    if crs is not None and not geographic and is_geographic(crs):
        raise ModelError(f"crs: {crs!r} is geographic (degrees); allowed: lat and lon columns with it, or a projected "
                         "CRS for x_m and y_m")
    if frame is not None and crs is None and not geographic:
        raise ModelError("frame: given for positions without a CRS; allowed: with --crs (the positions' CRS), or "
                         "positions as lat and lon")
    used = [k for k in axes if k is not None]
    status = header.index("status") if "status" in header else None
    survey = header.index("sigma_m") if "sigma_m" in header else None
    noise = header.index("toa_sigma_s") if "toa_sigma_s" in header else None
    offset = header.index("clock_sigma_s") if "clock_sigma_s" in header else None
    mean = header.index("clock_mean_sigma_s") if "clock_mean_sigma_s" in header else None
    rounded = header.index("rounding_sigma_s") if "rounding_sigma_s" in header else None
    label = next((k for k in range(len(header)) if k not in used and k not in (status, survey, noise, offset, mean,
                                                                                rounded)), None)
    names, positions, sigma, timing, offsets, means, roundings = [], [], [], [], [], [], []
    for k, (lineno, cells) in enumerate(rows, start=1):
        if len(cells) != len(header):
            raise ModelError(f"{what}: {name!r} line {lineno} has {len(cells)} cells, the header {len(header)} "
                             f"({','.join(header)[:80]})")
        names.append(cells[label] if label is not None else str(k))
        if survey is not None:
            sigma.append(math.nan if cells[survey] in MISSING else number(
                cells[survey], f"{what}: {name!r} line {lineno}", "sigma_m", *SURVEY_SIGMA_RANGE))
        if noise is not None:
            timing.append(math.nan if cells[noise] in MISSING else number(
                cells[noise], f"{what}: {name!r} line {lineno}", "toa_sigma_s", *TOA_SIGMA_RANGE))
        for column, at, into, allowed in (("clock_sigma_s", offset, offsets, CLOCK_SIGMA_RANGE),
                                          ("clock_mean_sigma_s", mean, means, CLOCK_SIGMA_RANGE),
                                          ("rounding_sigma_s", rounded, roundings, ROUNDING_SIGMA_RANGE)):
            if at is not None:
                into.append(math.nan if cells[at] in MISSING else number(
                    cells[at], f"{what}: {name!r} line {lineno}", column, *allowed))
        coordinates = [cells[k] for k in used]
        if all(c in MISSING for c in coordinates):
            positions.append([math.nan] * len(used))
            continue
        positions.append([number(c, f"{what}: {name!r} line {lineno}", header[k], -MAX_COORDINATE, MAX_COORDINATE)
                          for c, k in zip(coordinates, used)])
    if len(set(names)) != len(names):
        raise ModelError(f"{what}: {name!r}: a receiver name is given twice")
    positions = np.array(positions, float)
    chosen = None
    if geographic:
        lon, lat = positions[:, 0], positions[:, 1]
        check_latlon(lat, lon, f"{what}: {name!r}")
        if crs is not None:
            lon, lat = transform(crs, "EPSG:4326", lon, lat)
        chosen = frame_for(lat, lon, frame)
        positions[:, 0], positions[:, 1] = chosen.from_latlon(lat, lon)
    elif crs is not None:
        chosen = Frame(check_metric(crs, "crs"), CHOSEN_INPUT) if frame is None else Frame(check_metric(frame,
                                                                                                        "frame"))
        if frame is not None:
            positions[:, 0], positions[:, 1] = transform(crs, chosen.crs, positions[:, 0], positions[:, 1])
    return Receivers(names, positions, np.array(sigma, float) if survey is not None else None, chosen,
                     np.array(timing, float) if noise is not None else None,
                     np.array(offsets, float) if offset is not None else None,
                     np.array(means, float) if mean is not None else None,
                     np.array(roundings, float) if rounded is not None else None)


def _receivers_toml(path: Path, what: str) -> Receivers:
    name = str(path)
    text = "\n".join(line for _, line in _lines(path, what))
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(f"{what}: {name!r} is not valid TOML ({exc})") from None
    unknown = set(data) - {"receiver"}
    if unknown or not isinstance(data.get("receiver"), list) or not data["receiver"]:
        raise ModelError(f"{what}: {name!r}: expected [[receiver]] tables only (name, x_m, y_m[, z_m]), got "
                         f"{', '.join(sorted(unknown)) or 'no receiver'}")
    names, positions, sigma = [], [], []
    dims = set()
    for k, table in enumerate(data["receiver"], start=1):
        extra = set(table) - {"name", "x_m", "y_m", "z_m", "sigma_m"}
        if extra or "x_m" not in table or "y_m" not in table:
            raise ModelError(f"{what}: {name!r}: receiver {k}: the keys are name, x_m, y_m[, z_m][, sigma_m]; got "
                             f"{', '.join(sorted(table))}")
        value = table.get("sigma_m", math.nan)
        low, high = SURVEY_SIGMA_RANGE
        if "sigma_m" in table and (isinstance(value, bool) or not isinstance(value, (int, float))
                                   or not low <= value <= high):
            raise ModelError(f"{what}: {name!r}: receiver {k}: sigma_m = {value!r} is not allowed; allowed: a "
                             f"number in [{low:g}, {high:g}] m")
        sigma.append(float(value))
        row = []
        for key in ("x_m", "y_m", "z_m"):
            if key not in table:
                continue
            value = table[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or abs(value) > MAX_COORDINATE:
                raise ModelError(f"{what}: {name!r}: receiver {k}: {key} = {value!r} is not allowed; allowed: a "
                                 f"finite number in [{-MAX_COORDINATE:g}, {MAX_COORDINATE:g}] m")
            row.append(float(value))
        dims.add(len(row))
        names.append(str(table.get("name", k)))
        positions.append(row)
    if len(dims) != 1:
        raise ModelError(f"{what}: {name!r}: every receiver needs the same coordinates (all with z_m or none)")
    given = np.array(sigma, float)
    return Receivers(names, np.array(positions, float), given if np.isfinite(given).any() else None)



__all__ = ["LATITUDE", "LONGITUDE", "Receivers", "SURVEY_SIGMA_RANGE", "read_receivers"]
