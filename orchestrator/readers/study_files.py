"""A study's files as its people give them (``sblsim track``, :func:`sblsim.track`): which given file or folder is
what, each read by its reader, and many detection files read as one table.

The detections may be given as

* **an actel workspace**, the one folder actel works in (:mod:`.actel`; as its ``exampleWorkspace`` writes it):
  ``deployments.csv`` (the receivers, unless ``receivers`` names another sheet), ``spatial.csv`` (the stations'
  positions, unless ``spatial`` is given), ``biometrics.csv`` (the tags, unless ``tags`` is given) and the detections:
  the files of its ``detections`` folder, else its ``detections.csv`` (with both, the folder alone, as actel does:
  said);
* **a folder of detection files**: every ``*.csv`` file in it (its sub-folders not looked into), by name; the other
  files are named in a note, not read;
* **one or more files**;
* **a store** (a folder ``sblsim store`` wrote: :mod:`sblsim.orchestrator.store`), read as its file would be but
  without the file's row and size limits (a study, :mod:`sblsim.orchestrator.telemetry.study_detections`, reads it
  a batch of tags at a time: ``read_study(..., detections=False)``).

Each detection file is read by :func:`~sblsim.orchestrator.readers.detections.read_detections` in its own format
(``format``, else told from its first line): one receiver's log, or many receivers' in one file. Many files are one
table (:func:`read_many`): each row keeps its file (``file``) and line, each file's clock judged on its own (a
receiver's time going back within one file; :attr:`~.detections.Detections.clock_resets`, each with its ``file``), a
detection that an earlier file holds already (the same receiver, tag and time: an overlapping download) dropped and
counted; the files together hold at most :data:`~sblsim.orchestrator.readers.limits.MAX_DETECTIONS` rows.

The receivers sheet is actel's deployments where its header is (``Receiver``, ``Station.name``, ``Start``, ``Stop``:
local times, :func:`~.actel.read_actel_deployments` with ``spatial`` and the study's time zone ``tz``), else a
deployments sheet (:func:`~sblsim.orchestrator.readers.deployments.read_deployments`). The tag sheet is actel's
biometrics where its header has ``Signal`` and ``Release.date`` (:func:`~.actel.read_biometrics`), else a tag sheet
(:func:`~sblsim.orchestrator.readers.tag_sheet.read_tag_sheet`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers import actel
from sblsim.orchestrator.readers.cells import named, read_text, text_table
from sblsim.orchestrator.readers.deployments import Deployments, read_deployments
from sblsim.orchestrator.readers.detections import LOGGED, SORTED, Detections
from sblsim.orchestrator.readers.limits import MAX_DETECTION_BYTES, MAX_DETECTIONS
from sblsim.orchestrator.readers.tag_sheet import TagSheet, read_tag_sheet
from sblsim.orchestrator.store.read import is_store, read_any

#: The most detection files a study reads.
MAX_FILES = 10_000
#: The columns (normal names) that tell actel's biometrics from a tag sheet.
BIOMETRICS_FINGERPRINT = ("signal", "release_date")
#: How many of many files a summary names.
SHOWN_FILES = 3


class DetectionFiles(tuple):
    """Detection files (paths) as a user gave them: shown as a folder's name or the files' names."""

    shown: str = ""

    def __str__(self) -> str:
        return self.shown or _shown(list(self))


def _shown(paths: list[Path]) -> str:
    names = ", ".join(str(p) for p in paths[:SHOWN_FILES])
    return names + (f" and {len(paths) - SHOWN_FILES} more files" if len(paths) > SHOWN_FILES else "")


@dataclass
class StudyFiles:
    """Which file is what (module docstring).

    Attributes
    ----------
    detections : DetectionFiles
        The detection files, in the order read.
    receivers : Path
        The receivers (a deployments sheet or actel's deployments).
    spatial : Path or None
        actel's stations (``spatial.csv``).
    tags : Path or None
        The tag sheet or actel's biometrics.
    notes : list of str
        What was found that a user should know (a workspace's files, files not read).
    """

    detections: DetectionFiles
    receivers: Path
    spatial: Path | None = None
    tags: Path | None = None
    notes: list[str] = field(default_factory=list)


def _csv_files(folder: Path, notes: list[str]) -> list[Path]:
    """A folder's ``*.csv`` files by name (the others named in a note).

    Raises
    ------
    ModelError
        A folder without one, or with more than :data:`MAX_FILES`.
    """
    try:
        entries = sorted(folder.iterdir())
    except OSError as exc:
        raise ModelError(f"detections: {str(folder)!r} cannot be read ({exc.strerror or type(exc).__name__})") from None
    files = [p for p in entries if p.suffix.lower() == ".csv" and p.is_file()]
    others = [p.name for p in entries if p not in files and not p.is_dir()]
    if not files:
        raise ModelError(f"detections: the folder {str(folder)!r} holds no .csv file; allowed: a folder of detection "
                         "exports (CSV), or an actel workspace")
    if len(files) > MAX_FILES:
        raise ModelError(f"detections: the folder {str(folder)!r} holds {len(files):,} .csv files; allowed at most "
                         f"{MAX_FILES:,}")
    if others:
        notes.append(f"{folder}: {len(others)} files not read (not .csv): {', '.join(others[:6])}")
    return files


def study_files(detections: Path | Sequence[Path], receivers: Path | None = None, spatial: Path | None = None,
                tags: Path | None = None) -> StudyFiles:
    """Which given file is what (module docstring).

    Parameters
    ----------
    detections : Path or sequence of Path
        Detection files, a folder of them, or an actel workspace.
    receivers, spatial, tags : Path, optional
        Given one by one; a workspace's own where not given.

    Returns
    -------
    StudyFiles

    Raises
    ------
    ModelError
        No receivers (none given, and no workspace), a workspace without detections, a folder without a ``.csv``.
    """
    given = [Path(detections)] if isinstance(detections, (str, Path)) else [Path(p) for p in detections]
    if not given:
        raise ModelError("detections: none given; allowed: detection files, a folder of them, or an actel workspace")
    notes: list[str] = []
    shown = ""
    if len(given) == 1 and given[0].is_dir():
        folder = given[0]
        shown = str(folder)
        if is_store(folder):  # a store of detections (sblsim store): read as one file
            paths = [folder]
        elif (folder / actel.DEPLOYMENTS_FILE).is_file():  # actel's workspace
            found = [own for value, own in ((receivers, actel.DEPLOYMENTS_FILE), (spatial, actel.SPATIAL_FILE),
                                            (tags, actel.BIOMETRICS_FILE))
                     if value is None and (folder / own).is_file()]
            receivers = receivers or folder / actel.DEPLOYMENTS_FILE
            spatial = spatial or ((folder / actel.SPATIAL_FILE) if (folder / actel.SPATIAL_FILE).is_file() else None)
            tags = tags or ((folder / actel.BIOMETRICS_FILE) if (folder / actel.BIOMETRICS_FILE).is_file() else None)
            inner, single = folder / actel.DETECTIONS_FOLDER, folder / actel.DETECTIONS_FILE
            if inner.is_dir():
                paths = _csv_files(inner, notes)
                if single.is_file():
                    notes.append(f"{folder}: both a {actel.DETECTIONS_FOLDER} folder and {actel.DETECTIONS_FILE}: the "
                                 f"folder's files read, {actel.DETECTIONS_FILE} not (as actel does)")
            elif single.is_file():
                paths = [single]
            else:
                raise ModelError(f"detections: the actel workspace {str(folder)!r} holds neither a "
                                 f"{actel.DETECTIONS_FOLDER} folder nor {actel.DETECTIONS_FILE}; allowed: one of them")
            notes.insert(0, f"{folder}: an actel workspace ({', '.join(found)}; the detections: {len(paths)} "
                            f"file{'s' if len(paths) > 1 else ''})")
        else:
            paths = _csv_files(folder, notes)
    else:
        paths = []
        for path in given:
            paths.extend(_csv_files(path, notes) if path.is_dir() and not is_store(path) else [path])
    if receivers is None:
        raise ModelError("receivers: none given; allowed: the receivers' deployments (--receivers SHEET), or the "
                         f"detections as an actel workspace folder (holding {actel.DEPLOYMENTS_FILE} and "
                         f"{actel.SPATIAL_FILE})")
    files = DetectionFiles(paths)
    files.shown = shown
    return StudyFiles(files, Path(receivers), None if spatial is None else Path(spatial),
                      None if tags is None else Path(tags), notes)


def _header(path: Path, what: str) -> list[str]:
    """A table's header (its first line, pandas' parse), empty where it cannot be read as text (its reader then
    says why)."""
    try:
        first = read_text(path, what, MAX_DETECTION_BYTES, MAX_DETECTIONS, prefix=65536).split("\n", 1)[0]
        return text_table(first.rstrip("\r") + "\n", str(path), what, 1)[0] if first.strip() else []
    except ModelError:
        return []


def read_study(files: StudyFiles, format: str | None = None, crs: str | None = None, frame: str | None = None,
               tz: str | None = None, detections: bool = True
               ) -> tuple[Deployments, Detections | None, TagSheet | None, list[str]]:
    """A study's files read, each by its reader (module docstring).

    Parameters
    ----------
    files : StudyFiles
    format : str, optional
        The detections' format (every file's); default told from each file's first line.
    crs, frame : str, optional
        The receivers' CRS and the metric frame.
    tz : str, optional
        The study's IANA time zone (actel's local times).
    detections : bool
        Read the detections (else None: a store's, read by the study a batch of tags at a time).

    Returns
    -------
    deployments, detections, sheet, notes
        The receivers, the detections (:func:`read_many`; None where not read), the tag sheet (None where none is
        given) and the notes on what was read.

    Raises
    ------
    ModelError
        A file refused by its reader (one line), ``spatial`` with a receivers sheet that is not actel's.
    """
    notes = list(files.notes)
    local = False
    if actel.is_actel_deployments(_header(files.receivers, "receivers")):
        deployments = actel.read_actel_deployments(files.receivers, files.spatial, tz, crs, frame)
        notes.extend(deployments.notes)  # the join, the time zone, each open deployment: said
        local = True
    elif files.spatial is not None:
        raise ModelError(f"spatial: {str(files.spatial)!r} is actel's stations file, for actel's deployments "
                         f"(Receiver, Station.name, Start, Stop); the receivers sheet {str(files.receivers)!r} is not "
                         "one; allowed: actel's deployments, or no stations file")
    else:
        deployments = read_deployments(files.receivers, crs, frame)
    data = read_many(files.detections, format) if detections else None
    sheet = None
    if files.tags is not None:
        header = _header(files.tags, "tags")
        if all(named(header, (key,)) is not None for key in BIOMETRICS_FINGERPRINT):
            sheet = actel.read_biometrics(files.tags, tz)
            notes.extend(sheet.notes)
            local = True
        else:
            sheet = read_tag_sheet(files.tags)
    if tz is not None and not local:
        notes.append(f"the time zone {tz} not used: no file read holds local times (actel's deployments or "
                     "biometrics); every other time is UTC unless it carries its offset")
    return deployments, data, sheet, notes


def read_many(paths: Sequence[Path], format: str | None = None) -> Detections:
    """Detection files read (each by :func:`~sblsim.orchestrator.readers.detections.read_detections`) as one table
    (module docstring); one file: its table as read.

    Parameters
    ----------
    paths : sequence of Path
        The files, in the order read (a :class:`DetectionFiles` keeps how they were given, for the source).
    format : str, optional
        Every file's format; default told from each file's first line.

    Returns
    -------
    Detections
        ``frame`` with a ``file`` column (each row's file, categorical) besides the columns of one file's;
        ``source`` the folder given (or the files' names); ``format`` the formats read (joined by ``+``);
        ``duplicates`` the rows an earlier file held; ``clock_resets`` each with its ``file``, its ``clock_part``
        numbered among its receiver's parts in every file.

    Raises
    ------
    ModelError
        A file refused by its reader (one line naming it), the files holding more than
        :data:`~sblsim.orchestrator.readers.limits.MAX_DETECTIONS` rows together.
    """
    if len(paths) == 1:
        return read_any(paths[0], format)
    parts, total = [], 0
    for path in paths:
        part = read_any(path, format)
        total += len(part.frame)
        if total > MAX_DETECTIONS:
            raise ModelError(f"detections: {str(path)!r}: the files read up to it hold {total:,} detections; allowed "
                             f"at most {MAX_DETECTIONS:,} in a study's files together")
        parts.append(part)
    return combined(parts, str(paths) if isinstance(paths, DetectionFiles) else _shown(list(paths)))


def combined(parts: list[Detections], source: str) -> Detections:
    """Many files' detections (each read) as one table (:func:`read_many`)."""
    sources = [p.source for p in parts]
    frame = pd.concat([p.frame.assign(file=k) for k, p in enumerate(parts)], ignore_index=True)
    for key in frame.columns:
        if frame[key].dtype == object:
            frame[key] = frame[key].fillna("")
    keys = ["receiver", "tag", "time"]  # a detection an earlier file holds (within a file: as logged)
    repeated = (frame["file"] > frame.groupby(keys, sort=False)["file"].transform("min")).to_numpy(bool)
    notes = [note for p in parts for note in p.notes]
    if repeated.any():
        frame = frame[~repeated].reset_index(drop=True)
        notes.append(f"{int(repeated.sum()):,} detections dropped: an earlier file holds each (the same receiver, "
                     "tag and time: downloads that overlap)")
    resets = [r | {"file": sources[k], "_file": k} for k, p in enumerate(parts) for r in p.clock_resets]
    if resets:
        resets = _renumber(frame, resets)
    frame["file"] = pd.Categorical.from_codes(frame["file"].to_numpy(np.int64), categories=sources)
    formats = list(dict.fromkeys(p.format for p in parts))
    orders = {p.row_order for p in parts}
    ignored = list(dict.fromkeys(h for p in parts for h in p.ignored_columns))
    for r in resets:
        del r["_file"]
    return Detections(frame, source, "+".join(formats), ignored, resets, LOGGED if orders == {LOGGED} else SORTED,
                      sum(p.duplicates for p in parts) + int(repeated.sum()), notes)


def _renumber(frame: pd.DataFrame, resets: list[dict]) -> list[dict]:
    """Each receiver's clock parts across its files: where one of its files has a reset, each (file, part) of it
    that holds rows a part of its own, numbered in the files' order, then the parts' (``frame`` changed in place);
    the resets with their new parts (a reset whose part holds no row left out)."""
    if "clock_part" not in frame:
        frame["clock_part"] = 1
    part = frame["clock_part"].fillna(1).to_numpy(np.int64)
    mine = frame["receiver"].isin({r["receiver"] for r in resets}).to_numpy(bool)
    keys = pd.DataFrame({"receiver": frame["receiver"].to_numpy()[mine], "file": frame["file"].to_numpy()[mine],
                         "part": part[mine]})
    pieces = keys.drop_duplicates().sort_values(["receiver", "file", "part"], kind="stable")
    pieces["new"] = pieces.groupby("receiver").cumcount() + 1
    number = {(r, f, p): n for r, f, p, n in pieces[["receiver", "file", "part", "new"]].itertuples(index=False)}
    part[mine] = [number[k] for k in zip(keys["receiver"], keys["file"], keys["part"])]
    part[~mine] = 1
    frame["clock_part"] = part
    kept = [r for r in resets if (r["receiver"], r["_file"], r["clock_part"]) in number]
    for r in kept:
        r["clock_part"] = number[(r["receiver"], r["_file"], r["clock_part"])]
    return kept


__all__ = ["BIOMETRICS_FINGERPRINT", "DetectionFiles", "MAX_FILES", "SHOWN_FILES", "StudyFiles", "combined",
           "read_many", "read_study", "study_files"]
