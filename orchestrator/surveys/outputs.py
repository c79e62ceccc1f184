"""The files ``sblsim calibrate`` writes (:func:`write_calibration`): ``solution.json``, the residuals and their
figures, and the running solution's, the perturbation's and the search's tables and figures.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.surveys.solution import Calibration

#: The files of a perturbation: ``ntd.csv`` and ``ntd.png``; of a search, ``criterion.csv`` and ``criterion.png``.
PERTURBATION_FILES = ("ntd.csv", "ntd.png")
SEARCH_FILES = ("criterion.csv", "criterion.png")
#: The files ``sblsim calibrate`` writes.
OUTPUT_FILES = ("solution.json", "residuals.csv", "track.png", "residuals_time.png", "residuals_elevation.png")
#: The files of the running solution, written unless ``solver.running = false``.
RUNNING_FILES = ("running.csv", "running.png")


def write_calibration(result: Calibration, out: Path | str, extra: dict | None = None) -> Path:
    """Write :data:`OUTPUT_FILES` into ``out`` atomically (nothing changes there if a write fails).

    ``extra`` maps further files' names to functions writing them (given the file's path), written in the same
    step (a simulated survey's log and replicates)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    r = result.residuals
    title = result.solution["title"] or result.survey.name
    with staged_directory(out) as tmp:
        (tmp / "solution.json").write_text(json.dumps(result.solution, indent=2, allow_nan=False) + "\n")
        r.to_csv(tmp / "residuals.csv", index=False)
        used = r[r["used"]]
        rejected = r[~r["used"]]
        scale = float(np.nanpercentile(np.abs(used["residual_s"]) * 1e6, 98)) if len(used) else 1.0
        fig, ax = plt.subplots(figsize=(6.5, 6))
        dots = ax.scatter(used["rx_e_m"], used["rx_n_m"], c=used["residual_s"] * 1e6, cmap="coolwarm", s=8,
                          vmin=-scale, vmax=scale)
        ax.scatter(rejected["rx_e_m"], rejected["rx_n_m"], marker="x", c="k", s=16, label="rejected")
        for j, name in enumerate(result.survey.ids):
            t = result.solution["transponders"][j]
            ax.plot(t["apriori_e_m"] + t["e_m"], t["apriori_n_m"] + t["n_m"], "k^", ms=9)
            ax.annotate(f"transponder {name}", (t["apriori_e_m"] + t["e_m"], t["apriori_n_m"] + t["n_m"]),
                        textcoords="offset points", xytext=(6, 6))
        fig.colorbar(dots, ax=ax, label="TWTT residual [µs]")
        ax.set(xlabel="East [m]", ylabel="North [m]", aspect="equal", title=f"Track, {title}")
        ax.legend(loc="lower right")
        fig.savefig(tmp / "track.png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        for name, column, label in (("residuals_time.png", "t_tx_s", "transmit time [s from the first ping]"),
                                    ("residuals_elevation.png", "elevation_deg", "elevation angle [deg]")):
            fig, ax = plt.subplots(figsize=(7, 3.5))
            x0 = float(r["t_tx_s"].min()) if column == "t_tx_s" else 0.0
            for k, part in used.groupby("segment"):
                ax.plot(part[column] - x0, part["residual_s"] * 1e6, ".", ms=3, label=f"segment {k}")
            ax.plot(rejected[column] - x0, rejected["residual_s"] * 1e6, "kx", ms=5, label="rejected")
            ax.set(xlabel=label, ylabel="TWTT residual [µs]", title=title)
            ax.grid(True, lw=0.3)
            ax.legend(fontsize=7, ncol=3)
            fig.savefig(tmp / name, dpi=110, bbox_inches="tight")
            plt.close(fig)
        if result.running is not None:
            result.running.to_csv(tmp / "running.csv", index=False)
            _running_figure(result, tmp / "running.png", plt)
        if result.ntd is not None:
            result.ntd.to_csv(tmp / "ntd.csv", index=False)
            _ntd_figure(result, tmp / "ntd.png", plt)
        if result.search is not None:
            result.search.to_csv(tmp / "criterion.csv", index=False)
            _criterion_figure(result, tmp / "criterion.png", plt)
        for name, write in (extra or {}).items():
            write(tmp / name)
    return out


def _ntd_figure(result: Calibration, path: Path, plt) -> None:
    """SeaGap's figure of the perturbation: each transponder's nadir-normalised residual of the legs (less the
    gradients) and the solved delay against time, and what remains."""
    r = result.ntd
    title = result.solution["title"] or result.survey.name
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True)
    t0 = float(r["t_s"].min())
    used = r[r["used"]]
    for j, tid in enumerate(result.survey.ids):
        mine = used[used["transponder"] == tid]
        hours = (mine["t_s"] - t0) / 3600.0
        top.plot(hours, mine["observed_s"] * 1e3, "+", ms=3, color=f"C{j % 10}", label=f"transponder {tid}")
        bottom.plot(hours, mine["residual_s"] * 1e3, "+", ms=3, color=f"C{j % 10}")
    for k, part in r.groupby("segment"):
        part = part.sort_values("t_s")
        top.plot((part["t_s"] - t0) / 3600.0, part["ntd_s"] * 1e3, "k-", lw=1.2,
                 label="perturbation (nadir delay)" if k == 1 else None)
    top.set(ylabel="nadir-normalised delay [ms]", title=f"Sound-speed perturbation, {title}")
    bottom.set(xlabel="time [h from the first reply]", ylabel="residual [ms]")
    for ax in (top, bottom):
        ax.grid(True, lw=0.3)
    top.legend(fontsize=7, ncol=3)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _criterion_figure(result: Calibration, path: Path, plt) -> None:
    """The search's criteria against the number of bases (SeaGap's AIC and BIC) or the smoothness (GARPOS's ABIC),
    the chosen candidate marked."""
    table = result.search
    garpos = table["abic"].notna().any()
    names = ["abic"] if garpos else ["aic", "bic"]
    chosen = "abic" if garpos else result.survey.solver["criterion"]
    axis = "log_lambda0" if garpos and table["log_lambda0"].nunique() > 1 else "n_bases"
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for k, part in table.groupby("segment"):
        others = [c for c in ("log_grad_lambda", "mu_t", "mu_mt") if part[c].nunique() > 1]
        for values, line in (part.groupby(others) if others else [((), part)]):
            line = line.sort_values(axis)
            for name in names:
                label = ", ".join([name.upper()] + [f"{c} {v:g}" for c, v in zip(others, np.atleast_1d(values))])
                ax.plot(line[axis], line[name], "+-", label=label + (f", segment {k}" if k > 1 else ""))
        best = part[part["chosen"]]
        ax.axvline(float(best[axis].iloc[0]), color="r", lw=0.8)
        ax.annotate(f"{best[axis].iloc[0]:g} ({chosen.upper()})", (float(best[axis].iloc[0]),
                                                                      float(best[chosen].iloc[0])),
                    textcoords="offset points", xytext=(4, -12), color="r")
    ax.set(xlabel={"n_bases": "number of B-spline bases", "log_lambda0": "log10 lambda0^2"}[axis],
           ylabel="criterion", title=f"Model selection, {result.solution['title'] or result.survey.name}")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _running_figure(result: Calibration, path: Path, plt) -> None:
    """The running estimate of each transponder's East, North, Up offsets with its +-1-sigma band, beside each
    segment's weighted least-squares solution (dashed)."""
    r = result.running
    title = result.solution["title"] or result.survey.name
    ids = result.survey.ids
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    t0 = float(r["t_tx_s"].min())
    for axis, (ax, name) in enumerate(zip(axes, ("e", "n", "u"))):
        limits = []
        for j, tid in enumerate(ids):
            for segment, part in r[r["id"] == tid].groupby("segment"):
                t = part["t_tx_s"].to_numpy() - t0
                x, sd = part[f"{name}_m"].to_numpy(), part[f"sigma_{name}_m"].to_numpy()
                colour = f"C{j % 10}"
                label = f"transponder {tid}" if segment == 1 else None
                ax.plot(t, x, "-", color=colour, lw=1, label=label)
                ax.fill_between(t, x - sd, x + sd, color=colour, alpha=0.2, lw=0)
                sol = result.segments[segment - 1][3]
                ax.hlines(sol.offset[j, axis], t[0], t[-1], colors="k", linestyles="--", lw=0.8,
                          label="least squares" if (j, segment) == (0, 1) else None)
                # the band is metres wide at the start (the prior): show the last nine tenths
                tail = x[len(x) // 10:]
                spread = max(float(np.max(np.abs(tail - x[-1]))), 4.0 * sd[-1], 1e-3)
                limits += [x[-1] - 1.5 * spread, x[-1] + 1.5 * spread]
        ax.set_ylim(min(limits), max(limits))
        ax.set_ylabel(f"{name.upper()} offset [m]")
        ax.grid(True, lw=0.3)
    axes[0].set_title(f"Running solution (static Kalman filter, ±1σ), {title}")
    axes[0].legend(fontsize=7, ncol=3)
    axes[-1].set_xlabel("transmit time [s from the first ping]")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


__all__ = ["OUTPUT_FILES", "PERTURBATION_FILES", "RUNNING_FILES", "SEARCH_FILES", "write_calibration"]
