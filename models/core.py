"""Shared machinery of the component cores: variable declarations and random streams.

Every component core declares its interface once, as a tuple of
:class:`Variable`. The same declarations generate the FMU model description,
validate configuration values, and drive the orchestrator's connection checks.
This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

CAUSALITIES = ("parameter", "input", "output")
TYPES = ("Real", "Integer", "Boolean", "String")


class ModelError(ValueError):
    """A parameter or input of a component core is invalid.

    The message is one line and names the offending field and its allowed
    range, so the command line can show it as it is.
    """


@dataclass(frozen=True)
class Variable:
    """One declared variable of a component (an FMI 2.0 ScalarVariable).

    Parameters
    ----------
    name : str
        Variable name, unique in its component.
    causality : {'parameter', 'input', 'output'}
        FMI causality.
    type : {'Real', 'Integer', 'Boolean', 'String'}
        FMI base type.
    start : Any
        Start value (default of a parameter, initial value of an input).
    unit : str
        Unit of a Real variable, in the FMI unit names of
        :data:`models.core.UNITS`; empty for non-Real variables.
    description : str
        One-line description.
    min, max : float, optional
        Allowed closed range of a numeric variable.
    min_exclusive : bool
        The lower bound itself is not allowed (e.g. a zero baseline).
    choices : tuple of str, optional
        Allowed values of a String variable (None: free text such as a path).
    """

    name: str
    causality: str
    type: str = "Real"
    start: Any = 0.0
    unit: str = ""
    description: str = ""
    min: float | None = None
    max: float | None = None
    min_exclusive: bool = False
    choices: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if self.causality not in CAUSALITIES:
            raise ValueError(f"{self.name}: causality {self.causality!r} not in {CAUSALITIES}")
        if self.type not in TYPES:
            raise ValueError(f"{self.name}: type {self.type!r} not in {TYPES}")
        if self.type == "Real" and self.unit not in UNITS:
            raise ValueError(f"{self.name}: unit {self.unit!r} is not declared in models.core.UNITS")

    @property
    def variability(self) -> str:
        """FMI variability: ``fixed`` for parameters, ``continuous`` for Real
        signals, ``discrete`` for the others."""
        if self.causality == "parameter":
            return "fixed"
        return "continuous" if self.type == "Real" else "discrete"

    def allowed(self) -> str:
        """Human-readable allowed range, e.g. ``(0, inf) m`` or ``one of a, b``."""
        if self.type == "String":
            return "one of " + ", ".join(self.choices) if self.choices else "text"
        if self.type == "Boolean":
            return "true or false"
        lo = "-inf" if self.min is None else f"{self.min:g}"
        hi = "inf" if self.max is None else f"{self.max:g}"
        left = "(" if (self.min is None or self.min_exclusive) else "["
        right = "]" if self.max is not None else ")"
        unit = f" {self.unit}" if self.unit and self.unit != "1" else ""
        return f"{left}{lo}, {hi}{right}{unit}"

    def coerce(self, value: Any, where: str = "") -> Any:
        """Check ``value`` against type and range and return it as the declared type.

        Raises
        ------
        ModelError
            If the value has the wrong type or lies outside the allowed range;
            the message names ``where`` (or the variable) and the allowed range.
        """
        label = where or self.name
        if self.type == "String":
            if not isinstance(value, str):
                raise ModelError(f"{label}: expected text ({self.allowed()}), got {value!r}")
            if self.choices is not None and value not in self.choices:
                raise ModelError(f"{label}: {value!r} is not allowed; {self.allowed()}")
            return value
        if self.type == "Boolean":
            if not isinstance(value, (bool, np.bool_)):
                raise ModelError(f"{label}: expected true or false, got {value!r}")
            return bool(value)
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ModelError(f"{label}: expected a number in {self.allowed()}, got {value!r}")
        if not math.isfinite(float(value)):
            raise ModelError(f"{label}: {value!r} is not finite; allowed {self.allowed()}")
        if self.type == "Integer":
            if float(value) != int(value):
                raise ModelError(f"{label}: expected a whole number in {self.allowed()}, got {value!r}")
            value = int(value)
        else:
            value = float(value)
        below = self.min is not None and (value < self.min or (self.min_exclusive and value == self.min))
        above = self.max is not None and value > self.max
        if below or above:
            raise ModelError(f"{label}: {value!r} is outside the allowed range {self.allowed()}")
        return value


#: FMI unit definitions used by the declarations: name -> (SI base-unit exponents, factor).
#: Exponents are over (m, s, rad); the factor converts to SI (deg -> rad, % -> 1).
UNITS: dict[str, tuple[dict[str, int], float]] = {
    "1": ({}, 1.0),
    "m": ({"m": 1}, 1.0),
    "s": ({"s": 1}, 1.0),
    "m/s": ({"m": 1, "s": -1}, 1.0),
    "rad": ({"rad": 1}, 1.0),
    "rad/s": ({"rad": 1, "s": -1}, 1.0),
    "deg": ({"rad": 1}, math.pi / 180.0),
    "%": ({}, 0.01),
    "ppm": ({}, 1e-6),
    "m2/s3": ({"m": 2, "s": -3}, 1.0),
    "degC": ({"K": 1}, 1.0),
    "g/kg": ({}, 1e-3),
}


#: Integer parameters that every stochastic component takes to seed its
#: random streams (DESIGN.md, "Randomness").
SEED_PARAMETERS: tuple[Variable, ...] = (
    Variable("seed", "parameter", "Integer", 0, description="Campaign seed", min=0, max=2**31 - 1),
    Variable("scenario_key", "parameter", "Integer", 0, description="Scenario index in the seed tree",
             min=0, max=2**31 - 1),
    Variable("cell", "parameter", "Integer", 0, description="Design-cell index in the seed tree",
             min=0, max=2**31 - 1),
    Variable("replicate", "parameter", "Integer", 0, description="Replicate index in the seed tree",
             min=0, max=2**31 - 1),
)


def parameters(variables: Sequence[Variable]) -> dict[str, Variable]:
    """Parameters of a declaration tuple, by name."""
    return {v.name: v for v in variables if v.causality == "parameter"}


def resolve_parameters(variables: Sequence[Variable], values: Mapping[str, Any], where: str = "") -> dict[str, Any]:
    """Fill defaults, validate and coerce the parameter values of one component.

    Parameters
    ----------
    variables : sequence of Variable
        The component's declarations.
    values : mapping
        Parameter values by name; missing ones take the declared start.
    where : str
        Prefix for error messages (e.g. ``platform``).

    Returns
    -------
    dict
        Every declared parameter, validated and coerced.

    Raises
    ------
    ModelError
        On an unknown name or a value outside its allowed range.
    """
    params = parameters(variables)
    unknown = sorted(set(values) - set(params))
    if unknown:
        prefix = f"{where}." if where else ""
        raise ModelError(f"{prefix}{unknown[0]}: unknown parameter; known: {', '.join(sorted(params))}")
    out = {}
    for name, var in params.items():
        label = f"{where}.{name}" if where else name
        out[name] = var.coerce(values.get(name, var.start), label)
    return out


class RandomStreams:
    """Independent, block-drawn random streams for a batch of replicates.

    Replicate ``b`` and purpose ``s`` draw from
    ``Generator(PCG64(SeedSequence(seed, spawn_key=(scenario, cell, replicate, component, s))))``,
    so a replicate's numbers do not depend on the batch it is stepped in,
    the engine, or the order of execution. Draws are taken ``BLOCK`` steps
    at a time per replicate, which keeps per-step cost independent of the
    generator call overhead while leaving the sequence unchanged.

    Parameters
    ----------
    seed : int
        Campaign seed.
    keys : ndarray of int, shape (B, 3)
        ``(scenario_key, cell, replicate)`` of each replicate of the batch.
    component : int
        Component index in the seed tree.
    """

    BLOCK: ClassVar[int] = 256

    def __init__(self, seed: int, keys: np.ndarray, component: int) -> None:
        self.seed = int(seed)
        self.keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
        self.component = int(component)
        self._buffers: dict[tuple[int, str], list] = {}

    def generators(self, purpose: int) -> list[np.random.Generator]:
        """One fresh generator per replicate for a purpose index."""
        return [
            np.random.Generator(np.random.PCG64(np.random.SeedSequence(
                self.seed, spawn_key=(int(k[0]), int(k[1]), int(k[2]), self.component, int(purpose)))))
            for k in self.keys
        ]

    def draw(self, purpose: int, kind: str, width: int) -> np.ndarray:
        """This step's draws of one stream.

        Parameters
        ----------
        purpose : int
            Stream index inside the component; each purpose must always be
            called with the same ``kind`` and ``width``.
        kind : {'normal', 'uniform'}
            Standard normal or uniform on [0, 1).
        width : int
            Numbers per replicate and step.

        Returns
        -------
        ndarray, shape (B, width)
        """
        key = (purpose, kind)
        entry = self._buffers.get(key)
        if entry is None:
            entry = [self.generators(purpose), None, self.BLOCK]
            self._buffers[key] = entry
        gens, block, pos = entry
        if pos >= self.BLOCK:
            if kind == "normal":
                block = np.stack([g.standard_normal((self.BLOCK, width)) for g in gens])
            elif kind == "uniform":
                block = np.stack([g.random((self.BLOCK, width)) for g in gens])
            else:
                raise ValueError(f"kind: {kind!r} is not 'normal' or 'uniform'")
            entry[1] = block
            pos = 0
        entry[2] = pos + 1
        return block[:, pos, :]


class ComponentCore:
    """Base of the component cores: an FMI-shaped life cycle on batched state.

    Subclasses set :attr:`name` and :attr:`component_index` and implement
    :meth:`variables`, :meth:`_initialize` and :meth:`_step`. Inputs and
    outputs are dictionaries of arrays of shape (B,), one entry per declared
    variable.

    Parameters
    ----------
    params : mapping
        Parameter values by name; missing ones take their declared start,
        and all are validated (:func:`resolve_parameters`).
        The names in :attr:`batched_parameters` may also be arrays of shape
        (B,), one value per replicate (a batch spanning several design cells).
    replicates : sequence of int, optional
        Replicate indices of the batch (B = ``len(replicates)``); default the
        single replicate ``params['replicate']``.
    n_beacons : int
        Number of beacons of the interface (4 for the SBL cross).

    Raises
    ------
    ModelError
        If a parameter is unknown or outside its allowed range, or an array is
        given for a parameter that is not in :attr:`batched_parameters`.
    """

    name: ClassVar[str] = ""
    component_index: ClassVar[int] = 0
    #: Parameters that may differ between the replicates of one batch (arrays
    #: of shape (B,)): the batch then spans several design cells.
    batched_parameters: ClassVar[frozenset[str]] = frozenset({"cell"})

    def __init__(self, params: Mapping[str, Any], replicates: Sequence[int] | None = None,
                 n_beacons: int = 4) -> None:
        if n_beacons < 1:
            raise ModelError(f"n_beacons: {n_beacons} is outside the allowed range [1, inf)")
        self.n_beacons = int(n_beacons)
        self.declarations = self.variables(self.n_beacons)
        if replicates is None:
            replicates = [params.get("replicate", 0)]
        self.replicates = np.asarray(replicates, dtype=np.int64).reshape(-1)
        self.batch = self.replicates.size
        scalars, arrays = self._split_batched(params)
        self.params = resolve_parameters(self.declarations, scalars, self.name)
        self.params.update(arrays)
        self.inputs: dict[str, np.ndarray] = {
            v.name: np.full(self.batch, v.start) for v in self.declarations if v.causality == "input"}
        self.outputs: dict[str, np.ndarray] = {}
        self.time = 0.0

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        """The component's declarations for ``n_beacons`` beacons."""
        raise NotImplementedError

    def _split_batched(self, params: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """Separate per-replicate parameter arrays from scalar values and validate them.

        An array of shape (B,) gives each replicate of the batch its own value;
        only the names in :attr:`batched_parameters` may be arrays. An array
        whose values are all equal is taken as that scalar.
        """
        declared = parameters(self.declarations)
        scalars: dict[str, Any] = {}
        arrays: dict[str, np.ndarray] = {}
        for name, value in params.items():
            if not isinstance(value, np.ndarray) or value.ndim == 0:
                scalars[name] = value
                continue
            if name not in self.batched_parameters:
                raise ModelError(f"{self.name}.{name}: must be the same for every replicate of a batch; "
                                 f"per-replicate values are allowed for {', '.join(sorted(self.batched_parameters))}")
            if value.shape != (self.batch,):
                raise ModelError(f"{self.name}.{name}: {value.shape[0]} per-replicate values for a batch of "
                                 f"{self.batch}")
            var = declared.get(name)
            if var is None:
                scalars[name] = value  # reported as unknown by resolve_parameters
                continue
            for item in np.unique(value):
                var.coerce(item.item(), f"{self.name}.{name}")
            if np.all(value == value[0]):
                scalars[name] = value[0].item()
            else:
                arrays[name] = value.astype(np.int64 if var.type == "Integer" else float)
        return scalars, arrays

    def streams(self) -> RandomStreams:
        """Random streams of this component for the batch (needs the seed parameters)."""
        keys = np.column_stack([
            np.broadcast_to(self.params["scenario_key"], self.batch),
            np.broadcast_to(self.params["cell"], self.batch),
            self.replicates,
        ])
        return RandomStreams(self.params["seed"], keys, self.component_index)

    def initialize(self, t0: float = 0.0) -> None:
        """Enter the initial state at ``t0`` [s] and compute the initial outputs."""
        self.time = float(t0)
        self._initialize(float(t0))

    def set_inputs(self, values: Mapping[str, Any]) -> None:
        """Set input values, each an array of shape (B,) or a scalar.

        Raises
        ------
        KeyError
            If a name is not a declared input.
        """
        for name, value in values.items():
            if name not in self.inputs:
                raise KeyError(f"{self.name}.{name}: not an input")
            self.inputs[name] = np.broadcast_to(np.asarray(value), (self.batch,))

    def step(self, t: float, dt: float) -> None:
        """Advance from ``t`` to ``t + dt`` [s] (one communication step, doStep)."""
        self._step(float(t), float(dt))
        self.time = float(t) + float(dt)

    def _initialize(self, t0: float) -> None:
        raise NotImplementedError

    def _step(self, t: float, dt: float) -> None:
        raise NotImplementedError
