"""OTN detection extracts: ``dateCollectedUTC``, ``receiver``, ``tagName`` (the full ID; else ``codeSpace`` and the id),
``sensorValue``, ``sensorUnit``, ``station`` (the extracts before 2025: ``datecollected``, ``receiver``, ``tagname``,
``codespace``, ``sensorvalue``, ``sensorunit``, ``station``; header case ignored)."""

from __future__ import annotations

import pandas as pd

from sblsim.orchestrator.readers.network import extract


def otn(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
        ) -> tuple[pd.DataFrame, set[int]]:
    """An OTN detection extract (the module docstring) as detections."""
    return extract(header, body, lines, name, what, "OTN", {
        "time": ("datecollectedutc", "datecollected"), "receiver": ("receiver",), "full_id": ("tagname",),
        "space": ("codespace",), "id": ("tagid",), "value": ("sensorvalue",), "unit": ("sensorunit",),
        "station": ("station",)})


__all__ = ["otn"]
