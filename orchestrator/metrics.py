"""Position-error metrics (docs/model.md, "Metrics").

Per step: ``e_x = |x − x̂|``, ``e_y``, ``e_z`` and
``e_tot = sqrt(e_x² + e_y² + e_z²)``; per run: the time-average of each, the
RMS of e_tot and its standard deviation (population, ddof = 0). Steps where an
estimate is not available (NaN, e.g. no instrumentation fix yet) are left out.
"""

from __future__ import annotations

import numpy as np

METRIC_NAMES = ("e_x_mean", "e_y_mean", "e_z_mean", "e_tot_mean", "e_tot_rms", "e_tot_std")


def errors(truth: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """Per-step errors.

    Parameters
    ----------
    truth, estimate : ndarray, shape (..., 3)
        Positions [m].

    Returns
    -------
    ndarray, shape (..., 4)
        ``e_x, e_y, e_z, e_tot`` [m].
    """
    e = np.abs(truth - estimate)
    return np.concatenate([e, np.sqrt(np.sum(e * e, axis=-1, keepdims=True))], axis=-1)


def summarize(err: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
    """Run metrics from per-step errors.

    Parameters
    ----------
    err : ndarray, shape (N, B, 4)
        Per-step ``e_x, e_y, e_z, e_tot`` of B runs [m].
    prefix : str
        Prefix of the metric names (``instr_`` for the instrumentation).

    Returns
    -------
    dict
        Metric name -> array of shape (B,) [m]; NaN for a run with no valid step.
    """
    # run-major, time contiguous: every run is summed in the same order whatever B is
    err = np.ascontiguousarray(np.moveaxis(np.asarray(err, dtype=float), 0, -1))  # (B, 4, N)
    valid = np.all(np.isfinite(err), axis=1)  # (B, N)
    count = valid.sum(axis=-1)
    safe = np.where(valid[:, None, :], err, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = safe.sum(axis=-1) / count[:, None]
        rms = np.sqrt((safe[:, 3] ** 2).sum(axis=-1) / count)
        var = np.where(valid, (safe[:, 3] - mean[:, 3:4]) ** 2, 0.0).sum(axis=-1) / count
    values = (mean[:, 0], mean[:, 1], mean[:, 2], mean[:, 3], rms, np.sqrt(var))
    return {prefix + name: v for name, v in zip(METRIC_NAMES, values)}
