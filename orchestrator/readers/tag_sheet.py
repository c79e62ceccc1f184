"""A study's tag sheet: each transmitter's ping type, role and sensor, as a CSV with Vemco tag specifications' names.

One row per transmitter (header names matched case-insensitively, a trailing unit in brackets ignored):

* ``transmitter`` (or ``tag``, ``vue_tag_id``, ``full_id``): the full ID (``A69-1602-4555``) or the id alone;
* the ping type: ``ping_type`` (``sbi``, ``rbi`` or ``pbi``) and its figures: ``min_delay`` and ``max_delay`` [s]
  (Vemco's ``Step 1 Min Delay (sec)``/``Max Delay``; a random interval, or a stable one where they are equal),
  ``interval`` [s] (a nominal stable interval) or ``burst_sequence`` (a file of a pseudo-random tag's intervals, one
  per row, named relative to the sheet's folder and refused where it, links followed, leaves that folder). Without
  ``ping_type`` the figures decide it (equal delays or an interval: ``sbi``; a range: ``rbi``; a sequence:
  ``pbi``); without any, the tracker infers it from the detections;
* ``role``: ``animal`` (default), ``sync`` (a sync tag: used by the clocks' synchronisation, not tracked) or
  ``reference`` (a tag at a fixed place: tracked as stationary unless ``motion`` says ``moving``);
* ``motion``: ``moving`` or ``stationary``, overriding the role's;
* a sensor: ``sensor_type`` (``P``/``pressure``/``depth``, ``T``/``temperature``, ``A``/``acceleration``),
  ``sensor_slope`` and ``sensor_intercept`` (Vemco's ``Slope``, ``Intercept``): a raw value ``r`` the detections
  carry (VUE's ``ADC`` unit, Fathom's ``Raw Data``) is ``slope × r + intercept`` in the sensor's unit (a depth in
  metres, positive down; a ``sensor_unit`` given for a depth sensor must be metres); a value a file gives converted
  (unit ``m``) is taken as it is;
* ``name`` (or ``animal_id``): a label kept in the outputs;
* a reference tag's surveyed position (its study's accuracy check: :mod:`sblsim.orchestrator.telemetry.reference_tags`):
  ``lat``, ``lon`` (or ``latitude``, ``longitude``) [° WGS 84], both or neither, and ``depth_m`` [m, positive down];
  or ``receiver`` (or ``station``, ``deployment``): the deployment it sits at (its name, serial or station), whose
  position it takes; ``survey_sigma_m`` [m]: that position's error per horizontal axis.

The sheet may also be a workbook (``.xls``, ``.xlsx``: :mod:`.workbook`): Innovasea's tag specifications (sheet
``Tag Summary``: ``VUE Tag ID``, each step's ``Min Delay`` and ``Max Delay``, ``Sensor type``, ``Units``, ``Slope``,
``Intercept``), OTN's tagging metadata (sheet ``Tag Metadata``: ``TAG_CODE_SPACE``, ``TAG_ID_CODE``, ``ANIMAL_ID``)
or a sheet with the columns above; or OTN's tag releases table (``tag_device_id``: :mod:`.otn_tags`). A receiver's
binary log (VRL, VDAT) is refused, named (:mod:`.binary`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.schedule import PING_TYPES
from sblsim.orchestrator.io.paths import inside
from sblsim.orchestrator.readers.binary import LOGS, first_bytes, kind_of, log_refused
from sblsim.orchestrator.readers.burst_sequence import BURST_RANGE, read_burst_sequence
from sblsim.orchestrator.readers.cells import (
    UNITS,
    file_table,
    named,
    numbers,
    pattern,
    refuse,
    shown_header,
    whole_ids,
)
from sblsim.orchestrator.readers.deployments import DEPTH_RANGE, _blank
from sblsim.orchestrator.readers.otn_tags import otn_table, releases
from sblsim.orchestrator.readers.transmitters import TRANSMITTER
from sblsim.orchestrator.readers.workbook import located, read_workbook

#: The most transmitters a sheet lists.
MAX_TAGS = 10_000
#: The roles a tag may have.
ROLES = ("animal", "sync", "reference")
#: The motion models of ``motion`` (as :data:`sblsim.orchestrator.tracks.track.MOTIONS`).
MOTIONS = ("moving", "stationary")
#: The sensor types, by the names a sheet may give them.
SENSORS = {"p": "depth", "pressure": "depth", "depth": "depth", "d": "depth", "t": "temperature",
           "temperature": "temperature", "temp": "temperature", "a": "acceleration", "acceleration": "acceleration",
           "accel": "acceleration"}
#: The units of a sensor value taken as raw (converted by the sheet's slope and intercept).
RAW_UNITS = ("", "adc", "raw")
#: Each field's header names (normalised), first preferred.
ALIASES = {
    "transmitter": ("transmitter", "tag", "vue_tag_id", "full_id", "transmitter_id", "tag_id"),
    "ping_type": ("ping_type",), "min_delay": ("min_delay", "step_1_min_delay", "min_delay_s"),
    "max_delay": ("max_delay", "step_1_max_delay", "max_delay_s"), "interval": ("interval", "interval_s",
                                                                                "nominal_interval", "delay"),
    "burst_sequence": ("burst_sequence", "sequence"), "role": ("role",), "motion": ("motion",),
    "sensor_type": ("sensor_type",), "slope": ("sensor_slope", "slope"), "intercept": ("sensor_intercept",
                                                                                       "intercept"),
    "name": ("name", "animal_id"), "unit": ("sensor_unit", "sensor_units"),
    "lat": ("lat", "latitude"), "lon": ("lon", "long", "longitude"), "depth": ("depth_m", "surveyed_depth"),
    "receiver": ("receiver", "station", "deployment"), "survey_sigma": ("survey_sigma_m", "survey_sigma"),
}
#: The largest survey error a sheet may state [m] (per horizontal axis).
MAX_SURVEY_SIGMA = 1000.0


@dataclass(frozen=True)
class TagSpec:
    """One transmitter of a tag sheet.

    Attributes
    ----------
    transmitter : str
        As the sheet names it (a full ID or an id).
    role : str
        One of :data:`ROLES`.
    motion : str
        ``moving`` or ``stationary``.
    ping_type : str or None
        ``sbi``, ``rbi``, ``pbi``, or None (inferred from the detections).
    burst_interval : (float, float) or None
        [s] a random interval's bounds (``rbi``).
    interval : float or None
        [s] a stable interval (``sbi``) where given.
    burst_sequence : Path or None
        A ``pbi`` tag's intervals (a file in the sheet's folder).
    sensor : str
        ``depth``, ``temperature``, ``acceleration`` or ``""``.
    slope, intercept : float
        The raw value's conversion (NaN where not given).
    name : str
        A label (``""``).
    line : int
        The sheet's line.
    lat, lon : float
        A reference tag's surveyed position [° WGS 84] (NaN where not given).
    depth : float
        Its depth [m, positive down] (NaN).
    receiver : str
        The deployment it sits at (a name, serial or station; ``""``).
    survey_sigma : float
        Its surveyed position's error per horizontal axis [m] (NaN: not stated).
    """

    transmitter: str
    role: str = "animal"
    motion: str = "moving"
    ping_type: str | None = None
    burst_interval: tuple[float, float] | None = None
    interval: float | None = None
    burst_sequence: Path | None = None
    sensor: str = ""
    slope: float = float("nan")
    intercept: float = float("nan")
    name: str = ""
    line: int = 0
    lat: float = float("nan")
    lon: float = float("nan")
    depth: float = float("nan")
    receiver: str = ""
    survey_sigma: float = float("nan")

    def shortest_interval(self) -> float | None:
        """[s] the shortest interval the sheet states (the echo limit of the times-of-arrival matrix), None where
        it states none."""
        if self.burst_interval is not None:
            return self.burst_interval[0]
        if self.interval is not None:
            return self.interval
        if self.burst_sequence is not None:
            return float(read_burst_sequence(self.burst_sequence).min())
        return None

    def described(self) -> str:
        """The ping type as the console and the tags' table say it."""
        if self.ping_type == "rbi":
            return f"rbi {self.burst_interval[0]:g}-{self.burst_interval[1]:g} s"
        if self.ping_type == "sbi":
            return "sbi" + (f" {self.interval:g} s" if self.interval is not None else "")
        if self.ping_type == "pbi":
            return f"pbi {self.burst_sequence.name}"
        return "inferred"

    def depths(self, values: np.ndarray, units: np.ndarray) -> np.ndarray:
        """(n,) [m, positive down] the depth each detection's sensor value gives (NaN where none): converted by
        the slope and intercept where raw, as given where in metres; all NaN for a tag without a depth sensor.

        Raises
        ------
        ModelError
            Raw values of a depth sensor without a slope and an intercept (one line naming the transmitter).
        """
        values = np.asarray(values, float)
        units = np.char.lower(np.asarray(units, dtype=str))
        out = np.full(len(values), np.nan)
        if self.sensor != "depth":
            return out
        metres = units == "m"
        out[metres] = values[metres]
        raw = np.isin(units, RAW_UNITS) & np.isfinite(values)
        if raw.any():
            if not (np.isfinite(self.slope) and np.isfinite(self.intercept)):
                raise ModelError(f"tags: transmitter {self.transmitter} (line {self.line}) is a depth sensor whose "
                                 "detections carry raw values, and the sheet gives no sensor_slope and "
                                 "sensor_intercept; allowed: both, as the tag's specification states them")
            out[raw] = self.slope * values[raw] + self.intercept
        return out


@dataclass
class TagSheet:
    """A tag sheet read: ``tags`` (one :class:`TagSpec` per row, in the sheet's order) and ``source``."""

    tags: list[TagSpec]
    source: str

    def of_role(self, *roles: str) -> list[TagSpec]:
        """The sheet's tags of these roles, in its order."""
        return [t for t in self.tags if t.role in roles]


def read_tag_sheet(path: Path | str) -> TagSheet:
    """Read a tag sheet (the module docstring): a CSV, Innovasea's or OTN's workbook (:mod:`.workbook`), or OTN's
    tag releases table (:mod:`.otn_tags`), told by the file's first bytes and its header.

    Raises
    ------
    ModelError
        One line naming the file, its line (a workbook's sheet and row) and column and the allowed values: no
        transmitter column, a cell outside its pattern or range, a transmitter listed twice, a ping type its figures
        contradict, a sequence file outside the sheet's folder, a depth sensor's unit that is not metres; a
        receiver's binary log (:mod:`.binary`).
    """
    path, what = Path(path), "tags"
    name = str(path)
    kind = kind_of(first_bytes(path, what), path.suffix)
    if kind in LOGS:
        raise log_refused(name, what, kind)
    if kind in ("xls", "xlsx"):
        table = read_workbook(path, kind, what, ALIASES["transmitter"], MAX_TAGS)
        with located(name, table.sheet):
            return tag_table(table.header, table.body, table.lines, path, what, table.index)
    header, body, lines = file_table(path, what, MAX_TAGS)
    index = None
    if otn_table(header) is not None:
        body, lines, index = releases(header, body, lines, name, what)
    return tag_table(header, body, lines, path, what, index)


def tag_table(header: list[str], body: pd.DataFrame, lines: list[int], path: Path, what: str,
              index: dict[str, int | None] | None = None) -> TagSheet:
    """A tag sheet's rows (text cells, each row's line) checked into :class:`TagSpec` s.

    Parameters
    ----------
    header : list of str
        The column names.
    body : pandas.DataFrame
        The rows, every cell a str.
    lines : list of int
        Each row's line in the file.
    path : Path
        The sheet (its folder: a ``burst_sequence`` file's).
    what : str
        What the file is, as a refusal names it.
    index : dict, optional
        Each field (a key of :data:`ALIASES`) to its column, for a layout whose names are not the sheet's (a field
        not in it is not read); default: each field by its names in :data:`ALIASES`.

    Raises
    ------
    ModelError
        As :func:`read_tag_sheet`.
    """
    name = str(path)
    if index is None:
        index = {key: named(header, aliases) for key, aliases in ALIASES.items()}
    index = {key: index.get(key) for key in ALIASES}
    if index["transmitter"] is None:
        raise ModelError(f"{what}: {name!r}: the header needs a transmitter column (a full ID or an id per row); got "
                         f"{shown_header(header)}")
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no transmitters")
    transmitter = pattern(body[index["transmitter"]], TRANSMITTER, what, name, lines, header[index["transmitter"]],
                          "a transmitter's full ID (A69-1602-4555) or id")
    transmitter = whole_ids(transmitter)[0]  # 4555.0 as 4555, as the detections read it
    twice = transmitter[transmitter.duplicated()]
    if len(twice):
        raise ModelError(f"{what}: {name!r} line {lines[int(twice.index[0])]}: transmitter {twice.iloc[0]} is listed "
                         "twice; allowed: one row per transmitter")

    def text(key: str) -> pd.Series:
        if index[key] is None:
            return pd.Series([""] * len(body))
        return body[index[key]].astype(str).str.strip()

    def values(key: str, low: float, high: float, unit: str) -> np.ndarray:
        if index[key] is None:
            return np.full(len(body), np.nan)
        return numbers(body[index[key]], what, name, lines, header[index[key]], low, high, missing=True, unit=unit)

    def choice(key: str, allowed: dict | tuple, default: str) -> list[str]:
        cells = text(key).str.lower()
        out = []
        for k, cell in enumerate(cells):
            if cell == "":
                out.append(default)
            elif cell in allowed:
                out.append(allowed[cell] if isinstance(allowed, dict) else cell)
            else:
                options = sorted(set(allowed)) if isinstance(allowed, dict) else allowed
                raise refuse(what, name, lines[k], header[index[key]], cell, ", ".join(options) + " or empty")
        return out

    low, high = BURST_RANGE
    least, most, nominal = (values(k, low, high, "s") for k in ("min_delay", "max_delay", "interval"))
    slope, intercept = values("slope", -1e6, 1e6, ""), values("intercept", -1e6, 1e6, "")
    kinds = choice("ping_type", tuple(PING_TYPES), "")
    roles = choice("role", ROLES, "animal")
    motions = choice("motion", MOTIONS, "")
    sensors = choice("sensor_type", SENSORS, "")
    units = text("unit")
    wrong = np.flatnonzero([s == "depth" and u.lower() not in UNITS["metres"] + ("",) for s, u in zip(sensors, units)])
    if len(wrong):
        k = int(wrong[0])
        raise refuse(what, name, lines[k], header[index["unit"]], units.iloc[k], "a depth sensor's unit: "
                     + ", ".join(UNITS["metres"][:3]) + " or empty (the value slope x raw + intercept, in metres)")
    sequences = text("burst_sequence")
    labels = text("name").str.slice(0, 80)
    def surveyed(key: str, low: float, high: float, unit: str) -> np.ndarray:  # NA, NaN: not given
        if index[key] is None:
            return np.full(len(body), np.nan)
        return numbers(_blank(body[index[key]]), what, name, lines, header[index[key]], low, high, missing=True,
                       unit=unit)

    lat, lon = surveyed("lat", -90.0, 90.0, "°"), surveyed("lon", -180.0, 180.0, "°")
    halves = np.flatnonzero(np.isfinite(lat) != np.isfinite(lon))
    if len(halves):
        k = int(halves[0])
        raise ModelError(f"{what}: {name!r} line {lines[k]}: a surveyed position needs both lat and lon; allowed: "
                         "both (WGS 84 degrees) or neither")
    depth = surveyed("depth", *DEPTH_RANGE, "m (positive down)")
    survey = surveyed("survey_sigma", 0.0, MAX_SURVEY_SIGMA, "m")
    at = text("receiver").str.slice(0, 80)
    tags = []
    for k in range(len(body)):
        where = f"{what}: {name!r} line {lines[k]}"
        has_range = np.isfinite(least[k]) or np.isfinite(most[k])
        if has_range and not (np.isfinite(least[k]) and np.isfinite(most[k]) and least[k] <= most[k]):
            raise ModelError(f"{where}: min_delay {least[k]:g} and max_delay {most[k]:g} s; allowed: both, "
                             "min_delay <= max_delay")
        sequence = (inside(path.parent, sequences[k], f"{where} column burst_sequence", "tag sheet") if sequences[k]
                    else None)
        kind = kinds[k] or ("pbi" if sequence is not None else "rbi" if has_range and least[k] < most[k] else
                            "sbi" if has_range or np.isfinite(nominal[k]) else None)
        stable = nominal[k] if np.isfinite(nominal[k]) else least[k] if has_range and least[k] == most[k] else None
        bounds = (float(least[k]), float(most[k])) if has_range and least[k] < most[k] else None
        if kind == "rbi" and bounds is None:
            raise ModelError(f"{where}: ping_type rbi needs min_delay < max_delay [s] (the random interval's bounds)")
        if kind == "pbi" and sequence is None:
            raise ModelError(f"{where}: ping_type pbi needs burst_sequence (a file of the tag's intervals)")
        if kind == "sbi" and bounds is not None:
            raise ModelError(f"{where}: ping_type sbi with min_delay {least[k]:g} < max_delay {most[k]:g} s: a stable "
                             "interval has one delay; allowed: equal delays, an interval, or ping_type rbi")
        if kind != "pbi" and sequence is not None:
            raise ModelError(f"{where}: burst_sequence only with ping_type pbi")
        motion = motions[k] or ("stationary" if roles[k] == "reference" else "moving")
        tags.append(TagSpec(transmitter.iloc[k], roles[k], motion, kind, bounds if kind == "rbi" else None,
                            float(stable) if kind == "sbi" and stable is not None else None, sequence, sensors[k],
                            float(slope[k]), float(intercept[k]), labels.iloc[k], lines[k], float(lat[k]),
                            float(lon[k]), float(depth[k]), at.iloc[k], float(survey[k])))
    return TagSheet(tags, name)


def spec_for(sheet: TagSheet | None, transmitter: str) -> TagSpec:
    """The sheet's row of a transmitter, else an animal tag whose ping type the detections show."""
    found = next((t for t in sheet.tags if t.transmitter == transmitter), None) if sheet is not None else None
    return found or TagSpec(transmitter)


__all__ = ["ALIASES", "MAX_SURVEY_SIGMA", "MAX_TAGS", "MOTIONS", "RAW_UNITS", "ROLES", "SENSORS", "TagSheet", "TagSpec",
           "read_tag_sheet", "spec_for", "tag_table"]
