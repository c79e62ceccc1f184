"""Figures of one run: trajectory versus estimate (XY and 3D), errors over time, and the errors
against the receiver's reported ±2σ and the accuracy limit.

Each plotting function draws on a given matplotlib ``ax`` (or axes) and
returns its figure; ``receiver`` is the name of the receiver that ran
(``ekf``, ``ekf-seq``, ...), used in the legends.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

_AXES = (("x", "North"), ("y", "East"), ("z", "Down"))


def _beacons(ts: pd.DataFrame) -> pd.DataFrame:
    """The mean broadcast position of each beacon heard (N, E, D) [m], one row per beacon id."""
    heard = ts[ts["packet_valid"].astype(bool)] if "packet_valid" in ts else ts.iloc[:0]
    return heard.groupby("beacon_id")[["beacon_x", "beacon_y", "beacon_z"]].mean()


def _direction(ax, east, north, count: int = 6) -> None:
    """Arrows along a path at ``count`` evenly spaced samples, showing the direction of travel."""
    east, north = np.asarray(east), np.asarray(north)
    if len(east) < 3:
        return
    for k in np.linspace(0, len(east) - 2, count + 2, dtype=int)[1:-1]:
        ax.annotate("", xy=(east[k + 1], north[k + 1]), xytext=(east[k], north[k]),
                    arrowprops={"arrowstyle": "-|>", "color": "k", "lw": 0.8, "mutation_scale": 14})


def plot_trajectory_xy(ts: pd.DataFrame, ax, receiver: str = "receiver") -> plt.Figure:
    """Truth (start, end and direction marked), estimate and instrumentation fixes in the horizontal plane
    (East right, North up), with the platform and the beacons' mean broadcast positions. Without a truth
    (no ``true_*`` columns, or all NaN: a replayed log) the estimate's start, end and direction are marked."""
    ax.plot(ts["instr_y"], ts["instr_x"], ".", ms=2, color="0.6", label="instrumentation (multilateration)")
    truth = "true_x" in ts and bool(np.isfinite(ts["true_x"].to_numpy(dtype=float)).any())
    if truth:
        ax.plot(ts["true_y"], ts["true_x"], "-", color="k", lw=1.5, label="truth")
    ax.plot(ts["est_y"], ts["est_x"], "-", color="tab:red", lw=1.0, label=f"{receiver} estimate")
    track = "true" if truth else "est"
    _direction(ax, ts[f"{track}_y"], ts[f"{track}_x"])
    ax.plot(ts[f"{track}_y"].iloc[:1], ts[f"{track}_x"].iloc[:1], "o", color="tab:green", ms=7, label="start")
    ax.plot(ts[f"{track}_y"].iloc[-1:], ts[f"{track}_x"].iloc[-1:], "s", color="k", ms=6, mfc="none", label="end")
    ax.plot([0], [0], "^", color="tab:blue", ms=9, label="platform (mooring point)")
    beacons = _beacons(ts)
    if len(beacons):
        ax.plot(beacons["beacon_y"], beacons["beacon_x"], "x", color="tab:blue", ms=6, mew=1.5,
                label="beacons (mean broadcast position)")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8)
    return ax.figure


def plot_trajectory_3d(ts: pd.DataFrame, ax, receiver: str = "receiver") -> plt.Figure:
    """Truth and estimate in 3D (depth axis pointing down). ``ax`` must be a 3D axes.

    The depth axis spans at least a quarter of the horizontal extent, so that centimetres of depth noise
    at a constant depth do not look like metres."""
    ax.plot(ts["true_y"], ts["true_x"], ts["true_z"], color="k", lw=1.5, label="truth")
    ax.plot(ts["est_y"], ts["est_x"], ts["est_z"], color="tab:red", lw=1.0, label=f"{receiver} estimate")
    ax.scatter(ts["true_y"].iloc[:1], ts["true_x"].iloc[:1], ts["true_z"].iloc[:1], color="tab:green", s=30,
               label="start")
    # an estimate is NaN before the receiver's first fix
    horizontal = max(float(np.ptp(ts[c].dropna())) if ts[c].notna().any() else 0.0
                     for c in ("true_x", "true_y", "est_x", "est_y"))
    depth = pd.concat([ts["true_z"], ts["est_z"]]).dropna()
    half = max(0.55 * float(np.ptp(depth)), 0.125 * horizontal, 0.5)
    middle = 0.5 * (float(depth.min()) + float(depth.max()))
    ax.set_zlim(middle + half, middle - half)  # depth grows downwards
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_zlabel("Depth [m]")
    ax.legend(loc="best", fontsize=8)
    return ax.figure


def plot_errors(ts: pd.DataFrame, axes, receiver: str = "receiver") -> plt.Figure:
    """e_x, e_y, e_z and e_tot over time, receiver against instrumentation; ``axes`` holds four axes."""
    for ax, name in zip(axes, ("e_x", "e_y", "e_z", "e_tot")):
        ax.plot(ts["time"], ts[f"instr_{name}"], color="0.6", lw=0.8, label="instrumentation")
        ax.plot(ts["time"], ts[name], color="tab:red", lw=1.0, label=receiver)
        ax.set_ylabel(f"{name} [m]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize=8)
    return axes[0].figure


def plot_error_bounds(ts: pd.DataFrame, axes, receiver: str = "receiver") -> plt.Figure:
    """Signed error per axis against the receiver's reported ±2σ, and e_tot against its sqrt(trace P)
    and the position PCRB; ``axes`` holds four axes.

    A consistent receiver keeps about 95 % of each axis's error inside its
    band; the PCRB is the accuracy limit (docs/model.md, "Consistency and the
    accuracy limit").
    """
    t = ts["time"]
    settled = slice(len(ts) // 20, None)  # the scale leaves out the first 5 % of the run (P0's wide start)
    for ax, (a, axis) in zip(axes, _AXES):
        sigma = 2.0 * np.sqrt(np.clip(ts[f"cov_{a}{a}"], 0.0, None))
        error = ts[f"true_{a}"] - ts[f"est_{a}"]
        ax.fill_between(t, -sigma, sigma, color="tab:blue", alpha=0.2, lw=0, label=f"{receiver} ±2σ")
        ax.plot(t, error, color="tab:red", lw=0.9, label="error (truth − estimate)")
        ax.set_ylim(*_limits(np.abs(error.iloc[settled]), sigma.iloc[settled], symmetric=True))
        ax.set_ylabel(f"{axis} [m]")
        ax.grid(True, alpha=0.3)
    ax = axes[3]
    ax.plot(t, ts["e_tot"], color="tab:red", lw=0.9, label="e_tot")
    ax.plot(t, ts["pos_std"], color="tab:blue", lw=1.0, label=f"{receiver} sqrt(trace P)")
    ax.plot(t, ts["pcrb"], color="k", lw=1.0, ls="--", label="PCRB sqrt(trace)")
    ax.set_ylim(*_limits(ts["e_tot"].iloc[settled], ts["pos_std"].iloc[settled], ts["pcrb"].iloc[settled]))
    ax.set_ylabel("e_tot [m]")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize=8)
    ax.legend(loc="upper right", fontsize=8)
    return axes[0].figure


def _limits(*series, symmetric: bool = False) -> tuple[float, float]:
    """Axis limits that show the settled values (the 99th percentile of each series, with a margin)."""
    top = max((float(np.nanpercentile(np.asarray(v, dtype=float), 99)) for v in series
               if np.isfinite(np.asarray(v, dtype=float)).any()), default=1.0)  # none: no estimate at all
    top = 1.15 * top if np.isfinite(top) and top > 0 else 1.0
    return (-top, top) if symmetric else (0.0, top)


def run_figures(ts: pd.DataFrame, title: str = "", receiver: str = "receiver") -> dict[str, plt.Figure]:
    """The figures of replicate 0 of a run: ``trajectory_xy``, ``trajectory_3d``, ``errors`` and ``error_bounds``
    (name -> matplotlib figure; the caller closes them)."""
    ts = ts[ts["replicate"] == ts["replicate"].iloc[0]]
    figures = {}
    fig, ax = plt.subplots(figsize=(6.5, 6))
    plot_trajectory_xy(ts, ax, receiver).suptitle(f"Trajectory, {title}")
    figures["trajectory_xy"] = fig
    fig = plt.figure(figsize=(7, 6))
    plot_trajectory_3d(ts, fig.add_subplot(projection="3d"), receiver).suptitle(f"Trajectory 3D, {title}")
    figures["trajectory_3d"] = fig
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 8))
    plot_errors(ts, axes, receiver).suptitle(f"Position errors, {title}")
    figures["errors"] = fig
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 8))
    plot_error_bounds(ts, axes, receiver).suptitle(f"Errors against ±2σ and the PCRB, {title}\n"
                                                   "(scales fit the run after its first 5 %)", fontsize=10)
    figures["error_bounds"] = fig
    return figures


def save_run_figures(ts: pd.DataFrame, out_dir: Path | str, title: str = "", receiver: str = "receiver") -> list[Path]:
    """Write ``trajectory_xy.png``, ``trajectory_3d.png``, ``errors.png`` and ``error_bounds.png`` of replicate 0
    (:func:`run_figures`)."""
    out_dir = Path(out_dir)
    paths = []
    for name, fig in run_figures(ts, title, receiver).items():
        paths.append(out_dir / f"{name}.png")
        fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
        plt.close(fig)
    return paths
