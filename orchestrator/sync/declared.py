"""What a user declares about a telemetry study, checked against its detections at the first command that sees
both: the receivers' positions against the sync tags' travel times (``sblsim sync``, before its clocks are
fitted: :mod:`sblsim.models.sync.scale`), and against the spread of one tag's arrivals (``sblsim toa``); a stated stable
burst interval against the tag's pings (``sblsim toa``: :func:`sblsim.models.tracking.strays.stable_interval`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.sync.pings import group_pings, largest_travel_time
from sblsim.models.sync.resolution import check_resolution, time_quantum
from sblsim.models.sync.scale import (
    NOMINAL_SOUND_SPEED,
    SPEED_TOLERANCE,
    Scale,
    check_scale,
    distance_scale,
    double_differences,
    looks_like_degrees,
)
from sblsim.models.tracking.strays import stable_interval

#: What a refusal of the receivers' positions allows.
ALLOWED = ("positions in metres (x_m, y_m in a local frame or a projected CRS), or latitude and longitude as lat, "
           "lon columns (or --crs for the table's CRS)")
#: How far a tag's pings' arrivals may spread beyond the table's crossing time at the slowest sound speed, as a
#: factor and a synchronisation's tolerance [s], before the table's positions are refused (``sblsim toa``).
SPREAD_FACTOR = 1.5
#: The longest window a tag's arrivals are grouped again with to see their spread [s] (an array 6 km across).
PROBE_WINDOW = 5.0


def sync_scale(receiver: np.ndarray, tag: np.ndarray, emission: np.ndarray, time: np.ndarray, echo: np.ndarray,
               names: list[str], tag_names: list[str], tag_home: np.ndarray, table: pd.DataFrame,
               sound_speed: float | None, quantum: float = 0.0) -> Scale | None:
    """The factor between the sync tags' clock-free travel times and a receivers table's distances
    (:mod:`sblsim.models.sync.scale`: double differences of the raw arrivals), or None where too few.

    Parameters
    ----------
    receiver, tag, emission : numpy.ndarray of int, (n,)
        The sync tags' arrivals: each one's receiver (an index into ``names``), sync tag (into ``tag_names``) and
        emission.
    time : numpy.ndarray, (n,)
        [s] each arrival on its receiver's own clock.
    echo : numpy.ndarray of bool, (n,)
        A multipath echo (left out).
    names, tag_names : list of str
        The receivers' and the sync tags' names.
    tag_home : numpy.ndarray of int, (tags,)
        Each sync tag's receiver (its home: an index into ``names``).
    table : pandas.DataFrame
        The receivers as the table gives them (never refined): ``receiver``, ``x``, ``y``, ``z`` [m; z NaN: 2-D];
        a receiver or a tag's home not in it left out.
    sound_speed : float or None
        [m/s] the one given (a series' median), else :data:`NOMINAL_SOUND_SPEED`.
    quantum : float
        [s] the times' rounding (:func:`sblsim.models.sync.resolution.time_quantum`; 0: none).
    """
    index = {n: k for k, n in enumerate(table["receiver"].tolist())}
    at = np.array([index.get(n, -1) for n in names], np.int64)  # each receiver's row of the table (-1: none)
    home = at[np.asarray(tag_home, np.int64)]  # (a season's arrivals never copied into a frame: arrays alone)
    use = ~np.asarray(echo, bool) & (home[tag] >= 0) & (at[receiver] >= 0)
    if not use.any():
        return None
    xyz = table[["x", "y", "z"]].to_numpy(float)
    positions = xyz if np.isfinite(xyz[:, 2]).all() else xyz[:, :2]
    row, mine = at[receiver[use]], tag[use]
    present = np.unique(mine)  # the tags numbered in their names' order
    rank = np.zeros(len(tag_names), np.int64)
    rank[sorted(present, key=lambda k: tag_names[k])] = np.arange(len(present))
    distance = np.linalg.norm(positions[home[mine]] - positions[row], axis=1)
    acoustic, predicted, pair = double_differences(row, rank[mine], np.asarray(emission, np.int64)[use],
                                                   np.asarray(time, float)[use], distance,
                                                   sound_speed or NOMINAL_SOUND_SPEED, quantum)
    return distance_scale(acoustic, predicted, pair)


def check_sync_positions(found: Scale | None, table: pd.DataFrame, source: str, sound_speed: float | None
                         ) -> str | None:
    """Refuse a receivers table whose distances need a sound speed the water cannot have, or say it where the
    contradiction is small (:func:`~sblsim.models.sync.scale.check_scale` on :func:`sync_scale`'s ``found``).

    Parameters
    ----------
    found : Scale or None
        :func:`sync_scale`'s.
    table : pandas.DataFrame
        The receivers as the table gives them: ``x``, ``y`` [m].
    source : str
        What the message names: the receivers file (``receivers 'file.csv'``).
    sound_speed : float or None
        [m/s] the one given (a series' median), else None (:data:`NOMINAL_SOUND_SPEED` taken).

    Returns
    -------
    str or None
        A warning line, or None.

    Raises
    ------
    ModelError
        One line naming the file, the factor, the speed it needs, the unit the positions look like and what is
        allowed; a table of degrees where no double difference weighs it.
    """
    return check_scale(found, source, table["x"].to_numpy(float), table["y"].to_numpy(float), ALLOWED,
                       sound_speed or NOMINAL_SOUND_SPEED, sound_speed is not None)


def check_matrix(toa: np.ndarray, positions: np.ndarray, shortest: float, crossing: float, tolerance: float,
                 source: str, ping_type: str | None) -> None:
    """A tag's times-of-arrival matrix against what was declared: the receivers' positions (its arrivals grouped
    again with a window of a quarter of the ``shortest`` interval [s], at most :data:`PROBE_WINDOW`, whatever the
    table says: :func:`check_arrival_spread`) and a stable burst interval stated (``ping_type`` ``sbi``:
    :func:`~sblsim.models.tracking.strays.stable_interval`: its stray rows set aside).

    Parameters
    ----------
    toa : ndarray, (P, R)
        [s] the matrix (NaN where not heard).
    positions : ndarray, (R, dim)
        [m] its receivers as the table gives them.
    shortest : float
        [s] the tag's shortest burst interval.
    crossing, tolerance : float
        [s] the table's largest travel time at the slowest sound speed, and the synchronisation's tolerance.
    source : str
        The receivers file.
    ping_type : str or None
        The ping type stated.

    Raises
    ------
    ModelError
        One line (:func:`check_arrival_spread`, :func:`~sblsim.models.tracking.strays.stable_interval`).
    """
    toa = np.asarray(toa, float)
    ping, receiver = np.nonzero(np.isfinite(toa))
    time = toa[ping, receiver]
    group = group_pings(receiver, time, min(0.25 * shortest, PROBE_WINDOW))
    frame = pd.DataFrame({"group": group, "time": time})
    by = frame.groupby("group")["time"]
    spreads = (by.max() - by.min())[by.size() >= 2].to_numpy()
    check_arrival_spread(spreads, crossing, tolerance, source, positions[:, 0], positions[:, 1])
    if ping_type == "sbi" and len(toa) > 1:
        stable_interval(toa, crossing)


def check_arrival_spread(spreads: np.ndarray, crossing: float, tolerance: float, source: str,
                         x: np.ndarray, y: np.ndarray) -> None:
    """Refuse a receivers table too small for one tag's arrivals: the typical spread of its pings heard by two
    receivers or more (``spreads`` [s], grouped without the table's window) beyond :data:`SPREAD_FACTOR` times the
    table's ``crossing`` time [s] (its largest distance at the slowest sound speed) plus ``tolerance`` [s] (the
    synchronisation's), which no ping can spread over (the triangle inequality).

    Raises
    ------
    ModelError
        One line naming the receivers file ``source``, the typical spread, the crossing time, the unit the
        positions (``x``, ``y``) look like and what is allowed.
    """
    spreads = np.asarray(spreads, float)
    if not len(spreads):
        return
    typical = float(np.median(spreads))
    if typical <= SPREAD_FACTOR * crossing + tolerance:
        return
    ratio = typical / max(crossing, 1e-12)  # a spread is below the array's true crossing: a lower bound of the factor
    # the spread is a lower bound of the factor (a ping is heard across part of the array): a table of degrees may
    # show a few thousand, not the 10⁵ a degree is in metres; its values tell it
    unit = ("degrees (latitude and longitude)" if ratio >= 100 and looks_like_degrees(x, y) else "kilometres"
            if ratio >= 100 else "another array's, or not metres")
    raise ModelError(f"receivers {source!r}: the tag's pings reach the receivers over {typical * 1e3:.4g} ms "
                     f"(median), more than the {crossing * 1e3:.4g} ms sound takes across the table's positions; "
                     f"the positions look like {unit}; allowed: {ALLOWED}")


def checks_before_fit(sync: pd.DataFrame, source: str, hydrophones: pd.DataFrame, receivers_file: str | None,
                      names: list[str], tag_names: list[str], tag_home: np.ndarray, receiver: np.ndarray,
                      tag: np.ndarray, emission: np.ndarray, duplicate: np.ndarray, positions: np.ndarray,
                      sound_speed: float | None, series: tuple[np.ndarray, np.ndarray] | None,
                      alternatives: dict[str, pd.DataFrame]
                      ) -> list[str]:
    """The checks before the clocks are fitted (:func:`~sblsim.orchestrator.sync.run.synchronise`'s docstring) on the
    sync tags' arrivals (``sync``'s rows, each one's receiver, tag, emission and whether a multipath echo; each tag's
    home receiver ``tag_home``), at the sound speed given (a series' median), else the water's nominal: the table's
    distances weighed against the travel times (a table of degrees too small to weigh refused first), the times'
    rounding against the travel time across the array (the table's at the travel times' own scale: a table in another
    unit is never taken for a rounding), then the table's verdict, naming ``receivers_file`` (None: the receivers), and
    where it refuses the table, the first of ``alternatives`` (another reading of the positions) whose distances the
    travel times take named as the cause. Returns the lines said (a table slightly off)."""
    times = sync["time"].to_numpy(float)
    given = sound_speed if sound_speed is not None else None if series is None else float(np.median(series[1]))
    speed = given or NOMINAL_SOUND_SPEED
    arrays = (receiver, tag, emission, times, duplicate, names, tag_names, tag_home)
    found = sync_scale(*arrays, hydrophones, given, time_quantum(times))
    where = "receivers" if receivers_file is None else f"receivers {receivers_file!r}"
    if found is None:
        check_sync_positions(None, hydrophones, where, given)
    factor = found.scale if found is not None and found.scale > 0 else 1.0
    check_resolution(times, largest_travel_time(positions[np.unique(receiver)], speed) * factor, speed,
                     f"detections {source!r}")
    try:
        said = check_sync_positions(found, hydrophones, where, given) if found is not None else None
    except ModelError as refused:
        for cause, table in alternatives.items():
            other = sync_scale(*arrays, table, given, time_quantum(times))
            if other is not None and abs(other.scale - 1.0) <= SPEED_TOLERANCE:
                raise ModelError(f"{where}: the sync tags' travel times fit the positions with {cause} (the "
                                 f"distances by sound {other.scale:.3f} times the table's then), not as given "
                                 f"({found.scale:.3f} times); allowed: each position as the table's columns name it "
                                 "(latitude under lat, longitude under lon)") from None
        raise refused
    return [said] if said else []


__all__ = ["ALLOWED", "NOMINAL_SOUND_SPEED", "PROBE_WINDOW", "SPREAD_FACTOR", "check_arrival_spread", "check_matrix",
           "check_sync_positions", "checks_before_fit", "sync_scale"]
