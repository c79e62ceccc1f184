"""A design problem worked from its raw sections to its outputs (``sblsim design``'s work, the command's arguments
read): checked, resolved against its base scenario, its effort estimated and held to the most minutes allowed, its
candidates searched, each proposal confirmed by Monte Carlo, and ``design.json``, ``designs.csv``, the scenarios and
the figures written (:mod:`~sblsim.orchestrator.design.run`); a telemetry array's the same through its own modules
(:mod:`~sblsim.orchestrator.design.telemetry`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Callable

from sblsim.models.errors import ConfigError
from sblsim.orchestrator.design import telemetry, telemetry_confirm, telemetry_output, telemetry_search
from sblsim.orchestrator.design.checks import is_telemetry
from sblsim.orchestrator.design.confirm import confirm
from sblsim.orchestrator.design.effort import check_effort, estimate
from sblsim.orchestrator.design.output import document, write
from sblsim.orchestrator.design.problem import check_problem
from sblsim.orchestrator.design.resolution import resolve
from sblsim.orchestrator.design.run import search_all
from sblsim.orchestrator.io.progress import Progress as ProgressBar


def solve(raw: dict, scenario: Any, workers: int, progress: Any, prepare: Callable[[], Path | None],
          max_minutes: float | None = None, say: Callable[[str], object] | None = None,
          option: str = "max_minutes") -> tuple[dict, Any, Path | None]:
    """A design problem's raw sections checked (:func:`~sblsim.orchestrator.design.problem.check_problem`; a
    ``scenario`` in place of ``design.scenario``), resolved, estimated, searched, confirmed and written:
    ``prepare()`` the output folder (None: nothing written); the estimate checked against ``max_minutes`` (named
    ``option``) and told to ``say`` before the work starts; a telemetry array's by :func:`solve_telemetry`.

    Returns
    -------
    document : dict
        ``design.json``'s content.
    run : DesignRun or TelemetryRun
        The search's record.
    out : Path or None
        The folder written.

    Raises
    ------
    ConfigError
        Bad input, naming the key and its allowed range (``option`` where the estimate is above ``max_minutes``; a
        base scenario given for a telemetry array).
    """
    sections = check_problem(raw, scenario_given=scenario is not None)
    if is_telemetry(sections):
        if scenario is not None:
            raise ConfigError(f"{'--scenario' if option == '--max-minutes' else 'scenario'}: an ilbl design (a "
                              "telemetry array) reads no base scenario; allowed none (the site is [site.area] and "
                              "[detection])")
        return solve_telemetry(sections, progress, prepare, max_minutes, say, option)
    start = time.perf_counter()
    source = scenario if scenario is not None else sections["design"]["scenario"]
    if scenario is not None:
        sections["design"]["scenario"] = str(scenario) if not isinstance(scenario, Mapping) else "(a configuration)"
    resolved = resolve(sections, source)
    effort = estimate(resolved, workers)
    check_effort(effort, max_minutes, option)
    if say is not None:
        say(f"{sections['design']['name']}: {effort.line()}")
    target = prepare()
    run = search_all(resolved, workers, progress, effort.layouts)
    with ProgressBar(len(run.proposed), "monte carlo", "design", progress) as bar:
        for proposal in run.proposed:
            confirm(proposal, resolved)
            bar.update(1)
    seconds = time.perf_counter() - start
    if target is not None:
        write(run, target, seconds, effort)
    return document(run, seconds, effort), run, target


def solve_telemetry(sections: dict, progress: Any, prepare: Callable[[], Path | None], max_minutes: float | None,
                    say: Callable[[str], object] | None, option: str) -> tuple[dict, Any, Path | None]:
    """:func:`solve` of a telemetry array (``candidates.systems = ["ilbl"]``:
    :mod:`~sblsim.orchestrator.design.telemetry`), its sections checked.

    Raises
    ------
    ConfigError
        Naming ``option``: the estimate above ``max_minutes``.
    """
    start = time.perf_counter()
    resolved = telemetry.resolve(sections)
    effort = telemetry_search.estimate(resolved)
    check_effort(effort, max_minutes, option)
    if say is not None:
        say(f"{sections['design']['name']}: {effort.line()}")
    target = prepare()
    with ProgressBar(effort.candidates, "design", "count", progress) as bar:
        run = telemetry_search.search_all(resolved, bar.update)
    with ProgressBar(len(run.proposed), "monte carlo", "design", progress) as bar:
        for proposal in run.proposed:
            telemetry_confirm.confirm(proposal, resolved)
            bar.update(1)
    seconds = time.perf_counter() - start
    if target is not None:
        telemetry_output.write(run, target, seconds, effort)
    return telemetry_output.document(run, seconds, effort), run, target


__all__ = ["solve", "solve_telemetry"]
