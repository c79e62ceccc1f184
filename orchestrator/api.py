"""The Python API of sblsim: ``import sblsim``.

Every name in :data:`__all__` is public and stable; it is re-exported by the package ``sblsim`` itself
(``sblsim.run``, ``sblsim.load``, ...). Everything else in the project is private by convention, however it
is reached.

Each function does what the command of the same name does (``sblsim run``, ``compare``, ``map``, ``budget``,
``design``, ``replay``, ``calibrate``, ``campaign``, ``analyze``), with the same numbers: the function and the command
are one module of :mod:`sblsim.orchestrator.commands`, which this module re-exports (a tracking's functions and results,
``replay_toa``, ``replay_toa_tags``, ``TrackResult`` and ``TagsResult``, are the tracking room's,
:mod:`sblsim.orchestrator.tracks`, which ``sblsim replay --format toa`` calls; ``ReplayResult`` is the log room's,
:mod:`sblsim.orchestrator.logs`). Unlike a command, a function

- returns its results as Python objects: tables as :class:`pandas.DataFrame`, figures as
  :class:`matplotlib.figure.Figure` (made when asked for, by the results' ``plot`` methods);
- writes nothing unless ``out`` is given (then the files the command writes; a campaign always writes its
  directory);
- raises an exception on bad input, never :class:`SystemExit`: :class:`SblsimError` or one of its
  subclasses, the message naming the field and the allowed range (the command's one-line error);
- is silent unless asked: ``progress=True`` shows a tqdm bar on standard error, ``progress=callable``
  calls ``callable(done, total)`` as the work advances (in the units the function documents).

Examples
--------
>>> import sblsim
>>> r = sblsim.run("semicircle", seed=1)                        # doctest: +SKIP
>>> r.summary["e_tot_rms"]                                      # doctest: +SKIP
>>> cfg = sblsim.load("semicircle", set={"platform.baseline": 0.4})
>>> cfg["platform"]["baseline"]
0.4
"""


from __future__ import annotations

from sblsim.models.errors import SblsimError
from sblsim.orchestrator.commands.analyze import AnalysisResult, analyze
from sblsim.orchestrator.commands.budget import BudgetResult, budget
from sblsim.orchestrator.commands.calibrate import CalibrationResult, calibrate
from sblsim.orchestrator.commands.campaign import CampaignResult, campaign
from sblsim.orchestrator.commands.common import load
from sblsim.orchestrator.commands.compare import CompareResult, compare
from sblsim.orchestrator.commands.design import DesignResult, design
from sblsim.orchestrator.commands.map import MapResult, accuracy_map
from sblsim.orchestrator.commands.replay import replay
from sblsim.orchestrator.commands.run import RunResult, run
from sblsim.orchestrator.commands.store import StoreResult, store
from sblsim.orchestrator.commands.sync import SyncResult, sync
from sblsim.orchestrator.commands.toa import ToaResult, toa
from sblsim.orchestrator.commands.track import StudyResult, track
from sblsim.orchestrator.cosim.config import BUILTIN_SCENARIOS, ConfigError
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.plan import Config
from sblsim.orchestrator.logs.replay_result import ReplayResult
from sblsim.orchestrator.tracks.many import TagsResult, replay_toa_tags
from sblsim.orchestrator.tracks.replay import TrackResult, replay_toa

#: ``sblsim.map``: the function of ``sblsim map`` under the command's name (``accuracy_map`` is the same function,
#: its first name, kept).
map = accuracy_map  # the command's name (this module uses no built-in map)

__all__ = [
    "load", "run", "compare", "map", "accuracy_map", "budget", "design", "replay", "replay_toa", "replay_toa_tags",
    "calibrate", "campaign",
    "analyze", "Config", "RunResult", "CompareResult", "MapResult", "BudgetResult", "DesignResult", "ReplayResult",
    "TrackResult", "TagsResult", "store", "StoreResult", "sync", "SyncResult", "toa", "ToaResult", "track",
    "StudyResult",
    "CalibrationResult", "CampaignResult", "AnalysisResult", "SblsimError", "ConfigError", "ENGINES",
    "BUILTIN_SCENARIOS",
]
