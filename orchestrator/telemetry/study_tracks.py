"""``tracks.csv``, a study's every tracked tag's rows (:data:`TRACK_COLUMNS`, by tag and time): made whole in memory
(:func:`combined_tracks`, for :func:`sblsim.track`'s table), or a tag at a time from the tags' own ``track.csv``
files (:class:`TrackParts`, for ``sblsim track``: a season's rows are never in memory together).

The two give the same file byte for byte. pandas writes a column by its type (a count ``7`` in a column of whole
numbers, ``7.0`` in one that also holds an empty cell), and the table made whole takes each column's type from every
tag's: a tag's rows are written in the types :func:`pandas.concat` gives the whole table, found from a few rows of
each tag kept as it ended (:func:`type_rows`: for each column a row where it holds a value, so that a column empty
in a tag is empty in its rows too), and its own file read back exactly (pandas 3 parses a number to the float it was
written from; pandas 2 when asked, ``float_precision="round_trip"``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pandas as pd

#: pandas' reading of a number back to the very float it was written from (its default from pandas 3 on).
EXACT = {"float_precision": "round_trip"} if int(pd.__version__.split(".")[0]) < 3 else {}
#: The columns of ``tracks.csv`` (``z`` and ``sigma_z`` after ``y`` and ``sigma_y`` in 3-D).
TRACK_COLUMNS = ("tag", "time_utc", "epoch_s", "lat", "lon", "x", "y", "sigma_x", "sigma_y", "receivers_heard",
                 "quality", "quality_reason")


def _columns(three_d: bool) -> list[str]:
    columns = list(TRACK_COLUMNS)
    if three_d:
        columns[columns.index("y") + 1:columns.index("y") + 1] = ["z"]
        columns[columns.index("sigma_y") + 1:columns.index("sigma_y") + 1] = ["sigma_z"]
    return columns


def tag_rows(track: pd.DataFrame, tag: str) -> pd.DataFrame:
    """One tag's rows of ``tracks.csv``: its track with its ``tag`` first (``lat``, ``lon``, ``epoch_s`` NaN and
    ``time_utc`` empty where the track has none), its own columns of :data:`TRACK_COLUMNS`, by time (stable)."""
    t = track.copy()
    t.insert(0, "tag", tag)
    for key in ("lat", "lon", "epoch_s", "time_utc"):
        if key not in t:
            t[key] = np.nan if key != "time_utc" else ""
    return t[[c for c in _columns("z" in t) if c in t]]


def combined_tracks(outcomes: dict[str, Any], matrices: dict[str, Any]) -> pd.DataFrame:
    """``tracks.csv`` whole: each tracked tag's track rows (:func:`tag_rows`; its folder's ``track.csv``), in
    :data:`TRACK_COLUMNS`' order (``z``, ``sigma_z`` where the geometry is 3-D; ``lat``, ``lon`` NaN without a
    frame), by tag and time."""
    parts = [tag_rows(outcome.track, matrices[folder].summary["tag"]) for folder, outcome in outcomes.items()]
    if not parts:
        return pd.DataFrame(columns=list(TRACK_COLUMNS))
    tracks = pd.concat(parts, ignore_index=True)
    return tracks[_columns("z" in tracks)].sort_values(["tag", "epoch_s"], kind="stable").reset_index(drop=True)


def type_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """A few of a tag's rows of ``tracks.csv`` that give the whole table's column types as its every row does: for
    each column its first row holding a value (or its first row), in their order."""
    if not len(rows):
        return rows
    held = rows.notna().to_numpy()
    first = np.where(held.any(axis=0), held.argmax(axis=0), 0)
    return rows.iloc[np.unique(first)]


class TrackParts:
    """``tracks.csv`` from the tags' own ``track.csv`` files, a tag at a time (the module docstring).

    Parameters
    ----------
    folder : Path
        The study's folder (its tags' folders within).
    """

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.tags: dict[str, str] = {}  # tag -> its folder, relative to the study's
        self.types: list[pd.DataFrame] = []

    def add(self, tag: str, folder: str, track: pd.DataFrame) -> None:
        """A tag's track (its rows then written in its folder's ``track.csv``), kept as its few :func:`type_rows`."""
        self.tags[tag] = folder
        self.types.append(type_rows(tag_rows(track, tag)))

    def _types(self) -> pd.Series:
        whole = pd.concat(self.types, ignore_index=True)
        return whole[_columns("z" in whole)].dtypes

    def parts(self) -> Iterator[tuple[str, pd.DataFrame]]:
        """Each tag's rows of ``tracks.csv`` in its order (by tag, then time), in the whole table's column types."""
        if not self.tags:
            return
        types = self._types()
        for tag in sorted(self.tags):
            track = pd.read_csv(self.folder / self.tags[tag] / "track.csv", **EXACT)
            rows = tag_rows(track, tag).reindex(columns=types.index)
            yield tag, rows.astype(types.to_dict()).sort_values("epoch_s", kind="stable")

    def write(self, path: Path, each: Callable[[str, pd.DataFrame], None] | None = None) -> None:
        """``tracks.csv`` into ``path``, a tag's rows at a time; ``each(tag, rows)`` called with each tag's rows as
        they are written (what else is made of them, from this one reading of the tag's file)."""
        with open(path, "w", newline="") as handle:
            wrote = False
            for tag, rows in self.parts():
                rows.to_csv(handle, index=False, header=not wrote)
                wrote = True
                if each is not None:
                    each(tag, rows)
            if not wrote:
                pd.DataFrame(columns=list(TRACK_COLUMNS)).to_csv(handle, index=False)


def tag_tracks(tracks: pd.DataFrame | None, parts: TrackParts | None) -> Iterator[tuple[str, pd.DataFrame]]:
    """Each tag's rows of ``tracks.csv`` in its order: from the table made whole, or from the tags' files."""
    if parts is not None:
        yield from parts.parts()
    elif tracks is not None:
        yield from tracks.groupby("tag", sort=False)


__all__ = ["TRACK_COLUMNS", "TrackParts", "combined_tracks", "tag_rows", "tag_tracks", "type_rows"]
