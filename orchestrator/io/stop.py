"""One way to stop a command: Ctrl-C (SIGINT), SIGTERM or SIGHUP, wherever the command is.

The command line handles the three signals with :func:`stop_on`'s handler: the signal is recorded (the stop is
*pending*) and raised at once as :class:`KeyboardInterrupt`, so that Python code stops at its next instruction.
Where the handler runs inside a compiled library's call, the library may report the exception as its own error
and drop it: casadi's wrapper as ``NotImplementedError: Wrong number or type of arguments for function
'Function_call'`` or a ``TypeError``, CPython as ``SystemError: ... returned a result with an exception set``, a
numpy or scipy solve as whatever it raises next. The stop stays pending all the same: every long loop checks it at
its natural step (:func:`check`, called by :meth:`sblsim.orchestrator.io.progress.Progress.update` each time a
unit of work is done), and an exception that comes out of the work while a stop is pending is the stop, not an
error (:func:`is_stop`). The command then ends with one line and :func:`exit_status`: 128 + the signal (130 for
SIGINT, 143 for SIGTERM, 129 for SIGHUP). A signal handled inside a finaliser (a ``__del__`` the garbage collector
runs), where Python cannot raise the exception and prints it instead, is said nothing of: it stays pending.

A signal a parent process set to be ignored (``nohup``'s SIGHUP, a background job's SIGINT) stays ignored. The
Python API installs no handler: its callers' own handling of signals is theirs. A worker process a command starts
(a pool's, a Dask cluster's) ignores Ctrl-C (:func:`workers_ignore_ctrl_c`): a terminal sends it to the whole
process group, and the command stops its workers itself. Once a stopped command has said its line, the process does
not wait for good on a thread a library left running (:func:`exit_past_threads`), and a further signal ends it at
once with the stop's status (:func:`end_on_further_signals`).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from typing import Iterator

from sblsim.models import interrupts

#: The signals that stop a command, by name (those the platform has).
SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
#: A command's exit status when a signal stopped it is this plus the signal's number (POSIX shells' rule).
SIGNAL_STATUS_BASE = 128
#: The exit status of a stop without a recorded signal (a KeyboardInterrupt raised otherwise): Ctrl-C's.
EXIT_INTERRUPTED = SIGNAL_STATUS_BASE + int(signal.SIGINT)

#: How long a stopped command's process waits for the threads a library left running before it ends without them
#: [s] (:func:`exit_past_threads`).
THREADS_GRACE = 2.0

#: The signals received since :func:`stop_on` began and whether the handler raises (False while a command that is
#: stopping finishes its last lines): kept where the lowest layers see them (:mod:`sblsim.models.interrupts`).
_RECEIVED, _RAISING = interrupts.RECEIVED, interrupts.RAISING


def _handler(signum: int, frame) -> None:
    """The stop's signal handler: recorded, then raised as KeyboardInterrupt (unless the command is ending)."""
    _RECEIVED.append(signum)
    if _RAISING[0]:
        raise KeyboardInterrupt


#: The signal of the pending stop, or None; raise KeyboardInterrupt when one is pending (a long loop's check at its
#: natural step: its exception was lost in a compiled library's call, or the signal came between two of its steps).
pending, check = interrupts.pending, interrupts.check


def is_stop(exc: BaseException) -> bool:
    """Whether ``exc``, having ended a command, is its stop: a stop is pending (whatever ``exc`` is: the error a
    compiled library made of the signal's exception), or ``exc`` is or was caused by a
    :class:`KeyboardInterrupt` (CPython's ``SystemError`` from an extension's call that returned a value with one
    set, a campaign's own account of what it saved)."""
    if _RECEIVED:
        return True
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def exit_status() -> int:
    """The exit status of a stopped command: 128 + the pending stop's signal, else :data:`EXIT_INTERRUPTED`."""
    signum = pending()
    return SIGNAL_STATUS_BASE + signum if signum is not None else EXIT_INTERRUPTED


@contextmanager
def ending() -> Iterator[None]:
    """A command's last lines (its stop said, its locks released): a further signal is recorded, not raised."""
    raising = _RAISING[0]
    _RAISING[0] = False
    try:
        yield
    finally:
        _RAISING[0] = raising


def workers_ignore_ctrl_c() -> None:
    """In a worker process a command started (spawned: it imports the command line's module before its work),
    ignore SIGINT: Ctrl-C at a terminal reaches every process of the group, the command stops its workers (a pool
    terminated, a cluster closed) and a worker that took it itself would print its own traceback. Nothing in the
    command's own process.

    A worker is known by its process's name (``MainProcess`` only in the command): a spawned worker's preparation
    sets it first, before it imports this module, where its ``sys.argv`` is already the command's and its parent
    process not yet set."""
    worker = multiprocessing.current_process().name != "MainProcess"
    if worker and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def exit_past_threads(status: int, grace: float | None = None) -> None:
    """In a command's process that a stop ended (its outputs cleaned, its line said): wait at most ``grace`` seconds
    (default :data:`THREADS_GRACE`) in all for the threads the interpreter's exit would join (every one but daemons
    and this one), then, where one still runs, end the process at once with ``status`` (``os._exit``, the standard
    streams flushed first).

    The interpreter's exit joins such a thread without a bound, and a library's can be stuck for good once its work
    was cut short: CPython's process pool manager thread has deadlocked in its shutdown (python/cpython#105829, its
    wake-up pipe full of submissions; #125451, its shutdown against its feeding thread's error). Returns (the
    interpreter's own exit follows) where none is left."""
    deadline = time.monotonic() + (THREADS_GRACE if grace is None else grace)
    here = threading.current_thread()

    def lingering() -> list[threading.Thread]:
        return [t for t in threading.enumerate() if t is not here and not t.daemon and t.is_alive()]

    for thread in lingering():
        thread.join(max(0.0, deadline - time.monotonic()))
    if lingering():
        _exit_now(status)


def _exit_now(status: int) -> None:
    """End the process at once with ``status`` (``os._exit``), the standard streams flushed first."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe, a closed stream: nothing more to say there
            pass
    os._exit(status)


def end_on_further_signals(status: int) -> None:
    """In a command's process that a stop ended (its outputs cleaned, its line said), before the interpreter's exit:
    a further stop signal (Ctrl-C pressed again while the process ends, a signal sent twice) ends the process at once
    with ``status``, the standard streams flushed first. Python's own handlers, restored by :func:`stop_on`, would
    raise a KeyboardInterrupt through the exit instead: its traceback, and a process ended by SIGINT (130 to a shell)
    where the stop said 143 or 129. The main thread only; a signal the process ignores stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        return
    for name in SIGNALS:
        number = getattr(signal, name, None)
        if number is not None and signal.getsignal(number) is not signal.SIG_IGN:
            signal.signal(number, lambda signum, frame: _exit_now(status))


@contextmanager
def deferred() -> Iterator[None]:
    """The stop's signals held back (blocked, not lost) while the body runs, delivered when it ends: for work that a
    stop must not cut in two (a Dask cluster's start, whose half-started workers would fail its close at exit). The
    processes the body starts inherit them blocked: Ctrl-C at a terminal is their command's to handle. The main
    thread only, where a platform blocks signals (POSIX)."""
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {getattr(signal, name) for name in SIGNALS if hasattr(signal, name)}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


@contextmanager
def stop_on() -> Iterator[None]:
    """Handle :data:`SIGNALS` as stops while the body runs (the main thread only: signals are handled there),
    every signal the process does not ignore; the pending stop cleared on entry and on exit, the earlier handlers
    restored on exit (one not set from Python as the default)."""
    _RECEIVED.clear()
    _RAISING[0] = True
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for name in SIGNALS:
            number = getattr(signal, name, None)
            if number is not None and signal.getsignal(number) is not signal.SIG_IGN:
                previous[number] = signal.signal(number, _handler)
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_stop(hook)
    try:
        yield
    finally:
        sys.unraisablehook = hook
        for number, handler in previous.items():
            signal.signal(number, signal.SIG_DFL if handler is None else handler)
        _RECEIVED.clear()


def _quiet_stop(previous):
    """``sys.unraisablehook`` that says nothing of the stop's own exception where Python could not raise it (the
    handler ran inside a finaliser, a ``__del__`` the garbage collector called: CPython prints ``Exception ignored
    in: ...`` and its traceback, then goes on): the stop stays pending and ends the command at its next check.
    Every other unraisable exception goes to ``previous``."""
    def hook(unraisable) -> None:
        if _RECEIVED and unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            return
        previous(unraisable)
    return hook


__all__ = ["EXIT_INTERRUPTED", "SIGNALS", "SIGNAL_STATUS_BASE", "THREADS_GRACE", "check", "deferred",
           "end_on_further_signals", "ending", "exit_past_threads", "exit_status", "is_stop", "pending", "stop_on",
           "workers_ignore_ctrl_c"]
