"""The tag a telemetry array's design is confirmed with (``[tag]``): its ping type as the tracker names it and its
burst intervals, a ``pbi`` tag's sequence read from its file.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from sblsim.models.errors import ConfigError, ModelError
from sblsim.orchestrator.readers.burst_sequence import read_burst_sequence

#: A random-interval tag's burst interval where ``tag.burst_interval_s`` is empty [s]: the worked case's
#: (``lake-hald-array``), the one the confirmation simulated before the tag was a key.
DEFAULT_BURST_INTERVAL = (20.0, 40.0)


@dataclass(frozen=True)
class Tag:
    """The tag a design is confirmed with (``[tag]``): its ping type as the tracker names it
    (:data:`~sblsim.models.tracking.schedule.PING_TYPES`) and its intervals.

    Attributes
    ----------
    ping_type : str
        ``sbi``, ``rbi`` or ``pbi``.
    burst_interval : tuple of float
        ``rbi``: (min, max) [s]; ``sbi``: (Δ, Δ) [s]; ``pbi``: the sequence's (shortest, longest) [s].
    burst_sequence : numpy.ndarray or None
        ``pbi``: the tag's intervals in order [s] (k,); else None.
    source_level_db : float
        The tag's source level [dB re 1 µPa at 1 m] (0: none given; the detection curve is a range test's).
    """

    ping_type: str = "rbi"
    burst_interval: tuple[float, float] = DEFAULT_BURST_INTERVAL
    burst_sequence: np.ndarray | None = None
    source_level_db: float = 0.0

    def record(self) -> dict[str, Any]:
        """What ``design.json`` records of the tag."""
        out: dict[str, Any] = {"ping_type": self.ping_type, "burst_interval_s": list(self.burst_interval)}
        if self.burst_sequence is not None:
            out["burst_sequence_intervals"] = int(len(self.burst_sequence))
        if self.source_level_db > 0.0:
            out["source_level_db"] = self.source_level_db
        return out


def tag_of(section: Mapping[str, Any]) -> Tag:
    """The tag of a checked ``[tag]`` section (its keys checked together by the problem); a ``pbi`` tag's
    sequence read from its file (:func:`~sblsim.orchestrator.readers.burst_sequence.read_burst_sequence`, the tracker's
    ``--burst-sequence`` reader: bounded, one line naming the file and line where a row is bad).

    Raises
    ------
    ConfigError
        Naming ``tag.burst_sequence`` and the reader's reason.
    """
    kind, interval = section["ping_type"], tuple(float(v) for v in section["burst_interval_s"])
    sequence = None
    if kind == "pbi":
        try:
            sequence = read_burst_sequence(section["burst_sequence"])
        except ModelError as exc:
            raise ConfigError(f"tag.burst_sequence: {exc}") from None
        interval = (float(sequence.min()), float(sequence.max()))
    elif kind == "sbi":
        interval = (interval[0], interval[0])
    else:
        interval = interval or DEFAULT_BURST_INTERVAL
    return Tag(kind, interval, sequence, float(section["source_level_db"]))


__all__ = ["DEFAULT_BURST_INTERVAL", "Tag", "tag_of"]
