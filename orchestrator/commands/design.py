"""``sblsim design`` and ``sblsim.design``: the cheapest system and layout that meets an accuracy prescription over a
work area at a site, each proposed design confirmed by Monte Carlo (:mod:`sblsim.orchestrator.design`).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sblsim.models.declarations import shown
from sblsim.orchestrator.commands.common import Progress
from sblsim.orchestrator.commands.console import check_seed_option, output_folder, output_name
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.design.problem import read_problem
from sblsim.orchestrator.io.arguments import check_count, check_seed, path_argument, prepare_out
from sblsim.orchestrator.io.progress import check_progress

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure

#: The most worker processes of a design's search.
MAX_WORKERS = 64


@dataclass
class DesignResult:
    """The outcome of :func:`design`.

    Attributes
    ----------
    document : dict
        ``design.json``: ``problem`` (as resolved), ``summary`` (one line), ``meets`` (whether the best design
        meets the prescription) and ``designs``, the proposed designs best first (each its ``name``, ``system``,
        ``cost``, ``meets``, ``scenario``, ``transponders_m`` [m, East, North, depth], ``grades``, ``predicted``
        and ``monte_carlo``).
    run : DesignRun
        The search's record: every candidate searched and the proposed designs (their layouts, their accuracy at
        the work area's points).
    out : Path or None
    """

    document: dict
    run: Any
    out: Path | None = None

    @property
    def summary(self) -> str:
        """The outcome in one line."""
        return self.document["summary"]

    @property
    def designs(self) -> list[dict]:
        """The proposed designs, best first (``design.json``'s ``designs``)."""
        return self.document["designs"]

    @property
    def table(self) -> pd.DataFrame:
        """``designs.csv``: every candidate searched, ranked."""
        from sblsim.orchestrator.design.output import table
        from sblsim.orchestrator.design.telemetry_search import TelemetryRun

        if isinstance(self.run, TelemetryRun):
            from sblsim.orchestrator.design.telemetry_output import table
        return table(self.run)

    def scenario(self, name: str | None = None) -> str:
        """The TOML text of a proposed design's scenario (default the best), as ``NAME.toml`` holds it.

        Raises
        ------
        ConfigError
            If no proposed design has that name.
        """
        from sblsim.orchestrator.design.output import scenario_text
        from sblsim.orchestrator.design.telemetry_search import TelemetryRun

        if isinstance(self.run, TelemetryRun):
            raise ConfigError("name: an ilbl design (a telemetry array) has no scenario file; its receivers are "
                              "design.json's receivers_m")
        for design in self.run.proposed:
            if name is None or design.name == name:
                return scenario_text(design, self.run)
        raise ConfigError(f"name: {shown(name)} is not one of {', '.join(d.name for d in self.run.proposed)}")

    def plot(self) -> dict[str, Figure]:
        """The figures by name: ``layout``, ``pareto``, ``convergence``."""
        from sblsim.orchestrator.design.output import figures
        from sblsim.orchestrator.design.telemetry_search import TelemetryRun

        if isinstance(self.run, TelemetryRun):
            from sblsim.orchestrator.design.telemetry_output import figures
        return figures(self.run)


def design(problem: str | Path | Mapping | None = None, *, scenario: str | Path | Mapping | None = None,
           out: str | Path | None = None, workers: int = 1, seed: int | None = None, force: bool = False,
           progress: Progress = False, max_minutes: float | None = None, **sections: Mapping[str, Any]
           ) -> DesignResult:
    """Design a positioning system for a site: ``sblsim design``.

    Searches the candidates (systems, LBL transponder counts and places, an SBL's arm, hardware grades) for the
    cheapest that meets the prescription over the work area, judged by the Fisher information of one cycle, the
    accuracy map's (``sblsim map``), and confirms each proposed design by a Monte Carlo of static vehicles at the
    work area's worst and median points and of the scenario's receiver on a path across it (docs/design.md).

    Parameters
    ----------
    problem : str, Path or mapping, optional
        A built-in problem (``lbl-field-2km``, ``usbl-deep-head``, ``lake-hald-array``: a telemetry array), a
        ``DESIGN.toml`` file, or its sections as a
        mapping; default none (the sections from the keyword arguments alone).
    scenario : str, Path or mapping, optional
        The base scenario in place of ``design.scenario``: a built-in scenario, a ``CONFIG.toml`` or a
        configuration (a design file names no file itself).
    out : str or Path, optional
        Write ``design.json``, ``designs.csv``, a ``NAME.toml`` per proposed design and the figures there.
    workers : int
        Processes searching candidates at once, [1, 64]; the result does not depend on it.
    seed : int, optional
        The search's seed (``search.seed``), [0, 2147483647].
    force : bool
        Replace an earlier design in ``out``.
    progress : bool or callable
        Report the layouts the search evaluates (of the most it may: the estimate's), then each proposal's Monte
        Carlo.
    max_minutes : float, optional
        The longest the design may be estimated to take [min], (0, 525960]; default 60
        (:data:`~sblsim.orchestrator.design.effort.MAX_MINUTES`). A problem estimated longer is refused before
        anything is computed (:func:`~sblsim.orchestrator.design.effort.estimate`; ``result.document["search"]
        ["estimate"]`` holds the estimate of one that runs).
    **sections : mapping
        Sections of the problem over the file's (``work_area={"radius_m": 2000}``, ``prescription={...}``,
        ``candidates``, ``seafloor``, ``search``, ``monte_carlo``, ``design``), each key declared with its unit,
        default and range (docs/design.md).

    Returns
    -------
    DesignResult

    Raises
    ------
    ConfigError, SblsimError
        Bad input, naming the key and its allowed range, or a problem estimated above ``max_minutes`` (nothing is
        computed or written).
    """
    from sblsim.orchestrator.design.effort import check_minutes
    from sblsim.orchestrator.design.solve import solve

    seed = check_seed(seed)
    max_minutes = check_minutes(max_minutes)
    workers = check_count(workers, "workers", 1, MAX_WORKERS)
    check_progress(progress)
    raw = _problem(problem)
    for name, values in sections.items():
        if not isinstance(values, Mapping):
            raise ConfigError(f"{name}: expected a mapping of the section's keys, got {shown(values)}")
        raw.setdefault(name, {}).update(values)
    if seed is not None:
        raw.setdefault("search", {})["seed"] = seed
    if scenario is not None and not isinstance(scenario, Mapping):
        scenario = path_argument(scenario, "scenario", optional=False)
    return DesignResult(*solve(raw, scenario, workers, progress,
                               lambda: prepare_out(out, force, "design.json", "design"), max_minutes))


def _problem(problem: Any) -> dict:
    """The raw sections of a problem argument (a copy)."""
    if problem is None:
        return {}
    if isinstance(problem, Mapping):
        return {k: dict(v) if isinstance(v, Mapping) else v for k, v in problem.items()}
    if not isinstance(problem, (str, Path)):
        raise ConfigError(f"problem: expected a built-in design, a DESIGN.toml or a mapping, got {shown(problem)}")
    return read_problem(problem)


NAME = "design"
HELP = "design: the cheapest system and layout that meets an accuracy prescription over a work area"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim design``'s arguments."""
    p.add_argument("problem", help="built-in design problem (lbl-field-2km, usbl-deep-head, lake-hald-array) or "
                                   "DESIGN.toml")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/design_PROBLEM)")
    p.add_argument("--workers", type=int, default=1, help=f"processes searching candidates at once (default 1; at "
                                                          f"most {MAX_WORKERS}; the result does not depend on it)")
    p.add_argument("--seed", type=int, default=None, help="the search's seed (default search.seed of the problem)")
    p.add_argument("--scenario", default=None,
                   help="the base scenario in place of design.scenario: a built-in scenario or CONFIG.toml")
    p.add_argument("--force", action="store_true", help="replace an earlier design in --out")
    p.add_argument("--max-minutes", type=float, default=None, dest="max_minutes",
                   help="the longest the design may be estimated to take [min] (default 60; a problem estimated "
                        "longer is refused with its estimate)")


def main(args: argparse.Namespace) -> int:
    """``sblsim design`` from its parsed arguments: its lines printed, its exit status returned."""
    check_seed_option(args.seed)
    check_count(args.workers, "--workers", 1, MAX_WORKERS)
    from sblsim.orchestrator.design.effort import check_minutes
    from sblsim.orchestrator.design.solve import solve

    max_minutes = check_minutes(args.max_minutes, "--max-minutes")
    raw = _problem(args.problem)
    if args.seed is not None:
        raw.setdefault("search", {})["seed"] = args.seed
    default = Path("results") / f"design_{output_name(args.problem)}"
    result = DesignResult(*solve(raw, args.scenario, args.workers, "auto",
                                 lambda: output_folder(args.out, default, args.force, "design.json", "design"),
                                 max_minutes, lambda line: print(line, flush=True), "--max-minutes"))
    for record in result.designs:
        verdict = "meets" if record["meets"] else f"does not meet ({', '.join(f['part'] for f in record['fails'])})"
        p = record["predicted"]
        checks = ", ".join(f"{m['point']} {m['ratio']:.2f}" for m in record["monte_carlo"] if m["ratio"] is not None)
        flag = "" if record["confirmed"] else "  NOT CONFIRMED by the Monte Carlo"
        p95 = "no fix" if p["drms_p95_m"] is None else f"{p['drms_p95_m']:.3g} m"
        if "positioning_yield" in p:  # a telemetry array's design
            p95 += (f", yield {100 * p['positioning_yield']:.1f} %, sync {100 * p['sync_coverage']:.0f} %"
                    + "".join(f", simulated yield at the {m['point']} point {100 * m['simulated_yield']:.1f} %"
                              for m in record["monte_carlo"]))
        print(f"{record['name']}: {record['label']}, cost {record['cost']:g}: {verdict} "
              f"({100 * p['coverage']:.1f} % of the work area, DRMS p95 {p95}); Monte Carlo / map: {checks}{flag}")
    print(result.summary)
    files = [d["scenario"] for d in result.designs if d["scenario"]]
    telemetry = "positioning_yield" in result.designs[0]["predicted"]
    figures = "receivers.csv, layout.png" if telemetry else "layout.png, pareto.png, convergence.png"
    print(f"written to {result.out}/ (design.json, designs.csv, {''.join(f + ', ' for f in files)}{figures})")
    return 0
