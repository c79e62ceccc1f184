"""A detections file read a piece at a time into each piece's detections, in the file's order, for
:mod:`sblsim.orchestrator.store.ingest` (its docstring says what is read and how): the pieces cut at a line's end,
each read by the very reader of :func:`~sblsim.orchestrator.readers.detections.read_detections` under the file's
header (a Fathom piece under the ``_DESC`` lines in force there), a plain piece's cells parsed by Arrow
(:mod:`.plain`), every other's by the text reader; :data:`READING_THREADS` pieces read at once on threads, their
receivers and tags coded there (:class:`Coded`).
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Iterator, NamedTuple

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.progress import Progress
from sblsim.orchestrator.io.tables import MAX_LINE_BYTES, check_cells
from sblsim.orchestrator.readers import fathom
from sblsim.orchestrator.readers.binary import not_text
from sblsim.orchestrator.readers.cells import text_table
from sblsim.orchestrator.readers.detections import rows_read
from sblsim.orchestrator.readers.limits import MAX_DETECTION_CELLS, MAX_DETECTIONS
from sblsim.orchestrator.store.plain import fathom_detections, plain_body

#: The pieces read at once, each on a thread [1] (a VUE week's reading 1.3 times as fast with 2 as in one thread on
#: 2 cores: most of a piece's reading is Arrow's kernels, which free the GIL; the memory of as many more pieces).
READING_THREADS = 2
#: A Fathom CSV's first piece [bytes]: its ``_DESC`` lines, which the text reader reads (the pieces after them, in the
#: lines' columns, are read by Arrow: :func:`~.plain.fathom_detections`).
FIRST_FATHOM_BYTES = 2**16
_WHAT = "detections"


class NotUtf8(Exception):
    """A piece that is not UTF-8: the file is read again in Latin-1."""


class Coded(NamedTuple):
    """A piece's receivers and tags as codes (:func:`pandas.factorize`'s: 0 first) and their names."""

    receivers: tuple[np.ndarray, list[str]]
    tags: tuple[np.ndarray, list[str]]

    def counts(self, which: str) -> dict[str, int]:
        """Each receiver's (``which="receivers"``) or tag's rows in the piece."""
        codes, names = getattr(self, which)
        return dict(zip(names, np.bincount(codes[codes >= 0], minlength=len(names)).tolist()))  # as value_counts


def coded_piece(frame: pd.DataFrame) -> Coded:
    """A piece's receivers and tags coded (Arrow's hashing, which frees the GIL: done on the reading thread)."""
    found = []
    for column in ("receiver", "tag"):
        codes, names = pd.factorize(frame[column])
        found.append((codes, [str(name) for name in names]))
    return Coded(*found)


def _breaks(data: bytes) -> int:
    """The line breaks in ``data`` (``\\n``, ``\\r\\n`` or a lone ``\\r``, as pandas ends a row)."""
    breaks = data.count(b"\n")
    return breaks + data.count(b"\r") - data.count(b"\r\n") if b"\r" in data else breaks


def _cut(data: bytes, fathom_file: bool) -> int:
    """Where a piece ends in ``data``: after its last line end at which its quotes are balanced (in a Fathom file,
    before its last ``DET`` record); 0 where there is none."""
    end = data.rfind(b"\n") + 1
    if fathom_file:
        det = max(data.rfind(b"\nDET,", 0, end), data.rfind(b'\n"DET",', 0, end))
        end = det + 1 if det > 0 else end
    while end > 0 and b'"' in data and data.count(b'"', 0, end) % 2:
        end = data.rfind(b"\n", 0, end - 1) + 1
    return end


def pieces(handle, name: str, piece_bytes: int, fathom_file: bool, line: int = 2, *, check: bool = True
           ) -> Iterator[tuple[bytes, int]]:
    """The pieces of a file from where ``handle`` stands (after its header; ``line``: the number of the next line),
    each cut by :func:`_cut`, with the number of its first line in the file; each checked as the whole-file reader
    checks its text (no NUL byte; with ``check``, its lines' lengths and cells: else the caller's to check, as
    :func:`frames` does of a piece not :mod:`.plain`).

    Raises
    ------
    ModelError
        A NUL byte, a line longer than 1 MiB or of too many cells, a quoted cell spanning more than a piece.
    """
    rest = b""
    size = min(piece_bytes, FIRST_FATHOM_BYTES) if fathom_file else piece_bytes  # its _DESC lines in a piece alone
    while True:
        data = handle.read(size)
        size = piece_bytes
        ended = not data
        data = rest + data
        if not data:
            return
        end = len(data) if ended else _cut(data, fathom_file)
        if end == 0:
            if len(data) > max(piece_bytes, MAX_LINE_BYTES) * 4:
                raise ModelError(f"{_WHAT}: {name!r} line {line}: no line end where quotes close within "
                                 f"{len(data) // 2**20} MiB; allowed: lines of at most 1 MiB, a quoted cell closed")
            rest = data
            continue
        piece, rest = data[:end], data[end:]
        nul = piece.find(b"\0")
        if nul >= 0:
            raise not_text(name, _WHAT, piece, nul)
        if check:
            check_cells(piece, name, _WHAT, max_cells=MAX_DETECTION_CELLS, first_line=line)
        yield piece, line
        line += _breaks(piece)
        if ended:
            return


def _decoded(data: bytes, encoding: str) -> str:
    try:
        return data.decode(encoding)
    except UnicodeDecodeError:
        raise NotUtf8() from None


def _last_line(text: str, starts: tuple[str, ...]) -> str | None:
    """The last line of ``text`` starting with one of ``starts`` (its line end dropped), None where none does."""
    best = -1
    for start in starts:
        at = text.rfind(start)
        while at > 0 and text[at - 1] != "\n":
            at = text.rfind(start, 0, at)
        best = max(best, at)
    if best < 0:
        return None
    end = text.find("\n", best)
    return text[best:end if end >= 0 else len(text)].rstrip("\r")


def desc_line(text: str, record: str) -> str | None:
    """The last ``<record>_DESC`` line of a Fathom CSV's ``text`` (its columns, comma-separated as Fathom writes
    them; quoted or not), None where none is."""
    return _last_line(text, (f"{record}_DESC,", f'"{record}_DESC",'))


def _fathom_piece(head: str, descs: dict[str, str], text: str, line: int, name: str
                  ) -> tuple[list[str], pd.DataFrame, list[int]] | None:
    """A Fathom piece's ``DET`` (and ``DET_SENS``) tables under the ``_DESC`` lines in force (``descs``, updated
    from the piece), their rows numbered by the file's lines; None where no ``DET_DESC`` has come yet."""
    carried = [descs[record] for record in fathom.FATHOM_RECORDS if record in descs]
    for record in fathom.FATHOM_RECORDS:
        found = desc_line(text, record)
        if found is not None:
            descs[record] = found
    if "DET" not in descs:
        return None
    shift = line - (2 + len(carried))  # the piece's first line follows Fathom's first line and the carried lines
    header, body, lines = fathom.fathom_records("\n".join([head, *carried, text]), name, _WHAT, MAX_DETECTIONS,
                                                MAX_DETECTION_CELLS)
    sensors = body.attrs.get("sensors")
    if sensors is not None:
        body.attrs["sensors"] = (sensors[0], sensors[1], [k + shift for k in sensors[2]])
    return header, body, [k + shift for k in lines]


def _text_piece(format: str, head: str, descs: dict[str, str], piece: bytes, line: int, name: str, encoding: str
                ) -> tuple[pd.DataFrame, list[str], set[int]] | None:
    """A piece read by the text reader (its cells checked, decoded; a Fathom piece under ``descs``, updated from it):
    its detections, header and columns used; None where it holds none."""
    check_cells(piece, name, _WHAT, max_cells=MAX_DETECTION_CELLS, first_line=line)
    text = _decoded(piece, encoding)
    if format == "fathom":
        table = _fathom_piece(head, descs, text, line, name)
        if table is None:
            return None
        header, body, lines = table
    else:
        header, body, lines = text_table(head + "\n" + text, name, _WHAT, MAX_DETECTIONS, first_line=line - 1,
                                         max_cells=MAX_DETECTION_CELLS)
    if not len(body):
        return None
    frame, used = rows_read(format, header, body, lines, name, _WHAT)
    return frame, header, used


def _table_piece(format: str, head: str, header: list[str] | None, descs: dict[str, str], piece: bytes, line: int,
                 name: str, encoding: str) -> tuple[pd.DataFrame, list[str], set[int]] | None:
    """A piece of a table of one row a line: :mod:`.plain` where it is (``header`` given: UTF-8), else the text
    reader's; on a reading thread."""
    found = plain_body(piece, len(header), line) if header is not None else None
    if found is None:
        return _text_piece(format, head, descs, piece, line, name, encoding)
    frame, used = rows_read(format, header, found[0], found[1], name, _WHAT)
    return frame, header, used


def _fathom_plain_piece(head: str, descs: dict[str, str], header: list[str], empty: pd.DataFrame,
                        found: tuple[bytes, np.ndarray], piece: bytes, line: int, name: str
                        ) -> tuple[pd.DataFrame, list[str], set[int]] | None:
    """A plain Fathom piece's ``DET`` table (``found``: :func:`~.plain.fathom_detections`, parsed by Arrow) under
    the ``_DESC`` lines in force (``header``; ``empty``: their table without records, whose ``DET_SENS`` columns it
    carries), as :func:`_fathom_piece` makes it; where Arrow refuses it, the text reader's (``descs``: a copy; the
    piece holds no ``DET_`` line, so no ``_DESC`` line of its own). On a reading thread."""
    read = plain_body(found[0], len(header), 0)
    if read is None:
        return _text_piece("fathom", head, descs, piece, line, name, "utf-8")
    body, at = read
    if "sensors" in empty.attrs:
        body.attrs["sensors"] = empty.attrs["sensors"]
    frame, used = rows_read("fathom", header, body, (found[1][at] + line).tolist(), name, _WHAT)
    return frame, header, used


def _with_codes(read, *args) -> tuple[pd.DataFrame, list[str], set[int], Coded] | None:
    """``read(*args)``'s piece with its receivers and tags coded (:func:`coded_piece`), None where it holds none."""
    found = read(*args)
    return None if found is None else (*found, coded_piece(found[0]))


def _after_pieces_read(source: Iterator[tuple[bytes, int]], queue: deque[Future]
                       ) -> Iterator[tuple[bytes, int]]:
    """``source``'s pieces; where it refuses one (a NUL byte, a line too long), the pieces before it in ``queue``
    first, so that the file's first fault is the one named."""
    try:
        yield from source
    except ModelError:
        for earlier in list(queue):
            earlier.result()
        raise


def frames(path: Path, format: str, encoding: str, piece_bytes: int, digest, progress: Progress
           ) -> Iterator[tuple[pd.DataFrame, list[str], set[int], Coded]]:
    """Each piece's detections (the format's reader), its header, the header's columns used and its receivers and
    tags coded (:func:`coded_piece`), in the file's order; a piece of a table of one row a line, UTF-8 and
    :mod:`.plain`, parsed by Arrow's CSV reader, every other by the text reader. :data:`READING_THREADS` pieces are
    read at once on threads (their cells' checks are Arrow's kernels, which free the GIL), a piece's refusal raised
    in the file's order; a Fathom piece that is not plain is read in this thread, in order (its ``_DESC`` lines are
    in force for the pieces after it), its refusal raised in its turn too."""
    name = str(path)
    with open(path, "rb") as handle, ThreadPoolExecutor(READING_THREADS) as pool:
        first = handle.readline(MAX_LINE_BYTES + 2)
        digest.update(first)
        check_cells(first, name, _WHAT)
        head = _decoded(first, encoding + ("-sig" if encoding == "utf-8" else "")).rstrip("\r\n")
        descs: dict[str, str] = {}
        known: dict = {}
        header = text_table(head, name, _WHAT, MAX_DETECTIONS, max_cells=MAX_DETECTION_CELLS)[0] \
            if format != "fathom" and encoding == "utf-8" else None
        queue: deque[Future] = deque()
        try:
            for piece, line in _after_pieces_read(pieces(handle, name, piece_bytes, format == "fathom", check=False),
                                                  queue):
                digest.update(piece)
                progress.update(len(piece))
                if format != "fathom":
                    queue.append(pool.submit(_with_codes, _table_piece, format, head, header, descs, piece, line, name,
                                             encoding))
                elif (found := fathom_detections(piece) if encoding == "utf-8" and "DET" in descs else None) is None:
                    done: Future = Future()  # read here, its refusal raised in its turn as a thread's is
                    try:
                        done.set_result(_with_codes(_text_piece, format, head, descs, piece, line, name, encoding))
                    except (ModelError, NotUtf8) as exc:
                        done.set_exception(exc)
                    queue.append(done)
                else:
                    carried = tuple(descs[record] for record in fathom.FATHOM_RECORDS if record in descs)
                    if carried not in known:  # each set of _DESC lines' tables without records, made once
                        known[carried] = fathom.fathom_records("\n".join([head, *carried]), name, _WHAT,
                                                               MAX_DETECTIONS, MAX_DETECTION_CELLS)
                    queue.append(pool.submit(_with_codes, _fathom_plain_piece, head, dict(descs), known[carried][0],
                                             known[carried][1], found, piece, line, name))
                while len(queue) > READING_THREADS:
                    if (read := queue.popleft().result()) is not None:
                        yield read
            while queue:
                if (read := queue.popleft().result()) is not None:
                    yield read
        finally:
            for waiting in queue:  # a refusal, or the reader stopped: the pieces not begun dropped
                waiting.cancel()


__all__ = ["Coded", "FIRST_FATHOM_BYTES", "NotUtf8", "READING_THREADS", "coded_piece", "desc_line", "frames",
           "pieces"]
