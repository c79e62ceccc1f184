"""The commands a user types, one module each: ``sblsim run``, ``replay``, ``track``, ``report``, ``store``, ``sync``,
``toa``, ``calibrate``, ``compare``, ``budget``, ``map``, ``design``, ``campaign``, ``ssp``, ``analyze``, ``fmus`` and
``codegen``.

A command's module holds what the command is, from Python and from the command line:

- its function and its result class, the public API (``sblsim.run`` and :class:`RunResult` are
  :mod:`sblsim.orchestrator.commands.run`'s; :mod:`sblsim.orchestrator.api` re-exports them);
- ``NAME`` and ``HELP``, its word and its line of ``sblsim --help``;
- ``add_arguments(p)``, its arguments on its subparser, and ``main(args)``, which runs it from the parsed
  arguments and prints its lines, returning the exit status.

:data:`COMMANDS` registers them in the order ``sblsim --help`` lists them; ``sblsim``'s parser and dispatch
(:mod:`sblsim.orchestrator.cli`) are built from it, so adding a command is a module and a line here. A command is
thin: it reads its arguments, calls the library and prints; the work, its argument checks and the lines it prints are
the library's (``replay --format toa``'s: :mod:`sblsim.orchestrator.tracks`, ``replay_toa`` and ``replay_toa_tags``
with their results; the plain checks of a number, path or flag: :mod:`sblsim.orchestrator.io.arguments`). What the
commands share: :mod:`~sblsim.orchestrator.commands.common` (the checks of a scenario, overrides and engine, and the
resolution of a configuration) and :mod:`~sblsim.orchestrator.commands.console` (the command line's exit statuses,
output folders and metric lines). A command imports no other, except ``campaign``, whose ``--analyze`` and
:meth:`CampaignResult.analyze` run ``analyze`` (``tests/test_import_graph.py`` holds the rule).

A module imports at load only what ``sblsim --help`` needs; the modules that run the work (they load pandas,
scipy.stats or matplotlib) are imported by the functions that use them.
"""

from __future__ import annotations

from types import ModuleType

from sblsim.orchestrator.commands import (
    analyze,
    budget,
    calibrate,
    campaign,
    codegen,
    compare,
    design,
    fmus,
    replay,
    report,
    run,
    ssp,
    store,
    sync,
    toa,
    track,
)
from sblsim.orchestrator.commands import map as accuracy_map

#: The commands, in the order of ``sblsim --help``: name -> module.
COMMANDS: dict[str, ModuleType] = {module.NAME: module for module in (
    run, replay, track, report, store, sync, toa, calibrate, compare, budget, accuracy_map, design, campaign, ssp,
    analyze, fmus, codegen)}
