"""A detection's sensor value and unit as the exports give them (VUE's ``Sensor Value``/``Sensor Unit``, Fathom's,
GLATOS's ``sensor_value``/``sensor_unit``, OTN's ``sensorValue``/``sensorUnit``), checked."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from sblsim.orchestrator.readers.cells import numbers, pattern

#: A sensor's unit: at most 20 printable characters.
UNIT = re.compile(r"[^\x00-\x1f\x7f]{0,20}")


def sensor_columns(body: pd.DataFrame, value: int | None, unit: int | None, header: list[str], lines: list[int],
                   name: str, what: str) -> tuple[np.ndarray, np.ndarray]:
    """A sensor's value (NaN where empty) and unit (``""`` where none) per detection, checked."""
    values = np.full(len(body), np.nan) if value is None else numbers(
        body[value], what, name, lines, header[value], -1e6, 1e6, missing=True)
    units = np.full(len(body), "", dtype=object) if unit is None else pattern(
        body[unit], UNIT, what, name, lines, header[unit], "a unit of at most 20 printable characters").to_numpy()
    return values, units


__all__ = ["UNIT", "sensor_columns"]
