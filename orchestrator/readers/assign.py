"""Each detection at the deployment that logged it (:func:`assign`): by the receiver's serial and the detection's time
(on the receiver's clock, seconds off at most, against deployments days long); detections before a deployment, after
its recovery, between two, or at a serial the table does not list are set aside and counted, never used. A sync tag
deployed more than once is one sync tag per deployment."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.transmitters import match

#: The reasons a detection is set aside, in :attr:`Assigned.set_aside`'s keys.
SET_ASIDE = ("receiver_not_in_table", "outside_deployment", "sync_tag_outside_deployment")


@dataclass
class Assigned:
    """The detections of :func:`assign`: ``detections`` (each at its deployment: ``receiver`` the deployment's
    name, ``serial`` the serial logged; a sync tag deployed more than once named per deployment), ``hydrophones``
    (the deployments as :meth:`Deployments.hydrophones`, sync tags named as the detections name them),
    ``set_aside`` (counts per reason of :data:`SET_ASIDE`, and per serial) and ``mask`` (the file's rows kept)."""

    detections: Detections
    hydrophones: pd.DataFrame
    set_aside: dict[str, Any]
    mask: np.ndarray


def assign(detections: Detections, deployments: Deployments) -> Assigned:
    """Each detection at the deployment that logged it (the module docstring), the others set aside and counted.

    Raises
    ------
    ModelError
        No detection inside a deployment of the table (one line naming the serials of each).
    """
    frame = detections.frame
    table = deployments.table
    serial = frame["receiver"].to_numpy(dtype=object)
    time = frame["time"].to_numpy(float)
    where = np.full(len(frame), -1, np.int64)
    known = np.isin(serial, table["serial"].to_numpy(dtype=object))
    for s, rows in table.groupby("serial", sort=False).groups.items():
        part = table.loc[rows].sort_values("start")
        mine = np.flatnonzero(serial == s)
        k = np.searchsorted(part["start"].to_numpy(float), time[mine], side="right") - 1
        inside = (k >= 0) & (time[mine] <= part["end"].to_numpy(float)[np.clip(k, 0, None)])
        where[mine[inside]] = np.asarray(part.index)[k[inside]]
    outside = known & (where < 0)
    hydrophones = deployments.hydrophones()
    names = table["receiver"].to_numpy(dtype=object)
    renamed = frame.assign(serial=serial, receiver=np.where(where >= 0, names[np.clip(where, 0, None)], serial))
    # each sync tag as the detections name it, and per deployment where it was deployed more than once
    tags = renamed["tag"].to_numpy(dtype=object).copy()
    detected = frame["tag"].unique()
    stray = np.zeros(len(frame), bool)
    carried = table[table["sync_tag"] != ""]
    for given, rows in carried.groupby("sync_tag", sort=False).groups.items():
        key = match(given, detected) or given
        part = carried.loc[rows].sort_values("start")
        mine = np.flatnonzero(tags == key)
        k = np.searchsorted(part["start"].to_numpy(float), time[mine], side="right") - 1
        inside = (k >= 0) & (time[mine] <= part["end"].to_numpy(float)[np.clip(k, 0, None)])
        stray[mine[~inside]] = True
        labels = [key] if len(part) == 1 else [f"{key}.{j + 1}" for j in range(len(part))]
        tags[mine[inside]] = np.asarray(labels, dtype=object)[k[inside]]
        hydrophones.loc[np.asarray(part.index), "sync_tag"] = labels
    keep = (where >= 0) & ~stray
    kept = renamed.assign(tag=tags)[keep].reset_index(drop=True)
    if not len(kept):
        raise ModelError(f"detections: none of {detections.source!r} is inside a deployment of {deployments.source!r} "
                         f"(serials detected: {', '.join(sorted(map(str, set(serial)))[:8])}; in the table: "
                         f"{', '.join(sorted(map(str, table['serial'].unique()))[:8])}); allowed: detections at the "
                         "table's receivers between their deployment and recovery")
    per = pd.Series(serial[~keep]).value_counts()
    set_aside = {"receiver_not_in_table": int((~known).sum()), "outside_deployment": int(outside.sum()),
                 "sync_tag_outside_deployment": int((stray & (where >= 0)).sum()),
                 "per_serial": {str(k): int(v) for k, v in per.items()}}
    return Assigned(replace(detections, frame=kept), hydrophones, set_aside, keep)


__all__ = ["Assigned", "SET_ASIDE", "assign"]
