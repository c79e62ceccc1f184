"""A tag's rows flagged after its estimators have made them: a quality reason added to a row's (:func:`with_reason`),
the rows each reason holds for (:func:`reason_counts`), an estimator's rows flagged with a reason (:func:`flag_rows`),
and the rows whose pings lie where the receivers' clocks are interpolated across a stretch of too few pings to follow
them (:func:`flag_interpolated`: a study's clocks fitted from its moving tags' pings,
:mod:`~sblsim.orchestrator.telemetry.clock_stretches`), whose error is in no row's σ.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

#: The quality reason of a row whose ping lies in a stretch across which the clocks are interpolated.
INTERPOLATED_REASON = "clocks_interpolated"


def with_reason(reason: pd.Series, name: str) -> pd.Series:
    """A quality reason added to each row's (``;`` between: :func:`sblsim.models.tracking.quality.reasons`)."""
    return reason.where(reason == "", reason + ";") + name


def reason_counts(reason: pd.Series) -> dict[str, int]:
    """The rows each quality reason holds for, most first (a row of several counted under each)."""
    named = reason[reason != ""].str.split(";").explode()
    return {str(k): int(v) for k, v in named.value_counts().items()}


def flag_rows(frame: pd.DataFrame, rows, reason: str) -> int:
    """An estimator's ``rows`` (a boolean mask or the frame's labels) of ``frame`` flagged, ``reason`` added to each
    one's (:func:`with_reason`), in place; returns the frame's flagged rows counted again."""
    frame.loc[rows, "quality"] = "flagged"
    frame.loc[rows, "quality_reason"] = with_reason(frame["quality_reason"][rows], reason)
    return int((frame["quality"] == "flagged").sum())


def flag_interpolated(frames: dict[str, Any], flagged: dict[str, int], stretches: Sequence[tuple[float, float]],
                      origin: float | None) -> int:
    """Every estimator's rows (``frames``: each a frame with ``time`` [s from ``origin``, s since 1970 UTC]) whose
    time lies strictly inside one of ``stretches`` ((start, end) [s since 1970 UTC]: the clocks linear across it,
    bending more than the timing noise where the pings tie them) flagged :data:`INTERPOLATED_REASON`, each
    estimator's count in ``flagged`` made again; returns the rows of the first estimator so flagged. Nothing where
    none is given or the rows have no UTC time (``origin`` None)."""
    if not len(stretches) or origin is None:
        return 0
    bounds = np.asarray(stretches, float)
    first = None
    for estimator, frame in frames.items():
        t = frame["time"].to_numpy(float) + origin
        inside = ((t[:, None] > bounds[:, 0]) & (t[:, None] < bounds[:, 1])).any(axis=1)
        if inside.any():
            flagged[estimator] = flag_rows(frame, inside, INTERPOLATED_REASON)
        first = int(inside.sum()) if first is None else first
    return first or 0


__all__ = ["INTERPOLATED_REASON", "flag_interpolated", "flag_rows", "reason_counts", "with_reason"]
