"""Each detection at the deployment that logged it (:func:`assign`): by the receiver's serial and the detection's time
(on the receiver's clock, seconds off at most, against deployments days long); detections before a deployment, after
its recovery, between two, or at a serial the table does not list are set aside and counted, never used. A sync tag
deployed more than once is one sync tag per deployment. A sheet's serial given with the receiver's model
(``VR2AR-461000``, as VUE names a receiver) is the serial the detections' readers keep (``461000``) where no
detection names it whole (:func:`serials_as_logged`)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.readers.transmitters import after_last_dash, match, split

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
    mask: np.ndarray | None
    #: The kept detections' first and last times [s] where ``detections`` holds some of them only (a store's study:
    #: its sync tags' rows, :mod:`sblsim.orchestrator.telemetry.study_detections`); None: ``detections``' own.
    span: tuple[float, float] | None = None

    def kept_span(self) -> tuple[float, float]:
        """[s] the first and last kept detection's time (:attr:`span`, else the detections' own)."""
        if self.span is not None:
            return self.span
        times = self.detections.frame["time"].to_numpy(float)
        return float(times.min()), float(times.max())


def assign(detections: Detections, deployments: Deployments, detected: Any = None,
           refuse_empty: bool = True) -> Assigned:
    """Each detection at the deployment that logged it (the module docstring), the others set aside and counted.

    Parameters
    ----------
    detections : Detections
        The detections as read (``receiver`` the serial logged).
    deployments : Deployments
    detected : sequence of str, optional
        Every tag the study detected, where ``detections`` are some of its tags' only (a store read a batch of tags
        at a time): the deployments' sync tags are matched against them, as against the whole file's; default
        ``detections``' own.
    refuse_empty : bool
        Refuse detections none of which is kept (else an empty assignment: a batch of a store's tags).

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
    known = pd.Series(serial).isin(set(table["serial"])).to_numpy()
    at = pd.Series(serial).groupby(serial, sort=False).indices  # each serial's rows: the sheet's others cost nothing
    for s, rows in table[table["serial"].isin(list(at))].groupby("serial", sort=False).groups.items():
        part = table.loc[rows].sort_values("start")
        mine = at[s]
        k = np.searchsorted(part["start"].to_numpy(float), time[mine], side="right") - 1
        inside = (k >= 0) & (time[mine] <= part["end"].to_numpy(float)[np.clip(k, 0, None)])
        where[mine[inside]] = np.asarray(part.index)[k[inside]]
    outside = known & (where < 0)
    hydrophones = deployments.hydrophones()
    names = table["receiver"].to_numpy(dtype=object)
    renamed = frame.assign(serial=serial, receiver=np.where(where >= 0, names[np.clip(where, 0, None)], serial))
    # each sync tag as the detections name it, and per deployment where it was deployed more than once
    tags = renamed["tag"].to_numpy(dtype=object).copy()
    detected = frame["tag"].unique() if detected is None else np.asarray(detected, dtype=object)
    of_tag = pd.Series(tags).groupby(tags, sort=False).indices
    stray = np.zeros(len(frame), bool)
    carried = table[table["sync_tag"] != ""].sort_values(["sync_tag", "start"], kind="stable")
    given = carried["sync_tag"].to_numpy(dtype=object)
    ids = {split(t)[1] for t in detected}  # a sync tag none of whose ids is detected stands for itself
    key = {g: (match(g, detected) if split(g)[1] in ids else None) or g for g in pd.unique(given)}
    base = np.asarray([key[g] for g in given], dtype=object)
    size = carried.groupby("sync_tag", sort=False)["sync_tag"].transform("size").to_numpy()
    rank = carried.groupby("sync_tag", sort=False).cumcount().to_numpy() + 1
    labels = np.where(size > 1, base + "." + rank.astype(str), base).astype(object)
    hydrophones.loc[np.asarray(carried.index), "sync_tag"] = labels
    for g, at in pd.Series(np.arange(len(carried))).groupby(given, sort=False).indices.items():
        mine = of_tag.get(key[g])  # only the sync tags detected: the sheet's others cost nothing
        if mine is None:
            continue
        k = np.searchsorted(carried["start"].to_numpy(float)[at], time[mine], side="right") - 1
        inside = (k >= 0) & (time[mine] <= carried["end"].to_numpy(float)[at][np.clip(k, 0, None)])
        stray[mine[~inside]] = True
        tags[mine[inside]] = labels[at][k[inside]]
    keep = (where >= 0) & ~stray
    kept = renamed.assign(tag=tags)[keep].reset_index(drop=True)
    if not len(kept) and refuse_empty:
        raise nothing_kept(detections.source, serial, deployments)
    per = pd.Series(serial[~keep]).value_counts()
    set_aside = {"receiver_not_in_table": int((~known).sum()), "outside_deployment": int(outside.sum()),
                 "sync_tag_outside_deployment": int((stray & (where >= 0)).sum()),
                 "per_serial": {str(k): int(v) for k, v in per.items()}}
    return Assigned(replace(detections, frame=kept), hydrophones, set_aside, keep)


def serials_as_logged(deployments: Deployments, logged: Any) -> tuple[Deployments, str | None]:
    """The deployments with each serial given with the receiver's model (``VR2AR-461000``: VUE's and Fathom's name of
    a receiver, which their readers cut to the serial) taken as the serial alone (``461000``) where no detection
    names it whole, the detections name that serial, and no other of the sheet's serials is it or becomes it; and the
    note saying so (None where none is).

    Parameters
    ----------
    deployments : Deployments
    logged : iterable of str
        The receivers (serials) the detections name (every batch's: a store's whole list).
    """
    table = deployments.table
    logged = set(map(str, logged))
    given = table["serial"].astype(str)
    tail = after_last_dash(given)
    candidate = ~given.isin(logged) & tail.isin(logged) & (tail != given) & ~tail.isin(set(given))
    sources = given[candidate].groupby(tail[candidate]).nunique()  # one serial of the sheet per serial logged
    candidate &= tail.map(sources).eq(1)
    if not candidate.any():
        return deployments, None
    table = table.copy()
    table.loc[candidate, "serial"] = tail[candidate]
    first = int(np.flatnonzero(candidate.to_numpy())[0])
    note = (f"{int(given[candidate].nunique()):,} serials of {deployments.source} given with the receiver's model "
            f"({given.iloc[first]}, ...) taken as the serials the detections name ({tail.iloc[first]}, ...)")
    return replace(deployments, table=table, notes=[*deployments.notes, note]), note


def nothing_kept(source: str, serials, deployments: Deployments) -> ModelError:
    """The refusal of detections none of which is inside a deployment (one line naming the serials detected, those
    of the table and what is allowed)."""
    return ModelError(f"detections: none of {source!r} is inside a deployment of {deployments.source!r} (serials "
                      f"detected: {', '.join(sorted(map(str, set(serials)))[:8])}; in the table: "
                      f"{', '.join(sorted(map(str, deployments.table['serial'].unique()))[:8])}); allowed: "
                      "detections at the table's receivers between their deployment and recovery")


__all__ = ["Assigned", "SET_ASIDE", "assign", "nothing_kept", "serials_as_logged"]
