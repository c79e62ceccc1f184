"""Each tracked tag's figure in a report, from its rows of ``tracks.csv``: its track on the receivers, the rows
coloured by their 2-D σ and the flagged ones marked, and beside it the σ, the receivers heard and (where known)
the depth along the time (:func:`tag_figure`); its numbers (:func:`tag_rows`, :func:`flag_counts`) are those the
tests check against the files.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.telemetry.report.figures_study import WIDTH, used_receivers
from sblsim.orchestrator.telemetry.report.folder import StudyFolder
from sblsim.orchestrator.telemetry.report.images import Image, figure_image, new_figure
from sblsim.orchestrator.tracks.outputs import scale_bar

#: A tag's figure's height [in], and the share of its rows (each end) left out of the map's extent.
HEIGHT = 4.2
CLIP = 0.01
#: What a flagged row without a reason is called.
NO_REASON = "(no reason given)"


def _positioned(tracks: pd.DataFrame, tag: str) -> pd.DataFrame:
    """A tag's rows of ``tracks.csv`` that hold a position (a row set aside as no ping of its schedule holds
    none: it is counted in ``tags.csv``'s ``set_aside``, not among the rows positioned or flagged)."""
    mine = tracks[(tracks["tag"] == tag).to_numpy(bool)]  # (a category: its codes compared, no text made)
    placed = np.isfinite(mine[["x", "y", "epoch_s"]].to_numpy(float)).all(axis=1)
    return mine[placed]


def tag_rows(study: StudyFolder, tag: str) -> pd.DataFrame:
    """A tag's rows of ``tracks.csv`` that hold a position, by time, with ``sigma_m`` (the 2-D σ,
    ``hypot(sigma_x, sigma_y)`` [m]), ``flagged`` and ``hours`` (from its first row)."""
    rows = _positioned(study.tracks, tag).sort_values("epoch_s", kind="stable")
    epoch = rows["epoch_s"].to_numpy(float)
    return rows.assign(sigma_m=np.hypot(rows["sigma_x"].to_numpy(float), rows["sigma_y"].to_numpy(float)),
                       flagged=(rows["quality"].astype(str) == "flagged").to_numpy(),
                       hours=(epoch - (epoch[0] if len(epoch) else 0.0)) / 3600.0).reset_index(drop=True)


def flag_counts(study: StudyFolder, tag: str) -> dict[str, int]:
    """A tag's flagged rows of ``tracks.csv`` (those positioned, as ``tags.csv``'s ``flagged`` counts them) by
    reason (``quality_reason``: a row with several, separated by ``;``, counted under each), the most first."""
    rows = _positioned(study.tracks, tag)
    rows = rows[rows["quality"] == "flagged"]
    if "quality_reason" not in rows:
        return {NO_REASON: len(rows)} if len(rows) else {}
    reasons = rows["quality_reason"].astype(str).str.split(";").explode().str.strip().replace("", NO_REASON)
    return {str(k): int(v) for k, v in reasons.value_counts().items()}


def _depths(study: StudyFolder, tag: str, rows: pd.DataFrame) -> list[tuple[np.ndarray, np.ndarray, str]]:
    """The depths known along the time: the track's (``-z`` [m], in 3-D) and the tag's sensor's (``pings.csv``'s
    ``depth_m``); each as (hours, depth [m], label)."""
    out = []
    if "z" in rows and np.isfinite(rows["z"].to_numpy(float)).any():
        out.append((rows["hours"].to_numpy(), -rows["z"].to_numpy(float), "track (−z)"))
    pings = study.tag_pings.get(tag)
    if pings is not None and "time" in pings and len(rows):
        t0 = float(rows["epoch_s"].iloc[0])  # the first row positioned
        out.append(((pings["time"].to_numpy(float) - t0) / 3600.0, pings["depth_m"].to_numpy(float), "sensor"))
    return out


def _log_axis(axis) -> None:
    """A logarithmic axis read as plain numbers: ticks at 1, 2 and 5 of each decade, no minor ticks."""
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullLocator

    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_locator(NullLocator())


def _map(ax, bar, study: StudyFolder, rows: pd.DataFrame) -> None:
    """The track over the receivers used: rows not flagged coloured by σ (log, its scale in ``bar``), flagged ones
    red crosses."""
    from matplotlib.colors import LogNorm

    receivers = used_receivers(study)
    rx, ry = receivers["x_m"].to_numpy(float), receivers["y_m"].to_numpy(float)
    x, y = rows["x"].to_numpy(float), rows["y"].to_numpy(float)
    finite = np.isfinite(x) & np.isfinite(y)
    both = (np.r_[x[finite], rx[np.isfinite(rx)]], np.r_[y[finite], ry[np.isfinite(ry)]])
    origin = tuple(float(np.floor(np.min(v) / 1000.0) * 1000.0) if len(v) else 0.0 for v in both)
    ax.plot(rx - origin[0], ry - origin[1], "^", color="0.35", ms=4, zorder=1, label="receivers used")
    ok = finite & ~rows["flagged"].to_numpy()
    sigma = rows["sigma_m"].to_numpy(float)
    ax.plot(x[ok] - origin[0], y[ok] - origin[1], "-", color="0.7", lw=0.4, zorder=2)
    positive = sigma[ok][np.isfinite(sigma[ok]) & (sigma[ok] > 0)]
    if len(positive):
        low, high = float(positive.min()), float(max(positive.max(), positive.min() * 1.01))
        dots = ax.scatter(x[ok] - origin[0], y[ok] - origin[1], c=np.clip(sigma[ok], low, high), s=5,
                          cmap="viridis", norm=LogNorm(low, high), zorder=3, linewidths=0)
        ax.figure.colorbar(dots, cax=bar)
        bar.set_ylabel("σ [m]", fontsize=7)
        _log_axis(bar.yaxis)
        bar.tick_params(labelsize=6)
    else:
        bar.axis("off")
    bad = finite & rows["flagged"].to_numpy()
    if bad.any():
        ax.plot(x[bad] - origin[0], y[bad] - origin[1], "x", color="C3", ms=3.5, mew=0.8, zorder=4,
                label=f"flagged ({int(bad.sum()):,})")
    if finite.any():  # the track's extent (its outermost rows left out), the receivers near it with it
        lo = np.quantile(np.c_[x[finite], y[finite]], CLIP, axis=0)
        hi = np.quantile(np.c_[x[finite], y[finite]], 1 - CLIP, axis=0)
        pad = 0.12 * max(hi[0] - lo[0], hi[1] - lo[1], 20.0)
        ax.set_xlim(lo[0] - pad - origin[0], hi[0] + pad - origin[0])
        ax.set_ylim(lo[1] - pad - origin[1], hi[1] + pad - origin[1])
        scale_bar(ax, max(hi[0] - lo[0], hi[1] - lo[1]) + 2 * pad)
    ax.set_aspect("equal", adjustable="box", anchor="E")
    ax.set_xlabel(f"x [m] east of {origin[0]:,.0f}", fontsize=7)
    ax.set_ylabel(f"y [m] north of {origin[1]:,.0f}", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.legend(fontsize=6, loc="upper left")


def tag_figure(study: StudyFolder, tag: str) -> Image | None:
    """A tracked tag's figure (the module docstring), None where it has no row."""
    from matplotlib.ticker import MaxNLocator

    rows = tag_rows(study, tag)
    if not len(rows):
        return None
    depths = _depths(study, tag, rows)
    fig = new_figure(WIDTH, HEIGHT)
    _map(fig.add_axes((0.045, 0.11, 0.32, 0.82)), fig.add_axes((0.372, 0.11, 0.01, 0.82)), study, rows)
    hours, flagged, sigma = rows["hours"].to_numpy(), rows["flagged"].to_numpy(), rows["sigma_m"].to_numpy(float)
    panels = 2 + bool(depths)
    height = 0.82 / panels
    ax, *others = [fig.add_axes((0.45, 0.11 + (panels - 1 - k) * height, 0.54, height - 0.025))
                   for k in range(panels)]
    ax.plot(hours[~flagged], sigma[~flagged], ".", ms=2, color="C0", label="σ")
    ax.plot(hours[flagged], sigma[flagged], "x", ms=3, color="C3", mew=0.7, label="σ (flagged)")
    if np.nanmin(sigma, initial=np.inf) > 0:
        ax.set_yscale("log")
        _log_axis(ax.yaxis)
    ax.set_ylabel("σ [m]", fontsize=7)
    ax.legend(fontsize=6, loc="upper right", ncols=2)
    heard = rows["receivers_heard"].to_numpy(float) if "receivers_heard" in rows else np.full(len(rows), np.nan)
    others[0].plot(hours, heard, ".", ms=2, color="0.3")
    others[0].set_ylabel("receivers\nheard", fontsize=7)
    others[0].yaxis.set_major_locator(MaxNLocator(4, integer=True))
    if depths:
        for (t, depth, label), colour in zip(depths, ("C2", "C1")):
            others[1].plot(t, depth, ".", ms=2, color=colour, label=label)
        others[1].invert_yaxis()
        others[1].set_ylabel("depth [m]", fontsize=7)
        others[1].legend(fontsize=6, loc="lower right")
    axes = [ax, *others]
    for a in axes:
        a.set_xlim(0, max(float(hours[-1]), 1e-3) * 1.01)
        a.xaxis.set_major_locator(MaxNLocator(8))
        a.tick_params(labelsize=6, labelbottom=a is axes[-1])
        a.grid(alpha=0.3, lw=0.5)
    axes[-1].set_xlabel(f"hours from {iso_utc(rows['epoch_s'].iloc[:1])[0][:16]}Z", fontsize=7)
    fig.suptitle(f"{tag}: {len(rows):,} rows, {int(flagged.sum()):,} flagged", fontsize=8, x=0.01, ha="left")
    return figure_image(fig, f"tag {tag}'s track coloured by its σ and its σ, receivers heard"
                        + (" and depth" if depths else "") + " along the time")


__all__ = ["NO_REASON", "flag_counts", "tag_figure", "tag_rows"]
