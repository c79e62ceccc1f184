"""The maps of ``sblsim map``: one per configuration or per value of a compared key, each with its
configuration at the map's diver depth (:func:`make_maps`, :class:`MapConfig`).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import check_site_keys, scenario_system
from sblsim.orchestrator.cosim.plan import Config, RunPlan, load_plan, thaw
from sblsim.orchestrator.cosim.systems import compared
from sblsim.orchestrator.io.progress import Progress, ProgressSpec
from sblsim.orchestrator.maps.accuracy import site_maps
from sblsim.orchestrator.maps.map_grid import check_depth, diver_depth, grid


def make_maps(scenario: str, overrides: Sequence[str] = (), seed: int | None = None, extent: float = 30.0,
              step: float = 0.5, compare: tuple[str, list[str]] | None = None,
              depth: float | None = None, progress: ProgressSpec = False,
              options: tuple[str, str, str] = ("--extent", "--step", "--depth")
              ) -> tuple[list[str], list[dict], np.ndarray, np.ndarray, list[np.ndarray]]:
    """The accuracy map of a configuration, or one per value of a compared key (each configuration resolved
    once into its plan).

    ``progress`` reports each map made (:class:`sblsim.orchestrator.io.progress.Progress`); default silent.

    ``depth`` [m] is the diver's depth of every map (default :func:`diver_depth` of each configuration); the
    configurations returned hold it as ``target.depth``, which the table and the figure show. It is checked
    against each configuration's site (:func:`check_depth`). Errors name the extent, step and depth as
    ``options`` (the command's options, or the API's arguments).

    Returns
    -------
    labels : list of str
        Panel titles (``platform.baseline = 1`` or the scenario).
    configs : list of MapConfig
        Each map's configuration (a dict, ``target.depth`` the map's depth) and its plan (``.plan()``).
    east, north : ndarray
    maps : list of ndarray, each (len(north), len(east)) [m]

    Raises
    ------
    ConfigError, ModelError
        On a bad option or configuration value (nothing is computed).
    """
    east, north = grid(extent, step, options[:2])
    option = options[2]
    if compare is None:
        plans, labels = [load_plan(scenario, overrides, seed=seed)], [str(scenario)]
    else:  # a compared system starts from its defaults, the user's --set over them
        key, values = compare
        plans = [load_plan(scenario, items, seed=seed)
                 for items in compared(key, values, overrides, scenario_system(scenario))]
        labels = [f"{key} = {v}" for v in values]
    if depth is not None and not 0.0 <= depth <= 11000.0:
        raise ModelError(f"{option}: {depth!r} is outside the allowed range [0, 11000] m")
    check_site_keys(plans, overrides, str(scenario))  # a key no panel's site reads: refused (given) or noted
    configs = []
    for plan in plans:
        configs.append(MapConfig(plan, diver_depth(plan)[0] if depth is None else float(depth)))
        check_depth(configs[-1], configs[-1]["target"]["depth"], option if depth is not None else "target.depth")
    with Progress(len(configs), "map", "map", progress) as bar:
        maps = []
        for c in configs:
            drms, c.availability, c.echo = site_maps(c.plan(), east, north, depth=c["target"]["depth"])
            maps.append(drms)
            bar.update(1)
    return labels, configs, east, north, maps


class MapConfig(Config):
    """The configuration of one map: its plan's configuration (a changeable copy) with ``target.depth`` the
    map's diver depth [m]; :meth:`plan` is the plan the map was made of (resolved once: a map does not
    simulate, its depth is not resolved again)."""

    def __init__(self, plan: RunPlan, depth: float) -> None:
        config = thaw(plan.config)
        config["target"]["depth"] = depth
        super().__init__(config)
        self._plan = plan
        #: The map's probability of a fix in one cycle (:func:`availability_map`), once made.
        self.availability: np.ndarray | None = None
        #: The map's probability that a fix takes a reflected arrival (:func:`site_maps`), once made.
        self.echo: np.ndarray | None = None

    def plan(self) -> RunPlan:
        """The plan the map was made of (its ``target.depth`` the configuration's, not the map's)."""
        return self._plan
