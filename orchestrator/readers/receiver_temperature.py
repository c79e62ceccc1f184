"""The receivers' own temperature records as a water-temperature series: the file a study's user already holds, read
for the tracker's sound speed (:func:`sblsim.orchestrator.readers.water.read_temperature_series` recognises it by its
first line).

* **Fathom (VDAT) CSV** (first line ``VEMCO DATA LOG,<format version>,...``; the record types and columns of
  glatos's ``vdat_csv_schema``, formats 1.0.0 and 2.0.0): the records ``TEMP`` (``Ambient (deg C)``),
  ``TEMP_STATS`` (``Ambient Mean (deg C)``) and ``DIAG`` (``Ambient Temperature (deg C)``), each type's columns
  given by its ``<TYPE>_DESC`` line (:func:`~sblsim.orchestrator.readers.fathom.fathom_tables`; the other types'
  lines, the detections among them, skipped unread). The water's (ambient) temperature is taken, never the
  receiver's ``Internal (deg C)``; the time is ``Time`` (Fathom's corrected UTC) where the cell holds one, else
  ``Device Time (UTC)``; the receiver is ``Serial Number``. An empty temperature cell is no record.
* **VUE receiver events** (VUE's export of a receiver's events, as glatos's ``read_vue_event_csv`` reads it: the
  header ``Date and Time (UTC),Receiver,Description,Data,Units``): the rows whose ``Description`` is one of
  :data:`VUE_TEMPERATURE_DESCRIPTIONS` (case ignored), their ``Data`` a number in ``Units`` of
  :data:`VUE_TEMPERATURE_UNITS`; the other events (battery, daily pings, ...) skipped. VUE writes it in Windows'
  Latin-1 (``°C``): a file that is not UTF-8 is read as Latin-1.

Several receivers: each one's records (in time order; records at one time averaged) interpolated linearly at the
union of all records' times, held at its first and last value beyond them (``numpy.interp``), and averaged over the
receivers: the array's mean water temperature. Every temperature is checked against
:data:`~sblsim.models.tracking.sound_speed.TEMPERATURE_RANGE`; every refusal is one line naming the file, its line
and column and what is allowed (:class:`ModelError`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.sound_speed import TEMPERATURE_RANGE
from sblsim.orchestrator.io.times import EPOCH, ISO_TIME, utc_seconds
from sblsim.orchestrator.readers.cells import column, numbers, refuse, shown_header, text_table
from sblsim.orchestrator.readers.fathom import FATHOM_MARK, fathom_tables

#: The Fathom record types holding the water's temperature, and each one's column of it (case ignored).
FATHOM_TEMPERATURE_RECORDS = ("TEMP", "TEMP_STATS", "DIAG")
AMBIENT_COLUMNS = {"TEMP": "Ambient (deg C)", "TEMP_STATS": "Ambient Mean (deg C)",
                   "DIAG": "Ambient Temperature (deg C)"}
#: A VUE receiver-events export's columns (its header, case ignored).
VUE_EVENT_COLUMNS = ("Date and Time (UTC)", "Receiver", "Description", "Data", "Units")
#: The VUE events that are the water's temperature (``Description``, case ignored) and their units (``Units``, case
#: and spaces ignored).
VUE_TEMPERATURE_DESCRIPTIONS = ("temperature", "average temperature", "ambient temperature")
VUE_TEMPERATURE_UNITS = ("°C", "C", "deg C", "degC")
#: The encoding a file that is not UTF-8 is read in (VUE's on Windows).
FALLBACK_ENCODING = "latin-1"


def receiver_kind(first: str) -> str | None:
    """The receivers' export a file's first line shows: ``fathom`` (Fathom's mark), ``vue_events`` (VUE's
    receiver-events header), None for neither."""
    if first.lstrip("\ufeff").lstrip('"').startswith(FATHOM_MARK):
        return "fathom"
    cells = [c.strip().strip('"').strip().lower() for c in first.lstrip("\ufeff").split(",")]
    if all(name.lower() in cells for name in VUE_EVENT_COLUMNS):
        return "vue_events"
    return None


def receiver_temperatures(text: str, kind: str, name: str, what: str, max_rows: int,
                          max_cells: int | None = None) -> np.ndarray:
    """The array's water temperature from its receivers' records (the module docstring).

    Parameters
    ----------
    text : str
        The file's text.
    kind : str
        ``fathom`` or ``vue_events`` (:func:`receiver_kind`).
    name, what : str
        The file and what it is, as a refusal names them.
    max_rows, max_cells : int
        The most rows [1] of a table and cells [1] (default :data:`~sblsim.orchestrator.io.tables.MAX_CELLS`).

    Returns
    -------
    ndarray, (k, 2)
        Time [s since 1970-01-01 UTC] (increasing) and the receivers' mean in-situ temperature [°C].

    Raises
    ------
    ModelError
        One line naming the file (and the line and column): no temperature record, a record type without its
        temperature or time column, a cell that is not a time or a number, a unit that is not °C, a temperature
        outside :data:`~sblsim.models.tracking.sound_speed.TEMPERATURE_RANGE`.
    """
    if kind not in ("fathom", "vue_events"):
        raise ModelError(f"{what}: {name!r}: kind {kind!r} is not one of fathom, vue_events")
    records = (_fathom if kind == "fathom" else _vue_events)(text, name, what, max_rows, max_cells)
    if not len(records):
        raise ModelError(f"{what}: {name!r} holds no receiver temperature records (TEMP, TEMP_STATS or DIAG); "
                         "allowed: a Fathom CSV holding those records (each type with its _DESC line), VUE receiver "
                         f"events described {' / '.join(d.title() for d in VUE_TEMPERATURE_DESCRIPTIONS)} in °C, or "
                         "a CSV of time_utc and temperature_c")
    return array_mean(records)


def array_mean(records: pd.DataFrame) -> np.ndarray:
    """The receivers' mean temperature (``records``: ``receiver``, ``time`` [s], ``temperature`` [°C]): each
    receiver's series (records at one time averaged) interpolated at the union of all times, held at its ends, and
    averaged over the receivers; (k, 2) [s, °C]."""
    times = np.unique(records["time"].to_numpy(float))
    sums = np.zeros(len(times))
    receivers = 0
    for _, own in records.groupby("receiver", sort=True):
        series = own.groupby("time", sort=True)["temperature"].mean()
        sums += np.interp(times, series.index.to_numpy(float), series.to_numpy(float))
        receivers += 1
    return np.column_stack([times, sums / receivers])


def _fathom(text: str, name: str, what: str, max_rows: int, max_cells: int | None) -> pd.DataFrame:
    """The temperature records of a Fathom CSV as ``receiver``, ``time``, ``temperature`` rows."""
    tables = fathom_tables(text, name, what, FATHOM_TEMPERATURE_RECORDS, max_rows, max_cells)
    frames = []
    for record, (header, body, lines) in tables.items():
        if not len(body):
            continue
        ambient = column(header, (AMBIENT_COLUMNS[record].lower(),))
        serial = column(header, ("serial number",))
        device, corrected = column(header, ("device time (utc)",)), column(header, ("time",))
        missing = ([AMBIENT_COLUMNS[record]] if ambient is None else []) + \
            (["Serial Number"] if serial is None else []) + \
            (["Device Time (UTC) or Time"] if device is None and corrected is None else [])
        if missing:
            raise ModelError(f"{what}: {name!r}: Fathom's {record}_DESC line needs the columns Device Time (UTC) "
                             f"(or Time), Serial Number and {AMBIENT_COLUMNS[record]} (the water's temperature); "
                             f"{', '.join(missing)} missing, got {shown_header(header)}")
        temperature = numbers(body[ambient], what, name, lines, header[ambient], *TEMPERATURE_RANGE,
                              missing=True, unit="°C")
        kept = np.isfinite(temperature)
        if not kept.any():
            continue
        body = body[kept].reset_index(drop=True)
        lines = [line for line, k in zip(lines, kept) if k]
        frames.append(pd.DataFrame({
            "receiver": body[serial].astype(str).str.strip().to_numpy(),
            "time": _fathom_times(body, lines, header, device, corrected, what, name),
            "temperature": temperature[kept]}))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(
        columns=["receiver", "time", "temperature"])


def _fathom_times(body: pd.DataFrame, lines: list[int], header: list[str], device: int | None,
                  corrected: int | None, what: str, name: str) -> np.ndarray:
    """Each record's time [s since 1970 UTC]: ``Time`` where its cell holds a time, else ``Device Time (UTC)``."""
    where = f"{what}: {name!r}"
    times = np.full(len(body), np.nan)
    use = np.zeros(len(body), bool)
    if corrected is not None:
        cells = body[corrected].astype(str).str.strip()
        use = (cells.str.fullmatch(ISO_TIME.pattern) | cells.str.fullmatch(EPOCH.pattern)).to_numpy(bool)
        if use.any():
            times[use] = utc_seconds(cells[use], where, [lines[k] for k in np.flatnonzero(use)], header[corrected])
    rest = np.flatnonzero(~use)
    if len(rest):
        if device is None:  # a Time cell that is no time, and no Device Time to fall back on
            k = int(rest[0])
            raise refuse(what, name, lines[k], header[corrected], str(body[corrected].iloc[k]).strip(),
                         "a time (ISO 8601 UTC) in Time or Device Time (UTC)")
        times[rest] = utc_seconds(body[device].iloc[rest], where, [lines[k] for k in rest], header[device])
    return times


def _vue_events(text: str, name: str, what: str, max_rows: int, max_cells: int | None) -> pd.DataFrame:
    """The temperature events of a VUE receiver-events export as ``receiver``, ``time``, ``temperature`` rows."""
    header, body, lines = text_table(text, name, what, max_rows, max_cells=max_cells)
    index = {key: column(header, (key.lower(),)) for key in VUE_EVENT_COLUMNS}
    missing = [key for key, k in index.items() if k is None]
    if missing:
        raise ModelError(f"{what}: {name!r}: VUE's receiver events need the columns {', '.join(VUE_EVENT_COLUMNS)}; "
                         f"{', '.join(missing)} missing, got {shown_header(header)}")
    description = body[index["Description"]].astype(str).str.strip().str.lower()
    chosen = np.flatnonzero(description.isin(VUE_TEMPERATURE_DESCRIPTIONS).to_numpy(bool))
    if not len(chosen):
        return pd.DataFrame(columns=["receiver", "time", "temperature"])
    rows = body.iloc[chosen].reset_index(drop=True)
    lines = [lines[k] for k in chosen]
    units = rows[index["Units"]].astype(str).str.strip()
    allowed = {_unit(u) for u in VUE_TEMPERATURE_UNITS}
    bad = ~units.map(_unit).isin(allowed).to_numpy(bool)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise refuse(what, name, lines[k], header[index["Units"]], units.iloc[k],
                     f"a temperature in {', '.join(VUE_TEMPERATURE_UNITS)}")
    temperature = numbers(rows[index["Data"]], what, name, lines, header[index["Data"]], *TEMPERATURE_RANGE,
                          unit="°C")
    time = utc_seconds(rows[index["Date and Time (UTC)"]], f"{what}: {name!r}", lines,
                       header[index["Date and Time (UTC)"]])
    return pd.DataFrame({"receiver": rows[index["Receiver"]].astype(str).str.strip().to_numpy(), "time": time,
                         "temperature": temperature})


def _unit(text: str) -> str:
    """A unit as it is compared: lower case, no spaces."""
    return "".join(text.split()).lower()


__all__ = ["AMBIENT_COLUMNS", "FALLBACK_ENCODING", "FATHOM_TEMPERATURE_RECORDS", "VUE_EVENT_COLUMNS",
           "VUE_TEMPERATURE_DESCRIPTIONS", "VUE_TEMPERATURE_UNITS", "array_mean", "receiver_kind",
           "receiver_temperatures"]
