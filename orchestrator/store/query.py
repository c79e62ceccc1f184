"""A store of detections (:mod:`.ingest`) read back: a tag, some receivers or a time window at a time, or whole as
the reader's :class:`~sblsim.orchestrator.readers.detections.Detections`.

A store is anyone's folder: its ``store.json`` is read bounded (:data:`MAX_STORE_JSON` bytes) and checked (its marker,
its layout), no path it names is opened (the Parquet files are the ``part-*.parquet`` files of its ``detections``
folder, a link among them refused), and the Parquet files are data pyarrow decodes, never code.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.memory import release
from sblsim.orchestrator.io.times import MAX_EPOCH, TIME_SPAN
from sblsim.orchestrator.readers import network
from sblsim.orchestrator.readers.detections import LOGGED, NETWORKS, SORTED, Detections
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.store.layout import LAYOUT, MARKER, STORE_FILE

#: The largest ``store.json`` read [bytes] (its tags' and receivers' counts: 100,000 tags fit in a few MiB).
MAX_STORE_JSON = 64 * 2**20


#: ``store.json``'s keys a store is read by, and each one's type.
_KEYS = {"source": str, "format": str, "row_order": str, "rows": int, "files": int, "columns": list,
         "ignored_columns": list, "clock_resets": list, "tags": dict, "receivers": dict}
#: A clock reset's keys (:attr:`~sblsim.orchestrator.readers.detections.Detections.clock_resets`) and their types.
_RESET = {"receiver": str, "line": int, "previous_line": int, "step_s": float, "before_s": float, "after_s": float,
          "clock_part": int}
#: The columns every store's detections hold, and their Arrow types.
_COLUMNS = {"receiver": "string", "tag": "string", "time": "double", "line": "int64"}
#: The Arrow types each of :data:`_COLUMNS`' types stands for.
_TYPES = {"string": ("string", "large_string", "string_view"), "double": ("double",), "int64": ("int64",)}


def _check_info(info: dict, where: str) -> None:
    """Refuse a ``store.json`` whose keys are missing or of another type (a store is anyone's folder).

    Raises
    ------
    ModelError
        One line naming the key and the type allowed.
    """
    for key, kind in _KEYS.items():
        if not isinstance(info.get(key), kind) or isinstance(info.get(key), bool):
            raise ModelError(f"{where}: its {STORE_FILE}'s {key!r} is {type(info.get(key)).__name__}; allowed: "
                             f"{kind.__name__} (a store sblsim store wrote)")
    if info["format"] not in FORMATS or info["row_order"] not in (LOGGED, SORTED):
        raise ModelError(f"{where}: its {STORE_FILE}'s format {info['format'][:20]!r} or row order is none sblsim "
                         f"reads; allowed: one of {', '.join(FORMATS)}")
    texts = [*info["columns"], *info["ignored_columns"], *info["tags"], *info["receivers"]]
    counts = [*info["tags"].values(), *info["receivers"].values()]
    resets_ok = all(isinstance(r, dict) and all(isinstance(r.get(k), t) or (t is float and isinstance(r.get(k), int))
                                                for k, t in _RESET.items()) for r in info["clock_resets"])
    if not (all(isinstance(t, str) for t in texts) and all(isinstance(n, int) for n in counts) and resets_ok):
        raise ModelError(f"{where}: its {STORE_FILE}'s columns, tags, receivers or clock resets are not as sblsim "
                         "store writes them; allowed: a store sblsim store wrote")


class Store:
    """A store of detections.

    Parameters
    ----------
    folder : str or Path
        The store's folder (``sblsim store DETECTIONS --out FOLDER``).

    Attributes
    ----------
    folder : Path
    info : dict
        Its ``store.json``: ``source``, ``source_bytes``, ``source_sha256``, ``format``, ``encoding``,
        ``row_order``, ``rows``, ``time_span_s`` [s since 1970 UTC], ``clock_resets``, ``ignored_columns``, ``tags``
        and ``receivers`` (each one's detections) (:mod:`.ingest`).

    Raises
    ------
    ModelError
        A folder without a store (no ``store.json`` with its marker), of another layout, or whose files are
        missing, links, or not Parquet.
    """

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        where = f"store: {str(self.folder)!r}"
        path = self.folder / STORE_FILE
        if path.is_symlink() or not path.is_file():
            raise ModelError(f"{where} holds no {STORE_FILE}; allowed: a folder sblsim store wrote")
        with open(path, "rb") as handle:
            data = handle.read(MAX_STORE_JSON + 1)
        if len(data) > MAX_STORE_JSON:
            raise ModelError(f"{where}: its {STORE_FILE} is larger than {MAX_STORE_JSON // 2**20} MiB")
        try:
            info = json.loads(data)
        except ValueError:
            info = None
        if not isinstance(info, dict) or info.get("marker") != MARKER:
            raise ModelError(f"{where}: its {STORE_FILE} is not a store's description; allowed: a folder sblsim "
                             "store wrote")
        if info.get("layout") != LAYOUT:
            raise ModelError(f"{where}: layout {info.get('layout')!r}; this sblsim reads layout {LAYOUT} (write it "
                             "again with sblsim store)")
        _check_info(info, where)
        self.info = info
        self.files = sorted((self.folder / "detections").glob("part-*.parquet"))
        self._dataset = None
        if len(self.files) != info.get("files") or any(f.is_symlink() for f in self.files):
            raise ModelError(f"{where}: its detections folder holds {len(self.files)} files where {STORE_FILE} says "
                             f"{info.get('files')!r} (or a link); allowed: the store as sblsim store wrote it")

    @property
    def tags(self) -> list[str]:
        """The tags detected (full IDs where the file gives a code space), sorted."""
        return list(self.info["tags"])

    @property
    def receivers(self) -> list[str]:
        """The receivers (serials), sorted."""
        return list(self.info["receivers"])

    def _filter(self, tags, receivers, start, end):
        """The Arrow expression selecting ``tags``, ``receivers`` and [start, end) (None: all)."""
        parts = []
        if tags is not None:  # typed: an empty list is no type Arrow can match a column's with
            parts.append(pc.field("tag").isin(pa.array([str(t) for t in tags], pa.string())))
        if receivers is not None:
            parts.append(pc.field("receiver").isin(pa.array([str(r) for r in receivers], pa.string())))
        if start is not None:
            parts.append(pc.field("time") >= float(start))
        if end is not None:
            parts.append(pc.field("time") < float(end))
        expression = None
        for part in parts:
            expression = part if expression is None else expression & part
        return expression

    def frame(self, tags: list[str] | None = None, receivers: list[str] | None = None, start: float | None = None,
              end: float | None = None) -> pd.DataFrame:
        """The detections of some tags, receivers and a time window, in the reader's order (a receiver's log: the
        file's; a network extract: each receiver's, its exact duplicates dropped, as
        :func:`~sblsim.orchestrator.readers.network.ordered` puts it; a duplicate is one tag's, so a tag's rows read
        alone are those of the whole file).

        Parameters
        ----------
        tags, receivers : list of str, optional
            Only these (None: all).
        start, end : float, optional
            Only times in [start, end) [s since 1970 UTC, on the receiver's clock] (None: unbounded).

        Returns
        -------
        pandas.DataFrame
            :attr:`~sblsim.orchestrator.readers.detections.Detections.frame`'s columns (a ``clock_part`` column
            where the file's receivers' clocks were reset).

        Raises
        ------
        ModelError
            A Parquet file pyarrow cannot read (naming the store).
        """
        return self.detections(tags, receivers, start, end).frame

    def detections(self, tags: list[str] | None = None, receivers: list[str] | None = None,
                   start: float | None = None, end: float | None = None,
                   columns: Sequence[str] | None = None) -> Detections:
        """:meth:`frame`'s rows as :class:`~sblsim.orchestrator.readers.detections.Detections`, with the exact
        duplicates dropped among them and the reader's notes (the whole store: what
        :func:`~sblsim.orchestrator.readers.detections.read_detections` reads from the file, but its ``source``: the
        file's name); ``columns``: only these are read from the Parquet files and kept (None: all), besides
        ``receiver``, ``tag``, ``time``, ``line`` and ``clock_part``, which every store's detections hold (and, read
        but not kept, the receivers' notes a network extract's are said by)."""
        info = self.info
        try:  # a column only some pieces have (a receiver's note) is in the dataset's schema, empty elsewhere
            if self._dataset is None:  # every file's footer read once, not at each tag's query
                schema = pa.unify_schemas([pq.read_schema(f) for f in self.files])
                self._dataset = ds.dataset([str(f) for f in self.files], schema=schema, format="parquet")
            kept = None if columns is None else {*columns, *_COLUMNS, "clock_part"}
            read = None if kept is None else [c for c in self._dataset.schema.names
                                              if c in kept or c == "receiver_note"]
            table = self._dataset.to_table(columns=read, filter=self._filter(tags, receivers, start, end))
        except Exception as exc:  # pyarrow's errors of a damaged file
            raise ModelError(f"store: {str(self.folder)!r}: its detections cannot be read "
                             f"({' '.join(str(exc).split())[:160]})") from None
        wrong = [f"{name} ({table.schema.field(name).type if name in table.column_names else 'missing'})"
                 for name, kind in _COLUMNS.items()
                 if name not in table.column_names or str(table.schema.field(name).type) not in _TYPES[kind]]
        if wrong:
            raise ModelError(f"store: {str(self.folder)!r}: its detections' columns {', '.join(wrong)}; allowed: "
                             + ", ".join(f"{n} ({k})" for n, k in _COLUMNS.items()))
        # sorted by line in Arrow (no pandas copy of the whole frame to sort it), then converted column by column,
        # each Arrow column released as it is taken (1.17 M detections: the read's peak 496 MiB, was 551)
        table = table.take(pc.sort_indices(table, [("line", "ascending")]))
        frame = table.to_pandas(split_blocks=True, self_destruct=True)
        del table
        release()  # the read's buffers back to the system (a season's sync-tag rows: 0.19 GiB)
        time = frame["time"].to_numpy(float)
        bad = ~np.isfinite(time) | (time < 0) | (time > MAX_EPOCH)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ModelError(f"store: {str(self.folder)!r}: line {frame['line'].iloc[k]}'s time {float(time[k])!r} s; "
                             f"allowed: {TIME_SPAN}")
        for name in frame.columns:
            if not pd.api.types.is_numeric_dtype(frame[name]) and frame[name].isna().any():
                frame[name] = frame[name].fillna("")
        frame = frame[[c for c in info.get("columns", []) if c in frame] or list(frame.columns)]
        if not info["clock_resets"] and "clock_part" in frame:
            frame = frame.drop(columns="clock_part")
        duplicates, notes = 0, []
        if info["format"] in NETWORKS:
            frame, duplicates, notes = network.ordered(frame)
        if kept is not None:
            frame = frame[[c for c in frame.columns if c in kept]]
        return Detections(frame, str(info["source"]), info["format"], list(info["ignored_columns"]),
                          [dict(r) for r in info["clock_resets"]], info["row_order"], duplicates, notes)


__all__ = ["MAX_STORE_JSON", "Store"]
