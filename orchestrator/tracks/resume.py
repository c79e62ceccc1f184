"""Finished tags kept across runs: a study (or a folder of tags) interrupted by Ctrl-C, a killed process or a full disk,
run again with the same inputs and ``--out``, tracks only the tags it had not finished (and a study takes its kept
synchronisation: :mod:`~sblsim.orchestrator.telemetry.kept_clocks`, through :meth:`Resume.store` and
:meth:`Resume.fetch`).

Each tag's outcome is kept, as it ends, in a folder beside the output, ``.OUT.resume/`` (hidden, as the staging
folders are), under the hash of everything its track depends on (:func:`job_key`: its times-of-arrival and receivers
files' bytes, its options, each file an option names by its bytes, and sblsim's version). A run finds a tag's entry
only where that hash is the same: a changed input is tracked again, never taken from before. The folder is removed
when the run's output is written.

An entry is written beside its place and renamed into it, so that a process killed while writing leaves nothing that
looks done; it holds tables as Parquet, the summary and score as JSON and arrays as ``.npz`` read without pickles: an
entry is data, never code. An entry that cannot be read is tracked again; a disk that cannot hold an entry is said
once and the run goes on without keeping the others.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import uuid
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np

from sblsim.orchestrator.io.manifest import file_digest
from sblsim.orchestrator.io.version import installed_version
from sblsim.orchestrator.tracks.outcome import TrackOutcome

#: The file that marks a folder as sblsim's resume folder (a folder of that name without it is never used or removed).
MARKER = "SBLSIM_RESUME"
#: The tables of a :class:`TrackOutcome` kept as Parquet files of these names.
TABLES = ("track", "estimates", "errors", "bound", "set_aside")


def resume_folder(out: Path) -> Path:
    """The resume folder of the output folder ``out``: ``.NAME.resume`` beside it."""
    out = Path(out).absolute()
    return out.parent / f".{out.name}.resume"


def _canonical(value: Any) -> Any:
    """A JSON-able form of an option's value; a file named by the option taken by its bytes' hash."""
    if isinstance(value, Path):
        return {"file": file_digest(value) if value.is_file() else f"missing {value.name}"}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return repr(value)


def job_key(toa: Path, receivers: Path, options: dict[str, Any]) -> str:
    """The hash (SHA-256, hex) of what one tag's track depends on: sblsim's version, the times-of-arrival and
    receivers files' bytes, and ``options`` (each value; a :class:`~pathlib.Path` by its file's bytes)."""
    text = json.dumps({"version": installed_version(), "toa": file_digest(toa), "receivers": file_digest(receivers),
                       "options": options}, sort_keys=True, default=_canonical)
    return hashlib.sha256(text.encode()).hexdigest()


class Resume:
    """The kept outcomes of one output's tags (module docstring).

    Parameters
    ----------
    out : Path
        The run's output folder; its resume folder is :func:`resume_folder`.
    """

    def __init__(self, out: Path):
        self.folder = resume_folder(out)
        self.kept = 0  # tags' outcomes found and taken by this run
        self.taken: list[str] = []  # what else this run took from the folder, in words ("the synchronisation")
        self.usable = not self.folder.is_symlink() and (not os.path.lexists(self.folder)
                                                        or (self.folder / MARKER).is_file())
        if not self.usable:
            warnings.warn(f"{str(self.folder)!r} is not sblsim's resume folder (a link, or no {MARKER} in it): "
                          "finished tags are not kept for a rerun", stacklevel=2)

    def fetch(self, key: str, read: Callable[[Path], Any]) -> Any:
        """``read(entry)`` of the entry kept under ``key``, or None where none is kept or it cannot be read."""
        entry = self.folder / key
        if not self.usable or not entry.is_dir() or entry.is_symlink():
            return None
        try:
            return read(entry)
        except Exception:  # an entry damaged or not ours: made again
            return None

    def _made(self) -> None:
        if not self.folder.exists():
            self.folder.mkdir()
            (self.folder / MARKER).write_text("sblsim keeps finished tags here for a rerun; removed when the run "
                                              "ends\n")

    def _not_kept(self, staging: Path | None, failure: tuple[str, str]) -> None:
        """``staging`` removed and its ``failure`` said: a disk's (``"disk"``: said once, the folder not used again by
        this run) or an entry's (a table a file format cannot hold: made again on a rerun, nothing lost)."""
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
        kind, said = failure
        if kind == "disk":
            self.usable = False
            warnings.warn(f"finished tags are no longer kept for a rerun ({str(self.folder)!r}: {said})", stacklevel=3)
        else:
            warnings.warn(f"an outcome is not kept for a rerun ({said})", stacklevel=3)

    def store(self, key: str, write: Callable[[Path], None]) -> None:
        """Keep an entry under ``key``: ``write(folder)`` fills a folder of a temporary name (:meth:`staging`),
        renamed ``key`` once whole (:meth:`adopt`); a disk that cannot hold it is said once and the folder is not used
        again by this run."""
        staging = self.staging(key)
        if staging is not None:
            self.adopt(key, staging, filled(staging, write))

    def staging(self, key: str) -> Path | None:
        """Where the entry of ``key`` is written (:func:`filled`; by another process sharing this filesystem,
        :func:`write_entry`): a folder of a temporary name, not yet made, then kept by :meth:`adopt`; None where
        entries are not kept."""
        if not self.usable:
            return None
        try:
            self._made()
        except OSError as exc:
            self._not_kept(None, ("disk", str(exc.strerror or exc)))
            return None
        return self.folder / f".{key}.{os.getpid()}.{uuid.uuid4().hex}"

    def adopt(self, key: str, staging: Path, failure: tuple[str, str] | None) -> None:
        """Keep the entry written into ``staging`` (:meth:`staging`) under ``key``, or say why it was not
        (``failure``: :func:`filled`'s); after a disk's failure, removed unsaid (the folder not used again)."""
        if not self.usable:
            shutil.rmtree(staging, ignore_errors=True)
            return
        if failure is None:
            try:
                os.replace(staging, self.folder / key)
                return
            except OSError as exc:
                failure = ("disk", str(exc.strerror or exc))
        self._not_kept(staging, failure)

    def load(self, key: str, where: Path) -> TrackOutcome | str | None:
        """The tag's outcome kept under ``key`` (a refusal as its line, the token of its folder made ``where``), or
        None where none is kept or it cannot be read."""
        result = self.fetch(key, lambda entry: _read(entry, where))
        self.kept += result is not None
        return result

    def save(self, key: str, result: TrackOutcome | str, where: Path) -> None:
        """Keep a tag's ``result`` under ``key`` (``where``, the folder of the tag's files, made a token in a
        refusal's line)."""
        self.store(key, lambda entry: _write(entry, result, where))

    def remove(self) -> None:
        """Remove the resume folder (the run's output is written)."""
        if self.usable and (self.folder / MARKER).is_file():
            shutil.rmtree(self.folder, ignore_errors=True)


def filled(staging: Path, write: Callable[[Path], None]) -> tuple[str, str] | None:
    """``write(staging)`` into the folder ``staging`` (made here where it is not), or why it could not: ``("disk",
    line)`` where the disk refused it, ``("entry", line)`` where the outcome cannot be kept (:meth:`Resume.adopt`)."""
    try:
        staging.mkdir(exist_ok=True)
        write(staging)
    except OSError as exc:
        return "disk", str(exc.strerror or exc)
    except Exception as exc:
        return "entry", f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"
    return None


def write_entry(staging: Path, result: TrackOutcome | str, where: Path) -> tuple[str, str] | None:
    """A tag's ``result`` kept in ``staging`` (:meth:`Resume.staging`) as :meth:`Resume.save` keeps it, in the
    process that tracked it; returns :func:`filled`'s failure, or None."""
    return filled(staging, lambda entry: _write(entry, result, where))


def write_tables(entry: Path, holder: Any, names: tuple[str, ...]) -> None:
    """Each of ``holder``'s tables ``names`` (attributes: pandas DataFrames, or None: not written) as
    ``entry/NAME.parquet``."""
    for name in names:
        table = getattr(holder, name)
        if table is not None:
            table.to_parquet(entry / f"{name}.parquet")


def read_tables(entry: Path, names: tuple[str, ...]) -> dict[str, Any]:
    """The tables :func:`write_tables` wrote, by name (None where one was not written)."""
    import pandas as pd

    return {name: pd.read_parquet(entry / f"{name}.parquet") if (entry / f"{name}.parquet").is_file() else None
            for name in names}


#: What stands for a tag's folder in a kept refusal's line (its folder differs from run to run).
_WHERE = "\x00where\x00"


def _write(entry: Path, result: TrackOutcome | str, where: Path) -> None:
    if isinstance(result, str):
        (entry / "refusal.txt").write_text(result.replace(str(where), _WHERE), encoding="utf-8")
        return
    write_tables(entry, result, TABLES)
    meta = {"summary": result.summary, "score": result.score,
            "array": None if result.array is None else list(result.array[0])}
    (entry / "outcome.json").write_text(json.dumps(meta, allow_nan=False), encoding="utf-8")
    arrays = {k: v for k, v in (("truth", result.truth),
                                ("array", None if result.array is None else result.array[1])) if v is not None}
    np.savez(entry / "arrays.npz", **arrays)


def _read(entry: Path, where: Path) -> TrackOutcome | str:
    refusal = entry / "refusal.txt"
    if refusal.is_file():
        return refusal.read_text(encoding="utf-8").replace(_WHERE, str(where))
    meta = json.loads((entry / "outcome.json").read_text(encoding="utf-8"))
    tables = read_tables(entry, TABLES)
    with np.load(entry / "arrays.npz", allow_pickle=False) as arrays:
        truth = arrays["truth"] if "truth" in arrays else None
        positions = arrays["array"] if "array" in arrays else None
    return TrackOutcome(tables["track"], tables["estimates"], tables["errors"], meta["score"], meta["summary"],
                        tables["bound"], truth, None if meta["array"] is None else (meta["array"], positions),
                        tables["set_aside"])


__all__ = ["MARKER", "Resume", "TABLES", "filled", "job_key", "read_tables", "resume_folder", "write_entry",
           "write_tables"]
