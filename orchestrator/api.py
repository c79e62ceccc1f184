"""The Python API of sblsim: ``import sblsim``.

Every name in :data:`__all__` is public and stable; it is re-exported by the package ``sblsim`` itself
(``sblsim.run``, ``sblsim.load``, ...). Everything else in the project is private by convention, however it
is reached.

Each function does what the command of the same name does (``sblsim run``, ``compare``, ``map``, ``budget``,
``replay``, ``calibrate``, ``campaign``, ``analyze``), with the same numbers: both call the same functions of the
orchestrator. Unlike a command, a function

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

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from numbers import Real
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Union

import numpy as np
import tomli_w

from sblsim.models.declarations import shown
from sblsim.models.errors import SblsimError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.config import (
    BUILTIN_SCENARIOS,
    ConfigError,
    apply_overrides,
    check_receiver,
    load_config,
    parse_compare,
    resolve,
    scenario_system,
)
from sblsim.orchestrator.cosim.engines import ENGINES, close_handles, make_handles
from sblsim.orchestrator.cosim.plan import Config, RunPlan, load_plan, make_plan, thaw
from sblsim.orchestrator.cosim.systems import describe_defaults, parse_systems, system_overrides
from sblsim.orchestrator.io.output import check_output, check_writable
from sblsim.orchestrator.io.progress import check_progress
from sblsim.orchestrator.study import Study, load_study

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure

__all__ = [
    "load", "run", "compare", "accuracy_map", "budget", "replay", "calibrate", "campaign", "analyze",
    "Config", "RunResult", "CompareResult", "MapResult", "BudgetResult", "ReplayResult", "CalibrationResult",
    "CampaignResult", "AnalysisResult", "SblsimError", "ConfigError", "ENGINES", "BUILTIN_SCENARIOS",
]

#: What a ``progress`` argument may be: False or None (silent, the default), True (a tqdm bar on standard
#: error), or a callable ``progress(done, total)`` called as the work advances.
Progress = Union[bool, None, Callable[[float, float], object]]

#: What a ``set`` argument may be: a mapping ``{"section.key": value}`` (e.g. ``{"platform.baseline": 0.4,
#: "receiver": "lsq"}``) or a sequence of ``"section.key=value"`` texts as ``--set`` takes them.
Overrides = Union[Mapping[str, Any], Sequence[str], None]

MAX_SEED = 2**31 - 1


# --------------------------------------------------------------------------- configurations

def _check_seed(seed: Any, where: str = "seed") -> None:
    if seed is None:
        return
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"{where}: {shown(seed)} is outside the allowed range [0, {MAX_SEED}] (an integer)")


def _override_items(overrides: Overrides) -> list[str]:
    """``set`` as the ``section.key=value`` items of ``--set``: a mapping's values written as TOML values
    (a text stays a text, a number keeps every digit)."""
    if overrides is None:
        return []
    if isinstance(overrides, str):
        raise ConfigError(f"set: expected a mapping {{'section.key': value}} or a list of 'section.key=value', "
                          f"got the text {overrides!r}")
    if isinstance(overrides, Mapping):
        items = []
        for key, value in overrides.items():
            if not isinstance(key, str) or "=" in key:
                raise ConfigError(f"set: a key must be a text 'section.key', got {key!r}")
            try:
                text = tomli_w.dumps({"v": value}).split("=", 1)[1].strip()
            except TypeError:
                raise ConfigError(f"set: {key}: {value!r} is not a number, text, boolean or list") from None
            items.append(f"{key}={text}")
        return items
    if not isinstance(overrides, Sequence):
        raise ConfigError(f"set: expected a mapping {{'section.key': value}} or a list of 'section.key=value', got "
                          f"{shown(overrides)}")
    items = list(overrides)
    for item in items:
        if not isinstance(item, str):
            raise ConfigError(f"set: expected 'section.key=value' texts, got {item!r}")
    return items


def _config(source: Any, seed: int | None = None, overrides: Overrides = None) -> Config:
    """A :class:`Config` from a scenario name, a TOML file or a configuration (re-validated with the
    overrides and seed)."""
    _check_seed(seed)
    items = _override_items(overrides)
    if isinstance(source, Mapping):
        return Config(resolve(apply_overrides(thaw(source), items, seed)))
    _check_source(source)
    return Config(load_config(source, items, seed))


def _check_source(source: Any) -> None:
    if not isinstance(source, (str, Path)):
        raise ConfigError(f"scenario: expected a built-in scenario ({', '.join(BUILTIN_SCENARIOS)}), a TOML file "
                          f"or a configuration, got {type(source).__name__}")


def _plan(source: Any, seed: int | None = None, overrides: Overrides = None) -> RunPlan:
    """The plan of a run of a scenario name, a TOML file or a configuration with the overrides and seed: the one
    resolution of a call (:func:`sblsim.orchestrator.cosim.plan.make_plan`); a plan without overrides or seed is
    taken as it is."""
    _check_seed(seed)
    items = _override_items(overrides)
    if isinstance(source, RunPlan) and not items and seed is None:
        return source
    if isinstance(source, Mapping):
        return make_plan(apply_overrides(thaw(source), items, seed))
    _check_source(source)
    return load_plan(source, items, seed)


def load(scenario_or_path: str | Path | Mapping, *, seed: int | None = None, set: Overrides = None) -> Config:
    """The resolved, validated configuration of a scenario (``sblsim run``'s first step).

    Parameters
    ----------
    scenario_or_path : str, Path or mapping
        A built-in scenario (:data:`BUILTIN_SCENARIOS`), a configuration file ``CONFIG.toml`` (its relative
        paths taken from its own folder), or a configuration (e.g. a :class:`Config`; validated again).
    seed : int, optional
        The campaign seed ``run.seed`` [0, 2147483647]; default the configuration's (0).
    set : mapping or sequence of str, optional
        Overrides, ``{"platform.baseline": 0.4, "receiver": "lsq"}`` or ``["platform.baseline=0.4"]`` (as
        ``--set``; a key without a section is a ``simulation`` key).

    Returns
    -------
    Config

    Raises
    ------
    ConfigError, SblsimError
        An unknown scenario, section or key, a value outside its range (the message names it and the range),
        a file that is not valid TOML.
    """
    return _config(scenario_or_path, seed, set)


def _check_engine(engine: str) -> None:
    if not isinstance(engine, str) or engine not in ENGINES:
        raise ConfigError(f"engine: {engine!r} is not one of {', '.join(ENGINES)}")


def _check_count(value: Any, where: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(f"{where}: {value!r} is outside the allowed range [{low}, {high}] (an integer)")
    return value


def _integer(value: Any, where: str) -> None:
    """An integer argument or None, whose range the work it sets checks."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
        raise ConfigError(f"{where}: {shown(value)} is not an integer or None")


def _path(value: Any, where: str, optional: bool = True) -> Path | None:
    """A file or folder argument (a text or a path; None where it is optional) as a :class:`Path`."""
    if value is None and optional:
        return None
    text = os.fspath(value) if isinstance(value, (str, os.PathLike)) else None
    if not isinstance(text, str) or not text or "\0" in text:
        allowed = "a file or folder: a text or a pathlib.Path" + (", or None" if optional else "")
        raise ConfigError(f"{where}: {shown(value)} is not {allowed}")
    return Path(text)


def _flag(value: Any, where: str) -> bool:
    """A true-or-false argument (``force=\"no\"`` would replace an earlier result)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{where}: {shown(value)} is not True or False")
    return bool(value)


def _real(value: Any, where: str, low: float, high: float, unit: str, low_open: bool = False) -> float:
    """A finite real number argument in ``[low, high]`` (``(low, high]`` with ``low_open``)."""
    allowed = f"{'(' if low_open else '['}{low:g}, {high:g}] {unit}".rstrip()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Real):
        raise ConfigError(f"{where}: {shown(value)} is not a number; allowed: {allowed}")
    if not math.isfinite(value) or not (value > low if low_open else value >= low) or not value <= high:
        raise ConfigError(f"{where}: {shown(value)} is outside the allowed range {allowed}")
    return float(value)


def _text(value: Any, where: str, optional: bool = True) -> str | None:
    if value is None and optional:
        return None
    if not isinstance(value, str):
        raise ConfigError(f"{where}: {shown(value)} is not a text" + (" or None" if optional else ""))
    return value


def _prepare_out(out: str | Path | None, force: bool, marker: str, what: str) -> Path | None:
    """``out`` checked before any work (writable; an earlier result only with ``force``)."""
    out = _path(out, "out")
    force = _flag(force, "force")
    if out is None:
        return None
    check_output(out, force, marker, what, "out")
    return out


# --------------------------------------------------------------------------- run

@dataclass
class RunResult:
    """The outcome of :func:`run`.

    Attributes
    ----------
    config : Config
        The resolved configuration that ran.
    engine : str
        ``local`` or ``fmu``.
    timeseries : pandas.DataFrame
        One row per replicate and macro step: the columns of ``timeseries.parquet`` (``replicate``,
        ``time`` [s], ``true_*``, ``est_*``, ``instr_*`` [m], [m/s], the acoustic packet, the errors
        ``e_x``, ``e_y``, ``e_z``, ``e_tot`` [m], the receiver's covariance [m²] and the bound ``pcrb`` [m];
        the log-format page lists them).
    metrics : pandas.DataFrame
        One row per replicate: the metrics of ``summary.json`` (errors [m], NEES, NIS, coverage, ...).
    steps : int
        Macro steps per replicate.
    wall_time : float
        Wall-clock time of the simulation [s].
    out : Path or None
        Where the run was written (``out`` of :func:`run`), else None.
    """

    config: Config
    engine: str
    timeseries: pd.DataFrame
    metrics: pd.DataFrame
    steps: int
    wall_time: float
    out: Path | None = None
    _result: Any = field(default=None, repr=False)

    @property
    def summary(self) -> dict[str, Any]:
        """``summary.json`` of the first replicate (``run.replicate``): the keys ``sblsim run`` writes
        (``e_tot_rms`` [m], ``nees_mean``, ``coverage_95``, ``pcrb_rms`` [m], ``steps``, ``seed``, ...); a
        metric without a value is None."""
        return self.summaries[0]

    @property
    def summaries(self) -> list[dict[str, Any]]:
        """``summary.json`` of every replicate, in order."""
        from sblsim.orchestrator.cosim.run import RunResult as _Result
        from sblsim.orchestrator.cosim.run import summary

        r = self._result
        out = []
        for k in range(len(r.metrics)):
            row = r.metrics.iloc[[k]].reset_index(drop=True)
            plan = r.plan.with_replicate(int(row["replicate"].iloc[0]))
            out.append(summary(_Result(plan.config, r.engine, r.timeseries, row, r.steps, r.wall_time, plan=plan)))
        return out

    def plot(self, replicate: int | None = None) -> dict[str, Figure]:
        """The figures ``sblsim run`` writes, of one replicate (default the first).

        Returns
        -------
        dict
            ``trajectory_xy``, ``trajectory_3d``, ``errors``, ``error_bounds`` -> matplotlib Figure (close
            them with ``matplotlib.pyplot.close`` when done).

        Raises
        ------
        ConfigError
            A replicate the run does not have.
        """
        from sblsim.orchestrator.io.plots import run_figures

        ts = self.timeseries
        if replicate is not None:
            if replicate not in set(ts["replicate"].unique().tolist()):
                raise ConfigError(f"replicate: {replicate!r} is not one of the run's "
                                  f"{sorted(ts['replicate'].unique().tolist())}")
            ts = ts[ts["replicate"] == replicate]
        receiver = self._result.plan.receiver_label
        return run_figures(ts, f"{self.config.scenario}, {receiver} ({self.engine})", receiver)


def run(config_or_scenario: str | Path | Mapping, *, engine: str = "local", replicates: int = 1,
        seed: int | None = None, set: Overrides = None, out: str | Path | None = None, force: bool = False,
        fmu_dir: str | Path | None = None, progress: Progress = False) -> RunResult:
    """Simulate a scenario: the numbers of ``sblsim run``.

    Parameters
    ----------
    config_or_scenario : str, Path or mapping
        A built-in scenario, a ``CONFIG.toml`` or a configuration (:func:`load`).
    engine : {'local', 'fmu'}
        The component engine (:data:`ENGINES`); ``fmu`` needs the FMUs (``sblsim fmus build``, or built on
        demand for other beacon counts).
    replicates : int
        Replicates to run, ``run.replicate`` … ``run.replicate + replicates - 1`` [1, 100000] (stepped
        together on the local engine; each replicate's numbers are those of a run of it alone).
    seed : int, optional
        The campaign seed ``run.seed``; default the configuration's.
    set : mapping or sequence of str, optional
        Overrides, as for :func:`load`.
    out : str or Path, optional
        Write ``summary.json``, ``config.toml``, ``timeseries.parquet`` and the figures there (one
        replicate only), atomically; default: nothing is written.
    force : bool
        Replace an earlier run in ``out``.
    fmu_dir : str or Path, optional
        The built FMUs (fmu engine; default ``fmus/build``).
    progress : bool or callable
        Report the steps done, a unit being one macro step of one replicate (:data:`Progress`).

    Returns
    -------
    RunResult

    Raises
    ------
    ConfigError, SblsimError
        Bad input of any kind (nothing is run or written).
    """
    from sblsim.orchestrator.cosim.run import write_run

    plan = _plan(config_or_scenario, seed, set)
    _check_engine(engine)
    _check_count(replicates, "replicates", 1, 100_000)
    fmu_dir = _path(fmu_dir, "fmu_dir")
    check_progress(progress)
    if out is not None and replicates != 1:
        raise ConfigError(f"out: writes one run (the files of sblsim run); replicates is {replicates}")
    target = _prepare_out(out, force, "summary.json", "run")
    result = _simulate(plan, engine, replicates, fmu_dir, progress)
    if target is not None:
        write_run(result, target)
    return _run_result(result, target)


def _simulate(plan: RunPlan, engine: str, replicates: int = 1, fmu_dir: str | Path | None = None,
              progress: Any = False, ssp: Any = None) -> Any:
    """Simulate a plan's replicates ``run.replicate`` … (``sblsim run`` and :func:`run`); ``ssp``, an SSP
    package read back (:func:`sblsim.orchestrator.ssp.read_ssp`: its plan is ``plan``), brings its connections
    and, on the fmu engine, its FMUs."""
    from sblsim.orchestrator.cosim.run import run as _run

    handles, connections = None, None
    if ssp is not None:
        connections = ssp.connections
        handles = make_handles(engine, None, plan.n_beacons, dict(plan.sources),
                               fmu_files=ssp.fmu_files if engine == "fmu" else None)
    try:
        return _run(plan, engine, range(plan.replicate, plan.replicate + replicates), fmu_dir=fmu_dir,
                    handles=handles, progress=progress, connections=connections)
    finally:
        if handles is not None:
            close_handles(handles)


def _run_result(result: Any, target: Path | None = None) -> RunResult:
    return RunResult(Config(thaw(result.config)), result.engine, result.timeseries, result.metrics, result.steps,
                     result.wall_time, target, result)


# --------------------------------------------------------------------------- compare

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
        from sblsim.orchestrator.compare import markdown

        return markdown(self.table)

    def plot(self) -> Figure:
        """The figure ``compare.png``."""
        from sblsim.orchestrator.compare import plot

        return plot(self.table, self.title)


def _listed(value: str | Sequence[str] | None, what: str) -> str | None:
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
    from sblsim.orchestrator.compare import check_replicates, parse_receivers, plans, write
    from sblsim.orchestrator.compare import compare as _compare

    _check_seed(seed)
    _check_engine(engine)
    _check_count(replicates, "replicates", -2**63, 2**63)  # an integer; its range is checked by the comparison
    fmu_dir = _path(fmu_dir, "fmu_dir")
    check_progress(progress)
    items = _override_items(set)
    source = _source(scenario, configuration=True)
    names = parse_receivers(_listed(receivers, "receivers") or "")
    chosen = parse_systems(_listed(systems, "systems")) if systems is not None else None
    if chosen is not None:
        system_overrides(chosen[0], items)  # refuses a platform.system override before any work
    check_replicates(replicates)
    compared = plans(source, names, items, seed, chosen)  # each system and receiver resolved once
    target = _prepare_out(out, force, "compare.csv", "comparison")
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


def _source(scenario: Any, configuration: bool = False) -> str | Path | Mapping:
    """A scenario argument of the functions that take a name or file, or (``configuration``) a configuration
    too (a :class:`Config` or mapping, taken as it is)."""
    if isinstance(scenario, Mapping):
        if configuration:
            return scenario
        raise ConfigError("scenario: this function takes a built-in scenario or a CONFIG.toml; write a "
                          "configuration with Config.to_toml() and give the file")
    if not isinstance(scenario, (str, Path)):
        raise ConfigError(f"scenario: expected a built-in scenario or a TOML file, got {type(scenario).__name__}")
    return str(scenario)


# --------------------------------------------------------------------------- accuracy map

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


def _compared(compare: str | tuple[str, Sequence[Any]] | None) -> tuple[str, list[str]] | None:
    if compare is None:
        return None
    if isinstance(compare, str):
        return parse_compare(compare)
    try:
        key, values = compare
    except (TypeError, ValueError):
        raise ConfigError(f"compare: expected 'KEY=V1,V2' or (key, [values]), got {shown(compare)}") from None
    if not isinstance(key, str):
        raise ConfigError(f"compare: the key must be a text 'section.key', got {shown(key)}")
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
        raise ConfigError(f"compare: the values of {key} must be a list of at least one value, got {shown(values)}")
    return parse_compare(f"{key}={','.join(str(v) for v in values)}")


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

    _check_seed(seed)
    source = _source(scenario)
    extent = _real(extent, "extent", 0.0, MAX_EXTENT, "m", low_open=True)
    step = _real(step, "step", 0.0, extent, "m (the extent)", low_open=True)
    depth = None if depth is None else _real(depth, "depth", 0.0, 11000.0, "m")
    check_progress(progress)
    if isinstance(levels, (str, bytes)) or not isinstance(levels, (Sequence, np.ndarray)):
        raise ConfigError(f"levels: expected a list of accuracies [m], got {shown(levels)}")
    try:
        level_text = ",".join(repr(float(v)) for v in levels)
    except (TypeError, ValueError):
        raise ConfigError(f"levels: expected numbers [m], got {shown(levels)}") from None
    return _accuracy_map(source, _override_items(set), seed, extent, step, parse_levels(level_text, "levels"),
                         _compared(compare), depth, progress, lambda: _prepare_out(out, force, "map.csv", "map"),
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


# --------------------------------------------------------------------------- budget

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
        from sblsim.orchestrator.budget import table

        return table(self.budgets, self.compared[0] if self.compared else None)

    def markdown(self) -> str:
        """``budget.md``'s table."""
        from sblsim.orchestrator.budget import markdown

        return markdown(self.budgets, self.compared[0] if self.compared else None)

    def lines(self) -> list[str]:
        """What ``sblsim budget`` prints for each budget: one line per source, the floor, remainder, total
        and what to improve first."""
        from sblsim.orchestrator.budget import advice, lines

        out = []
        for b in self.budgets:
            if self.compared is not None:
                out.append(f"{b.label}:")
            out += lines(b)
            out.append(f"  {advice(b)}")
        return out

    def plot(self) -> Figure:
        """The figure ``budget.png``."""
        from sblsim.orchestrator.budget import plot

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
    from sblsim.orchestrator.budget import DEFAULT_REPLICATES, check_replicates

    _check_seed(seed)
    source = _source(scenario)
    receiver = _text(receiver, "receiver")
    check_progress(progress)
    _prepare_out(out, force, "budget.csv", "budget")  # before any work (and again once the plans are made)
    replicates = DEFAULT_REPLICATES if replicates is None else replicates
    _check_count(replicates, "replicates", -2**63, 2**63)
    check_replicates(replicates)
    if isinstance(compare, str):
        chosen = parse_compare(compare, "platform.system=" + ",".join(SYSTEMS))
    else:
        chosen = _compared(compare)
    if receiver is not None:
        check_receiver(receiver, "receiver")
    return _budget(source, _override_items(set), seed, receiver, chosen, replicates, progress,
                   lambda: _prepare_out(out, force, "budget.csv", "budget"))


def _budget(source: str, items: list[str], seed: int | None, receiver: str | None,
            chosen: tuple[str, list[str]] | None, replicates: int, progress: Any,
            prepare: Callable[[], Path | None]) -> BudgetResult:
    """:func:`budget` (and ``sblsim budget``) after the checks of its arguments: each configuration and its
    switched-off ones resolved once, ``prepare()`` the output folder (None: nothing is written), run, write."""
    from sblsim.orchestrator.budget import budgets, configurations, title, write

    configs = configurations(source, items, seed, receiver, chosen)  # every check before any output
    target = prepare()
    results = budgets(configs, replicates, progress=progress)
    heading = title(source, results, items)
    if target is not None:
        write(results, target, heading, chosen[0] if chosen else None)
    return BudgetResult(results, heading, chosen, target)


# --------------------------------------------------------------------------- replay

@dataclass
class ReplayResult:
    """The outcome of :func:`replay`.

    Attributes
    ----------
    config : Config
        The configuration the receiver ran with.
    source : str
        Where that configuration came from.
    engine : str
    summary : dict
        ``summary.json``: a run's keys (errors None without a truth track), ``log`` (what was read of the
        log) and ``truth``.
    timeseries : pandas.DataFrame
        One row per macro step: ``time`` [s] on the log's clock, ``log_row``, the receiver's inputs and
        outputs; with a truth track ``true_*`` [m], ``pcrb`` and the errors ``e_*`` [m].
    out : Path or None
    """

    config: Config
    source: str
    engine: str
    summary: dict[str, Any]
    timeseries: pd.DataFrame
    out: Path | None = None
    _plan: Any = field(default=None, repr=False)

    def plot(self) -> dict[str, Figure]:
        """The figures of a run over the steps the truth track covers (empty without truth)."""
        from sblsim.orchestrator.io.plots import run_figures

        ts = self.timeseries
        covered = ts[np.isfinite(ts["true_x"].to_numpy())] if "true_x" in ts else ts.iloc[:0]
        if not len(covered):
            return {}
        receiver = self._plan.receiver_label if self._plan is not None else self.config.plan().receiver_label
        if "replicate" not in covered:
            covered = covered.assign(replicate=0)
        return run_figures(covered, f"replay of {self.summary['log']['file']}, {receiver} ({self.engine})", receiver)


def replay(log: str | Path, *, receiver: str | None = None, config: str | Path | None = None,
           truth: str | Path | None = None, engine: str = "local", set: Overrides = None,
           fmu_dir: str | Path | None = None, out: str | Path | None = None, force: bool = False) -> ReplayResult:
    """Run a receiver on a recorded log: ``sblsim replay``.

    Parameters
    ----------
    log : str or Path
        The log, ``.csv`` or ``.parquet`` (the log-format page; ``sblsim run --export-log`` writes one).
    receiver : str, optional
        ``ekf``, ``ekf-seq``, ``ukf``, ``lsq``, ``model:PATH.py`` or ``fmu:PATH`` (default the
        configuration's).
    config : str or Path, optional
        The receiver's parameters, T and rate ratio: a built-in scenario or ``CONFIG.toml`` (default the
        configuration an exported log carries, else the semicircle scenario's).
    truth : str or Path, optional
        Truth track (``time_s``, ``n_m``, ``e_m``, ``d_m``): errors, consistency and figures.
    engine, set, fmu_dir
        As for :func:`run`.
    out : str or Path, optional
        Write ``summary.json``, ``config.toml``, ``timeseries.parquet`` and the figures there.
    force : bool
        Replace an earlier replay in ``out``.

    Returns
    -------
    ReplayResult

    Raises
    ------
    ConfigError, SblsimError
        A log or truth track that cannot be read (the message names the row and column), bad options.
    """
    from sblsim.orchestrator.replay import replay_config

    _check_engine(engine)
    log = _path(log, "log", optional=False)
    truth = _path(truth, "truth")
    fmu_dir = _path(fmu_dir, "fmu_dir")
    receiver = _text(receiver, "receiver")
    config = None if config is None else str(_path(config, "config"))
    _prepare_out(out, force, "summary.json", "replay")  # before any work (and again once the log is read)
    plan, source = replay_config(log, config, receiver, _override_items(set))
    return _replay_plan(plan, source, log, truth, engine, fmu_dir,
                        lambda: _prepare_out(out, force, "summary.json", "replay"))


def _replay_plan(plan: RunPlan, source: str, log: Path, truth: Path | None, engine: str,
                 fmu_dir: str | Path | None, prepare: Callable[[], Path | None]) -> ReplayResult:
    """:func:`replay` of a plan (and ``sblsim replay``): read the log and the truth track, ``prepare()`` the
    output folder (None: nothing is written), replay and write."""
    from sblsim.orchestrator.replay import read_log, read_truth, write_replay
    from sblsim.orchestrator.replay import replay as _replay

    data = read_log(log, plan.n_beacons, plan.system, plan["acoustics"]["sound_speed_assumed"])
    track = read_truth(truth) if truth is not None else None
    target = prepare()
    result = _replay(data, plan, engine, fmu_dir, track)
    if target is not None:
        write_replay(result, target)
    return ReplayResult(Config(thaw(result.config)), source, result.engine, result.summary, result.timeseries,
                        target, result.config)


# --------------------------------------------------------------------------- calibration

@dataclass
class CalibrationResult:
    """The outcome of :func:`calibrate`.

    Attributes
    ----------
    name : str
        The survey's name (the default output folder's).
    sound_speed : str
        What the travel times were computed with: a sound speed, straight rays at each transponder's harmonic
        mean of a profile, or eigenrays through one.
    segments : int
        The survey's segments, each solved on its own before they are combined.
    solution : dict
        ``solution.json``: each transponder's position from its a-priori ENU [m] with its sigma [m], the
        sound speed [m/s], the residuals' RMS [s], the solver's settings; a simulated survey's truth, errors
        [m] and bound [m].
    residuals : pandas.DataFrame
        ``residuals.csv``: one row per reply, its TWTT residual [s] and whether it was used.
    running : pandas.DataFrame or None
        ``running.csv``: the running solution (Kalman form), one row per reply.
    ntd : pandas.DataFrame or None
        ``ntd.csv``: the sound-speed perturbation of each reply (a moving-ocean solve).
    search : pandas.DataFrame or None
        ``criterion.csv``: the candidates of the number of bases' search.
    replicates : pandas.DataFrame or None
        ``replicates.parquet``: a simulated survey's replicates (errors against the truth [m], NEES, bound).
    notes, warnings : list of str
        What was left out of the log, and what a user must know about the solution (one line each).
    out : Path or None
    """

    name: str
    sound_speed: str
    segments: int
    solution: dict[str, Any]
    residuals: pd.DataFrame
    running: pd.DataFrame | None
    ntd: pd.DataFrame | None
    search: pd.DataFrame | None
    replicates: pd.DataFrame | None
    notes: list[str]
    warnings: list[str]
    out: Path | None = None


def calibrate(survey: str | Path, *, format: str | None = None, initcfg: str | Path | None = None,
              svp: str | Path | None = None, set: Overrides = None, replicates: int | None = None,
              out: str | Path | None = None, force: bool = False, progress: Progress = False) -> CalibrationResult:
    """Locate seafloor transponders from a surface survey's two-way travel times: ``sblsim calibrate``.

    The box-in least squares of GNSS-Acoustic calibration (docs/calibration.md), with the moving-ocean
    perturbation of SeaGap and GARPOS where the survey asks for it; a simulated survey (``box-in`` or a
    ``CONFIG.toml``) is solved against its truth.

    Parameters
    ----------
    survey : str or Path
        A built-in survey (``xie-2021-07-23``, ``ncl1-2022-208``, ``seagap-example``, ``box-in``, ...), a
        survey log (``.csv`` or ``.parquet``; a text file with ``format='xie'``; a SeaGap folder with
        ``format='seagap'``) or a simulated survey's ``CONFIG.toml``.
    format : str, optional
        The log's format: ``sblsim`` (default), ``xie``, ``seagap`` or ``garpos`` (with ``initcfg`` and
        ``svp``).
    initcfg, svp : str or Path, optional
        ``format='garpos'``: GARPOS's initial site-parameter file (the paths it names are not read) and its
        sound-speed profile.
    set : mapping or sequence of str, optional
        Solver settings (``solver.sound_speed_mps``, ...) or a simulated survey's ``survey.KEY`` /
        ``platform.KEY``.
    replicates : int, optional
        A simulated survey: solve this many replicates (``replicates`` of the result).
    out : str or Path, optional
        Write ``solution.json``, ``residuals.csv`` and the figures there (and the tables above that exist).
    force : bool
        Replace an earlier calibration in ``out``.
    progress : bool or callable
        Report a simulated survey's replicates solved.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ConfigError, SblsimError
        A survey that cannot be read (the message names the row and column), bad settings or options.
    """
    source = str(_path(survey, "survey", optional=False))
    fmt = _text(format, "format")
    initcfg, svp = _path(initcfg, "initcfg"), _path(svp, "svp")
    _integer(replicates, "replicates")  # its range the survey's
    check_progress(progress)
    _prepare_out(out, force, "solution.json", "calibration")  # before any work (and again before the write)
    return _calibrate(source, fmt, _override_items(set), initcfg, svp, replicates, progress,
                      lambda name: _prepare_out(out, force, "solution.json", "calibration"), lambda n: n)


def _calibrate(source: str, fmt: str | None, overrides: list[str], initcfg: Path | str | None,
               svp: Path | str | None, replicates: int | None, progress: Any,
               prepare: Callable[[str], Path | None], option: Callable[[str], str]) -> CalibrationResult:
    """:func:`calibrate` (and ``sblsim calibrate``): read the survey, solve it, ``prepare(name)`` the output
    folder (None: nothing is written; a survey's log is solved first, a simulated survey's folder prepared
    first) and write. ``option(name)`` is how an option is named in a message (``--replicates`` on the command
    line)."""
    from sblsim.orchestrator.surveys.calibrate import calibrate as solve
    from sblsim.orchestrator.surveys.calibrate import load_survey, write_calibration
    from sblsim.orchestrator.surveys.log import write_log
    from sblsim.orchestrator.surveys.simulate import REPLICATES_RANGE, is_simulated, load_simulated, run_simulated

    table, extra = None, {}
    if not is_simulated(source):
        if replicates is not None:
            raise ConfigError(f"{option('replicates')}: only a simulated survey (box-in or a CONFIG.toml) has "
                              "replicates")
        survey = load_survey(source, fmt, overrides, initcfg, svp)  # all read first
        result, name = solve(survey), survey.name
        target = prepare(name)
    else:
        if fmt is not None or initcfg is not None or svp is not None:
            raise ConfigError(f"{option('format')}: a simulated survey has no log format; give "
                              f"{option('format')} with a log")
        if replicates is not None and not REPLICATES_RANGE[0] <= replicates <= REPLICATES_RANGE[1]:
            raise ConfigError(f"{option('replicates')}: {replicates} is outside the allowed range "
                              f"[{REPLICATES_RANGE[0]}, {REPLICATES_RANGE[1]}]")
        sim = load_simulated(source, overrides)  # every input read and checked first
        name = sim.name
        target = prepare(name)
        result, table = run_simulated(sim, replicates, progress=progress)
        survey = result.survey
        extra = {"survey_log.csv": lambda path: write_log(survey.log, path)}  # replicate 0's log
        if table is not None:
            extra["replicates.parquet"] = lambda path: table.to_parquet(path, index=False)
    if target is not None:
        write_calibration(result, target, extra)
    s = result.solution
    profile = s["solver"]["sound_speed_profile"] or "the survey's own profile"
    if s["solver"]["propagation"] == "ray":
        speed = f"eigenrays through {profile}"
    elif s["solver"]["sound_speed_profile"] or survey.profile is not None:
        speed = f"straight rays at each transponder's harmonic mean of {profile}"
    else:
        speed = f"sound speed {s['sound_speed_mps']:.6g} m/s"
    return CalibrationResult(name, speed, len(result.segments), s, result.residuals, result.running,
                             result.ntd, result.search, table, list(survey.notes), list(result.warnings), target)


# --------------------------------------------------------------------------- campaign and analysis

@dataclass
class CampaignResult:
    """The outcome of :func:`campaign`.

    Attributes
    ----------
    out : Path
        The campaign directory.
    total : int
        Runs in ``runs.parquet``.
    computed : int
        Runs simulated by this call (0 when a finished campaign is resumed).
    wall_time : float
        Wall-clock time of the simulation [s].
    """

    out: Path
    total: int
    computed: int
    wall_time: float
    _result: Any = field(default=None, repr=False)

    @property
    def runs(self) -> pd.DataFrame:
        """``runs.parquet``: one row per run, the factors' levels and the metrics (read when first asked)."""
        return self._result.runs

    def analyze(self, **options: Any) -> AnalysisResult:
        """:func:`analyze` of this campaign (options as for :func:`analyze`)."""
        return analyze(self.out, **options)


def campaign(study: str | Path | Mapping, out: str | Path, *, seed: int | None = None, engine: str = "local",
             workers: int | None = None, scheduler: str | None = None, resume: bool = False,
             batch: int | None = None, save_timeseries: bool = False, fmu_dir: str | Path | None = None,
             progress: Progress = False) -> CampaignResult:
    """A factorial Monte Carlo study: ``sblsim campaign``.

    Parameters
    ----------
    study : str, Path or mapping
        A built-in study (``paper``), a ``STUDY.toml`` or a study's tables.
    out : str or Path
        The campaign directory (written: ``study.toml``, ``chunks/``, ``manifest.json``, ``runs.parquet``).
    seed : int, optional
        The campaign seed (default the study's).
    engine : {'local', 'fmu'}
    workers : int, optional
        Worker processes (default all cores; 1: in this process).
    scheduler : str, optional
        A Dask distributed scheduler ``tcp://host:port``, or ``local``.
    resume : bool
        Finish the campaign in ``out`` (missing chunks only).
    batch : int, optional
        Runs per chunk (does not change the results).
    save_timeseries : bool
        Also write every run's per-step time series.
    fmu_dir : str or Path, optional
        The built FMUs (fmu engine).
    progress : bool or callable
        Report the runs done (``True``: a bar; a callable ``progress(done, total)`` [runs]).

    Returns
    -------
    CampaignResult

    Raises
    ------
    SblsimError
        Bad input (nothing is written).
    sblsim.orchestrator.campaign.CampaignInterrupted
        On Ctrl-C: the finished chunks are kept (``resume=True`` finishes).
    """
    from sblsim.orchestrator.campaign import run_campaign

    _check_seed(seed)
    _check_engine(engine)
    out = _path(out, "out", optional=False)
    fmu_dir = _path(fmu_dir, "fmu_dir")
    scheduler = _text(scheduler, "scheduler")
    resume, save_timeseries = _flag(resume, "resume"), _flag(save_timeseries, "save_timeseries")
    _integer(workers, "workers")  # their ranges the campaign's
    _integer(batch, "batch")
    check_progress(progress)
    if isinstance(study, Study):  # validated already (sblsim campaign loads it to name its output)
        if seed is not None:
            raise ConfigError("seed: a loaded study holds its seed; give the seed to load_study")
        loaded = study
    else:
        if isinstance(study, Mapping):
            study = dict(study)
        elif isinstance(study, Path):
            study = str(study)
        elif not isinstance(study, str):
            raise ConfigError(f"study: expected a built-in study, a STUDY.toml or a study's tables, got "
                              f"{shown(study)}")
        loaded = load_study(study, seed=seed)
    check_writable(out, "out")
    # "auto" (sblsim campaign): a bar at a terminal, log lines otherwise
    spec: Any = (None if isinstance(progress, str) and progress == "auto" else "off" if progress in (False, None)
                 else True if progress is True else progress)
    result = run_campaign(loaded, out, workers=workers, scheduler=scheduler, resume=resume, engine=engine,
                          batch=batch, fmu_dir=fmu_dir, save_timeseries=save_timeseries, progress=spec)
    return CampaignResult(result.out, result.total, result.computed, result.wall_time, result)


@dataclass
class AnalysisResult:
    """The outcome of :func:`analyze`.

    Attributes
    ----------
    effects : pandas.DataFrame
        ``effects.csv``: per scenario and term, ``effect``, ``coefficient``, ``std_err``, ``t``, ``p_value``
        (in the metric's unit, [m] for the errors; with ``transform="log"`` also ``ratio``).
    anova : pandas.DataFrame
        ``anova.csv``.
    tables : pandas.DataFrame
        ``tables.csv``: the tidy tables of the report.
    diagnostics : pandas.DataFrame
        ``diagnostics.csv``: one row per scenario.
    warnings : list of str
    fits : dict
        Scenario -> the fit (its ``effects``, ``anova``, ``lmbda``, ...).
    out : Path or None
    """

    effects: pd.DataFrame
    anova: pd.DataFrame
    tables: pd.DataFrame
    diagnostics: pd.DataFrame
    warnings: list[str]
    fits: dict[str, Any]
    out: Path | None = None
    _analysis: Any = field(default=None, repr=False)

    def plot(self, scenario: str | None = None) -> dict[str, Figure]:
        """The report's figures of one scenario (default the first): ``pareto``, ``main_effects``,
        ``interactions``, ``residuals`` -> matplotlib Figure.

        Raises
        ------
        ConfigError
            A scenario the campaign does not have.
        """
        from sblsim.orchestrator.analysis.plots import figures

        a = self._analysis
        name = next(iter(a.fits)) if scenario is None else scenario
        if name not in a.fits:
            raise ConfigError(f"scenario: {name!r} is not one of {', '.join(a.fits)}")
        return figures(a.fits[name], a.runs[a.runs["scenario"] == name], a.study.factors)


def analyze(directory: str | Path, *, metric: str = "e_tot_rms", order: int = 2, transform: str = "none",
            alpha: float = 0.05, out: str | Path | None = None, progress: Callable[[str], object] | None = None
            ) -> AnalysisResult:
    """The factorial analysis of a campaign: ``sblsim analyze``.

    Parameters
    ----------
    directory : str or Path
        A campaign directory (with ``runs.parquet`` and ``study.toml``).
    metric : str
        The response column: an error metric (default ``e_tot_rms`` [m]) or ``detected_pct`` [%], the share of
        the slots whose packet was received.
    order : int
        Highest interaction order of the model, 1 … number of factors.
    transform : {'none', 'log', 'boxcox'}
        Fit the metric, its logarithm (effects as factors) or its Box-Cox transform.
    alpha : float
        Significance level [-], (0, 1).
    out : str or Path, optional
        Write the report, tables and figures there (``sblsim analyze`` writes into the campaign directory).
    progress : callable, optional
        Called with one line per step of the work.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    SblsimError
        Missing or corrupt ``runs.parquet`` or ``study.toml``, unknown metric or transform, bad order or
        alpha.
    """
    import pandas as pd

    from sblsim.orchestrator.analysis import compute, write

    directory = _path(directory, "directory", optional=False)
    out = _path(out, "out")
    _text(metric, "metric", optional=False)
    _text(transform, "transform", optional=False)
    _check_count(order, "order", 1, 2**31 - 1)
    _real(alpha, "alpha", 0.0, 1.0, "", low_open=True)
    if progress is not None and not callable(progress):
        raise ConfigError(f"progress: {shown(progress)} is not None or a callable(line)")
    if out is not None:
        check_writable(out, "out")
    a = compute(directory, metric, order, alpha, progress=progress, transform=transform)
    target = write(a, out, progress=progress) if out is not None else None
    effects = pd.concat([r.effects.assign(scenario=s) for s, r in a.fits.items()], ignore_index=True)
    anova = pd.concat([r.anova.assign(scenario=s) for s, r in a.fits.items()], ignore_index=True)
    return AnalysisResult(effects, anova, a.tables, a.diagnostics, list(a.warnings), dict(a.fits), target, a)

