"""A run's output: the ``summary.json`` of a single-replicate run, and the run's folder (``summary.json``,
``config.toml``, ``timeseries.parquet`` and the figures) written atomically.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable

from sblsim.orchestrator.cosim.config import receiver_label, to_toml
from sblsim.orchestrator.cosim.run import RunRecord
from sblsim.orchestrator.io.output import staged_directory


def summary(result: RunRecord) -> dict[str, Any]:
    """``summary.json`` content of a single-replicate run (the keys the README lists); strict JSON: a metric
    without a value (e.g. no instrumentation fix at all) is ``None`` (``null``), never NaN."""
    row = result.metrics.iloc[0]
    def value(k: str) -> Any:
        if k in ("diverged", "beyond_geometry"):
            return bool(row[k])
        if k in ("updates", "fix_steps"):
            return int(row[k])
        return None if math.isnan(row[k]) else float(row[k])

    out: dict[str, Any] = {k: value(k) for k in result.metrics.columns if k != "replicate"}
    out.update(engine=result.engine, receiver=_label(result), seed=int(result.config["run"]["seed"]),
               steps=int(result.steps),
               scenario=result.config["run"]["scenario"], replicate=int(row["replicate"]),
               duration=float(result.steps * result.config["simulation"]["sampling_time"]),
               wall_time=round(result.wall_time, 3))
    return out


def _label(result: RunRecord) -> str:
    """What figures and tables call the receiver of a result (its plan's label)."""
    return result.plan.receiver_label if result.plan is not None else receiver_label(result.config)


def write_run(result: RunRecord, out_dir: Path | str, then: Callable[[], object] | None = None) -> Path:
    """Write ``summary.json``, ``config.toml``, ``timeseries.parquet`` and figures atomically.

    Everything is written into a temporary directory beside ``out_dir`` and
    moved into place only when complete, so an error leaves nothing
    half-written.

    Parameters
    ----------
    result : RunRecord
    out_dir : path
    then : callable, optional
        What else the run writes (``sblsim run --export-log``'s log), called when the run's own files are written
        and before they are moved into place: if it raises, ``out_dir`` is left as it was.

    Returns
    -------
    Path
        ``out_dir``.
    """
    from sblsim.orchestrator.io.plots import save_run_figures

    out_dir = Path(out_dir)
    with staged_directory(out_dir) as tmp:
        (tmp / "summary.json").write_text(json.dumps(summary(result), indent=2, allow_nan=False) + "\n")
        (tmp / "config.toml").write_text(to_toml(result.config))
        result.timeseries.to_parquet(tmp / "timeseries.parquet", index=False)
        receiver = _label(result)
        save_run_figures(result.timeseries, tmp, title=f"{result.config['run']['scenario']}, {receiver} "
                         f"({result.engine})", receiver=receiver)
        if then is not None:
            then()
    return out_dir


__all__ = ["summary", "write_run"]
