"""Executing chunks: in this process, in a pool of worker processes, or on a Dask distributed cluster."""

from __future__ import annotations

import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Iterator

import pandas as pd

from sblsim.orchestrator.campaign.errors import CampaignError
from sblsim.orchestrator.campaign.plan import Chunk
from sblsim.orchestrator.campaign.worker import run_chunk, watch_parent
from sblsim.orchestrator.study import Study

#: ``--scheduler`` value that starts a Dask ``LocalCluster`` on this machine.
LOCAL_CLUSTER = "local"


def connect(scheduler: str, timeout: float = 10.0, workers: int | None = None):
    """A Dask distributed client of a scheduler address, or of a new ``LocalCluster`` (:data:`LOCAL_CLUSTER`:
    ``workers`` processes of one thread each, closed with the client).

    Raises
    ------
    CampaignError
        If no scheduler answers at the address.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - dask[distributed] is a dependency
        raise CampaignError("--scheduler: dask.distributed is not installed") from None
    if scheduler == LOCAL_CLUSTER:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster, set_as_default=False)
        client.cluster_owned = cluster  # closed with the client (close_client)
        return client
    try:
        return Client(scheduler, timeout=f"{timeout}s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CampaignError(f"--scheduler: no Dask scheduler reachable at {scheduler!r} ({reason})") from None


def close_client(client) -> None:
    """Close a Dask client, and the LocalCluster it started."""
    client.close()
    cluster = getattr(client, "cluster_owned", None)
    if cluster is not None:
        cluster.close()


def execute(chunks: list[Chunk], study: Study, engine: str, fmu_dir, timeseries: bool, workers: int | None,
            client) -> Iterator[tuple[Chunk, tuple[pd.DataFrame, pd.DataFrame | None]]]:
    """Yield each chunk with its result as soon as it is finished."""
    if client is not None:
        from distributed import as_completed

        futures = {client.submit(run_chunk, c, study, engine, fmu_dir, timeseries, pure=False,
                                 key=f"sblsim-{study.name}-{c.id}-{os.getpid()}-{time.time_ns()}"): c
                   for c in chunks}
        try:
            for future in as_completed(futures, loop=client.loop):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()
        return
    workers = workers or os.cpu_count() or 1
    if workers == 1 or len(chunks) == 1:
        for c in chunks:
            yield c, run_chunk(c, study, engine, fmu_dir, timeseries)
        return
    import multiprocessing

    pool = ProcessPoolExecutor(max_workers=min(workers, len(chunks)),
                               mp_context=multiprocessing.get_context("spawn"), initializer=watch_parent,
                               initargs=(os.getpid(),))
    try:
        pending = {pool.submit(run_chunk, c, study, engine, fmu_dir, timeseries): c for c in chunks}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                yield pending.pop(future), future.result()
    finally:
        pool.shutdown(wait=False, cancel_futures=True)
