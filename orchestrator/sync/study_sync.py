"""``sblsim sync`` on a study's files: the raw detections, the receivers' deployments and a sound-speed series read,
each detection put at its deployment and the clocks synchronised (:func:`synchronise_study`, on
:func:`~sblsim.orchestrator.sync.run.synchronise`, which weighs the times' rounding and, from
:func:`synchronise_files`, the table's positions against the sync tags' clock-free travel times before it fits the
clocks); a matrix's or a study's detections' time resolution against the array (:func:`rounding_warning`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.sync.pings import largest_travel_time
from sblsim.models.sync.resolution import resolution_warning
from sblsim.models.sync.scale import NOMINAL_SOUND_SPEED
from sblsim.models.sync.windows import WINDOW_DAYS
from sblsim.orchestrator.io.memory import arrow_pool, emptied
from sblsim.orchestrator.readers.assign import assign, serials_as_logged
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.in_water import in_water
from sblsim.orchestrator.readers.sound_speed import read_sound_speed
from sblsim.orchestrator.store.read import is_store, read_any
from sblsim.orchestrator.sync.run import SYNC_COLUMNS, SyncOutcome, synchronise


def rounding_warning(detections: Detections, hydrophones: pd.DataFrame, sound_speed: float | None,
                     quantum: float | None = None) -> str | None:
    """One line where the detections' times are rounded too coarsely for the array
    (:func:`sblsim.models.sync.resolution.resolution_warning`; ``hydrophones``' ``x``, ``y``, ``z`` [m] give the
    largest travel time at ``sound_speed`` [m/s], 1,480 m/s where not known), else None; ``quantum`` [s] their
    rounding where found already (a store's study: its batches'), else the detections' times'."""
    speed = sound_speed or NOMINAL_SOUND_SPEED
    xyz = np.nan_to_num(hydrophones[["x", "y", "z"]].to_numpy(float))  # a depth not given: the horizontal alone
    times = None if quantum is not None else detections.frame["time"].to_numpy(float)
    return resolution_warning(times, largest_travel_time(xyz, speed), speed, f"detections {detections.source!r}",
                              quantum)


def synchronise_study(detections: Detections, deployments, sound_speed: float | None = None,
                      series: tuple[np.ndarray, np.ndarray] | None = None, bin_hours: float = 1.0,
                      reference: str | None = None, **options: Any) -> SyncOutcome:
    """:func:`synchronise` on a study's receivers (a
    :class:`~sblsim.orchestrator.readers.deployments.Deployments`): each detection at its deployment first (the
    others set aside, counted in ``summary["set_aside"]``), only the deployments that logged a kept detection taken
    (:func:`~sblsim.orchestrator.readers.in_water.in_water`: the frame chosen again over them where it was chosen
    automatically; the others listed in ``summary["receivers_file"]``), the frame and the deployments in
    ``summary["receivers_file"]``, and the refined positions (``positions.csv``) in latitude and longitude too where
    the frame is known; ``options`` as :func:`synchronise` takes them (``release_rows``: ``detections``' rows
    emptied once assigned, and the assigned ones once the synchronisation has taken its arrivals).

    Raises
    ------
    ModelError
        As :func:`synchronise`, or no detection inside a deployment.
    """
    deployments = serials_as_logged(deployments, detections.frame["receiver"].unique())[0]  # VR2AR-461000: 461000
    array = in_water(detections, assign(detections, deployments), deployments)  # the deployments that logged it
    deployments, assigned = array.deployments, array.assigned
    if options.get("release_rows"):  # the rows as read let go too: the assigned ones are the synchronisation's
        detections.frame = emptied(detections.frame)
    outcome = synchronise(assigned.detections, assigned.hydrophones, sound_speed, series, bin_hours, reference,
                          alternatives=deployments.alternatives(), **options)
    outcome.summary["set_aside"] = assigned.set_aside
    outcome.summary["receivers_file"] = deployments.summary()
    if array.line():
        outcome.summary.setdefault("notes", []).append(array.line("counted in sync.json's receivers_file"))
    frame = deployments.frame
    if outcome.positions is not None and frame is not None:
        outcome.positions["lat"], outcome.positions["lon"] = frame.to_latlon(outcome.positions["x_m"].to_numpy(),
                                                                             outcome.positions["y_m"].to_numpy())
    return outcome


def synchronise_files(detections: Path, receivers: Path, format: str | None, sound_speed: float | None,
                      sound_speed_file: Path | None, bin_hours: float, reference: str | None,
                      refine_positions: bool = False, survey_sigma: float | None = None, crs: str | None = None,
                      frame: str | None = None, window_days: float | None = WINDOW_DAYS) -> SyncOutcome:
    """``sblsim sync``'s synchronisation from its files (:func:`sblsim.orchestrator.commands.sync.sync`'s arguments,
    checked): the detections read (in ``format``; None: from the file's first line) and the deployments (in ``crs``,
    projected to ``frame``); of a store, the deployments' sync tags' rows alone; the sound-speed series where given,
    synchronised (:func:`synchronise_study`), the table's positions checked against the sync tags' clock-free travel
    times first
    (:func:`~sblsim.orchestrator.sync.declared.check_sync_positions`, once the arrivals are grouped, before the
    clocks are fitted); a season longer than ``window_days`` [days] fitted in windows (0: one fit); ``survey_sigma``
    [m] the table's stated error as :func:`synchronise` takes it.

    Raises
    ------
    ModelError, ConfigError
        One line: a file refused by its reader, a synchronisation that cannot be made, the table's positions in
        another unit than metres (feet, kilometres, degrees, ...), times rounded too coarsely for the array.
    """
    # a file read (or refused) first, before the deployments load their geodesy; of a store, the deployments' sync
    # tags' rows alone: a season's other detections are never read
    arrow_pool()
    store = is_store(detections)
    data = None if store else read_any(detections, format)
    deployments = read_deployments(receivers, crs, frame)
    if store:
        # the columns the synchronisation reads alone, the others never read from the store's files
        data = read_any(detections, format, tags=set(deployments.table["sync_tag"]) - {""}, columns=SYNC_COLUMNS)
    series = read_sound_speed(sound_speed_file) if sound_speed_file is not None else None
    # the table's positions against the sync tags' clock-free travel times (another unit refused, a table slightly
    # off said) and the times' rounding against the array, before the clocks are fitted (run.synchronise)
    return synchronise_study(data, deployments, sound_speed, series, bin_hours, reference,
                             refine_positions=refine_positions, survey_sigma=survey_sigma,
                             receivers_file=deployments.source, window_days=window_days or None,
                             release_rows=True)  # (read here: no caller reads them)



__all__ = ["rounding_warning", "synchronise_files", "synchronise_study"]
