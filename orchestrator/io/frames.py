"""The local metric frame of a study: positions given as latitude and longitude (or in any CRS) projected to
metres, and the results projected back to WGS 84 latitude and longitude, every projection by pyproj.

The frame is a projected CRS with metre axes, x east and y north: by default the **UTM zone of the array's centre**
on WGS 84 (pyproj's database query of the UTM zones whose area holds that point, EPSG 326zz / 327zz), or the one a
user gives (``--frame EPSG:…``), or, where positions are given as x and y in a projected CRS (``--crs EPSG:…``),
that CRS itself (metric coordinates are kept as they are given). The frame's point scale factor at the array's
centre (UTM's is 0.9996 on its central meridian and grows away from it) is stated with it: every distance in the
frame is that much longer than on the ground, which a sound speed calibrated from the pings absorbs and a given one
does not.

A :class:`Frame` is described by its CRS text alone (it pickles to a worker process); its transformers are made
once per process and CRS.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from sblsim.models.declarations import ModelError

#: Latitude and longitude: the geographic CRS of every lat/lon this project writes (WGS 84, degrees).
WGS84 = "EPSG:4326"
#: How a frame was chosen, as the summaries say it.
CHOSEN_UTM = "the UTM zone of the array's centre"
CHOSEN_GIVEN = "given"
CHOSEN_INPUT = "the CRS the positions were given in"
#: The largest departure from 1 of a frame's point scale factor over the array [1] (0.1 %: a UTM zone's is 0.04 % on
#: its central meridian and 0.1 % at its edges; Web Mercator's is 80 % at 56° N).
MAX_SCALE_ERROR = 1e-3


def _crs(text: str, where: str):
    """A pyproj CRS from a user's text (``EPSG:32632``, a PROJ string or WKT), refused in one line."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    if not isinstance(text, str) or not 0 < len(text) <= 4096:
        raise ModelError(f"{where}: {str(text)[:40]!r} is not allowed; allowed: a CRS such as EPSG:4326 or "
                         "EPSG:32632")
    try:
        return CRS.from_user_input(text)
    except CRSError:
        raise ModelError(f"{where}: {text[:40]!r} is not a CRS pyproj knows; allowed: a CRS such as EPSG:4326 (WGS "
                         "84 latitude and longitude) or EPSG:32632 (WGS 84 / UTM zone 32N)") from None


def check_crs(text: str, where: str) -> str:
    """A CRS given by a user, checked (pyproj knows it): its text, as given."""
    _crs(text, where)
    return text


def is_geographic(text: str) -> bool:
    """Whether a CRS (a checked text) gives latitude and longitude (else projected x, y)."""
    return bool(_crs(text, "crs").is_geographic)


def check_metric(text: str, where: str) -> str:
    """A projected CRS with metre axes (a frame), refused in one line otherwise; its text."""
    crs = _crs(text, where)
    units = {a.unit_name for a in crs.axis_info}
    if not crs.is_projected or units - {"metre", "meter"}:
        raise ModelError(f"{where}: {text[:40]!r} ({crs.name}) is not a projected CRS in metres; allowed: a metric "
                         "frame such as a UTM zone (EPSG:326zz north, EPSG:327zz south)")
    return text


@lru_cache(maxsize=64)
def _transformer(source: str, target: str):
    from pyproj import Transformer

    return Transformer.from_crs(source, target, always_xy=True)


def transform(source: str, target: str, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates from one CRS to another (pyproj, axes in x/east–y/north order: longitude before latitude).

    Parameters
    ----------
    source, target : str
        The CRSs (checked texts).
    a, b : numpy.ndarray
        (n,) the first (x or longitude) and second (y or latitude) coordinates in ``source``.

    Returns
    -------
    tuple of numpy.ndarray
        (n,), (n,) in ``target`` (NaN stays NaN).

    Raises
    ------
    ModelError
        A point pyproj cannot transform (outside the CRS's domain: infinite).
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    x, y = _transformer(source, target).transform(a, b)
    x, y = np.asarray(x, float), np.asarray(y, float)
    lost = (np.isfinite(a) & np.isfinite(b)) & ~(np.isfinite(x) & np.isfinite(y))
    if lost.any():
        k = int(np.flatnonzero(lost)[0])
        raise ModelError(f"crs: the point ({a[k]:.10g}, {b[k]:.10g}) of {source} has no place in {target}; allowed: "
                         "points inside the CRS's area")
    return x, y


def utm_zone(lat: float, lon: float) -> str:
    """The WGS 84 UTM zone holding a point, as pyproj's database lists it (``EPSG:32632``)."""
    from pyproj.aoi import AreaOfInterest
    from pyproj.database import query_utm_crs_info

    found = query_utm_crs_info(datum_name="WGS 84", area_of_interest=AreaOfInterest(lon, lat, lon, lat))
    if not found:
        raise ModelError(f"frame: no UTM zone holds ({lat:.6g}°, {lon:.6g}°) (beyond 84° N or 80° S); allowed: give "
                         "a metric frame (--frame EPSG:…)")
    return f"{found[0].auth_name}:{found[0].code}"


@dataclass(frozen=True)
class Frame:
    """A study's local metric frame: a projected CRS in metres, x east and y north.

    Attributes
    ----------
    crs : str
        The frame's CRS (``EPSG:32632``).
    chosen : str
        How it was chosen (:data:`CHOSEN_UTM`, :data:`CHOSEN_GIVEN` or :data:`CHOSEN_INPUT`).
    """

    crs: str
    chosen: str = CHOSEN_GIVEN

    def from_latlon(self, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,), (n,) [m] x, y of WGS 84 latitudes and longitudes [°]."""
        return transform(WGS84, self.crs, lon, lat)

    def to_latlon(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,), (n,) [°] WGS 84 latitudes and longitudes of x, y [m]."""
        lon, lat = transform(self.crs, WGS84, x, y)
        return lat, lon

    def summary(self, lat: float | None = None, lon: float | None = None) -> dict[str, Any]:
        """What every output's summary states: the CRS, its name, how it was chosen, and (at ``lat``, ``lon``)
        the frame's point scale factor there."""
        from pyproj import Proj

        crs = _crs(self.crs, "frame")
        out: dict[str, Any] = {"crs": self.crs, "name": crs.name, "chosen": self.chosen,
                               "latlon": "WGS 84 (EPSG:4326), degrees"}
        if lat is not None and lon is not None and np.isfinite([lat, lon]).all():
            factors = Proj(crs).get_factors(float(lon), float(lat))
            out["scale_factor"] = float(factors.meridional_scale)
            out["scale_note"] = ("distances in the frame are this factor times those on the ground at the array's "
                                 "centre")
        return out


def frame_summary(frame: Frame | None, x: np.ndarray, y: np.ndarray) -> dict[str, Any] | None:
    """``frame``'s summary (:meth:`Frame.summary`) at the centre of the points ``x``, ``y`` [m] of the frame (their
    mean), None without a frame."""
    if frame is None:
        return None
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        return frame.summary()
    lat, lon = frame.to_latlon(np.array([np.mean(x[ok])]), np.array([np.mean(y[ok])]))
    return frame.summary(float(lat[0]), float(lon[0]))


def scale_range(crs: str, lat: np.ndarray, lon: np.ndarray) -> tuple[float, float]:
    """The smallest and largest point scale factor [1] of a projected CRS at points given as WGS 84 latitude and
    longitude [°] (pyproj's ``Proj.get_factors``: the meridional and the parallel scale, equal in a conformal
    projection such as UTM or Mercator): every distance in the CRS is between these times the distance on the
    ground there (Snyder 1987, *Map Projections: A Working Manual*, USGS Professional Paper 1395, §4)."""
    from pyproj import Proj

    ok = np.isfinite(lat) & np.isfinite(lon)
    factors = Proj(_crs(crs, "frame")).get_factors(np.asarray(lon, float)[ok], np.asarray(lat, float)[ok])
    scales = np.concatenate([np.atleast_1d(factors.meridional_scale), np.atleast_1d(factors.parallel_scale)])
    scales = scales[np.isfinite(scales)]
    if not len(scales):
        return float("nan"), float("nan")
    return float(scales.min()), float(scales.max())


def check_scale(crs: str, lat: np.ndarray, lon: np.ndarray, where: str) -> None:
    """Refuse a metric frame whose scale over the points (:func:`scale_range`) is not within
    :data:`MAX_SCALE_ERROR` of 1: its metres are not the ground's, and every range by sound would disagree with the
    positions by that factor (Web Mercator's is 1.8 at 56° N).

    Raises
    ------
    ModelError
        One line naming the frame, its scale over the points and a frame that fits them.
    """
    low, high = scale_range(crs, lat, lon)
    if np.isfinite([low, high]).all() and max(abs(low - 1.0), abs(high - 1.0)) <= MAX_SCALE_ERROR:
        return
    ok = np.isfinite(lat) & np.isfinite(lon)
    centre = ((np.min(lat[ok]) + np.max(lat[ok])) / 2, (np.min(lon[ok]) + np.max(lon[ok])) / 2) if ok.any() else None
    suggestion = f" such as the UTM zone of the array ({utm_zone(*centre)})" if centre is not None else ""
    shown = f"{low:.6g}" if np.isclose(low, high, rtol=0, atol=5e-7) else f"{low:.6g} to {high:.6g}"
    raise ModelError(f"{where}: {crs[:40]} ({_crs(crs, where).name}) scales distances by {shown} over the array; "
                     f"allowed: a metric frame whose scale there is within {MAX_SCALE_ERROR:.1%} of 1,{suggestion}")


def frame_for(lat: np.ndarray, lon: np.ndarray, given: str | None = None, check: bool = True) -> Frame:
    """The frame of points given as WGS 84 latitude and longitude: ``given`` (a metric CRS whose scale over the
    points is within :data:`MAX_SCALE_ERROR` of 1: :func:`check_scale`; ``check`` False leaves that to the caller,
    who knows which of the points are used) or the UTM zone of their centre (the middle of their extent).

    Raises
    ------
    ModelError
        ``given`` not a projected metric CRS, or one that distorts distances over the points; no finite point.
    """
    ok = np.isfinite(lat) & np.isfinite(lon)
    if given is not None:
        frame = Frame(check_metric(given, "frame"), CHOSEN_GIVEN)
        if ok.any() and check:
            check_scale(frame.crs, np.asarray(lat, float), np.asarray(lon, float), "frame")
        return frame
    if not ok.any():
        raise ModelError("frame: no position to choose a frame from; allowed: positions with latitude and longitude")
    centre_lat = (np.min(lat[ok]) + np.max(lat[ok])) / 2
    centre_lon = (np.min(lon[ok]) + np.max(lon[ok])) / 2
    return Frame(utm_zone(float(centre_lat), float(centre_lon)), CHOSEN_UTM)


def check_latlon(lat: np.ndarray, lon: np.ndarray, where: str, lines: list[int] | None = None) -> None:
    """Latitudes in [-90, 90]° and longitudes in [-180, 180]°, refused in one line (the first outside)."""
    bad = np.flatnonzero((np.abs(lat) > 90) | (np.abs(lon) > 180))
    if len(bad):
        k = int(bad[0])
        at = f" line {lines[k]}" if lines is not None else ""
        raise ModelError(f"{where}{at}: latitude {lat[k]:.10g}, longitude {lon[k]:.10g} is not allowed; allowed: a "
                         "latitude in [-90, 90]° and a longitude in [-180, 180]° (WGS 84 degrees; projected "
                         "coordinates need --crs)")


__all__ = ["CHOSEN_GIVEN", "CHOSEN_INPUT", "CHOSEN_UTM", "Frame", "MAX_SCALE_ERROR", "WGS84", "check_crs",
           "check_latlon", "check_metric", "check_scale", "frame_for", "frame_summary", "is_geographic", "scale_range",
           "transform", "utm_zone"]
