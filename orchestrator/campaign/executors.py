"""Executing chunks: in this process, in a pool of worker processes, or on a Dask distributed cluster."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import re
import signal
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Iterator

import pandas as pd

from sblsim.orchestrator.campaign.errors import CampaignError
from sblsim.orchestrator.campaign.plan import Chunk
from sblsim.orchestrator.campaign.study import Study
from sblsim.orchestrator.campaign.worker import run_chunk, watch_parent
from sblsim.orchestrator.io import stop

#: ``--scheduler`` value that starts a Dask ``LocalCluster`` on this machine.
LOCAL_CLUSTER = "local"


#: How long :func:`connect` waits for a scheduler to answer [s].
CONNECT_TIMEOUT = 5.0
#: The form of a scheduler address: ``tcp://``, a host name, IPv4 address or [IPv6] address, a port.
ADDRESS = re.compile(r"(tcp)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9]([A-Za-z0-9.-]{0,252}[A-Za-z0-9])?):([0-9]{1,5})")


def check_address(scheduler: str) -> str:
    """A ``--scheduler`` value of the allowed form: :data:`LOCAL_CLUSTER`, or ``tcp://HOST:PORT`` with a port in
    [1, 65535].

    Raises
    ------
    CampaignError
        Naming ``--scheduler``, the value and the allowed forms.
    """
    if scheduler == LOCAL_CLUSTER:
        return scheduler
    match = ADDRESS.fullmatch(scheduler)
    if match is None or not 1 <= int(match.group(4)) <= 65535:
        raise CampaignError(f"--scheduler: {scheduler!r} is not a scheduler address; give tcp://HOST:PORT "
                            f"(port 1 to 65535, e.g. tcp://127.0.0.1:8786) or {LOCAL_CLUSTER!r}")
    return scheduler


async def _identity(address: str, timeout: float) -> dict:
    """What answers at a scheduler address: one ``identity`` request over a comm of its own, closed after."""
    from distributed.comm import connect as open_comm

    comm = await open_comm(address, timeout=f"{timeout}s")
    try:
        await asyncio.wait_for(comm.write({"op": "identity", "reply": True}), timeout)
        return await asyncio.wait_for(comm.read(), timeout)
    finally:
        comm.abort()


def probe(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Check that a Dask scheduler answers at ``address`` within ``timeout`` [s], before a client is made (a
    client that fails half-way blocks the exit and logs dozens of lines).

    Raises
    ------
    CampaignError
        Naming ``--scheduler``, the address and what happened instead.
    """
    try:
        with _quiet_dask():
            answer = asyncio.run(asyncio.wait_for(_identity(address, timeout), 2 * timeout))
    except Exception as exc:  # refused, timed out, or something else answered (garbage frames: any error)
        reason = str(exc).splitlines()[0] if str(exc) else ""
        raise CampaignError(f"--scheduler: no Dask scheduler answered at {address!r} within {timeout:g} s "
                            f"({type(exc).__name__}{': ' + reason[:200] if reason else ''})") from None
    if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
        shown = repr(answer)[:100]
        raise CampaignError(f"--scheduler: what answered at {address!r} is not a Dask scheduler (it said {shown})")


@contextlib.contextmanager
def _quiet_dask():
    """Silence distributed's log lines (a failed handshake logs dozens) while connecting."""
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def connect(scheduler: str, timeout: float = CONNECT_TIMEOUT, workers: int | None = None):
    """A Dask distributed client of a scheduler address, or of a new ``LocalCluster`` (:data:`LOCAL_CLUSTER`:
    ``workers`` processes of one thread each, closed with the client).

    The address is checked first (:func:`check_address`), then a scheduler must answer within ``timeout``
    [s]; anything else that answers (or fails in any way while connecting) is one error.

    Raises
    ------
    CampaignError
        If the address is malformed, or no Dask scheduler answers at it.
    """
    check_address(scheduler)
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - dask[distributed] is a dependency
        raise CampaignError("--scheduler: dask.distributed is not installed") from None
    if scheduler == LOCAL_CLUSTER:
        cluster = None
        try:
            with stop.deferred():  # a stop waits for the cluster to be up (a half-started one fails its close at exit)
                cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=logging.ERROR)  # a stop's tasks unsaid
            client = Client(cluster, set_as_default=False)
        except BaseException:
            if cluster is not None:
                cluster.close()
            raise
        client.cluster_owned = cluster  # closed with the client (close_client)
        return client
    probe(scheduler, timeout)
    try:
        with _quiet_dask():
            return Client(scheduler, timeout=f"{timeout}s", set_as_default=False)
    except Exception as exc:  # refused, timed out, or something else answered (garbage frames: any error)
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CampaignError(f"--scheduler: no Dask scheduler answered at {scheduler!r} within {timeout:g} s "
                            f"({type(exc).__name__}: {reason[:200]})") from None


def close_client(client) -> None:
    """Close a Dask client, and the LocalCluster it started (stopped by a signal: its worker processes killed first,
    their chunks dropped for ``--resume`` to recompute, instead of Dask's nanny waiting 4 s for a chunk's compiled
    code before it kills them)."""
    cluster = getattr(client, "cluster_owned", None)
    if stop.pending() is not None:  # the command ends on a signal: the comms its closing breaks are not said (a
        # scheduler logs each, with a traceback, once the cluster's own silence has ended), nor anything after
        for name in ("distributed", "tornado", "asyncio"):
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    if cluster is not None and stop.pending() is not None:
        for nanny in list(getattr(cluster, "workers", {}).values()):
            pid = getattr(nanny, "pid", None)
            if pid:
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
    client.close()
    if cluster is not None:
        cluster.close()


def start_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of ``workers`` worker processes, started now: each imports the worker module while the campaign's
    process goes on planning (rather than after it, when the chunks are submitted).

    A spawn pool starts a process for a submission that finds none idle: one trivial task per worker starts
    them all. :func:`execute` runs the chunks in it and shuts it down; :func:`stop_pool` stops it unused.
    """
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=watch_parent, initargs=(os.getpid(),))
    for _ in range(workers):
        pool.submit(os.getpid)
    return pool


def execute(chunks: list[Chunk], study: Study, engine: str, fmu_dir, timeseries: bool, workers: int | None,
            client, pool: ProcessPoolExecutor | None = None
            ) -> Iterator[tuple[Chunk, tuple[pd.DataFrame, pd.DataFrame | None]]]:
    """Yield each chunk with its result as soon as it is finished (in ``pool``, a pool of :func:`start_pool`,
    when the chunks run in worker processes and one is given)."""
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
    if pool is None:
        pool = ProcessPoolExecutor(max_workers=min(workers, len(chunks)),
                                   mp_context=multiprocessing.get_context("spawn"), initializer=watch_parent,
                                   initargs=(os.getpid(),))
    pending: dict = {}
    ended = False
    try:
        pending = {pool.submit(run_chunk, c, study, engine, fmu_dir, timeseries): c for c in chunks}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                yield pending.pop(future), future.result()
        ended = True
    finally:
        if not ended:  # interrupted (while submitting too) or failed: stop the chunks under way (results dropped)
            stop_pool(pool)
        else:  # every chunk ended: the idle workers and the management thread joined (none left to race the exit)
            pool.shutdown(cancel_futures=True)


def stop_pool(pool: ProcessPoolExecutor) -> None:
    """Stop a process pool at once: cancel the chunks not started and terminate the worker processes, so an
    interrupted campaign exits promptly (a running chunk, in compiled code, would otherwise finish first and
    the exit would wait for it). The finished chunks are already saved; the stopped ones are recomputed by
    ``--resume``."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)  # shutdown() forgets it, joined or not
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=5.0)
    # the pool's management thread too, now that its processes are gone: left running, it closes its wake-up pipe
    # while the interpreter's exit hook writes to it ("Exception ignored in: <module 'threading'> ... _python_exit")
    if manager is not None and manager.is_alive():
        manager.join(timeout=5.0)
