"""Declarations of the component models: every variable declared once.

A component declares its interface as a tuple of :class:`Variable` (name,
causality, variability, type, unit, start, description, allowed range, and
for a parameter its :class:`Table` or choices). From these come the FMU model
description, the configuration checks and their one-line messages
(:class:`~sblsim.models.errors.ModelError`), the connection checks, the C variable tables of the
native FMUs, the SSP export and the docs' variable tables.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from sblsim.models.errors import ModelError

CAUSALITIES = ("parameter", "input", "output")
TYPES = ("Real", "Integer", "Boolean", "String")
SCOPES = ("both", "fmu", "config")


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
    "m2": ({"m": 2}, 1.0),
    "m2/s": ({"m": 2, "s": -1}, 1.0),
    "degC": ({"K": 1}, 1.0),
    "g/kg": ({}, 1e-3),
    "s/m": ({"m": -1, "s": 1}, 1.0),
    "Hz": ({"s": -1}, 1.0),
    # logarithmic levels: dimensionless to FMI (a level is not converted to another unit)
    "dB": ({}, 1.0),
    "dB/m": ({"m": -1}, 1.0),
}


def _format_bound(value: float) -> str:
    if float(value).is_integer() and abs(value) < 1e15 and abs(value) >= 1e6:
        return str(int(value))  # e.g. 2147483647, not 2.14748e+09
    return f"{value:g}"


def shown(value: Any) -> str:
    """A value for a message, in one line: its repr, shortened when it is very long (a 400-digit number); an
    array by its shape (``a numpy array of shape (2,)``), a repr of several lines in one."""
    if isinstance(value, np.ndarray):
        return f"a numpy array of shape {value.shape}"
    text = repr(value)
    if "\n" in text:
        text = " ".join(text.split())
    return text if len(text) <= 24 else f"{text[:12]}... ({len(text)} characters)"


@dataclass(frozen=True)
class Column:
    """One column of a table parameter: the name of its FMU array, unit and allowed closed range."""

    name: str
    unit: str = ""
    description: str = ""
    min: float | None = None
    max: float | None = None

    def allowed(self) -> str:
        lo = "-inf" if self.min is None else _format_bound(self.min)
        hi = "inf" if self.max is None else _format_bound(self.max)
        unit = f" {self.unit}" if self.unit and self.unit != "1" else ""
        return f"[{lo}, {hi}]{unit}"

    @property
    def start(self) -> float:
        """Start value of the unused entries: 0, or the nearest allowed value."""
        lo = -math.inf if self.min is None else self.min
        hi = math.inf if self.max is None else self.max
        return float(min(max(0.0, lo), hi))


@dataclass(frozen=True)
class Table:
    """A numeric table carried by FMU parameters: a row count and one Real array per column.

    The Integer parameter that declares the table holds the number of rows
    in use; column ``c`` is the Real parameters ``c.name[1]`` …
    ``c.name[max_rows]`` (FMI 2.0 names; the rows beyond the count are
    ignored). In a configuration the same table is text, rows separated by
    ``;`` and values by blanks or commas (:func:`~sblsim.models.table_text.parse_table`).

    Attributes
    ----------
    columns : tuple of Column
    max_rows : int
        Largest number of rows.
    increasing : bool
        The first column must be strictly increasing.
    min_rows : int
        Rows needed when the String choice ``when = (name, choice)`` holds (always, if None).
    when : tuple of (str, str), optional
    """

    columns: tuple[Column, ...]
    max_rows: int
    increasing: bool = False
    min_rows: int = 0
    when: tuple[str, str] | None = None

    def array_variables(self) -> tuple["Variable", ...]:
        """The Real parameters of the columns, column by column."""
        return tuple(
            Variable(f"{col.name}[{k}]", "parameter", "Real", col.start, col.unit, f"{col.description}, row {k}",
                     min=col.min, max=col.max, in_table=True)
            for col in self.columns for k in range(1, self.max_rows + 1))

    def values(self, rows: np.ndarray, name: str) -> dict[str, Any]:
        """FMU parameter values of a parsed table: the row count ``name`` and the used array entries."""
        out: dict[str, Any] = {name: int(rows.shape[0])}
        for j, col in enumerate(self.columns):
            out.update({f"{col.name}[{k + 1}]": float(rows[k, j]) for k in range(rows.shape[0])})
        return out

    def rows(self, values: Mapping[str, Any], name: str) -> np.ndarray:
        """The table held by FMU parameter values (the inverse of :meth:`values`)."""
        n = int(values.get(name, 0))
        return np.array([[float(values.get(f"{col.name}[{k}]", 0.0)) for col in self.columns]
                         for k in range(1, n + 1)]).reshape(n, len(self.columns))


@dataclass(frozen=True)
class FileKey:
    """How a free-text configuration key names a file: the one declaration every rule for files reads.

    A value names a file unless it is one of ``names`` or starts with one of ``name_prefixes`` (a built-in source
    such as ``ctd:NAME``); it then names the path after the first of ``prefixes`` it starts with (``""``: the
    whole value is the path). Every key whose value may be a path is declared with one (:attr:`Variable.file`):
    the configuration makes its relative paths absolute from the folder of the file that gives it, a design's
    overrides, a log's configuration and an SSP package's parameters may not name one.

    Parameters
    ----------
    prefixes : tuple of str
        What comes before the path (``model:``, ``fmu:``); ``""`` for a bare path.
    names : tuple of str
        Values that name no file.
    name_prefixes : tuple of str
        Starts of values that name no file.
    """

    prefixes: tuple[str, ...] = ("",)
    names: tuple[str, ...] = ("",)
    name_prefixes: tuple[str, ...] = ()

    def path(self, value: Any) -> str:
        """The path a value names; empty when it names no file (not text, a name, or a prefix alone)."""
        if not isinstance(value, str) or value in self.names or value.startswith(self.name_prefixes):
            return ""
        for prefix in sorted(self.prefixes, key=len, reverse=True):
            if value.startswith(prefix):
                return value[len(prefix):]
        return ""

    def with_path(self, value: str, path: str) -> str:
        """``value`` with the path it names replaced by ``path`` (its prefix kept)."""
        return value[:len(value) - len(self.path(value))] + path


@dataclass(frozen=True)
class Variable:
    """One declared variable of a component (an FMI 2.0 ScalarVariable), or a configuration key.

    Parameters
    ----------
    name : str
        Variable name, unique in its component.
    causality : {'parameter', 'input', 'output'}
        FMI causality.
    type : {'Real', 'Integer', 'Boolean', 'String'}
        Base type in the configuration. A String with ``choices`` is an
        Integer in the FMU: the index of the choice (:attr:`fmi_type`).
    start : Any
        Start value (default of a parameter, initial value of an input).
    unit : str
        Unit of a Real variable, in the FMI unit names of
        :data:`sblsim.models.declarations.UNITS`; empty for non-Real variables.
    description : str
        One-line description.
    min, max : float, optional
        Allowed closed range of a numeric variable.
    min_exclusive : bool
        The lower bound itself is not allowed (e.g. a zero baseline).
    choices : tuple of str, optional
        Allowed values of a String variable (None: free text such as a path).
    discrete : bool
        A Real input or output that changes only at communication points (a
        sampled signal: a packet, a sensor reading, an estimate): FMI
        variability ``discrete``, so hosts hold it instead of interpolating.
    scope : {'both', 'fmu', 'config'}
        ``both``: an FMU variable and, for a parameter, a configuration key;
        ``fmu``: an FMU parameter the orchestrator fills from other keys
        (e.g. a sound-speed table from a CTD cast); ``config``: a
        configuration key only (e.g. a file path), turned into FMU parameters.
    table : Table, optional
        This Integer parameter is the row count of a table whose columns are
        FMU arrays (:meth:`Table.array_variables`).
    in_table : bool
        An entry of a table column (checked only in the rows in use).
    file : FileKey, optional
        This free-text configuration key may name a file, and how (every key that does is declared so).
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
    discrete: bool = False
    scope: str = "both"
    table: Table | None = None
    in_table: bool = False
    file: FileKey | None = None

    def __post_init__(self) -> None:
        if self.causality not in CAUSALITIES:
            raise ValueError(f"{self.name}: causality {self.causality!r} not in {CAUSALITIES}")
        if self.type not in TYPES:
            raise ValueError(f"{self.name}: type {self.type!r} not in {TYPES}")
        if self.type == "Real" and self.unit not in UNITS:
            raise ValueError(f"{self.name}: unit {self.unit!r} is not declared in sblsim.models.declarations.UNITS")
        if self.type != "Real" and self.unit:
            raise ValueError(f"{self.name}: an FMI {self.type} has no unit")
        if self.scope not in SCOPES:
            raise ValueError(f"{self.name}: scope {self.scope!r} not in {SCOPES}")
        if self.type == "String" and self.in_fmu and self.choices is None:
            raise ValueError(f"{self.name}: a free-text String can only be a configuration key (scope='config')")
        if self.table is not None and self.type != "Integer":
            raise ValueError(f"{self.name}: the row count of a table is an Integer")
        if self.file is not None and (self.type != "String" or self.choices is not None or self.in_fmu):
            raise ValueError(f"{self.name}: a file key is a free-text String configuration key (scope='config')")

    @property
    def variability(self) -> str:
        """FMI variability: ``fixed`` for parameters, ``discrete`` for sampled
        signals and non-Real ones, ``continuous`` for the other Real signals."""
        if self.causality == "parameter":
            return "fixed"
        return "discrete" if (self.discrete or self.type != "Real") else "continuous"

    @property
    def in_fmu(self) -> bool:
        """The variable is part of the FMU (not a configuration-only key)."""
        return self.scope != "config"

    @property
    def fmi_type(self) -> str:
        """FMI base type in the FMU: a String choice is the Integer index of the choice."""
        return "Integer" if self.type == "String" else self.type

    @property
    def fmi_start(self) -> Any:
        """Start value in the FMU (a choice's index)."""
        return self.choices.index(self.start) if self.type == "String" else self.start

    def fmi_description(self) -> str:
        """The description, with the codes of a choice (``0: semicircle, 1: spiral, ...``)."""
        if self.type == "String":
            return f"{self.description} ({', '.join(f'{k}: {c}' for k, c in enumerate(self.choices))})"
        return self.description

    def allowed(self) -> str:
        """Human-readable allowed range, e.g. ``(0, inf) m`` or ``one of a, b``."""
        if self.type == "String":
            return "one of " + ", ".join(self.choices) if self.choices else "text"
        if self.type == "Boolean":
            return "true or false"
        lo = "-inf" if self.min is None else _format_bound(self.min)
        hi = "inf" if self.max is None else _format_bound(self.max)
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
                raise ModelError(f"{label}: expected text ({self.allowed()}), got {shown(value)}")
            if self.choices is not None and value not in self.choices:
                raise ModelError(f"{label}: {value!r} is not allowed; {self.allowed()}")
            return value
        if self.type == "Boolean":
            if not isinstance(value, (bool, np.bool_)):
                raise ModelError(f"{label}: expected true or false, got {shown(value)}")
            return bool(value)
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ModelError(f"{label}: expected a number in {self.allowed()}, got {shown(value)}")
        try:
            number = float(value)
        except OverflowError:
            raise ModelError(f"{label}: {shown(value)} is outside the allowed range {self.allowed()}") from None
        if not math.isfinite(number):
            raise ModelError(f"{label}: {value!r} is not finite; allowed {self.allowed()}")
        if self.type == "Integer":
            if not isinstance(value, (int, np.integer)) and not number.is_integer():
                raise ModelError(f"{label}: expected a whole number in {self.allowed()}, got {value!r}")
            value = int(value)
        else:
            value = number
        below = self.min is not None and (value < self.min or (self.min_exclusive and value == self.min))
        above = self.max is not None and value > self.max
        if below or above:
            raise ModelError(f"{label}: {shown(value)} is outside the allowed range {self.allowed()}")
        return value

    def code(self, value: Any) -> float:
        """The value as it travels in ``p``: the number, 0/1, or the index of a String choice."""
        if self.type == "String":
            return float(self.choices.index(value))
        return float(value)


#: Allowed closed ranges of the signals that travel between components, by kind: the declared ranges of
#: the FMU inputs (an FMU refuses a value outside them with fmi2Error and a log line). Wide enough for every
#: real deployment, narrow enough that every output stays finite (squares and sums of these values are far
#: from overflow):
#:
#: * ``position`` [m]: ±1e7 m, more than an Earth radius from the local origin of the NED frame;
#: * ``velocity`` [m/s]: ±1e4 m/s, well above the speed of sound (a diver swims at a few m/s);
#: * ``range`` [m]: ±1e7 m, like a position; a short measured range can be negative (range noise);
#: * ``time`` [s]: ±1e9 s (about 31 years) around the host's clock origin, which may lie before the start;
#: * ``depth`` [m]: [-1e4, 2e4] m, the deepest ocean (11 km) plus nine standard deviations of the
#:   noisiest depth sensor the target allows (1 km), and as far above the surface;
#: * ``counter``: a slot counter or a beacon id, [0, 2^31 - 1] (the range of an FMI Integer).
SIGNAL_RANGES: dict[str, tuple[float, float]] = {
    "position": (-1e7, 1e7),
    "velocity": (-1e4, 1e4),
    "range": (-1e7, 1e7),
    "time": (-1e9, 1e9),
    "depth": (-1e4, 2e4),
    "counter": (0, 2**31 - 1),
}


def signal_range(kind: str) -> dict[str, float]:
    """The ``min`` and ``max`` of a :class:`Variable` for a kind of :data:`SIGNAL_RANGES`, e.g.
    ``Variable("depth", "input", "Real", **signal_range("depth"))``."""
    lo, hi = SIGNAL_RANGES[kind]
    return {"min": lo, "max": hi}


#: Integer parameters that every stochastic component takes to seed its
#: random streams (module docstring, "Randomness").
SEED_PARAMETERS: tuple[Variable, ...] = (
    Variable("seed", "parameter", "Integer", 0, description="Campaign seed", min=0, max=2**31 - 1),
    Variable("scenario_key", "parameter", "Integer", 0, description="Scenario index in the seed tree",
             min=0, max=2**31 - 1),
    Variable("cell", "parameter", "Integer", 0, description="Design-cell index in the seed tree",
             min=0, max=2**31 - 1),
    Variable("replicate", "parameter", "Integer", 0, description="Replicate index in the seed tree",
             min=0, max=2**31 - 1),
)
SEED_NAMES = tuple(v.name for v in SEED_PARAMETERS)


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


__all__ = ["CAUSALITIES", "Column", "FileKey", "ModelError", "SCOPES", "SEED_NAMES", "SEED_PARAMETERS", "TYPES",
           "Table", "UNITS", "SIGNAL_RANGES", "Variable", "parameters", "resolve_parameters", "shown", "signal_range"]
