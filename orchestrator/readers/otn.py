"""OTN detection extracts (OTN's detection extract documentation; glatos's ``otn_detection_schema``), both layouts,
header case ignored:

* 2025: ``dateCollectedUTC``, ``receiver``, ``tagName`` (the full ID; else ``codeSpace`` and the id), ``sensorValue``,
  ``sensorUnit``, ``station`` (``decimalLatitude``, ``decimalLongitude`` and the animal's columns not read);
* before 2025: ``datecollected`` with ``timezone`` (which must say UTC), ``receiver``, ``tagname``, ``codespace``,
  ``sensorvalue``, ``sensorunit``, ``station``; an extract not matched to animals names the receiver
  ``collectornumber`` and the tag ``fieldnumber``.

A receiver cell annotated after its serial (``5321(lost/found)``) is read as the serial, the note kept
(:func:`~.network.annotated`); the rows are put in each receiver's order after reading (:func:`~.network.ordered`)."""

from __future__ import annotations

import pandas as pd

from sblsim.orchestrator.readers.network import extract

#: Each field's header names, both layouts (case ignored; :data:`~.network.FIELDS`).
SCHEMA = {"time": ("datecollectedutc", "datecollected"), "receiver": ("receiver", "collectornumber"),
          "full_id": ("tagname", "fieldnumber"), "space": ("codespace",), "id": ("tagid",),
          "value": ("sensorvalue",), "unit": ("sensorunit",), "station": ("station",), "zone": ("timezone",)}


def otn(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
        ) -> tuple[pd.DataFrame, set[int]]:
    """An OTN detection extract (the module docstring) as detections, in the file's order."""
    return extract(header, body, lines, name, what, "OTN", SCHEMA)


__all__ = ["SCHEMA", "otn"]
