"""A study's detections as a command takes them: a file read whole, or a store's folder (:mod:`.query`), told apart
by the folder's ``store.json``. Light: pyarrow's dataset and Parquet modules (about a gigabyte of address space
reserved at import) are loaded only where a store is read."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Sequence

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.detections import Detections, read_detections
from sblsim.orchestrator.readers.transmitters import match
from sblsim.orchestrator.store.layout import STORE_FILE


def is_store(path: str | Path) -> bool:
    """Whether ``path`` is a folder holding a ``store.json`` (a store, or a folder claiming to be one:
    :class:`~.query.Store` then checks it)."""
    path = Path(path)
    return path.is_dir() and (path / STORE_FILE).is_file()


def read_any(path: str | Path, format: str | None = None, tags: Iterable[str] | None = None,
             columns: Sequence[str] | None = None) -> Detections:
    """A detections file read whole (:func:`~sblsim.orchestrator.readers.detections.read_detections`, within its
    limits), or a store's detections (:meth:`~.query.Store.detections`: no row limit but memory), as one table; of a
    store, where ``tags`` are given, those tags' rows alone (each found among the store's tags as an id or a full ID:
    :func:`~sblsim.orchestrator.readers.transmitters.match`; a name it does not hold, or holds twice, reads nothing),
    and where ``columns`` are given, those columns alone read from its files (with the ones every store holds:
    :meth:`~.query.Store.detections`); a file read whole keeps every column.

    Raises
    ------
    ModelError
        The reader's refusals; a store that is none (:class:`~.query.Store`), or whose format is not ``format``; of
        a store, ``tags`` of which it holds none.
    """
    if not is_store(path):
        return read_detections(path, format)
    from sblsim.orchestrator.store.query import Store  # pyarrow's dataset and Parquet: a gigabyte of address space

    store = Store(path)
    held = store.info.get("format")
    if format is not None and format != held:
        raise ModelError(f"format: {format!r}, but the store {str(path)!r} holds {held!r} detections (read from "
                         f"{store.info.get('source')!r}); allowed: {held!r} or none")
    keys = None if tags is None else sorted({k for t in tags if (k := _held(t, store.tags)) is not None})
    if keys == [] and tags:
        asked = sorted(map(str, tags))
        raise ModelError(f"tag: {', '.join(asked[:8])} {'is' if len(asked) == 1 else 'are'} never detected in the "
                         f"store {str(path)!r}; allowed: one of {', '.join(store.tags[:8])}"
                         + (f" ({len(store.tags)} tags)" if len(store.tags) > 8 else ""))
    detections = store.detections(tags=keys, columns=columns)
    detections.source = f"{path} (the store of {store.info.get('source')})"
    return detections


def _held(name: str, held: list[str]) -> str | None:
    """The store's tag ``name`` stands for, None where none (or two: an id two code spaces share)."""
    try:
        return match(name, held)
    except ModelError:
        return None


__all__ = ["is_store", "read_any"]
