"""A track's files and figure: ``track.csv``, ``estimates.csv``, ``summary.json``, ``track.png`` and, with a truth,
``score.json``, ``errors.csv`` and ``bound.csv``, written all or nothing.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.tracks.track import ESTIMATOR_NAMES, TrackOutcome


def figure(outcome: TrackOutcome):
    """The track against the truth, and the 2-D errors along the time with the track's 2σ band (a matplotlib
    figure)."""
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.5))
    best, tr, truth = outcome.summary["track"], outcome.track, outcome.truth
    if truth is not None:
        ax.plot(truth[:, 1], truth[:, 2], "-", color="0.6", lw=1, label="truth")
    ax.plot(tr["x"], tr["y"], ".", ms=2, label=ESTIMATOR_NAMES[best])
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title="track")
    ax.legend()
    if outcome.errors is not None:
        for estimator in ("fix", "ekf", "rts", "robust", "reference"):
            e = outcome.errors[outcome.errors["estimator"] == estimator]
            if len(e):
                bx.semilogy(e["time"], e["error_2d_m"], ".", ms=2, label=ESTIMATOR_NAMES[estimator])
        # the track's own 2σ of the 2-D error (2 √(σx² + σy²), its covariance's DRMS doubled)
        bx.semilogy(tr["time"], 2 * np.hypot(tr["sigma_x"], tr["sigma_y"]), "-", color="k", lw=0.8,
                    label=f"{ESTIMATOR_NAMES[best]} 2σ (2 DRMS)")
        bx.set(xlabel="emission time [s]", ylabel="2-D error [m]", title="error against the truth")
        bx.legend()
    fig.tight_layout()
    return fig


def write(outcome: TrackOutcome, out: Path) -> None:
    """``track.csv``, ``estimates.csv``, ``summary.json``, ``track.png`` and with a truth ``score.json``,
    ``errors.csv`` and ``bound.csv``, all or nothing."""
    import matplotlib.pyplot as plt

    fig = figure(outcome)
    try:
        with staged_directory(out) as tmp:
            outcome.track.to_csv(tmp / "track.csv", index=False)
            outcome.estimates.to_csv(tmp / "estimates.csv", index=False)
            if outcome.errors is not None:
                outcome.errors.to_csv(tmp / "errors.csv", index=False)
            if outcome.bound is not None:
                outcome.bound.to_csv(tmp / "bound.csv", index=False)
            if outcome.score is not None:
                (tmp / "score.json").write_text(json.dumps(outcome.score, indent=2, allow_nan=False) + "\n")
            (tmp / "summary.json").write_text(json.dumps(outcome.summary, indent=2, allow_nan=False) + "\n")
            fig.savefig(tmp / "track.png", dpi=110)
    finally:
        plt.close(fig)


__all__ = ["figure", "write"]
