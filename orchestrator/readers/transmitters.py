"""Transmitters by their full ID: a code space and an id (``A69-1602-4555``: the code space ``A69-1602``, the id
``4555``), as Innovasea's receivers, VUE, Fathom, GLATOS and OTN name them; one id in two code spaces is two tags.

A detection's tag is its full ID where its file gives the code space (:func:`full_ids`), else its id alone (the YAPS
tables). A tag named by a user (``--tag``, a tag sheet's ``transmitter``, a deployment's sync tag) is found among
the detected tags by :func:`match`: the same text (its letters' case aside), else the same id where one of the two
names has no code space (``4555`` finds ``A69-1602-4555`` and the other way round), never the same id in another
code space; a bare id that two code spaces share is refused, both named.
"""

from __future__ import annotations

import re
from typing import Iterable

import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.cells import per_value

#: A full transmitter ID: a code space of one to three parts (``A69-1602``, ``R64K``, ``A180-1702``) and an id.
FULL_ID = re.compile(r"(?:[A-Za-z0-9._]{1,20}-){1,3}[A-Za-z0-9._]{1,40}")
#: A transmitter as a user or a file may name it: a full ID, or an id alone.
TRANSMITTER = re.compile(r"(?:[A-Za-z0-9._]{1,20}-){0,3}[A-Za-z0-9._]{1,40}")
#: A code space alone (``A69-1602``).
CODE_SPACE = re.compile(r"[A-Za-z0-9._]{1,20}(?:-[A-Za-z0-9._]{1,20}){0,2}")
#: A transmitter's id alone.
TAG_ID = re.compile(r"[A-Za-z0-9._]{1,40}")


def split(name: str) -> tuple[str, str]:
    """A transmitter's code space (``""`` for none) and id: ``A69-1602-4555`` -> (``A69-1602``, ``4555``)."""
    space, _, ident = name.rpartition("-")
    return space, ident


def before_last_dash(cells: pd.Series) -> pd.Series:
    """Each cell's text before its last ``-`` (``""`` for none): a transmitter's code space (:func:`split`'s first
    part), a ``MODEL-SERIAL`` receiver's model; one regular expression over the column's distinct cells (pyarrow's,
    not a Python call a cell: :func:`~.cells.per_value`), in the column's order and index."""
    return per_value(cells, lambda v: v.str.replace(r"-?[^-]*$", "", regex=True))


def after_last_dash(cells: pd.Series) -> pd.Series:
    """Each cell's text after its last ``-`` (the whole cell for none): a ``MODEL-SERIAL`` receiver's serial."""
    return per_value(cells, lambda v: v.str.replace(r"^.*-", "", regex=True))


def full_ids(space: pd.Series, ident: pd.Series) -> pd.Series:
    """Each detection's tag: ``SPACE-ID`` where the code space is given, else the id."""
    space, ident = space.astype(str).str.strip(), ident.astype(str).str.strip()
    return ident.where(space == "", space + "-" + ident)


def match(given: str, tags: Iterable[str]) -> str | None:
    """The detected tag (one of ``tags``) a user's name stands for (module docstring), None where none.

    Raises
    ------
    ModelError
        A bare id in two code spaces (both named: give the full ID).
    """
    tags = set(tags)
    if given in tags:
        return given
    alike = [t for t in tags if t.casefold() == given.casefold()]  # a69-1602-4555: a code space's letters typed small
    if len(alike) == 1:
        return alike[0]
    space, ident = split(given)
    found = sorted(t for t in tags if split(t)[1] == ident and (not space or not split(t)[0]))
    if len(found) > 1:
        raise ModelError(f"tag: {given!r} is the id of {len(found)} transmitters in different code spaces "
                         f"({', '.join(found[:4])}); allowed: the full ID (code space and id)")
    return found[0] if found else None


__all__ = ["CODE_SPACE", "FULL_ID", "TAG_ID", "TRANSMITTER", "after_last_dash", "before_last_dash", "full_ids", "match",
           "split"]
