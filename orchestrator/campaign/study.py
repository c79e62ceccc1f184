"""Factorial Monte Carlo studies: scenarios × 2-level design cells × replicates.

A study file (TOML) names the scenarios, the factors (any configuration key
with its LOW and HIGH level), the design, the replicates and the campaign
seed::

    [study]
    name = "paper"
    scenarios = ["semicircle", "spiral", "random"]   # built-in names or TOML files
    replicates = 50
    seed = 1
    design = "full"          # 2-level full factorial, or "fractional"
    resolution = 4           # fractional: the lowest resolution wanted (pyDOE3)
    generators = ""          # fractional: or explicit generators, e.g. "a b c d abc"
    set = []                 # overrides applied to every scenario ("section.key=value")

    [[factors]]
    name = "baseline"
    key = "platform.baseline"
    low = 0.4
    high = 3.0

Design cell ``c`` is row ``c`` of the design matrix of pyDOE3 (``ff2n`` for
the full factorial: the first factor changes slowest; ``fracfact_by_res`` or
``fracfact`` for a fractional one), coded −1 (LOW) and +1 (HIGH): made by
:mod:`sblsim.orchestrator.campaign.factorial`. Every
value is validated against the declaration of its key before anything runs,
so a bad level gets a one-line error naming the factor and the allowed range.
A study as a campaign's results record it is :mod:`sblsim.orchestrator.campaign.study_record`'s.

References
----------
Montgomery, Design and Analysis of Experiments, 9th ed., Wiley 2017,
chapters 6 (2^k designs) and 8 (2^(k-p) fractional designs). Cario et al.,
Sensors 21(3):762, 2021, doi:10.3390/s21030762, Table 3 (the paper study).
"""

from __future__ import annotations

import copy
import json
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from sblsim.models import RECEIVER_MODELS
from sblsim.models.acoustics.channel.interface import FIXED_KEYS, SNR_KEYS
from sblsim.models.declarations import ModelError, Variable, shown
from sblsim.orchestrator.campaign.errors import StudyError
from sblsim.orchestrator.campaign.factorial import design_matrix
from sblsim.orchestrator.cosim.config import (
    BUILTIN_SCENARIOS,
    SECTIONS,
    check_receiver,
    load_config,
    read_source,
    section_variables,
)
from sblsim.orchestrator.cosim.metrics import RUN_METRICS
from sblsim.orchestrator.cosim.plan import RunPlan, load_plan
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.paths import inside

BUILTIN_STUDIES = ("paper", "million")
DESIGNS = ("full", "fractional")
_STUDY_KEYS = {"name", "scenarios", "replicates", "seed", "design", "resolution", "generators", "set"}
_FACTOR_KEYS = {"name", "key", "low", "high"}
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*$")
#: Columns of ``runs.parquet`` besides the factors and the metrics (a factor may not take their names).
RESULT_COLUMNS = ("scenario", "scenario_key", "cell", "replicate", "seed", "receiver")


@dataclass(frozen=True)
class Factor:
    """One 2-level factor.

    Attributes
    ----------
    name : str
        Identifier used in result columns and model terms.
    key : str
        Configuration key ``section.name`` it sets ('' when unknown: inferred from results).
    low, high : float or str
        Levels in the key's unit (coded −1 and +1); text for a text key (e.g. a receiver).
    unit : str
        Unit of the levels, e.g. ``m``, ``deg``, ``s``, ``%``.
    description : str
    variable : Variable or None
        The key's declaration (type, unit, allowed range), when the study was validated.
    """

    name: str
    key: str
    low: Any
    high: Any
    unit: str = ""
    description: str = ""
    variable: Variable | None = field(default=None, compare=False, repr=False)

    @property
    def section(self) -> str:
        return self.key.split(".", 1)[0]

    def level(self, coded: int) -> Any:
        """Physical level of a coded level (−1 or +1)."""
        return self.low if coded < 0 else self.high


@dataclass
class Study:
    """A validated, resolved study.

    Attributes
    ----------
    name : str
    scenarios : list of str
        Built-in scenario names or absolute paths of TOML files.
    replicates : int
        Runs per design cell and scenario.
    seed : int
        Campaign seed (root of the seed tree).
    design : {'full', 'fractional'}
    resolution : int
        Requested resolution of a fractional design (0: not used).
    generators : str
        Explicit generators of a fractional design ('' : not used).
    overrides : list of str
        ``section.key=value`` applied to every scenario before the factors.
    factors : list of Factor
    matrix : ndarray of int, shape (cells, k)
        Coded design matrix (−1/+1); row ``c`` is design cell ``c``.
    """

    name: str
    scenarios: list[str]
    replicates: int
    seed: int
    design: str
    resolution: int
    generators: str
    overrides: list[str]
    factors: list[Factor]
    matrix: np.ndarray = field(repr=False)

    @property
    def cells(self) -> int:
        return int(self.matrix.shape[0])

    @property
    def runs(self) -> int:
        return len(self.scenarios) * self.cells * self.replicates

    def cell_overrides(self, cell: int) -> list[str]:
        """``--set`` items of the factors' levels in a design cell."""
        return [f"{f.key}={json.dumps(f.level(int(c)))}" for f, c in zip(self.factors, self.matrix[cell])]

    def cell_config(self, scenario: str, cell: int) -> dict:
        """Resolved configuration of one design cell (``run.cell`` set, replicate 0).

        Raises
        ------
        ConfigError, ModelError
            If the levels do not make a valid configuration for the scenario.
        """
        return load_config(scenario, self._cell_settings(cell), seed=self.seed)

    def cell_plan(self, scenario: str, cell: int) -> RunPlan:
        """The plan of one design cell (``run.cell`` set, replicate 0), resolved once
        (:func:`sblsim.orchestrator.cosim.plan.load_plan`); its replicates share it.

        Raises
        ------
        ConfigError, ModelError
            If the levels do not make a valid configuration for the scenario.
        """
        return load_plan(scenario, self._cell_settings(cell), seed=self.seed)

    def _cell_settings(self, cell: int) -> list[str]:
        """The study's overrides, the cell's levels and ``run.cell``, in that order."""
        return [*self.overrides, *self.cell_overrides(cell), f"run.cell={cell}"]

    def to_dict(self) -> dict[str, Any]:
        """The resolved study as a TOML-ready table (``study.toml``)."""
        return {
            "study": {"name": self.name, "scenarios": list(self.scenarios), "replicates": self.replicates,
                      "seed": self.seed, "design": self.design, "resolution": self.resolution,
                      "generators": self.generators, "set": list(self.overrides)},
            "factors": [{"name": f.name, "key": f.key, "low": f.low, "high": f.high, "unit": f.unit,
                         "description": f.description} for f in self.factors],
            "design": {"cells": self.cells, "matrix": self.matrix.tolist()},
        }

    def to_toml(self) -> str:
        header = "# sblsim resolved study: scenarios, factors with their levels, the design matrix (row = cell).\n"
        return header + tomli_w.dumps(self.to_dict())



def _check_type(table: dict, key: str, kinds: tuple[type, ...], what: str, where: str) -> Any:
    value = table[key]
    if isinstance(value, bool) and bool not in kinds or not isinstance(value, kinds):
        raise StudyError(f"{where}.{key}: expected {what}, got {value!r}")
    return value


def study_source(name: str) -> tuple[dict[str, Any], Path | None]:
    """Raw table of a built-in study or a study file, and the file's folder.

    Raises
    ------
    StudyError
        Unknown study, missing file or invalid TOML.
    """
    if name in BUILTIN_STUDIES:
        text = (resources.files("sblsim.orchestrator") / "studies" / f"{name}.toml").read_text()
        return tomlfile.loads(text), None
    path = Path(name)
    if not path.is_file():
        raise StudyError(f"study: unknown study {name!r}; one of {', '.join(BUILTIN_STUDIES)} or a study .toml file")
    try:
        return tomlfile.loads(path.read_text()), path.resolve().parent
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise StudyError(f"study: {name!r} is not valid TOML ({exc})") from None


def load_study(source: str | Path | dict[str, Any], seed: int | None = None) -> Study:
    """Validate and resolve a study: built-in name, TOML file or raw table.

    Parameters
    ----------
    source : str, Path or dict
        ``paper``, a study file, or its parsed table.
    seed : int, optional
        Overrides ``study.seed``.

    Returns
    -------
    Study

    Raises
    ------
    StudyError, ModelError
        On any invalid field (one line naming it and the allowed range).
    """
    if isinstance(source, dict):
        raw, base = copy.deepcopy(source), None
    else:
        raw, base = study_source(str(source))
    unknown = sorted(set(raw) - {"study", "factors"})
    if unknown:
        raise StudyError(f"{unknown[0]}: unknown table; a study has [study] and [[factors]]")
    table = raw.get("study")
    if not isinstance(table, dict):
        raise StudyError("study: missing [study] table")
    bad = sorted(set(table) - _STUDY_KEYS)
    if bad:
        raise StudyError(f"study.{bad[0]}: unknown key; known: {', '.join(sorted(_STUDY_KEYS))}")
    for key in ("scenarios", "replicates"):
        if key not in table:
            raise StudyError(f"study.{key}: missing")
    name = str(table.get("name", "study"))
    scenarios = _check_type(table, "scenarios", (list,), "a list of scenario names or files", "study")
    if not scenarios or not all(isinstance(s, str) for s in scenarios):
        raise StudyError("study.scenarios: expected a non-empty list of scenario names or .toml files")
    try:  # a scenario file the study file names: in the study file's folder (sblsim.orchestrator.io.paths)
        scenarios = [s if (base is None or s in BUILTIN_SCENARIOS) else
                     str(inside(base, s, "study.scenarios", "study file")) for s in scenarios]
    except ModelError as exc:
        raise StudyError(str(exc)) from None
    replicates = _check_type(table, "replicates", (int,), "a whole number of replicates", "study")
    if not 1 <= replicates <= 1_000_000:
        raise StudyError(f"study.replicates: {replicates} is outside the allowed range [1, 1000000]")
    if seed is None:
        seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= 2**31 - 1:
        raise StudyError(f"study.seed: {shown(seed)} is outside the allowed range [0, 2147483647]")
    design = table.get("design", "full")
    if design not in DESIGNS:
        raise StudyError(f"study.design: {design!r} is not allowed; one of {', '.join(DESIGNS)}")
    resolution = table.get("resolution", 0)
    generators = table.get("generators", "")
    if isinstance(resolution, bool) or not isinstance(resolution, int) or not isinstance(generators, str):
        raise StudyError("study.resolution/generators: expected a whole number and a text")
    overrides = table.get("set", [])
    if not isinstance(overrides, list) or not all(isinstance(o, str) for o in overrides):
        raise StudyError("study.set: expected a list of 'section.key=value' items")

    factors = _factors(raw.get("factors"))
    matrix = design_matrix(len(factors), design, resolution, generators)
    study = Study(name, scenarios, replicates, int(seed), design, resolution if design == "fractional" else 0,
                  generators if design == "fractional" else "", overrides, factors, matrix)
    _check_scenarios(study)
    return study


def _factors(items: Any) -> list[Factor]:
    if not isinstance(items, list) or not items:
        raise StudyError("factors: expected at least one [[factors]] table")
    factors, names, keys = [], set(), set()
    for k, item in enumerate(items):
        where = f"factors[{k}]"
        if not isinstance(item, dict):
            raise StudyError(f"{where}: expected a table with {', '.join(sorted(_FACTOR_KEYS))}")
        bad = sorted(set(item) - _FACTOR_KEYS - {"unit", "description"})
        if bad:
            raise StudyError(f"{where}.{bad[0]}: unknown key; known: {', '.join(sorted(_FACTOR_KEYS))}")
        missing = sorted(_FACTOR_KEYS - set(item))
        if missing:
            raise StudyError(f"{where}.{missing[0]}: missing")
        name, key = item["name"], item["key"]
        if not isinstance(name, str) or not _NAME.match(name):
            raise StudyError(f"{where}.name: {name!r} is not an identifier (letters, digits, underscore)")
        if name in names:
            raise StudyError(f"{where}.name: {name!r} is used by two factors")
        if name in RESULT_COLUMNS or name.endswith("_value") or name in RUN_METRICS:
            raise StudyError(f"{where}.name: {name!r} is a column of the results ({', '.join(RESULT_COLUMNS)}, "
                             f"the metrics, NAME_value); choose another, e.g. {name + '_factor'!r}")
        if not isinstance(key, str) or key.count(".") != 1:
            raise StudyError(f"factors.{name}.key: expected section.name, got {key!r}; sections: "
                             f"{', '.join(s for s in SECTIONS if s != 'run')}")
        section, var_name = key.split(".")
        if section == "run":
            raise StudyError(f"factors.{name}.key: {key!r} is set by the campaign (seed tree), not a factor")
        try:
            declared = _declared(section)
        except ModelError:
            raise StudyError(f"factors.{name}.key: unknown section {section!r}; one of "
                             f"{', '.join(s for s in SECTIONS if s != 'run')}") from None
        if var_name not in declared:
            raise StudyError(f"factors.{name}.key: unknown key {key!r}; known in {section}: "
                             f"{', '.join(sorted(declared))}")
        if key in keys:
            raise StudyError(f"factors.{name}.key: {key!r} is set by two factors")
        var = declared[var_name]
        low = var.coerce(item["low"], f"factors.{name}.low")
        high = var.coerce(item["high"], f"factors.{name}.high")
        if key == "simulation.receiver":
            low, high = (check_receiver(v, f"factors.{name}.{w}") for v, w in ((low, "low"), (high, "high")))
        if low == high:
            raise StudyError(f"factors.{name}: LOW and HIGH are both {low!r}; a factor needs two levels")
        if var.type in ("Real", "Integer") and low > high:
            raise StudyError(f"factors.{name}: LOW ({low!r}) is above HIGH ({high!r}); swap them (an effect is the "
                             "change from LOW to HIGH)")
        names.add(name)
        keys.add(key)
        factors.append(Factor(name, key, low, high, var.unit, var.description, var))
    return factors


def _declared(section: str) -> dict[str, Variable]:
    """The keys a factor may set in a section; for ``receiver``, those of any built-in receiver
    (:func:`_check_receiver_factors` then checks them against the receiver each scenario and cell runs)."""
    if section != "receiver":
        return {v.name: v for v in section_variables(section)}
    declared: dict[str, Variable] = {}
    for receiver in RECEIVER_MODELS:
        for v in section_variables(section, receiver):
            declared.setdefault(v.name, v)
    return declared


def _check_receiver_factors(study: Study, scenario: str, cfg: dict) -> None:
    """Every ``receiver.*`` factor is a parameter of each receiver the scenario runs (its own, or the
    levels of a ``simulation.receiver`` factor)."""
    chosen = [f for f in study.factors if f.key == "simulation.receiver"]
    receivers = [chosen[0].low, chosen[0].high] if chosen else [cfg["simulation"]["receiver"]]
    for factor in study.factors:
        if factor.section != "receiver":
            continue
        for receiver in receivers:
            names = [v.name for v in section_variables("receiver", receiver)]
            if factor.key.split(".")[1] not in names:
                raise StudyError(f"factors.{factor.name}.key: {factor.key!r} is not a parameter of the {receiver} "
                                 f"receiver ({scenario}); its keys: {', '.join(names)}")


def _check_detection_factors(study: Study, scenario: str, cfg: dict) -> None:
    """Every ``acoustics.*`` factor is read by the scenario's detection: a key of the site
    (:data:`~sblsim.models.acoustics.core.SNR_KEYS`) needs ``acoustics.detection = "snr"``, one of the fixed
    percentages (:data:`~sblsim.models.acoustics.core.FIXED_KEYS`) ``"fixed"``; otherwise both of its levels would
    run the same (unless ``acoustics.detection`` is a factor too: then the interaction says it)."""
    if any(f.key == "acoustics.detection" for f in study.factors):
        return
    detection = cfg["acoustics"]["detection"]
    for factor in study.factors:
        name = factor.key.split(".")[1]
        if factor.section != "acoustics" or (name not in SNR_KEYS and name not in FIXED_KEYS):
            continue
        needed = "snr" if name in SNR_KEYS else "fixed"
        if detection != needed:
            how = ('"acoustics.detection=snr", "acoustics.propagation=ray"' if needed == "snr"
                   else '"acoustics.detection=fixed"')
            raise StudyError(f"factors.{factor.name}.key: {factor.key!r} is read only with acoustics.detection = "
                             f"{needed}, and {scenario} has {detection}: both levels would run the same; allowed: "
                             f"a scenario with detection {needed} (e.g. study.set = [{how}])")


def _check_scenarios(study: Study) -> None:
    """Every scenario resolves with its overrides, and scenario keys are distinct."""
    keys: dict[int, str] = {}
    for scenario in study.scenarios:
        read_source(scenario)  # unknown scenario / missing file
        cfg = load_config(scenario, study.overrides, seed=study.seed)
        _check_receiver_factors(study, scenario, cfg)
        _check_detection_factors(study, scenario, cfg)
        key = cfg["run"]["scenario_key"]
        if key in keys:
            raise StudyError(f"study.scenarios: {keys[key]!r} and {scenario!r} share run.scenario_key {key}; "
                             "give each scenario its own key (seed tree)")
        keys[key] = scenario


__all__ = ["BUILTIN_STUDIES", "DESIGNS", "RESULT_COLUMNS", "Factor", "Study", "load_study", "study_source"]
