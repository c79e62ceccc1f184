"""``sblsim store`` and ``sblsim.store``: a detections file read into a store (Apache Parquet files and a
``store.json``) a piece at a time, in memory bounded by the piece, not the file; the work is
:mod:`sblsim.orchestrator.store`. ``sblsim track``, ``sync`` and ``toa`` read a store's folder given as their
detections.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sblsim.orchestrator.commands.console import output_folder
from sblsim.orchestrator.io.arguments import path_argument, prepare_out, text_argument
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.io.progress import ProgressSpec, check_progress
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.store.layout import STORE_FILE


@dataclass
class StoreResult:
    """The outcome of :func:`store`.

    Attributes
    ----------
    info : dict
        ``store.json``: the file read (``source``, ``source_bytes``, ``source_sha256``), ``format``, ``encoding``,
        ``rows``, ``files``, ``time_span_s`` [s since 1970 UTC], ``clock_resets``, ``ignored_columns``, each tag's and
        receiver's detections (``tags``, ``receivers``), ``seconds`` (the wall time [s]).
    out : Path
        The store's folder: read it with :class:`sblsim.orchestrator.store.query.Store`, pyarrow, R's ``arrow`` or
        DuckDB.
    """

    info: dict[str, Any]
    out: Path


def store(detections: str | Path, *, out: str | Path, format: str | None = None, force: bool = False,
          progress: ProgressSpec = False) -> StoreResult:
    """Read a detections file into a store: ``sblsim store``.

    Parameters
    ----------
    detections : str or Path
        Raw detections in any format :func:`sblsim.orchestrator.readers.detections.read_detections` reads (a YAPS
        table, a VUE export, a Fathom CSV, a GLATOS or OTN extract, actel's detections, a Thelma export), of any
        size the disk holds.
    out : str or Path
        The store's folder.
    format : str, optional
        One of :data:`~sblsim.orchestrator.readers.formats.FORMATS`; default read from the file's first line.
    force : bool
        Replace an earlier store in ``out``.
    progress : bool, str or callable
        :data:`~sblsim.orchestrator.io.progress.ProgressSpec`, in bytes of the file.

    Returns
    -------
    StoreResult

    Raises
    ------
    ModelError
        One line: a cell the reader refuses (naming the file's line and column), a disk without the file's size
        free or that fills (nothing kept), an earlier store in ``out`` without ``force``, a file in ``out`` that
        sblsim did not write.
    """
    from sblsim.orchestrator.store.ingest import ingest

    detections = path_argument(detections, "detections", optional=False)
    if format is not None:
        format = text_argument(format, "format")
    check_progress(progress)
    target = prepare_out(path_argument(out, "out", optional=False), force, STORE_FILE, "store")
    return StoreResult(ingest(detections, target, format, progress=progress), target)


NAME = "store"
HELP = "read a detections file of any size into a store (Parquet) that track, sync and toa read"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim store``'s arguments."""
    p.add_argument("detections", type=Path, help="raw detections: a YAPS table, a VUE export, a Fathom (VDAT) CSV, a "
                   "GLATOS or an OTN extract, actel's detections or a Thelma export")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="the detections' format (default: read from the file's first line)")
    p.add_argument("--out", type=Path, default=None, help="the store's folder (default results/store_NAME)")
    p.add_argument("--force", action="store_true", help="replace an earlier store in --out")


def lines(info: dict[str, Any], out: Path) -> list[str]:
    """What ``sblsim store`` prints of a store written (``info``: its ``store.json``)."""
    from sblsim.orchestrator.readers.detections import reset_line

    rate = info["rows"] / max(info["seconds"], 1e-9)
    size = sum(f.stat().st_size for f in (out / "detections").glob("*.parquet")) / 2**20
    said = [f"store: {info['rows']:,} detections of {len(info['tags']):,} tags at {len(info['receivers']):,} "
            f"receivers ({info['format']}, {info['source_bytes'] / 2**20:,.1f} MiB) read in {info['seconds']:.1f} s "
            f"({rate:,.0f} detections/s) into {out}/ ({size:,.1f} MiB of Parquet)"]
    said += [f"note: {reset_line(reset)}" for reset in info["clock_resets"][:10]]
    if info["ignored_columns"]:
        said.append(f"note: columns not used: {', '.join(info['ignored_columns'][:12])}")
    said.append(f"next: sblsim track {out} --receivers SHEET (or sync, toa): the store read as its file")
    return said


def main(args: argparse.Namespace) -> int:
    """``sblsim store`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.store.ingest import ingest

    out = output_folder(args.out, Path("results") / f"store_{folder_name(args.detections.stem)}", args.force,
                        STORE_FILE, "store")
    info = ingest(args.detections, out, args.format, progress="auto")
    for line in lines(info, out):
        print(line)
    return 0


__all__ = ["StoreResult", "store"]
