"""A map's table (``map.csv``), figure (``map.png``) and their writing into an output directory
(:func:`table`, :func:`plot`, :func:`write`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sblsim.orchestrator.cosim.plan import RunPlan, as_plan
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.maps.accuracy import MIN_AVAILABILITY
from sblsim.orchestrator.maps.panels import MapConfig

#: A point whose fixes take a reflected arrival at least this often is echo-only (``map.csv``'s ``echo_only``).
ECHO_ONLY = 0.99


def system_line(plan: RunPlan | dict) -> str:
    """The geometry of a plan's system in a few words (a panel's title; a configuration: its plan is made)."""
    plan = as_plan(plan)
    return plan.system.describe(plan["platform"])


def table(labels: Sequence[str], configs: Sequence[dict], east: np.ndarray, north: np.ndarray,
          maps: Sequence[np.ndarray], compare: tuple[str, list[str]] | None = None) -> pd.DataFrame:
    """Long table of the maps: (compared value,) east, north, depth [m], drms [m] (NaN: no fix), availability
    (the probability of a fix in one cycle, when the map has it) and, with detection by signal-to-noise, echo (the
    probability that a fix takes a reflected arrival) and echo_only (true where it is at least
    :data:`ECHO_ONLY`: only echoes are heard first there)."""
    E, N = np.meshgrid(east, north)
    frames = []
    for label, cfg, m in zip(labels, configs, maps):
        frame = pd.DataFrame({"east": E.ravel(), "north": N.ravel(), "depth": float(cfg["target"]["depth"]),
                              "drms": m.ravel()})
        available = getattr(cfg, "availability", None)
        if available is not None:
            frame["availability"] = available.ravel()
        echo = getattr(cfg, "echo", None)
        if echo is not None and cfg["acoustics"]["detection"] == "snr":
            frame["echo"] = echo.ravel()
            frame["echo_only"] = echo.ravel() >= ECHO_ONLY
        if compare is not None:
            frame.insert(0, compare[0], label.split(" = ", 1)[1])
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def plot(labels: Sequence[str], configs: Sequence[dict], east: np.ndarray, north: np.ndarray,
         maps: Sequence[np.ndarray], levels: Sequence[float]):
    """Heat maps (shared logarithmic colour scale) with contours at the accuracy prescriptions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import LogLocator, ScalarFormatter

    finite = np.concatenate([m[np.isfinite(m)] for m in maps])
    if finite.size == 0:  # no fix anywhere (detection by signal-to-noise): any scale
        finite = np.array([1e-4, 1.0])
    norm = LogNorm(vmin=max(float(finite.min()), 1e-4), vmax=float(finite.max()))
    plans = [cfg.plan() if isinstance(cfg, MapConfig) else as_plan(cfg) for cfg in configs]
    # detection by signal-to-noise: the probability of a fix beside (below) each accuracy map
    heard = [getattr(cfg, "availability", None) if p["acoustics"]["detection"] == "snr" else None
             for cfg, p in zip(configs, plans)]
    rows = 2 if any(a is not None for a in heard) else 1
    fig, axes = plt.subplots(rows, len(maps), figsize=(5.2 * len(maps) + 0.8, 4.8 * rows), squeeze=False)
    systems = [p.system for p in plans]
    step = float(east[1] - east[0]) if len(east) > 1 else 1.0
    for k, (ax, label, cfg, m) in enumerate(zip(axes[0], labels, configs, maps)):
        mesh = ax.pcolormesh(east, north, m, norm=norm, cmap="viridis", shading="nearest")
        lines = ax.contour(east, north, m, levels=list(levels), colors="w", linewidths=1.2)
        ax.clabel(lines, fmt=lambda v: f"{v:g} m", fontsize=8)
        echo = getattr(cfg, "echo", None)
        hatched = heard[k] is not None and echo is not None and bool((echo >= ECHO_ONLY).any())
        if hatched:  # where only echoes come first
            ax.contourf(east, north, (echo >= ECHO_ONLY).astype(float), levels=[0.5, 1.5], colors="none",
                        hatches=["//"])
            ax.plot([], [], " ", label="/// echo-only")
        arms = plans[k].lever_arms
        inside = (np.abs(arms[:, 1]) <= east.max()) & (np.abs(arms[:, 0]) <= north.max())
        ax.plot(arms[inside, 1], arms[inside, 0], "r^", ms=6, label=systems[k].marker)
        if not inside.all():  # the grid, not the far markers, sets the axes
            ax.set_xlim(east.min() - step / 2, east.max() + step / 2)
            ax.set_ylim(north.min() - step / 2, north.max() + step / 2)
        ax.set_aspect("equal")
        ax.set_xlabel("East [m]")
        if k == 0:
            ax.set_ylabel("North [m]")
        what = f"{system_line(plans[k])}\n" if label.startswith("platform.system = ") else ""
        off = ("" if inside.all() else f", the {systems[k].marker} off the map" if not inside.any()
               else f", {int((~inside).sum())} of the {len(arms)} {systems[k].marker} off the map")
        ax.set_title(f"{label}\n({what}diver at {cfg['target']['depth']:g} m depth{off})", fontsize=9)
        if (inside.any() and (k == 0 or systems[k] != systems[0])) or hatched:
            ax.legend(loc="upper right", fontsize=8)
    what = "measurements" if any(not s.takes_ranges for s in systems) else "ranges"
    bar = fig.colorbar(mesh, ax=axes[0].tolist(), label=f"horizontal DRMS of one round of {what} + depth [m]")
    bar.locator = LogLocator(subs=(1.0, 2.0, 5.0))  # 0.1, 0.2, 0.5, 1, 2, 5 ... labelled, not only the decades
    bar.formatter = ScalarFormatter()
    bar.update_ticks()
    if rows == 2:
        for k, (ax, available) in enumerate(zip(axes[1], heard)):
            if available is None:  # fixed detection: no site to hear at
                ax.set_axis_off()
                continue
            shade = ax.pcolormesh(east, north, available, vmin=0.0, vmax=1.0, cmap="magma", shading="nearest")
            if np.ptp(available) > 0:
                lines = ax.contour(east, north, available, levels=[0.5, 0.9, 0.99], colors="c", linewidths=1.0)
                ax.clabel(lines, fmt=lambda v: f"{v:g}", fontsize=8)
            ax.set_aspect("equal")
            ax.set_xlabel("East [m]")
            if k == 0:
                ax.set_ylabel("North [m]")
            ax.set_title("probability of a fix in one cycle\n(the map above is blank where it is below "
                         f"{MIN_AVAILABILITY:g})", fontsize=9)
        fig.colorbar(shade, ax=axes[1].tolist(), label="availability [0-1]")
    return fig


def write(labels, configs, east, north, maps, levels, out: Path | str,
          compare: tuple[str, list[str]] | None = None) -> Path:
    """Write ``map.csv`` and ``map.png`` into ``out`` atomically; return ``out``."""
    import matplotlib.pyplot as plt

    with staged_directory(out) as tmp:
        table(labels, configs, east, north, maps, compare).to_csv(tmp / "map.csv", index=False)
        fig = plot(labels, configs, east, north, maps, levels)
        fig.savefig(tmp / "map.png", dpi=120, bbox_inches="tight")
        plt.close(fig)
    return Path(out)
