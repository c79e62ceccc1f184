"""A design problem's detection curves: the site's logistic curve of detection against range (or the one its sound
levels give), and a telemetry array's per receiver (:class:`~sblsim.models.design.detection_curve.ReceiverCurves`).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.design.detection_curve import DetectionCurve, ReceiverCurves
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.design.area import existing_devices
from sblsim.orchestrator.design.keys import MAX_RECEIVERS, MAX_VERTICES


def receiver_curves(problem: Mapping[str, Mapping[str, Any]]) -> DetectionCurve | ReceiverCurves:
    """An ilbl design's detection curves: the site's (:func:`detection_curve`), and with ``detection.per_receiver``
    each receiver in place (``candidates.existing_m``, first in every layout, in its order) with its own logistic
    curve (:class:`~sblsim.models.design.detection_curve.ReceiverCurves`; a range test at that receiver, Kessel et
    al. 2014 as the module's).

    Raises
    ------
    ConfigError
        Naming ``detection.per_receiver``: a row of other than four numbers, more rows than
        :data:`~sblsim.orchestrator.design.keys.MAX_RECEIVERS`, a row at no receiver of ``candidates.existing_m``, two
        rows for one receiver, a
        ``range_50_m`` or ``slope`` outside the logistic curve's allowed range.
    """
    site = site_curve(problem)
    text = problem["detection"]["per_receiver"]
    rows = [r for r in text.replace(",", " ").split(";") if r.strip()]
    if not rows:
        return site
    where = "detection.per_receiver"
    if len(rows) > MAX_RECEIVERS:
        raise ConfigError(f"{where}: {len(rows)} rows; allowed at most {MAX_RECEIVERS}")
    kept = existing_devices(problem["candidates"]["existing_m"])[:, :2]
    curves: list[DetectionCurve | None] = [None] * len(kept)
    for k, row in enumerate(rows):
        try:
            values = [float(x) for x in row.split()]
        except ValueError:
            values = []
        if len(values) != 4 or not all(math.isfinite(v) for v in values):
            raise ConfigError(f"{where}: expected 'north east range_50_m slope; ...' in numbers, got "
                              f"{row.strip()[:40]!r}")
        north, east, range_50_m, slope = values
        at = np.flatnonzero(np.hypot(kept[:, 0] - north, kept[:, 1] - east) <= 1e-6) if len(kept) else []
        if not len(at):
            raise ConfigError(f"{where}: no receiver of candidates.existing_m at {north:g} m North, {east:g} m East; "
                              "allowed the places of the receivers in place")
        if curves[at[0]] is not None:
            raise ConfigError(f"{where}: two curves for the receiver at {north:g} m North, {east:g} m East; allowed "
                              "one per receiver in place")
        try:
            curves[at[0]] = DetectionCurve.logistic(range_50_m, slope, f"{where}[{k}]")
        except ModelError as exc:
            raise ConfigError(str(exc)) from None
    return ReceiverCurves(site, tuple(curves))


def site_curve(problem: Mapping[str, Mapping[str, Any]]) -> DetectionCurve:
    """An ilbl design's site-wide detection curve: the range test's (:func:`detection_curve`), or, with
    ``tag.source_level_db`` and neither ``detection.range_50_m`` nor ``detection.table``, the site's SNR model
    (:meth:`~sblsim.models.design.detection_curve.DetectionCurve.sonar_equation`, the ``[detection]`` keys of
    :data:`~sblsim.orchestrator.design.keys.SNR_KEYS`).

    Raises
    ------
    ConfigError
        As :func:`detection_curve`; naming ``tag.source_level_db`` where the site hears the tag nowhere.
    """
    section, level = problem["detection"], problem["tag"]["source_level_db"]
    if level <= 0.0 or section["range_50_m"] > 0.0 or section["table"]:
        return detection_curve(section)
    try:
        return DetectionCurve.sonar_equation(level, section["frequency_hz"], section["bandwidth_hz"],
                                             section["beaufort"], section["shipping"], section["threshold_db"],
                                             section["fluctuation_db"], section["directivity_db"],
                                             section["temperature_c"], section["salinity"])
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


def detection_curve(section: Mapping[str, Any]) -> DetectionCurve:
    """The detection range curve of a checked ``[detection]`` section
    (:meth:`~sblsim.models.design.detection_curve.DetectionCurve.from_mapping`).

    Raises
    ------
    ConfigError
        Naming ``detection.range_50_m``, ``detection.slope`` or ``detection.table`` and what is allowed.
    """
    values: dict[str, Any] = {}
    if section["table"]:
        rows = [r for r in section["table"].replace(",", " ").split(";") if r.strip()]
        try:
            values["table"] = [[float(x) for x in r.split()] for r in rows[:MAX_VERTICES + 1]]
        except ValueError:
            raise ConfigError("detection.table: expected 'distance_m probability; ...' in numbers") from None
        if not 2 <= len(rows) <= MAX_VERTICES or any(len(r) != 2 for r in values["table"]):
            raise ConfigError(f"detection.table: {len(rows)} rows; allowed 2 to {MAX_VERTICES} rows "
                              "'distance_m probability'")
    for name in ("range_50_m", "slope"):
        if section[name] > 0.0:
            values[name] = section[name]
    if not values:
        raise ConfigError("detection: missing; give detection.range_50_m and detection.slope, or detection.table "
                          "(or the tag's tag.source_level_db: the site's SNR model)")
    try:
        return DetectionCurve.from_mapping(values, "detection")
    except ModelError as exc:
        raise ConfigError(str(exc)) from None


__all__ = ["detection_curve", "receiver_curves", "site_curve"]
