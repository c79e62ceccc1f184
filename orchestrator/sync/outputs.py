"""``sblsim sync``'s files and figures: ``sync.json``, ``offsets.csv``, ``residuals.csv``, ``sync_tags.csv`` (and
``positions.csv`` with the positions refined) and
``offsets.png``, ``residuals.png``, ``coverage.png``, written all or nothing."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.sync.run import SyncOutcome


def figures(outcome: SyncOutcome) -> dict:
    """The figures (matplotlib): ``offsets`` (each receiver's offset against time, its 2σ band), ``residuals``
    (the kept residuals' distribution per receiver) and ``coverage`` (the array: which receiver hears which sync
    tag, the lines' width by the number of arrivals)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    o, r, rec = outcome.offsets, outcome.residuals, outcome.receivers
    fig1, ax = plt.subplots(figsize=(11, 6.5))
    if "segment" in o:  # a receiver whose clock broke: each segment over the bins it holds for, named by its number
        o = o[(o["end"] >= o["clock_from"].fillna(-np.inf)) & (o["start"] <= o["clock_to"].fillna(np.inf))]
        o = o.assign(receiver=np.where(o.groupby("receiver")["segment"].transform("max") > 1,
                                       o["receiver"].astype(str) + " (" + o["segment"].astype(str) + ")",
                                       o["receiver"].astype(str)))
    groups = list(o.groupby("receiver", sort=False))
    colours = plt.get_cmap("tab20").colors
    for k, (name, g) in enumerate(groups):
        t = np.r_[g["start"].to_numpy(), g["end"].to_numpy()[-1:]]
        y = np.r_[g["offset_start_s"].to_numpy(), g["offset_end_s"].to_numpy()[-1:]]
        s = np.r_[g["offset_start_sigma_s"].to_numpy(), g["offset_end_sigma_s"].to_numpy()[-1:]]
        hours = (t - o["start"].min()) / 3600
        # the offset less its own straight line (least squares over the knots): the drift's wander and its band
        slope, intercept = np.polyfit(hours, y, 1) if len(hours) > 1 else (0.0, float(y[0]))
        rest = (y - (slope * hours + intercept)) * 1e3
        colour, style = colours[k % len(colours)], ("-", "--", ":", "-.")[(k // len(colours)) % 4]
        ax.plot(hours, rest, style, color=colour, lw=1.2,
                label=f"{name}: {intercept:+.3f} s, {slope / 3600 * 1e6:+.2f} ppm")
        ax.fill_between(hours, rest - 2e3 * s, rest + 2e3 * s, color=colour, alpha=0.15)
    ax.axhline(0, color="k", lw=0.5)
    ax.set(xlabel="time from the first bin [h]", ylabel="offset less its linear trend [ms]",
           title=f"clock offsets against the reference receiver {outcome.summary['reference_receiver']}, each less its "
                 "linear trend (legend: the trend's offset at the first bin and drift), 2σ bands")
    ax.title.set_fontsize(9)
    ax.legend(fontsize=6, ncol=4, loc="upper left", bbox_to_anchor=(1.01, 1.0) if len(groups) > 24 else None)
    fig1.tight_layout()
    fig2, bx = plt.subplots(figsize=(10, 5))
    drawn, pairs = _kept_by_receiver(r)
    names = [n for n in rec["receiver"] if n in drawn]
    bx.boxplot([drawn[n] for n in names], showfliers=False)
    bx.set_xticks(range(1, len(names) + 1), names, rotation=90, fontsize=7)
    bx.axhline(0, color="k", lw=0.5)
    bx.set(ylabel="residual [m]", title="sync residuals per receiver (kept arrivals; whiskers 1.5 IQR)")
    fig2.tight_layout()
    fig3, cx = plt.subplots(figsize=(7, 7))
    xy = rec[["x", "y"]].to_numpy()
    home = {t: k for k, t in enumerate(rec["sync_tag"]) if t}
    index = {n: k for k, n in enumerate(rec["receiver"])}
    top = max(pairs.values(), default=1)
    for (tag, name), n in sorted(pairs.items()):  # drawn in the names' order
        a, b = xy[home[tag]], xy[index[name]]
        cx.plot([a[0], b[0]], [a[1], b[1]], "-", color="tab:blue", lw=0.3 + 2.5 * n / top, alpha=0.5)
    synced = rec["synchronised"].to_numpy(bool)
    cx.plot(xy[synced, 0], xy[synced, 1], "o", color="k", label="synchronised")
    cx.plot(xy[~synced, 0], xy[~synced, 1], "x", color="tab:red", label="not synchronised")
    if outcome.positions is not None:  # the table's positions, a line to the refined ones
        q = outcome.positions
        for a, b, c, d in q[["table_x_m", "table_y_m", "x_m", "y_m"]].to_numpy():
            cx.plot([a, c], [b, d], "-", color="tab:orange", lw=1)
        cx.plot(q["table_x_m"], q["table_y_m"], ".", color="tab:orange", label="the table's position (refined: black)")
    for name, (x, y) in zip(rec["receiver"], xy):
        cx.annotate(name, (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
    cx.ticklabel_format(useOffset=False, style="plain")
    cx.set(aspect="equal", xlabel="x [m]", ylabel="y [m]", title="which receiver hears which sync tag")
    cx.legend(fontsize=8)
    fig3.tight_layout()
    return {"offsets": fig1, "residuals": fig2, "coverage": fig3}


def _kept_by_receiver(residuals) -> tuple[dict[str, np.ndarray], dict[tuple[str, str], int]]:
    """The kept arrivals' residuals [m] by receiver (each in the rows' order) and their count by sync tag and
    receiver, from the receivers' and tags' codes (a season's rows never copied into a frame of the kept ones, nor
    grouped by their names: at 13 weeks the figures' tables were 0.2 GiB)."""
    kept = residuals["kept"].to_numpy(bool)
    at, receivers = pd.factorize(residuals["receiver"])
    of, tags = pd.factorize(residuals["tag"])
    values = residuals["residual_m"].to_numpy(float)
    drawn, pairs = {}, {}
    for k, name in enumerate(receivers):
        mine = kept & (at == k)
        if mine.any():
            drawn[str(name)] = values[mine]
            heard = np.bincount(of[mine], minlength=len(tags))
            pairs |= {(tags[j], name): int(n) for j, n in enumerate(heard) if n}
    return drawn, pairs


def plain(value: Any) -> Any:
    """A summary as JSON takes it: NaN and infinities None, numpy scalars Python's, paths texts."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def write(outcome: SyncOutcome, out: Path) -> None:
    """The files and figures (the module docstring), all or nothing."""
    import matplotlib.pyplot as plt

    made = figures(outcome)
    try:
        with staged_directory(out) as tmp:
            (tmp / "sync.json").write_text(json.dumps(plain(outcome.summary), indent=2, allow_nan=False) + "\n")
            outcome.offsets.to_csv(tmp / "offsets.csv", index=False)
            outcome.residuals.to_csv(tmp / "residuals.csv", index=False)
            outcome.sync_tags.to_csv(tmp / "sync_tags.csv", index=False)
            if outcome.positions is not None:
                outcome.positions.to_csv(tmp / "positions.csv", index=False)
            for name, fig in made.items():
                fig.savefig(tmp / f"{name}.png", dpi=110)
    finally:
        for fig in made.values():
            plt.close(fig)


__all__ = ["figures", "plain", "write"]
