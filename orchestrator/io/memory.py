"""Memory a long computation has freed handed back to the system between its stages (:func:`release`).

pandas' text columns are Arrow's, and Arrow's memory pool (mimalloc) keeps the memory its buffers freed for its next
allocation: over a season's synchronisation the sync tags' rows' strings, their lookups and copies are freed early
and kept, and the resident memory grew with the season's length (`docs/benchmarks.md`, "A season's
synchronisation"). The C library's allocator (glibc's ``malloc``) does the same with the arrays NumPy and pandas
free: a freed array of more than its threshold for mapping memory raises that threshold (up to 32 MiB), the next
ones of that size come from its heap, and freed heap pages stay resident: over a season's tracking the study's
process grew as each tag's result came back, was written and let go (`docs/benchmarks.md`, "What a season's study
keeps").

Arrow's pool is made jemalloc's, its freed pages handed back at once, as the command line starts (:func:`arrow_pool`):
mimalloc's, Arrow's default on Linux, kept memory it had freed resident through a season's study
(`docs/benchmarks.md`, "Arrow's pool").

What a stage does not need need not be held through it: a table whose rows are let go for good is made anew empty
(:func:`emptied`: a slice of it, or a copy of one, would hold its buffers), and one needed again after the stage is
kept on disk through it (:func:`spilled`).
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import importlib.util
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any


@functools.cache
def _trim():
    """glibc's ``malloc_trim`` (man 3 malloc_trim), or None on another C library or system."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        trim = ctypes.CDLL(None).malloc_trim  # the process's own symbols, its C library's among them
    except (OSError, AttributeError):  # no glibc (musl has no malloc_trim)
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


def release() -> None:
    """Arrow's default memory pool's freed memory returned to the system (``pyarrow.MemoryPool.release_unused``:
    on mimalloc, the calling thread's freed pages; on jemalloc, every arena's; the buffers in use are untouched),
    and on glibc its heaps' free pages too (``malloc_trim(0)``). Costs milliseconds: called between a computation's
    stages, not in its loops."""
    import pyarrow as pa  # (imported here: the modules that call this one import no Arrow at their own import)

    pa.default_memory_pool().release_unused()
    trim = _trim()
    if trim is not None:
        trim(0)


#: The environment variable by which Arrow takes its default memory pool (``jemalloc``, ``mimalloc``, ``system``):
#: where a user set it, :func:`arrow_pool` leaves Arrow's choice as it is.
POOL_VARIABLE = "ARROW_DEFAULT_MEMORY_POOL"
#: The environment variable by which Arrow's own jemalloc (its symbols prefixed ``je_arrow_``) takes its settings as it
#: starts (jemalloc's ``MALLOC_CONF``, jemalloc(3)); :func:`arrow_pool` sets its pages' decay to none where a user did
#: not set it: freed pages handed back to the system at once (Arrow's own setting keeps them a second, and a page freed
#: in an arena made before ``pyarrow.jemalloc_set_decay_ms`` is called keeps that setting).
DECAY_VARIABLE = "JE_ARROW_MALLOC_CONF"


@functools.cache
def arrow_pool(decay: bool = True) -> str | None:
    """Arrow's default memory pool made jemalloc's, where the installed pyarrow has jemalloc (not every build has:
    Windows' wheels have none; its build's ``arrow/util/config.h`` says) and ``ARROW_DEFAULT_MEMORY_POOL`` names no
    pool: the variable set, with jemalloc's freed pages handed back at once unless ``decay`` is False
    (:data:`DECAY_VARIABLE`: a store's reading, whose memory is its piece's, was 12 % slower with it), for this
    process where pyarrow is not imported yet (Arrow's C++ library takes its default pool once, when it is loaded)
    and for every worker process it starts; where pyarrow is imported already, its Python functions' pool
    (``pyarrow.set_memory_pool``) too. mimalloc's, Arrow's default on Linux, kept what it had freed resident (a
    season's study of 91 days: 123 MiB of its region when the tags' tracking began, 26 MiB of it allocated); on
    jemalloc's a season's study peaked a fifth lower at 28 and at 91 days, in the same time (`docs/benchmarks.md`,
    "Arrow's pool"). Buffers made before keep their own pool. Called as ``sblsim``'s command line starts (``sblsim
    store``'s without ``decay``), and by :func:`sblsim.track`, :func:`sblsim.sync` and :func:`sblsim.store`; the
    first call of a process sets the variables.

    Returns
    -------
    str or None
        The pool ``ARROW_DEFAULT_MEMORY_POOL`` names after the call; None where it names none (no jemalloc).
    """
    named = os.environ.get(POOL_VARIABLE)
    if named:
        return named
    if not _has_jemalloc():
        return None
    os.environ[POOL_VARIABLE] = "jemalloc"
    if decay:
        os.environ.setdefault(DECAY_VARIABLE, "dirty_decay_ms:0,muzzy_decay_ms:0")
    if "pyarrow" in sys.modules:
        import pyarrow as pa

        pa.set_memory_pool(pa.jemalloc_memory_pool())
    return "jemalloc"


def _has_jemalloc() -> bool:
    """Whether the installed pyarrow's Arrow was built with jemalloc (``#define ARROW_JEMALLOC`` in its
    ``arrow/util/config.h``), found without importing it; False where it cannot tell."""
    try:
        spec = importlib.util.find_spec("pyarrow")
        folder = Path(spec.origin).parent if spec is not None and spec.origin else None
        config = None if folder is None else folder / "include" / "arrow" / "util" / "config.h"
        return config is not None and config.is_file() and \
            re.search(r"^#define ARROW_JEMALLOC\b", config.read_text(errors="replace"), re.M) is not None
    except (OSError, ImportError, ValueError):
        return False


def emptied(frame: Any) -> Any:
    """A pandas DataFrame of no rows with ``frame``'s columns and dtypes, made anew: it holds none of ``frame``'s
    buffers (``frame.iloc[:0]`` is a view of them, and a copy of it still holds its Arrow text buffers)."""
    import pandas as pd

    return pd.DataFrame(columns=frame.columns).astype(frame.dtypes.to_dict())


@contextlib.contextmanager
def spilled(holder: Any, name: str, folder: Path) -> Iterator[None]:
    """``holder``'s table ``name`` (a pandas DataFrame attribute) kept on disk while the block runs, as Parquet in a
    folder of its own made in ``folder`` (the attribute None meanwhile), then read back and the folder removed,
    whether the block ends or raises. Read back its values are the same, its text columns Arrow's strings (as a
    table kept for a resumed run is read). Where it cannot be written (a full disk) it stays in memory.

    Raises
    ------
    OSError
        The table cannot be read back (its folder removed under the run).
    """
    import pandas as pd

    table = getattr(holder, name, None)
    if table is None or not len(table):
        yield
        return
    where = None
    try:
        where = Path(tempfile.mkdtemp(prefix=".held-", dir=folder))
        table.to_parquet(where / f"{name}.parquet")
    except OSError:  # (a full disk: kept in memory, as without this)
        if where is not None:
            shutil.rmtree(where, ignore_errors=True)
        where = None
    if where is None:
        yield
        return
    setattr(holder, name, None)
    del table
    release()
    try:
        yield
    finally:
        release()  # what the block freed handed back before the table is read into it
        try:  # each column's Arrow buffers let go as it is converted, and what the reading freed handed back
            setattr(holder, name, pd.read_parquet(where / f"{name}.parquet",
                                                  to_pandas_kwargs={"self_destruct": True, "split_blocks": True}))
        finally:
            shutil.rmtree(where, ignore_errors=True)
        release()


__all__ = ["DECAY_VARIABLE", "POOL_VARIABLE", "arrow_pool", "emptied", "release", "spilled"]
