"""The outcome of a recorded track (:func:`~sblsim.orchestrator.tracks.track.track`): its tables and summary
(:class:`TrackOutcome`), the estimators in the order of the outputs and their names in words, and the keys of
``score.json``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: The estimators, in the order of the outputs, and their names in words (the console, the figure).
ESTIMATOR_NAMES = {"stationary": "stationary fix", "robust": "robust smoother", "rts": "RTS smoother",
                   "ekf": "EKF (causal)", "ekf-seq": "sequential EKF (causal)", "ukf": "UKF (causal)",
                   "fix": "single-ping fix", "reference": "reference"}


ESTIMATORS = ("stationary", "robust", "rts", "ekf", "ekf-seq", "ukf", "fix")


#: The keys of ``score.json`` for the track (the issue's names), before the further ones.
SCORE_KEYS = ("n_pings", "n_fixed", "mean_m", "median_m", "rms_m", "p90_m", "p95_m", "nees", "lag_s")


@dataclass
class TrackOutcome:
    """The outcome of :func:`~sblsim.orchestrator.tracks.track.track`: ``track`` (the track's rows, ``track.csv``),
    ``estimates`` (every estimator's rows, ``estimates.csv``), ``errors`` (``errors.csv``, None without a truth),
    ``score`` (``score.json``, None without a truth), ``summary`` (how the run went, ``summary.json``), ``bound``
    (``bound.csv``, None without a truth), ``truth`` (the truth track as read, rows ``t, x, y[, z]``, for the
    figure; None without one), ``array`` (the receivers used: their names and positions (k, dim) [m], for the
    figure) and ``set_aside`` (the rows the stated interval sets aside as no pings, ``set_aside.csv``; None where no
    interval is stated)."""

    track: Any  # pandas.DataFrame
    estimates: Any  # pandas.DataFrame
    errors: Any  # pandas.DataFrame or None
    score: dict[str, Any] | None
    summary: dict[str, Any]
    bound: Any = None  # pandas.DataFrame or None (bound.csv)
    truth: np.ndarray | None = None
    array: tuple[list[str], np.ndarray] | None = None
    set_aside: Any = None  # pandas.DataFrame or None (set_aside.csv)



__all__ = ["ESTIMATORS", "ESTIMATOR_NAMES", "SCORE_KEYS", "TrackOutcome"]
