"""The receivers' position errors a synchronisation's folder says it took, for a study or a matrix given that folder
as its clocks (``--sync DIR``): the same σ as where the synchronisation is made there.

- **Positions as surveyed** (:func:`folder_survey`): ``sync.json``'s ``survey_sigma_m`` where its
  ``survey_sigma_from`` is ``"seen"`` (:func:`~sblsim.orchestrator.sync.run.synchronise` took the error its residuals
  between receivers showed).
- **Positions refined** (``--refine-positions``; :func:`folder_position_sigmas`): each receiver's own error
  (:func:`position_errors`), written by the synchronisation as ``positions.csv``'s ``position_sigma_m``: its
  posterior σ in the array's shape where refined, the refinement's prior where it kept the table's position.

The files are read as anyone's: their size and lines bounded before they are read, JSON parsed (no code run, no path
it names opened), the numbers taken checked in their ranges; anything else in them is not read.

Units: metres [m].
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.arguments import real_argument
from sblsim.orchestrator.io.paths import inside
from sblsim.orchestrator.readers.cells import read_text
from sblsim.orchestrator.readers.receivers_file import SURVEY_SIGMA_RANGE
from sblsim.orchestrator.sync.clocks import read_position_sigmas

#: The largest ``sync.json`` read [bytes] and its most lines (a season's offsets per receiver and bin: a few MB).
MAX_SYNC_JSON_BYTES = 64 * 2**20
MAX_SYNC_JSON_LINES = 5_000_000


def read_sync_json(folder: Path | str) -> tuple[dict | None, str]:
    """A synchronisation's ``folder``'s ``sync.json`` as a JSON object (None where it has none) and its name as said
    in a refusal, read as anyone's (module docstring): nothing in it is taken unchecked.

    Raises
    ------
    ModelError
        ``sync.json`` larger than :data:`MAX_SYNC_JSON_BYTES`, not JSON, or not an object (one line).
    """
    folder = Path(folder)
    path = inside(folder, "sync.json", f"sync: {str(folder)[:80]!r}", "synchronisation")
    shown = f"sync: {str(path)[:120]!r}"
    if not path.is_file():
        return None, shown
    text = read_text(path, "sync", MAX_SYNC_JSON_BYTES, MAX_SYNC_JSON_LINES)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise ModelError(f"{shown} is not JSON ({str(exc)[:80]}); allowed: the sync.json sblsim sync writes") from None
    if not isinstance(data, dict):
        raise ModelError(f"{shown} holds no JSON object; allowed: the sync.json sblsim sync writes")
    return data, shown


def folder_survey(folder: Path | str, read: tuple[dict | None, str] | None = None) -> float | None:
    """The survey error [m per horizontal axis] a synchronisation's ``folder`` took as seen (module docstring);
    None where it took none (stated, not seen, or no ``sync.json``). ``read``: its ``sync.json`` as
    :func:`read_sync_json` gave it already (else read here).

    Raises
    ------
    ModelError
        ``sync.json`` refused (:func:`read_sync_json`), or its ``survey_sigma_m`` not a number in a stated survey
        error's range (:data:`~sblsim.orchestrator.readers.receivers_file.SURVEY_SIGMA_RANGE`) where it says it took
        one (one line).
    """
    data, shown = read_sync_json(folder) if read is None else read
    if data is None or data.get("survey_sigma_from") != "seen":
        return None
    return real_argument(data.get("survey_sigma_m"), f"{shown} survey_sigma_m", *SURVEY_SIGMA_RANGE, "m")


def position_errors(names: Sequence[str], ratios: Sequence[float], refined: Sequence[bool],
                    prior: float) -> dict[str, float]:
    """Each receiver's position error on refined positions [m per horizontal axis], by its name: where ``refined``
    its posterior σ in the array's shape (``ratios`` × ``prior``: the array's translation and rotation, which no time
    of arrival tells, move a still tag and its receiver together); elsewhere the survey's ``prior`` (its position the
    survey's)."""
    sigma = np.where(np.asarray(refined, bool), np.asarray(ratios, float), 1.0) * float(prior)
    return {str(n): float(v) for n, v in zip(names, sigma, strict=True)}


def folder_position_sigmas(folder: Path | str, names: Sequence[str]) -> dict[str, float] | None:
    """Each receiver's position error [m per horizontal axis] in a synchronisation's ``folder`` whose positions were
    refined (its ``positions.csv``'s ``position_sigma_m``: :func:`position_errors` as the synchronisation made them),
    by its serial, for each of ``names`` (one the folder does not list: the largest listed, the survey's where any
    position was left as surveyed); None where they were not refined (no ``positions.csv``, or one written before
    that column).

    Raises
    ------
    ModelError
        A cell of ``positions.csv`` refused (one line).
    """
    sigmas = read_position_sigmas(Path(folder))
    if sigmas is None:
        return None
    return {str(n): sigmas.get(str(n), max(sigmas.values())) for n in names}


__all__ = ["MAX_SYNC_JSON_BYTES", "MAX_SYNC_JSON_LINES", "folder_position_sigmas", "folder_survey", "read_sync_json",
           "position_errors"]
