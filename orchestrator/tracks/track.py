"""A recorded inverted-LBL track: the times of arrival through the single-ping fix, the EKF and the RTS smoother
(:mod:`sblsim.models.receiver.toa_tracking`), scored against a truth track, written to a folder.

Scoring: the truth (x, y, t) interpolated linearly at each estimate's emission time; per ping the 2-D error
[m]; over the pings an estimator positions, the count, mean, median, RMS, 90th and 95th percentiles, and the mean
2-D NEES (the estimator's covariance against the truth, whose own error is not in it). A reference solution
(x, y, t rows) is scored the same way on the rows it reports.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.output import staged_directory

#: The standard deviation of a time of arrival the tracker assumes [s] (Lake Hald's single-ping residuals: 0.13 ms
#: by their median absolute deviation, 0.15 ms by their standard deviation).
SIGMA_TOA = 1.5e-4
#: The estimators, in the order of the outputs.
ESTIMATORS = ("rts", "ekf", "fix")


@dataclass
class TrackOutcome:
    """Per estimator a table of its pings and the summary (:func:`track`)."""

    tracks: Any  # pandas.DataFrame
    errors: Any  # pandas.DataFrame or None
    summary: dict[str, Any]


def _usable(toa_matrix, receivers) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The TOA columns matched to the receivers (by the header's names, else by order), those without a position
    or never heard dropped: times (m, k), positions (k, dim), names (k)."""
    if toa_matrix.names is not None:
        missing = [n for n in toa_matrix.names if n not in receivers.names]
        if missing:
            raise ModelError(f"toa: the receiver {missing[0]!r} of the header is not in the receivers file")
        order = [receivers.names.index(n) for n in toa_matrix.names]
    else:
        if toa_matrix.toa.shape[1] != len(receivers.names):
            raise ModelError(f"toa: {toa_matrix.toa.shape[1]} columns and {len(receivers.names)} receivers; allowed: "
                             "one column per receiver, in the receivers file's order (or a header of their names)")
        order = list(range(len(receivers.names)))
    positions = receivers.positions[order]
    keep = np.isfinite(positions).all(axis=1) & np.isfinite(toa_matrix.toa).any(axis=0)
    if keep.sum() < positions.shape[1] + 1:
        raise ModelError(f"receivers: {int(keep.sum())} receivers with a position heard a ping; allowed: at least "
                         f"{positions.shape[1] + 1}")
    return toa_matrix.toa[:, keep], positions[keep], [receivers.names[k] for k, ok in zip(order, keep) if ok]


def score(t: np.ndarray, xy: np.ndarray, truth: np.ndarray, cov: np.ndarray | None = None) -> tuple[dict, np.ndarray]:
    """The 2-D errors [m] of estimates at times ``t`` (m,) [s], positions ``xy`` (m, 2) [m] against the truth
    (rows t, x, y) interpolated at those times, and their statistics (the estimates outside the truth's span not
    scored); ``cov`` (m, 2, 2) [m²] adds the mean NEES."""
    inside = (t >= truth[0, 0]) & (t <= truth[-1, 0])
    gx = np.interp(t, truth[:, 0], truth[:, 1])
    gy = np.interp(t, truth[:, 0], truth[:, 2])
    e = np.column_stack([xy[:, 0] - gx, xy[:, 1] - gy])
    err = np.where(inside, np.hypot(e[:, 0], e[:, 1]), np.nan)
    ok = np.isfinite(err)
    s = err[ok]
    stats = {"n_scored": int(ok.sum())}
    if ok.any():
        stats |= {"mean_m": float(s.mean()), "median_m": float(np.median(s)), "rms_m": float(np.sqrt(np.mean(s**2))),
                  "p90_m": float(np.percentile(s, 90)), "p95_m": float(np.percentile(s, 95))}
        if cov is not None:
            c = cov[ok]
            det = c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] * c[:, 1, 0]
            good = np.isfinite(det) & (det > 1e-9 * c[:, 0, 0] * c[:, 1, 1])  # a 3-receiver fix may have none
            x, y, c, det = e[ok][good, 0], e[ok][good, 1], c[good], det[good]
            nees = (c[:, 1, 1] * x**2 - (c[:, 0, 1] + c[:, 1, 0]) * x * y + c[:, 0, 0] * y**2) / det
            stats["nees"] = float(nees.mean()) if good.any() else None
    return stats, err


def track(toa_path: Path, receivers_path: Path, truth_path: Path | None = None, reference_path: Path | None = None,
          smooth: bool = True, sound_speed: float | None = None) -> TrackOutcome:
    """Read, track and score (module docstring); ``sound_speed`` None: calibrated from the pings
    (:func:`~sblsim.models.receiver.toa_tracking.calibrate_sound_speed`)."""
    import pandas as pd

    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.orchestrator.tracks.toa import read_receivers, read_toa, read_track

    start = time.perf_counter()
    matrix = read_toa(toa_path)
    receivers = read_receivers(receivers_path)
    truth = read_track(truth_path, "truth") if truth_path is not None else None
    reference = read_track(reference_path, "reference", increasing=False) if reference_path is not None else None
    toa, positions, names = _usable(matrix, receivers)
    dim = positions.shape[1]
    if sound_speed is None:
        c, sigma_c, calibration_pings = tt.calibrate_sound_speed(toa, positions, SIGMA_TOA)
        speed = {"sound_speed_m_s": c, "source": "calibrated", "sigma_m_s": sigma_c, "pings": calibration_pings}
    else:
        c = sound_speed
        speed = {"sound_speed_m_s": c, "source": "given"}
    fx, fe, fc, fused, _ = tt.fix_pings(toa, positions, c, SIGMA_TOA)
    steps = np.diff(fe)
    interval = float(np.nanmedian(steps)) if np.isfinite(steps).any() else 2.0
    settings = tt.TrackerSettings(sound_speed=c, sigma_toa=SIGMA_TOA, interval=interval)
    tracker = tt.ToaTracker(positions, settings)
    record = tracker.run(toa)
    columns = ["x", "y", "z"][:dim]
    frames = []

    def rows(estimator: str, ping: np.ndarray, t: np.ndarray, p: np.ndarray, cov: np.ndarray, heard: np.ndarray):
        frame = pd.DataFrame({"ping": ping, "time": t, **{a: p[:, k] for k, a in enumerate(columns)},
                              **{f"sigma_{a}": np.sqrt(cov[:, k, k]) for k, a in enumerate(columns)},
                              "receivers_heard": heard, "estimator": estimator})
        frames.append(frame)

    positioned = record.used.any(axis=1) & np.isfinite(record.x_filtered[:, 0])
    k = np.flatnonzero(positioned)
    if smooth:
        xs, Ps = tracker.smooth(record)
        rows("rts", k, xs[k, -2], xs[k, :dim], Ps[k][:, :dim, :dim], record.used[k].sum(axis=1))
    rows("ekf", k, record.x_filtered[k, -2], record.x_filtered[k, :dim], record.P_filtered[k][:, :dim, :dim],
         record.used[k].sum(axis=1))
    f = np.flatnonzero(np.isfinite(fe))
    rows("fix", f, fe[f], fx[f], fc[f][:, :dim, :dim], fused[f].sum(axis=1))
    tracks = pd.concat(frames, ignore_index=True)
    summary: dict[str, Any] = {
        "n_pings": int(len(toa)), "receivers": names, "dimensions": dim, "sound_speed": speed,
        "sigma_toa_s": SIGMA_TOA, "ping_interval_s": interval, "restarts": len(record.restarts),
        "estimators": {}, "truth": None if truth_path is None else str(truth_path)}
    errors = None
    parts = []
    for estimator, frame in tracks.groupby("estimator", sort=False):
        entry: dict[str, Any] = {"n_fixed": int(len(frame))}
        if truth is not None:
            if estimator == "rts":
                cov = Ps[frame["ping"].to_numpy()][:, :2, :2]
            elif estimator == "ekf":
                cov = record.P_filtered[frame["ping"].to_numpy()][:, :2, :2]
            else:
                cov = fc[frame["ping"].to_numpy()][:, :2, :2]
            stats, err = score(frame["time"].to_numpy(), frame[["x", "y"]].to_numpy(), truth[:, :3], cov)
            entry |= stats
            parts.append(pd.DataFrame({"estimator": estimator, "ping": frame["ping"].to_numpy(),
                                       "time": frame["time"].to_numpy(), "error_2d_m": err}))
        summary["estimators"][estimator] = entry
    if reference is not None:
        entry = {"n_fixed": int(len(reference)), "file": str(reference_path)}
        if truth is not None:
            stats, err = score(reference[:, 0], reference[:, 1:3], truth[:, :3])
            entry |= stats
            parts.append(pd.DataFrame({"estimator": "reference", "ping": -1, "time": reference[:, 0],
                                       "error_2d_m": err}))
        summary["estimators"]["reference"] = entry
    if parts:
        errors = pd.concat(parts, ignore_index=True)
    summary["wall_time_s"] = time.perf_counter() - start
    return TrackOutcome(tracks, errors, summary)


def figure(outcome: TrackOutcome, truth_path: Path | None):
    """The track against the truth and the 2-D error along the time (a matplotlib figure)."""
    import matplotlib.pyplot as plt

    from sblsim.orchestrator.tracks.toa import read_track

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.5))
    best = "rts" if "rts" in outcome.summary["estimators"] else "ekf"
    tr = outcome.tracks[outcome.tracks["estimator"] == best]
    if truth_path is not None:
        truth = read_track(truth_path, "truth")
        ax.plot(truth[:, 1], truth[:, 2], "-", color="0.6", lw=1, label="truth")
    ax.plot(tr["x"], tr["y"], ".", ms=2, label=best)
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title="track")
    ax.legend()
    if outcome.errors is not None:
        for estimator in ("fix", "ekf", "rts", "reference"):
            e = outcome.errors[outcome.errors["estimator"] == estimator]
            if len(e):
                bx.semilogy(e["time"], e["error_2d_m"], ".", ms=2, label=estimator)
        bx.set(xlabel="emission time [s]", ylabel="2-D error [m]", title="error against the truth")
        bx.legend()
    fig.tight_layout()
    return fig


def write(outcome: TrackOutcome, out: Path, truth_path: Path | None) -> None:
    """``track.csv``, ``summary.json``, ``errors.csv`` (with a truth) and ``track.png``, all or nothing."""
    import matplotlib.pyplot as plt

    fig = figure(outcome, truth_path)
    try:
        with staged_directory(out) as tmp:
            outcome.tracks.to_csv(tmp / "track.csv", index=False)
            if outcome.errors is not None:
                outcome.errors.to_csv(tmp / "errors.csv", index=False)
            (tmp / "summary.json").write_text(json.dumps(outcome.summary, indent=2, allow_nan=False) + "\n")
            fig.savefig(tmp / "track.png", dpi=110)
    finally:
        plt.close(fig)


__all__ = ["ESTIMATORS", "SIGMA_TOA", "TrackOutcome", "figure", "score", "track", "write"]
