"""``sblsim analyze`` and ``sblsim.analyze``: the factorial analysis of a campaign's runs (effects, ANOVA,
diagnostics) and its report (:mod:`sblsim.orchestrator.analysis`).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from sblsim.models.declarations import shown
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.io.arguments import check_count, path_argument, real_argument, text_argument
from sblsim.orchestrator.io.output import check_writable

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class AnalysisResult:
    """The outcome of :func:`analyze`.

    Attributes
    ----------
    effects : pandas.DataFrame
        ``effects.csv``: per scenario and term, ``effect``, ``coefficient``, ``std_err``, ``t``, ``p_value``
        (in the metric's unit, [m] for the errors; with ``transform="log"`` also ``ratio``).
    anova : pandas.DataFrame
        ``anova.csv``.
    tables : pandas.DataFrame
        ``tables.csv``: the tidy tables of the report.
    diagnostics : pandas.DataFrame
        ``diagnostics.csv``: one row per scenario.
    warnings : list of str
    fits : dict
        Scenario -> the fit (its ``effects``, ``anova``, ``lmbda``, ...).
    out : Path or None
    """

    effects: pd.DataFrame
    anova: pd.DataFrame
    tables: pd.DataFrame
    diagnostics: pd.DataFrame
    warnings: list[str]
    fits: dict[str, Any]
    out: Path | None = None
    _analysis: Any = field(default=None, repr=False)

    def plot(self, scenario: str | None = None) -> dict[str, Figure]:
        """The report's figures of one scenario (default the first): ``pareto``, ``main_effects``,
        ``interactions``, ``residuals`` -> matplotlib Figure.

        Raises
        ------
        ConfigError
            A scenario the campaign does not have.
        """
        from sblsim.orchestrator.analysis.plots import figures

        a = self._analysis
        name = next(iter(a.fits)) if scenario is None else scenario
        if name not in a.fits:
            raise ConfigError(f"scenario: {name!r} is not one of {', '.join(a.fits)}")
        return figures(a.fits[name], a.runs[a.runs["scenario"] == name], a.study.factors)


def analyze(directory: str | Path, *, metric: str = "e_tot_rms", order: int = 2, transform: str = "none",
            alpha: float = 0.05, out: str | Path | None = None, progress: Callable[[str], object] | None = None
            ) -> AnalysisResult:
    """The factorial analysis of a campaign: ``sblsim analyze``.

    Parameters
    ----------
    directory : str or Path
        A campaign directory (with ``runs.parquet`` and ``study.toml``).
    metric : str
        The response column: an error metric (default ``e_tot_rms`` [m]) or ``detected_pct`` [%], the share of
        the slots whose packet was received.
    order : int
        Highest interaction order of the model, 1 … number of factors.
    transform : {'none', 'log', 'boxcox'}
        Fit the metric, its logarithm (effects as factors) or its Box-Cox transform.
    alpha : float
        Significance level [-], (0, 1).
    out : str or Path, optional
        Write the report, tables and figures there (``sblsim analyze`` writes into the campaign directory).
    progress : callable, optional
        Called with one line per step of the work.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    SblsimError
        Missing or corrupt ``runs.parquet`` or ``study.toml``, unknown metric or transform, bad order or
        alpha.
    """
    import pandas as pd

    from sblsim.orchestrator.analysis import compute, write

    directory = path_argument(directory, "directory", optional=False)
    out = path_argument(out, "out")
    text_argument(metric, "metric", optional=False)
    text_argument(transform, "transform", optional=False)
    order = check_count(order, "order", 1, 2**31 - 1)
    real_argument(alpha, "alpha", 0.0, 1.0, "", low_open=True)
    if progress is not None and not callable(progress):
        raise ConfigError(f"progress: {shown(progress)} is not None or a callable(line)")
    if out is not None:
        check_writable(out, "out")
    a = compute(directory, metric, order, alpha, progress=progress, transform=transform)
    target = write(a, out, progress=progress) if out is not None else None
    effects = pd.concat([r.effects.assign(scenario=s) for s, r in a.fits.items()], ignore_index=True)
    anova = pd.concat([r.anova.assign(scenario=s) for s, r in a.fits.items()], ignore_index=True)
    return AnalysisResult(effects, anova, a.tables, a.diagnostics, list(a.warnings), dict(a.fits), target, a)


NAME = "analyze"
HELP = "factorial analysis and report of a campaign directory"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim analyze``'s arguments."""
    p.add_argument("dir", type=Path, help="campaign directory (with runs.parquet)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: the campaign directory)")
    p.add_argument("--metric", default="e_tot_rms",
                   help="response column: an error metric [m] (default e_tot_rms) or detected_pct [%%]")
    p.add_argument("--order", type=int, default=2, help="highest interaction order in the model (default 2)")
    p.add_argument("--transform", choices=("none", "log", "boxcox"), default="none",
                   help="fit the model to the metric (none, default), its logarithm (log: effects as factors) or "
                        "its Box-Cox transform (boxcox: lambda by maximum likelihood); see diagnostics.csv")


def main(args: argparse.Namespace) -> int:
    """``sblsim analyze`` from its parsed arguments: its lines printed, its exit status returned."""
    return analyze_folder(args.dir, args.out, args.metric, args.order, args.transform)


def analyze_folder(directory: Path, out: Path | None = None, metric: str = "e_tot_rms", order: int = 2,
                   transform: str = "none") -> int:
    """``sblsim analyze`` of a campaign folder (also ``sblsim campaign --analyze``): the analysis written, its
    significant terms printed."""
    from sblsim.orchestrator.analysis import compute, write

    check_writable(out or directory)

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    analysis = compute(directory, metric, order, progress=say, transform=transform)
    for note in analysis.warnings:
        print(f"note: {note}", file=sys.stderr)
    target = write(analysis, out or directory, progress=say)
    for scenario, result in analysis.fits.items():
        effects = result.effects
        significant = effects[effects["p_value"] < analysis.alpha].sort_values("t", key=abs, ascending=False)
        if "ratio" in significant.columns:  # log: the factor by which each term multiplies the metric
            names = [f"{t} (x{r:.3g})" for t, r in zip(significant["term"].head(5), significant["ratio"].head(5))]
        else:
            names = list(significant["term"].head(5))
        print(f"{scenario}: significant terms, largest first: {', '.join(names) or 'none'}")
        if result.lmbda is not None:
            low, high = result.lmbda_ci
            print(f"{scenario}: Box-Cox lambda = {result.lmbda:.3g} (95 % CI {low:.3g} to {high:.3g})")
    print(f"analysis written to {target}/ (report.html, report.md, effects.csv, diagnostics.csv, anova.csv, "
          "tables.csv, figures)")
    return 0
