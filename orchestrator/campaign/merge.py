"""The Parquet merge: the chunk files of a campaign into one sorted ``runs.parquet``."""

from __future__ import annotations

import os
import tempfile
from collections import OrderedDict
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from sblsim.orchestrator.campaign.plan import Chunk

#: Rows per row group of runs.parquet (and what collect holds at once, besides a few chunks).
ROW_GROUP = 8192


def collect(out: Path, chunks: list[Chunk], path: Path, cached: int = 8) -> None:
    """Write the chunk files of a campaign as one table sorted by scenario_key, cell, replicate, atomically.

    A streaming merge: each design cell's runs lie in one chunk, in replicate order, so the cells are taken in
    order from their chunks, holding only the few chunks in use (``cached``) and one row group: the memory
    is bounded by the chunk size, not by the study's.
    """
    order = sorted((c.plans[0]["run"]["scenario_key"], cell, c.id, k, c.replicates)
                   for c in chunks for k, cell in enumerate(c.cells))
    tables: OrderedDict[str, pa.Table] = OrderedDict()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    writer, parts, rows = None, [], 0
    try:
        for _, _, chunk_id, k, replicates in order:
            if chunk_id not in tables:
                tables[chunk_id] = pq.read_table(out / "chunks" / f"{chunk_id}.parquet")
                if len(tables) > cached:
                    tables.popitem(last=False)
            tables.move_to_end(chunk_id)
            parts.append(tables[chunk_id].slice(k * replicates, replicates))
            rows += replicates
            if rows >= ROW_GROUP:
                writer = _write_parts(writer, tmp, parts)
                parts, rows = [], 0
        if parts or writer is None:
            writer = _write_parts(writer, tmp, parts)
        writer.close()
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _write_parts(writer, tmp: str, parts: list):
    table = pa.concat_tables(parts) if parts else None
    if writer is None:
        writer = pq.ParquetWriter(tmp, table.schema)
    if table is not None:
        writer.write_table(table, row_group_size=ROW_GROUP)
    return writer
