"""A track's files and figure: ``track.csv``, ``estimates.csv``, ``summary.json``, ``track.png`` and, with a truth,
``score.json``, ``errors.csv`` and ``bound.csv``, written all or nothing.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.tracks.outcome import ESTIMATOR_NAMES, TrackOutcome


def scale_bar(ax, extent: float) -> None:
    """A scale bar in the lower right of a map in metres: a round length near a fifth of ``extent`` [m]
    (matplotlib's ``AnchoredSizeBar``)."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    if not np.isfinite(extent) or extent <= 0:
        return
    raw = extent / 5
    length = min((m * 10 ** np.floor(np.log10(raw)) for m in (1, 2, 5, 10)), key=lambda v: abs(v - raw))
    label = f"{length / 1000:g} km" if length >= 1000 else f"{length:g} m"
    ax.add_artist(AnchoredSizeBar(ax.transData, length, label, "lower right", pad=0.5, frameon=True, size_vertical=0))


def figure(outcome: TrackOutcome):
    """The track on a map over the receivers (the ok rows coloured by their 2-D σ, the flagged ones marked, the
    truth where there is one, a scale bar), and beside it the 2-D errors along the time with the track's 2σ band
    (with a truth) or the track's own σ along the time (without one): a matplotlib figure."""
    import matplotlib

    matplotlib.use("Agg")  # (drawn to a file, in a worker process too: never a display's backend)
    import matplotlib.pyplot as plt
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(14, 6.5), width_ratios=(1.4, 1))
    best, tr, truth = outcome.summary["track"], outcome.track, outcome.truth
    drms = np.hypot(tr["sigma_x"].to_numpy(float), tr["sigma_y"].to_numpy(float))
    flagged = (tr["quality"] == "flagged").to_numpy()
    x, y = tr["x"].to_numpy(float), tr["y"].to_numpy(float)
    if outcome.array is not None:
        names, positions = outcome.array
        ax.plot(positions[:, 0], positions[:, 1], "^", color="k", ms=6, label="receivers", zorder=3)
        for name, (px, py) in zip(names, positions[:, :2]):
            ax.annotate(name, (px, py), fontsize=6, xytext=(3, 3), textcoords="offset points")
    if truth is not None:
        ax.plot(truth[:, 1], truth[:, 2], "-", color="0.6", lw=1, label="truth")
    ax.plot(x, y, "-", color="0.85", lw=0.5, zorder=1)
    ok = ~flagged & np.isfinite(drms)
    points = ax.scatter(x[ok], y[ok], c=drms[ok], s=4, cmap="viridis", norm=_log_norm(drms[ok]), zorder=2,
                        label=f"{ESTIMATOR_NAMES[best]} ({ok.sum()} rows)")
    bar = fig.colorbar(points, ax=ax, label="2-D σ (DRMS) [m]", shrink=0.8)
    bar.ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    bar.ax.yaxis.set_major_formatter(ScalarFormatter())
    bar.ax.yaxis.set_minor_formatter(NullFormatter())
    bar.ax.tick_params(labelsize=7)
    if flagged.any():
        ax.plot(x[flagged], y[flagged], "x", color="tab:red", ms=3, label=f"flagged ({flagged.sum()})", zorder=2)
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=7)
    frame = outcome.summary.get("frame")
    ax.set(xlabel="x (east) [m]", ylabel="y (north) [m]", aspect="equal")
    ax.set_title("track" + (f" ({frame['name']}, {frame['crs']})" if frame else ""), fontsize=9)
    shown = [x, y] if outcome.array is None else [np.r_[x, outcome.array[1][:, 0]], np.r_[y, outcome.array[1][:, 1]]]
    spans = [float(np.ptp(v[np.isfinite(v)])) for v in shown if np.isfinite(v).any()]
    scale_bar(ax, max(spans) if spans else float("nan"))
    ax.legend(fontsize=7, loc="best")
    if outcome.errors is not None:
        for estimator in ("fix", "ekf", "rts", "robust", "reference"):
            e = outcome.errors[outcome.errors["estimator"] == estimator]
            if len(e):
                bx.semilogy(e["time"], e["error_2d_m"], ".", ms=2, label=ESTIMATOR_NAMES[estimator])
        # the track's own 2σ of the 2-D error (2 √(σx² + σy²), its covariance's DRMS doubled)
        bx.semilogy(tr["time"], 2 * drms, "-", color="k", lw=0.8, label=f"{ESTIMATOR_NAMES[best]} 2σ (2 DRMS)")
        bx.set(xlabel="emission time [s]", ylabel="2-D error [m]", title="error against the truth")
    else:
        hours = (tr["time"].to_numpy(float) - tr["time"].min()) / 3600 if len(tr) else np.array([])
        bx.semilogy(hours[ok], drms[ok], ".", ms=2, label=f"{ESTIMATOR_NAMES[best]}: ok rows")
        if flagged.any():
            bx.semilogy(hours[flagged], drms[flagged], "x", color="tab:red", ms=3, label="flagged rows")
        start = tr["time_utc"].iloc[0] if "time_utc" in tr and len(tr) else ""
        bx.set(xlabel="time from the first row [h]" + (f" ({start})" if start else ""), ylabel="2-D σ (DRMS) [m]",
               title="the track's own uncertainty (no truth given)")
    bx.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _log_norm(values: np.ndarray):
    """A logarithmic colour scale over positive ``values`` (linear where there are none)."""
    from matplotlib.colors import LogNorm, Normalize

    positive = values[values > 0]
    if len(positive) < 2 or positive.min() == positive.max():
        return Normalize()
    return LogNorm(positive.min(), positive.max())


def write(outcome: TrackOutcome, out: Path) -> None:
    """``track.csv``, ``estimates.csv``, ``summary.json``, ``track.png``, with a truth ``score.json``,
    ``errors.csv`` and ``bound.csv``, and where a stated interval set rows aside ``set_aside.csv``, all or
    nothing."""
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
            if outcome.set_aside is not None and len(outcome.set_aside):
                outcome.set_aside.to_csv(tmp / "set_aside.csv", index=False)
            if outcome.score is not None:
                (tmp / "score.json").write_text(json.dumps(outcome.score, indent=2, allow_nan=False) + "\n")
            (tmp / "summary.json").write_text(json.dumps(outcome.summary, indent=2, allow_nan=False) + "\n")
            fig.savefig(tmp / "track.png", dpi=110)
    finally:
        plt.close(fig)


def written_light(outcome: TrackOutcome, out: Path) -> TrackOutcome:
    """``outcome``'s files written into ``out`` (:func:`write`), and what is kept of it in memory: its track, summary,
    score, truth and array; its ``estimates``, ``errors``, ``bound`` and ``set_aside`` None (read from its files:
    a study of a season keeps every tag's track, not every estimator's rows)."""
    write(outcome, out)
    return replace(outcome, estimates=None, errors=None, bound=None, set_aside=None)


def written_main(outcome: TrackOutcome | str, out: Path) -> TrackOutcome | str:
    """``outcome``'s files written into ``out`` (:func:`write`), and what is sent back of it: :func:`written_light`'s,
    its ``estimates`` the rows of its track's own estimator alone (``summary["track"]``: its ``tags.csv`` row's
    counts). Run where the tag was tracked (a worker sharing the study's filesystem), so that a season's tag never
    travels whole. A refusal's line is returned as it is."""
    if isinstance(outcome, str):
        return outcome
    rows = outcome.estimates
    return replace(written_light(outcome, out), estimates=rows[rows["estimator"] == outcome.summary["track"]])


__all__ = ["figure", "scale_bar", "write", "written_light", "written_main"]
