"""The detections each receiver kept per day (``detections_daily.csv``): what a study's report draws so that a
receiver that stopped logging, or logged only part of its deployment, shows (:func:`daily_counts`,
:func:`write_daily`).

A row per deployment used and UTC day on which it kept a detection: ``receiver`` (the deployment, as
``receivers.csv`` names it), ``day`` (``YYYY-MM-DD``, the detection's logged time's day in UTC: on the receiver's own
clock, seconds from the reference receiver's at most) and ``detections`` (the kept detections, those inside a
deployment: every tag's, the sync tags' too). A day a receiver kept none has no row.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

#: The file's name in a study's folder and its columns.
DAILY_FILE = "detections_daily.csv"
DAILY_COLUMNS = ("receiver", "day", "detections")
#: A day [s].
DAY_S = 86400.0


def daily_counts(frame: pd.DataFrame) -> pd.DataFrame:
    """The kept detections per deployment and UTC day.

    Parameters
    ----------
    frame : pandas.DataFrame
        The detections kept (``receiver``: the deployment's name; ``time`` [s since 1970 UTC, the receiver's clock]).

    Returns
    -------
    pandas.DataFrame
        :data:`DAILY_COLUMNS`: a row per deployment and day with a detection, by deployment and day.
    """
    if not len(frame):
        return pd.DataFrame(columns=list(DAILY_COLUMNS))
    day = np.floor(frame["time"].to_numpy(float) / DAY_S).astype(np.int64)
    counts = pd.DataFrame({"receiver": frame["receiver"].astype(str).to_numpy(), "day": day}) \
        .groupby(["receiver", "day"], sort=True).size().rename("detections").reset_index()
    counts["day"] = pd.to_datetime(counts["day"].to_numpy() * np.int64(DAY_S), unit="s", utc=True) \
        .strftime("%Y-%m-%d")
    return counts[list(DAILY_COLUMNS)]


def write_daily(counts: pd.DataFrame | None, folder: Path) -> None:
    """``detections_daily.csv`` in ``folder`` (nothing where ``counts`` is None: a study run without them)."""
    if counts is not None:
        counts.to_csv(Path(folder) / DAILY_FILE, index=False)


__all__ = ["DAILY_COLUMNS", "DAILY_FILE", "DAY_S", "daily_counts", "write_daily"]
