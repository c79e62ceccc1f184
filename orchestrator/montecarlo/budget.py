"""``sblsim budget``: each error source's share of the position error of one configuration.

The measure is the mean squared error of the receiver's position, per run
``MSE = e_tot_rms²`` (the mean of e_tot² over the run's steps), averaged
over the replicates 0 … N − 1 (docs/model.md, "Error budget"):

* ``total`` = MSE with every error source as configured (all on);
* ``floor`` = MSE with every source of :data:`SOURCES` off: what the receiver
  makes of perfect measurements (its own lag and start-up, and the staleness
  of ranges held for up to one sampling time, which no switch removes
  without changing the step count);
* ``contribution_i`` = MSE(all on) − MSE(all on but source i off);
* ``remainder`` = total − floor − Σ contribution_i: the interactions (errors
  that do not add in the mean square), so that
  ``floor + Σ contribution_i + remainder = total`` exactly;
* ``share_i`` = contribution_i / total, and ``rms`` = sqrt(max(contribution_i, 0)) [m].

Every configuration of a budget runs the same replicates with the same seed.
Each random stream is keyed by its purpose (:mod:`sblsim.models.philox`), so
switching one source to zero leaves every other random number of a run
unchanged (common random numbers): the paired per-replicate differences
are far less noisy than two independent estimates, and their standard error
(``se``, of the mean over the replicates) is the one given. The receiver is
the same in every run of a budget: its section is resolved once, all
sources on, and kept (its R does not follow a switched-off source, as
the ties of :mod:`sblsim.orchestrator.cosim.config` would have it).

A source that is already zero in the configuration (its switched-off
configuration equals the configured one) contributes exactly 0 and is not
run (``off in this configuration``); a source the system does not use (the
survey error of an SBL) runs and contributes exactly 0, every run unchanged
(``no effect``).

The sources and their switches are :mod:`sblsim.orchestrator.montecarlo.error_sources`'; a budget's printed
lines, tables, figure and files :mod:`sblsim.orchestrator.montecarlo.budget_outputs`'.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import scenario_system
from sblsim.orchestrator.cosim.limits import check_replicates
from sblsim.orchestrator.cosim.master import RecordBuffer
from sblsim.orchestrator.cosim.plan import RunPlan, as_plan, load_plan, with_replicates
from sblsim.orchestrator.cosim.run import run_batch
from sblsim.orchestrator.cosim.systems import compared
from sblsim.orchestrator.io.progress import Progress, ProgressSpec
from sblsim.orchestrator.montecarlo.error_sources import SOURCES, _switches

DEFAULT_REPLICATES = 500
#: Status of a source in a budget.
ON, NO_EFFECT, OFF = "on", "no effect", "off in this configuration"
COLUMNS = ("source", "description", "status", "contribution", "se", "share", "rms")


@dataclass
class Budget:
    """The error budget of one configuration.

    Attributes
    ----------
    label : str
        What the budget is of (the scenario, or ``KEY = VALUE`` of a comparison).
    config : RunPlan
        The plan of the configuration, every source on (reads as the configuration).
    replicates : int
    total, total_se, floor, floor_se, remainder, remainder_se : float
        [m²]; the standard errors of the mean over the replicates (the remainder's from its per-replicate
        values).
    table : pandas.DataFrame
        One row per source (:data:`COLUMNS`), largest contribution first, the sources the configuration
        has off last.
    diverged : int
        Runs of the budget whose receiver diverged (their numbers mean nothing).
    runs : int
        Runs made (configurations run × replicates).
    wall_time : float
        [s].
    """

    label: str
    config: RunPlan
    replicates: int
    total: float
    total_se: float
    floor: float
    floor_se: float
    remainder: float
    remainder_se: float
    table: pd.DataFrame
    diverged: int
    runs: int
    wall_time: float
    differences: dict[str, np.ndarray]

    def first(self) -> list[str]:
        """The sources to improve first: the largest contribution if it is significant (above 2 se), with
        every other that it does not exceed by 2 se of their paired difference (empty: none significant)."""
        on = self.table[self.table["status"] == ON]
        if on.empty or not on.iloc[0]["contribution"] > 2.0 * on.iloc[0]["se"]:
            return []
        top = str(on.iloc[0]["source"])
        out = [top]
        for name in on["source"].iloc[1:]:
            gap = self.differences[top] - self.differences[name]
            if not np.mean(gap) > 2.0 * _se(gap):
                out.append(str(name))
        return out


def _se(values: np.ndarray) -> float:
    return float(np.std(values, ddof=1) / math.sqrt(len(values))) if len(values) > 1 else math.nan


def budget(cfg: RunPlan | dict[str, dict], replicates: int = DEFAULT_REPLICATES, label: str | None = None,
           bar=None, records: RecordBuffer | None = None) -> Budget:
    """The error budget of a configuration (module docstring).

    Parameters
    ----------
    cfg : RunPlan or dict
        The plan of the configuration, every source as configured (a configuration: its plan is made once).
    replicates : int
        Runs per configuration (replicates 0 … N − 1 of ``run.seed``).
    label : str, optional
        Default the scenario.
    bar : Progress, optional
        Advanced by every step of every replicate of every configuration run
        (:class:`sblsim.orchestrator.io.progress.Progress`).
    records : RecordBuffer, optional
        Record memory re-used from batch to batch.

    Raises
    ------
    ConfigError, ModelError
        On a source that cannot be switched off in this configuration (nothing is run); a configuration whose
        receiver has no estimate in a replicate (it heard nothing, made no fix: its error is not a number).
    """
    check_budget_replicates(replicates)
    start = time.perf_counter()
    cfg = as_plan(cfg)
    names = SOURCES
    off, floor_cfg = _switches(cfg)
    records = records if records is not None else RecordBuffer()
    done: list[tuple[RunPlan, np.ndarray, int]] = []  # (plan, per-replicate MSE, diverged runs)

    def mse(c: RunPlan, what: str) -> np.ndarray:
        for other, values, _ in done:
            if other == c:  # the same configuration: the same runs
                return values
        result = run_batch(with_replicates(c, range(replicates)), "local", timeseries=False, records=records,
                           progress=bar if bar is not None else False)
        m = result.metrics
        values = m["e_tot_rms"].to_numpy(dtype=float) ** 2
        if not np.isfinite(values).all():  # a receiver without a fix has no estimate: no error to share out
            raise ModelError(_no_estimate(label or cfg.scenario, c, what, m))
        done.append((c, values, int(m["diverged"].sum())))
        return values

    on = mse(cfg, "every source on")
    floor = mse(floor_cfg, "every source off")
    rows, differences = [], {}
    for name, (description, _) in names.items():
        if off[name] == cfg:
            rows.append((name, description, OFF, 0.0, 0.0))
            continue
        without = mse(off[name], f"{name} off")
        d = on - without
        differences[name] = d
        status = NO_EFFECT if not np.any(d) else ON
        rows.append((name, description, status, float(np.mean(on) - np.mean(without)), _se(d)))
    total, floor_mean = float(np.mean(on)), float(np.mean(floor))
    contributions = [r[3] for r in rows]
    remainder = total - floor_mean - math.fsum(contributions)
    per_replicate = on - floor - (np.sum(list(differences.values()), axis=0) if differences else 0.0)
    table = pd.DataFrame([{"source": n, "description": desc, "status": s, "contribution": c, "se": se,
                           "share": c / total if total > 0 else math.nan, "rms": math.sqrt(max(c, 0.0))}
                          for n, desc, s, c, se in rows], columns=list(COLUMNS))
    rank = table["status"].map({ON: 0, NO_EFFECT: 1, OFF: 2})
    table = (table.assign(_rank=rank, _size=-table["contribution"]).sort_values(["_rank", "_size"], kind="stable")
             .drop(columns=["_rank", "_size"]).reset_index(drop=True))
    return Budget(label or cfg.scenario, cfg, replicates, total, _se(on), floor_mean, _se(floor),
                  remainder, _se(per_replicate), table, sum(d for _, _, d in done), len(done) * replicates,
                  time.perf_counter() - start, differences)


def _no_estimate(label: str, plan: RunPlan, what: str, metrics: pd.DataFrame) -> str:
    """The one line of a budget refused because a configuration's receiver had no estimate in some replicates
    (``what``: which configuration of the budget, e.g. ``every source on``): whether it heard nothing (no update),
    the system and the settings that decide what is heard."""
    none = ~np.isfinite(metrics["e_tot_rms"].to_numpy(dtype=float))
    unheard = none & (metrics["updates"].to_numpy() == 0)
    a = plan["acoustics"]
    if a["detection"] == "snr":
        setting = (f"acoustics.detection snr, acoustics.source_level = {a['source_level']:g} dB re 1 µPa at 1 m, "
                   f"acoustics.detection_threshold = {a['detection_threshold']:g} dB")
    else:
        setting = f"acoustics.detection fixed, acoustics.loss_pct = {a['loss_pct']:g} %"
    verb = "heard nothing" if unheard.sum() == none.sum() else "had no estimate"
    return (f"budget: {label}: the {plan.receiver_label} receiver {verb} with {what} (platform.system "
            f"{plan['platform']['system']}, {setting}): {int(none.sum())} of its {len(none)} replicates made no fix "
            f"({int(unheard.sum())} without a single update) and have no estimate, so no error to share out; "
            "allowed: a configuration whose receiver hears its beacons (sblsim run shows its updates); nothing "
            "written")


def planned(cfg: RunPlan | dict[str, dict]) -> int:
    """How many configurations a budget of ``cfg`` runs: all on, the floor and each source that is on, the
    same configuration once."""
    cfg = as_plan(cfg)
    off, floor = _switches(cfg)
    distinct: list[RunPlan] = []
    for c in (cfg, floor, *(c for c in off.values() if c != cfg)):
        if not any(c == d for d in distinct):
            distinct.append(c)
    return len(distinct)


def check_budget_replicates(replicates: int) -> None:
    """Refuse a budget's replicate count outside [2, :data:`~sblsim.orchestrator.cosim.limits.MAX_REPLICATES`]: its
    standard errors need two."""
    check_replicates(replicates, 2, "the standard errors need two")


def configurations(scenario: str | Path, overrides: Sequence[str] = (), seed: int | None = None,
                   receiver: str | None = None,
                   compare: tuple[str, list[str]] | None = None) -> list[tuple[str, RunPlan]]:
    """The plans of a budget, or of one budget per compared value: (label, plan), each resolved once with its
    switched-off plans.

    ``receiver`` sets ``simulation.receiver``; a compared ``platform.system`` starts, as in ``sblsim compare
    --systems``, from its :attr:`~sblsim.models.systems.System.compare_defaults` with the overrides over them
    (:func:`~sblsim.orchestrator.cosim.systems.system_overrides`).

    Raises
    ------
    ConfigError, ModelError
        On a bad key or value (the message names it), or a source that cannot be switched off; nothing is
        run.
    """
    items = [*overrides, *([f"simulation.receiver={receiver}"] if receiver is not None else [])]
    if compare is None:
        out = [(Path(str(scenario)).stem, load_plan(scenario, items, seed=seed))]
    else:
        key, values = compare
        out = [(f"{key} = {value}", load_plan(scenario, items_of, seed=seed))
               for value, items_of in zip(values, compared(key, values, items, scenario_system(scenario)))]
    for _, cfg in out:  # every switch is checked before any run
        _switches(cfg)
    return out


def budgets(configs: Sequence[tuple[str, RunPlan]], replicates: int = DEFAULT_REPLICATES,
            progress: ProgressSpec = False) -> list[Budget]:
    """The budget of every plan (:func:`configurations`), each of the replicates 0 … N − 1.

    ``progress`` reports the steps of every run (:class:`sblsim.orchestrator.io.progress.Progress`); default
    silent."""
    check_budget_replicates(replicates)
    configs = [(label, as_plan(cfg)) for label, cfg in configs]
    steps = sum(planned(cfg) * cfg.n_steps for _, cfg in configs)
    records = RecordBuffer()
    with Progress(steps * replicates, "budget", "step", progress) as bar:
        return [budget(cfg, replicates, label, bar, records) for label, cfg in configs]



__all__ = ["COLUMNS", "DEFAULT_REPLICATES", "Budget", "budget", "budgets", "check_budget_replicates",
           "configurations", "planned"]
