"""The memory a stage freed handed back to the system between stages (``orchestrator/io/memory.py``), measured as the
process's resident memory in ``/proc``."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from sblsim.orchestrator.io import memory

STATM = Path("/proc/self/statm")


def _resident() -> int:
    """This process's resident memory [bytes] (proc(5): statm's second field, in pages)."""
    return int(STATM.read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.skipif(memory._trim() is None or not STATM.is_file(), reason="glibc's malloc_trim on Linux only")
def test_freed_heap_pages_are_handed_back():
    """Arrays of 64 KiB come from the C library's heap; nine in ten freed leave holes it keeps resident (only the
    heap's top is returned as it is freed). ``release`` hands most of them back; those kept are untouched."""
    memory.release()  # the heap's free pages of the tests before, which the arrays would reuse, handed back first
    before = _resident()
    blocks = [np.full(8192, float(k)) for k in range(2000)]  # 125 MiB, every page written
    grown = _resident() - before
    kept = blocks[::10]
    del blocks
    held = _resident() - before
    assert grown > 100 * 2**20 and held > 0.8 * grown  # freed, still resident: what release is for
    memory.release()
    after = _resident() - before
    assert after < held - 0.5 * 0.9 * grown  # at least half the freed nine tenths handed back
    assert all(block[0] == 10 * k and block[-1] == 10 * k for k, block in enumerate(kept))


def test_release_off_glibc_is_arrows_alone(monkeypatch):
    """Off Linux (macOS, Windows) there is no ``malloc_trim`` to call: ``release`` returns Arrow's pool alone and
    raises nothing."""
    memory._trim.cache_clear()
    monkeypatch.setattr(memory.sys, "platform", "darwin")
    try:
        assert memory._trim() is None
        memory.release()
    finally:
        memory._trim.cache_clear()
