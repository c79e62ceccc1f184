"""Figures of one run: trajectory versus estimate (XY and 3D) and errors over time.

Each plotting function draws on a given matplotlib ``ax`` and returns its figure.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402


def plot_trajectory_xy(ts: pd.DataFrame, ax) -> plt.Figure:
    """Truth, EKF estimate and instrumentation fixes in the horizontal plane (East right, North up)."""
    ax.plot(ts["instr_y"], ts["instr_x"], ".", ms=2, color="0.6", label="instrumentation (multilateration)")
    ax.plot(ts["true_y"], ts["true_x"], "-", color="k", lw=1.5, label="truth")
    ax.plot(ts["est_y"], ts["est_x"], "-", color="tab:red", lw=1.0, label="EKF estimate")
    ax.plot([0], [0], "^", color="tab:blue", ms=8, label="SBL platform")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8)
    return ax.figure


def plot_trajectory_3d(ts: pd.DataFrame, ax) -> plt.Figure:
    """Truth and EKF estimate in 3D (depth axis pointing down). ``ax`` must be a 3D axes."""
    ax.plot(ts["true_y"], ts["true_x"], ts["true_z"], color="k", lw=1.5, label="truth")
    ax.plot(ts["est_y"], ts["est_x"], ts["est_z"], color="tab:red", lw=1.0, label="EKF estimate")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_zlabel("Depth [m]")
    ax.invert_zaxis()
    ax.legend(loc="best", fontsize=8)
    return ax.figure


def plot_errors(ts: pd.DataFrame, axes) -> plt.Figure:
    """e_x, e_y, e_z and e_tot over time, EKF against instrumentation; ``axes`` holds four axes."""
    for ax, name in zip(axes, ("e_x", "e_y", "e_z", "e_tot")):
        ax.plot(ts["time"], ts[f"instr_{name}"], color="0.6", lw=0.8, label="instrumentation")
        ax.plot(ts["time"], ts[name], color="tab:red", lw=1.0, label="EKF")
        ax.set_ylabel(f"{name} [m]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize=8)
    return axes[0].figure


def save_run_figures(ts: pd.DataFrame, out_dir: Path | str, title: str = "") -> list[Path]:
    """Write ``trajectory_xy.png``, ``trajectory_3d.png`` and ``errors.png`` of replicate 0."""
    out_dir = Path(out_dir)
    ts = ts[ts["replicate"] == ts["replicate"].iloc[0]]
    paths = []
    fig, ax = plt.subplots(figsize=(6.5, 6))
    plot_trajectory_xy(ts, ax).suptitle(f"Trajectory, {title}")
    paths.append(out_dir / "trajectory_xy.png")
    fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)
    fig = plt.figure(figsize=(7, 6))
    plot_trajectory_3d(ts, fig.add_subplot(projection="3d")).suptitle(f"Trajectory 3D, {title}")
    paths.append(out_dir / "trajectory_3d.png")
    fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 8))
    plot_errors(ts, axes).suptitle(f"Position errors, {title}")
    paths.append(out_dir / "errors.png")
    fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)
    return paths
