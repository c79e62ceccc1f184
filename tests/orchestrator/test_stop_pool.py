"""A stopped process pool (:func:`~sblsim.orchestrator.campaign.executors.stop_pool`, used by an interrupted
campaign, design and track) leaves nothing running that the interpreter's exit would race."""
from __future__ import annotations

import concurrent.futures.process as cf_process
import multiprocessing
import threading
import time
from concurrent.futures import ProcessPoolExecutor

from sblsim.orchestrator.campaign.executors import stop_pool


def test_stop_pool_ends_the_workers_and_joins_the_management_thread():
    """Two workers busy for a minute: stopped within seconds, each worker ended, and the pool's management thread
    ended with its wake-up pipe closed (the exit hook's write to it is then a no-op, not a write racing its close,
    the "Exception ignored ... _python_exit" once seen after Ctrl-C)."""
    pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn"))
    futures = [pool.submit(time.sleep, 60.0) for _ in range(3)]
    deadline = time.monotonic() + 60
    while sum(f.running() for f in futures) < 2:
        assert time.monotonic() < deadline, "the workers never started"
        time.sleep(0.01)
    processes = list(pool._processes.values())
    manager = pool._executor_manager_thread
    wakeup = pool._executor_manager_thread_wakeup
    started = time.monotonic()
    stop_pool(pool)
    assert time.monotonic() - started < 15.0
    assert not any(p.is_alive() for p in processes)
    assert not manager.is_alive()
    assert wakeup._closed
    assert all(w._closed for t, w in list(cf_process._threads_wakeups.items()) if t is manager)
    assert manager not in threading.enumerate()
    assert all(f.done() for f in futures)
