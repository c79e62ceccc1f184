"""A study's folder read back for its report (``sblsim report DIR``, and every ``sblsim track``): the files
``sblsim track`` wrote (:mod:`sblsim.orchestrator.telemetry.outputs`), read as hostile input, since a folder may come
from anyone.

Each file is taken from the folder only (a link leading out of it refused:
:func:`~sblsim.orchestrator.io.paths.inside`), read to a bounded size
(:func:`~sblsim.orchestrator.readers.cells.read_text`), its CSV parsed by pandas into text cells
(:func:`~sblsim.orchestrator.readers.cells.text_table`) and each number column checked cell by cell
(:func:`~sblsim.orchestrator.readers.cells.numbers`: a number or empty); a JSON file must hold an object.
``tracks.csv``, a season's every ping, is read a piece at a time (:func:`read_tracks`: the lines of each piece
checked before they are parsed, :func:`~sblsim.orchestrator.io.log_tables.line_chunks`), and of it only the columns
a report draws are kept, as numbers and categories: no limit of its size but :data:`MAX_TRACK_ROWS`. A tag's own
folder is found from its id as ``sblsim track`` names it (``tags/<id>/``), never from a path a file gives. The text
cells are shown in the page as text (the template escapes them). A file missing that a study always has is refused
in one line; the others (the synchronisation's, the reference tags', the daily detections, a tag's summary) are
read where they are.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pandas.api.types import union_categoricals

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.log_tables import line_chunks
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.io.paths import inside
from sblsim.orchestrator.readers.cells import numbers, read_text, text_table
from sblsim.orchestrator.telemetry.report.daily import DAILY_FILE
from sblsim.orchestrator.telemetry.study import TAGS_FOLDER

#: The largest table, JSON file and image read [bytes], and the most rows of a table.
MAX_TABLE_BYTES = 256 * 2**20
MAX_JSON_BYTES = 64 * 2**20
MAX_IMAGE_BYTES = 16 * 2**20
MAX_ROWS = 2_000_000
#: The most rows of ``tracks.csv`` (and of a tag's ``pings.csv``) a report reads (a row kept in about 60 bytes:
#: 10**7 rows, a season of a hundred tags, 0.6 GB; its text cells would take some 1.5 kB), and the columns of
#: ``tracks.csv`` kept (the rest of the file is not held).
MAX_TRACK_ROWS = 50_000_000
TRACK_TEXT = ("tag", "quality", "quality_reason")
TRACK_NUMBERS = ("epoch_s", "x", "y", "z", "sigma_x", "sigma_y", "receivers_heard")
#: The columns of a tag's ``pings.csv`` a report draws (its depth sensor's readings).
PING_NUMBERS = ("ping", "time", "depth_m")
#: The numbers a study's tables hold are within this of 0 (times in seconds since 1970, metres in a projected frame).
BOUND = 1e13
#: Each table's file, the columns it must have and its number columns (the others are text).
TABLES: dict[str, tuple[str, tuple[str, ...], tuple[str, ...]]] = {
    "tags": ("tags.csv", ("tag", "transmitter", "status", "reason_code", "reason"),
             ("detections", "receivers", "pings", "pings_at_once", "positioned", "set_aside", "not_positioned",
              "flagged", "share_flagged", "median_sigma_m", "sound_speed_m_s", "time_resolution_s", "wall_time_s")),
    "receivers": ("receivers.csv", ("receiver",),
                  ("x_m", "y_m", "z_m", "lat", "lon", "bottom_depth_m", "detections")),
    "tracks": ("tracks.csv", ("tag", "epoch_s", "x", "y", "sigma_x", "sigma_y", "quality"),
               ("epoch_s", "lat", "lon", "x", "y", "z", "sigma_x", "sigma_y", "sigma_z", "receivers_heard")),
    "daily": (DAILY_FILE, ("receiver", "day", "detections"), ("detections",)),
    "offsets": ("sync/offsets.csv", ("receiver", "start", "end", "offset_start_s", "offset_end_s"),
                ("bin", "start", "end", "offset_start_s", "offset_start_sigma_s", "offset_end_s",
                 "offset_end_sigma_s", "drift", "arrivals", "toa_sigma_s", "clock_sigma_s", "segment", "clock_from",
                 "clock_to", "clock_part")),
    "sync_tags": ("sync/sync_tags.csv", ("tag", "receiver"),
                  ("x_m", "y_m", "emissions", "fixes", "receivers_used", "median_error_m", "median_sigma_m",
                   "rms_error_m", "p90_error_m", "nees_mean", "nees_median", "median_position_error_m")),
    "pings": ("pings.csv", ("ping",), ("ping", "time", "receivers", "depth_m")),
}
#: The tables a study's folder always has.
REQUIRED = ("tags", "receivers", "tracks")
#: The reference tags' table (its columns as written: every one read, a column of numbers or empty cells as numbers).
REFERENCE_FILE = "reference_tags.csv"
REFERENCE_TEXT = ("tag", "kind", "truth", "receiver", "verdict")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@dataclass
class StudyFolder:
    """A study's folder as read (the module docstring).

    Attributes
    ----------
    name : str
        The folder as the caller names it (in the page's title and in refusals).
    summary : dict
        ``study.json``.
    tags, receivers : pandas.DataFrame
        ``tags.csv``, ``receivers.csv`` (number columns as floats, NaN where empty).
    tracks : pandas.DataFrame
        ``tracks.csv``'s columns a report draws (:func:`read_tracks`).
    daily : pandas.DataFrame or None
        ``detections_daily.csv`` (:mod:`.daily`), None where the folder has none.
    offsets, sync_tags : pandas.DataFrame or None
        ``sync/offsets.csv`` and ``sync/sync_tags.csv``, where the study synchronised its clocks.
    reference : pandas.DataFrame or None
        ``reference_tags.csv``, where the study scored reference tags.
    map_png : bytes or None
        ``map.png``.
    tag_summaries, tag_pings : dict
        Each tracked tag's ``summary.json`` and ``pings.csv`` (by its id), where its folder has them.
    """

    name: str
    summary: dict[str, Any]
    tags: pd.DataFrame
    receivers: pd.DataFrame
    tracks: pd.DataFrame
    daily: pd.DataFrame | None = None
    offsets: pd.DataFrame | None = None
    sync_tags: pd.DataFrame | None = None
    reference: pd.DataFrame | None = None
    map_png: bytes | None = None
    tag_summaries: dict[str, dict[str, Any]] = field(default_factory=dict)
    tag_pings: dict[str, pd.DataFrame] = field(default_factory=dict)


def _path(folder: Path, name: str, label: str) -> Path:
    """A file of the folder (links followed), refused where it leaves it."""
    return inside(folder, name, f"report: {label}", "study")


def _shown(label: str, name: str) -> str:
    return f"{label}/{name}"


def read_table(folder: Path, label: str, key: str, within: str = "") -> pd.DataFrame | None:
    """One of :data:`TABLES` (``within``: a sub-folder, a tag's), None where the file is not there.

    Raises
    ------
    ModelError
        One line: the file larger than :data:`MAX_TABLE_BYTES` or :data:`MAX_ROWS` rows, not CSV text, without a
        column it must have, or a number cell that is not a number.
    """
    path, shown = _located(folder, label, key, within)
    return None if path is None else _table(path, shown, *TABLES[key][1:])


def _located(folder: Path, label: str, key: str, within: str) -> tuple[Path | None, str]:
    """One of :data:`TABLES`' file in the folder (``within``: a sub-folder; None where it is not there) and its name
    as refusals show it."""
    name = f"{within}/{TABLES[key][0]}" if within else TABLES[key][0]
    path = _path(folder, name, label)
    return (path if path.is_file() else None), _shown(label, name)


def _check_columns(header: list[str], needed: tuple[str, ...], shown: str, what: str) -> None:
    """Refuse a table without one of the ``needed`` columns, in one line naming them."""
    missing = [c for c in needed if c not in header]
    if missing:
        raise ModelError(f"{what}: {shown!r} has no column {', '.join(missing)}; allowed: the table as sblsim track "
                         "writes it")


def _table(path: Path, shown: str, needed: tuple[str, ...], numeric: tuple[str, ...] | None,
           text: tuple[str, ...] = ()) -> pd.DataFrame:
    """A CSV of the folder: text cells, ``numeric``'s columns as numbers (None: each column of numbers and empty
    cells only, but those of ``text``)."""
    what = "report"
    header, body, lines = text_table(read_text(path, what, MAX_TABLE_BYTES, MAX_ROWS), shown, what, MAX_ROWS)
    _check_columns(header, needed, shown, what)
    out = {}
    for k, name in enumerate(header):
        cells = body[k] if k in body else pd.Series([""] * len(body), dtype=str)
        if numeric is None and name not in text:
            trimmed = cells.str.strip()
            parsed = pd.to_numeric(trimmed.where(trimmed != "", "nan"), errors="coerce")
            use = len(cells) > 0 and bool((parsed.notna() | (trimmed == "")).all()) and bool(parsed.notna().any())
            out[name] = parsed.to_numpy(float) if use else cells.to_numpy(dtype=object)
        elif numeric is not None and name in numeric:
            out[name] = numbers(cells, what, shown, lines, name, -BOUND, BOUND, missing=True)
        else:
            out[name] = cells.to_numpy(dtype=object)
    return pd.DataFrame(out, index=pd.RangeIndex(len(body)))


def read_tracks(folder: Path, label: str) -> pd.DataFrame | None:
    """``tracks.csv`` in pieces (:func:`read_pieces`): :data:`TRACK_NUMBERS` and :data:`TRACK_TEXT`."""
    return read_pieces(folder, label, "tracks", TRACK_NUMBERS, TRACK_TEXT)


def read_pieces(folder: Path, label: str, key: str, kept: tuple[str, ...], text: tuple[str, ...] = (),
                within: str = "") -> pd.DataFrame | None:
    """One of :data:`TABLES` of any length (``tracks.csv``, a tag's ``pings.csv``: a season's every ping) in pieces
    (:func:`~sblsim.orchestrator.io.log_tables.line_chunks`), each parsed as :func:`read_table` parses a table and
    let go: of its columns, ``kept`` as floats (NaN where empty) and ``text`` as categories, where the file has them;
    None where the file is not there.

    Raises
    ------
    ModelError
        One line: more than :data:`MAX_TRACK_ROWS` rows, a line too long or too wide, not UTF-8 CSV text, without a
        column it must have, or a number cell that is not a number.
    """
    path, shown = _located(folder, label, key, within)
    if path is None:
        return None
    needed, what = TABLES[key][1], "report"
    head, rows, parts = None, 0, []
    for lines in line_chunks(path, what):
        while head is None and lines:  # its first line that is not blank, checked before any row is parsed
            head, lines = (lines[0][1] if lines[0][1].strip() else None), lines[1:]
            if head is not None:
                _check_columns(text_table(head, shown, what, 0)[0], needed, shown, what)
        if not lines:
            continue
        header, body, where = text_table("\n".join([head, *(line for _, line in lines)]), shown, what, MAX_TRACK_ROWS,
                                         lines[0][0] - 1)
        rows += len(body)
        if rows > MAX_TRACK_ROWS:
            raise ModelError(f"{what}: {shown!r} holds more than {MAX_TRACK_ROWS:,} rows; allowed at most "
                             f"{MAX_TRACK_ROWS:,}")
        at = {h: k for k, h in enumerate(header)}
        parts.append({c: numbers(body[at[c]], what, shown, where, c, -BOUND, BOUND, missing=True)
                      for c in kept if c in at}
                     | {c: pd.Categorical(body[at[c]].to_numpy(dtype=object)) for c in text if c in at})
    if head is None:
        raise ModelError(f"{what}: {shown!r} holds no header; allowed: a header line and rows")
    if not parts:
        return pd.DataFrame({c: pd.Series(dtype=object if c in text else float) for c in needed})
    out = {}
    for c in parts[0]:
        values = [p[c] for p in parts]
        out[c] = union_categoricals(values) if c in text else np.concatenate(values)
    return pd.DataFrame(out, index=pd.RangeIndex(rows))


def read_json(folder: Path, label: str, name: str) -> dict[str, Any] | None:
    """A JSON object of the folder, None where the file is not there.

    Raises
    ------
    ModelError
        The file larger than :data:`MAX_JSON_BYTES`, not JSON, or not an object (one line).
    """
    path = _path(folder, name, label)
    if not path.is_file():
        return None
    shown = _shown(label, name)
    text = read_text(path, "report", MAX_JSON_BYTES, MAX_ROWS)
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise ModelError(f"report: {shown!r} is not JSON ({str(exc)[:80]}); allowed: the file sblsim track "
                         "writes") from None
    if not isinstance(data, dict):
        raise ModelError(f"report: {shown!r} holds no JSON object; allowed: the file sblsim track writes")
    return data


def _image(folder: Path, label: str, name: str) -> bytes | None:
    """A PNG of the folder (at most :data:`MAX_IMAGE_BYTES`), None where absent or not a PNG."""
    path = _path(folder, name, label)
    if not path.is_file() or path.stat().st_size > MAX_IMAGE_BYTES:
        return None
    data = path.read_bytes()[:MAX_IMAGE_BYTES]
    return data if data.startswith(PNG_MAGIC) else None


def tag_folder(tag: str) -> str:
    """A tag's folder in the study's, as ``sblsim track`` names it (from its id, never from a file's path)."""
    return f"{TAGS_FOLDER}/{folder_name(tag, 'tag')}"


def read_folder(folder: Path | str, label: str | None = None) -> StudyFolder:
    """A study's folder (the module docstring).

    Parameters
    ----------
    folder : Path or str
        The folder ``sblsim track --out`` wrote.
    label : str, optional
        The folder as refusals and the page name it (default: ``folder`` as given).

    Returns
    -------
    StudyFolder

    Raises
    ------
    ModelError
        One line: not a study's folder (no ``study.json``, ``tags.csv``, ``receivers.csv`` or ``tracks.csv``), or
        one of its files refused (:func:`read_table`, :func:`read_json`).
    """
    folder = Path(folder)
    label = str(folder) if label is None else label
    if not folder.is_dir():
        raise ModelError(f"report: {label!r} is not a folder; allowed: a study's folder (sblsim track --out)")
    summary = read_json(folder, label, "study.json")
    tables = {key: read_table(folder, label, key) if key != "tracks" else read_tracks(folder, label)
              for key in REQUIRED}
    missing = [TABLES[k][0] for k, v in tables.items() if v is None] + (["study.json"] if summary is None else [])
    if missing:
        raise ModelError(f"report: {label!r} holds no {', '.join(missing)}; allowed: a study's folder (sblsim track "
                         "--out)")
    out = StudyFolder(label, summary, tables["tags"], tables["receivers"], tables["tracks"],
                      read_table(folder, label, "daily"), read_table(folder, label, "offsets"),
                      read_table(folder, label, "sync_tags"), map_png=_image(folder, label, "map.png"))
    path = _path(folder, REFERENCE_FILE, label)
    if path.is_file():
        out.reference = _table(path, _shown(label, REFERENCE_FILE), ("tag",), None, REFERENCE_TEXT)
    tracked = out.tags.loc[out.tags["status"] == "tracked", "tag"].astype(str)
    for tag in tracked:
        own = tag_folder(tag)
        summary_json = read_json(folder, label, f"{own}/summary.json")
        if summary_json is not None:
            out.tag_summaries[tag] = summary_json
        pings = read_pieces(folder, label, "pings", PING_NUMBERS, within=own)
        if pings is not None and "depth_m" in pings and np.isfinite(pings["depth_m"].to_numpy(float)).any():
            out.tag_pings[tag] = pings
    return out


__all__ = ["REFERENCE_FILE", "StudyFolder", "TABLES", "read_folder", "read_json", "read_pieces", "read_table",
           "read_tracks", "tag_folder"]
