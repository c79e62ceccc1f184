"""GLATOS detection extracts: ``detection_timestamp_utc``, ``receiver_sn``, ``transmitter_codespace``,
``transmitter_id``, ``sensor_value``, ``sensor_unit``, ``station`` (else ``station_no``)."""

from __future__ import annotations

import pandas as pd

from sblsim.orchestrator.readers.network import extract


def glatos(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
           ) -> tuple[pd.DataFrame, set[int]]:
    """A GLATOS detection extract (the module docstring) as detections."""
    return extract(header, body, lines, name, what, "GLATOS", {
        "time": ("detection_timestamp_utc",), "receiver": ("receiver_sn",), "full_id": ("transmitter",),
        "space": ("transmitter_codespace",), "id": ("transmitter_id",), "value": ("sensor_value",),
        "unit": ("sensor_unit",), "station": ("station", "station_no")})


__all__ = ["glatos"]
