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


def _table(n: int = 50_000):
    """A table of a season's kinds of columns: Arrow text, floats, integers, booleans."""
    import pandas as pd

    rng = np.random.default_rng(3)
    names = np.array([f"A69-1602-{k}" for k in range(40)], dtype=object)
    return pd.DataFrame({"tag": pd.array(names[rng.integers(0, 40, n)], dtype="str"),
                         "receiver": names[rng.integers(0, 40, n)], "time": rng.uniform(0, 8e6, n),
                         "line": np.arange(n, dtype=np.int64), "kept": rng.random(n) < 0.9})


def test_emptied_keeps_columns_and_dtypes_and_none_of_the_rows():
    """The table made anew has no rows, the same columns and dtypes, and none of the original's buffers: the Arrow
    pool's bytes the original's text held go when the original goes (a slice, or a copy of it, keeps them)."""
    import pyarrow as pa

    table = _table()
    empty = memory.emptied(table)
    assert len(empty) == 0 and list(empty.columns) == list(table.columns)
    assert empty.dtypes.to_dict() == table.dtypes.to_dict()
    for column in ("time", "line", "kept"):
        assert not np.shares_memory(empty[column].to_numpy(), table[column].to_numpy())
    held = pa.total_allocated_bytes()
    sliced = table.iloc[:0].copy()  # the way that held them: the text column's buffers shared
    del table
    assert pa.total_allocated_bytes() == held  # the slice's copy holds the text whole
    del sliced
    assert pa.total_allocated_bytes() < held  # then they go: the empty table held none of them


class _Holder:
    residuals = None


def test_spilled_table_is_off_memory_in_the_block_and_back_after(tmp_path):
    """Inside the block the attribute is None and the table is a file in a folder of its own; after it, the same
    values (its text as Arrow strings) and no file left, whether the block ends or raises."""
    import pandas as pd

    holder = _Holder()
    holder.residuals = original = _table()
    with memory.spilled(holder, "residuals", tmp_path):
        assert holder.residuals is None
        assert [p.suffix for p in tmp_path.rglob("*") if p.is_file()] == [".parquet"]
    pd.testing.assert_frame_equal(holder.residuals, original, check_dtype=False)
    assert (holder.residuals["receiver"] == original["receiver"]).all()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(KeyboardInterrupt), memory.spilled(holder, "residuals", tmp_path):
        raise KeyboardInterrupt
    pd.testing.assert_frame_equal(holder.residuals, original, check_dtype=False)
    assert list(tmp_path.iterdir()) == []


def test_spilled_table_stays_in_memory_where_the_disk_is_full(tmp_path, monkeypatch):
    """A table that cannot be written (no space left) is held as without the spill: the block runs, nothing is left
    on disk."""
    import errno

    import pandas as pd

    def full(self, path, *args, **kwargs):
        Path(path).write_bytes(b"PAR1")  # a part written before the disk filled
        raise OSError(errno.ENOSPC, "No space left on device")

    holder = _Holder()
    holder.residuals = original = _table(100)
    monkeypatch.setattr(pd.DataFrame, "to_parquet", full)
    with memory.spilled(holder, "residuals", tmp_path):
        assert holder.residuals is original
    assert holder.residuals is original and list(tmp_path.iterdir()) == []


def test_spilled_table_stays_in_memory_where_no_folder_can_be_made(tmp_path):
    """The folder to spill into cannot be made (here: its parent is a file): the table is held, the block runs."""
    holder = _Holder()
    holder.residuals = original = _table(100)
    parent = tmp_path / "a-file"
    parent.write_text("")
    with memory.spilled(holder, "residuals", parent):
        assert holder.residuals is original
    assert holder.residuals is original and [p.name for p in tmp_path.iterdir()] == ["a-file"]


_POOL_CHILD = """
import json, os, sys
if sys.argv[1]:
    os.environ["ARROW_DEFAULT_MEMORY_POOL"] = sys.argv[1]
else:
    os.environ.pop("ARROW_DEFAULT_MEMORY_POOL", None)
os.environ.pop("JE_ARROW_MALLOC_CONF", None)
if sys.argv[2] == "before":
    import pyarrow
from sblsim.orchestrator.io.memory import arrow_pool
loaded = "pyarrow" in sys.modules
first = arrow_pool(decay=sys.argv[3] == "decay")
import pyarrow as pa
print(json.dumps({"loaded": loaded, "first": first, "again": arrow_pool(decay=sys.argv[3] == "decay"),
                  "backend": pa.default_memory_pool().backend_name,
                  "made": pa.array([1.5, 2.5]).buffers()[1] is not None,
                  "variable": os.environ.get("ARROW_DEFAULT_MEMORY_POOL"),
                  "decay": os.environ.get("JE_ARROW_MALLOC_CONF"),
                  "supported": pa.supported_memory_backends()}))
"""


@pytest.mark.parametrize("variable, imported, decay", [("", "after", "decay"), ("", "before", "decay"),
                                                       ("", "after", "kept"), ("system", "after", "decay")])
def test_arrow_pool_is_jemallocs_unless_the_user_named_one(variable, imported, decay):
    """In a fresh process: with no ``ARROW_DEFAULT_MEMORY_POOL``, Arrow's default pool becomes jemalloc's where this
    pyarrow has it, pyarrow imported after the call or before it, and the variable says so to the worker processes,
    jemalloc's pages' decay none unless asked to keep it (a store's); else Arrow's own default is kept, the
    variables unset; a pool the user named is kept, the variables untouched. The memory module itself does not
    load pyarrow."""
    import json
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-c", _POOL_CHILD, variable, imported, decay], capture_output=True,
                         text=True, check=True)
    got = json.loads(run.stdout)
    assert got["loaded"] == (imported == "before") and got["first"] == got["again"] and got["made"]
    assert "Unsupported backend" not in run.stderr
    if variable:
        assert got["backend"] == got["first"] == got["variable"] == variable and got["decay"] is None
    elif "jemalloc" in got["supported"]:
        assert got["backend"] == got["first"] == got["variable"] == "jemalloc"
        assert got["decay"] == ("dirty_decay_ms:0,muzzy_decay_ms:0" if decay == "decay" else None)
    else:
        assert got["backend"] != "jemalloc" and got["first"] is None and got["variable"] is got["decay"] is None
