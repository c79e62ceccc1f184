"""The campaign directory's records: ``study.toml``, the manifest of finished chunks, and their checks."""

from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import tomli_w

from sblsim.orchestrator.campaign.errors import CampaignError
from sblsim.orchestrator.campaign.plan import Chunk
from sblsim.orchestrator.campaign.study import Study
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.manifest import file_digest
from sblsim.orchestrator.io.output import refuse_link, write_atomic


def write_parquet(frame: pd.DataFrame, path: Path) -> None:
    """Write a Parquet file through a temporary file in the same folder and an atomic rename."""
    write_atomic(path, lambda tmp: frame.to_parquet(tmp, index=False))


MANIFEST = "manifest.json"
#: The manifest's entry recording the chunk plan (engine, batch size), beside the chunks' entries.
PLAN = "_plan"


def read_manifest(out: Path) -> dict[str, dict] | None:
    """The campaign's manifest (chunk id -> entry), or None when there is none.

    Raises
    ------
    CampaignError
        If it cannot be read, saying what to do.
    """
    path = out / MANIFEST
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
        if not isinstance(manifest, dict) or not all(isinstance(v, dict) for v in manifest.values()):
            raise ValueError("not a table of chunks")
    except (ValueError, UnicodeDecodeError) as exc:
        raise CampaignError(f"--resume: {str(path)!r} is damaged ({str(exc).splitlines()[0]}); delete it and "
                            "resume again: every chunk is then checked by its content") from None
    return manifest


def write_manifest(out: Path, manifest: dict[str, dict]) -> None:
    """Write the manifest atomically."""
    write_atomic(out / MANIFEST, lambda tmp: tmp.write_text(json.dumps(manifest, indent=1, sort_keys=True)))


def manifest_entry(chunk: Chunk, path: Path, series: Path | None = None, seconds: float | None = None
                   ) -> dict[str, Any]:
    """What the manifest records of a finished chunk (with the worker's seconds for it, when known)."""
    entry = {"rows": chunk.runs, "cells": list(chunk.cells), "replicates": chunk.replicates,
             "sha256": file_digest(path)}
    if seconds is not None:
        entry["seconds"] = round(float(seconds), 3)
    if series is not None:
        entry["series_sha256"] = file_digest(series)
    return entry


def verify_chunk(chunk: Chunk, path: Path, entry: dict | None, scenario_key: int, study: Study) -> str:
    """Why a chunk file cannot be kept ('' if it can): checksum, rows, cells, replicates, scenario, and the
    seed and factor levels of its rows (a chunk of another study is refused even with the same cells)."""
    if not path.is_file():
        return "missing"
    if entry is not None:
        if entry.get("sha256") != file_digest(path):
            return "its checksum differs from the manifest's"
        if entry.get("cells") != list(chunk.cells) or entry.get("rows") != chunk.runs:
            return "the manifest records other cells"
    levels = [f"{f.name}_value" for f in study.factors]
    try:
        frame = pd.read_parquet(path, columns=["scenario_key", "cell", "replicate", "seed", *levels])
    except Exception as exc:  # pyarrow raises several kinds on a damaged file
        return f"unreadable ({type(exc).__name__})"
    expected = {(c, r) for c in chunk.cells for r in range(chunk.replicates)}
    got = set(zip(frame["cell"].tolist(), frame["replicate"].tolist()))
    if len(frame) != chunk.runs or got != expected or set(frame["scenario_key"].tolist()) != {scenario_key}:
        return "it holds other runs than the plan's"
    cells = frame["cell"].to_numpy()
    for k, (factor, column) in enumerate(zip(study.factors, levels)):
        want = np.where(study.matrix[cells, k] < 0, factor.low, factor.high)
        if not np.array_equal(frame[column].to_numpy(), want) or not (frame["seed"] == study.seed).all():
            return "its rows belong to another study (seed or factor levels)"
    return ""


def prepare_directory(out: Path, study: Study, resume: bool, engine: str, batch: int) -> int:
    """Check or create the campaign directory; return the batch size to use.

    A new directory gets ``study.toml`` (with the engine and batch size in an
    ``[execution]`` table). ``--resume`` requires the same study and engine
    and re-uses the recorded batch size, so the chunk plan is unchanged.

    Raises
    ------
    CampaignError
        If the directory holds another campaign, or a campaign without
        ``--resume``, or is a non-empty folder without a campaign.
    """
    study_file = out / "study.toml"
    text = study.to_toml()
    if out.exists() and not out.is_dir():
        raise CampaignError(f"--out: {str(out)!r} exists and is not a directory")
    if study_file.is_file():
        if not resume:
            raise CampaignError(f"--out: {str(out)!r} already holds a campaign; add --resume to finish it "
                                "or choose another directory")
        try:
            recorded = tomlfile.loads(study_file.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise CampaignError(f"--resume: {str(study_file)!r} is damaged ({str(exc).splitlines()[0]}); delete it "
                                "and resume again: it is rewritten from the study you give, and every chunk is "
                                "checked against that study") from None
        execution = recorded.pop("execution", {})
        if not isinstance(execution, dict):
            execution = {}
        if recorded != tomlfile.loads(text):
            raise CampaignError(f"--resume: {str(out)!r} holds a different study; choose another --out")
        if execution.get("engine", engine) != engine:
            raise CampaignError(f"--engine: {str(out)!r} was run on the {execution['engine']} engine; "
                                "resume it with the same engine")
        return int(execution.get("batch", batch))
    if out.is_dir() and any(out.iterdir()):
        if not (resume and (out / "chunks").is_dir()):
            raise CampaignError(f"--out: {str(out)!r} is not empty and holds no campaign; choose another directory")
        # a campaign whose study.toml was deleted: rewritten from the study given, with the recorded plan
        plan_record = (read_manifest(out) or {}).get(PLAN, {})
        if plan_record.get("engine", engine) != engine:
            raise CampaignError(f"--engine: {str(out)!r} was run on the {plan_record['engine']} engine; "
                                "resume it with the same engine")
        batch = int(plan_record.get("batch", batch))
        print(f"campaign: {str(study_file)!r} was missing; written again from the study given", file=sys.stderr)
    out.mkdir(parents=True, exist_ok=True)
    for name in ("chunks", "timeseries"):  # folders written into: never through a link
        refuse_link(out / name, "--out")
    (out / "chunks").mkdir(exist_ok=True)
    execution = "\n# how the campaign is executed (does not change the results)\n" + tomli_w.dumps(
        {"execution": {"engine": engine, "batch": batch}})
    write_atomic(study_file, lambda tmp: tmp.write_text(text + execution))
    return batch
