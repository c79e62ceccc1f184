"""A detections file cut into pieces, and a piece read into its detections (:mod:`.ingest` stores them).

A piece is about ``piece_bytes`` bytes cut at a line's end (where the quotes of the piece are balanced: a quoted cell
spanning lines is never cut; in a Fathom CSV, before a ``DET`` record, so that a detection's ``DET_SENS`` records stay
with it), and it is read by the very reader of :func:`~sblsim.orchestrator.readers.detections.read_detections` under
the file's header (a Fathom piece under the ``_DESC`` lines in force there): the same cells checked with the same rules
and errors, naming the file's own lines. A plain piece is cut into its cells by Arrow's CSV reader (:mod:`.plain`),
every other by the text reader's pandas. What a piece needs from the pieces before it is its job's
(:func:`piece_jobs`: the header, the ``_DESC`` lines in force), so that the pieces are read in any process, in any
order, and their detections taken in the file's order (:func:`in_order`).
"""

from __future__ import annotations

import functools
from collections import deque
from concurrent.futures import Executor, Future
from typing import Iterable, Iterator

import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.tables import MAX_LINE_BYTES, check_cells
from sblsim.orchestrator.readers import fathom
from sblsim.orchestrator.readers.binary import not_text
from sblsim.orchestrator.readers.cells import text_table
from sblsim.orchestrator.readers.detections import rows_read
from sblsim.orchestrator.readers.limits import MAX_DETECTION_CELLS, MAX_DETECTIONS
from sblsim.orchestrator.store.plain import fathom_detections, plain_body

#: A Fathom CSV's first piece [bytes]: its ``_DESC`` lines, which the text reader reads (the pieces after them, in the
#: lines' columns, are read by Arrow: :func:`~.plain.fathom_detections`).
FIRST_FATHOM_BYTES = 2**16
#: The pieces each side of the one read: read ahead by :func:`in_order` [1 per worker, and one more].
AHEAD = 1
_WHAT = "detections"


class NotUtf8(Exception):
    """A piece that is not UTF-8: the file is read again in Latin-1."""


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
    :func:`_frames` does of a piece not :mod:`.plain`).

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


def decoded(data: bytes, encoding: str) -> str:
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


def _fathom_piece(head: str, descs: dict[str, str], text: str, line: int, name: str
                  ) -> tuple[list[str], pd.DataFrame, list[int]] | None:
    """A Fathom piece's ``DET`` (and ``DET_SENS``) tables under the ``_DESC`` lines in force (``descs``, updated
    from the piece), their rows numbered by the file's lines; None where no ``DET_DESC`` has come yet."""
    carried = [descs[record] for record in fathom.FATHOM_RECORDS if record in descs]
    for record in fathom.FATHOM_RECORDS:
        found = _last_line(text, (f"{record}_DESC,", f'"{record}_DESC",'))
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


def _fathom_plain(head: str, descs: dict[str, str], piece: bytes, line: int, name: str
                  ) -> tuple[list[str], pd.DataFrame, list[int]] | None:
    """A plain Fathom piece's ``DET`` table (:func:`~.plain.fathom_detections`, parsed by Arrow) under the
    ``_DESC`` lines in force, as :func:`_fathom_piece` makes it (the same header; the ``DET_SENS`` table it carries
    empty); None where the piece is not plain (then read by :func:`_fathom_piece`)."""
    if "DET" not in descs:
        return None
    found = fathom_detections(piece)
    if found is None:
        return None
    carried = tuple(descs[record] for record in fathom.FATHOM_RECORDS if record in descs)
    header, empty, _ = _desc_tables(head, carried, name)
    read = plain_body(found[0], len(header), 0)
    if read is None:
        return None
    body, at = read
    if "sensors" in empty.attrs:
        body.attrs["sensors"] = empty.attrs["sensors"]
    return header, body, (found[1][at] + line).tolist()


@functools.lru_cache(maxsize=16)
def _desc_tables(head: str, carried: tuple[str, ...], name: str) -> tuple[list[str], pd.DataFrame, list[int]]:
    """The tables of a Fathom file's first line and ``_DESC`` lines ``carried``, without records (each set read once
    in a process, for every piece under it)."""
    return fathom.fathom_records("\n".join([head, *carried]), name, _WHAT, MAX_DETECTIONS, MAX_DETECTION_CELLS)


def advance_descs(descs: dict[str, str], piece: bytes, encoding: str) -> None:
    """The ``_DESC`` lines in force after ``piece`` (``descs``, updated in place: each record's last ``_DESC`` line
    in the piece), as :func:`_fathom_piece` updates them; a piece without a ``_DESC`` line changes none (a plain
    piece, :func:`~.plain.fathom_detections`, holds no ``DET_`` record's line)."""
    if b"_DESC" not in piece:
        return
    text = decoded(piece, encoding)
    for record in fathom.FATHOM_RECORDS:
        found = _last_line(text, (f"{record}_DESC,", f'"{record}_DESC",'))
        if found is not None:
            descs[record] = found


def read_piece(format: str, encoding: str, head: str, header: list[str] | None, descs: dict[str, str],
               piece: bytes, line: int, name: str) -> tuple[pd.DataFrame, list[str], set[int]] | None:
    """A piece's detections (the format's reader, :func:`~sblsim.orchestrator.readers.detections.rows_read`), its
    header and the header's columns used; None where it holds none (a Fathom piece before its ``DET_DESC``).

    Parameters
    ----------
    format, encoding : str
        The file's format and encoding.
    head : str
        The file's first line, decoded.
    header : list of str or None
        Its cells (None for a Fathom file, or a file not UTF-8: the text reader reads the piece under ``head``).
    descs : dict
        A Fathom file's ``_DESC`` lines in force before the piece (by record; a copy is updated).
    piece : bytes
        Whole lines of the file (:func:`pieces`), the first of them the file's line ``line``.
    name : str
        The file's name, as the errors say it.

    Raises
    ------
    ModelError
        As the whole-file reader, naming the file's line and column.
    NotUtf8
        The piece is not UTF-8 (the file is read again in Latin-1).
    """
    if format == "fathom":
        descs = dict(descs)
        read = _fathom_plain(head, descs, piece, line, name) if encoding == "utf-8" else None
    else:
        found = plain_body(piece, len(header), line) if header is not None else None
        read = None if found is None else (header, *found)
    if read is not None:
        frame, used = rows_read(format, read[0], read[1], read[2], name, _WHAT)
        return frame, read[0], used
    check_cells(piece, name, _WHAT, max_cells=MAX_DETECTION_CELLS, first_line=line)
    text = decoded(piece, encoding)
    if format == "fathom":
        table = _fathom_piece(head, descs, text, line, name)
        if table is None:
            return None
        header_read, body, lines = table
    else:
        header_read, body, lines = text_table(head + "\n" + text, name, _WHAT, MAX_DETECTIONS, first_line=line - 1,
                                              max_cells=MAX_DETECTION_CELLS)
    if not len(body):
        return None
    frame, used = rows_read(format, header_read, body, lines, name, _WHAT)
    return frame, header_read, used


def in_order(jobs: Iterable[tuple], executor: Executor | None, workers: int
             ) -> Iterator[tuple[pd.DataFrame, list[str], set[int]]]:
    """Each job's :func:`read_piece` (its arguments), those with detections, in the jobs' order: in this process
    where ``executor`` is None, else in the executor's ``workers`` with a piece more than them read ahead (the memory
    of ``workers`` + 1 pieces and their detections). An error is raised where the jobs' order meets it: a piece's,
    or the file's beyond it (a NUL byte, a line too long) after the pieces before it have been read."""
    if executor is None:
        for job in jobs:
            found = read_piece(*job)
            if found is not None:
                yield found
        return
    queue: deque[Future] = deque()
    jobs = iter(jobs)
    failed: BaseException | None = None
    try:
        while True:
            while failed is None and len(queue) < workers + AHEAD:
                try:
                    job = next(jobs)
                except StopIteration:
                    break
                except (ModelError, NotUtf8) as exc:  # said once the pieces before it are read
                    failed = exc
                    break
                queue.append(executor.submit(read_piece, *job))
            if not queue:
                break
            found = queue.popleft().result()
            if found is not None:
                yield found
    finally:
        for future in queue:
            future.cancel()
    if failed is not None:
        raise failed


__all__ = ["AHEAD", "FIRST_FATHOM_BYTES", "NotUtf8", "advance_descs", "decoded", "in_order", "pieces", "read_piece"]
