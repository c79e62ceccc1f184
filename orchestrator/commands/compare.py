"""``sblsim compare`` and ``sblsim.compare``: several receivers, or positioning systems, on the same replicates
of a scenario (:mod:`sblsim.orchestrator.montecarlo.compare`).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from sblsim.models.declarations import shown
from sblsim.orchestrator.commands.common import Overrides, Progress, check_engine, override_items, scenario_source
from sblsim.orchestrator.commands.console import (
    ALL_SYSTEMS,
    check_seed_option,
    config_options,
    output_folder,
    output_name,
)
from sblsim.orchestrator.cosim.config import ConfigError, check_site_keys, load_config, scenario_system
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.limits import check_replicates
from sblsim.orchestrator.cosim.systems import describe_defaults, parse_systems, system_overrides
from sblsim.orchestrator.io.arguments import check_count, check_seed, path_argument, prepare_out
from sblsim.orchestrator.io.progress import check_progress

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class CompareResult:
    """The outcome of :func:`compare`.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per receiver (per system, then receiver): ``compare.csv`` (``rms_e_tot``, ``pcrb_rms`` [m],
        ``nees``, ``coverage_95``, ``us_per_step`` [µs], ...).
    title : str
        The heading ``sblsim compare`` prints.
    note : str
        The compared systems' defaults (empty without ``systems``).
    out : Path or None
    """

    table: pd.DataFrame
    title: str
    note: str = ""
    out: Path | None = None

    def markdown(self) -> str:
        """The table as ``compare.md`` shows it."""
        from sblsim.orchestrator.montecarlo.compare import markdown

        return markdown(self.table)

    def plot(self) -> Figure:
        """The figure ``compare.png``."""
        from sblsim.orchestrator.montecarlo.compare import plot

        return plot(self.table, self.title)


def _listed(value: str | Sequence[str] | None, what: str) -> str | None:
    """A list of names argument (``receivers``, ``systems``) as the comma-separated text the command takes."""
    if value is None or isinstance(value, str):
        return value
    if not isinstance(value, Sequence) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{what}: expected a text or a list of names, got {shown(value)}")
    return ",".join(value)


def compare(scenario: str | Path | Mapping, *, receivers: str | Sequence[str] = ("ekf", "ekf-seq", "ukf", "lsq"),
            systems: str | Sequence[str] | None = None, replicates: int = 20, seed: int | None = None,
            set: Overrides = None, engine: str = "local", fmu_dir: str | Path | None = None,
            out: str | Path | None = None, force: bool = False, progress: Progress = False) -> CompareResult:
    """Several receivers (of several positioning systems) on the same replicates: ``sblsim compare``.

    Parameters
    ----------
    scenario : str, Path or mapping
        A built-in scenario or ``CONFIG.toml`` (a configuration: its TOML is compared).
    receivers : str or sequence of str
        ``ekf``, ``ekf-seq``, ``ukf``, ``lsq``, ``model:PATH.py`` or ``fmu:PATH``.
    systems : str or sequence of str, optional
        ``sbl``, ``lbl``, ``usbl``: every system with every receiver, each from its defaults with ``set``
        over them.
    replicates : int
        Runs per receiver, replicates 0 … N − 1 [1, 100000].
    seed, set, engine, fmu_dir
        As for :func:`run`.
    out : str or Path, optional
        Write ``compare.csv``, ``compare.md`` and ``compare.png`` there.
    force : bool
        Replace an earlier comparison in ``out``.
    progress : bool or callable
        Report the steps done, a unit being one macro step of one replicate of one receiver.

    Returns
    -------
    CompareResult

    Raises
    ------
    ConfigError, SblsimError
        Bad input (nothing is run or written).
    """
    from sblsim.orchestrator.montecarlo.compare import compare as _compare
    from sblsim.orchestrator.montecarlo.compare import parse_receivers, plans, write

    seed = check_seed(seed)
    check_engine(engine)
    replicates = check_count(replicates, "replicates", -2**63, 2**63)  # an integer; the comparison checks its range
    fmu_dir = path_argument(fmu_dir, "fmu_dir")
    check_progress(progress)
    items = override_items(set)
    source = scenario_source(scenario, configuration=True)
    names = parse_receivers(_listed(receivers, "receivers") or "")
    chosen = parse_systems(_listed(systems, "systems")) if systems is not None else None
    if chosen is not None:
        system_overrides(chosen[0], items)  # refuses a platform.system override before any work
    check_replicates(replicates)
    compared = plans(source, names, items, seed, chosen)  # each system and receiver resolved once
    check_site_keys(compared, items, "the configuration" if isinstance(source, Mapping) else str(source))
    target = prepare_out(out, force, "compare.csv", "comparison")
    table = _compare(compared, replicates=replicates, engine=engine, fmu_dir=fmu_dir, progress=progress,
                     systems=chosen)
    title, note = compare_title(source, replicates, items, seed, chosen, compared[0].seed)
    if target is not None:
        write(table, target, title, note)
    return CompareResult(table, title, note, target)


def compare_title(scenario: str | Path | Mapping, replicates: int, overrides: Sequence[str], seed: int | None,
                  systems: Sequence[str] | None, run_seed: int | None = None) -> tuple[str, str]:
    """The heading and note of a comparison (``sblsim compare`` prints them, ``compare.md`` holds them);
    ``run_seed``, the ``run.seed`` of the comparison's first plan (default: its configuration is loaded; given
    for a configuration)."""
    # the seed of the title: of the first compared system's configuration, which its defaults make valid (the
    # user's --set may hold keys that apply over them only, e.g. platform.beacons over the LBL circle)
    own = scenario_system(scenario) if systems is not None else None
    if run_seed is None:
        first = system_overrides(systems[0], overrides, own=own) if systems is not None else list(overrides)
        run_seed = load_config(scenario, first, seed)["run"]["seed"]
    per = "receiver" if systems is None else "system and receiver"
    name = scenario.get("run", {}).get("scenario", "configuration") if isinstance(scenario, Mapping) else scenario
    title = (f"{name}: {replicates} replicates per {per}, seed {run_seed}"
             + (f", {' '.join(overrides)}" if overrides else ""))
    note = "" if systems is None else f"systems: {describe_defaults(systems, own)}" + (
        "; then --set " + " ".join(overrides) if overrides else "")
    return title, note


NAME = "compare"
HELP = ("run several receivers (or positioning systems) on the same replicates of a "
       "scenario")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim compare``'s arguments."""
    p.add_argument("scenario", help="built-in scenario or CONFIG.toml")
    p.add_argument("--receivers", default="ekf,ekf-seq,ukf,lsq",
                   help="comma-separated receivers (default ekf,ekf-seq,ukf,lsq; model:PATH.py or fmu:PATH for "
                        "your own)")
    p.add_argument("--systems", default=None, metavar="SYSTEMS",
                   help=f"compare positioning systems, e.g. {ALL_SYSTEMS}: every system, with every receiver, "
                        "on the same diver paths, replicates and error levels, each from its defaults, your --set "
                        f"over them: {describe_defaults()}")
    p.add_argument("--replicates", type=int, default=20, help="runs per receiver (default 20)")
    p.add_argument("--engine", choices=ENGINES, default="local", help="component engine (default local)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/compare_SCENARIO)")
    p.add_argument("--force", action="store_true", help="replace an earlier comparison in --out")
    config_options(p)


def main(args: argparse.Namespace) -> int:
    """``sblsim compare`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.montecarlo.compare import markdown, parse_receivers, write

    check_seed_option(args.seed)
    receivers = parse_receivers(args.receivers)
    systems = parse_systems(args.systems) if args.systems is not None else None
    if systems is not None:
        system_overrides(systems[0], args.overrides)  # refuses a --set platform.system before any work
    out = output_folder(args.out, Path("results") / f"compare_{output_name(args.scenario)}", args.force, "compare.csv",
                  "comparison")
    result = compare(args.scenario, receivers=receivers, systems=systems, replicates=args.replicates,
                         seed=args.seed, set=args.overrides, engine=args.engine, fmu_dir=args.fmu_dir,
                         progress="auto")
    print(result.title)
    if result.note:
        print(result.note)
    print(markdown(result.table), end="")
    write(result.table, out, result.title, result.note)
    print(f"written to {out}/ (compare.csv, compare.md, compare.png)")
    return 0
