"""``sblsim budget`` and ``sblsim.budget``: the error budget, each error source's share of the position error
from runs with the sources switched off one at a time (:mod:`sblsim.orchestrator.montecarlo.budget`).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.commands.common import Overrides, Progress, compared, override_items, scenario_source
from sblsim.orchestrator.commands.console import (
    ALL_SYSTEMS,
    check_seed_option,
    output_folder,
    output_name,
)
from sblsim.orchestrator.cosim.config import check_receiver, parse_compare
from sblsim.orchestrator.io.arguments import check_count, check_seed, prepare_out, text_argument
from sblsim.orchestrator.io.progress import check_progress

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class BudgetResult:
    """The outcome of :func:`budget`.

    Attributes
    ----------
    budgets : list
        One budget per configuration (the scenario, or each compared value), each with ``label``,
        ``config``, ``total``, ``floor``, ``remainder`` [m²], their standard errors, ``table`` (one row per
        error source: ``contribution`` [m²], ``se`` [m²], ``share`` [-], ``rms`` [m], ``status``),
        ``diverged``, ``runs`` and ``wall_time`` [s].
    title : str
        The heading ``sblsim budget`` prints.
    compared : tuple or None
    out : Path or None
    """

    budgets: list[Any]
    title: str
    compared: tuple[str, list[str]] | None = None
    out: Path | None = None

    @property
    def table(self) -> pd.DataFrame:
        """``budget.csv``: one row per source (per compared value), the contributions [m²] and shares."""
        from sblsim.orchestrator.montecarlo.budget_outputs import table

        return table(self.budgets, self.compared[0] if self.compared else None)

    def markdown(self) -> str:
        """``budget.md``'s table."""
        from sblsim.orchestrator.montecarlo.budget_outputs import markdown

        return markdown(self.budgets, self.compared[0] if self.compared else None)

    def lines(self) -> list[str]:
        """What ``sblsim budget`` prints for each budget: one line per source, the floor, remainder, total
        and what to improve first."""
        from sblsim.orchestrator.montecarlo.budget_outputs import advice, lines

        out = []
        for b in self.budgets:
            if self.compared is not None:
                out.append(f"{b.label}:")
            out += lines(b)
            out.append(f"  {advice(b)}")
        return out

    def plot(self) -> Figure:
        """The figure ``budget.png``."""
        from sblsim.orchestrator.montecarlo.budget_outputs import plot

        return plot(self.budgets, self.title)


def budget(scenario: str | Path, *, replicates: int | None = None, receiver: str | None = None,
           compare: str | tuple | None = None, seed: int | None = None, set: Overrides = None,
           out: str | Path | None = None, force: bool = False, progress: Progress = False) -> BudgetResult:
    """The error budget, each error source's share of the position error: ``sblsim budget``.

    Parameters
    ----------
    scenario : str or Path
        A built-in scenario or ``CONFIG.toml``.
    replicates : int, optional
        Runs per configuration (all sources on, all off, one per source off) [2, …]; default 500.
    receiver : str, optional
        The receiver (default the configuration's).
    compare : str or tuple, optional
        One budget per value, e.g. ``"platform.system=sbl,lbl,usbl"``.
    seed, set
        As for :func:`run`.
    out : str or Path, optional
        Write ``budget.csv``, ``budget.md``, ``budget.png`` and the configurations there.
    force : bool
        Replace an earlier budget in ``out``.
    progress : bool or callable
        Report the steps done, a unit being one macro step of one replicate of one configuration.

    Returns
    -------
    BudgetResult

    Raises
    ------
    ConfigError, SblsimError
        Bad input, or a source that cannot be switched off (nothing is run or written).
    """
    from sblsim.orchestrator.montecarlo.budget import DEFAULT_REPLICATES, check_budget_replicates

    seed = check_seed(seed)
    source = scenario_source(scenario)
    receiver = text_argument(receiver, "receiver")
    check_progress(progress)
    prepare_out(out, force, "budget.csv", "budget")  # before any work (and again once the plans are made)
    replicates = DEFAULT_REPLICATES if replicates is None else replicates
    replicates = check_count(replicates, "replicates", -2**63, 2**63)
    check_budget_replicates(replicates)
    if isinstance(compare, str):
        chosen = parse_compare(compare, "platform.system=" + ",".join(SYSTEMS))
    else:
        chosen = compared(compare)
    if receiver is not None:
        check_receiver(receiver, "receiver")
    return _budget(source, override_items(set), seed, receiver, chosen, replicates, progress,
                   lambda: prepare_out(out, force, "budget.csv", "budget"))


def _budget(source: str, items: list[str], seed: int | None, receiver: str | None,
            chosen: tuple[str, list[str]] | None, replicates: int, progress: Any,
            prepare: Callable[[], Path | None]) -> BudgetResult:
    """:func:`budget` (and ``sblsim budget``) after the checks of its arguments: each configuration and its
    switched-off ones resolved once, ``prepare()`` the output folder (None: nothing is written), run, write."""
    from sblsim.orchestrator.montecarlo.budget import budgets, configurations
    from sblsim.orchestrator.montecarlo.budget_outputs import title, write

    configs = configurations(source, items, seed, receiver, chosen)  # every check before any output
    target = prepare()
    results = budgets(configs, replicates, progress=progress)
    heading = title(source, results, items)
    if target is not None:
        write(results, target, heading, chosen[0] if chosen else None)
    return BudgetResult(results, heading, chosen, target)


NAME = "budget"
HELP = "error budget: each error source's share of the position error"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim budget``'s arguments."""
    p.add_argument("scenario", help="built-in scenario or CONFIG.toml")
    p.add_argument("--replicates", type=int, default=None,
                   help="runs per configuration: the all-on one, the all-off one and one per source switched off "
                        "(default 500)")
    p.add_argument("--receiver", default=None,
                   help="the receiver (default: the configuration's); ekf, ekf-seq, ukf, lsq, model:PATH.py or "
                        "fmu:PATH")
    p.add_argument("--compare", default=None, metavar="KEY=V1,V2,...",
                   help=f"one budget per value, side by side, e.g. platform.system={ALL_SYSTEMS}")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/budget_SCENARIO)")
    p.add_argument("--force", action="store_true", help="replace an earlier budget in --out")
    p.add_argument("--seed", type=int, default=None, help="campaign seed (default: from the configuration, 0)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key (repeatable)")


def main(args: argparse.Namespace) -> int:
    """``sblsim budget`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.montecarlo.budget import DEFAULT_REPLICATES, check_budget_replicates
    from sblsim.orchestrator.montecarlo.budget_outputs import write

    check_seed_option(args.seed)
    replicates = DEFAULT_REPLICATES if args.replicates is None else args.replicates
    check_budget_replicates(replicates)
    compare = parse_compare(args.compare, f"platform.system={ALL_SYSTEMS}") if args.compare else None
    if args.receiver is not None:
        check_receiver(args.receiver, "--receiver")
    target: list[Path] = []

    def prepare() -> None:  # after every configuration is checked (resolved once), before any run
        target.append(output_folder(args.out, Path("results") / f"budget_{output_name(args.scenario)}", args.force,
                              "budget.csv", "budget"))

    result = _budget(args.scenario, list(args.overrides), args.seed, args.receiver, compare, replicates,
                         "auto", prepare)
    out = target[0]
    results, heading = result.budgets, result.title
    print(heading)
    print("\n".join(result.lines()))
    for b in results:
        if b.diverged:
            print(f"sblsim: warning: the receiver diverged in {b.diverged} of {b.runs} runs of {b.label}: the budget "
                  "means nothing", file=sys.stderr)
    write(results, out, heading, compare[0] if compare else None)
    print(f"{sum(b.runs for b in results)} runs in {sum(b.wall_time for b in results):.1f} s; written to {out}/ "
          "(budget.csv, budget.md, budget.png, config.toml)")
    return 0
