"""A study's detections as its steps take them (:mod:`.study`): a file read whole, or a store
(:mod:`sblsim.orchestrator.store`) read a batch of tags at a time, so that a season's detections are never in memory
together.

Of all its detections a study needs only what they add up to (:class:`Tally`: the rows read and kept, the detections
set aside and why, each deployment's kept detections and the span they cover, the serials logged, the kept
detections per deployment and day, the times' rounding, each tag's kept detections); of the deployments' sync tags
their rows, for the clocks; of each tag it tracks its own rows (:meth:`StudyDetections.frames`). Read whole, these
are taken from the one table; from a store, each batch of tags (:data:`BATCH_ROWS` detections at most, a tag never
split) is read, assigned to its deployments (:func:`~sblsim.orchestrator.readers.assign.assign`, the sync tags
matched against every tag of the store, as against the whole file's) and added up, its sync tags' rows kept, then
let go. The tags' rows are read again, a batch at a time, once the clocks are known. Each tag's rows, and the sync
tags', come in the order the whole file's reader puts them (a receiver's log: its lines'; a network extract: each
receiver's, by time), so a study of a store is the study of its file.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np
import pandas as pd

from sblsim.models.sync.resolution import common_quantum, time_quantum
from sblsim.orchestrator.io.memory import release
from sblsim.orchestrator.readers.assign import SET_ASIDE, Assigned, assign, nothing_kept
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.readers.detections import NETWORKS, Detections
from sblsim.orchestrator.store.read import read_any
from sblsim.orchestrator.sync.run import SYNC_COLUMNS
from sblsim.orchestrator.telemetry.report.daily import DAILY_COLUMNS, daily_counts

#: The most detections a store's batch of tags holds [1] (a tag with more is a batch alone): its reading and
#: assignment peak at about 0.2 GiB beyond the process's own, whatever the season's length (a million: 0.65 GiB).
BATCH_ROWS = 250_000


@dataclass
class Tally:
    """What a study's detections add up to.

    Attributes
    ----------
    rows : int
        The detections read (a network extract's exact duplicates dropped).
    set_aside : dict
        :attr:`~sblsim.orchestrator.readers.assign.Assigned.set_aside`: the detections set aside per reason and per
        serial.
    kept : pandas.Series
        The kept detections per deployment (by its name).
    span : tuple of float
        [s since 1970 UTC] the first and last kept detection's time.
    serials : ndarray of str
        The serials that logged a detection (kept or not).
    daily : pandas.DataFrame
        The kept detections per deployment and UTC day (:func:`~.report.daily.daily_counts`).
    quantum : float
        [s] the kept times' rounding (:func:`~sblsim.models.sync.resolution.time_quantum`, 0 where finer than a
        millisecond).
    tags : pandas.Series
        The kept detections per tag (as assigned: a sync tag deployed twice named per deployment), most first.
    labelled : set of str
        The tags a ``species`` column calls ``sync``.
    stored_as : dict
        Each kept tag's name in the file (a sync tag named per deployment: its file's name).
    """

    rows: int
    set_aside: dict
    kept: pd.Series
    span: tuple[float, float]
    serials: np.ndarray
    daily: pd.DataFrame
    quantum: float
    tags: pd.Series
    labelled: set
    stored_as: dict

    @property
    def used(self) -> int:
        """The kept detections [1]."""
        return int(self.kept.sum())

    @classmethod
    def of(cls, data: Detections, assigned: Assigned) -> Tally:
        """The tally of ``data`` as ``assigned``."""
        kept = assigned.detections.frame
        times = kept["time"].to_numpy(float)
        species = kept["species"].astype(str).str.lower() == "sync" if "species" in kept else None
        pairs = pd.DataFrame({"kept": kept["tag"].to_numpy(dtype=object),
                              "file": data.frame["tag"].to_numpy(dtype=object)[assigned.mask]}).drop_duplicates()
        return cls(int(len(data.frame)), assigned.set_aside, kept["receiver"].value_counts(),
                   (float(times.min()), float(times.max())) if len(times) else (np.inf, -np.inf),
                   data.frame["receiver"].unique(), daily_counts(kept), time_quantum(times),
                   kept["tag"].value_counts(), set() if species is None else set(kept.loc[species, "tag"]),
                   dict(zip(pairs["kept"], pairs["file"])))

    @classmethod
    def merged(cls, parts: Sequence[Tally]) -> Tally:
        """The tally of batches' detections together (each tag in one batch only)."""
        aside = {k: sum(p.set_aside[k] for p in parts) for k in SET_ASIDE}
        per = pd.concat([pd.Series(p.set_aside["per_serial"], dtype=np.int64) for p in parts])
        per = per.groupby(level=0).sum().sort_values(ascending=False, kind="stable")
        aside["per_serial"] = {str(k): int(v) for k, v in per.items()}
        daily = pd.concat([p.daily for p in parts], ignore_index=True)
        daily = daily.groupby(["receiver", "day"], sort=True)["detections"].sum().reset_index()[list(DAILY_COLUMNS)]
        tags = pd.concat([p.tags for p in parts])
        tags = tags.iloc[np.lexsort((tags.index.to_numpy(dtype=str), -tags.to_numpy()))]
        quanta = [p.quantum for p in parts if p.used > 1]
        return cls(sum(p.rows for p in parts), aside,
                   pd.concat([p.kept for p in parts]).groupby(level=0, sort=False).sum(),
                   (min(p.span[0] for p in parts), max(p.span[1] for p in parts)),
                   pd.unique(np.concatenate([p.serials for p in parts])), daily,
                   common_quantum(quanta), tags, set().union(*(p.labelled for p in parts)),
                   {k: v for p in parts for k, v in p.stored_as.items()})


def reader_order(frame: pd.DataFrame, format: str) -> pd.DataFrame:
    """Rows read in batches put in the order the whole file's reader gives them: by line; a network extract's by
    its receiver's serial (``serial`` once assigned), time and line
    (:func:`~sblsim.orchestrator.readers.network.ordered`)."""
    if format in NETWORKS:
        serial = frame["serial" if "serial" in frame else "receiver"].to_numpy(dtype=str)
        order = np.lexsort((frame["line"].to_numpy(), frame["time"].to_numpy(float), serial))
    else:
        order = np.argsort(frame["line"].to_numpy(), kind="stable")
    return frame.iloc[order].reset_index(drop=True)


class StudyDetections:
    """A study's detections: ``data`` read whole, or a ``store``'s (:class:`~sblsim.orchestrator.store.query.Store`)
    read a batch of tags at a time.

    Parameters
    ----------
    data : Detections
        The detections read whole, or (with ``store``) a store's description: its source, format, columns and clock
        resets, without rows.
    store : Store, optional
        The store the detections are read from.
    """

    def __init__(self, data: Detections, store=None):
        self.data = data
        self.store = store

    @classmethod
    def stored(cls, path: Path, format: str | None = None) -> StudyDetections:
        """A store's detections (:func:`~sblsim.orchestrator.store.read.read_any`'s checks: the store's, its format
        ``format`` where given), none read yet."""
        from sblsim.orchestrator.store.query import Store  # pyarrow's dataset: loaded only where a store is read

        empty = read_any(path, format, tags=())
        return cls(empty, Store(path))

    def receivers(self) -> list[str]:
        """The receivers (serials) the detections name: the store's, or those of the rows read."""
        return self.store.receivers if self.store is not None else self.data.frame["receiver"].unique().tolist()

    def batches(self, names: Sequence[str]) -> list[list[str]]:
        """The store's tags ``names`` in batches of at most :data:`BATCH_ROWS` detections (by the store's count of
        each), in the store's order of tags (its row groups': a batch reads few of them)."""
        counts = self.store.info["tags"]
        batches: list[list[str]] = [[]]
        rows = 0
        for name in sorted(set(names)):
            if batches[-1] and rows + counts.get(name, 0) > BATCH_ROWS:
                batches.append([])
                rows = 0
            batches[-1].append(name)
            rows += counts.get(name, 0)
        return [b for b in batches if b]

    def _read(self, names: list[str], deployments: Deployments) -> tuple[Detections, Assigned]:
        """A batch of the store's tags read and assigned."""
        part = self.store.detections(tags=names)
        part.source = self.data.source
        return part, assign(part, deployments, self.store.tags, refuse_empty=False)

    def assigned(self, deployments: Deployments) -> tuple[Assigned, Tally]:
        """The detections assigned to ``deployments`` and their :class:`Tally`. Read whole, every kept detection
        (:func:`~sblsim.orchestrator.readers.assign.assign`); from a store, the deployments' sync tags' kept rows
        only, the others added up batch by batch (the module docstring).

        Raises
        ------
        ModelError
            As :func:`~sblsim.orchestrator.readers.assign.assign` (no detection inside a deployment: one line); a
            store that cannot be read.
        """
        if self.store is None:
            assigned = assign(self.data, deployments)
            return assigned, Tally.of(self.data, assigned)
        parts, sync, hydrophones = [], [], None
        for names in self.batches(self.store.tags):
            part, got = self._read(names, deployments)
            parts.append(Tally.of(part, got))
            hydrophones = got.hydrophones
            labels = set(hydrophones["sync_tag"]) - {""}
            frame = got.detections.frame
            # the columns the synchronisation reads alone: a season's sync-tag rows are held through the study
            held = [c for c in frame.columns if c in SYNC_COLUMNS]
            sync.append(frame.loc[frame["tag"].isin(labels).to_numpy(), held])
        tally = Tally.merged(parts)
        if not tally.used:  # said as of the whole file
            raise nothing_kept(self.data.source, tally.serials, deployments)
        rows = pd.concat(sync, ignore_index=True)
        sync.clear()  # the batches' rows let go before they are ordered (not three copies of a season's at once)
        rows = reader_order(rows, self.data.format)
        release()  # the batches' buffers back to the system before the synchronisation (13 weeks': 0.16 GiB)
        return Assigned(replace(self.data, frame=rows), hydrophones, tally.set_aside, None, tally.span), tally

    def frames(self, keys: Sequence[str | None], tally: Tally, deployments: Deployments,
               assigned: Assigned) -> Iterator[tuple[int, pd.DataFrame | None]]:
        """Each tag's kept rows, as ``(i, rows)`` for ``keys[i]`` (a kept tag's name; None: no rows, given first):
        read whole, in ``keys``' order; from a store, a batch of tags at a time, in the store's order of tags (each
        batch read once, whatever the order asked).

        Parameters
        ----------
        keys : sequence of str or None
        tally : Tally
        deployments : Deployments
            The deployments the rows are assigned to (the study's sheet as read).
        assigned : Assigned
            The detections as assigned (read whole: their rows).
        """
        if self.store is None:
            groups = assigned.detections.frame.groupby("tag", sort=False).groups
            for i, key in enumerate(keys):
                yield i, None if key is None else assigned.detections.frame.loc[groups[key]]
            return
        wanted: dict[str, list[int]] = {}
        for i, key in enumerate(keys):
            if key is None:
                yield i, None
            else:
                wanted.setdefault(tally.stored_as.get(key, key), []).append(i)
        for names in self.batches(list(wanted)):
            _, got = self._read(names, deployments)
            frame = got.detections.frame
            groups = frame.groupby("tag", sort=False).groups
            for name in names:
                for i in wanted[name]:
                    rows = groups.get(keys[i])
                    yield i, frame.iloc[:0] if rows is None else frame.loc[rows]


__all__ = ["BATCH_ROWS", "StudyDetections", "Tally", "reader_order"]
