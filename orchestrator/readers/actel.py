"""actel's workspace, the files an actel user keeps in one folder (Flávio & Baktoft 2021, Methods Ecol. Evol.
12:196; actel's manual, "Preparing your data", and its ``exampleWorkspace``), read into a study's tables:

* ``deployments.csv``: ``Receiver`` (the serial; ``VR2W-300101`` keeps ``300101``, as actel does), ``Station.name``,
  ``Start``, ``Stop``: a receiver's deployment at a station, its times in the study's **local time zone** (actel's
  ``tz``: :mod:`.local_times`; an empty ``Stop`` is an open deployment, said);
* ``spatial.csv``: ``Station.name``, ``Latitude``, ``Longitude`` [° WGS 84] (or ``x``, ``y`` in a stated CRS),
  ``Array``, ``Section``, ``Type`` (``Hydrophone`` or ``Release``; without it every row a hydrophone), joined to the
  deployments by station (:func:`read_actel_deployments`); a release site (``Type`` ``Release``) is no receiver;
* ``biometrics.csv``: ``Release.date`` (local time), ``Release.site``, ``Serial.nr``, ``Signal`` (one signal, or a
  multi-sensor tag's signals joined by ``|``: ``611|612``, as actel's ``loadBio`` splits them), ``Code.space``
  (optional), ``Group`` and the animal's measurements: a tag sheet (:func:`read_biometrics`), each signal a
  transmitter of its own (its ping type inferred from the detections), the release kept;
* the detections (a ``detections`` folder of files, or ``detections.csv``) in actel's standard format: ``Timestamp``
  (UTC, as actel reads it; ``T`` and ``Z`` allowed), ``Receiver`` (the serial), ``CodeSpace`` (``R64K``,
  ``A69-1602``), ``Signal`` (the transmitter's id), ``Sensor.Value``, ``Sensor.Unit`` (``NA`` for missing), read by
  :func:`actel` for :func:`~sblsim.orchestrator.readers.detections.read_detections`; or in Thelma's
  (:mod:`.thelma`), VUE's or Fathom's. A detections file's format is told from its header's names, as actel's
  ``compileDetections`` tells them (:func:`format_by_header`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import iso_utc, utc_seconds
from sblsim.orchestrator.readers import thelma
from sblsim.orchestrator.readers.cells import (
    column,
    file_table,
    named,
    numbers,
    pattern,
    refuse,
    shown_header,
    text_table,
)
from sblsim.orchestrator.readers.deployments import ALIASES, MAX_DEPLOYMENTS, Deployments, read_deployments
from sblsim.orchestrator.readers.limits import MAX_COORDINATE
from sblsim.orchestrator.readers.local_times import local_seconds
from sblsim.orchestrator.readers.network import RECEIVER
from sblsim.orchestrator.readers.sensors import sensor_columns
from sblsim.orchestrator.readers.tag_sheet import MAX_TAGS, TagSheet, TagSpec
from sblsim.orchestrator.readers.transmitters import CODE_SPACE, TAG_ID, full_ids

#: The files of actel's workspace, in its folder.
DEPLOYMENTS_FILE, SPATIAL_FILE, BIOMETRICS_FILE = "deployments.csv", "spatial.csv", "biometrics.csv"
DETECTIONS_FOLDER, DETECTIONS_FILE = "detections", "detections.csv"
#: The columns (lower case) that tell actel's standard detections, as its ``header_formats`` lists them.
FINGERPRINT = ("timestamp", "codespace", "receiver", "signal")
#: The columns (:func:`~sblsim.orchestrator.readers.cells.normal_name`) that tell actel's deployments.
DEPLOYMENT_FINGERPRINT = ("receiver", "station_name", "start", "stop")
#: The kinds of a station in ``spatial.csv``'s ``Type``.
TYPES = ("hydrophone", "release")
#: The cell actel (R's ``write.csv``) writes for a missing value.
NA = "NA"


def header_names(first: str) -> set[str]:
    """A header line's names, stripped and in lower case (pandas parses the line); empty where it is none."""
    try:
        return {h.lower() for h in text_table(first + "\n", "", "detections", 1)[0]} if first.strip() else set()
    except ModelError:
        return set()


def format_by_header(first: str) -> str | None:
    """``"thelma"`` or ``"actel"`` where a detections file's first line holds all the columns of one of Thelma's
    layouts or of actel's standard format (actel's fingerprints), else None."""
    names = header_names(first)
    if thelma.is_thelma(names):
        return "thelma"
    if set(FINGERPRINT) <= names:
        return "actel"
    return None


def is_actel_deployments(header: list[str]) -> bool:
    """Whether a receivers table's header is actel's deployments' (``Receiver``, ``Station.name``, ``Start``,
    ``Stop``: times in local time)."""
    return all(named(header, (key,)) is not None for key in DEPLOYMENT_FINGERPRINT)


def actel(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
          ) -> tuple[pd.DataFrame, set[int]]:
    """actel's standard detections (the module docstring) as detections, in the file's order.

    Returns
    -------
    frame : pandas.DataFrame
        ``receiver``, ``tag`` (the full ID ``CODESPACE-SIGNAL``), ``code_space``, ``time`` [s since 1970 UTC],
        ``sensor_value`` (NaN where ``NA``), ``sensor_unit`` (``""`` where ``NA``).
    used : set of int
        The columns read.

    Raises
    ------
    ModelError
        One line naming the file, its line and column: a column missing, a cell outside its pattern or range.
    """
    index = {key: column(header, (key,)) for key in (*FINGERPRINT, "sensor.value", "sensor.unit")}
    missing = [h for h, key in zip(("Timestamp", "CodeSpace", "Receiver", "Signal"), FINGERPRINT) if index[key] is None]
    if missing:
        raise ModelError(f"{what}: {name!r}: actel's detections need the columns Timestamp, Receiver, CodeSpace and "
                         f"Signal; {', '.join(missing)} missing, got {shown_header(header)}")
    time = utc_seconds(body[index["timestamp"]], f"{what}: {name!r}", lines, header[index["timestamp"]])
    receiver = pattern(body[index["receiver"]], RECEIVER, what, name, lines, header[index["receiver"]],
                       "a receiver's serial (or MODEL-SERIAL)").str.rpartition("-")[2]
    space = pattern(body[index["codespace"]], CODE_SPACE, what, name, lines, header[index["codespace"]],
                    "a code space, e.g. R64K or A69-1602")
    signal = pattern(body[index["signal"]], TAG_ID, what, name, lines, header[index["signal"]],
                     "a transmitter's signal (its id), e.g. 610")
    frame = pd.DataFrame({"receiver": receiver.to_numpy(), "tag": full_ids(space, signal).to_numpy(),
                          "code_space": space.to_numpy(), "time": time})
    sensors = body.copy(deep=False)
    for key in ("sensor.value", "sensor.unit"):
        if index[key] is not None:
            cells = body[index[key]].astype(str).str.strip()
            sensors[index[key]] = cells.where(cells != NA, "")
    frame["sensor_value"], frame["sensor_unit"] = sensor_columns(sensors, index["sensor.value"], index["sensor.unit"],
                                                                 header, lines, name, what)
    return frame, {k for k in index.values() if k is not None}


def _stations(path: Path) -> tuple[pd.DataFrame, list[str], list[str]]:
    """``spatial.csv``'s stations: a table by station name (``kind``, its ``line``, each position column's text)
    and the position columns (header names as sblsim's deployments read them) with their names in the file.

    Raises
    ------
    ModelError
        No ``Station.name`` or no positions, a station named twice, a ``Type`` neither Hydrophone nor Release.
    """
    what, name = "stations", str(path)
    header, body, lines = file_table(path, what, MAX_DEPLOYMENTS)
    index = {key: named(header, ALIASES[key]) for key in ("lat", "lon", "x", "y")}
    station, kind = named(header, ("station_name",)), named(header, ("type",))
    axes = ["lat", "lon"] if index["lat"] is not None and index["lon"] is not None else \
        ["x", "y"] if index["x"] is not None and index["y"] is not None else None
    if station is None or axes is None:
        raise ModelError(f"{what}: {name!r}: actel's spatial file needs the columns Station.name, Latitude and "
                         f"Longitude (or x and y, with --crs); got {shown_header(header)}")
    names = body[station].astype(str).str.strip()
    twice = names[names.duplicated(keep=False)]
    if len(twice):
        first, second = (lines[int(k)] for k in twice.index[:2])
        raise ModelError(f"{what}: {name!r} lines {first} and {second}: the station {twice.iloc[0][:40]!r} is listed "
                         "twice; allowed: one row per station")
    kinds = pd.Series(["hydrophone"] * len(body)) if kind is None else body[kind].astype(str).str.strip().str.lower()
    bad = np.flatnonzero(~kinds.isin(TYPES).to_numpy(bool))
    if len(bad):
        k = int(bad[0])
        raise refuse(what, name, lines[k], header[kind], body.iloc[k, kind], "Hydrophone or Release")
    table = pd.DataFrame({"kind": kinds.to_numpy(), "line": lines}, index=names.to_numpy())
    for axis in axes:
        table[axis] = body[index[axis]].astype(str).str.strip().to_numpy()
    return table, axes, [header[index[a]] for a in axes]


def read_actel_deployments(path: Path | str, spatial: Path | str | None, tz: str | None, crs: str | None = None,
                           frame: str | None = None) -> Deployments:
    """actel's deployments joined with its stations (the module docstring): one row per deployment, projected.

    Parameters
    ----------
    path : str or Path
        ``deployments.csv`` (``Receiver``, ``Station.name``, ``Start``, ``Stop``); where it has ``Latitude`` and
        ``Longitude`` itself (joined by hand), ``spatial`` may be None.
    spatial : str or Path or None
        ``spatial.csv``: the stations' positions and types.
    tz : str or None
        The study's IANA time zone of ``Start`` and ``Stop`` (None: each must carry its offset).
    crs, frame : str, optional
        The positions' CRS and the metric frame (:func:`~sblsim.orchestrator.readers.deployments.read_deployments`).

    Returns
    -------
    Deployments
        Its notes say where the positions came from, the release sites left out, the time zone and each open
        deployment.

    Raises
    ------
    ModelError
        One line naming the file, its line and column: a column missing, a deployment at a station ``spatial.csv``
        does not list or lists as a release site, a time without an offset and no ``tz``, a cell outside its pattern
        or range, the checks of :func:`~sblsim.orchestrator.readers.deployments.read_deployments` (a Stop before
        its Start, one receiver deployed twice at once).
    """
    path, what = Path(path), "receivers"
    name = str(path)
    header, body, lines = file_table(path, what, MAX_DEPLOYMENTS)
    index = {key: named(header, (key,)) for key in DEPLOYMENT_FINGERPRINT}
    missing = [h for h, key in zip(("Receiver", "Station.name", "Start", "Stop"), DEPLOYMENT_FINGERPRINT)
               if index[key] is None]
    if missing:
        raise ModelError(f"{what}: {name!r}: actel's deployments need the columns Receiver, Station.name, Start and "
                         f"Stop; {', '.join(missing)} missing, got {shown_header(header)}")
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no deployments")
    serial = pattern(body[index["receiver"]], RECEIVER, what, name, lines, header[index["receiver"]],
                     "a receiver's serial (or MODEL-SERIAL, e.g. VR2W-300101)").str.rpartition("-")[2]
    station = body[index["station_name"]].astype(str).str.strip()
    where = f"{what}: {name!r}"
    start = local_seconds(body[index["start"]], tz, where, lines, header[index["start"]], missing=True)
    stop = local_seconds(body[index["stop"]], tz, where, lines, header[index["stop"]], missing=True)
    notes = []
    if spatial is not None:
        stations, axes, shown = _stations(Path(spatial))
        _check_stations(station, stations, lines, name, header[index["station_name"]], str(spatial))
        at = stations.loc[station.to_numpy()]
        positions = {axis: at[axis].to_numpy() for axis in axes}
        source, source_lines = str(spatial), at["line"].tolist()
        releases = stations.index[stations["kind"] == "release"].tolist()
        idle = sorted(set(stations.index[stations["kind"] == "hydrophone"]) - set(station))
        notes.append(f"positions from {spatial} ({', '.join(shown)}), joined by Station.name: {len(body)} deployments "
                     f"at {station.nunique()} hydrophone stations" + (
                         f"; {len(releases)} release site{'s' if len(releases) > 1 else ''} (Type Release) left "
                         "out: no receiver" if releases else "") + (
                         f"; {len(idle)} hydrophone stations without a deployment ({', '.join(idle[:6])})"
                         if idle else ""))
    else:
        own = {key: named(header, ALIASES[key]) for key in ("lat", "lon", "x", "y")}
        axes = ["lat", "lon"] if own["lat"] is not None and own["lon"] is not None else \
            ["x", "y"] if own["x"] is not None and own["y"] is not None else None
        if axes is None:
            raise ModelError(f"{where}: actel's deployments hold no positions; allowed: with the stations' file "
                             f"(--spatial {SPATIAL_FILE}: Station.name, Latitude, Longitude, Type), or Latitude and "
                             "Longitude columns of its own")
        positions = {axis: body[own[axis]].astype(str).str.strip().to_numpy() for axis in axes}
        shown, source, source_lines = [header[own[a]] for a in axes], name, lines
    limits = {"lat": (-90.0, 90.0, "°"), "lon": (-180.0, 180.0, "°"), "x": (-MAX_COORDINATE, MAX_COORDINATE, "m"),
              "y": (-MAX_COORDINATE, MAX_COORDINATE, "m")}
    for axis, column_name in zip(axes, shown):
        numbers(pd.Series(positions[axis]), "stations" if spatial is not None else what, source, source_lines,
                column_name, *limits[axis][:2], unit=limits[axis][2])
    joined = pd.DataFrame({"serial": serial.to_numpy(), "station": station.to_numpy(), **positions,
                           "start": _epoch(start), "end": _epoch(stop)})
    rows = joined.astype(str)
    rows.columns = range(rows.shape[1])
    deployments = read_deployments(path, crs, frame, rows=(list(joined.columns), rows, lines))
    opened = [lines[k] for k in np.flatnonzero(np.isnan(stop))]
    if tz is not None:
        notes.append(f"Start and Stop read in {tz} (the study's time zone; summer time where it keeps it), "
                     "converted to UTC")
    if opened:
        notes.append(f"{len(opened)} deployments without a Stop ({header[index['stop']]} empty at line"
                     f"{'s' if len(opened) > 1 else ''} {', '.join(map(str, opened[:8]))}): open, in the water to "
                     "the end of the detections")
    if np.isnan(start).any():
        notes.append(f"{int(np.isnan(start).sum())} deployments without a Start: open from the first detection")
    deployments.notes[:0] = notes
    return deployments


def _check_stations(station: pd.Series, stations: pd.DataFrame, lines: list[int], name: str, column_name: str,
                    spatial: str) -> None:
    """Every deployment at a hydrophone station of ``spatial.csv`` (else refused: its line, the station)."""
    known = station.isin(stations.index).to_numpy(bool)
    release = station.isin(stations.index[stations["kind"] == "release"]).to_numpy(bool)
    bad = np.flatnonzero(~known | release)
    if len(bad):
        k = int(bad[0])
        why = "is a release site (Type Release) in" if known[k] else "is not listed in"
        raise ModelError(f"receivers: {name!r} line {lines[k]} column {column_name}: the station "
                         f"{station.iloc[k][:40]!r} {why} {spatial!r}; allowed: a hydrophone station of that file")


def _epoch(seconds: np.ndarray) -> list[str]:
    """Seconds since 1970 UTC as epoch text (``""`` where NaN: open), to the microsecond."""
    return ["" if not np.isfinite(s) else f"{s:.6f}" for s in seconds]


@dataclass
class Biometrics(TagSheet):
    """actel's ``biometrics.csv`` as a tag sheet (:class:`~sblsim.orchestrator.readers.tag_sheet.TagSheet`: one
    animal tag per signal, its ping type inferred) and what the sheet says besides.

    Attributes
    ----------
    releases : pandas.DataFrame
        One row per transmitter: ``transmitter``, ``serial_nr``, ``release_utc`` (ISO 8601 UTC; ``""`` where not
        given), ``release_site``, ``group``, ``line``.
    notes : list of str
        What the reader decided that a user should know (multi-signal tags split, the time zone).
    """

    releases: pd.DataFrame = field(default_factory=pd.DataFrame)
    notes: list[str] = field(default_factory=list)


def read_biometrics(path: Path | str, tz: str | None) -> Biometrics:
    """Read actel's ``biometrics.csv`` (the module docstring) as a tag sheet.

    Parameters
    ----------
    path : str or Path
        The file.
    tz : str or None
        The study's IANA time zone of ``Release.date`` (None: each must carry its offset).

    Returns
    -------
    Biometrics

    Raises
    ------
    ModelError
        One line naming the file, its line and column: no ``Signal`` column, a signal or code space outside its
        pattern, a transmitter listed twice, a release date without an offset and no ``tz``.
    """
    path, what = Path(path), "tags"
    name = str(path)
    header, body, lines = file_table(path, what, MAX_TAGS)
    index = {key: named(header, (key,)) for key in ("signal", "code_space", "release_date", "release_site",
                                                     "serial_nr", "group")}
    if index["signal"] is None:
        raise ModelError(f"{what}: {name!r}: actel's biometrics need a Signal column (each tag's signal, or its "
                         f"signals joined by |); got {shown_header(header)}")
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no tags")

    def text(key: str) -> pd.Series:
        return pd.Series([""] * len(body)) if index[key] is None else \
            body[index[key]].astype(str).str.strip().str.slice(0, 80)

    space = text("code_space")
    if index["code_space"] is not None:
        space = pattern(space, CODE_SPACE, what, name, lines, header[index["code_space"]], "a code space, e.g. R64K")
    released = local_seconds(body[index["release_date"]], tz, f"{what}: {name!r}", lines,
                             header[index["release_date"]], missing=True) if index["release_date"] is not None else \
        np.full(len(body), np.nan)
    signals = body[index["signal"]].astype(str).str.strip().str.split("|", regex=False).explode()
    rows = signals.index.to_numpy()
    signals = pattern(signals.str.strip().reset_index(drop=True), TAG_ID, what, name, [lines[k] for k in rows],
                      header[index["signal"]], "a signal (the tag's id, e.g. 610), or several joined by |")
    transmitter = full_ids(space.iloc[rows].reset_index(drop=True), signals)
    twice = np.flatnonzero(transmitter.duplicated(keep=False).to_numpy(bool))
    if len(twice):
        a, b = (lines[int(rows[k])] for k in twice[:2])
        raise ModelError(f"{what}: {name!r} lines {a} and {b}: transmitter {transmitter.iloc[int(twice[0])]} is "
                         "listed twice; allowed: each signal once")
    label = text("serial_nr")
    tags = [TagSpec(t, name=str(label.iloc[k]), line=lines[k]) for t, k in zip(transmitter, rows)]
    releases = pd.DataFrame({"transmitter": transmitter.to_numpy(), "serial_nr": label.iloc[rows].to_numpy(),
                             "release_utc": iso_utc(released[rows]), "release_site": text("release_site").iloc[rows]
                             .to_numpy(), "group": text("group").iloc[rows].to_numpy(),
                             "line": [lines[k] for k in rows]})
    notes = []
    several = int((np.bincount(rows) > 1).sum())
    if several:
        notes.append(f"{name}: {several} tags with several signals (joined by |): each signal tracked as a "
                     "transmitter of its own")
    return Biometrics([*tags], name, releases, notes)


__all__ = ["BIOMETRICS_FILE", "Biometrics", "DEPLOYMENTS_FILE", "DEPLOYMENT_FINGERPRINT", "DETECTIONS_FILE",
           "DETECTIONS_FOLDER", "FINGERPRINT", "NA", "SPATIAL_FILE", "TYPES", "actel", "format_by_header",
           "header_names", "is_actel_deployments", "read_actel_deployments", "read_biometrics"]
