"""The bounds every reader of a study's files holds to (sizes, rows, cells, times, coordinates) and the pattern of an
identifier, in one place: a hostile file is refused by its shape before pandas builds a cell."""

from __future__ import annotations

import re

from sblsim.orchestrator.io.times import MAX_EPOCH

#: The largest file read [bytes] and the most rows (detections; receivers; points of a sound-speed series).
MAX_DETECTION_BYTES = 256 * 2**20
MAX_DETECTIONS = 3_000_000
MAX_HYDROPHONES = 1000
MAX_SERIES = 1_000_000
#: The most cells a detections file holds [1]: 3 million detections of 11 cells (a VUE export has 10 columns, a
#: Fathom DET record about 20, a GLATOS or OTN extract about 30 in rows a few hundred bytes long); a table of as many
#: cells of one character each is parsed in about 0.9 GiB.
MAX_DETECTION_CELLS = 2**25
#: The allowed coordinates [m] and sound speeds [m/s] (the latest time:
#: :data:`~sblsim.orchestrator.io.times.MAX_EPOCH`).
MAX_COORDINATE = 1e7
SOUND_SPEED_RANGE = (1300.0, 1700.0)
#: A receiver's serial or a tag's id: letters, digits, ``. _ -``, 1 to 40 characters, a letter or digit first.
IDENTIFIER = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,39}")

__all__ = ["IDENTIFIER", "MAX_COORDINATE", "MAX_DETECTIONS", "MAX_DETECTION_BYTES", "MAX_DETECTION_CELLS",
           "MAX_EPOCH", "MAX_HYDROPHONES", "MAX_SERIES", "SOUND_SPEED_RANGE"]
