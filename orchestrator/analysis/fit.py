"""The two-level factorial model of one scenario: terms, model matrix, response transform, OLS fit with
statsmodels, Lenth's PSE and the checks of the model's assumptions."""

from __future__ import annotations

import itertools
import warnings as _warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import pandas as pd
from scipy import optimize, stats

from sblsim.orchestrator.analysis.data import AnalysisError, check_metric, check_order, check_transform

ANOVA_TYPE = 2
#: A diagnostic test below this p-value is reported as a failed assumption [-].
DIAGNOSTIC_P = 0.01
#: Columns of ``diagnostics.csv`` after ``scenario`` (:func:`diagnose`).
DIAGNOSTIC_COLUMNS = ("metric", "transform", "lambda", "lambda_ci_low", "lambda_ci_high", "n", "df_resid", "r2",
                      "r2_adj", "bp_stat", "bp_p", "cell_sd_ratio", "jb_stat", "jb_p", "skew", "kurtosis",
                      "share_fitted_nonpositive", "warning")


@dataclass
class FitResult:
    """OLS fit of one scenario's response on the coded factors.

    Attributes
    ----------
    scenario : str
    metric : str
        Response column (:data:`~sblsim.orchestrator.analysis.data.RESPONSES`: an error [m] or
        ``detected_pct`` [%]; the unit of the values below).
        Factor names in design order.
    order : int
        Highest interaction order of the model.
    alpha : float
        Significance level [-].
    effects : pandas.DataFrame
        ``term, effect, coefficient, std_err, t, p_value`` (no Intercept row);
        effect and coefficient [m] (on the transformed scale with a
        transform), ``std_err`` of the coefficient, t [-]; with ``log`` also
        ``ratio = exp(effect)`` [-].
    intercept : float
        Intercept = grand mean of the (transformed) response in a balanced design [m].
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
    transform : str
        ``none``, ``log`` or ``boxcox``: the fit, effects, residuals and
        ANOVA are on this scale of the response.
    lmbda : float or None
        Box-Cox λ (maximum likelihood) [-]; None unless ``transform == "boxcox"``.
    lmbda_ci : tuple of float or None
        95 % likelihood-ratio interval of λ [-].
    diagnostics : dict
        The checks of the model's assumptions (:func:`diagnose`).
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
    transform: str = "none"
    lmbda: float | None = None
    lmbda_ci: tuple[float, float] | None = None
    diagnostics: dict = field(default_factory=dict)

    @property
    def response(self) -> str:
        """Name of the fitted response: ``e_tot_rms``, ``log(e_tot_rms)`` or ``boxcox(e_tot_rms)``."""
        return self.metric if self.transform == "none" else f"{self.transform}({self.metric})"

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


def boxcox_lambda(y: np.ndarray, X: np.ndarray, bounds: tuple[float, float] = (-3.0, 3.0)
                  ) -> tuple[float, tuple[float, float]]:
    """Box-Cox λ of a linear model by maximum likelihood, with its 95 % likelihood-ratio interval.

    The profile log-likelihood of λ for ``y(λ) = X β + ε``, ε ~ N(0, σ²)
    (Box and Cox 1964) is ``ℓ(λ) = −n/2 · log(RSS(λ)/n) + (λ − 1) · Σ log y``,
    where ``RSS(λ)`` is the residual sum of squares of the OLS fit
    (statsmodels) of :func:`scipy.stats.boxcox` ``(y, λ)`` on ``X``; it is
    maximised with :func:`scipy.optimize.minimize_scalar`. Unlike
    :func:`scipy.stats.boxcox` without ``lmbda`` (the λ that makes ``y``
    itself look normal), this is the λ that makes the *residuals* of the
    factorial model look normal with a constant variance.

    Parameters
    ----------
    y : ndarray
        Positive response [m].
    X : ndarray
        Model matrix (with the intercept column).
    bounds : tuple of float
        Search interval of λ [-].

    Returns
    -------
    lmbda : float
        Maximum-likelihood λ [-].
    ci : tuple of float
        ``{λ : 2 (ℓ(λ̂) − ℓ(λ)) ≤ χ²_{1, 0.95}}`` (clipped to ``bounds``) [-].

    References
    ----------
    .. [1] G. E. P. Box and D. R. Cox, "An analysis of transformations",
       J. R. Stat. Soc. B, 26(2), pp. 211-252, 1964.
    """
    import statsmodels.api as sm

    y = np.asarray(y, dtype=float)
    n, log_sum = len(y), float(np.log(y).sum())

    def loglik(lam: float) -> float:
        rss = sm.OLS(stats.boxcox(y, lmbda=lam), X).fit().ssr
        return -n / 2.0 * np.log(rss / n) + (lam - 1.0) * log_sum

    best = optimize.minimize_scalar(lambda lam: -loglik(lam), bounds=bounds, method="bounded",
                                    options={"xatol": 1e-6})
    lam, top = float(best.x), -float(best.fun)
    cut = top - stats.chi2.ppf(0.95, 1) / 2.0
    ends = []
    for edge in bounds:
        if loglik(edge) >= cut:
            ends.append(float(edge))
        else:
            ends.append(float(optimize.brentq(lambda v: loglik(v) - cut, *sorted((edge, lam)), xtol=1e-6)))
    return lam, (ends[0], ends[1])


def diagnose(model, y_raw: np.ndarray, transform: str = "none", lmbda: float | None = None,
             cells: np.ndarray | None = None) -> dict:
    """Checks of the OLS model's assumptions: fit, constant variance, normality, impossible fitted values.

    Parameters
    ----------
    model : statsmodels.regression.linear_model.RegressionResults
        The fit (on the transformed scale).
    y_raw : ndarray
        The untransformed response of the rows fitted [m].
    transform : str
        ``none``, ``log`` or ``boxcox``.
    lmbda : float, optional
        Box-Cox λ [-].
    cells : ndarray, optional
        Design cell of each row fitted (for ``cell_sd_ratio``).

    Returns
    -------
    dict
        ``r2``, ``r2_adj``; ``bp_stat``, ``bp_p``: Breusch-Pagan test of a
        variance that changes with the model's terms (statsmodels
        ``het_breuschpagan``, Koenker's studentized form); ``cell_sd_ratio``:
        largest over smallest standard deviation of the residuals within a
        design cell (the size of the unequal variance that the test detects;
        NaN unless every cell has 2 runs or more); ``jb_stat``,
        ``jb_p``, ``skew``, ``kurtosis`` (3 for a normal law): Jarque-Bera test
        of normal residuals (statsmodels ``jarque_bera``);
        ``share_fitted_nonpositive``: share of the fitted values that stand for
        a response <= 0 although every observed one is > 0 (``none``: fitted
        <= 0; ``boxcox``: ``1 + λ·fitted <= 0``, no back-transform; ``log``:
        0; NaN when the response is not positive). Tests are NaN without
        residual degrees of freedom.
    """
    from statsmodels.stats.diagnostic import het_breuschpagan
    from statsmodels.stats.stattools import jarque_bera

    fitted = np.asarray(model.fittedvalues, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):  # a constant response: R² is NaN
        out = {"r2": float(model.rsquared), "r2_adj": float(model.rsquared_adj)}
    resid = np.asarray(model.resid, dtype=float)
    if round(model.df_resid) > 0 and np.ptp(resid) > 0:
        lm, lm_p, _, _ = het_breuschpagan(resid, model.model.exog)
        jb, jb_p, skew, kurt = jarque_bera(resid)
        out.update(bp_stat=float(lm), bp_p=float(lm_p), jb_stat=float(jb), jb_p=float(jb_p), skew=float(skew),
                   kurtosis=float(kurt))
    else:
        out.update(bp_stat=np.nan, bp_p=np.nan, jb_stat=np.nan, jb_p=np.nan, skew=np.nan, kurtosis=np.nan)
    out["cell_sd_ratio"] = np.nan
    if cells is not None:
        groups = pd.Series(resid).groupby(np.asarray(cells))
        sd = groups.std(ddof=1)
        if (groups.size() >= 2).all() and sd.min() > 0:
            out["cell_sd_ratio"] = float(sd.max() / sd.min())
    if not (np.asarray(y_raw) > 0).all():
        share = np.nan
    elif transform == "none":
        share = float((fitted <= 0).mean())
    elif transform == "boxcox" and lmbda is not None and lmbda != 0:
        share = float((1.0 + lmbda * fitted <= 0).mean())
    else:
        share = 0.0
    out["share_fitted_nonpositive"] = share
    return out


def assumption_warning(diag: dict, transform: str, metric: str) -> str:
    """One line naming the failed assumptions of a fit (empty when none failed).

    An assumption fails when the Breusch-Pagan or the Jarque-Bera p-value is
    below :data:`DIAGNOSTIC_P`, or when fitted values stand for a
    response <= 0 of a positive metric. Untransformed, the line suggests
    ``--transform log``.
    """
    parts = []
    if diag.get("bp_p", np.nan) < DIAGNOSTIC_P:
        ratio = diag.get("cell_sd_ratio", np.nan)
        size = (f"; the largest residual std of a cell is {ratio:.3g} times the smallest" if np.isfinite(ratio)
                else "")
        parts.append(f"the residuals' variance changes with the terms (Breusch-Pagan p = {diag['bp_p']:.2g}{size})")
    if diag.get("jb_p", np.nan) < DIAGNOSTIC_P:
        parts.append(f"the residuals are not normal (Jarque-Bera p = {diag['jb_p']:.2g}, skew "
                     f"{diag['skew']:.2f}, kurtosis {diag['kurtosis']:.2f} against 3)")
    share = diag.get("share_fitted_nonpositive", np.nan)
    if share > 0:
        parts.append(f"{100 * share:.3g} % of the fitted values are <= 0 for a positive {metric}")
    if not parts:
        return ""
    text = "model assumptions fail: " + "; ".join(parts) + ": the t and p values are approximate"
    if transform == "none" and np.isfinite(share):
        text += " (try --transform log: effects as factors, often a constant variance)"
    else:
        text += " (the effects are still the contrasts of the cell means; compare the residual plots)"
    return text


def fit(frame: pd.DataFrame, factors: Sequence[str], metric: str = "e_tot_rms", order: int = 2,
        alpha: float = 0.05, scenario: str = "", transform: str = "none") -> FitResult:
    """Fit the two-level factorial model of one scenario by OLS (statsmodels).

    Parameters
    ----------
    frame : pandas.DataFrame
        Runs of one scenario: the coded factor columns (−1/+1) and ``metric``.
    factors : sequence of str
        Factor names in design order.
    metric : str
        Response column (:data:`~sblsim.orchestrator.analysis.data.RESPONSES`) [m] or [%].
    order : int
        Highest interaction order, 1 .. len(factors).
    alpha : float
        Significance level [-], 0 < alpha < 1.
    scenario : str
        Label of the scenario (messages and result).
    transform : str
        ``none`` (the metric), ``log`` (its natural logarithm: an effect is
        the log of the ratio HIGH/LOW of the geometric means) or ``boxcox``
        (:func:`scipy.stats.boxcox` with λ of :func:`boxcox_lambda`). The
        metric must be > 0 for ``log`` and ``boxcox``.

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
        Unknown metric or transform, bad order, coded values other than
        −1/+1, a value <= 0 for ``log`` / ``boxcox``, or no estimable effect.

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
    check_transform(transform, frame, metric)
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
    if len(y) and np.ptp(y) == 0:  # e.g. detected_pct at 100 % in every run: the levels change nothing
        notes.append(f"{metric} is {y[0]:.6g} in every run: no factor changes it (every effect is 0)")
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
    lmbda, lmbda_ci = None, None
    if transform == "log":
        df["y"] = np.log(y)
    elif transform == "boxcox":
        lmbda, lmbda_ci = boxcox_lambda(y, X[kept].to_numpy())
        df["y"] = stats.boxcox(y, lmbda=lmbda)
    else:
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
    if transform == "log":
        effects["ratio"] = np.exp(effect)
    diag = diagnose(model, y, transform, lmbda, data["cell"].to_numpy() if "cell" in data.columns else None)
    diag.update(metric=metric, transform=transform, n=len(y), df_resid=df_resid,
                **{"lambda": np.nan if lmbda is None else lmbda,
                   "lambda_ci_low": np.nan if lmbda_ci is None else lmbda_ci[0],
                   "lambda_ci_high": np.nan if lmbda_ci is None else lmbda_ci[1]})
    diag["warning"] = assumption_warning(diag, transform, metric)
    if diag["warning"]:
        notes.append(diag["warning"])
    return FitResult(scenario=scenario, metric=metric, factors=factors, order=order, alpha=alpha,
                     effects=effects, intercept=float(params["Intercept"]), anova=anova, anova_type=anova_type,
                     fitted=model.fittedvalues.to_numpy(), resid=model.resid.to_numpy(), df_resid=df_resid,
                     critical=critical, method=method, pse=pse, n=len(y), dropped=dropped, warnings=notes,
                     transform=transform, lmbda=lmbda, lmbda_ci=lmbda_ci,
                     diagnostics={k: diag[k] for k in DIAGNOSTIC_COLUMNS})
