"""Factorial analysis of a campaign: effects, ANOVA, tables and the report.

Input: a campaign directory holding ``runs.parquet`` (one row per Monte Carlo
run: ``scenario``, ``scenario_key``, ``cell``, ``replicate``, ``seed``, per
factor ``NAME`` coded −1/+1 and ``NAME_value`` physical level, and the
metrics of :mod:`sblsim.orchestrator.cosim.metrics` for the receiver and, prefixed ``instr_``,
for the instrumentation fix) and ``study.toml`` (the resolved study: design,
replicates, seed, scenarios and one ``[[factors]]`` table per factor). Without
``study.toml`` the factors are the columns that have a ``NAME_value`` partner.

Per scenario, the response (``e_tot_rms`` by default, any error metric [m] or
``detected_pct`` [%], the share of the slots whose packet was received; with ``transform`` its
natural logarithm or its Box-Cox transform, λ by maximum likelihood) is
regressed by ordinary least squares on the coded factors with every interaction up to ``order``
(default 2: main effects and two-factor interactions). With the −1/+1 coding
the effect of a term is twice its coefficient, i.e. the mean response where
the term's contrast column is +1 minus the mean where it is −1 (Yates'
contrast; Montgomery 2017, ch. 6). The standardized effect is
``t = coefficient / standard error``; a term is significant when its two-sided
p-value is below ``alpha``, i.e. ``|t|`` exceeds ``t_{1−α/2, df_resid}``.

A model with no residual degrees of freedom (saturated, e.g. an unreplicated
design with the full model) has no error estimate: the t values and the
significance line then use Lenth's pseudo standard error (Lenth 1989) and the
analysis says so. Terms aliased with an earlier term (fractional designs) are
left out of the model, with a warning naming the alias.

Outputs (written atomically into ``out``):

``effects.csv``
    ``scenario, term, effect, coefficient, std_err, t, p_value``: one row per
    model term, in model order (main effects, then two-factor interactions,
    ...); terms are factor names joined with ``:``. The Intercept is *not* a
    row (it is no effect; the grand mean of the response is in the report).
    ``effect`` and ``coefficient`` are in the response's unit ([m], or [%] for
    ``detected_pct``); ``std_err`` is the standard error of the coefficient
    in that unit (Lenth: PSE / 2); ``t`` is
    the standardized effect [-].
    With ``transform = "log"`` the effects are differences of mean log
    response and a last column ``ratio = exp(effect)`` [-] is the factor by
    which the term multiplies the response: for a main effect, the ratio
    HIGH/LOW of the geometric means; with ``boxcox`` they are on the
    Box-Cox scale.
``diagnostics.csv``
    One row per scenario: ``scenario, metric, transform, lambda,
    lambda_ci_low, lambda_ci_high, n, df_resid, r2, r2_adj, bp_stat, bp_p,
    cell_sd_ratio, jb_stat, jb_p, skew, kurtosis, share_fitted_nonpositive, warning``: the
    checks of the model's assumptions (see
    :func:`~sblsim.orchestrator.analysis.fit.diagnose`); ``warning`` names the
    failed ones (Breusch-Pagan or Jarque-Bera p < 0.01, fitted values <= 0 of
    a positive response) and is also among the report's warnings.
``anova.csv``
    ``scenario, term, df, sum_sq, mean_sq, F, p_value`` with a ``Residual``
    row per scenario: Type II sums of squares (statsmodels ``anova_lm``,
    ``typ=2``), equal to the sequential (Type I) ones and to ``N·β²`` for the
    orthogonal −1/+1 columns of a balanced two-level design. A saturated model
    gets the sequential sums of squares and no F test.
``tables.csv``
    Tidy: ``scenario, table, subset, cell, estimator, statistic, value``.
    ``table = errors``: mean over runs of ``e_x_mean, e_y_mean, e_z_mean,
    e_tot_mean`` (statistics ``e_x, e_y, e_z, e_tot`` [m]) for the subsets
    ``all runs`` and ``best cell`` (the design cell with the lowest mean
    response; its index in ``cell``) and the estimators: the receiver that
    ran (its name from the ``receiver`` column, e.g. ``ekf``; names joined
    by ``+`` where the subset mixes receivers) and ``instrumentation``.
    ``table = receiver_vs_instr``: ``mean``, ``std``
    (ddof = 1) [m] and ``n`` [-] over runs of ``e_tot_mean`` per estimator
    (subset ``all runs``). Runs with a NaN metric are left out.
``report.html``, ``report.md``, ``figures/<scenario>_{pareto,main_effects,interactions,residuals}.png``
    The study's settings, warnings, the ranking of the significant terms in
    plain language, the tables and the figures (embedded as base64 data URIs
    in the HTML, referenced as relative PNG paths in the Markdown).

References
----------
.. [1] D. C. Montgomery, *Design and Analysis of Experiments*, 9th ed.,
   Wiley, 2017 (ch. 6: the 2^k factorial design, effects, Yates' algorithm;
   ch. 8: two-level fractional factorial designs).
.. [2] R. V. Lenth, "Quick and easy analysis of unreplicated factorials",
   *Technometrics*, 31(4), pp. 469-473, 1989.
"""


from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

import pandas as pd

from sblsim.orchestrator.analysis.data import (
    METRICS,
    REQUIRED_COLUMNS,
    RESPONSES,
    TRANSFORMS,
    AnalysisError,
    allowed_metrics,
    check_metric,
    check_order,
    check_transform,
    infer_factors,
    load_campaign_study,
    load_runs,
    scenario_order,
)
from sblsim.orchestrator.analysis.fit import (
    ANOVA_TYPE,
    DIAGNOSTIC_COLUMNS,
    FitResult,
    boxcox_lambda,
    diagnose,
    fit,
    lenth_pse,
    model_matrix,
    model_terms,
    term_name,
)
from sblsim.orchestrator.analysis.report import (
    Analysis,
    format_level,
    metric_label,
    ranking,
    report_html,
    report_markdown,
)
from sblsim.orchestrator.analysis.tables import best_cell, tables
from sblsim.orchestrator.campaign.study import Factor
from sblsim.orchestrator.campaign.study_record import StudyRecord
from sblsim.orchestrator.io.output import staged_directory


def compute(directory: Path | str, metric: str = "e_tot_rms", order: int = 2, alpha: float = 0.05,
            progress: Callable[[str], None] | None = None, transform: str = "none") -> Analysis:
    """Read a campaign directory and fit every scenario (nothing is written).

    Parameters
    ----------
    directory : path
        Campaign directory with ``runs.parquet`` (and ``study.toml``).
    metric : str
        Response column, one of :data:`RESPONSES`: an error metric [m] or ``detected_pct`` [%].
    order : int
        Highest interaction order, 1 .. number of factors.
    alpha : float
        Significance level [-].
    progress : callable, optional
        Called with one line per step of the work (the fits take seconds each on a large study).
    transform : str
        ``none`` (default), ``log`` or ``boxcox``: the scale of the response
        the model is fitted on (see :func:`~sblsim.orchestrator.analysis.fit.fit`).

    Returns
    -------
    Analysis

    Raises
    ------
    AnalysisError
        Missing or corrupt ``runs.parquet``, corrupt ``study.toml``, unknown
        metric or transform, a value <= 0 for ``log`` / ``boxcox``, bad order or alpha.
    """
    runs = load_runs(directory)
    study, notes = load_campaign_study(directory, runs)
    check_metric(metric, runs)
    check_transform(transform, runs, metric)
    names = [f.name for f in study.factors]
    order = check_order(order, len(names))
    if not 0.0 < alpha < 1.0:
        raise AnalysisError(f"alpha: {alpha!r} is outside the allowed range (0, 1)")
    present = scenario_order(runs)
    scenarios = [s for s in study.scenarios if s in present] + [s for s in present if s not in study.scenarios]
    fits, parts = {}, []
    if study.replicates == 1 or (runs.groupby(["scenario", "cell"]).size() == 1).all():
        notes.append("no replicates: there is no pure error; the residual error (if any) comes from the terms "
                     "left out of the model")
    for k, scenario in enumerate(scenarios, 1):
        if progress:
            progress(f"analyze: fitting {scenario} ({k}/{len(scenarios)}, {int((runs['scenario'] == scenario).sum())} "
                     "runs)")
        frame = runs[runs["scenario"] == scenario]
        result = fit(frame, names, metric, order, alpha, scenario, transform)
        fits[scenario] = result
        notes += [f"{scenario}: {w}" for w in result.warnings]
        parts.append(tables(frame, metric, scenario))
    return Analysis(study=study, runs=runs, metric=metric, order=order, alpha=alpha, fits=fits,
                    tables=pd.concat(parts, ignore_index=True), warnings=notes, transform=transform)


def analyze(directory: Path | str, out: Path | str | None = None, metric: str = "e_tot_rms", order: int = 2,
            alpha: float = 0.05, transform: str = "none") -> Path:
    """Analyse a campaign and write the effects, ANOVA, tables, figures and report.

    Parameters
    ----------
    directory : path
        Campaign directory with ``runs.parquet`` and ``study.toml``.
    out : path, optional
        Output directory (default ``directory``).
    metric : str
        Response column, one of :data:`RESPONSES` ([m], ``detected_pct`` [%]); default ``e_tot_rms``.
    order : int
        Highest interaction order of the model, 1 .. number of factors;
        default 2 (main effects and two-factor interactions).
    alpha : float
        Significance level [-]; default 0.05.
    transform : str
        ``none`` (default), ``log`` or ``boxcox``: fit the model to the
        metric, its logarithm (effects read as factors) or its Box-Cox transform.

    Returns
    -------
    Path
        ``out``, holding ``effects.csv``, ``diagnostics.csv``, ``anova.csv``, ``tables.csv``,
        ``report.html``, ``report.md`` and ``figures/*.png``. Everything is
        built in a temporary directory beside ``out`` and moved into place only
        when complete, so an error leaves nothing half-written.

    Raises
    ------
    AnalysisError
        Bad input (see :func:`compute`); the message is one line.

    References
    ----------
    .. [1] D. C. Montgomery, Design and Analysis of Experiments, 9th ed., Wiley, 2017.
    .. [2] R. V. Lenth, Technometrics, 31(4), pp. 469-473, 1989.
    """
    analysis = compute(directory, metric, order, alpha, transform=transform)
    return write(analysis, Path(out) if out is not None else Path(directory))


def write(analysis: Analysis, out: Path | str, progress: Callable[[str], None] | None = None) -> Path:
    """Write the outputs of an :class:`Analysis` into ``out`` atomically; return ``out``.

    ``progress``, if given, is called with one line per scenario's figures."""
    from sblsim.orchestrator.analysis.plots import save_figures

    out = Path(out).absolute()
    with staged_directory(out) as tmp:
        fig_dir = tmp / "figures"
        fig_dir.mkdir()
        factors = analysis.study.factors
        figures: dict[str, dict[str, str]] = {}
        used: set[str] = set()
        for k, (scenario, result) in enumerate(analysis.fits.items(), 1):
            if progress:
                progress(f"analyze: figures of {scenario} ({k}/{len(analysis.fits)})")
            stem = _file_stem(scenario, used)
            frame = analysis.runs[analysis.runs["scenario"] == scenario]
            paths = save_figures(result, frame, factors, fig_dir, stem)
            figures[scenario] = {kind: f"figures/{p.name}" for kind, p in paths.items()}
        effects = pd.concat([r.effects.assign(scenario=s) for s, r in analysis.fits.items()], ignore_index=True)
        columns = ["scenario", "term", "effect", "coefficient", "std_err", "t", "p_value"]
        effects[columns + (["ratio"] if "ratio" in effects.columns else [])].to_csv(tmp / "effects.csv", index=False)
        analysis.diagnostics.to_csv(tmp / "diagnostics.csv", index=False)
        anova = pd.concat([r.anova.assign(scenario=s) for s, r in analysis.fits.items()], ignore_index=True)
        anova[["scenario", "term", "df", "sum_sq", "mean_sq", "F", "p_value"]].to_csv(tmp / "anova.csv", index=False)
        analysis.tables.to_csv(tmp / "tables.csv", index=False)
        (tmp / "report.md").write_text(report_markdown(analysis, figures), encoding="utf-8")
        (tmp / "report.html").write_text(report_html(analysis, figures, tmp), encoding="utf-8")
    return out


def _file_stem(scenario: str, used: set[str]) -> str:
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", scenario).strip("._") or "scenario"
    base, i = stem, 1
    while stem in used:
        i += 1
        stem = f"{base}_{i}"
    used.add(stem)
    return stem


__all__ = ["ANOVA_TYPE", "DIAGNOSTIC_COLUMNS", "METRICS", "REQUIRED_COLUMNS", "RESPONSES", "TRANSFORMS", "Analysis",
           "AnalysisError", "Factor", "FitResult", "StudyRecord", "allowed_metrics", "analyze", "best_cell",
           "boxcox_lambda", "check_metric", "check_order", "check_transform", "compute", "diagnose", "fit",
           "format_level", "infer_factors", "lenth_pse", "load_runs", "load_campaign_study", "metric_label",
           "model_matrix", "model_terms", "ranking", "report_html", "report_markdown", "scenario_order", "tables",
           "term_name", "write"]
