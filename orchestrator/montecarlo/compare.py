"""``sblsim compare``: several receivers, or several positioning systems, on the same runs of one scenario.

Every receiver sees the same replicates (same seeds, so the same diver path,
platform motion, ranges, losses and outliers: the receiver draws no random
numbers).

With ``systems`` (``sblsim compare --systems sbl,lbl,usbl``) every system
runs with every receiver on the same replicates, diver paths and error
levels (the target's random numbers do not depend on the system), each
system from its :attr:`~sblsim.models.systems.System.compare_defaults` with
the user's ``--set`` over them (:mod:`sblsim.orchestrator.cosim.systems`); the
table gains a ``system`` column, one row per system and receiver.

The ``pcrb_rms`` of each system is its own: ranges and depth for SBL and
LBL, range, azimuth, elevation and depth for USBL (:mod:`sblsim.models.bound`).

Per receiver (and system), over the steps with an estimate of all replicates
(none before a receiver's first fix: its estimate is NaN there, never its
starting guess):

* ``rms_e_tot``: RMS of e_tot [m] (``sqrt(mean(e_tot_rms²))``, each run weighted
  alike: the runs' steps before the first fix may differ in number), and ``rms_e_tot_sd``, the standard deviation of
  the runs' RMS e_tot over the replicates [m] (the spread a designer sees from
  run to run);
* ``mean_e_tot``: mean e_tot [m];
* ``nees``, ``coverage_95``, ``nis``, ``gated_pct``: means over runs of the
  consistency metrics (:mod:`sblsim.orchestrator.cosim.metrics`), and ``nees_sd``
  the standard deviation of the runs' mean NEES;
* ``pcrb_rms`` [m] and ``ratio_to_pcrb = rms_e_tot / pcrb_rms``;
* ``us_per_step``: wall-clock time of the receiver's doStep per run and
  communication step [µs], the runs stepped together on the local engine. It
  includes the per-call cost of a batch step, shared by the replicates, and it
  moves with the machine's load: an indication of the receivers' relative cost
  (shown to two significant digits), not a benchmark (``benchmarks/`` has those);
* ``diverged``: the number of runs whose receiver diverged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sblsim.models import RECEIVER_MODELS
from sblsim.models.declarations import ModelError
from sblsim.models.systems import system
from sblsim.orchestrator.cosim.config import apply_overrides, check_receiver, note, scenario_system
from sblsim.orchestrator.cosim.limits import check_replicates
from sblsim.orchestrator.cosim.master import RecordBuffer
from sblsim.orchestrator.cosim.plan import RunPlan, load_plan, make_plan, thaw, with_replicates
from sblsim.orchestrator.cosim.run import run_batch
from sblsim.orchestrator.cosim.systems import system_overrides
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.io.progress import ProgressSpec, progress_of

COLUMNS = ("receiver", "runs", "rms_e_tot", "rms_e_tot_sd", "mean_e_tot", "nees", "nees_sd", "coverage_95", "nis",
           "gated_pct", "pcrb_rms", "ratio_to_pcrb", "us_per_step", "diverged")


def parse_receivers(text: str) -> list[str]:
    """``ekf,ekf-seq,ukf`` -> the list, each checked.

    Raises
    ------
    ConfigError
        Naming ``--receivers`` and what is allowed.
    """
    receivers = [r.strip() for r in text.split(",") if r.strip()]
    if not receivers:
        raise ModelError(f"--receivers: expected a comma-separated list of {', '.join(RECEIVER_MODELS)} or fmu:PATH")
    if len(set(receivers)) != len(receivers):
        raise ModelError(f"--receivers: {text!r} names a receiver twice")
    return [check_receiver(r, "--receivers") for r in receivers]


def plans(scenario: str | Mapping, receivers: Sequence[str], overrides: Sequence[str] = (), seed: int | None = None,
          systems: Sequence[str] | None = None) -> list[RunPlan]:
    """The plan of every receiver (of every system) of a comparison, each resolved once
    (:func:`sblsim.orchestrator.cosim.plan.load_plan`); the arguments as for :func:`compare`.

    ``scenario`` may be a configuration (a :class:`~sblsim.orchestrator.cosim.plan.Config` or its mapping): each
    receiver then takes its sections as they are and, of its ``[receiver]`` section, the keys that receiver has
    (:func:`~sblsim.orchestrator.cosim.config.switch_receiver`, as a configuration file's: a resolved
    configuration holds every key of its own receiver, some of which another receiver does not take).

    Raises
    ------
    ConfigError, ModelError
        On a bad receiver or override (nothing is run).
    """
    def plan_of(items: list[str]) -> RunPlan:
        if not isinstance(scenario, Mapping):
            return load_plan(scenario, items, seed=seed)
        return make_plan(apply_overrides(thaw(scenario), items, seed))

    if systems is None:
        return [plan_of([*overrides, f"simulation.receiver={r}"]) for r in receivers]
    own = scenario_system(scenario)
    out = []
    for s in systems:  # a receiver a system cannot take (the inverted LBL's without an emission epoch) is left out
        taken = [r for r in receivers if _takes(s, r)]
        if not taken:
            system(s).check_receiver(receivers[0], "--receivers")  # raises, naming the receivers it takes
        if len(taken) < len(receivers):
            note(f"{s}: {', '.join(r for r in receivers if r not in taken)} left out (it cannot track {s}: "
                 f"{', '.join(taken)} compared)")
        out += [plan_of(system_overrides(s, [*overrides, f"simulation.receiver={r}"], own=own)) for r in taken]
    return out


def _takes(name: str, receiver: str) -> bool:
    """The system ``name`` can take the receiver (:meth:`~sblsim.models.systems.System.check_receiver`)."""
    try:
        system(name).check_receiver(receiver)
    except ModelError:
        return False
    return True


def compare(scenario: str | Sequence[RunPlan], receivers: Sequence[str] = (), replicates: int = 20,
            overrides: Sequence[str] = (), seed: int | None = None, engine: str = "local",
            fmu_dir: Path | str | None = None, progress: ProgressSpec = False,
            systems: Sequence[str] | None = None) -> pd.DataFrame:
    """Run every receiver (of every system) on the same replicates of a scenario and tabulate them.

    Parameters
    ----------
    scenario : str or sequence of RunPlan
        Built-in scenario or configuration file; or the comparison's plans (:func:`plans`, then
        ``receivers``, ``overrides``, ``seed`` are theirs, and ``systems`` only says whether the table has a
        ``system`` column).
    receivers : sequence of str
        ``simulation.receiver`` values.
    replicates : int
        Runs per receiver (replicates 0 … N − 1), 1 … 100000.
    overrides, seed, engine, fmu_dir
        As for ``sblsim run``.
    progress : bool, 'auto' or callable
        Report the steps done over every receiver's runs (:class:`sblsim.orchestrator.io.progress.Progress`; a
        unit is one step of one replicate); default silent.
    systems : sequence of str, optional
        ``platform.system`` values, each run from its compare defaults
        with ``overrides`` over them (:func:`system_overrides`); default: the
        scenario's system as configured, and no ``system`` column.

    Returns
    -------
    pandas.DataFrame
        One row per receiver (per system, then receiver), the columns of
        :data:`COLUMNS` (after ``system`` when systems are given).

    Raises
    ------
    ConfigError, ModelError
        On a bad receiver, override or replicate count (nothing is run).
    """
    check_replicates(replicates)
    if isinstance(scenario, (str, Path)):
        configs = plans(str(scenario), receivers, overrides, seed, systems)
    else:
        configs = list(scenario)
    rows = []
    records = RecordBuffer()  # one record memory for the receivers' batches, one after the other
    steps = sum(p.n_steps for p in configs)
    bar, own = progress_of(progress, steps * replicates, "compare")
    try:
        results = [run_batch(with_replicates(plan, range(replicates)), engine, fmu_dir=fmu_dir, timeseries=False,
                             progress=bar, records=records) for plan in configs]
    finally:
        if own:
            bar.close()
    for plan, result in zip(configs, results):
        m = result.metrics
        rms = math.sqrt(float(np.mean(m["e_tot_rms"] ** 2)))
        bound = math.sqrt(float(np.mean(m["pcrb_rms"] ** 2)))
        rows.append({"system": plan.system.name, "receiver": plan.receiver_label, "runs": replicates,
                     "rms_e_tot": rms,
                     "rms_e_tot_sd": float(np.std(m["e_tot_rms"], ddof=1)) if replicates > 1 else math.nan,
                     "mean_e_tot": float(m["e_tot_mean"].mean()), "nees": float(m["nees_mean"].mean()),
                     "nees_sd": float(np.std(m["nees_mean"], ddof=1)) if replicates > 1 else math.nan,
                     "coverage_95": float(m["coverage_95"].mean()), "nis": float(m["nis_mean"].mean()),
                     "gated_pct": float(m["gated_pct"].mean()), "pcrb_rms": bound, "ratio_to_pcrb": rms / bound,
                     "us_per_step": 1e6 * result.step_time.get("receiver", math.nan) / (result.steps * replicates),
                     "diverged": int(m["diverged"].sum())})
    return pd.DataFrame(rows, columns=list(COLUMNS) if systems is None else ["system", *COLUMNS])


def _number(value: float, digits: str) -> str:
    return format(value, digits) if math.isfinite(value) else "n/a"


def markdown(table: pd.DataFrame) -> str:
    """The comparison as a Markdown table (units in the header; a ``system`` column first when it has one)."""
    systems = "system" in table.columns
    head = (("| system " if systems else "") + "| receiver | RMS e_tot [m] (± sd over runs) | mean e_tot [m] "
            "| NEES (3) | coverage 95 % | gated [%] | PCRB RMS [m] | RMS / PCRB | µs per step | diverged runs |")
    lines = [head, "|---" * (10 + systems) + "|"]
    for r in table.itertuples():
        spread = f" ± {r.rms_e_tot_sd:.3f}" if math.isfinite(r.rms_e_tot_sd) else ""
        lines.append((f"| {r.system} " if systems else "")
                     + f"| {r.receiver} | {r.rms_e_tot:.3f}{spread} | {r.mean_e_tot:.3f} | {r.nees:.2f} "
                     f"| {r.coverage_95:.3f} | {r.gated_pct:.2f} | {_number(r.pcrb_rms, '.3f')} "
                     f"| {_number(r.ratio_to_pcrb, '.2f')} | {r.us_per_step:.2g} | {r.diverged} |")
    return "\n".join(lines) + "\n"


def labels(table: pd.DataFrame) -> list[str]:
    """The figure's label of each row: the receiver, or the system and receiver (the system alone when every
    row has the same receiver)."""
    if "system" not in table.columns:
        return list(table["receiver"])
    if table["receiver"].nunique() == 1:
        return list(table["system"])
    return [f"{s}\n{r}" for s, r in zip(table["system"], table["receiver"])]


def plot(table: pd.DataFrame, title: str):
    """RMS e_tot per receiver with its spread over the runs and the PCRB; mean NEES per receiver with its spread
    and the consistent value 3 (log scale: an overconfident receiver's NEES is tens)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(max(11, 1.1 * len(table) + 4), 4.5))
    x = np.arange(len(table))
    names = labels(table)
    what = "receiver" if "system" not in table.columns else (
        "system" if table["receiver"].nunique() == 1 else "system and receiver")
    sd = table["rms_e_tot_sd"].fillna(0.0)
    ax1.bar(x, table["rms_e_tot"], yerr=sd, capsize=4, color="tab:red", alpha=0.8,
            label="RMS e_tot (± sd over runs)")
    ax1.plot(x, table["pcrb_rms"], "k_", ms=30, mew=2, label="PCRB RMS (the limit)")
    ax1.set_xticks(x, names)
    ax1.set_xlabel(what)
    ax1.set_ylabel("position error, RMS e_tot [m]")
    ax1.set_ylim(0, None)
    ax1.grid(True, axis="y", alpha=0.3)
    ax1.legend(fontsize=8)
    nees = table["nees"].to_numpy(dtype=float)
    spread = table["nees_sd"].fillna(0.0).to_numpy(dtype=float)
    low = np.minimum(spread, 0.9 * nees)  # a log axis cannot show the bar below zero
    ax2.errorbar(x, nees, yerr=[low, spread], fmt="o", color="tab:blue", capsize=4, ms=7,
                 label="mean NEES (± sd over runs)")
    for k, value in enumerate(nees):
        ax2.annotate(f"{value:.1f}", (x[k], value), textcoords="offset points", xytext=(8, 4), fontsize=8)
    ax2.axhline(3.0, color="k", ls="--", lw=1, label="consistent: 3 (3 dof)")
    ax2.set_yscale("log")
    ax2.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax2.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if f"{v:g}"[0] in "235" else ""))
    ax2.set_xticks(x, names)
    ax2.set_xlim(-0.5, len(table) - 0.5)
    ax2.set_xlabel(what)
    ax2.set_ylabel("position NEES (above 3: overconfident)")
    ax2.grid(True, axis="y", which="both", alpha=0.3)
    ax2.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def write(table: pd.DataFrame, out: Path | str, title: str, note: str = "") -> Path:
    """Write ``compare.csv``, ``compare.md`` and ``compare.png`` into ``out`` atomically; return ``out``.

    ``note``, a line under the title of ``compare.md`` (the compared systems' defaults).
    """
    import matplotlib.pyplot as plt

    with staged_directory(out) as tmp:
        table.to_csv(tmp / "compare.csv", index=False)
        (tmp / "compare.md").write_text(f"{title}\n\n" + (f"{note}\n\n" if note else "") + markdown(table),
                                        encoding="utf-8")
        fig = plot(table, title)
        fig.savefig(tmp / "compare.png", dpi=120, bbox_inches="tight")
        plt.close(fig)
    return Path(out)


__all__ = ["COLUMNS", "compare", "labels", "markdown", "parse_receivers", "plans", "plot", "write"]
