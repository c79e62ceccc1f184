"""Figures of the factorial analysis: Pareto chart, main effects, interactions, residuals.

Each plotting function draws on given matplotlib axes and returns their
figure; :func:`save_figures` writes the four PNGs of one scenario.

References
----------
.. [1] D. C. Montgomery, *Design and Analysis of Experiments*, 9th ed.,
   Wiley, 2017 (ch. 6: effects, interaction and residual plots).
.. [2] R. V. Lenth, "Quick and easy analysis of unreplicated factorials",
   *Technometrics*, 31(4), pp. 469-473, 1989.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import matplotlib
from scipy.special import boxcox

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy import stats  # noqa: E402

from sblsim.orchestrator.analysis.data import response_unit  # noqa: E402
from sblsim.orchestrator.analysis.report import format_level  # noqa: E402

LOW_COLOR, HIGH_COLOR = "tab:blue", "tab:red"


def _unit(response: str) -> str:
    """`` [m]`` for an error metric, `` [%]`` for ``detected_pct``, nothing for a transformed response such as
    ``log(e_tot_rms)``."""
    unit = response_unit(response)
    return f" [{unit}]" if unit else ""


def _name(factor: Any) -> str:
    return factor if isinstance(factor, str) else factor.name


def _tick(factor: Any, code: int) -> str:
    """Tick label of a level: the code and, if known, the physical level."""
    label = f"{code:+d}"
    if isinstance(factor, str):
        return label
    text = format_level(factor.low if code < 0 else factor.high, factor.unit)
    return label if text == "?" else f"{label}\n({text})"


def plot_pareto(result, ax) -> plt.Figure:
    """Pareto chart of the standardized effects ``|t|``, largest at the top.

    Parameters
    ----------
    result : sblsim.orchestrator.analysis.FitResult
        Fit of one scenario.
    ax : matplotlib.axes.Axes

    Returns
    -------
    matplotlib.figure.Figure
        One horizontal bar per model term and a vertical dashed line at the
        critical value ``result.critical`` (``t_{1−α/2, df_resid}``, or
        ``t_{1−α/2, m/3}`` with Lenth's pseudo standard error).
    """
    e = result.effects.assign(abs_t=result.effects["t"].abs())
    e = e.sort_values("abs_t", ascending=True, na_position="first", kind="stable")
    y = np.arange(len(e))
    colors = [HIGH_COLOR if v > result.critical else "0.6" for v in e["abs_t"].fillna(0.0)]
    ax.barh(y, e["abs_t"].fillna(0.0), color=colors, height=0.7)
    ax.set_yticks(y, e["term"])
    if result.method == "lenth":
        label = f"t(1-α/2, m/3) = {result.critical:.3g} (Lenth)"
        ax.set_xlabel("|standardized effect| = |effect| / PSE")
    else:
        label = f"t(1-α/2, {result.df_resid}) = {result.critical:.3g}"
        ax.set_xlabel("|standardized effect| = |t|")
    ax.axvline(result.critical, color="k", ls="--", lw=1.2, label=label)
    ax.set_title(f"{result.scenario}: Pareto chart, {result.response}, α = {result.alpha:g}")
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(True, axis="x", alpha=0.3)
    return ax.figure


def _level_means(frame: pd.DataFrame, name: str, metric: str) -> list[float]:
    means = frame.groupby(name)[metric].mean()
    return [float(means.get(-1, np.nan)), float(means.get(1, np.nan))]


def plot_main_effects(frame: pd.DataFrame, factors: Sequence[Any], metric: str, axes) -> plt.Figure:
    """Mean response at the low and high level of each factor, one panel per factor.

    Parameters
    ----------
    frame : pandas.DataFrame
        Runs of one scenario (coded factor columns and ``metric``).
    factors : sequence of Factor or str
        Factors in design order (a :class:`~sblsim.orchestrator.analysis.Factor`
        adds the physical levels to the tick labels).
    metric : str
        Response column [m] (or a transformed one, e.g. ``log(e_tot_rms)``).
    axes : sequence of matplotlib.axes.Axes
        One axes per factor (flattened); extra axes are removed from the figure.

    Returns
    -------
    matplotlib.figure.Figure
        The overall mean is the dotted horizontal line in every panel.
    """
    axes = np.ravel(axes)
    grand = float(frame[metric].mean())
    means = {_name(f): _level_means(frame, _name(f), metric) for f in factors}
    values = [v for m in means.values() for v in m if np.isfinite(v)] + [grand]
    span = (max(values) - min(values)) or max(abs(grand), 1.0) * 0.1
    lim = (min(values) - 0.1 * span, max(values) + 0.1 * span)
    for i, (ax, f) in enumerate(zip(axes, factors)):
        name = _name(f)
        ax.plot([-1, 1], means[name], "o-", color="tab:blue")
        ax.axhline(grand, color="k", ls=":", lw=1.0)
        ax.set_xticks([-1, 1], [_tick(f, -1), _tick(f, 1)], fontsize=8)
        ax.set_xlim(-1.5, 1.5)
        ax.set_ylim(lim)
        ax.set_title(name)
        ax.grid(True, alpha=0.3)
        spec = ax.get_subplotspec()
        if i and (spec is None or not spec.is_first_col()):
            ax.tick_params(labelleft=False)
    for i, ax in enumerate(axes[:len(factors)]):
        spec = ax.get_subplotspec()
        if i == 0 or (spec is not None and spec.is_first_col()):
            ax.set_ylabel(f"mean {metric}{_unit(metric)}")
    fig = axes[0].figure
    for ax in axes[len(factors):]:
        ax.remove()
    return fig


def plot_interactions(frame: pd.DataFrame, factors: Sequence[Any], metric: str, axes) -> plt.Figure:
    """Interaction-plot matrix: k×k panels for k factors.

    Panel (i, j), i ≠ j: mean response against the level of factor j, one line
    per level of factor i (blue: low, red: high). Diagonal panels are blank
    and carry the factor's name. Non-parallel lines show an interaction.

    Parameters
    ----------
    frame : pandas.DataFrame
        Runs of one scenario.
    factors : sequence of Factor or str
    metric : str
        Response column [m] (or a transformed one, e.g. ``log(e_tot_rms)``).
    axes : ndarray of matplotlib.axes.Axes, shape (k, k)

    Returns
    -------
    matplotlib.figure.Figure
    """
    axes = np.asarray(axes).reshape(len(factors), len(factors))
    names = [_name(f) for f in factors]
    cell = {}
    for a in names:
        for b in names:
            if a != b:
                g = frame.groupby([a, b])[metric].mean()
                cell[a, b] = [[float(g.get((li, lj), np.nan)) for lj in (-1, 1)] for li in (-1, 1)]
    values = [v for m in cell.values() for row in m for v in row if np.isfinite(v)] or [0.0]
    span = (max(values) - min(values)) or max(abs(values[0]), 1.0) * 0.1
    lim = (min(values) - 0.1 * span, max(values) + 0.1 * span)
    for i in range(len(factors)):
        for j, fj in enumerate(factors):
            ax = axes[i, j]
            if i == j:
                ax.set_xticks([])
                ax.set_yticks([])
                ax.text(0.5, 0.5, names[i], ha="center", va="center", fontsize=11, weight="bold",
                        transform=ax.transAxes)
                continue
            lines = cell[names[i], names[j]]
            ax.plot([-1, 1], lines[0], "o-", color=LOW_COLOR, ms=3, lw=1.2, label=f"{names[i]} low")
            ax.plot([-1, 1], lines[1], "s--", color=HIGH_COLOR, ms=3, lw=1.2, label=f"{names[i]} high")
            ax.set_xlim(-1.5, 1.5)
            ax.set_ylim(lim)
            ax.set_xticks([-1, 1], ["-", "+"] if i < len(factors) - 1 else [_tick(fj, -1), _tick(fj, 1)],
                          fontsize=7)
            ax.tick_params(labelsize=7, labelleft=(j == 0 or (i == 0 and j == 1)))
            ax.grid(True, alpha=0.3)
    for j in range(len(factors)):
        if j:
            axes[0, j].set_title(names[j], fontsize=9)
        axes[-1, j].set_xlabel(names[j], fontsize=9)
        axes[j, 0].set_ylabel(f"line: {names[j]}", fontsize=8)
    axes[-1, -1].legend(handles=[plt.Line2D([], [], color=LOW_COLOR, marker="o", label="row factor low (-1)"),
                                 plt.Line2D([], [], color=HIGH_COLOR, marker="s", ls="--",
                                            label="row factor high (+1)")],
                        loc="lower center", fontsize=6, frameon=False)
    return axes[0, 0].figure


def plot_residuals(result, axes) -> plt.Figure:
    """The four residual plots in a 2×2 grid.

    Normal probability plot (:func:`scipy.stats.probplot`), histogram,
    residuals versus fitted values and residuals versus observation order
    (the row order of ``runs.parquet``).

    Parameters
    ----------
    result : sblsim.orchestrator.analysis.FitResult
    axes : ndarray of matplotlib.axes.Axes, shape (2, 2)

    Returns
    -------
    matplotlib.figure.Figure
    """
    axes = np.asarray(axes).reshape(2, 2)
    resid, fitted = np.asarray(result.resid), np.asarray(result.fitted)
    unit = _unit(result.response)
    saturated = result.df_resid == 0
    ax = axes[0, 0]
    if saturated:
        for a in axes.ravel():
            a.text(0.5, 0.5, "saturated model:\nno residual degrees of freedom", ha="center", va="center",
                   transform=a.transAxes, fontsize=9, color="0.4")
    else:
        stats.probplot(resid, dist="norm", plot=ax)
        ax.get_lines()[0].set(marker=".", markersize=4, color="tab:blue")
        ax.get_lines()[1].set(color="tab:red")
    ax.set_title("Normal probability plot")
    ax.set_xlabel("theoretical quantile [-]")
    ax.set_ylabel(f"residual{unit}")
    ax = axes[0, 1]
    if not saturated:
        ax.hist(resid, bins=max(5, min(30, int(np.sqrt(len(resid))) + 1)), color="tab:blue", edgecolor="w")
    ax.set_title("Histogram")
    ax.set_xlabel(f"residual{unit}")
    ax.set_ylabel("count")
    ax = axes[1, 0]
    if not saturated:
        ax.plot(fitted, resid, ".", color="tab:blue")
        ax.axhline(0.0, color="k", lw=0.8)
    ax.set_title("Versus fits")
    ax.set_xlabel(f"fitted {result.response}{unit}")
    ax.set_ylabel(f"residual{unit}")
    ax = axes[1, 1]
    if not saturated:
        ax.plot(np.arange(1, len(resid) + 1), resid, ".-", color="tab:blue", lw=0.5)
        ax.axhline(0.0, color="k", lw=0.8)
    ax.set_title("Versus order")
    ax.set_xlabel("observation order")
    ax.set_ylabel(f"residual{unit}")
    for a in axes.ravel():
        a.grid(True, alpha=0.3)
    return axes[0, 0].figure


def figures(result, frame: pd.DataFrame, factors: Sequence[Any]) -> dict[str, plt.Figure]:
    """The four figures of one scenario's fit: ``pareto``, ``main_effects``, ``interactions``, ``residuals``
    (kind -> matplotlib figure; the caller closes them)."""
    k = len(factors)
    metric = result.response  # main effects and interactions on the scale of the fit
    if result.transform != "none":
        y = frame[result.metric].to_numpy(dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            frame = frame.assign(**{metric: np.log(y) if result.transform == "log" else boxcox(y, result.lmbda)})
    out = {}
    fig, ax = plt.subplots(figsize=(7, 1.2 + 0.3 * len(result.effects)), layout="constrained")
    out["pareto"] = plot_pareto(result, ax)
    ncol = min(k, 4)
    nrow = -(-k // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(2.4 * ncol, 2.6 * nrow), squeeze=False, layout="constrained")
    plot_main_effects(frame, factors, metric, axes).suptitle(f"{result.scenario}: main effects, {metric}")
    out["main_effects"] = fig
    fig, axes = plt.subplots(k, k, figsize=(1.9 * k + 1, 1.7 * k + 0.8), squeeze=False, layout="constrained")
    plot_interactions(frame, factors, metric, axes).suptitle(
        f"{result.scenario}: interactions, mean {metric}{_unit(metric)}")
    out["interactions"] = fig
    fig, axes = plt.subplots(2, 2, figsize=(9, 7), layout="constrained")
    plot_residuals(result, axes).suptitle(f"{result.scenario}: residuals, {result.response}")
    out["residuals"] = fig
    return out


def save_figures(result, frame: pd.DataFrame, factors: Sequence[Any], out_dir: Path | str,
                 stem: str | None = None) -> dict[str, Path]:
    """Write the four PNGs of one scenario into ``out_dir`` (:func:`figures`).

    Returns
    -------
    dict
        ``pareto``, ``main_effects``, ``interactions``, ``residuals`` ->
        ``out_dir/<stem>_<kind>.png`` (``stem`` defaults to the scenario).
    """
    out_dir = Path(out_dir)
    stem = stem or result.scenario
    paths = {}
    for kind, fig in figures(result, frame, factors).items():
        paths[kind] = out_dir / f"{stem}_{kind}.png"
        fig.savefig(paths[kind], dpi=110, bbox_inches="tight")
        plt.close(fig)
    return paths
