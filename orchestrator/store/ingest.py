"""A detections file read into a store (:mod:`sblsim.orchestrator.store`) a piece at a time, in memory bounded by the
piece, not the file: ``sblsim store``.

The file is read in pieces of about :data:`PIECE_BYTES` bytes, each cut at a line's end (where the quotes of the piece
are balanced: a quoted cell spanning lines is never cut; in a Fathom CSV, before a ``DET`` record, so that a
detection's ``DET_SENS`` records stay with it), and each piece is read by the very reader of
:func:`~sblsim.orchestrator.readers.detections.read_detections` under the file's header (a Fathom piece under the
``_DESC`` lines in force there): the same cells checked with the same rules and errors, naming the file's own lines.
A plain piece is cut into its cells by Arrow's CSV reader (:mod:`.plain`), every other by the text reader's pandas;
:data:`READING_THREADS` pieces are read at once on threads, taken in the file's order, and each piece is written on a
thread while the next are read.
What a reader judges over the whole file is carried from piece to piece: each receiver's clock parts (its time going
back in the file's order: :class:`ClockParts`, as :func:`~sblsim.orchestrator.readers.detections.clock_parts`), the
encoding (a file not UTF-8 is read again in Latin-1, as the whole-file reader decodes it), the counts of tags and
receivers. A network extract (GLATOS, OTN) is stored in its file's order; its rows are put in each receiver's order
and its exact duplicates dropped as they are read back (:mod:`.query`), a tag at a time.

The row and size limits of the whole-file reader become the disk's: the store is written only where the disk holds
the file's size free (a Parquet store of detections is a fraction of its CSV: zstd and dictionary-encoded columns),
said before the work; a disk that fills on the way leaves nothing (the store is written in a staging folder, moved
into place when complete: :func:`~sblsim.orchestrator.io.output.staged_directory`). A line is still at most 1 MiB
and 512 cells, a piece's cells bounded, the file a regular file and no receiver's binary log.

The store's files: ``store.json`` (what was read: the file's name, size and SHA-256, the format, the encoding, the
rows, each tag's and receiver's detections, the time span, the clock resets, the columns not used; written last)
and ``detections/part-NNNNN.parquet``, one per piece, its rows sorted by tag and line (row groups of
:data:`ROW_GROUP` rows, so that a tag's rows are read alone by their statistics), zstd-compressed.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time as clock
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.memory import arrow_pool
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.io.progress import Progress, ProgressSpec
from sblsim.orchestrator.io.tables import regular_file
from sblsim.orchestrator.io.version import installed_version
from sblsim.orchestrator.readers.binary import refuse_log
from sblsim.orchestrator.readers.cells import cut_short, tail_text
from sblsim.orchestrator.readers.detections import (
    CLOCK_TOLERANCE,
    LOGGED,
    NETWORKS,
    SORTED,
    check_parts,
    sniff_format,
)
from sblsim.orchestrator.readers.fathom import no_det_desc
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.store.layout import LAYOUT, MARKER, STORE_FILE
from sblsim.orchestrator.store.reading import FIRST_FATHOM_BYTES, Coded, NotUtf8, desc_line, frames

#: The bytes of the file read as one piece [bytes] (reading a VUE export, a Fathom CSV or a GLATOS extract of a week
#: peaked at 0.39-0.48 GiB with it, two pieces read at once while the one before them is written; 0.37-0.38 GiB with
#: one; with pandas' parse alone 0.31-0.33 GiB, 0.41-0.49 GiB with 16 MiB, 0.26-0.27 GiB with 4 MiB, one at once).
PIECE_BYTES = 8 * 2**20
#: The smallest piece allowed [bytes].
MIN_PIECE_BYTES = 4096
#: The rows of a Parquet row group [1]: a tag's rows found by the groups' statistics.
ROW_GROUP = 65536
#: The columns a store's queries select by (:mod:`.query`), the only ones with statistics; text columns are
#: dictionary-encoded, numbers not (a piece of a VUE week written in 0.027 s of CPU, 1.18 MiB; with statistics and
#: dictionaries of every column, times and lines unique, 0.051 s, 1.62 MiB).
FILTERED = ("tag", "receiver", "time")
_WHAT = "detections"


class ClockParts:
    """Each receiver's clock parts judged across pieces read in the file's order, as
    :func:`~sblsim.orchestrator.readers.detections.clock_parts` judges them in the whole file: :meth:`add` gives a
    piece's rows their ``clock_part`` (1 first), :meth:`finish` refuses a receiver whose rows are not in its logging
    order and returns the resets."""

    def __init__(self, name: str):
        self.name = name
        self.last: dict[str, tuple[float, int]] = {}  # receiver -> its last time [s] and line
        self.part: dict[str, int] = {}
        self.tags: dict[tuple[str, int], set] = {}
        self.resets: list[dict] = []

    def add(self, frame: pd.DataFrame, coded: Coded) -> None:
        """Set ``frame["clock_part"]`` (in place) for a piece's rows, in the file's order (each receiver's rows found
        by its code: numpy's passes, not a group's Python objects); ``coded``: the piece's codes, as its reading
        thread made them (:func:`~.reading.coded_piece`)."""
        time = frame["time"].to_numpy(float)
        lines = frame["line"].to_numpy(np.int64)
        codes, names = coded.receivers
        n = len(frame)
        order = np.argsort(codes, kind="stable")  # each receiver's rows together, in the file's order
        sorted_codes = codes[order]
        starts = np.flatnonzero(np.r_[True, sorted_codes[1:] != sorted_codes[:-1]])
        ends = np.r_[starts[1:], n] - 1
        before, before_line = np.empty(n), np.empty(n)
        before[order[1:]], before_line[order[1:]] = time[order[:-1]], lines[order[:-1]]
        for g, k in zip(sorted_codes[starts], order[starts]):  # a receiver's first row: its last row before
            before[k], before_line[k] = self.last.get(names[g], (np.nan, np.nan))
        step = time - before
        back = np.flatnonzero(step < -CLOCK_TOLERANCE)
        reset = np.zeros(n, np.int64)
        reset[back] = 1
        counted = np.cumsum(reset[order])
        base = np.array([self.part.get(r, 1) for r in names], np.int64)
        part = np.empty(n, np.int64)
        part[order] = counted - np.repeat(counted[starts] - reset[order[starts]], ends - starts + 1) + \
            base[sorted_codes]
        frame["clock_part"] = part
        self.resets += [{"receiver": names[codes[k]], "line": int(lines[k]), "previous_line": int(before_line[k]),
                         "step_s": float(step[k]), "before_s": float(before[k]), "after_s": float(time[k]),
                         "clock_part": int(part[k])} for k in back]
        tag_codes, tags = coded.tags
        span = int(part.max()) + 1
        for key in pd.unique((codes.astype(np.int64) * span + part) * len(tags) + tag_codes):  # each (r, p, tag)
            (g, p), t = divmod(int(key) // len(tags), span), int(key) % len(tags)
            self.tags.setdefault((names[g], p), set()).add(tags[t])
        for g, k in zip(sorted_codes[starts], order[ends]):
            self.last[names[g]], self.part[names[g]] = (float(time[k]), int(lines[k])), int(part[k])

    def finish(self) -> list[dict]:
        """The resets in the file's order (:attr:`~sblsim.orchestrator.readers.detections.Detections.clock_resets`).

        Raises
        ------
        ModelError
            A receiver with more than the allowed resets, or whose parts share no tag
            (:func:`~sblsim.orchestrator.readers.detections.check_parts`).
        """
        self.resets.sort(key=lambda reset: reset["line"])
        for r in dict.fromkeys(reset["receiver"] for reset in self.resets):
            mine = [reset for reset in self.resets if reset["receiver"] == r]
            first = mine[0]
            check_parts(r, first["line"], first["previous_line"], first["step_s"], len(mine),
                        [self.tags.get((r, p), set()) for p in range(1, len(mine) + 2)], self.name, _WHAT)
        return self.resets


def _write(path: Path, folder: Path, format: str, encoding: str, piece_bytes: int, progress: Progress) -> dict:
    """Read ``path`` into ``folder`` (the staging folder's ``detections``); returns ``store.json``'s content."""
    digest = hashlib.sha256()
    clocks = None if format in NETWORKS else ClockParts(str(path))
    tags: Counter = Counter()
    receivers: Counter = Counter()
    rows, span, ignored, files, columns = 0, [np.inf, -np.inf], None, 0, []
    with ThreadPoolExecutor(1) as writer:  # a piece written while the next is read (Arrow's writing frees the GIL)
        written = None
        for frame, header, used, coded in frames(path, format, encoding, piece_bytes, digest, progress):
            if clocks is not None:
                clocks.add(frame, coded)
            columns = merged_columns(columns, list(frame.columns))
            if ignored is None:
                ignored = [h for k, h in enumerate(header) if k not in used and h]
            tags.update(coded.counts("tags"))
            receivers.update(coded.counts("receivers"))
            rows += len(frame)
            span = [min(span[0], float(frame["time"].min())), max(span[1], float(frame["time"].max()))]
            if written is not None:
                written.result()  # one piece in writing at a time: the memory of two pieces at most
            written = writer.submit(_write_part, frame, folder / f"part-{files:05d}.parquet", coded)
            files += 1
        if written is not None:
            written.result()
    if not rows and format == "fathom":  # no DET record read: said as the whole-file reader says it
        with path.open("rb") as handle:
            head = handle.read(FIRST_FATHOM_BYTES).decode(encoding, errors="replace")
        if desc_line(head, "DET") is None:
            raise no_det_desc(head, str(path), _WHAT)
    if not rows:
        raise ModelError(f"{_WHAT}: {str(path)!r} holds a header and no detections")
    resets = clocks.finish() if clocks is not None else []
    return {"marker": MARKER, "layout": LAYOUT, "sblsim": installed_version(), "source": path.name,
            "source_bytes": path.stat().st_size, "source_sha256": digest.hexdigest(), "format": format,
            "encoding": encoding, "row_order": SORTED if format in NETWORKS else LOGGED, "rows": rows,
            "files": files, "columns": columns, "time_span_s": span, "ignored_columns": ignored or [],
            "clock_resets": resets,
            "tags": dict(sorted(tags.items())), "receivers": dict(sorted(receivers.items()))}


def _write_part(frame: pd.DataFrame, path: Path, coded: Coded) -> None:
    """A piece's detections written as one Parquet file, its rows by tag, then line (the module docstring); the
    tags' order from the piece's codes (``coded``: each code's rank among the names, a tag left empty first)."""
    codes, names = coded.tags
    rank = np.argsort(np.argsort(np.array(names, dtype=object), kind="stable"))
    order = np.lexsort((frame["line"].to_numpy(np.int64), np.where(codes >= 0, rank[codes], -1)))
    table = pa.Table.from_pandas(frame, preserve_index=False).take(order)
    text = [field.name for field in table.schema if pa.types.is_string(field.type) or
            pa.types.is_large_string(field.type)]
    pq.write_table(table, path, row_group_size=ROW_GROUP, compression="zstd", use_dictionary=text,
                   write_statistics=[name for name in FILTERED if name in table.column_names])


def merged_columns(known: list[str], more: list[str]) -> list[str]:
    """The columns of pieces so far and a piece's (a column only some pieces have, a network extract's
    ``receiver_note`` say), each new one placed before the known column that follows it in its piece."""
    known = list(known)
    for k, name in enumerate(more):
        if name not in known:
            after = next((c for c in more[k + 1:] if c in known), None)
            known.insert(known.index(after) if after is not None else len(known), name)
    return known


def check_space(path: Path, out: Path, size: int) -> None:
    """Refuse a store the disk under ``out`` cannot hold (less free than the file's ``size`` [bytes]), before the work.

    Raises
    ------
    ModelError
        One line naming both sizes.
    """
    probe = out.absolute()
    while not probe.exists():
        probe = probe.parent
    free = shutil.disk_usage(probe).free
    if free < size:
        raise ModelError(f"--out: {str(out)!r}: the store of {str(path)!r} needs up to {size / 2**20:,.1f} MiB "
                         f"(the file's size) and the disk holds {free / 2**20:,.1f} MiB free; allowed: a folder on a "
                         "disk with room for it")


def ingest(path: Path | str, out: Path | str, format: str | None = None, *, piece_bytes: int = PIECE_BYTES,
           progress: ProgressSpec = False) -> dict:
    """Read a detections file into a store at ``out`` (the module docstring), a piece at a time.

    Parameters
    ----------
    path : str or Path
        The detections file: any format of :func:`~sblsim.orchestrator.readers.detections.read_detections`.
    out : str or Path
        The store's folder (made; an earlier store there replaced, a file sblsim did not write never).
    format : str, optional
        One of :data:`~sblsim.orchestrator.readers.formats.FORMATS`; None: read from the file's first line.
    piece_bytes : int
        The bytes read as one piece [bytes] (:data:`PIECE_BYTES`; at least :data:`MIN_PIECE_BYTES`; a piece holds at
        least one line however long, up to 1 MiB).
    progress : bool, str or callable
        :data:`~sblsim.orchestrator.io.progress.ProgressSpec`, in bytes of the file.

    Returns
    -------
    dict
        ``store.json``'s content, with ``seconds`` (the wall time [s]).

    Raises
    ------
    ModelError
        One line: every refusal of :func:`~sblsim.orchestrator.readers.detections.read_detections` but its row and
        size limits (naming the file's line and column; a file cut short before anything is written:
        :func:`~sblsim.orchestrator.readers.cells.cut_short`), a disk without the file's size free, a disk that
        fills.
    """
    started = clock.perf_counter()
    arrow_pool(decay=False)  # (its memory is its piece's: jemalloc's pages kept a second, 12 % faster)
    path, out = Path(path), Path(out)
    if format is not None and format not in FORMATS:
        raise ModelError(f"format: {format!r} is not one of {', '.join(FORMATS)}")
    if not isinstance(piece_bytes, int) or piece_bytes < MIN_PIECE_BYTES:
        raise ModelError(f"piece_bytes: {piece_bytes!r} is below {MIN_PIECE_BYTES}; allowed: at least "
                         f"{MIN_PIECE_BYTES} bytes")
    refuse_log(path, _WHAT)
    size = regular_file(path, _WHAT)
    format = format or sniff_format(path)
    tail, whole = tail_text(path)
    cut_short(tail, str(path), _WHAT, by_record=format == "fathom", whole=whole)  # before a piece is written
    check_space(path, out, size)
    with staged_directory(out) as stage, Progress(size, "store", "B", progress) as bar:
        folder = stage / "detections"
        try:
            for encoding in ("utf-8", "latin-1"):
                shutil.rmtree(folder, ignore_errors=True)
                folder.mkdir()
                try:
                    summary = _write(path, folder, format, encoding, piece_bytes, bar)
                    break
                except NotUtf8:
                    continue
            summary["seconds"] = round(clock.perf_counter() - started, 3)
            (stage / STORE_FILE).write_text(json.dumps(summary, indent=1) + "\n")
        except OSError as exc:
            raise ModelError(f"--out: {str(out)!r}: the store could not be written ({exc.strerror or exc}); "
                             "nothing was kept") from None
    return summary


__all__ = ["ClockParts", "MIN_PIECE_BYTES", "PIECE_BYTES", "ROW_GROUP",
           "check_space", "ingest", "merged_columns"]
