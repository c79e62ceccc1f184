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


def plot_trajectory_xy(ts: pd.DataFrame, ax, receiver: str = "receiver") -> plt.Figure:
    """Truth, estimate and instrumentation fixes in the horizontal plane (East right, North up)."""
    ax.plot(ts["instr_y"], ts["instr_x"], ".", ms=2, color="0.6", label="instrumentation (multilateration)")
    ax.plot(ts["true_y"], ts["true_x"], "-", color="k", lw=1.5, label="truth")
    ax.plot(ts["est_y"], ts["est_x"], "-", color="tab:red", lw=1.0, label=f"{receiver} estimate")
    ax.plot([0], [0], "^", color="tab:blue", ms=8, label="SBL platform")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8)
    return ax.figure


def plot_trajectory_3d(ts: pd.DataFrame, ax, receiver: str = "receiver") -> plt.Figure:
    """Truth and estimate in 3D (depth axis pointing down). ``ax`` must be a 3D axes."""
    ax.plot(ts["true_y"], ts["true_x"], ts["true_z"], color="k", lw=1.5, label="truth")
    ax.plot(ts["est_y"], ts["est_x"], ts["est_z"], color="tab:red", lw=1.0, label=f"{receiver} estimate")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_zlabel("Depth [m]")
    ax.invert_zaxis()
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
    for ax, (a, axis) in zip(axes, _AXES):
        sigma = 2.0 * np.sqrt(np.clip(ts[f"cov_{a}{a}"], 0.0, None))
        ax.fill_between(t, -sigma, sigma, color="tab:blue", alpha=0.2, lw=0, label=f"{receiver} ±2σ")
        ax.plot(t, ts[f"true_{a}"] - ts[f"est_{a}"], color="tab:red", lw=0.9, label="error (truth − estimate)")
        ax.set_ylabel(f"{axis} [m]")
        ax.grid(True, alpha=0.3)
    ax = axes[3]
    ax.plot(t, ts["e_tot"], color="tab:red", lw=0.9, label="e_tot")
    ax.plot(t, ts["pos_std"], color="tab:blue", lw=1.0, label=f"{receiver} sqrt(trace P)")
    ax.plot(t, ts["pcrb"], color="k", lw=1.0, ls="--", label="PCRB sqrt(trace)")
    ax.set_ylabel("e_tot [m]")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("time [s]")
    axes[0].legend(loc="upper right", fontsize=8)
    ax.legend(loc="upper right", fontsize=8)
    return axes[0].figure


def save_run_figures(ts: pd.DataFrame, out_dir: Path | str, title: str = "", receiver: str = "receiver") -> list[Path]:
    """Write ``trajectory_xy.png``, ``trajectory_3d.png``, ``errors.png`` and ``error_bounds.png`` of replicate 0."""
    out_dir = Path(out_dir)
    ts = ts[ts["replicate"] == ts["replicate"].iloc[0]]
    paths = []

    def save(fig, name):
        paths.append(out_dir / name)
        fig.savefig(paths[-1], dpi=120, bbox_inches="tight")
        plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.5, 6))
    plot_trajectory_xy(ts, ax, receiver).suptitle(f"Trajectory, {title}")
    save(fig, "trajectory_xy.png")
    fig = plt.figure(figsize=(7, 6))
    plot_trajectory_3d(ts, fig.add_subplot(projection="3d"), receiver).suptitle(f"Trajectory 3D, {title}")
    save(fig, "trajectory_3d.png")
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 8))
    plot_errors(ts, axes, receiver).suptitle(f"Position errors, {title}")
    save(fig, "errors.png")
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 8))
    plot_error_bounds(ts, axes, receiver).suptitle(f"Errors against ±2σ and the PCRB, {title}")
    save(fig, "error_bounds.png")
    return paths
