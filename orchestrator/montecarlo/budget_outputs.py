"""The outputs of ``sblsim budget``: a budget's printed lines and advice, the rows of ``budget.csv``, the
Markdown of ``budget.md``, the figure ``budget.png``, and the files written together (:func:`write`).

The budgets are :mod:`sblsim.orchestrator.montecarlo.budget`'s (docs/model.md, "Error budget").
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from sblsim.orchestrator.cosim.config import to_toml
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.montecarlo.budget import NO_EFFECT, OFF, ON, Budget


def _pm(value: float, se: float, total: float, spec: str = ".3g") -> str:
    """``value ± se`` [m²]; a standard error at rounding level (below 1e-12 of the total) shows as 0."""
    shown = 0.0 if abs(se) <= 1e-12 * abs(total) else se
    return f"{value:{spec}} ± {shown:.2g}"


def lines(b: Budget) -> list[str]:
    """The printed lines of a budget: one per source, largest first, then the floor, remainder and total."""
    width = max(len(n) for n in b.table["source"]) + 1

    def share(value: float) -> str:
        return f"{100 * value / b.total:5.1f} %" if b.total > 0 else "   n/a"

    out = []
    for r in b.table.itertuples():
        if r.status == OFF:
            out.append(f"  {r.source + ':':<{width}} off in this configuration")
        elif r.status == NO_EFFECT:
            out.append(f"  {r.source + ':':<{width}} 0 (no effect: every run unchanged)")
        else:
            out.append(f"  {r.source + ':':<{width}} {_pm(r.contribution, r.se, b.total)} m² "
                       f"({share(r.contribution)}), RMS {r.rms:.3f} m")
    out.append(f"  {'floor:':<{width}} {_pm(b.floor, b.floor_se, b.total)} m² ({share(b.floor)}): the receiver "
               "with every source off")
    out.append(f"  {'remainder:':<{width}} {_pm(b.remainder, b.remainder_se, b.total)} m² ({share(b.remainder)}): "
               "interactions")
    out.append(f"  {'total:':<{width}} {_pm(b.total, b.total_se, b.total)} m² (RMS e_tot {math.sqrt(b.total):.3f} m)")
    return out


def advice(b: Budget) -> str:
    """One sentence: which source to improve first."""
    first = b.first()
    if not first:
        return ("No source contributes more than twice its standard error: the error is the receiver's floor "
                "and the interactions (or more replicates are needed).")
    rows = [b.table[b.table["source"] == n].iloc[0] for n in first]
    if len(rows) == 1:
        return (f"Improve {first[0]} ({rows[0]['description']}) first: switched off, it removes "
                f"{100 * rows[0]['share']:.0f} % of the mean squared error.")
    named = ", ".join(f"{r['source']} ({100 * r['share']:.0f} %)" for r in rows[:-1])
    return (f"Improve {named} or {rows[-1]['source']} ({100 * rows[-1]['share']:.0f} %) first: their contributions "
            "to the mean squared error are equal within two standard errors of their paired difference.")


def table(budgets: Sequence[Budget], key: str | None = None) -> pd.DataFrame:
    """The rows of ``budget.csv``: every source, then floor, remainder and total (with the compared value
    first when ``key`` is given)."""
    frames = []
    for b in budgets:
        extra = pd.DataFrame([
            {"source": "floor", "description": "every source off", "status": "", "contribution": b.floor,
             "se": b.floor_se},
            {"source": "remainder", "description": "interactions", "status": "", "contribution": b.remainder,
             "se": b.remainder_se},
            {"source": "total", "description": "every source on", "status": "", "contribution": b.total,
             "se": b.total_se}])
        extra["share"] = extra["contribution"] / b.total if b.total > 0 else math.nan
        extra["rms"] = np.sqrt(np.maximum(extra["contribution"], 0.0))
        frame = pd.concat([b.table, extra], ignore_index=True)
        if key is not None:
            frame.insert(0, key, b.label.split(" = ", 1)[1])
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def _cell(row: Any, total: float) -> str:
    if row["status"] == OFF:
        return "off"
    if row["status"] == NO_EFFECT:
        return "0 (no effect)"
    return f"{_pm(row['contribution'], row['se'], total)} ({100 * row['contribution'] / total:.1f} %)"


def markdown(budgets: Sequence[Budget], key: str | None = None) -> str:
    """The budget as Markdown: one table (a column per compared value), the total, floor and remainder, and
    which source to improve first."""
    if len(budgets) == 1:
        b = budgets[0]
        lines_ = ["| source | what | contribution [m²] (± se) | share | RMS [m] |", "|---|---|---|---|---|"]
        for _, r in b.table.iterrows():
            if r["status"] == ON:
                value = _pm(r["contribution"], r["se"], b.total, ".4g")
                lines_.append(f"| {r['source']} | {r['description']} | {value} | {100 * r['share']:.1f} % "
                              f"| {r['rms']:.3f} |")
            else:
                lines_.append(f"| {r['source']} | {r['description']} | {r['status']} | 0 % | 0 |")
        lines_ += ["", *_summary(b), "", advice(b)]
        return "\n".join(lines_) + "\n"
    order = _order(budgets)
    head = "| source | " + " | ".join(b.label.split(" = ", 1)[1] for b in budgets) + " |"
    lines_ = [f"Contribution to the MSE [m²] (± se) and share, per {key}:", "", head,
              "|---|" + "---|" * len(budgets)]
    for name in order:
        cells = [_cell(b.table[b.table["source"] == name].iloc[0], b.total) for b in budgets]
        lines_.append(f"| {name} | " + " | ".join(cells) + " |")
    for what, attr in (("floor", "floor"), ("remainder", "remainder"), ("total", "total")):
        cells = [_pm(getattr(b, attr), getattr(b, attr + "_se"), b.total)
                 + (f" ({100 * getattr(b, attr) / b.total:.1f} %)" if what != "total" else
                    f" (RMS {math.sqrt(b.total):.3f} m)") for b in budgets]
        lines_.append(f"| **{what}** | " + " | ".join(cells) + " |")
    lines_.append("")
    lines_ += [f"{b.label}: {advice(b)}" for b in budgets]
    return "\n".join(lines_) + "\n"


def _summary(b: Budget) -> list[str]:
    share = (lambda v: f"{100 * v / b.total:.1f} %") if b.total > 0 else (lambda v: "n/a")
    return [f"* total: {_pm(b.total, b.total_se, b.total, '.4g')} m² (RMS e_tot {math.sqrt(b.total):.3f} m), every "
            "source on",
            f"* floor: {_pm(b.floor, b.floor_se, b.total, '.4g')} m² ({share(b.floor)}), every source off: the "
            "receiver's own lag, start-up and the staleness of held ranges",
            f"* remainder: {_pm(b.remainder, b.remainder_se, b.total, '.4g')} m² ({share(b.remainder)}): "
            "interactions, total − floor − Σ contributions"]


def _order(budgets: Sequence[Budget]) -> list[str]:
    """The sources, by their largest share in any budget (the ones off everywhere last)."""
    best: dict[str, float] = {}
    for b in budgets:
        for _, r in b.table.iterrows():
            share = r["share"] if r["status"] == ON and math.isfinite(r["share"]) else -1.0
            best[r["source"]] = max(best.get(r["source"], -1.0), share)
    return sorted(best, key=lambda n: -best[n])


def plot(budgets: Sequence[Budget], title: str):
    """Horizontal bars of the shares of the total MSE (± 2 se), the floor and the remainder, one panel per
    budget."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    order = [n for n in _order(budgets)
             if any(b.table.loc[b.table["source"] == n, "status"].iloc[0] == ON for b in budgets)]
    names = [*order, "remainder", "floor"]
    fig, axes = plt.subplots(1, len(budgets), figsize=(4.2 * len(budgets) + 2.0, 0.35 * len(names) + 1.8),
                             squeeze=False, sharey=True)
    y = np.arange(len(names))[::-1]
    for ax, b in zip(axes[0], budgets):
        scale = 100.0 / b.total if b.total > 0 else math.nan
        values, errors, colors, notes = [], [], [], []
        for n in names:
            if n in ("remainder", "floor"):
                values.append(getattr(b, n) * scale)
                errors.append(2.0 * getattr(b, f"{n}_se") * scale)
                colors.append("0.6")
                notes.append(f"{values[-1]:.1f} %")
            else:
                r = b.table[b.table["source"] == n].iloc[0]
                values.append(r["contribution"] * scale)
                errors.append(2.0 * r["se"] * scale)
                colors.append("tab:red")
                notes.append(f"{values[-1]:.1f} %" if r["status"] == ON else {OFF: "off"}.get(r["status"], r["status"]))
        ax.barh(y, values, xerr=errors, color=colors, capsize=3, alpha=0.85)
        for k, (value, error, note) in enumerate(zip(values, errors, notes)):
            if math.isfinite(value):
                ax.annotate(note, (max(value, 0.0) + error, y[k]), textcoords="offset points", xytext=(4, -3),
                            fontsize=7, color="k" if note.endswith("%") else "0.5")
        ax.margins(x=0.12)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_yticks(y, names)
        ax.set_xlabel("share of the total MSE [%] (± 2 se)")
        ax.set_title(f"{b.label}\ntotal {b.total:.3g} m² (RMS {math.sqrt(b.total):.3f} m)", fontsize=9)
        ax.grid(True, axis="x", alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _config_name(b: Budget, many: bool) -> str:
    if not many:
        return "config.toml"
    value = re.sub(r"[^A-Za-z0-9._-]", "_", b.label.split(" = ", 1)[1])
    return f"config_{value}.toml"


def write(budgets: Sequence[Budget], out: Path | str, title: str, key: str | None = None) -> Path:
    """Write ``budget.csv``, ``budget.md``, ``budget.png`` and the all-on configuration (``config.toml``, or
    ``config_VALUE.toml`` per compared value) into ``out`` atomically; return ``out``."""
    import matplotlib.pyplot as plt

    with staged_directory(out) as tmp:
        table(budgets, key).to_csv(tmp / "budget.csv", index=False)
        (tmp / "budget.md").write_text(f"{title}\n\n{markdown(budgets, key)}", encoding="utf-8")
        fig = plot(budgets, title)
        fig.savefig(tmp / "budget.png", dpi=120, bbox_inches="tight")
        plt.close(fig)
        for b in budgets:
            (tmp / _config_name(b, key is not None)).write_text(to_toml(b.config), encoding="utf-8")
    return Path(out)


def title(scenario: str, budgets: Sequence[Budget], overrides: Sequence[str] = ()) -> str:
    """The heading of a budget's outputs: scenario, receiver, replicates, seed and overrides."""
    cfg = budgets[0].config
    receivers = sorted({b.config.receiver_label for b in budgets})
    return (f"{scenario}: error budget of the {', '.join(receivers)} receiver, {budgets[0].replicates} replicates "
            f"per configuration, seed {cfg['run']['seed']}" + (f", {' '.join(overrides)}" if overrides else ""))


__all__ = ["advice", "lines", "markdown", "plot", "table", "title", "write"]
