"""A study's receivers as the field keeps them: deployments in latitude and longitude (or in any CRS), with dates,
one serial at several stations over time; and each detection assigned to the deployment that logged it.

A deployments table (CSV, one row per deployment; header names matched case-insensitively, a trailing unit or note
in brackets ignored: :func:`~sblsim.orchestrator.readers.cells.normal_name`) takes the community's names (GLATOS
``receiver_locations``, OTN deployments) or sblsim's own:

* the receiver: ``serial`` (or ``ins_serial_no``, ``receiver_sn``, ``receiver_serial_number``, ``receiver``);
  ``station`` (or ``station_no``, ``station_name``), kept for the outputs;
* its position: ``lat``, ``lon`` (or ``latitude``/``longitude``, ``deploy_lat``/``deploy_long``,
  ``stn_lat``/``stn_long``) in WGS 84 degrees, or in the geographic CRS given (``crs``); else ``x_m``, ``y_m`` (or
  ``x``, ``y``) [m] in the projected CRS given, or in a local frame without one (no latitude and longitude out);
* its depth: ``z_m`` (height, up) or ``instrument_depth`` (or ``depth``) [m, positive down]; ``bottom_depth`` [m,
  positive down: the water's depth at the receiver, at least the instrument's], which bounds a tag's depth
  (``sblsim track``: the deepest of the receivers that heard the tag, where no ``--water-depth`` is given);
* its dates: ``deploy_date_time`` (or ``deploy_date``, ``start``) and ``recover_date_time`` (or ``recovery_date``,
  ``recover_date``, ``end``), ISO 8601 (UTC unless a zone is given) or epoch seconds; empty: open;
* its co-located sync tag: ``sync_tag`` (or ``transmitter``), a full ID or an id, empty for none.

Positions given as latitude and longitude are projected to the study's metric frame
(:func:`sblsim.orchestrator.io.frames.frame_for`: the UTM zone of the array's centre, or ``frame``); x and y given in
a projected CRS stay in it (it is the frame). A serial deployed more than once is one receiver per deployment,
named ``SERIAL.1``, ``SERIAL.2``, … in order of deployment (a serial deployed once keeps its name); two deployments
of one serial that overlap in time are refused, as is a sync tag at two places at once.

:func:`assign` gives each detection its deployment by the receiver's serial and the detection's time (on the
receiver's clock, seconds off at most, against deployments days long); detections before a deployment, after its
recovery, between two, or at a serial the table does not list are set aside and counted, never used.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.frames import (
    CHOSEN_GIVEN,
    CHOSEN_INPUT,
    CHOSEN_UTM,
    MAX_SCALE_ERROR,
    Frame,
    check_crs,
    check_latlon,
    check_metric,
    check_scale,
    frame_for,
    is_geographic,
    scale_range,
    transform,
)
from sblsim.orchestrator.io.times import iso_utc, utc_seconds
from sblsim.orchestrator.readers.cells import (
    file_table,
    named,
    numbers,
    pattern,
    shown_header,
    units_row,
    whole_ids,
)
from sblsim.orchestrator.readers.limits import IDENTIFIER, MAX_COORDINATE
from sblsim.orchestrator.readers.transmitters import TRANSMITTER

#: The most deployments a table holds.
MAX_DEPLOYMENTS = 10_000
#: Each field's header names (as :func:`~sblsim.orchestrator.readers.cells.normal_name` makes them), first preferred.
ALIASES = {
    "serial": ("serial", "ins_serial_no", "receiver_sn", "receiver_serial_number", "receiver", "name"),
    "station": ("station", "station_no", "station_name"),
    "sync_tag": ("sync_tag", "transmitter", "sync_transmitter"),
    "lat": ("lat", "latitude", "deploy_lat", "stn_lat", "decimallatitude"),
    "lon": ("lon", "long", "longitude", "deploy_long", "deploy_lon", "stn_long", "decimallongitude"),
    "x": ("x_m", "x", "easting"), "y": ("y_m", "y", "northing"), "z": ("z_m", "z"),
    "depth": ("instrument_depth", "depth", "receiver_depth", "depth_m"), "bottom": ("bottom_depth",),
    "start": ("deploy_date_time", "deploy_date", "deploy_time", "deploy_datetime_utc", "start", "time"),
    "end": ("recover_date_time", "recovery_date_time", "recovery_date", "recover_date", "recovery_datetime_utc",
            "end"),
}
#: The kind of unit (:data:`~sblsim.orchestrator.readers.cells.UNITS`) an ERDDAP-style units row must state, if any,
#: over each field read (OTN's receiver deployment table: ``degrees_north``, ``degrees_east``, ``UTC``, ``m``).
UNIT_KINDS = {"lat": "latitude", "lon": "longitude", "x": "metres", "y": "metres", "z": "metres", "depth": "metres",
              "bottom": "metres", "start": "time", "end": "time"}
#: The cells that say a value is missing (ERDDAP's and pandas' ``NaN``, R's ``NA``; case ignored), read as empty
#: where a field may be empty (a depth, a date) and in the serial (a deployment without one: set aside).
MISSING = ("nan", "na")
#: The depths allowed [m] (an instrument's; positive down), and the bottom's (below the surface).
DEPTH_RANGE = (-10.0, 11000.0)
BOTTOM_RANGE = (0.0, 11000.0)
#: The columns of :attr:`Deployments.table`.
COLUMNS = ("receiver", "serial", "station", "sync_tag", "x", "y", "z", "lat", "lon", "start", "end",
           "bottom_depth", "line")


@dataclass
class Deployments:
    """A study's receivers, one row per deployment.

    Attributes
    ----------
    table : pandas.DataFrame
        :data:`COLUMNS`: ``receiver`` (the deployment's name: the serial, or ``SERIAL.k``), ``serial``,
        ``station`` (``""`` where not given), ``sync_tag`` (as given, ``""`` for none), ``x``, ``y`` [m] in the
        frame, ``z`` [m, up; NaN where not given], ``lat``, ``lon`` [° WGS 84; NaN without a CRS], ``start``,
        ``end`` [s since 1970 UTC; -inf, +inf where open], ``bottom_depth`` [m; NaN], ``line`` (the file's).
    frame : Frame or None
        The metric frame of ``x``, ``y``; None where the positions were given as x, y without a CRS.
    source : str
        The file read.
    notes : list of str
        What the reader decided that a user should know (columns ignored, depths partly given).
    sheet : pandas.DataFrame or None
        Where these are the deployments in use of a larger sheet (:meth:`restricted`): every deployment of it as
        :meth:`written` gives them, in this frame, with the columns the restriction added (``used``, ...).
    """

    table: pd.DataFrame
    frame: Frame | None
    source: str
    notes: list[str] = field(default_factory=list)
    sheet: pd.DataFrame | None = None

    def hydrophones(self) -> pd.DataFrame:
        """The receivers as the clocks' synchronisation and the times-of-arrival matrix take them: ``receiver``,
        ``sync_tag``, ``x``, ``y``, ``z``."""
        return self.table[["receiver", "sync_tag", "x", "y", "z"]].reset_index(drop=True)

    def alternatives(self) -> dict[str, pd.DataFrame]:
        """Other readings of positions given as latitude and longitude, for a synchronisation to name where the table
        is refused (:func:`~sblsim.orchestrator.sync.run.synchronise`'s ``alternatives``): ``"latitude and longitude
        swapped"``, the hydrophones (:meth:`hydrophones`) with each deployment's latitude taken as its longitude and
        its longitude as its latitude, in the UTM zone of their centre; none where the positions were not given as
        latitude and longitude or swapped they are no latitudes."""
        lat, lon = self.table["lat"].to_numpy(float), self.table["lon"].to_numpy(float)
        if self.frame is None or not np.isfinite(lat).all() or (np.abs(lon) > 90).any():
            return {}
        x, y = frame_for(lon, lat).from_latlon(lon, lat)
        return {"latitude and longitude swapped": self.hydrophones().assign(x=x, y=y)}

    def summary(self) -> dict[str, Any]:
        """The frame and the deployments as every output's summary states them."""
        t = self.table
        lat, lon = t["lat"].to_numpy(float), t["lon"].to_numpy(float)
        centre = (float(np.nanmean(lat)), float(np.nanmean(lon))) if np.isfinite(lat).any() else (None, None)
        out = {"file": self.source, "deployments": int(len(t)), "receivers": int(t["serial"].nunique()),
               "redeployed": sorted(t.loc[t["serial"].duplicated(), "serial"].unique().tolist()),
               "frame": None if self.frame is None else self.frame.summary(*centre),
               "notes": list(self.notes)}
        if self.sheet is not None and "not_used" in self.sheet:  # the sheet's deployments not used, per cause
            causes = self.sheet.loc[self.sheet["not_used"] != "", "not_used"].value_counts()
            out |= {"in_sheet": int(len(self.sheet)), "used": int(len(t)),
                    "not_used": {"count": int(causes.sum())} | {str(k): int(v) for k, v in causes.items()}}
        return out

    def written(self) -> pd.DataFrame:
        """``receivers.csv``: each deployment's name, serial, station, sync tag, position in the frame and in
        latitude and longitude, depth and dates (ISO 8601 UTC, empty where open); every deployment of the sheet
        where these are those in use of it (:attr:`sheet`)."""
        if self.sheet is not None:
            return self.sheet.copy()
        t = self.table
        out = pd.DataFrame({"receiver": t["receiver"], "serial": t["serial"], "station": t["station"],
                            "sync_tag": t["sync_tag"], "x_m": t["x"], "y_m": t["y"], "z_m": t["z"],
                            "lat": t["lat"], "lon": t["lon"]})
        for key in ("start", "end"):
            values = t[key].to_numpy(float)
            out[f"{key}_utc"] = iso_utc(np.where(np.isfinite(values), values, np.nan))
        out["bottom_depth_m"] = t["bottom_depth"]
        return out

    def restricted(self, keep: np.ndarray, columns: dict[str, np.ndarray] | None = None) -> Deployments:
        """The deployments ``keep`` as a study's array, in a frame chosen over them alone.

        Where the frame was chosen automatically (the UTM zone of the centre: :func:`frame_for`), it is chosen
        again over the kept deployments' latitudes and longitudes and, where that zone differs, x and y are
        projected to it; a frame given, or the CRS the positions were given in, is kept with its x and y.

        Parameters
        ----------
        keep : numpy.ndarray
            (n,) bool over :attr:`table`'s rows.
        columns : dict of str to numpy.ndarray, optional
            Each (n,): columns added to :attr:`sheet` (``used``, the cause of a deployment not used, ...).

        Returns
        -------
        Deployments
            The kept rows (index 0..k-1), their frame, and as :attr:`sheet` every row of this table as
            :meth:`written` gives it in that frame (x, y [m] empty for a deployment the frame cannot hold), with
            ``columns``.

        Raises
        ------
        ModelError
            No deployment kept.
        """
        keep = np.asarray(keep, bool)
        if not keep.any():
            raise ModelError(f"receivers: no deployment of {self.source!r} is in use; allowed: deployments that "
                             "logged the detections")
        table, frame = self.table, self.frame
        if frame is not None and frame.chosen == CHOSEN_GIVEN:  # a frame given: its scale over the array used
            check_scale(frame.crs, table["lat"].to_numpy(float)[keep], table["lon"].to_numpy(float)[keep], "frame")
        if frame is not None and frame.chosen == CHOSEN_UTM and not keep.all():
            lat, lon = table["lat"].to_numpy(float), table["lon"].to_numpy(float)
            chosen = frame_for(lat[keep], lon[keep])
            if chosen.crs != frame.crs:
                x, y = np.full(len(table), np.nan), np.full(len(table), np.nan)
                x[keep], y[keep] = chosen.from_latlon(lat[keep], lon[keep])
                try:  # the others where pyproj can hold them in that zone
                    x[~keep], y[~keep] = chosen.from_latlon(lat[~keep], lon[~keep])
                except ModelError:
                    pass
                table = table.assign(x=x, y=y)
            frame = chosen
        sheet = replace(self, table=table, frame=frame, sheet=None).written().assign(**(columns or {}))
        return Deployments(table[keep].reset_index(drop=True), frame, self.source, list(self.notes), sheet)


def _index(header: list[str]) -> dict[str, int | None]:
    return {key: named(header, aliases) for key, aliases in ALIASES.items()}


def read_deployments(path: Path | str, crs: str | None = None, frame: str | None = None,
                     rows: tuple[list[str], pd.DataFrame, list[int]] | None = None) -> Deployments:
    """Read a study's receivers (the module docstring's columns) into one row per deployment, projected.

    Parameters
    ----------
    path : str or Path
        The table (CSV).
    crs : str, optional
        The CRS of its positions (``EPSG:4326`` by default for ``lat``/``lon``; for ``x_m``/``y_m``, a projected
        CRS, else they are taken in a local frame without one).
    frame : str, optional
        The metric frame (a projected CRS in metres; default the UTM zone of the array's centre for positions
        given as latitude and longitude).
    rows : (list of str, pandas.DataFrame, list of int), optional
        The table's header, rows (text cells) and each row's line, read already by another layout's reader
        (actel's deployments joined with its stations: :mod:`.actel`); default read from ``path``.

    Returns
    -------
    Deployments

    Raises
    ------
    ModelError
        One line naming the file, its line and column and the allowed values: no serial or position column, a
        cell outside its pattern or range, a recovery before its deployment, one serial's deployments overlapping,
        one sync tag at two places at once, a CRS pyproj does not know or that does not fit the columns.
    """
    path, what = Path(path), "receivers"
    name = str(path)
    if rows is None:
        header, body, lines = file_table(path, what, MAX_DEPLOYMENTS)  # a row's line: where it starts
    else:
        header, body, lines = rows
    index = _index(header)
    body, lines, units = units_row(header, body, lines, {index[k]: kind for k, kind in UNIT_KINDS.items()
                                                         if index[k] is not None}, name, what)
    notes: list[str] = [] if units is None else [f"line {units}: the units row under the header skipped (the "
                                                  "columns read in its units)"]
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no receivers")
    geographic = index["lat"] is not None and index["lon"] is not None
    projected = index["x"] is not None and index["y"] is not None
    if crs is not None:
        check_crs(crs, "crs")
        geographic = geographic and is_geographic(crs)
        projected = projected and not is_geographic(crs)
    if index["serial"] is None and (geographic or projected) and index["station"] is not None:
        raise ModelError(f"{what}: {name!r} is a station sheet ({shown_header(header)}) without the receivers' "
                         "serials: the detections are put at receivers by serial; allowed: a receiver deployment "
                         "table with a serial column (OTN's receiver deployment table: receiver_serial_number; "
                         "GLATOS's receiver locations: ins_serial_no)")
    if index["serial"] is None or not (geographic or projected):
        given = "" if crs is None else f" (in {crs})"
        raise ModelError(f"{what}: {name!r}: the header needs a serial (or ins_serial_no) column and positions{given}: "
                         "lat and lon (or deploy_lat and deploy_long), or x_m and y_m; got "
                         f"{shown_header(header)}")
    body, lines = _with_serial(body, lines, header[index["serial"]], index["serial"], name, what, notes)
    serial = pattern(body[index["serial"]], IDENTIFIER, what, name, lines, header[index["serial"]],
                     "a receiver's serial of 1 to 40 letters, digits, '.', '_' or '-'")
    serial, decimals = whole_ids(serial)  # 802357.0 as 802357 (a number column with blanks, saved)

    def text(key: str, regex=None, allowed: str = "") -> np.ndarray:
        if index[key] is None:
            return np.full(len(body), "", dtype=object)
        cells = body[index[key]].astype(str).str.strip()
        if regex is not None:
            given = (cells != "").to_numpy()
            pattern(cells[given], regex, what, name, [lines[k] for k in np.flatnonzero(given)], header[index[key]],
                    allowed)
        return cells.str.slice(0, 80).to_numpy(dtype=object)

    def values(key: str, low: float, high: float, unit: str, missing: bool = True) -> np.ndarray:
        if index[key] is None:
            return np.full(len(body), np.nan)
        cells = _blank(body[index[key]]) if missing else body[index[key]]
        return numbers(cells, what, name, lines, header[index[key]], low, high, missing=missing, unit=unit)

    if geographic:
        lat = values("lat", -90.0, 90.0, "°", missing=False)
        lon = values("lon", -180.0, 180.0, "°", missing=False)
        check_latlon(lat, lon, f"{what}: {name!r}", lines)
        if crs is not None and check_crs(crs, "crs") not in ("EPSG:4326", "epsg:4326"):
            lon, lat = transform(crs, "EPSG:4326", lon, lat)
        chosen = frame_for(lat, lon, frame, check=False)  # a given frame's scale: over the array used (restricted)
        x, y = chosen.from_latlon(lat, lon)
        if projected:
            notes.append(f"the columns {header[index['x']]}, {header[index['y']]} ignored: the positions are "
                         f"{header[index['lat']]}, {header[index['lon']]}")
    else:
        x = values("x", -MAX_COORDINATE, MAX_COORDINATE, "m", missing=False)
        y = values("y", -MAX_COORDINATE, MAX_COORDINATE, "m", missing=False)
        if crs is None:
            if frame is not None:
                raise ModelError("frame: given for positions without a CRS; allowed: with --crs (the positions' CRS), "
                                 "or positions as lat and lon")
            chosen, lat, lon = None, np.full(len(x), np.nan), np.full(len(x), np.nan)
        else:
            chosen = Frame(check_metric(crs, "crs"), CHOSEN_INPUT) if frame is None else \
                Frame(check_metric(frame, "frame"))
            if frame is not None:
                x, y = transform(crs, chosen.crs, x, y)
            lat, lon = chosen.to_latlon(x, y)
            low, high = scale_range(chosen.crs, lat, lon)
            if frame is None and not max(abs(low - 1), abs(high - 1)) <= MAX_SCALE_ERROR:
                utm = frame_for(lat, lon)  # the positions' CRS distorts them: taken to the array's UTM zone
                x, y = utm.from_latlon(lat, lon)
                notes.append(f"the positions' CRS {crs[:40]} scales distances by {low:.6g} to {high:.6g} over the "
                             f"array: projected to {utm.crs} (the UTM zone of the array's centre), whose metres are "
                             "the ground's within 0.1 %")
                chosen = utm
    z = values("z", -DEPTH_RANGE[1], -DEPTH_RANGE[0], "m (up)")
    if index["z"] is None and index["depth"] is not None:
        z = -values("depth", *DEPTH_RANGE, "m (positive down)")
    if np.isfinite(z).any() and not np.isfinite(z).all():
        notes.append(f"depths given for {int(np.isfinite(z).sum())} of {len(z)} deployments: the geometry is 2-D "
                     "(give every deployment's depth for 3-D)")
    start, end = (utc_seconds(_blank(body[index[key]]), f"{what}: {name!r}", lines, header[index[key]], missing=True)
                  if index[key] is not None else np.full(len(body), np.nan) for key in ("start", "end"))
    start, end = np.where(np.isnan(start), -np.inf, start), np.where(np.isnan(end), np.inf, end)
    if index["end"] is not None and np.isinf(end).any():
        notes.append(f"{int(np.isinf(end).sum()):,} of {len(end):,} deployments without a recovery date: open (in the "
                     "water to the end of the detections)")
    backwards = np.flatnonzero(end <= start)
    if len(backwards):
        k = int(backwards[0])
        raise ModelError(f"{what}: {name!r} line {lines[k]}: the recovery {iso_utc([end[k]])[0]} is not after the "
                         f"deployment {iso_utc([start[k]])[0]}; allowed: a recovery after its deployment")
    table = pd.DataFrame({"receiver": "", "serial": serial.to_numpy(dtype=object),
                          "station": text("station"),
                          "sync_tag": text("sync_tag", TRANSMITTER, "a transmitter's full ID (A69-1601-60123) or "
                                                                    "id, or empty"),
                          "x": x, "y": y, "z": z, "lat": lat, "lon": lon, "start": start, "end": end,
                          "bottom_depth": _bottom(values("bottom", *BOTTOM_RANGE, "m (positive down)"), z,
                                                  f"{what}: {name!r}", lines,
                                                  None if index["bottom"] is None else header[index["bottom"]]),
                          "line": np.asarray(lines, np.int64)})
    sync_tags, tag_decimals = whole_ids(table["sync_tag"])
    table["sync_tag"] = sync_tags.to_numpy(dtype=object)
    for key, count in ((index["serial"], decimals), (index["sync_tag"], tag_decimals)):
        if count:
            notes.append(f"{count:,} cells of {header[key]} read as whole numbers (802357.0 as 802357: a number column "
                         "with blank cells, as a spreadsheet or pandas writes it)")
    _check_overlaps(table, "serial", "receiver", name, what)
    _check_overlaps(table[table["sync_tag"] != ""], "sync_tag", "sync tag", name, what)
    order = table.sort_values(["serial", "start"], kind="stable")
    counts = order.groupby("serial", sort=False)["serial"].transform("size").to_numpy()
    rank = order.groupby("serial", sort=False).cumcount().to_numpy() + 1
    names = np.where(counts > 1, order["serial"].astype(str) + "." + rank.astype(str), order["serial"].astype(str))
    table.loc[order.index, "receiver"] = names
    used = {k for k in index.values() if k is not None}
    ignored = [h for k, h in enumerate(header) if k not in used and h]
    if ignored:
        notes.append(f"columns not used: {', '.join(h[:30] for h in ignored[:12])}")
    return Deployments(table, chosen, name, notes)


def _blank(cells: pd.Series) -> pd.Series:
    """A column's cells stripped, those saying a value is missing (:data:`MISSING`) made empty."""
    cells = cells.astype(str).str.strip()
    return cells.where(~cells.str.lower().isin(MISSING), "")


def _with_serial(body: pd.DataFrame, lines: list[int], column: str, k: int, name: str, what: str, notes: list[str]
                 ) -> tuple[pd.DataFrame, list[int]]:
    """The rows that name a receiver's serial (column ``k``); those without one (a receiver lost, none recorded:
    no detection can be put at it) set aside and said in ``notes`` with their lines.

    Raises
    ------
    ModelError
        No row names a serial (one line).
    """
    empty = (_blank(body[k]) == "").to_numpy(bool)
    if not empty.any():
        return body, lines
    if empty.all():
        raise ModelError(f"{what}: {name!r}: no row names a receiver's serial (column {column} empty); allowed: each "
                         "deployment's serial, the detections are put at receivers by serial")
    aside = [lines[j] for j in np.flatnonzero(empty)]
    notes.append(f"{len(aside):,} deployments without a serial ({column} empty: line "
                 f"{', '.join(map(str, aside[:5]))}{', ...' if len(aside) > 5 else ''}) set aside: the detections are "
                 "put at receivers by serial")
    return body[~empty].reset_index(drop=True), [lines[j] for j in np.flatnonzero(~empty)]


def _bottom(bottom: np.ndarray, z: np.ndarray, where: str, lines: list[int], column: str | None) -> np.ndarray:
    """The bottom's depth per deployment [m], checked against the instrument's height ``z`` [m, up].

    Raises
    ------
    ModelError
        A bottom above its instrument (one line naming the line and the column).
    """
    above = np.flatnonzero(np.isfinite(bottom) & np.isfinite(z) & (bottom < -z))
    if len(above):
        k = int(above[0])
        raise ModelError(f"{where} line {lines[k]} column {column}: {bottom[k]:g} m is above the instrument at "
                         f"{-z[k]:g} m; allowed: a bottom at least as deep as the instrument, in [{-z[k]:g}, "
                         f"{BOTTOM_RANGE[1]:g}] m")
    return bottom


def _check_overlaps(table: pd.DataFrame, key: str, what_key: str, name: str, what: str) -> None:
    """Refuse two deployments of one ``key`` (a serial, a sync tag) whose windows overlap, with both lines."""
    order = table.sort_values([key, "start"], kind="stable")
    same = (order[key].to_numpy()[1:] == order[key].to_numpy()[:-1])
    overlap = same & (order["start"].to_numpy()[1:] < order["end"].to_numpy()[:-1])
    if overlap.any():
        k = int(np.flatnonzero(overlap)[0])
        a, b = order.iloc[k], order.iloc[k + 1]
        raise ModelError(f"{what}: {name!r} lines {a['line']} and {b['line']}: {what_key} {a[key]} is deployed twice "
                         f"at once (from {iso_utc([b['start']])[0] or 'the start'}, before the recovery "
                         f"{iso_utc([a['end']])[0] or 'at the end'}); allowed: one place at a time")


__all__ = ["ALIASES", "BOTTOM_RANGE", "COLUMNS", "DEPTH_RANGE", "Deployments", "MAX_DEPLOYMENTS", "read_deployments"]
