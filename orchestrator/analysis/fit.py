"""The two-level factorial model of one scenario: terms, model matrix, OLS fit with statsmodels, Lenth's PSE."""

from __future__ import annotations

import itertools
import warnings as _warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from sblsim.orchestrator.analysis.data import AnalysisError, check_metric, check_order

ANOVA_TYPE = 2


@dataclass
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


def model_terms(factors: Sequence[str], order: int) -> list[tuple[str, ...]]:
    """Terms of the model: every combination of up to ``order`` factors, lowest order first."""
    return [t for r in range(1, order + 1) for t in itertools.combinations(factors, r)]


def term_name(term: Sequence[str]) -> str:
    """``('baseline', 'gps')`` -> ``'baseline:gps'``."""
    return ":".join(term)


def model_matrix(frame: pd.DataFrame, factors: Sequence[str], order: int) -> pd.DataFrame:
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
    X = model_matrix(data, factors, order)
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
