"""The Vemco/Innovasea VUE export CSV: ``Date and Time (UTC)`` (ISO 8601: ``YYYY-MM-DD hh:mm:ss[.ffffff]`` or
``…T…Z``; a header ``Date and Time (UTC+hh:mm)`` gives a fixed zone, converted to UTC), ``Receiver``
(``VR2W-128355``: the model and the serial, the serial kept), ``Transmitter`` (the full ID ``A69-1602-59335``: the
tag, its code space also in a column of its own), ``Sensor Value`` and ``Sensor Unit`` (kept per detection: a depth
in metres, or a raw ``ADC`` value), ``Station Name``; the other columns are ignored
(:func:`~sblsim.orchestrator.readers.detections.read_detections`)."""

from __future__ import annotations

import re

import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import pattern, trimmed
from sblsim.orchestrator.readers.sensors import sensor_columns
from sblsim.orchestrator.readers.transmitters import TRANSMITTER, after_last_dash, before_last_dash

ZONE = re.compile(r"date and time \(utc(?:([+-])([0-9]{2}):?([0-9]{2}))?\)")
#: The VUE export's columns (lower case) this reader uses; the others of the export are ignored.
VUE_COLUMNS = ("receiver", "transmitter", "sensor value", "sensor unit", "station name")
#: A receiver as VUE names it: ``MODEL-SERIAL`` (``VR2W-128355``), or the serial alone.
RECEIVER = re.compile(r"(?:[A-Za-z0-9._]{1,20}-)?[A-Za-z0-9._]{1,40}")


def vue(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
         ) -> tuple[pd.DataFrame, set[int]]:
    lower = [h.lower() for h in header]
    when = next((k for k, h in enumerate(lower) if h.startswith("date and time")), None)
    zone = ZONE.fullmatch(lower[when]) if when is not None else None
    index = {key: (lower.index(key) if key in lower else None) for key in VUE_COLUMNS}
    missing = [key for key in ("receiver", "transmitter") if index[key] is None]
    if zone is None or missing:
        raise ModelError(f"{what}: {name!r}: a VUE export needs the columns 'Date and Time (UTC)' (or 'Date and "
                         f"Time (UTC+hh:mm)'), 'Receiver' and 'Transmitter'; "
                         f"{'the date column' if zone is None else ', '.join(missing)} not found")
    seconds = utc_seconds(body[when], f"{what}: {name!r}", lines, header[when])
    if zone.group(1):
        shift = (int(zone.group(2)) * 3600 + int(zone.group(3)) * 60) * (1 if zone.group(1) == "+" else -1)
        seconds = seconds - shift  # local time = UTC + shift
    receiver = pattern(body[index["receiver"]], RECEIVER, what, name, lines, header[index["receiver"]],
                        "a receiver as MODEL-SERIAL, e.g. VR2W-128355")
    transmitter = pattern(body[index["transmitter"]], TRANSMITTER, what, name, lines, header[index["transmitter"]],
                           "a transmitter as CODESPACE-ID, e.g. A69-1602-59335")
    frame = pd.DataFrame({"receiver": after_last_dash(receiver).array, "tag": transmitter.array,
                          "code_space": before_last_dash(transmitter).array, "time": seconds})
    frame["sensor_value"], frame["sensor_unit"] = sensor_columns(
        body, index["sensor value"], index["sensor unit"], header, lines, name, what)
    frame["receiver_model"] = before_last_dash(receiver).array
    if index["station name"] is not None:
        frame["station"] = trimmed(body[index["station name"]], 80)
    used = {when} | {k for k in index.values() if k is not None}
    return frame, used


__all__ = ["RECEIVER", "VUE_COLUMNS", "ZONE", "vue"]
