"""Error tables of a scenario: all runs and the best cell, receiver against instrumentation."""

from __future__ import annotations

import math

import pandas as pd

from sblsim.orchestrator.analysis.data import AnalysisError, higher_is_better


def _estimators(frame: pd.DataFrame) -> tuple[tuple[str, str], ...]:
    """(name, metric prefix) of the receiver that ran in ``frame`` and of the instrumentation."""
    names = sorted(frame["receiver"].dropna().unique()) if "receiver" in frame.columns else []
    return (("+".join(names) or "receiver", ""), ("instrumentation", "instr_"))


def best_cell(frame: pd.DataFrame, metric: str) -> int:
    """Design cell with the best mean ``metric`` over its runs (NaN runs left out): the lowest error, the
    highest ``detected_pct`` (:func:`~sblsim.orchestrator.analysis.data.higher_is_better`)."""
    means = frame.groupby("cell")[metric].mean()
    if means.isna().all():
        raise AnalysisError(f"runs.parquet: {metric} is NaN in every run")
    return int(means.idxmax() if higher_is_better(metric) else means.idxmin())


def tables(frame: pd.DataFrame, metric: str = "e_tot_rms", scenario: str = "") -> pd.DataFrame:
    """Error tables of one scenario in the tidy layout of ``tables.csv``.

    Parameters
    ----------
    frame : pandas.DataFrame
        Runs of one scenario.
    metric : str
        Response that picks the best cell (:func:`best_cell`).
    scenario : str

    Returns
    -------
    pandas.DataFrame
        ``scenario, table, subset, cell, estimator, statistic, value``: see
        the module documentation; values [m] except ``n`` [-].
    """
    cell = best_cell(frame, metric)
    rows = []
    for subset, part, c in (("all runs", frame, pd.NA), ("best cell", frame[frame["cell"] == cell], cell)):
        for estimator, prefix in _estimators(part):
            for a in ("e_x", "e_y", "e_z", "e_tot"):
                col = f"{prefix}{a}_mean"
                if col in part.columns:
                    rows.append((scenario, "errors", subset, c, estimator, a, float(part[col].mean())))
    for estimator, prefix in _estimators(frame):
        col = f"{prefix}e_tot_mean"
        if col in frame.columns:
            v = frame[col].dropna()
            rows += [(scenario, "receiver_vs_instr", "all runs", pd.NA, estimator, "mean", float(v.mean())),
                     (scenario, "receiver_vs_instr", "all runs", pd.NA, estimator, "std",
                      float(v.std(ddof=1)) if len(v) > 1 else math.nan),
                     (scenario, "receiver_vs_instr", "all runs", pd.NA, estimator, "n", float(len(v)))]
    out = pd.DataFrame(rows, columns=["scenario", "table", "subset", "cell", "estimator", "statistic", "value"])
    out["cell"] = out["cell"].astype("Int64")
    return out
