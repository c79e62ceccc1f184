"""GLATOS detection extracts (the GLATOS data dictionary; glatos's ``glatos_detection_schema``):
``detection_timestamp_utc``, ``receiver_sn``, ``transmitter_codespace``, ``transmitter_id``, ``sensor_value``,
``sensor_unit``, ``station`` (else ``station_no``); the other columns (the animal's, the deployment's position) are
not read. The rows are put in each receiver's order after reading (:func:`~.network.ordered`)."""

from __future__ import annotations

import pandas as pd

from sblsim.orchestrator.readers.network import extract

#: Each field's header names (case ignored; :data:`~.network.FIELDS`).
SCHEMA = {"time": ("detection_timestamp_utc",), "receiver": ("receiver_sn",), "full_id": ("transmitter",),
          "space": ("transmitter_codespace",), "id": ("transmitter_id",), "value": ("sensor_value",),
          "unit": ("sensor_unit",), "station": ("station", "station_no")}


def glatos(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
           ) -> tuple[pd.DataFrame, set[int]]:
    """A GLATOS detection extract (the module docstring) as detections, in the file's order."""
    return extract(header, body, lines, name, what, "GLATOS", SCHEMA)


__all__ = ["SCHEMA", "glatos"]
