"""Memory a long computation has freed handed back to the system between its stages (:func:`release`).

pandas' text columns are Arrow's, and Arrow's memory pool (mimalloc) keeps the memory its buffers freed for its next
allocation: over a season's synchronisation the sync tags' rows' strings, their lookups and copies are freed early
and kept, and the resident memory grew with the season's length (`docs/benchmarks.md`, "A season's
synchronisation").
"""

from __future__ import annotations

import pyarrow as pa


def release() -> None:
    """Arrow's default memory pool's freed memory returned to the system (``pyarrow.MemoryPool.release_unused``:
    on mimalloc, the calling thread's freed pages; the buffers in use are untouched). Costs milliseconds: called
    between a computation's stages, not in its loops."""
    pa.default_memory_pool().release_unused()


__all__ = ["release"]
