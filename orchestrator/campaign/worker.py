"""What a worker process does: simulate one chunk and return its rows; exit with the campaign's process."""

from __future__ import annotations

import os
import threading
import time
from functools import cache
from typing import Any

import numpy as np
import pandas as pd

from sblsim.orchestrator.campaign.plan import Chunk
from sblsim.orchestrator.campaign.study import Study
from sblsim.orchestrator.cosim.master import RecordBuffer
from sblsim.orchestrator.cosim.metrics import FLAG_NAMES, RUN_METRICS
from sblsim.orchestrator.cosim.plan import with_replicates
from sblsim.orchestrator.cosim.run import run_batch


@cache
def process_records() -> RecordBuffer:
    """The record memory of this process, re-used by the chunks it runs one after another (each worker
    process has its own; a chunk's result holds no reference to it)."""
    return RecordBuffer()


def run_chunk(chunk: Chunk, study: Study, engine: str = "local", fmu_dir: str | None = None,
              timeseries: bool = False) -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """Simulate one chunk (in a worker) and return its result rows.

    Returns
    -------
    rows : pandas.DataFrame
        One row per run: identity, factor levels (coded and physical) and metrics.
    series : pandas.DataFrame or None
        Per-step time series with ``cell`` and ``replicate`` columns, if asked.
    """
    start = time.perf_counter()
    plans = [plan for base in chunk.plans for plan in with_replicates(base, range(chunk.replicates))]
    result = run_batch(plans, engine, fmu_dir=fmu_dir, timeseries=timeseries, records=process_records())
    cells = np.repeat(chunk.cells, chunk.replicates)
    first = chunk.plans[0]["run"]
    rows: dict[str, Any] = {
        "scenario": first["scenario"], "scenario_key": np.int64(first["scenario_key"]),
        "cell": cells.astype(np.int64), "replicate": result.metrics["replicate"].to_numpy(np.int64),
        "seed": np.int64(study.seed),
    }
    for k, factor in enumerate(study.factors):
        coded = study.matrix[cells, k]
        rows[factor.name] = coded.astype(np.int64)
        rows[f"{factor.name}_value"] = np.where(coded < 0, factor.low, factor.high)
    rows["receiver"] = chunk.plans[0].receiver_label  # a chunk shares its receiver (batch_key)
    rows.update({m: result.metrics[m].to_numpy() for m in RUN_METRICS + FLAG_NAMES})
    series = None
    if timeseries:
        series = result.timeseries
        series.insert(0, "cell", np.repeat(cells, result.steps))
        series.insert(0, "scenario_key", np.int64(first["scenario_key"]))
    frame = pd.DataFrame(rows)
    frame.attrs["seconds"] = time.perf_counter() - start  # the worker's time for the chunk (in the manifest)
    return frame, series


def watch_parent(parent: int, every: float = 0.5) -> None:
    """In a worker process: exit as soon as the campaign's process is gone (killed, even by SIGKILL).

    A daemon thread compares the parent's process id with ``parent`` every
    ``every`` seconds; the pool's own shutdown covers a parent that exits
    normally.
    """
    def watch() -> None:
        while True:
            time.sleep(every)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="sblsim-parent-watch", daemon=True).start()
