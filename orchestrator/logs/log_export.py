"""A run's receiver inputs written as a log (docs/log-format.md) and its truth track beside it: ``sblsim run
--export-log FILE``, checked before any work, so that a replay of the export
(:mod:`sblsim.orchestrator.logs.replay`) equals the run.
"""

from __future__ import annotations

import io
import math
import os
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.declarations import ModelError
from sblsim.models.systems import System
from sblsim.orchestrator.cosim.config import (
    to_toml,
)
from sblsim.orchestrator.cosim.metrics import new_on_lane
from sblsim.orchestrator.cosim.plan import as_plan
from sblsim.orchestrator.cosim.run import RunRecord
from sblsim.orchestrator.cosim.run_output import _label
from sblsim.orchestrator.io.log_tables import (
    CONFIG_PREFIX,
    META_CONFIG,
    META_TITLE,
    SUFFIXES,
)
from sblsim.orchestrator.io.output import write_together
from sblsim.orchestrator.logs.receiver_log import LOG_TITLE, TRUTH_TITLE


def truth_path(log_path: Path | str) -> Path:
    """Where ``--export-log FILE`` writes the truth track: ``FILE``'s stem with ``_truth``, the same suffix."""
    path = Path(log_path)
    return path.with_name(f"{path.stem}_truth{path.suffix}")


def check_export(path: Path, force: bool) -> None:
    """Refuse an ``--export-log`` file before any work: a suffix other than .csv or .parquet, a directory,
    or an existing log or truth file without ``force``.

    Raises
    ------
    ModelError
        Naming ``--export-log``.
    """
    if path.suffix.lower() not in SUFFIXES:
        raise ModelError(f"--export-log: {str(path)!r} must end in .csv or .parquet")
    for target in (path, truth_path(path)):
        if target.is_dir():
            raise ModelError(f"--export-log: {str(target)!r} is a directory")
        if target.exists() and not force:
            raise ModelError(f"--export-log: {str(target)!r} exists; add --force to replace it or choose another "
                             "file")


def log_frames(ts: pd.DataFrame, system: System | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A run's time series (one replicate) as a log, one row per slot, and its truth track (every step).

    A slot whose packet was lost is a depth-only row (``beacon_id`` missing); ``time_s`` is the packet's
    epoch (``tx_time``), ``rx_time`` its arrival (the run's receiver used it at its first step reaching
    that). The rows are in the order the receiver was given them (of arrival). Values are the receiver's
    inputs as the run recorded them, with the columns the run's ``system`` adds
    (:attr:`~sblsim.models.systems.System.log_columns`: USBL's direction of arrival).
    """
    parts = []  # per lane of a delivery: its new packets (step, lane, columns by lane 1's names)
    for m in range(1, LANES + 1):
        prefix = "" if m == 1 else f"lane{m}_"
        if prefix + "packet_seq" not in ts:
            break
        seq = ts[prefix + "packet_seq"].to_numpy()
        if m == 1:
            new = (seq != np.concatenate([[0], seq[:-1]])) & (seq > 0)
        else:
            new = new_on_lane(seq)
        steps = np.flatnonzero(new)
        columns = {c[len(prefix):]: ts[c].to_numpy()[steps] for c in ts.columns if c.startswith(prefix)}
        columns["depth"] = ts["depth"].to_numpy()[steps]
        parts.append((steps, np.full(steps.size, m), columns))
    order = np.lexsort((np.concatenate([p[1] for p in parts]), np.concatenate([p[0] for p in parts])))
    slot = pd.DataFrame({name: np.concatenate([p[2][name] for p in parts])[order]
                         for name in parts[0][2] if all(name in p[2] for p in parts)})
    valid = slot["packet_valid"].to_numpy(bool)

    def packet(column: str) -> np.ndarray:
        return np.where(valid, slot[column].to_numpy(dtype=float), np.nan)

    log = pd.DataFrame({"time_s": slot["tx_time"].to_numpy(dtype=float),
                        **({"rx_time": slot["rx_time"].to_numpy(dtype=float)} if "rx_time" in slot else {}),
                        "beacon_id": pd.array(np.where(valid, slot["beacon_id"].to_numpy(), 0), dtype="Int64"),
                        "range_m": packet("range"), "beacon_n_m": packet("beacon_x"),
                        "beacon_e_m": packet("beacon_y"), "beacon_d_m": packet("beacon_z"),
                        "depth_m": slot["depth"].to_numpy(dtype=float)})
    log.loc[~valid, "beacon_id"] = pd.NA
    for column, source in (system.log_columns if system is not None else {}).items():
        log[column] = packet(source)
    truth = pd.DataFrame({"time_s": ts["time"].to_numpy(dtype=float), "n_m": ts["true_x"].to_numpy(dtype=float),
                          "e_m": ts["true_y"].to_numpy(dtype=float), "d_m": ts["true_z"].to_numpy(dtype=float)})
    return log, truth


def _csv_text(frame: pd.DataFrame, comments: Sequence[str]) -> str:
    """A frame as CSV text: numbers as Python writes them (they read back exactly), missing values empty."""
    buffer = io.StringIO()
    for line in comments:
        buffer.write(f"{line}\n")
    buffer.write(",".join(frame.columns) + "\n")
    columns = [frame[c].to_numpy(dtype=object) for c in frame.columns]
    for values in zip(*columns):
        buffer.write(",".join("" if v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v))
                              else (repr(float(v)) if isinstance(v, (float, np.floating)) else str(v))
                              for v in values) + "\n")
    return buffer.getvalue()


def export_log(result: RunRecord, path: Path | str) -> tuple[Path, Path]:
    """Write a run's receiver inputs as a log (``path``) and its truth track beside it (:func:`truth_path`).

    The log carries the run's resolved configuration (CSV: ``#%`` comment lines; Parquet: schema
    metadata), which ``sblsim replay`` takes unless it is given ``--config``.

    Returns
    -------
    (Path, Path)
        The log and the truth track.

    Raises
    ------
    ModelError
        ``--export-log: ...`` when a write fails (a full disk): then neither file is replaced, nor is a folder
        made for them left (:func:`sblsim.orchestrator.io.output.write_together`).
    """
    path = Path(path)
    cfg = result.config
    ts = result.timeseries
    ts = ts[ts["replicate"] == ts["replicate"].iloc[0]]
    plan = result.plan if result.plan is not None else as_plan(cfg)
    log, truth = log_frames(ts, plan.system)
    origin = (f"exported from: sblsim run {cfg['run']['scenario']} (seed {cfg['run']['seed']}, "
              f"platform.system {cfg['platform']['system']}, receiver {_label(result)}, {result.engine} engine)")
    config = to_toml(cfg)
    lost = int(log["beacon_id"].isna().sum())
    comments = [f"# {LOG_TITLE}",
                "# columns, units and the replay's rules: docs/log-format.md; time_s is the packet's epoch, a row "
                "without beacon_id a depth reading only",
                f"# {origin}; {len(log)} slots, {lost} packets lost",
                "# the run's resolved configuration, which `sblsim replay` uses unless given --config:",
                *[f"{CONFIG_PREFIX}{line}" if line else CONFIG_PREFIX.rstrip() for line in config.splitlines()]]
    target = truth_path(path)
    if path.suffix.lower() == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        def parquet(frame: pd.DataFrame, meta: dict[bytes, bytes]):
            def write(tmp: Path) -> None:
                table = pa.Table.from_pandas(frame, preserve_index=False)
                pq.write_table(table.replace_schema_metadata({**(table.schema.metadata or {}), **meta}), tmp)
            return write

        writers = (parquet(log, {META_TITLE: LOG_TITLE.encode(), META_CONFIG: config.encode()}),
                   parquet(truth, {META_TITLE: TRUTH_TITLE.encode()}))
    else:
        text = _csv_text(log, comments)
        truth_text = _csv_text(truth, [f"# {TRUTH_TITLE}", f"# {origin}; the diver's true position at the end "
                                       "of every step (N, E, D in the platform's frame)"])
        writers = (lambda tmp: tmp.write_text(text, encoding="utf-8"),
                   lambda tmp: tmp.write_text(truth_text, encoding="utf-8"))
    try:  # the pair as one: both written, or neither replaced (nor a folder made for them left)
        write_together(dict(zip((path, target), writers)))
    except OSError as exc:  # e.g. a full disk
        reason = os.strerror(exc.errno) if exc.errno else str(exc)
        raise ModelError(f"--export-log: {reason}; neither the log nor its truth track was written ({str(path)!r} "
                         "is as it was)") from None
    return path, target


#: The files ``sblsim run`` writes into its output folder that an ``--export-log`` file could replace.
RUN_FILES = ("summary.json", "config.toml", "timeseries.parquet")


def _check_export_apart(export: Path | None, out: Path) -> None:
    """Refuse an ``--export-log`` file (or its truth track) that is one of the run's own files in ``out``.

    Raises
    ------
    ModelError
        Naming ``--export-log`` and the file.
    """
    if export is None:
        return
    folder = out.resolve()
    for target in (export, truth_path(export)):
        if target.resolve().parent == folder and target.name.lower() in RUN_FILES:
            raise ModelError(f"--export-log: {str(target)!r} is the run's own {target.name} in --out {str(out)!r}; "
                             "give the log another name or folder")


__all__ = ["RUN_FILES", "check_export", "export_log", "log_frames", "truth_path"]
