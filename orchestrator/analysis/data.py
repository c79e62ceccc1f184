"""Reading a campaign for the analysis: ``runs.parquet``, the study record, the response and model checks."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.errors import CampaignError
from sblsim.orchestrator.campaign.errors import StudyError
from sblsim.orchestrator.campaign.study import Factor
from sblsim.orchestrator.campaign.study_record import StudyRecord, level_value, read_record
from sblsim.orchestrator.cosim.metrics import METRIC_NAMES

METRICS = tuple(METRIC_NAMES) + tuple(f"instr_{m}" for m in METRIC_NAMES)
#: Every response a fit can take: the error metrics [m] and the share of the slots whose packet was received
#: (``detected_pct`` [%], detection by signal-to-noise), each with its unit and whether a higher value is better.
RESPONSES: dict[str, tuple[str, bool]] = {**{m: ("m", False) for m in METRICS}, "detected_pct": ("%", True)}
#: Columns ``runs.parquet`` must hold besides the factors and the metrics.
REQUIRED_COLUMNS = ("scenario", "cell", "replicate")

#: Transforms of the response before the fit: none, the natural logarithm, Box-Cox with λ by maximum likelihood.
TRANSFORMS = ("none", "log", "boxcox")


_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class AnalysisError(CampaignError):
    """Bad analysis input; the one-line message names the file or option at fault."""


def load_runs(directory: Path | str) -> pd.DataFrame:
    """Read ``DIR/runs.parquet``.

    Raises
    ------
    AnalysisError
        The file is missing, unreadable, empty or lacks a required column.
    """
    path = Path(directory) / "runs.parquet"
    if not path.is_file():
        raise AnalysisError(f"runs.parquet: no such file {str(path)!r}; run a campaign first")
    try:
        frame = pd.read_parquet(path)
    except Exception as exc:  # pyarrow raises several types for a corrupt file
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise AnalysisError(f"runs.parquet: cannot read {str(path)!r} ({reason})") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise AnalysisError(f"runs.parquet: missing column(s) {', '.join(missing)} in {str(path)!r}")
    if frame.empty:
        raise AnalysisError(f"runs.parquet: {str(path)!r} holds no runs")
    frame = frame.copy()
    frame["scenario"] = frame["scenario"].astype(str)
    return frame


def infer_factors(runs: pd.DataFrame) -> list[Factor]:
    """Factors from the columns of ``runs.parquet``: every ``NAME`` with a ``NAME_value`` partner.

    The physical levels are the values of ``NAME_value`` where ``NAME`` is −1
    and +1 (NaN if a level never occurs); the unit is unknown.
    """
    factors = []
    for col in runs.columns:
        if col in RESPONSES or not isinstance(col, str) or f"{col}_value" not in runs.columns:
            continue
        levels = []
        for code in (-1, 1):
            values = runs.loc[runs[col] == code, f"{col}_value"]
            levels.append(level_value(values.iloc[0]) if len(values) else math.nan)
        factors.append(Factor(col, "", levels[0], levels[1]))
    return factors


def load_campaign_study(directory: Path | str, runs: pd.DataFrame) -> tuple[StudyRecord, list[str]]:
    """Read ``DIR/study.toml`` (:func:`sblsim.orchestrator.campaign.study_record.read_record`), or infer the study from
    ``runs`` when it is missing.

    Returns
    -------
    study : StudyRecord
    warnings : list of str

    Raises
    ------
    AnalysisError
        A corrupt ``study.toml``, a factor that is not an identifier, or a
        factor without a coded column in ``runs.parquet``.
    """
    path = Path(directory) / "study.toml"
    notes: list[str] = []
    scen = scenario_order(runs)
    if not path.is_file():
        factors = infer_factors(runs)
        notes.append("study.toml not found: the factors are inferred from the columns of runs.parquet "
                     "(NAME with a NAME_value partner); units and descriptions are unknown")
        seeds = runs["seed"].unique() if "seed" in runs.columns else []
        per_cell = runs.groupby(["scenario", "cell"]).size()
        study = StudyRecord(name=Path(directory).name, seed=int(seeds[0]) if len(seeds) == 1 else None,
                            replicates=int(per_cell.max()) if per_cell.nunique() == 1 else None,
                            design="unknown", resolution=0, generators="", scenarios=scen, engine="",
                            factors=factors, inferred=True)
    else:
        try:
            study = read_record(path, Path(directory).name, scen)
        except StudyError as exc:
            raise AnalysisError(str(exc)) from None
        absent = [x for x in study.scenarios if x not in scen]
        if absent:
            notes.append(f"scenario(s) {', '.join(absent)} of study.toml have no run in runs.parquet")
    if not study.factors:
        raise AnalysisError("factors: none found (study.toml lists no [[factors]] and runs.parquet "
                            "has no NAME/NAME_value column pair)")
    for f in study.factors:
        if not _NAME.match(f.name):
            raise AnalysisError(f"factors: name {f.name!r} is not an identifier (letters, digits, underscore)")
        if f.name not in runs.columns:
            raise AnalysisError(f"runs.parquet: no coded column for factor {f.name!r}")
    names = [f.name for f in study.factors]
    if len(set(names)) != len(names):
        raise AnalysisError(f"factors: duplicate names in {', '.join(names)}")
    return study, notes


def scenario_order(runs: pd.DataFrame) -> list[str]:
    """Scenarios in ``scenario_key`` order (else in order of appearance)."""
    if "scenario_key" in runs.columns:
        runs = runs.sort_values("scenario_key", kind="stable")
    return list(dict.fromkeys(runs["scenario"]))


def response_unit(metric: str) -> str:
    """The unit of a response of :data:`RESPONSES` (``m``, ``%``); '' for another column."""
    return RESPONSES.get(metric, ("", False))[0]


def higher_is_better(metric: str) -> bool:
    """Whether a higher value of the response is better (``detected_pct``), not a lower one (the errors)."""
    return RESPONSES.get(metric, ("", False))[1]


def allowed_metrics(frame: pd.DataFrame) -> list[str]:
    """Response columns of :data:`RESPONSES` present in ``frame``."""
    return [m for m in RESPONSES if m in frame.columns]


def check_metric(metric: str, frame: pd.DataFrame) -> None:
    """Raise :class:`AnalysisError` unless ``metric`` is a response column (:data:`RESPONSES`) of ``frame``."""
    allowed = allowed_metrics(frame)
    if metric not in allowed:
        if metric in RESPONSES:
            raise AnalysisError(f"runs.parquet: has no {metric!r} column (not written by a finished campaign?); "
                                f"--metric can be one of {', '.join(allowed) or '(no metric column)'}")
        raise AnalysisError(f"metric: {metric!r} is not one of {', '.join(allowed) or '(no metric column)'}")


def check_order(order: Any, k: int) -> int:
    """Validate the model order against the number of factors ``k``; return it as int."""
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 1 <= order <= k:
        raise AnalysisError(f"order: {order!r} is outside the allowed range [1, {k}] (1 = main effects, "
                            f"{k} = full model with {k} factors)")
    return int(order)


def check_transform(transform: str, frame: pd.DataFrame | None = None, metric: str = "e_tot_rms") -> str:
    """Validate a response transform; for ``log`` and ``boxcox`` the metric must be positive.

    Parameters
    ----------
    transform : str
        One of :data:`TRANSFORMS`.
    frame : pandas.DataFrame, optional
        Runs holding ``metric``; when given, its finite values must be > 0
        for ``log`` and ``boxcox`` (non-finite runs are left out of the fit anyway).
    metric : str
        Response column.

    Returns
    -------
    str
        ``transform``.

    Raises
    ------
    AnalysisError
        Unknown transform, or a value <= 0 for ``log`` / ``boxcox``.
    """
    if transform not in TRANSFORMS:
        raise AnalysisError(f"transform: {transform!r} is not one of {', '.join(TRANSFORMS)}")
    if transform != "none" and frame is not None and metric in frame.columns:
        y = frame[metric].to_numpy(dtype=float)
        bad = int((np.isfinite(y) & (y <= 0.0)).sum())
        if bad:
            raise AnalysisError(f"--transform {transform}: metric {metric} has {bad} value{'s' if bad > 1 else ''} "
                                "<= 0 (the log and Box-Cox transforms need a positive response; use --transform none)")
    return transform
