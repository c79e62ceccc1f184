"""Memory a long computation has freed handed back to the system between its stages (:func:`release`).

pandas' text columns are Arrow's, and Arrow's memory pool (mimalloc) keeps the memory its buffers freed for its next
allocation: over a season's synchronisation the sync tags' rows' strings, their lookups and copies are freed early
and kept, and the resident memory grew with the season's length (`docs/benchmarks.md`, "A season's
synchronisation"). The C library's allocator (glibc's ``malloc``) does the same with the arrays NumPy and pandas
free: a freed array of more than its threshold for mapping memory raises that threshold (up to 32 MiB), the next
ones of that size come from its heap, and freed heap pages stay resident: over a season's tracking the study's
process grew as each tag's result came back, was written and let go (`docs/benchmarks.md`, "What a season's study
keeps").
"""

from __future__ import annotations

import ctypes
import functools
import sys


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
    on mimalloc, the calling thread's freed pages; the buffers in use are untouched), and on glibc its heaps' free
    pages too (``malloc_trim(0)``). Costs milliseconds: called between a computation's stages, not in its loops."""
    import pyarrow as pa  # (imported here: the modules that call this one import no Arrow at their own import)

    pa.default_memory_pool().release_unused()
    trim = _trim()
    if trim is not None:
        trim(0)


__all__ = ["release"]
