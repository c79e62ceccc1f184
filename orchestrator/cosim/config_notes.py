"""The one-line notes of the configurations read (a ``[receiver]`` key the chosen receiver does not have, a site
key no detection reads): collected while :func:`collected_notes` collects them, for the command line to print.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

#: The notes of the configurations read while :func:`collected_notes` collects them (None: not collected, as the
#: API is silent).
_NOTES: ContextVar[dict[str, bool] | None] = ContextVar("sblsim_configuration_notes", default=None)


@contextmanager
def collected_notes() -> Iterator[None]:
    """Collect the one-line notes of the configurations read meanwhile (:func:`switch_receiver`'s), each once, for
    :func:`take_notes` (the command line prints them; without this they are dropped)."""
    token = _NOTES.set({})
    try:
        yield
    finally:
        _NOTES.reset(token)


def _note(line: str) -> None:
    notes = _NOTES.get()
    if notes is not None:
        notes.setdefault(line, False)


def note(line: str) -> None:
    """Add a one-line note for the command line to print (:func:`collected_notes`; dropped where none collects)."""
    _note(line)


def take_notes() -> list[str]:
    """The notes collected (:func:`collected_notes`) and not taken yet, in order."""
    notes = _NOTES.get() or {}
    fresh = [line for line, taken in notes.items() if not taken]
    for line in fresh:
        notes[line] = True
    return fresh
