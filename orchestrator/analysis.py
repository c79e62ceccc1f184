"""Factorial analysis of a campaign: effects, ANOVA, tables and the report.

Input: a campaign directory holding ``runs.parquet`` (one row per Monte Carlo
run: ``scenario``, ``scenario_key``, ``cell``, ``replicate``, ``seed``, per
factor ``NAME`` coded −1/+1 and ``NAME_value`` physical level, and the
metrics of :mod:`orchestrator.metrics` for the receiver and, prefixed ``instr_``,
for the instrumentation fix) and ``study.toml`` (the resolved study: design,
replicates, seed, scenarios and one ``[[factors]]`` table per factor). Without
``study.toml`` the factors are the columns that have a ``NAME_value`` partner.

Per scenario, the response (``e_tot_rms`` by default) is regressed by ordinary
least squares on the coded factors with every interaction up to ``order``
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
    ``effect`` and ``coefficient`` are in the response's unit [m]; ``std_err``
    is the standard error of the coefficient [m] (Lenth: PSE / 2); ``t`` is
    the standardized effect [-].
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

import base64
import html
import itertools
import math
import re
import tomllib
import warnings as _warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from models.core import ModelError
from orchestrator.metrics import METRIC_NAMES
from orchestrator.output import staged_directory

#: Metric columns a response may be taken from (the receiver's, then the instrumentation's).
METRICS = tuple(METRIC_NAMES) + tuple(f"instr_{m}" for m in METRIC_NAMES)
#: Columns ``runs.parquet`` must hold besides the factors and the metrics.
REQUIRED_COLUMNS = ("scenario", "cell", "replicate")
#: Figure kinds written per scenario, in report order.
FIGURES = ("pareto", "main_effects", "interactions", "residuals")
ANOVA_TYPE = 2
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
def _estimators(frame: pd.DataFrame) -> tuple[tuple[str, str], ...]:
    """(name, metric prefix) of the receiver that ran in ``frame`` and of the instrumentation."""
    names = sorted(frame["receiver"].dropna().unique()) if "receiver" in frame.columns else []
    return (("+".join(names) or "receiver", ""), ("instrumentation", "instr_"))


class AnalysisError(ModelError):
    """Bad analysis input; the one-line message names the file or option at fault."""


@dataclass(frozen=True)
class Factor:
    """One two-level factor of the study.

    Attributes
    ----------
    name : str
        Identifier; the coded column of ``runs.parquet``.
    low, high : float or str
        Physical levels at coded −1 and +1 [unit] (text for a text key, e.g. a receiver).
    unit : str
        Unit of the levels, e.g. ``m``, ``deg``, ``s``, ``%``.
    key : str
        Configuration key the factor sets, e.g. ``platform.baseline``.
    description : str
    """

    name: str
    low: float | str
    high: float | str
    unit: str = ""
    key: str = ""
    description: str = ""


@dataclass
class Study:
    """The resolved study (``study.toml``) or what could be inferred from ``runs.parquet``.

    Attributes
    ----------
    name : str
    seed : int or None
        Campaign seed.
    replicates : int or None
        Runs per design cell.
    design : str
        ``full``, ``fractional`` or ``unknown`` (inferred).
    resolution : int
        Resolution of a fractional design (0 otherwise).
    generators : str
        Generators of a fractional design.
    scenarios : list of str
    engine : str
    factors : list of Factor
        In design order.
    inferred : bool
        True when ``study.toml`` was missing.
    """

    name: str
    seed: int | None
    replicates: int | None
    design: str
    resolution: int
    generators: str
    scenarios: list[str]
    engine: str
    factors: list[Factor]
    inferred: bool = False


@dataclass
class FitResult:
    """OLS fit of one scenario's response on the coded factors.

    Attributes
    ----------
    scenario : str
    metric : str
        Response column.
    factors : list of str
        Factor names in design order.
    order : int
        Highest interaction order of the model.
    alpha : float
        Significance level [-].
    effects : pandas.DataFrame
        ``term, effect, coefficient, std_err, t, p_value`` (no Intercept row);
        effect and coefficient [m], ``std_err`` of the coefficient [m], t [-].
    intercept : float
        Intercept = grand mean of the response in a balanced design [m].
    anova : pandas.DataFrame
        ``term, df, sum_sq, mean_sq, F, p_value`` with a ``Residual`` row.
    anova_type : str
        ``Type II`` or, for a saturated model, ``Type I (sequential)``.
    fitted, resid : ndarray
        Fitted values and residuals [m], in the order of the rows used.
    df_resid : int
        Residual degrees of freedom.
    critical : float
        Significance line for ``|t|``: ``t_{1−α/2, df_resid}`` or, with
        Lenth's method, ``t_{1−α/2, m/3}``.
    method : str
        ``t`` (OLS residual error) or ``lenth`` (pseudo standard error).
    pse : float or None
        Lenth's pseudo standard error of the effects [m].
    n : int
        Runs used.
    dropped : list of str
        Terms left out as aliased or not estimable.
    warnings : list of str
    """

    scenario: str
    metric: str
    factors: list[str]
    order: int
    alpha: float
    effects: pd.DataFrame
    intercept: float
    anova: pd.DataFrame
    anova_type: str
    fitted: np.ndarray
    resid: np.ndarray
    df_resid: int
    critical: float
    method: str
    pse: float | None
    n: int
    dropped: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def significant(self) -> pd.DataFrame:
        """Significant terms (``p_value < alpha``), largest ``|t|`` first."""
        sig = self.effects[self.effects["p_value"] < self.alpha]
        return sig.reindex(sig["t"].abs().sort_values(ascending=False).index)


@dataclass
class Analysis:
    """Everything the report shows.

    Attributes
    ----------
    study : Study
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
    """

    study: Study
    runs: pd.DataFrame
    metric: str
    order: int
    alpha: float
    fits: dict[str, FitResult]
    tables: pd.DataFrame
    warnings: list[str]


# --------------------------------------------------------------------------- input


def load_runs(directory: Path | str) -> pd.DataFrame:
    """Read ``DIR/runs.parquet``.

    Raises
    ------
    AnalysisError
        The file is missing, unreadable, empty or lacks a required column.
    """
    path = Path(directory) / "runs.parquet"
    if not path.is_file():
        raise AnalysisError(f"runs.parquet: no such file {str(path)!r}; run a campaign first")
    try:
        frame = pd.read_parquet(path)
    except Exception as exc:  # pyarrow raises several types for a corrupt file
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise AnalysisError(f"runs.parquet: cannot read {str(path)!r} ({reason})") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise AnalysisError(f"runs.parquet: missing column(s) {', '.join(missing)} in {str(path)!r}")
    if frame.empty:
        raise AnalysisError(f"runs.parquet: {str(path)!r} holds no runs")
    frame = frame.copy()
    frame["scenario"] = frame["scenario"].astype(str)
    return frame


def infer_factors(runs: pd.DataFrame) -> list[Factor]:
    """Factors from the columns of ``runs.parquet``: every ``NAME`` with a ``NAME_value`` partner.

    The physical levels are the values of ``NAME_value`` where ``NAME`` is −1
    and +1 (NaN if a level never occurs); the unit is unknown.
    """
    factors = []
    for col in runs.columns:
        if col in METRICS or not isinstance(col, str) or f"{col}_value" not in runs.columns:
            continue
        levels = []
        for code in (-1, 1):
            values = runs.loc[runs[col] == code, f"{col}_value"]
            levels.append(level_value(values.iloc[0]) if len(values) else math.nan)
        factors.append(Factor(col, levels[0], levels[1]))
    return factors


def load_study(directory: Path | str, runs: pd.DataFrame) -> tuple[Study, list[str]]:
    """Read ``DIR/study.toml``, or infer the study from ``runs`` when it is missing.

    Returns
    -------
    study : Study
    warnings : list of str

    Raises
    ------
    AnalysisError
        A corrupt ``study.toml``, a factor that is not an identifier, or a
        factor without a coded column in ``runs.parquet``.
    """
    path = Path(directory) / "study.toml"
    notes: list[str] = []
    scen = _scenario_order(runs)
    if not path.is_file():
        factors = infer_factors(runs)
        notes.append("study.toml not found: the factors are inferred from the columns of runs.parquet "
                     "(NAME with a NAME_value partner); units and descriptions are unknown")
        seeds = runs["seed"].unique() if "seed" in runs.columns else []
        per_cell = runs.groupby(["scenario", "cell"]).size()
        study = Study(name=Path(directory).name, seed=int(seeds[0]) if len(seeds) == 1 else None,
                      replicates=int(per_cell.max()) if per_cell.nunique() == 1 else None,
                      design="unknown", resolution=0, generators="", scenarios=scen, engine="",
                      factors=factors, inferred=True)
    else:
        try:
            raw = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise AnalysisError(f"study.toml: cannot parse {str(path)!r} ({exc})") from None
        s = raw.get("study", {})
        try:
            factors = [Factor(name=str(f["name"]), low=level_value(f["low"]), high=level_value(f["high"]),
                              unit=str(f.get("unit", "")), key=str(f.get("key", "")),
                              description=str(f.get("description", "")))
                       for f in raw.get("factors", [])]
            study = Study(name=str(s.get("name", Path(directory).name)),
                          seed=int(s["seed"]) if "seed" in s else None,
                          replicates=int(s["replicates"]) if "replicates" in s else None,
                          design=str(s.get("design", "full")), resolution=int(s.get("resolution", 0)),
                          generators=str(s.get("generators", "")),
                          scenarios=[str(x) for x in s.get("scenarios", scen)],
                          engine=str(raw.get("execution", {}).get("engine", s.get("engine", ""))),
                          factors=factors)
        except (KeyError, TypeError, ValueError) as exc:
            raise AnalysisError(f"study.toml: invalid entry in {str(path)!r} ({type(exc).__name__}: {exc})") from None
        absent = [x for x in study.scenarios if x not in scen]
        if absent:
            notes.append(f"scenario(s) {', '.join(absent)} of study.toml have no run in runs.parquet")
    if not study.factors:
        raise AnalysisError("factors: none found (study.toml lists no [[factors]] and runs.parquet "
                            "has no NAME/NAME_value column pair)")
    for f in study.factors:
        if not _NAME.match(f.name):
            raise AnalysisError(f"factors: name {f.name!r} is not an identifier (letters, digits, underscore)")
        if f.name not in runs.columns:
            raise AnalysisError(f"runs.parquet: no coded column for factor {f.name!r}")
    names = [f.name for f in study.factors]
    if len(set(names)) != len(names):
        raise AnalysisError(f"factors: duplicate names in {', '.join(names)}")
    return study, notes


def _scenario_order(runs: pd.DataFrame) -> list[str]:
    if "scenario_key" in runs.columns:
        runs = runs.sort_values("scenario_key", kind="stable")
    return list(dict.fromkeys(runs["scenario"]))


def allowed_metrics(frame: pd.DataFrame) -> list[str]:
    """Metric columns of :data:`METRICS` present in ``frame``."""
    return [m for m in METRICS if m in frame.columns]


def check_metric(metric: str, frame: pd.DataFrame) -> None:
    """Raise :class:`AnalysisError` unless ``metric`` is a metric column of ``frame``."""
    allowed = allowed_metrics(frame)
    if metric not in allowed:
        if metric in METRICS:
            raise AnalysisError(f"runs.parquet: has no {metric!r} column (not written by a finished campaign?); "
                                f"--metric can be one of {', '.join(allowed) or '(no metric column)'}")
        raise AnalysisError(f"metric: {metric!r} is not one of {', '.join(allowed) or '(no metric column)'}")


def check_order(order: Any, k: int) -> int:
    """Validate the model order against the number of factors ``k``; return it as int."""
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 1 <= order <= k:
        raise AnalysisError(f"order: {order!r} is outside the allowed range [1, {k}] (1 = main effects, "
                            f"{k} = full model with {k} factors)")
    return int(order)


# --------------------------------------------------------------------------- model


def model_terms(factors: Sequence[str], order: int) -> list[tuple[str, ...]]:
    """Terms of the model: every combination of up to ``order`` factors, lowest order first."""
    return [t for r in range(1, order + 1) for t in itertools.combinations(factors, r)]


def term_name(term: Sequence[str]) -> str:
    """``('baseline', 'gps')`` -> ``'baseline:gps'``."""
    return ":".join(term)


def design_matrix(frame: pd.DataFrame, factors: Sequence[str], order: int) -> pd.DataFrame:
    """Model matrix with named columns: ``Intercept`` and one contrast column per term.

    The column of a term is the product of its factors' coded (−1/+1) columns.
    """
    coded = {f: frame[f].to_numpy(dtype=float) for f in factors}
    cols = {"Intercept": np.ones(len(frame))}
    for term in model_terms(factors, order):
        cols[term_name(term)] = np.prod([coded[f] for f in term], axis=0)
    return pd.DataFrame(cols, index=frame.index)


def _estimable(X: pd.DataFrame) -> tuple[list[str], list[str], list[str]]:
    """Greedy rank check: keep a column unless it lies in the span of the kept ones."""
    kept, dropped, notes = [], [], []
    basis = np.zeros((len(X), 0))
    for name in X.columns:
        v = X[name].to_numpy()
        r = v - basis @ (basis.T @ v)
        if np.linalg.norm(r) > 1e-8 * max(np.linalg.norm(v), 1.0):
            kept.append(name)
            basis = np.column_stack([basis, r / np.linalg.norm(r)])
            continue
        dropped.append(name)
        alias = next((k for k in kept if np.allclose(v, X[k]) or np.allclose(v, -X[k])), None)
        if alias is not None:
            sign = "" if np.allclose(v, X[alias]) else "−"
            notes.append(f"term {name} is aliased with {sign}{alias}: left out of the model")
        else:
            notes.append(f"term {name} is a linear combination of other terms: left out of the model")
    return kept, dropped, notes


def lenth_pse(effects: np.ndarray) -> float:
    """Lenth's pseudo standard error of the effects.

    ``s0 = 1.5·median|c_j|``, ``PSE = 1.5·median{|c_j| : |c_j| < 2.5·s0}``.

    Parameters
    ----------
    effects : ndarray
        Effect estimates c_j [m].

    Returns
    -------
    float
        PSE [m]; 0 when no effect is below ``2.5·s0`` (e.g. all zero).

    References
    ----------
    .. [1] R. V. Lenth, "Quick and easy analysis of unreplicated factorials",
       Technometrics, 31(4), pp. 469-473, 1989.
    """
    a = np.abs(np.asarray(effects, dtype=float))
    s0 = 1.5 * np.median(a)
    small = a[a < 2.5 * s0]
    return float(1.5 * np.median(small)) if small.size else 0.0


def fit(frame: pd.DataFrame, factors: Sequence[str], metric: str = "e_tot_rms", order: int = 2,
        alpha: float = 0.05, scenario: str = "") -> FitResult:
    """Fit the two-level factorial model of one scenario by OLS (statsmodels).

    Parameters
    ----------
    frame : pandas.DataFrame
        Runs of one scenario: the coded factor columns (−1/+1) and ``metric``.
    factors : sequence of str
        Factor names in design order.
    metric : str
        Response column [m].
    order : int
        Highest interaction order, 1 .. len(factors).
    alpha : float
        Significance level [-], 0 < alpha < 1.
    scenario : str
        Label of the scenario (messages and result).

    Returns
    -------
    FitResult
        Effects (``effect = 2·coefficient``, the Yates contrast
        ``mean(y | +) − mean(y | −)`` of a balanced design), ANOVA, residuals
        and the significance line. With no residual degrees of freedom the
        t values are ``effect / PSE`` and the line ``t_{1−α/2, m/3}`` (Lenth).

    Raises
    ------
    AnalysisError
        Unknown metric, bad order, coded values other than −1/+1, or no
        estimable effect.

    References
    ----------
    .. [1] D. C. Montgomery, Design and Analysis of Experiments, 9th ed., Wiley, 2017, ch. 6.
    .. [2] R. V. Lenth, Technometrics, 31(4), pp. 469-473, 1989.
    """
    import statsmodels.formula.api as smf
    from statsmodels.stats.anova import anova_lm

    factors = list(factors)
    order = check_order(order, len(factors))
    check_metric(metric, frame)
    if not 0.0 < alpha < 1.0:
        raise AnalysisError(f"alpha: {alpha!r} is outside the allowed range (0, 1)")
    where = f"{scenario}: " if scenario else ""
    notes: list[str] = []
    for f in factors:
        bad = ~frame[f].isin([-1, 1])
        if bad.any():
            raise AnalysisError(f"runs.parquet: {where}factor {f!r} has coded values other than -1/+1 "
                                f"({frame.loc[bad, f].iloc[0]!r})")
    y = frame[metric].to_numpy(dtype=float)
    finite = np.isfinite(y)
    if not finite.all():
        notes.append(f"{int((~finite).sum())} run(s) with a non-finite {metric} left out")
    data = frame.loc[finite]
    y = y[finite]
    X = design_matrix(data, factors, order)
    kept, dropped, alias_notes = _estimable(X)
    notes += alias_notes
    terms = [t for t in kept if t != "Intercept"]
    if "Intercept" not in kept or not terms:
        raise AnalysisError(f"runs.parquet: {where}{len(y)} run(s) with a finite {metric} cannot estimate any effect")

    # Formula on safe variable names: factor names such as T, C, Q or range never meet patsy's syntax.
    safe = {f: f"x{i}" for i, f in enumerate(factors)}
    back = {}
    for t in terms:
        back[":".join(safe[f] for f in t.split(":"))] = t
    df = pd.DataFrame({safe[f]: data[f].to_numpy(dtype=float) for f in factors})
    df["y"] = y
    model = smf.ols("y ~ " + " + ".join(back), data=df).fit()
    params = model.params.rename(index=back)
    coef = params[terms].to_numpy()
    effect = 2.0 * coef
    df_resid = round(model.df_resid)
    pse = None
    if df_resid > 0:
        method = "t"
        bse = model.bse.rename(index=back)[terms].to_numpy()
        tval = model.tvalues.rename(index=back)[terms].to_numpy()
        pval = model.pvalues.rename(index=back)[terms].to_numpy()
        critical = float(stats.t.ppf(1.0 - alpha / 2.0, df_resid))
        table = anova_lm(model, typ=ANOVA_TYPE)
        anova_type = "Type II"
    else:
        method = "lenth"
        m = len(effect)
        pse = lenth_pse(effect)
        dof = m / 3.0
        critical = float(stats.t.ppf(1.0 - alpha / 2.0, dof))
        notes.append(f"no residual degrees of freedom (saturated model: {len(y)} runs, {m + 1} parameters): "
                     f"t values and the significance line use Lenth's pseudo standard error "
                     f"(PSE = {pse:.4g}, critical value t(1-alpha/2, m/3 = {dof:.3g}) = {critical:.4g})")
        with np.errstate(divide="ignore", invalid="ignore"):
            tval = effect / pse if pse > 0 else np.full(m, np.nan)
        if not pse > 0:
            notes.append("Lenth's pseudo standard error is zero: no t value can be computed")
        bse = np.full(m, pse / 2.0)
        pval = 2.0 * stats.t.sf(np.abs(tval), dof)
        with _warnings.catch_warnings(), np.errstate(divide="ignore", invalid="ignore"):
            _warnings.simplefilter("ignore")
            table = anova_lm(model, typ=1)
        table["F"] = np.nan
        table["PR(>F)"] = np.nan
        anova_type = "Type I (sequential)"
    effects = pd.DataFrame({"term": terms, "effect": effect, "coefficient": coef, "std_err": bse,
                            "t": tval, "p_value": pval})
    anova = pd.DataFrame({"term": [back.get(i, i) for i in table.index],
                          "df": table["df"].to_numpy(dtype=float),
                          "sum_sq": table["sum_sq"].to_numpy(dtype=float)})
    with np.errstate(divide="ignore", invalid="ignore"):
        anova["mean_sq"] = anova["sum_sq"] / anova["df"]
    anova.loc[anova["df"] == 0, "mean_sq"] = np.nan
    anova["F"] = table["F"].to_numpy(dtype=float)
    anova["p_value"] = table["PR(>F)"].to_numpy(dtype=float)
    return FitResult(scenario=scenario, metric=metric, factors=factors, order=order, alpha=alpha,
                     effects=effects, intercept=float(params["Intercept"]), anova=anova, anova_type=anova_type,
                     fitted=model.fittedvalues.to_numpy(), resid=model.resid.to_numpy(), df_resid=df_resid,
                     critical=critical, method=method, pse=pse, n=len(y), dropped=dropped, warnings=notes)


# --------------------------------------------------------------------------- tables


def best_cell(frame: pd.DataFrame, metric: str) -> int:
    """Design cell with the lowest mean ``metric`` over its runs (NaN runs left out)."""
    means = frame.groupby("cell")[metric].mean()
    if means.isna().all():
        raise AnalysisError(f"runs.parquet: {metric} is NaN in every run")
    return int(means.idxmin())


def tables(frame: pd.DataFrame, metric: str = "e_tot_rms", scenario: str = "") -> pd.DataFrame:
    """Error tables of one scenario in the tidy layout of ``tables.csv``.

    Parameters
    ----------
    frame : pandas.DataFrame
        Runs of one scenario.
    metric : str
        Response that picks the best cell (lowest mean).
    scenario : str

    Returns
    -------
    pandas.DataFrame
        ``scenario, table, subset, cell, estimator, statistic, value``: see
        the module documentation; values [m] except ``n`` [-].
    """
    cell = best_cell(frame, metric)
    rows = []
    for subset, part, c in (("all runs", frame, pd.NA), ("best cell", frame[frame["cell"] == cell], cell)):
        for estimator, prefix in _estimators(part):
            for a in ("e_x", "e_y", "e_z", "e_tot"):
                col = f"{prefix}{a}_mean"
                if col in part.columns:
                    rows.append((scenario, "errors", subset, c, estimator, a, float(part[col].mean())))
    for estimator, prefix in _estimators(frame):
        col = f"{prefix}e_tot_mean"
        if col in frame.columns:
            v = frame[col].dropna()
            rows += [(scenario, "receiver_vs_instr", "all runs", pd.NA, estimator, "mean", float(v.mean())),
                     (scenario, "receiver_vs_instr", "all runs", pd.NA, estimator, "std",
                      float(v.std(ddof=1)) if len(v) > 1 else math.nan),
                     (scenario, "receiver_vs_instr", "all runs", pd.NA, estimator, "n", float(len(v)))]
    out = pd.DataFrame(rows, columns=["scenario", "table", "subset", "cell", "estimator", "statistic", "value"])
    out["cell"] = out["cell"].astype("Int64")
    return out


# --------------------------------------------------------------------------- analysis


def compute(directory: Path | str, metric: str = "e_tot_rms", order: int = 2, alpha: float = 0.05) -> Analysis:
    """Read a campaign directory and fit every scenario (nothing is written).

    Parameters
    ----------
    directory : path
        Campaign directory with ``runs.parquet`` (and ``study.toml``).
    metric : str
        Response column, one of :data:`METRICS` [m].
    order : int
        Highest interaction order, 1 .. number of factors.
    alpha : float
        Significance level [-].

    Returns
    -------
    Analysis

    Raises
    ------
    AnalysisError
        Missing or corrupt ``runs.parquet``, corrupt ``study.toml``, unknown
        metric, bad order or alpha.
    """
    runs = load_runs(directory)
    study, notes = load_study(directory, runs)
    check_metric(metric, runs)
    names = [f.name for f in study.factors]
    order = check_order(order, len(names))
    if not 0.0 < alpha < 1.0:
        raise AnalysisError(f"alpha: {alpha!r} is outside the allowed range (0, 1)")
    present = _scenario_order(runs)
    scenarios = [s for s in study.scenarios if s in present] + [s for s in present if s not in study.scenarios]
    fits, parts = {}, []
    if study.replicates == 1 or (runs.groupby(["scenario", "cell"]).size() == 1).all():
        notes.append("no replicates: there is no pure error; the residual error (if any) comes from the terms "
                     "left out of the model")
    for scenario in scenarios:
        frame = runs[runs["scenario"] == scenario]
        result = fit(frame, names, metric, order, alpha, scenario)
        fits[scenario] = result
        notes += [f"{scenario}: {w}" for w in result.warnings]
        parts.append(tables(frame, metric, scenario))
    return Analysis(study=study, runs=runs, metric=metric, order=order, alpha=alpha, fits=fits,
                    tables=pd.concat(parts, ignore_index=True), warnings=notes)


def analyze(directory: Path | str, out: Path | str | None = None, metric: str = "e_tot_rms", order: int = 2,
            alpha: float = 0.05) -> Path:
    """Analyse a campaign and write the effects, ANOVA, tables, figures and report.

    Parameters
    ----------
    directory : path
        Campaign directory with ``runs.parquet`` and ``study.toml``.
    out : path, optional
        Output directory (default ``directory``).
    metric : str
        Response column, one of :data:`METRICS` [m]; default ``e_tot_rms``.
    order : int
        Highest interaction order of the model, 1 .. number of factors;
        default 2 (main effects and two-factor interactions).
    alpha : float
        Significance level [-]; default 0.05.

    Returns
    -------
    Path
        ``out``, holding ``effects.csv``, ``anova.csv``, ``tables.csv``,
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
    analysis = compute(directory, metric, order, alpha)
    return write(analysis, Path(out) if out is not None else Path(directory))


def write(analysis: Analysis, out: Path | str) -> Path:
    """Write the outputs of an :class:`Analysis` into ``out`` atomically; return ``out``."""
    from orchestrator.analysis_plots import save_figures

    out = Path(out).absolute()
    with staged_directory(out) as tmp:
        fig_dir = tmp / "figures"
        fig_dir.mkdir()
        factors = analysis.study.factors
        figures: dict[str, dict[str, str]] = {}
        used: set[str] = set()
        for scenario, result in analysis.fits.items():
            stem = _file_stem(scenario, used)
            frame = analysis.runs[analysis.runs["scenario"] == scenario]
            paths = save_figures(result, frame, factors, fig_dir, stem)
            figures[scenario] = {kind: f"figures/{p.name}" for kind, p in paths.items()}
        effects = pd.concat([r.effects.assign(scenario=s) for s, r in analysis.fits.items()], ignore_index=True)
        effects[["scenario", "term", "effect", "coefficient", "std_err", "t", "p_value"]].to_csv(
            tmp / "effects.csv", index=False)
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


# --------------------------------------------------------------------------- report text

_METRIC_WORDS = {"e_x_mean": "mean e_x", "e_y_mean": "mean e_y", "e_z_mean": "mean e_z",
                 "e_tot_mean": "mean e_tot", "e_tot_rms": "RMS e_tot", "e_tot_std": "std of e_tot"}


def metric_label(metric: str) -> str:
    """Plain words for a metric column, e.g. ``instr_e_tot_rms`` -> ``instrumentation RMS e_tot``."""
    if metric.startswith("instr_"):
        return "instrumentation " + _METRIC_WORDS.get(metric[6:], metric[6:])
    return _METRIC_WORDS.get(metric, metric)


def level_value(value: Any) -> float | str:
    """A factor level as read from a file: a number, or the text of a text key (e.g. ``ekf-seq``)."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return float(value)


def format_level(value: float | str | None, unit: str = "") -> str:
    """A level for tables and figures: ``3 m``, ``ekf-seq``, or ``?`` when unknown."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "?"
    text = value if isinstance(value, str) else f"{value:g}"
    return f"{text} {unit}" if unit else text


def ranking(result: FitResult, factors: Sequence[Factor]) -> str:
    """Plain-language ranking of the significant terms of one scenario, largest ``|t|`` first.

    Main effects say what going from the low to the high level does to the
    response and which level is better (lower error); two-factor
    interactions say how much the first factor's effect changes between the
    levels of the second (twice the interaction effect, Montgomery 2017, §6.2).
    """
    by_name = {f.name: f for f in factors}
    what = metric_label(result.metric)
    sig = result.significant
    test = "Lenth's method" if result.method == "lenth" else "t test"
    head = f"{result.scenario}: "
    if sig.empty:
        return head + f"no term is significant at alpha = {result.alpha:g} ({test})."
    parts = []
    for row in sig.itertuples():
        names = row.term.split(":")
        e = row.effect
        if len(names) == 1:
            f = by_name[names[0]]
            verb = "raises" if e > 0 else "lowers"
            better = "low" if e > 0 else "high"
            parts.append(f"{row.term} (effect {e:+.3g} m: going from {format_level(f.low, f.unit)} to "
                         f"{format_level(f.high, f.unit)} {verb} {what} by {abs(e):.3g} m; the {better} level "
                         f"({format_level(f.low if better == 'low' else f.high, f.unit)}) is better)")
        elif len(names) == 2:
            a, b = names
            more = "larger" if e > 0 else "smaller"
            parts.append(f"{row.term} (interaction effect {e:+.3g} m: the effect of {a} is {abs(2 * e):.3g} m "
                         f"{more} at high {b} ({format_level(by_name[b].high, by_name[b].unit)}) than at low {b} "
                         f"({format_level(by_name[b].low, by_name[b].unit)}))")
        else:
            parts.append(f"{row.term} (interaction effect {e:+.3g} m)")
    return (head + f"the significant terms (alpha = {result.alpha:g}, {test}), largest first: "
            + "; ".join(parts) + ".")


def _design_text(study: Study, runs: pd.DataFrame) -> str:
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
        ("response", f"{analysis.metric} ({metric_label(analysis.metric)}) [m]"),
        ("model", f"OLS on the coded factors (-1/+1), interactions up to order {analysis.order}"),
        ("significance", f"alpha = {analysis.alpha:g}, two-sided"),
        ("ANOVA", "Type II sums of squares (Type I for a saturated model; equal for an orthogonal design)"),
    ]


def _factor_table(study: Study) -> pd.DataFrame:
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
    return (f"best cell: {cell} (lowest mean {analysis.metric} = {mean:.4g} m): " + ", ".join(levels))


def _effects_view(result: FitResult) -> pd.DataFrame:
    e = result.effects.copy()
    e["significant"] = np.where(e["p_value"] < result.alpha, "yes", "")
    return e


def _method_text(result: FitResult) -> str:
    if result.method == "lenth":
        return (f"{result.n} runs, no residual degrees of freedom: Lenth's pseudo standard error "
                f"PSE = {result.pse:.4g} m, t = effect / PSE, significance line t(1-alpha/2, m/3) = "
                f"{result.critical:.4g}; grand mean {result.intercept:.4g} m.")
    return (f"{result.n} runs, {result.df_resid} residual degrees of freedom, significance line "
            f"t(1-alpha/2, {result.df_resid}) = {result.critical:.4g}; grand mean {result.intercept:.4g} m.")


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
    lines += ["## Significant factors", ""]
    lines += [f"- {ranking(r, analysis.study.factors)}" for r in analysis.fits.values()] + [""]
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
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}
th{background:#eee}img{max-width:100%;display:block;margin:0.5em 0}.warn{color:#a40}"""


def report_html(analysis: Analysis, figures: dict[str, dict[str, str]], root: Path | str) -> str:
    """``report.html``: as :func:`report_markdown`, self-contained (figures as base64 data URIs).

    ``root`` is the directory the figure paths are relative to.
    """
    esc = html.escape

    def table(frame: pd.DataFrame) -> str:
        return frame.to_html(index=False, float_format=_FLOAT, na_rep="", border=0)

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
    body += ["<h2>Significant factors</h2>", "<ul>"]
    body += [f"<li>{esc(ranking(r, analysis.study.factors))}</li>" for r in analysis.fits.values()] + ["</ul>"]
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
