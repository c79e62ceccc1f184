"""``sblsim map`` and ``sblsim.accuracy_map``: the accuracy limit (the horizontal standard deviation of a fix)
over a grid around the platform, one map per compared value (:mod:`sblsim.orchestrator.maps`).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from sblsim.models.declarations import shown
from sblsim.orchestrator.commands.common import Overrides, Progress, compared, override_items, scenario_source
from sblsim.orchestrator.commands.console import (
    ALL_SYSTEMS,
    check_seed_option,
    output_folder,
    output_name,
)
from sblsim.orchestrator.cosim.config import ConfigError, parse_compare
from sblsim.orchestrator.cosim.plan import Config
from sblsim.orchestrator.io.arguments import check_seed, prepare_out, real_argument
from sblsim.orchestrator.io.progress import check_progress

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class MapResult:
    """The outcome of :func:`accuracy_map`.

    Attributes
    ----------
    labels : list of str
        One per map: the scenario, or ``KEY = VALUE`` of a comparison.
    configs : list of Config
        The configuration of each map (``target.depth`` the diver's depth of the map [m]).
    east, north : ndarray
        The grid [m], shapes (E,) and (N,).
    maps : list of ndarray
        The horizontal DRMS of one round of fresh measurements plus depth [m], each of shape (N, E).
    levels : list of float
        The accuracy prescriptions contoured [m].
    compared : tuple or None
        ``(key, values)`` of a comparison.
    out : Path or None
    """

    labels: list[str]
    configs: list[Config]
    east: Any
    north: Any
    maps: list[Any]
    levels: list[float]
    compared: tuple[str, list[str]] | None = None
    out: Path | None = None

    @property
    def table(self) -> pd.DataFrame:
        """``map.csv``: (compared value,) ``east``, ``north``, ``depth``, ``drms`` [m], one row per cell."""
        from sblsim.orchestrator.maps import table

        return table(self.labels, self.configs, self.east, self.north, self.maps, self.compared)

    def shares(self) -> list[dict[float, float]]:
        """Per map: level [m] -> the share of the grid's cells within it [%]."""
        out = []
        for m in self.maps:
            out.append({v: 100 * float((m <= v).sum()) / m.size for v in self.levels})
        return out

    def plot(self) -> Figure:
        """The figure ``map.png``."""
        from sblsim.orchestrator.maps import plot

        return plot(self.labels, self.configs, self.east, self.north, self.maps, self.levels)


def accuracy_map(scenario: str | Path, *, extent: float = 30.0, step: float = 0.5,
                 levels: Sequence[float] = (0.5, 1.0, 2.0), compare: str | tuple | None = None,
                 depth: float | None = None, seed: int | None = None, set: Overrides = None,
                 out: str | Path | None = None, force: bool = False, progress: Progress = False) -> MapResult:
    """The accuracy map around the platform: ``sblsim map``.

    The horizontal standard deviation (DRMS) of one fix from one round of fresh measurements plus depth,
    on a square grid, from the Fisher information of the configured error sources (Kay 1993, Section 3.7).

    Parameters
    ----------
    scenario : str or Path
        A built-in scenario or ``CONFIG.toml`` (the geometry and error levels).
    extent : float
        Half-width of the square grid [m], (0, 100000].
    step : float
        Grid spacing [m].
    levels : sequence of float
        Accuracy prescriptions to contour [m].
    compare : str or tuple, optional
        One map per value: ``"platform.baseline=0.4,1,3"`` or ``("platform.system", ["sbl", "lbl",
        "usbl"])`` (a compared system starts from its defaults, ``set`` over them).
    depth : float, optional
        The diver's depth of the maps [m] (default ``target.depth``, or the median depth of a trajectory
        file).
    seed, set
        As for :func:`run`.
    out : str or Path, optional
        Write ``map.csv`` and ``map.png`` there.
    force : bool
        Replace an earlier map in ``out``.
    progress : bool or callable
        Report each map made.

    Returns
    -------
    MapResult

    Raises
    ------
    ConfigError, SblsimError
        Bad input (nothing is computed or written).
    """
    from sblsim.orchestrator.maps import MAX_EXTENT, parse_levels

    seed = check_seed(seed)
    source = scenario_source(scenario)
    extent = real_argument(extent, "extent", 0.0, MAX_EXTENT, "m", low_open=True)
    step = real_argument(step, "step", 0.0, extent, "m (the extent)", low_open=True)
    depth = None if depth is None else real_argument(depth, "depth", 0.0, 11000.0, "m")
    check_progress(progress)
    if isinstance(levels, (str, bytes)) or not isinstance(levels, (Sequence, np.ndarray)):
        raise ConfigError(f"levels: expected a list of accuracies [m], got {shown(levels)}")
    try:
        level_text = ",".join(repr(float(v)) for v in levels)
    except (TypeError, ValueError):
        raise ConfigError(f"levels: expected numbers [m], got {shown(levels)}") from None
    return _accuracy_map(source, override_items(set), seed, extent, step, parse_levels(level_text, "levels"),
                         compared(compare), depth, progress, lambda: prepare_out(out, force, "map.csv", "map"),
                         ("extent", "step", "depth"))


def _accuracy_map(source: str, items: list[str], seed: int | None, extent: float, step: float, levels: list[float],
                  chosen: tuple[str, list[str]] | None, depth: float | None, progress: Any,
                  prepare: Callable[[], Path | None], options: tuple[str, str, str]) -> MapResult:
    """:func:`accuracy_map` (and ``sblsim map``) after the checks of its arguments: ``prepare()`` the output folder
    (None: nothing is written), the maps, the files; errors name the extent, step and depth as ``options``."""
    from sblsim.orchestrator.maps import grid, make_maps, write

    grid(extent, step, options[:2])  # the grid's size before any output
    target = prepare()
    labels, configs, east, north, maps = make_maps(source, items, seed, extent, step, chosen, depth,
                                                   progress=progress, options=options)
    if target is not None:
        write(labels, configs, east, north, maps, levels, target, chosen)
    return MapResult(labels, configs, east, north, maps, levels, chosen, target)


NAME = "map"
HELP = "accuracy map: horizontal standard deviation of a fix around the platform"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim map``'s arguments."""
    p.add_argument("scenario", help="built-in scenario or CONFIG.toml (geometry and error levels)")
    p.add_argument("--extent", type=float, default=30.0,
                   help="half-width of the square grid [m] (default 30; at most 100000)")
    p.add_argument("--step", type=float, default=0.5, help="grid spacing [m] (default 0.5)")
    p.add_argument("--levels", default="0.5,1,2", help="accuracy prescriptions to contour [m] (default 0.5,1,2)")
    p.add_argument("--compare", default=None, metavar="KEY=V1,V2,...",
                   help="one map per value, side by side, e.g. platform.baseline=0.4,1,3; "
                        f"platform.system={ALL_SYSTEMS} "
                        "maps each system from the defaults of compare --systems, your --set over them")
    p.add_argument("--depth", type=float, default=None,
                   help="the diver's depth of the maps [m] (default target.depth, or the median depth of a "
                        "trajectory file); above the site's water depth acoustics.water_depth and, LBL, above its "
                        "seafloor transponders")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/map_SCENARIO)")
    p.add_argument("--force", action="store_true", help="replace an earlier map in --out")
    p.add_argument("--seed", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key (repeatable)")


def main(args: argparse.Namespace) -> int:
    """``sblsim map`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.maps import ECHO_ONLY, diver_depth, grid, parse_levels, write

    check_seed_option(args.seed)
    levels = parse_levels(args.levels)
    compare = parse_compare(args.compare) if args.compare else None
    out = output_folder(args.out, Path("results") / f"map_{output_name(args.scenario)}", args.force, "map.csv", "map",
                  before=lambda _: grid(args.extent, args.step))
    result = _accuracy_map(args.scenario, list(args.overrides), args.seed, args.extent, args.step, levels, compare,
                               args.depth, "auto", lambda: None, ("--extent", "--step", "--depth"))
    labels, configs, east, north, maps = result.labels, result.configs, result.east, result.north, result.maps
    depth = configs[0]["target"]["depth"]
    where = "--depth" if args.depth is not None else diver_depth(configs[0])[1]  # (compared systems' defaults)
    print(f"maps at {depth:g} m depth ({where}; --depth D to choose)")
    for label, cfg, m in zip(labels, configs, maps):
        cells = m.size
        shares = ", ".join(f"{100 * float((m <= v).sum()) / cells:.0f} % within {v:g} m" for v in levels)
        echo = getattr(cfg, "echo", None)
        only = ""
        if echo is not None and cfg["acoustics"]["detection"] == "snr" and (echo >= ECHO_ONLY).any():
            only = f"; {100 * float((echo >= ECHO_ONLY).sum()) / cells:.0f} % echo-only (hatched)"
        print(f"{label}: horizontal DRMS {np.nanmin(m):.3f} … {np.nanmax(m[np.isfinite(m)]):.3f} m over "
              f"±{args.extent:g} m; {shares}{only}")
    write(labels, configs, east, north, maps, levels, out, compare)
    print(f"written to {out}/ (map.csv, map.png)")
    return 0
