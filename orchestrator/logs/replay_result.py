"""The outcome of a receiver replayed on a recorded log, as :func:`sblsim.replay` and ``sblsim replay LOG`` hand it
back (:class:`ReplayResult`), and the replay of a resolved plan that makes it
(:func:`sblsim.orchestrator.logs.replay.replay_files`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from sblsim.orchestrator.cosim.plan import Config, RunPlan, thaw

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class ReplayResult:
    """The outcome of :func:`sblsim.replay`.

    Attributes
    ----------
    config : Config
        The configuration the receiver ran with.
    source : str
        Where that configuration came from.
    engine : str
    summary : dict
        ``summary.json``: a run's keys (errors None without a truth track), ``log`` (what was read of the
        log) and ``truth``.
    timeseries : pandas.DataFrame
        One row per macro step: ``time`` [s] on the log's clock, ``log_row``, the receiver's inputs and
        outputs; with a truth track ``true_*`` [m], ``pcrb`` and the errors ``e_*`` [m].
    out : Path or None
    """

    config: Config
    source: str
    engine: str
    summary: dict[str, Any]
    timeseries: pd.DataFrame
    out: Path | None = None
    _plan: Any = field(default=None, repr=False)

    def plot(self) -> dict[str, Figure]:
        """The figures of a run over the steps the truth track covers (empty without truth)."""
        from sblsim.orchestrator.io.plots import run_figures

        ts = self.timeseries
        covered = ts[np.isfinite(ts["true_x"].to_numpy())] if "true_x" in ts else ts.iloc[:0]
        if not len(covered):
            return {}
        receiver = self._plan.receiver_label if self._plan is not None else self.config.plan().receiver_label
        if "replicate" not in covered:
            covered = covered.assign(replicate=0)
        return run_figures(covered, f"replay of {self.summary['log']['file']}, {receiver} ({self.engine})", receiver)


def _replay_plan(plan: RunPlan, source: str, log: Path, truth: Path | None, engine: str,
                 fmu_dir: str | Path | None, prepare: Callable[[], Path | None]) -> ReplayResult:
    """:func:`sblsim.replay` of a plan (and ``sblsim replay``): read the log and the truth track, ``prepare()`` the
    output folder (None: nothing is written), replay and write
    (:func:`sblsim.orchestrator.logs.replay.replay_files`)."""
    from sblsim.orchestrator.logs.replay import replay_files

    result, target = replay_files(plan, log, truth, engine, fmu_dir, prepare)
    return ReplayResult(Config(thaw(result.config)), source, result.engine, result.summary, result.timeseries,
                        target, result.config)


__all__ = ["ReplayResult"]
