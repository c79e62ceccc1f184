"""Factorial analysis against independent computations on synthetic 2^4 designs."""

from __future__ import annotations

import itertools
import math
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from scipy import stats  # noqa: E402

from sblsim.models.errors import CampaignError  # noqa: E402
from sblsim.orchestrator.analysis import AnalysisError, analyze, compute, fit, lenth_pse, tables  # noqa: E402
from sblsim.orchestrator.analysis import plots as analysis_plots  # noqa: E402
from sblsim.orchestrator.analysis.plots import plot_interactions, plot_main_effects, plot_pareto, plot_residuals  # noqa: E402
from sblsim.orchestrator.cosim.metrics import METRIC_NAMES  # noqa: E402

# Names chosen to clash with formula syntax and Python builtins.
FACTORS = ("baseline", "range", "T", "gps")
LEVELS = {"baseline": (0.4, 3.0, "m"), "range": (0.1, 1.0, "m"), "T": (0.1, 1.0, "s"), "gps": (0.1, 3.5, "m")}
#: Planted effects [m] (effect = 2 × coefficient); every other term is zero.
PLANTED = {"range": 0.8, "T": -0.5, "baseline:T": 0.4}
NOISE = 0.05  # [m]
MEAN = 2.0  # [m]


#: The receiver the synthetic runs name; the tables call its estimator by it.
ESTIMATOR = "ekf-seq"


def _design(replicates: int, seed: int = 7, scenario: str = "semicircle", key: int = 0) -> pd.DataFrame:
    """Runs of a full 2^4 design: planted effects plus Gaussian noise on every metric."""
    rng = np.random.default_rng(seed)
    rows = []
    for cell, codes in enumerate(itertools.product((-1, 1), repeat=len(FACTORS))):
        x = dict(zip(FACTORS, codes))
        for rep in range(replicates):
            row = {"scenario": scenario, "scenario_key": key, "cell": cell, "replicate": rep, "seed": 1,
                   "receiver": ESTIMATOR}
            for name in FACTORS:
                low, high, _ = LEVELS[name]
                row[name] = x[name]
                row[f"{name}_value"] = low if x[name] < 0 else high
            y = MEAN + sum(e / 2 * np.prod([x[f] for f in t.split(":")]) for t, e in PLANTED.items())
            for prefix, scale in (("", 1.0), ("instr_", 1.7)):
                for m in METRIC_NAMES:
                    row[prefix + m] = scale * y + rng.normal(0.0, NOISE)
            rows.append(row)
    return pd.DataFrame(rows)


def _study_toml(replicates: int, scenarios=("semicircle",)) -> str:
    head = (f'[study]\nname = "test"\nseed = 1\nreplicates = {replicates}\ndesign = "full"\nresolution = 0\n'
            f'generators = ""\nscenarios = {list(scenarios)!r}\nengine = "local"\n'.replace("'", '"'))
    body = "".join(f'\n[[factors]]\nname = "{n}"\nkey = "x.{n}"\nlow = {LEVELS[n][0]}\nhigh = {LEVELS[n][1]}\n'
                   f'unit = "{LEVELS[n][2]}"\ndescription = "factor {n}"\n' for n in FACTORS)
    return head + body


def _campaign(path: Path, replicates: int = 3, scenarios=("semicircle", "spiral"), study: bool = True) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    frame = pd.concat([_design(replicates, seed=10 + k, scenario=s, key=k) for k, s in enumerate(scenarios)],
                      ignore_index=True)
    frame.to_parquet(path / "runs.parquet", index=False)
    if study:
        (path / "study.toml").write_text(_study_toml(replicates, scenarios))
    return path


def _yates(frame: pd.DataFrame, term: str, metric: str = "e_tot_rms") -> float:
    """Classical contrast: mean response where the term's column is + minus where it is −."""
    sign = np.prod([frame[f].to_numpy() for f in term.split(":")], axis=0)
    y = frame[metric].to_numpy()
    return y[sign > 0].mean() - y[sign < 0].mean()


def _all_terms(order: int) -> list[str]:
    return [":".join(t) for r in range(1, order + 1) for t in itertools.combinations(FACTORS, r)]


# --------------------------------------------------------------------------- statistics


def test_effects_match_yates_and_planted_terms_are_significant():
    frame = _design(replicates=3)
    result = fit(frame, FACTORS, "e_tot_rms", order=2)
    terms = _all_terms(2)
    assert list(result.effects["term"]) == terms
    effects = result.effects.set_index("term")
    for term in terms:
        assert effects.loc[term, "effect"] == pytest.approx(_yates(frame, term), abs=1e-10)
        assert effects.loc[term, "coefficient"] == pytest.approx(effects.loc[term, "effect"] / 2, abs=1e-12)
    # independent least squares: residual variance and the standard error of an orthogonal ±1 column
    X = np.column_stack([np.ones(len(frame))] + [np.prod([frame[f] for f in t.split(":")], axis=0) for t in terms])
    beta, rss, *_ = np.linalg.lstsq(X, frame["e_tot_rms"].to_numpy(), rcond=None)
    df_resid = len(frame) - X.shape[1]
    assert result.df_resid == df_resid == 48 - 11
    se = math.sqrt(rss[0] / df_resid / len(frame))
    np.testing.assert_allclose(effects["std_err"], se, rtol=1e-9)
    np.testing.assert_allclose(effects["t"], beta[1:] / se, rtol=1e-9)
    np.testing.assert_allclose(effects["p_value"], 2 * stats.t.sf(np.abs(beta[1:] / se), df_resid), rtol=1e-7)
    assert set(result.significant["term"]) == set(PLANTED)
    assert list(result.significant["term"]) == ["range", "T", "baseline:T"]  # largest |t| first
    assert result.method == "t" and result.pse is None
    # ANOVA (Type II): for orthogonal ±1 columns SS = N·β², residual SS = RSS
    assert list(result.anova["term"]) == terms + ["Residual"] and result.anova_type == "Type II"
    anova = result.anova.set_index("term")
    np.testing.assert_allclose(anova.loc[terms, "sum_sq"], len(frame) * beta[1:] ** 2, rtol=1e-9)
    assert anova.loc["Residual", "sum_sq"] == pytest.approx(rss[0], rel=1e-9)
    assert anova.loc["Residual", "df"] == df_resid


def test_order_one_and_full_model_term_counts():
    frame = _design(replicates=2)
    assert len(fit(frame, FACTORS, order=1).effects) == 4
    full = fit(frame, FACTORS, order=4)
    assert len(full.effects) == 15 and full.df_resid == 32 - 16
    assert full.effects["term"].iloc[-1] == "baseline:range:T:gps"


def test_unreplicated_full_model_falls_back_to_lenth():
    frame = _design(replicates=1)
    result = fit(frame, FACTORS, "e_tot_rms", order=4)
    assert result.df_resid == 0 and result.method == "lenth"
    assert any("Lenth" in w for w in result.warnings)
    c = np.array([_yates(frame, t) for t in _all_terms(4)])
    np.testing.assert_allclose(result.effects["effect"], c, atol=1e-10)
    s0 = 1.5 * np.median(np.abs(c))
    pse = 1.5 * np.median(np.abs(c)[np.abs(c) < 2.5 * s0])
    assert result.pse == pytest.approx(pse, rel=1e-12) and lenth_pse(c) == pytest.approx(pse, rel=1e-12)
    np.testing.assert_allclose(result.effects["t"], c / pse, rtol=1e-10)
    assert result.critical == pytest.approx(stats.t.ppf(0.975, 15 / 3), rel=1e-12)
    np.testing.assert_allclose(result.effects["p_value"], 2 * stats.t.sf(np.abs(c / pse), 5), rtol=1e-10)
    # 12 null effects at alpha = 0.05 may give a false positive: the planted terms must lead the ranking
    assert list(result.significant["term"])[:3] == ["range", "T", "baseline:T"]


def test_aliased_terms_of_a_half_fraction_are_dropped_with_a_warning():
    frame = _design(replicates=2)
    half = frame[frame["gps"] == frame["baseline"] * frame["range"] * frame["T"]]  # 2^(4-1), D = ABC
    result = fit(half, FACTORS, order=2)
    assert len(result.effects) == 4 + 3  # three 2fi alias pairs: one of each kept
    # in design order AB, AC, AD are kept; BC = AD, BD = AC, CD = AB are left out
    assert result.dropped == ["range:T", "range:gps", "T:gps"]
    assert any("range:T is aliased with baseline:gps" in w for w in result.warnings)
    effects = result.effects.set_index("term")["effect"]
    assert effects["baseline:gps"] == pytest.approx(_yates(half, "baseline:gps"), abs=1e-10)


# --------------------------------------------------------------------------- figures


def test_pareto_line_is_the_t_quantile_and_bars_are_sorted():
    result = fit(_design(replicates=3), FACTORS, order=2)
    fig, ax = plt.subplots()
    try:
        assert plot_pareto(result, ax) is fig
        bars = ax.patches
        assert len(bars) == len(result.effects) == 10
        widths = [b.get_width() for b in sorted(bars, key=lambda b: b.get_y())]
        assert widths == sorted(widths)  # largest at the top
        assert max(widths) == pytest.approx(result.effects["t"].abs().max())
        vertical = [ln for ln in ax.get_lines() if len(set(ln.get_xdata())) == 1]
        assert len(vertical) == 1
        assert vertical[0].get_xdata()[0] == pytest.approx(stats.t.ppf(0.975, 48 - 11), rel=1e-12)
    finally:
        plt.close(fig)


def test_panel_counts_of_the_other_figures():
    frame = _design(replicates=2)
    result = fit(frame, FACTORS, order=2)
    k = len(FACTORS)
    fig, axes = plt.subplots(2, 3)
    plot_main_effects(frame, FACTORS, "e_tot_rms", axes)
    assert len(fig.axes) == k  # the spare panels are removed
    ax0 = fig.axes[0]
    low, high = ax0.get_lines()[0].get_ydata()
    assert low == pytest.approx(frame.loc[frame["baseline"] < 0, "e_tot_rms"].mean())
    assert high == pytest.approx(frame.loc[frame["baseline"] > 0, "e_tot_rms"].mean())
    assert ax0.get_lines()[1].get_ydata()[0] == pytest.approx(frame["e_tot_rms"].mean())  # dotted grand mean
    assert ax0.get_lines()[1].get_linestyle() == ":"
    plt.close(fig)
    fig, axes = plt.subplots(k, k)
    plot_interactions(frame, FACTORS, "e_tot_rms", axes)
    assert len(fig.axes) == k * k
    assert all(len(axes[i, i].get_lines()) == 0 and axes[i, i].texts[0].get_text() == FACTORS[i] for i in range(k))
    assert all(len(axes[i, j].get_lines()) == 2 for i in range(k) for j in range(k) if i != j)
    plt.close(fig)
    fig, axes = plt.subplots(2, 2)
    plot_residuals(result, axes)
    assert len(fig.axes) == 4
    assert len(axes[0, 1].patches) > 0  # histogram
    np.testing.assert_allclose(axes[1, 1].get_lines()[0].get_ydata(), result.resid)
    plt.close(fig)


# --------------------------------------------------------------------------- report


@pytest.mark.slow
def test_analyze_writes_csvs_figures_and_reports(tmp_path):
    src = _campaign(tmp_path / "campaign", replicates=3)
    out = analyze(src, out=tmp_path / "out")
    assert out == (tmp_path / "out").absolute()
    effects = pd.read_csv(out / "effects.csv")
    assert list(effects.columns) == ["scenario", "term", "effect", "coefficient", "std_err", "t", "p_value"]
    assert len(effects) == 2 * 10 and "Intercept" not in set(effects["term"])
    runs = pd.read_parquet(src / "runs.parquet")
    spiral = runs[runs["scenario"] == "spiral"]
    got = effects[effects["scenario"] == "spiral"].set_index("term")["effect"]
    assert got["baseline:T"] == pytest.approx(_yates(spiral, "baseline:T"), abs=1e-10)
    anova = pd.read_csv(out / "anova.csv")
    assert list(anova.columns[:2]) == ["scenario", "term"] and set(anova["scenario"]) == {"semicircle", "spiral"}
    pngs = sorted((out / "figures").glob("*.png"))
    assert len(pngs) == 2 * 4
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 8
    assert "<img" in html and 'src="figures/' not in html  # self-contained
    md = (out / "report.md").read_text()
    refs = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert len(refs) == 8 and all((out / r).is_file() for r in refs)
    assert sorted(out / r for r in refs) == pngs
    for text in (md, html):
        assert "full 2^4 factorial" in text and "replicates per cell" in text
        assert re.search(r"range \(effect \+0\.(79|80)\d* m: going from 0\.1 m to 1 m raises RMS e_tot", text)
        assert "the low level (0.1 m) is better" in text
        assert re.search(r"; T \(effect -0\.(49|50|51)\d* m: going from 0\.1 s to 1 s lowers", text)
        assert "the high level (1 s) is better" in text
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp dir left


def test_tables_against_pandas(tmp_path):
    frame = _design(replicates=3)
    tab = tables(frame, "e_tot_rms", "semicircle")
    cell = int(frame.groupby("cell")["e_tot_rms"].mean().idxmin())
    row = frame[frame["cell"] == cell].iloc[0]  # planted: range +0.8, T -0.5, baseline:T +0.4
    assert (row["baseline"], row["range"], row["T"]) == (-1, -1, 1)
    def value(**kw):
        sel = tab
        for k, v in kw.items():
            sel = sel[sel[k] == v]
        assert len(sel) == 1
        return sel["value"].iloc[0]
    best = frame[frame["cell"] == cell]
    assert value(table="errors", subset="all runs", estimator=ESTIMATOR, statistic="e_x") == pytest.approx(
        frame["e_x_mean"].mean())
    assert value(table="errors", subset="best cell", estimator="instrumentation", statistic="e_tot") == pytest.approx(
        best["instr_e_tot_mean"].mean())
    assert (tab.loc[tab["subset"] == "best cell", "cell"] == cell).all()
    assert value(table="receiver_vs_instr", estimator="instrumentation", statistic="std") == pytest.approx(
        frame["instr_e_tot_mean"].std(ddof=1))
    assert value(table="receiver_vs_instr", estimator=ESTIMATOR, statistic="mean") == pytest.approx(
        frame["e_tot_mean"].mean())


@pytest.mark.slow
def test_unreplicated_campaign_states_lenth_in_report(tmp_path):
    src = _campaign(tmp_path / "c", replicates=1, scenarios=("random",))
    analysis = compute(src, order=4)
    assert any("Lenth" in w for w in analysis.warnings)
    out = analyze(src, order=4)
    assert out == src.absolute()
    assert "Lenth" in (out / "report.md").read_text() and "Lenth" in (out / "report.html").read_text()
    assert len(pd.read_csv(out / "effects.csv")) == 15


def test_missing_study_infers_factors(tmp_path):
    src = _campaign(tmp_path / "c", replicates=2, scenarios=("semicircle",), study=False)
    analysis = compute(src)
    assert [f.name for f in analysis.study.factors] == list(FACTORS)
    assert analysis.study.factors[1].low == 0.1 and analysis.study.factors[1].high == 1.0
    assert any("study.toml not found" in w for w in analysis.warnings)


# --------------------------------------------------------------------------- bad input


def _one_line_error(excinfo) -> str:
    message = str(excinfo.value)
    assert isinstance(excinfo.value, CampaignError) and "\n" not in message  # the kind of an analysis's errors
    return message


def test_unknown_metric(tmp_path):
    src = _campaign(tmp_path / "c", replicates=2, scenarios=("semicircle",))
    with pytest.raises(AnalysisError) as excinfo:
        analyze(src, out=tmp_path / "out", metric="e_tot_max")
    message = _one_line_error(excinfo)
    assert message.startswith("metric: 'e_tot_max'") and "e_tot_rms" in message and "instr_e_tot_std" in message
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("order", [0, 5])
def test_bad_order(tmp_path, order):
    src = _campaign(tmp_path / "c", replicates=2, scenarios=("semicircle",))
    with pytest.raises(AnalysisError) as excinfo:
        analyze(src, out=tmp_path / "out", order=order)
    message = _one_line_error(excinfo)
    assert message.startswith("order:") and "[1, 4]" in message


def test_corrupt_and_missing_runs(tmp_path):
    src = tmp_path / "c"
    src.mkdir()
    with pytest.raises(AnalysisError) as excinfo:
        analyze(src, out=tmp_path / "out")
    assert "runs.parquet" in _one_line_error(excinfo)
    (src / "runs.parquet").write_bytes(b"PAR1 this is not a parquet file\n\x00\x01")
    with pytest.raises(AnalysisError) as excinfo:
        analyze(src, out=tmp_path / "out")
    assert "runs.parquet" in _one_line_error(excinfo)
    assert not (tmp_path / "out").exists()


def test_error_while_writing_leaves_nothing(tmp_path, monkeypatch):
    src = _campaign(tmp_path / "c", replicates=2, scenarios=("semicircle",))
    out = tmp_path / "out"

    def boom(*args, **kwargs):
        raise RuntimeError("plot failed")

    monkeypatch.setattr(analysis_plots, "plot_residuals", boom)
    with pytest.raises(RuntimeError):
        analyze(src, out=out)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c"]


# --------------------------------------------------------------------------- transforms and diagnostics

#: Planted effects on log(response) [-]: exp(effect) is the ratio HIGH/LOW of the geometric means.
LOG_PLANTED = {"range": 2.0, "T": -1.2, "baseline:T": 0.6}
LOG_NOISE = 0.3  # standard deviation of log(response) [-]


def _multiplicative(replicates: int = 8, seed: int = 3, scenario: str = "semicircle", key: int = 0) -> pd.DataFrame:
    """Runs of a full 2^4 design whose metrics are exp(log 2 + planted effects / 2 · contrast + noise)."""
    rng = np.random.default_rng(seed)
    frame = _design(replicates, seed=seed, scenario=scenario, key=key)
    log_y = math.log(2.0) + sum(e / 2 * np.prod([frame[f].to_numpy() for f in t.split(":")], axis=0)
                                for t, e in LOG_PLANTED.items())
    for prefix in ("", "instr_"):
        for m in METRIC_NAMES:
            frame[prefix + m] = np.exp(log_y + rng.normal(0.0, LOG_NOISE, len(frame)))
    return frame


def _multiplicative_campaign(path: Path, scenarios=("semicircle",)) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    frame = pd.concat([_multiplicative(seed=20 + k, scenario=s, key=k) for k, s in enumerate(scenarios)],
                      ignore_index=True)
    frame.to_parquet(path / "runs.parquet", index=False)
    (path / "study.toml").write_text(_study_toml(8, scenarios))
    return path


def _log_contrast(frame: pd.DataFrame, term: str, metric: str = "e_tot_rms") -> float:
    """Mean of log(metric) where the term's column is + minus the mean where it is −."""
    sign = np.prod([frame[f].to_numpy() for f in term.split(":")], axis=0)
    z = np.log(frame[metric].to_numpy())
    return z[sign > 0].mean() - z[sign < 0].mean()


@pytest.mark.slow
def test_log_effects_are_contrasts_of_the_log_and_ratios_of_geometric_means(tmp_path):
    src = _multiplicative_campaign(tmp_path / "c")
    runs = pd.read_parquet(src / "runs.parquet")
    out = analyze(src, out=tmp_path / "out", transform="log")
    effects = pd.read_csv(out / "effects.csv").set_index("term")
    assert list(effects.columns)[-1] == "ratio"
    for term in _all_terms(2):
        assert effects.loc[term, "effect"] == pytest.approx(_log_contrast(runs, term), abs=1e-10)
    y = runs["e_tot_rms"].to_numpy()
    high, low = y[runs["range"] > 0], y[runs["range"] < 0]
    geometric = np.exp(np.log(high).mean()) / np.exp(np.log(low).mean())
    assert effects.loc["range", "ratio"] == pytest.approx(geometric, rel=1e-10)
    assert effects.loc["range", "ratio"] == pytest.approx(math.exp(2.0), rel=0.15)  # planted x7.4
    md = (out / "report.md").read_text()
    ratio = effects.loc["range", "ratio"]
    assert f"going from 0.1 m to 1 m multiplies RMS e_tot by {ratio:.3g}" in md
    t_ratio = effects.loc["T", "ratio"]
    assert f"going from 0.1 s to 1 s multiplies RMS e_tot by {t_ratio:.3g}" in md
    assert "the high level (1 s) is better" in md


@pytest.mark.slow
def test_diagnostics_flag_the_untransformed_fit_of_a_multiplicative_response(tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    src = _multiplicative_campaign(tmp_path / "c")
    assert main(["analyze", str(src), "--out", str(tmp_path / "raw")]) == 0
    raw_err = capsys.readouterr().err
    assert main(["analyze", str(src), "--out", str(tmp_path / "log"), "--transform", "log"]) == 0
    captured = capsys.readouterr()
    log_err = captured.err
    assert "semicircle: significant terms, largest first: range (x" in captured.out
    raw = pd.read_csv(tmp_path / "raw" / "diagnostics.csv", keep_default_na=False).iloc[0]
    log = pd.read_csv(tmp_path / "log" / "diagnostics.csv", keep_default_na=False).iloc[0]
    assert (raw["transform"], log["transform"]) == ("none", "log")
    assert raw["bp_p"] < 1e-3 and raw["cell_sd_ratio"] > 10  # the spread grows with the response
    assert log["bp_p"] > 0.05 and log["jb_p"] > 0.05 and log["cell_sd_ratio"] < 4
    assert log["r2"] > raw["r2"]
    assert log["share_fitted_nonpositive"] == 0.0
    assert "Breusch-Pagan" in raw["warning"] and "--transform log" in raw["warning"]
    assert log["warning"] == ""
    note = [ln for ln in raw_err.splitlines() if ln.startswith("note: semicircle: model assumptions fail")]
    assert len(note) == 1 and "try --transform log" in note[0]
    assert "model assumptions fail" not in log_err
    assert "model assumptions fail" in (tmp_path / "raw" / "report.md").read_text()
    assert "## Diagnostics" in (tmp_path / "log" / "report.md").read_text()


def test_negative_fitted_values_of_a_positive_response_are_counted():
    frame = _design(replicates=2)
    frame["e_tot_rms"] = np.where(frame["range"] > 0, 10.0, 0.05) * np.where(frame["T"] > 0, 1.0, 0.02)
    frame["e_tot_rms"] += np.random.default_rng(0).uniform(0.0, 0.01, len(frame))
    result = fit(frame, FACTORS, "e_tot_rms", order=1)
    share = float((result.fitted <= 0).mean())
    assert share > 0 and result.diagnostics["share_fitted_nonpositive"] == pytest.approx(share)
    assert any("of the fitted values are <= 0" in w for w in result.warnings)
    assert fit(frame, FACTORS, "e_tot_rms", order=1, transform="log").diagnostics["share_fitted_nonpositive"] == 0


@pytest.mark.slow
def test_boxcox_lambda_is_the_maximum_likelihood_of_the_model_and_near_zero_for_a_log_normal_response():
    frame = _multiplicative()
    result = fit(frame, FACTORS, "e_tot_rms", order=2, transform="boxcox")
    lam = result.lmbda
    assert abs(lam) < 0.15 and result.lmbda_ci[0] < 0.0 < result.lmbda_ci[1]
    # independent profile likelihood on a grid (numpy least squares)
    y = frame["e_tot_rms"].to_numpy()
    X = np.column_stack([np.ones(len(frame))] + [np.prod([frame[f] for f in t.split(":")], axis=0)
                                                 for t in _all_terms(2)])
    grid = np.linspace(-0.3, 0.3, 6001)  # step 1e-4

    def loglik(g):
        z = np.log(y) if g == 0 else (y ** g - 1) / g
        rss = np.sum((z - X @ np.linalg.lstsq(X, z, rcond=None)[0]) ** 2)
        return -len(y) / 2 * np.log(rss / len(y)) + (g - 1) * np.log(y).sum()

    # the λ of the model's residuals, not scipy's λ of the response alone (1.2e-3 away here)
    assert lam == pytest.approx(grid[np.argmax([loglik(g) for g in grid])], abs=2e-4)
    assert abs(lam - stats.boxcox(y)[1]) > 5e-4
    effects = result.effects.set_index("term")["effect"]
    z = stats.boxcox(y, lmbda=lam)
    sign = frame["range"].to_numpy()
    assert effects["range"] == pytest.approx(z[sign > 0].mean() - z[sign < 0].mean(), abs=1e-10)
    assert result.diagnostics["lambda"] == lam and result.response == "boxcox(e_tot_rms)"


@pytest.mark.slow
@pytest.mark.parametrize("transform", ["log", "boxcox"])
def test_transform_of_a_non_positive_metric_is_one_line(tmp_path, transform):
    src = _campaign(tmp_path / "c", replicates=2, scenarios=("semicircle",))
    runs = pd.read_parquet(src / "runs.parquet")
    runs.loc[[0, 5, 9], "e_tot_rms"] = [0.0, -1.0, -0.5]
    runs.to_parquet(src / "runs.parquet", index=False)
    with pytest.raises(AnalysisError) as excinfo:
        analyze(src, out=tmp_path / "out", transform=transform)
    assert _one_line_error(excinfo).startswith(f"--transform {transform}: metric e_tot_rms has 3 values <= 0")
    assert not (tmp_path / "out").exists()
    analyze(src, out=tmp_path / "out", metric="e_tot_mean", transform=transform)  # another, positive metric


def test_unknown_transform(tmp_path):
    src = _campaign(tmp_path / "c", replicates=2, scenarios=("semicircle",))
    with pytest.raises(AnalysisError) as excinfo:
        analyze(src, out=tmp_path / "out", transform="sqrt")
    assert _one_line_error(excinfo).startswith("transform: 'sqrt' is not one of none, log, boxcox")
