"""A sound-speed series: ``epo`` (or ``time``) [s since 1970-01-01 UTC], increasing, and ``sound_speed_m_s`` (or
``ss``) [m/s], other columns ignored."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.cells import column, file_table, numbers
from sblsim.orchestrator.readers.limits import MAX_EPOCH, MAX_SERIES, SOUND_SPEED_RANGE


def read_sound_speed(path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Read a sound-speed series: ``epo`` (or ``time``) [s since 1970-01-01 UTC], increasing, and
    ``sound_speed_m_s`` (or ``ss``) [m/s] in :data:`SOUND_SPEED_RANGE`; other columns ignored.

    Returns
    -------
    times, speeds : numpy.ndarray
        (m,) [s] and (m,) [m/s].

    Raises
    ------
    ModelError
        One line naming the file, the line and column and the allowed range.
    """
    path, what = Path(path), "sound speed"
    name = str(path)
    header, body, lines = file_table(path, what, MAX_SERIES)
    t, c = column(header, ("epo", "time", "time_s")), column(header, ("sound_speed_m_s", "ss", "sound_speed"))
    if t is None or c is None:
        raise ModelError(f"{what}: {name!r}: the header needs epo (or time) and sound_speed_m_s (or ss) columns; got "
                         f"{','.join(h[:20] for h in header[:12])}")
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no rows")
    times = numbers(body[t], what, name, lines, header[t], 0.0, float(MAX_EPOCH), unit="s")
    speeds = numbers(body[c], what, name, lines, header[c], *SOUND_SPEED_RANGE, unit="m/s")
    steps = np.diff(times)
    if (steps <= 0).any():
        k = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise ModelError(f"{what}: {name!r} line {lines[k]}: the time {times[k]:.10g} s does not increase; allowed: "
                         "times in increasing order")
    return times, speeds


__all__ = ["read_sound_speed"]
