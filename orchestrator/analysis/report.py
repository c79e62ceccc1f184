"""The report: plain-language ranking of the effects, settings, tables, figures (Markdown and HTML)."""

from __future__ import annotations

import base64
import html
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sblsim.orchestrator.analysis.data import higher_is_better, response_unit
from sblsim.orchestrator.analysis.fit import DIAGNOSTIC_COLUMNS, FitResult
from sblsim.orchestrator.analysis.tables import best_cell
from sblsim.orchestrator.campaign.study import Factor
from sblsim.orchestrator.campaign.study_record import StudyRecord

_METRIC_WORDS = {"e_x_mean": "mean e_x", "e_y_mean": "mean e_y", "e_z_mean": "mean e_z",
                 "e_tot_mean": "mean e_tot", "e_tot_rms": "RMS e_tot", "e_tot_std": "std of e_tot",
                 "detected_pct": "the share of packets received"}


@dataclass
class Analysis:
    """Everything the report shows.

    Attributes
    ----------
    study : StudyRecord
    runs : pandas.DataFrame
    metric : str
    order : int
    alpha : float
    fits : dict
        Scenario -> :class:`FitResult`, in scenario order.
    tables : pandas.DataFrame
        Tidy tables (layout of ``tables.csv``).
    warnings : list of str
        Study-level and per-scenario warnings (``scenario: ...``).
    transform : str
        Transform of the response: ``none``, ``log`` or ``boxcox``.
    """

    study: StudyRecord
    runs: pd.DataFrame
    metric: str
    order: int
    alpha: float
    fits: dict[str, FitResult]
    tables: pd.DataFrame
    warnings: list[str]
    transform: str = "none"

    @property
    def diagnostics(self) -> pd.DataFrame:
        """One row per scenario: the layout of ``diagnostics.csv``."""
        rows = [{"scenario": s, **r.diagnostics} for s, r in self.fits.items()]
        return pd.DataFrame(rows, columns=["scenario", *DIAGNOSTIC_COLUMNS])


def metric_label(metric: str) -> str:
    """Plain words for a metric column, e.g. ``instr_e_tot_rms`` -> ``instrumentation RMS e_tot``."""
    if metric.startswith("instr_"):
        return "instrumentation " + _METRIC_WORDS.get(metric[6:], metric[6:])
    return _METRIC_WORDS.get(metric, metric)


def format_level(value: float | str | None, unit: str = "") -> str:
    """A level for tables and figures: ``3 m``, ``ekf-seq``, or ``?`` when unknown."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "?"
    text = value if isinstance(value, str) else f"{value:g}"
    return f"{text} {unit}" if unit else text


def ranking(result: FitResult, factors: Sequence[Factor]) -> str:
    """Plain-language ranking of the significant terms of one scenario, largest ``|t|`` first.

    Main effects say what going from the low to the high level does to the
    response and which level is better (lower error, more packets received: ``detected_pct``); two-factor
    interactions say how much the first factor's effect changes between the
    levels of the second (twice the interaction effect, Montgomery 2017, §6.2).
    With ``transform = "log"`` effects read as factors: a main effect
    multiplies the response by ``exp(effect)`` (the ratio HIGH/LOW of the
    geometric means) and an interaction multiplies the first factor's ratio
    by ``exp(2·effect)`` at the high level of the second; with ``boxcox`` the
    effects are on the Box-Cox scale (no unit).
    """
    by_name = {f.name: f for f in factors}
    what = metric_label(result.metric)
    sig = result.significant
    test = "Lenth's method" if result.method == "lenth" else "t test"
    head = f"{result.scenario}: "
    if sig.empty:
        return head + f"no term is significant at alpha = {result.alpha:g} ({test})."
    parts = []
    # none: effects in the response's unit; boxcox: on the transformed scale (no unit); log: factors (_ratio_text)
    unit = f" {response_unit(result.metric)}" if result.transform == "none" else ""
    # a change of a share in words: percentage points, not a percentage of it
    amount = " percentage points" if unit == " %" else unit
    higher = higher_is_better(result.metric)
    scale = f" on the Box-Cox scale, lambda = {result.lmbda:.3g}" if result.transform == "boxcox" else ""
    for row in sig.itertuples():
        names = row.term.split(":")
        e = row.effect
        if result.transform == "log" and len(names) <= 2:
            parts.append(_ratio_text(row.term, e, by_name, what, higher))
        elif len(names) == 1:
            f = by_name[names[0]]
            verb = "raises" if e > 0 else "lowers"
            by = f" by {abs(e):.3g}{amount}" if result.transform == "none" else ""
            better = "low" if (e > 0) != higher else "high"
            parts.append(f"{row.term} (effect {e:+.3g}{unit}{scale}: going from {format_level(f.low, f.unit)} to "
                         f"{format_level(f.high, f.unit)} {verb} {what}{by}; the {better} level "
                         f"({format_level(f.low if better == 'low' else f.high, f.unit)}) is better)")
        elif len(names) == 2:
            a, b = names
            more = "larger" if e > 0 else "smaller"
            hi, lo = format_level(by_name[b].high, by_name[b].unit), format_level(by_name[b].low, by_name[b].unit)
            parts.append(f"{row.term} (interaction effect {e:+.3g}{unit}{scale}: the effect of {a} is "
                         f"{abs(2 * e):.3g}{amount} {more} at high {b} ({hi}) than at low {b} ({lo}))")
        else:
            on = f" on log({result.metric})" if result.transform == "log" else scale
            parts.append(f"{row.term} (interaction effect {e:+.3g}{unit}{on})")
    return (head + f"the significant terms (alpha = {result.alpha:g}, {test}), largest first: "
            + "; ".join(parts) + ".")


def _summary_line(result: FitResult) -> str:
    """One short line per scenario for the report's overview: the significant terms, largest ``|t|`` first (the
    scenario's own section says what each does)."""
    terms = ", ".join(result.significant["term"]) if not result.significant.empty else "none"
    return f"{result.scenario}: {terms}"


def _ratio_text(term: str, e: float, by_name: dict[str, Factor], what: str, higher: bool = False) -> str:
    """A term of a log fit in plain words: the factor by which it multiplies the response (``higher``: a
    higher response is better)."""
    names = term.split(":")
    if len(names) == 1:
        f = by_name[names[0]]
        better = "low" if (e > 0) != higher else "high"
        return (f"{term} (x{math.exp(e):.3g}: going from {format_level(f.low, f.unit)} to "
                f"{format_level(f.high, f.unit)} multiplies {what} by {math.exp(e):.3g} ({_percent(e)}); the "
                f"{better} level ({format_level(f.low if better == 'low' else f.high, f.unit)}) is better)")
    a, b = names
    return (f"{term} (x{math.exp(e):.3g}: the factor of {a} is {math.exp(2 * e):.3g} times as large at high {b} "
            f"({format_level(by_name[b].high, by_name[b].unit)}) as at low {b} "
            f"({format_level(by_name[b].low, by_name[b].unit)}))")


def _percent(log_ratio: float) -> str:
    change = 100.0 * (math.exp(log_ratio) - 1.0)
    return f"{change:+.3g} %"


def _design_text(study: StudyRecord, runs: pd.DataFrame) -> str:
    k = len(study.factors)
    cells = int(runs.groupby("scenario")["cell"].nunique().max())
    if study.design == "full":
        text = f"full 2^{k} factorial ({cells} cells)"
    elif study.design == "fractional":
        p = k - round(math.log2(cells)) if cells > 0 else 0
        text = f"2^({k}-{p}) fractional factorial ({cells} cells"
        if study.resolution:
            text += f", resolution {study.resolution}"
        if study.generators:
            text += f", generators {study.generators}"
        text += ")"
    else:
        text = f"{study.design} ({cells} cells over {k} factors)"
    return text


def _settings(analysis: Analysis) -> list[tuple[str, str]]:
    s = analysis.study
    return [
        ("study", s.name),
        ("design", _design_text(s, analysis.runs)),
        ("replicates per cell", "?" if s.replicates is None else str(s.replicates)),
        ("campaign seed", "?" if s.seed is None else str(s.seed)),
        ("scenarios", ", ".join(analysis.fits)),
        ("engine", s.engine or "?"),
        ("runs", str(len(analysis.runs))),
        ("response", f"{analysis.metric} ({metric_label(analysis.metric)}) [{response_unit(analysis.metric)}]"),
        ("transform", _transform_text(analysis)),
        ("model", f"OLS on the coded factors (-1/+1), interactions up to order {analysis.order}"),
        ("significance", f"alpha = {analysis.alpha:g}, two-sided"),
        ("ANOVA", "Type II sums of squares (Type I for a saturated model; equal for an orthogonal design)"),
    ]


def _transform_text(analysis: Analysis) -> str:
    if analysis.transform == "log":
        return (f"log: the model is fitted to log({analysis.metric}); an effect is a difference of mean logs and "
                "exp(effect) (column ratio) the factor by which the term multiplies the response (main effect: "
                "ratio HIGH/LOW of the geometric means)")
    if analysis.transform == "boxcox":
        lams = ", ".join(f"{s} {r.lmbda:.3g} (95 % CI {r.lmbda_ci[0]:.3g} to {r.lmbda_ci[1]:.3g})"
                         for s, r in analysis.fits.items())
        return (f"Box-Cox, lambda by maximum likelihood of the factorial model per scenario: {lams}; effects are "
                "on the transformed scale (y^lambda - 1) / lambda")
    unit = {"m": "metres", "%": "percentage points"}.get(response_unit(analysis.metric), "the response's unit")
    return f"none (the effects are in {unit}; see the diagnostics before reading the t and p values)"


def _diagnostics_table(analysis: Analysis) -> pd.DataFrame:
    d = analysis.diagnostics.drop(columns=["metric", "warning"])
    if analysis.transform != "boxcox":
        d = d.drop(columns=["lambda", "lambda_ci_low", "lambda_ci_high"])
    return d


_DIAGNOSTICS_TEXT = ("Checks of the model's assumptions: R², Breusch-Pagan test of a residual variance that changes "
                     "with the terms (bp, Koenker's form) and the ratio of the largest to the smallest residual "
                     "standard deviation within a design cell, Jarque-Bera test of normal residuals (jb; kurtosis 3 "
                     "for a normal law), share of fitted values that stand for a response <= 0. A p-value below "
                     "0.01 or any such fitted value is listed under Warnings.")


def _factor_table(study: StudyRecord) -> pd.DataFrame:
    return pd.DataFrame([{"factor": f.name, "key": f.key, "low (-1)": format_level(f.low, f.unit),
                          "high (+1)": format_level(f.high, f.unit), "description": f.description}
                         for f in study.factors])


def _error_table(tab: pd.DataFrame, scenario: str) -> pd.DataFrame:
    t = tab[(tab["scenario"] == scenario) & (tab["table"] == "errors")]
    wide = t.pivot_table(index=["subset", "estimator"], columns="statistic", values="value", sort=False)
    wide = wide[[c for c in ("e_x", "e_y", "e_z", "e_tot") if c in wide.columns]]
    wide.columns = [f"{c} [m]" for c in wide.columns]
    return wide.reset_index()


def _comparison_table(tab: pd.DataFrame, scenario: str) -> pd.DataFrame:
    t = tab[(tab["scenario"] == scenario) & (tab["table"] == "receiver_vs_instr")]
    wide = t.pivot_table(index="estimator", columns="statistic", values="value", sort=False)
    wide = wide.rename(columns={"mean": "mean e_tot_mean [m]", "std": "std e_tot_mean [m]", "n": "runs"})
    if "runs" in wide.columns:
        wide["runs"] = wide["runs"].astype(int)
    wide.columns.name = None
    return wide.reset_index()


def _best_cell_text(analysis: Analysis, scenario: str) -> str:
    frame = analysis.runs[analysis.runs["scenario"] == scenario]
    cell = best_cell(frame, analysis.metric)
    row = frame[frame["cell"] == cell].iloc[0]
    levels = []
    for f in analysis.study.factors:
        code = int(row[f.name])
        value = f.low if code < 0 else f.high
        levels.append(f"{f.name} = {format_level(value, f.unit)} ({code:+d})")
    mean = frame.loc[frame["cell"] == cell, analysis.metric].mean()
    best = "highest" if higher_is_better(analysis.metric) else "lowest"
    return (f"best cell: {cell} ({best} mean {analysis.metric} = {mean:.4g} {response_unit(analysis.metric)}): "
            + ", ".join(levels))


def _effects_view(result: FitResult) -> pd.DataFrame:
    e = result.effects.copy()
    e["significant"] = np.where(e["p_value"] < result.alpha, "yes", "")
    return e


def _method_text(result: FitResult) -> str:
    unit = f" {response_unit(result.metric)}"
    if result.transform == "log":
        mean = f"geometric mean {math.exp(result.intercept):.4g}{unit}"
    elif result.transform == "boxcox":
        mean = f"grand mean {result.intercept:.4g} on the Box-Cox scale (lambda = {result.lmbda:.3g})"
    else:
        mean = f"grand mean {result.intercept:.4g}{unit}"
    unit = unit if result.transform == "none" else ""
    if result.method == "lenth":
        return (f"{result.n} runs, no residual degrees of freedom: Lenth's pseudo standard error "
                f"PSE = {result.pse:.4g}{unit}, t = effect / PSE, significance line t(1-alpha/2, m/3) = "
                f"{result.critical:.4g}; {mean}.")
    return (f"{result.n} runs, {result.df_resid} residual degrees of freedom, significance line "
            f"t(1-alpha/2, {result.df_resid}) = {result.critical:.4g}; {mean}.")


_FIGURE_TITLES = {"pareto": "Pareto chart of the standardized effects",
                  "main_effects": "Main effects", "interactions": "Interaction plots",
                  "residuals": "Residual plots"}


_REFERENCES = ("D. C. Montgomery, Design and Analysis of Experiments, 9th ed., Wiley, 2017.",
               ("R. V. Lenth, \"Quick and easy analysis of unreplicated factorials\", "
                "Technometrics, 31(4), pp. 469-473, 1989."))


_FLOAT = "{:.4g}".format


def report_markdown(analysis: Analysis, figures: dict[str, dict[str, str]]) -> str:
    """``report.md``: settings, warnings, rankings, tables and figure links (paths relative to the report)."""
    def table(frame: pd.DataFrame) -> str:
        return frame.to_markdown(index=False, floatfmt=".4g")

    lines = [f"# Factorial analysis: {analysis.study.name}", "", "## Study", ""]
    lines += [f"- **{k}**: {v}" for k, v in _settings(analysis)]
    lines += ["", "### Factors", "", table(_factor_table(analysis.study)), ""]
    if analysis.warnings:
        lines += ["## Warnings", ""] + [f"- {w}" for w in analysis.warnings] + [""]
    lines += ["## Diagnostics", "", _DIAGNOSTICS_TEXT, "", table(_diagnostics_table(analysis)), ""]
    lines += ["## Significant factors", ""]
    lines += [f"- {_summary_line(r)}" for r in analysis.fits.values()] + [""]
    for scenario, result in analysis.fits.items():
        lines += [f"## Scenario {scenario}", "", ranking(result, analysis.study.factors), "",
                  _method_text(result), "", "### Errors", "", _best_cell_text(analysis, scenario), "",
                  table(_error_table(analysis.tables, scenario)), "", "### Receiver versus instrumentation", "",
                  table(_comparison_table(analysis.tables, scenario)), "", "### Effects", "",
                  table(_effects_view(result)), "", f"### ANOVA ({result.anova_type})", "",
                  table(result.anova), "", "### Figures", ""]
        for kind, path in figures.get(scenario, {}).items():
            lines += [f"![{scenario}: {_FIGURE_TITLES[kind]}]({path})", ""]
    lines += ["## References", ""] + [f"- {r}" for r in _REFERENCES] + [""]
    return "\n".join(lines)


_CSS = """body{font-family:sans-serif;max-width:75em;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:2px 8px}
.num{text-align:right}.text{text-align:left}
th{background:#eee}img{max-width:100%;display:block;margin:0.5em 0}.warn{color:#a40}"""


def report_html(analysis: Analysis, figures: dict[str, dict[str, str]], root: Path | str) -> str:
    """``report.html``: as :func:`report_markdown`, self-contained (figures as base64 data URIs).

    ``root`` is the directory the figure paths are relative to.
    """
    esc = html.escape

    def table(frame: pd.DataFrame) -> str:
        """A table whose number columns are right-aligned and text columns left-aligned."""
        numeric = [pd.api.types.is_numeric_dtype(frame[c]) and not pd.api.types.is_bool_dtype(frame[c])
                   for c in frame.columns]

        def cell(value, number: bool) -> str:
            if number and isinstance(value, float):
                return "" if math.isnan(value) else _FLOAT(value)
            return esc(str(value))

        head = "".join(f'<th class="{"num" if n else "text"}">{esc(str(c))}</th>'
                       for c, n in zip(frame.columns, numeric))
        rows = ["<tr>" + "".join(f'<td class="{"num" if n else "text"}">{cell(v, n)}</td>'
                                 for v, n in zip(values, numeric)) + "</tr>"
                for values in frame.itertuples(index=False, name=None)]
        return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"

    def image(path: str, title: str) -> str:
        data = base64.b64encode((Path(root) / path).read_bytes()).decode("ascii")
        return (f'<figure><img alt="{esc(title)}" src="data:image/png;base64,{data}">'
                f"<figcaption>{esc(title)}</figcaption></figure>")

    body = [f"<h1>Factorial analysis: {esc(analysis.study.name)}</h1>", "<h2>Study</h2>", "<ul>"]
    body += [f"<li><b>{esc(k)}</b>: {esc(v)}</li>" for k, v in _settings(analysis)]
    body += ["</ul>", "<h3>Factors</h3>", table(_factor_table(analysis.study))]
    if analysis.warnings:
        body += ["<h2>Warnings</h2>", '<ul class="warn">'] + [f"<li>{esc(w)}</li>" for w in analysis.warnings]
        body += ["</ul>"]
    body += ["<h2>Diagnostics</h2>", f"<p>{esc(_DIAGNOSTICS_TEXT)}</p>", table(_diagnostics_table(analysis))]
    body += ["<h2>Significant factors</h2>", "<ul>"]
    body += [f"<li>{esc(_summary_line(r))}</li>" for r in analysis.fits.values()] + ["</ul>"]
    for scenario, result in analysis.fits.items():
        body += [f"<h2>Scenario {esc(scenario)}</h2>", f"<p>{esc(ranking(result, analysis.study.factors))}</p>",
                 f"<p>{esc(_method_text(result))}</p>", "<h3>Errors</h3>",
                 f"<p>{esc(_best_cell_text(analysis, scenario))}</p>", table(_error_table(analysis.tables, scenario)),
                 "<h3>Receiver versus instrumentation</h3>", table(_comparison_table(analysis.tables, scenario)),
                 "<h3>Effects</h3>", table(_effects_view(result)),
                 f"<h3>ANOVA ({esc(result.anova_type)})</h3>", table(result.anova), "<h3>Figures</h3>"]
        body += [image(path, f"{scenario}: {_FIGURE_TITLES[kind]}") for kind, path in figures.get(scenario, {}).items()]
    body += ["<h2>References</h2>", "<ul>"] + [f"<li>{esc(r)}</li>" for r in _REFERENCES] + ["</ul>"]
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>Factorial analysis: {esc(analysis.study.name)}</title><style>{_CSS}</style></head>\n<body>\n"
            + "\n".join(body) + "\n</body></html>\n")
