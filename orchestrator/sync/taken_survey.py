"""The survey error a synchronisation's folder says it took (``sync.json``'s ``survey_sigma_m`` where its
``survey_sigma_from`` is ``"seen"``: :func:`~sblsim.orchestrator.sync.run.synchronise` took the error its residuals
between receivers showed), for a study given that folder as its clocks (``--sync DIR``): the same σ as the study
that synchronises its own clocks.

The file is read as anyone's: its size and lines bounded before it is read, JSON parsed (no code run, no path it
names opened), the one number taken checked in its range; anything else in it is not read.

Units: metres [m].
"""

from __future__ import annotations

import json
from pathlib import Path

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.arguments import real_argument
from sblsim.orchestrator.io.paths import inside
from sblsim.orchestrator.readers.cells import read_text
from sblsim.orchestrator.readers.receivers_file import SURVEY_SIGMA_RANGE

#: The largest ``sync.json`` read [bytes] and its most lines (a season's offsets per receiver and bin: a few MB).
MAX_SYNC_JSON_BYTES = 64 * 2**20
MAX_SYNC_JSON_LINES = 5_000_000


def folder_survey(folder: Path | str) -> float | None:
    """The survey error [m per horizontal axis] a synchronisation's ``folder`` took as seen (module docstring);
    None where it took none (stated, not seen, or no ``sync.json``).

    Raises
    ------
    ModelError
        ``sync.json`` larger than :data:`MAX_SYNC_JSON_BYTES`, not JSON, not an object, or its ``survey_sigma_m``
        not a number in a stated survey error's range
        (:data:`~sblsim.orchestrator.readers.receivers_file.SURVEY_SIGMA_RANGE`) where it says it took one (one line).
    """
    folder = Path(folder)
    path = inside(folder, "sync.json", f"sync: {str(folder)[:80]!r}", "synchronisation")
    if not path.is_file():
        return None
    shown = f"sync: {str(path)[:120]!r}"
    text = read_text(path, "sync", MAX_SYNC_JSON_BYTES, MAX_SYNC_JSON_LINES)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise ModelError(f"{shown} is not JSON ({str(exc)[:80]}); allowed: the sync.json sblsim sync writes") from None
    if not isinstance(data, dict):
        raise ModelError(f"{shown} holds no JSON object; allowed: the sync.json sblsim sync writes")
    if data.get("survey_sigma_from") != "seen":
        return None
    return real_argument(data.get("survey_sigma_m"), f"{shown} survey_sigma_m", *SURVEY_SIGMA_RANGE, "m")


__all__ = ["MAX_SYNC_JSON_BYTES", "MAX_SYNC_JSON_LINES", "folder_survey"]
