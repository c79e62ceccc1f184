"""The water's outline of a telemetry array's design from a file (``site.area.file``): a CSV of vertices or a
GeoJSON polygon, read bounded.

* **CSV** (``.csv``, ``.txt``): one vertex a row, ``north_m, east_m`` [m] in the site's local frame; a first row
  naming the columns (``north_m,east_m``) is optional, ``#`` comments and blank lines are skipped;
* **GeoJSON** (``.geojson``, ``.json``): a ``Polygon``, a ``MultiPolygon`` (islands as holes) or a ``Feature`` of
  one, its coordinates ``[east_m, north_m]`` (GeoJSON's x, y order) in the same local metric frame — not degrees.

Either is refused in one line naming ``site.area.file`` where it is not a regular file, larger than
:data:`MAX_BYTES`, not UTF-8 text, holds more than :data:`~sblsim.models.design.area.MAX_VERTICES` vertices, a
number that is not finite, or an outline that is not a valid polygon; a CSV also where a line is longer than 1 MiB or
holds more than 512 cells, or the file more than :data:`MAX_CELLS`, counted before it is parsed
(:func:`~sblsim.orchestrator.io.tables.check_cells`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import shapely

from sblsim.models.design import area as areas
from sblsim.models.errors import ConfigError, ModelError
from sblsim.orchestrator.io.tables import csv_cells, read_lines

#: The largest outline file read [bytes].
MAX_BYTES = 16 << 20
#: The most cells a CSV outline holds [1]: two a vertex, and as many again for a header, blank cells and comments.
MAX_CELLS = 4 * areas.MAX_VERTICES
#: The key the errors name.
KEY = "site.area.file"


def _refuse(name: str, what: str, amount: str) -> ModelError:
    return ModelError(f"{what}: {name!r} {amount}; allowed at most {MAX_BYTES // 2**20} MiB and "
                      f"{areas.MAX_VERTICES:,} vertices")


def _constant(text: str) -> float:
    raise ValueError(f"{text} is not a finite number")


def read_area(path: str | Path):
    """The water's polygon, its coordinates (North, East) [m] (module docstring).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    shapely Polygon or MultiPolygon

    Raises
    ------
    ConfigError
        Naming ``site.area.file`` (module docstring).
    """
    path = Path(path)
    geojson = path.suffix.lower() in (".geojson", ".json")
    try:  # a CSV's cells counted before it is parsed (a GeoJSON's numbers are bounded by MAX_BYTES alone)
        lines = read_lines(path, KEY, max_bytes=MAX_BYTES, max_rows=areas.MAX_VERTICES, refuse=_refuse,
                           delimiter=None if geojson else ",", max_cells=MAX_CELLS, comments=True)
        if geojson:
            return _geojson("\n".join(lines))
        return _csv(lines)
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def _csv(lines: list[str]):
    numbered = [(k, line) for k, line in enumerate(lines, start=1) if line.strip() and not line.lstrip()
                .startswith("#")]
    rows = csv_cells(numbered, KEY)
    if rows and rows[0][1] and not _numeric(rows[0][1][0]):
        header = [c.strip().lower() for c in rows[0][1]]
        if header[:2] != ["north_m", "east_m"]:
            raise ModelError(f"{KEY}: line {rows[0][0]}: columns {rows[0][1][:4]}; allowed north_m, east_m")
        rows = rows[1:]
    vertices = []
    for line, cells in rows:
        if len(cells) != 2:
            raise ModelError(f"{KEY}: line {line}: {len(cells)} cells; allowed 2 (north_m, east_m)")
        try:
            vertices.append([float(cells[0]), float(cells[1])])
        except ValueError:
            raise ModelError(f"{KEY}: line {line}: {cells!r} is not two numbers (north_m, east_m)") from None
    return areas.polygon(np.asarray(vertices, float) if vertices else np.zeros((0, 2)), KEY)


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _geojson(text: str):
    try:
        data = json.loads(text, parse_constant=_constant)
    except (ValueError, RecursionError) as exc:
        raise ModelError(f"{KEY}: not valid GeoJSON ({' '.join(str(exc).split())[:120]})") from None
    if not isinstance(data, dict):
        raise ModelError(f"{KEY}: a GeoJSON {type(data).__name__}; allowed a Polygon, a MultiPolygon or a Feature "
                         "of one")
    geometry = areas.polygon(data, KEY)
    return shapely.transform(geometry, lambda xy: xy[:, ::-1])  # GeoJSON's (east, north) -> (north, east)


__all__ = ["KEY", "MAX_BYTES", "MAX_CELLS", "read_area"]
