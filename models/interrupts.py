"""Whether a stop is pending: the signal that asked a command to stop (Ctrl-C, SIGTERM, SIGHUP), recorded here by
the command line's handler (:mod:`sblsim.orchestrator.io.stop`) so that the lowest layers see it too.

A signal's exception raised inside a compiled library's call may be lost there (casadi's wrapper reports it as a
``NotImplementedError`` or a ``RuntimeError`` of its own): compiled work cut into pieces checks the pending stop
between two of them (:func:`check`), and a fallback never takes a lost stop for a failure to fall back from
(:func:`pending`). Nothing is recorded outside the command line (the Python API installs no handler).
"""

from __future__ import annotations

#: The signals received since the command began, in order (empty: no stop is pending).
RECEIVED: list[int] = []
#: Whether :func:`check` raises (False while a stopping command says its last lines).
RAISING = [True]


def pending() -> int | None:
    """The signal of the pending stop (the first received), or None."""
    return RECEIVED[0] if RECEIVED else None


def check() -> None:
    """Raise :class:`KeyboardInterrupt` when a stop is pending (a piece of long work done: the next one not begun).

    Raises
    ------
    KeyboardInterrupt
        A stop is pending.
    """
    if RECEIVED and RAISING[0]:
        raise KeyboardInterrupt


__all__ = ["RAISING", "RECEIVED", "check", "pending"]
