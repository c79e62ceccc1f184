"""A study's synchronisation kept across runs (:mod:`~sblsim.orchestrator.tracks.resume`): a study stopped part way
and run again does not synchronise its clocks again where what the synchronisation reads is the same.

The synchronisation made here (:func:`~sblsim.orchestrator.telemetry.study_clocks.study_clocks`, its source
"synchronised here") is kept in the output's resume folder under the hash of what it reads (:func:`clocks_key`: the
detections' table, the receivers' table, the sound speed or its series, the bins, sblsim's version), its tables as
Parquet, its fit's arrays as ``.npz`` read without pickles and the rest as JSON; clocks given as a folder or taken as
logged cost nothing and are not kept.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.sync.breaks import ClockBreak
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.orchestrator.io.version import installed_version
from sblsim.orchestrator.sync.clocks import offsets_clocks
from sblsim.orchestrator.sync.run import SyncOutcome
from sblsim.orchestrator.telemetry.study_clocks import study_clocks
from sblsim.orchestrator.tracks.resume import Resume, read_tables, write_tables

#: The tables of a :class:`~sblsim.orchestrator.sync.run.SyncOutcome` kept as Parquet files of these names.
TABLES = ("offsets", "residuals", "sync_tags", "receivers", "positions")


def _plain(value: Any) -> Any:
    """A numpy scalar as its Python number (for JSON)."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not kept")


def _table_hash(table: pd.DataFrame) -> bytes:
    digest = hashlib.sha256(pd.util.hash_pandas_object(table, index=True).to_numpy().tobytes())
    digest.update(json.dumps([list(map(str, table.columns)), list(map(str, table.dtypes))]).encode())
    return digest.digest()


def clocks_key(assigned, sound_speed: float | None, series: tuple[np.ndarray, np.ndarray] | None,
               bin_hours: float, survey_sigma: float | None = None, take_seen: bool = True) -> str:
    """The hash (SHA-256, hex) of what a study's synchronisation reads: the assigned detections' table, source and
    clock resets, the receivers' table, the sound speed or its series, the bins [h], the survey's stated error [m]
    (where stated; where the error seen is not taken, that too) and sblsim's version."""
    digest = hashlib.sha256(b"clocks")
    digest.update(_table_hash(assigned.detections.frame))
    digest.update(_table_hash(assigned.hydrophones))
    digest.update(json.dumps([installed_version(), assigned.detections.source, assigned.detections.clock_resets,
                              sound_speed, bin_hours] + ([] if survey_sigma is None else [survey_sigma])
                             + ([] if take_seen else ["said"]),
                             default=_plain).encode())
    for array in series or ():
        digest.update(np.ascontiguousarray(array, float).tobytes())
    return digest.hexdigest()


def _write(entry: Path, outcome: SyncOutcome, info: dict[str, Any]) -> None:
    write_tables(entry, outcome, TABLES)
    arrays, rest = {}, {}
    for item in fields(ClockFit):
        value = getattr(outcome.fit, item.name)
        if isinstance(value, np.ndarray):
            arrays[item.name] = value
        elif item.name == "breaks" and value is not None:
            rest[item.name] = [asdict(b) for b in value]
        else:
            rest[item.name] = value
    np.savez(entry / "fit.npz", **arrays)
    (entry / "outcome.json").write_text(json.dumps({"summary": outcome.summary, "origin": outcome.origin,
                                                    "fit": rest, "info": info}, default=_plain), encoding="utf-8")


def _read(entry: Path) -> tuple[SyncOutcome, dict[str, Any]]:
    meta = json.loads((entry / "outcome.json").read_text(encoding="utf-8"))
    tables = read_tables(entry, TABLES)
    with np.load(entry / "fit.npz", allow_pickle=False) as kept:
        arrays = {name: kept[name] for name in kept.files}
    rest = meta["fit"]
    if rest.get("breaks") is not None:
        rest["breaks"] = [ClockBreak(**b) for b in rest["breaks"]]
    fit = ClockFit(**{item.name: arrays[item.name] if item.name in arrays else rest[item.name]
                      for item in fields(ClockFit)})
    outcome = SyncOutcome(meta["summary"], tables["offsets"], tables["residuals"], tables["sync_tags"],
                          tables["receivers"], fit, meta["origin"], tables["positions"])
    return outcome, meta["info"]


def kept_study_clocks(resume: Resume | None, sync_dir: Path | None, assigned, deployments, sound_speed: float | None,
                      series: tuple[np.ndarray, np.ndarray] | None, bin_hours: float, notes: list[str],
                      survey_sigma: float | None = None, take_seen: bool = True, release_rows: bool = False):
    """:func:`~sblsim.orchestrator.telemetry.study_clocks.study_clocks`, its synchronisation taken from ``resume``
    where a run of the same output kept it for what it reads (:func:`clocks_key`), else made and kept there.

    Raises
    ------
    ModelError
        As :func:`~sblsim.orchestrator.telemetry.study_clocks.study_clocks` (a refusal is never kept).
    """
    if resume is None or sync_dir is not None:
        return study_clocks(sync_dir, assigned, deployments, sound_speed, series, bin_hours, notes, survey_sigma,
                            take_seen, release_rows)
    key = clocks_key(assigned, sound_speed, series, bin_hours, survey_sigma, take_seen)
    kept = resume.fetch(key, _read)
    if kept is not None:
        resume.taken.append("the synchronisation")
        outcome, info = kept
        notes.extend(outcome.summary.get("warnings", []))
        return offsets_clocks(outcome.offsets), assigned.hydrophones, info, outcome
    clocks, table, info, outcome = study_clocks(sync_dir, assigned, deployments, sound_speed, series, bin_hours,
                                                notes, survey_sigma, take_seen, release_rows)
    if outcome is not None:
        resume.store(key, lambda entry: _write(entry, outcome, info))
    return clocks, table, info, outcome


__all__ = ["TABLES", "clocks_key", "kept_study_clocks"]
