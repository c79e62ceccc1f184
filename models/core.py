"""Shared machinery of the component models: declarations, the model program, random streams.

Every component declares its interface once, as a tuple of :class:`Variable`,
and its per-step math once, as casadi functions gathered in a
:class:`Program`. From these two come the FMU model description, the
configuration checks, the connection checks, the C code of the native FMUs
and of the batched local engine, and the docs' variable tables.

The program of a component (what the generated C runs, in this order):

* ``prepare(p) -> d``: quantities derived once from the parameters (e.g. a
  padded, interpolation-ready table), at the end of initialization;
* ``init(p, d, w, t0) -> x``: the state at the start time ``t0`` [s];
* every communication step ``doStep(t, h)``:

  1. ``step(x, u, p, d, w, t, h) -> x`` once (if the program has one);
  2. each :class:`Event` in order: while ``guard(x, u, p, d, t, h)`` is
     true, ``handler(x, u, p, d, w, t, h) -> x`` (a sample of a sensor, an
     acoustic slot, a packet, one iteration of a least-squares fix);

* ``output(x, p, d, t) -> y`` after initialization and after every step, at
  the end time ``t`` of the step (outputs never depend on inputs directly).

``p`` holds the FMU parameters in declaration order (Real, Integer, Boolean,
the index of a String choice, the entries of table columns), ``u`` the
inputs and ``y`` the outputs in declaration order, ``w`` the random numbers
the function declares (:class:`Stream`). Integer and Boolean values travel
as doubles. The FMUs have no String variables, so that every SSP host can set
every parameter.

Randomness (docs/model.md, "Time and randomness"). Draw ``n`` of purpose ``s`` of
component ``c`` in run ``(seed, scenario_key, cell, replicate)`` takes its
uniforms from the Philox-4×64-10 counter-based generator (Salmon et al.,
"Parallel random numbers: as easy as 1, 2, 3", SC'11; ``numpy.random.Philox``)
with key ``(seed, scenario_key·2³² + c·2¹⁶ + s)`` and counters
``(j, n, cell, replicate)``, j = 0, 1, ... the block of four 64-bit words
within the draw. A uniform is ``(word >> 11)·2⁻⁵³`` as numpy makes it; a
standard normal takes two consecutive uniforms ``(u₁, u₂)`` by one
Box-Muller branch, ``sqrt(−2 ln(1 − u₁)) cos(2π u₂)``. The C runtime
(``fmus/c``) implements the same; :func:`uniforms` and :func:`normals` are
the reference the tests pin it against. A run's numbers therefore do not
depend on batch size, engine, host step or execution order.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, ClassVar, Mapping, Sequence

import casadi as ca
import numpy as np

CAUSALITIES = ("parameter", "input", "output")
TYPES = ("Real", "Integer", "Boolean", "String")
SCOPES = ("both", "fmu", "config")


class ModelError(ValueError):
    """A parameter or input of a component is invalid.

    The message is one line and names the offending field and its allowed
    range, so the command line can show it as it is.
    """


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
}


def _format_bound(value: float) -> str:
    if float(value).is_integer() and abs(value) < 1e15 and abs(value) >= 1e6:
        return str(int(value))  # e.g. 2147483647, not 2.14748e+09
    return f"{value:g}"


def shown(value: Any) -> str:
    """A value for a message: its repr, shortened when it is very long (a 400-digit number)."""
    text = repr(value)
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
    ``;`` and values by blanks or commas (:func:`parse_table`).

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
        :data:`models.core.UNITS`; empty for non-Real variables.
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

    def __post_init__(self) -> None:
        if self.causality not in CAUSALITIES:
            raise ValueError(f"{self.name}: causality {self.causality!r} not in {CAUSALITIES}")
        if self.type not in TYPES:
            raise ValueError(f"{self.name}: type {self.type!r} not in {TYPES}")
        if self.type == "Real" and self.unit not in UNITS:
            raise ValueError(f"{self.name}: unit {self.unit!r} is not declared in models.core.UNITS")
        if self.type != "Real" and self.unit:
            raise ValueError(f"{self.name}: an FMI {self.type} has no unit")
        if self.scope not in SCOPES:
            raise ValueError(f"{self.name}: scope {self.scope!r} not in {SCOPES}")
        if self.type == "String" and self.in_fmu and self.choices is None:
            raise ValueError(f"{self.name}: a free-text String can only be a configuration key (scope='config')")
        if self.table is not None and self.type != "Integer":
            raise ValueError(f"{self.name}: the row count of a table is an Integer")

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


_ROW_SPLIT = re.compile(r"[\s,]+")


def parse_table(text: str, table: Table, where: str) -> np.ndarray:
    """Parse a table given as text ``"a b; a b; ..."`` and check it.

    Returns
    -------
    ndarray, shape (rows, len(table.columns))
        The values; 0 rows for a blank text.

    Raises
    ------
    ModelError
        On a non-numeric or non-finite value (naming the row and column), a
        wrong number of values in a row, more rows than the table holds, a
        value outside its column's range, or a first column that is not
        strictly increasing when it must be.
    """
    ncol = len(table.columns)
    rows = [r.strip() for r in text.split(";")]
    if rows and not rows[-1]:
        rows = rows[:-1]  # a trailing ';'
    if not any(rows):
        return np.zeros((0, ncol))
    if len(rows) > table.max_rows:
        raise ModelError(f"{where}: {len(rows)} rows; at most {table.max_rows}")
    values = np.empty((len(rows), ncol))
    for i, row in enumerate(rows, start=1):
        items = [s for s in _ROW_SPLIT.split(row) if s]
        if len(items) != ncol:
            raise ModelError(f"{where}: row {i} has {len(items)} values, expected {ncol} "
                             f"({' '.join(c.name for c in table.columns)})")
        for j, (item, col) in enumerate(zip(items, table.columns)):
            try:
                number = float(item)
            except ValueError:
                raise ModelError(f"{where}: row {i}, column {col.name}: {item!r} is not a number") from None
            check_entry(number, col, f"{where}: row {i}, column {col.name}")
            values[i - 1, j] = number
    check_increasing(values, table, where)
    return values


def check_entry(number: float, col: Column, label: str) -> None:
    """Check one table value against its column (finite, in range).

    Raises
    ------
    ModelError
        Naming ``label`` and the column's allowed range.
    """
    if not math.isfinite(number):
        raise ModelError(f"{label}: {number!r} is not finite; allowed {col.allowed()}")
    if (col.min is not None and number < col.min) or (col.max is not None and number > col.max):
        raise ModelError(f"{label}: {number:g} is outside the allowed range {col.allowed()}")


def check_increasing(values: np.ndarray, table: Table, where: str, lines: Sequence[int] | None = None,
                     unit: str = "row") -> None:
    """Check that the first column is strictly increasing where the table asks for it.

    Parameters
    ----------
    lines : sequence of int, optional
        The file line (or row) number of each row, for the message (default 1, 2, ...).
    unit : str
        What the numbers are called in the message (``row`` or ``line``).

    Raises
    ------
    ModelError
        Naming the first row that is not greater than the row before.
    """
    if table.increasing and values.shape[0] > 1 and np.any(np.diff(values[:, 0]) <= 0.0):
        k = int(np.flatnonzero(np.diff(values[:, 0]) <= 0.0)[0]) + 1
        number = lines[k] if lines is not None else k + 1
        raise ModelError(f"{where}: {unit} {number}, column {table.columns[0].name}: must be greater than the "
                         f"{unit} before")


def format_table(values: np.ndarray) -> str:
    """A table as text, every value with 17 significant digits (read back exactly)."""
    return "; ".join(" ".join(repr(float(v)) for v in row) for row in np.asarray(values, float))


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


# --------------------------------------------------------------------------------------------
# The model program


@dataclass(frozen=True)
class Stream:
    """Random numbers a program function takes in its ``w`` input, one draw per call.

    Attributes
    ----------
    purpose : int
        Stream index inside the component (0 … 65535); its draws are counted
        across every function that uses it.
    kind : {'uniform', 'normal'}
        Uniform on [0, 1) or standard normal.
    width : int
        Numbers per draw.
    when : (str, str), optional
        ``(choice parameter, choice)``: draw only when the parameter holds that
        choice (e.g. ``("trajectory", "random-walk")``); otherwise the numbers
        are zeros and the stream's draw counter stays, so a run draws what it
        uses and nothing else.
    """

    purpose: int
    kind: str
    width: int
    when: tuple[str, str] | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("uniform", "normal"):
            raise ValueError(f"stream {self.purpose}: kind {self.kind!r} is not 'uniform' or 'normal'")


@dataclass(frozen=True)
class Event:
    """A handler run while its guard holds, after the step function of a ``doStep``.

    Attributes
    ----------
    name : str
    guard : casadi.Function
        ``(x, u, p, d, t, h) -> g``; the handler runs while ``g > 0.5``.
    handler : casadi.Function
        ``(x, u, p, d, w, t, h) -> x``.
    streams : tuple of Stream
        Random numbers of the handler.
    """

    name: str
    guard: ca.Function
    handler: ca.Function
    streams: tuple[Stream, ...] = ()


@dataclass(frozen=True)
class Program:
    """A component's per-step math as casadi functions (see the module docstring).

    Attributes
    ----------
    states : tuple of (str, int)
        Named blocks of the state vector ``x`` and their sizes.
    prepare, init, output : casadi.Function
    step : casadi.Function or None
        None: nothing happens every step but the events.
    init_streams, step_streams : tuple of Stream
    events : tuple of Event
    """

    states: tuple[tuple[str, int], ...]
    prepare: ca.Function
    init: ca.Function
    step: ca.Function | None
    output: ca.Function
    init_streams: tuple[Stream, ...] = ()
    step_streams: tuple[Stream, ...] = ()
    events: tuple[Event, ...] = ()

    @property
    def state_size(self) -> int:
        return sum(n for _, n in self.states)

    @property
    def derived_size(self) -> int:
        return int(self.prepare.numel_out(0))

    def state_slices(self) -> dict[str, slice]:
        """Where each named state block lies in ``x``."""
        out, k = {}, 0
        for name, n in self.states:
            out[name] = slice(k, k + n)
            k += n
        return out

    def functions(self) -> list[ca.Function]:
        """Every casadi function of the program (for code generation)."""
        funcs = [self.prepare, self.init, self.output] + ([self.step] if self.step is not None else [])
        for ev in self.events:
            funcs += [ev.guard, ev.handler]
        return funcs

    def check_dense(self) -> None:
        """Every function's inputs and outputs are dense vectors (what the C runtime reads and writes).

        Raises
        ------
        ValueError
            Naming a function with a sparse input or output.
        """
        for f in self.functions():
            for k in range(f.n_out()):
                if not f.sparsity_out(k).is_dense():
                    raise ValueError(f"{f.name()}: output {k} is sparse; the runtime writes dense vectors")
            for k in range(f.n_in()):
                if not f.sparsity_in(k).is_dense():
                    raise ValueError(f"{f.name()}: input {k} is sparse; the runtime reads dense vectors")

    def purposes(self) -> list[int]:
        """The stream purposes the program draws from, sorted."""
        streams = list(self.init_streams) + list(self.step_streams) + [s for e in self.events for s in e.streams]
        return sorted({s.purpose for s in streams})


class Blocks:
    """Named blocks of a casadi vector: ``Blocks([('x', 6), ('P', 36)])``.

    ``unpack(v)`` gives a dict of sub-vectors, ``pack(dict)`` concatenates
    them back in declaration order; missing names keep the values of
    ``default`` (a dict from :meth:`unpack`).
    """

    def __init__(self, blocks: Sequence[tuple[str, int]]) -> None:
        self.blocks = tuple((str(n), int(s)) for n, s in blocks)
        self.size = sum(s for _, s in self.blocks)

    def unpack(self, v: ca.SX) -> dict[str, ca.SX]:
        out, k = {}, 0
        for name, n in self.blocks:
            out[name] = v[k:k + n]
            k += n
        return out

    def pack(self, values: Mapping[str, Any], default: Mapping[str, Any] | None = None) -> ca.SX:
        parts = []
        for name, n in self.blocks:
            value = values[name] if name in values else default[name]
            value = ca.SX(value) if not isinstance(value, ca.SX) else value
            if value.numel() != n:
                raise ValueError(f"block {name}: {value.numel()} values, expected {n}")
            parts.append(ca.reshape(value, n, 1))
        return ca.densify(ca.vertcat(*parts))  # the runtime reads and writes dense vectors


class ProgramBuilder:
    """Builds a component's :class:`Program` from Python functions of named blocks.

    The functions receive the parameters, derived quantities, state, inputs
    and random numbers as dictionaries of casadi SX values (by variable,
    block or stream name) and return dictionaries; the builder packs them
    into the vectors of the standard signatures (module docstring).

    Parameters
    ----------
    component : type
        The :class:`Component` subclass.
    n_beacons : int
    states : sequence of (str, int)
        Named blocks of the state ``x``.
    derived : sequence of (str, int)
        Named blocks of ``d`` (what ``prepare`` computes).
    """

    def __init__(self, component: type, n_beacons: int, states: Sequence[tuple[str, int]],
                 derived: Sequence[tuple[str, int]] = ()) -> None:
        self.component, self.n = component, n_beacons
        self.prefix = f"sblsim_{component.name}"
        self.X = Blocks(states)
        self.D = Blocks(derived if derived else [("none", 1)])
        params = component.fmu_parameters_declared(n_beacons)
        self.param_vars = params
        self.input_vars = component.inputs(n_beacons)
        self.output_vars = component.outputs(n_beacons)
        self.x = ca.SX.sym("x", self.X.size)
        self.u = ca.SX.sym("u", len(self.input_vars))
        self.p = ca.SX.sym("p", len(params))
        self.d = ca.SX.sym("d", self.D.size)
        self.t = ca.SX.sym("t")
        self.h = ca.SX.sym("h")

    # named views -------------------------------------------------------------------------
    def params(self, p=None) -> dict[str, Any]:
        """Parameters by name; a table's columns also as vectors under their column names.

        ``p`` is the parameter vector to view (default the SX symbol; ``prepare`` views an MX one).
        """
        p = self.p if p is None else p
        out = {v.name: p[k] for k, v in enumerate(self.param_vars)}
        index = {v.name: k for k, v in enumerate(self.param_vars)}
        for v in self.param_vars:
            if v.table is not None:
                for col in v.table.columns:
                    first = index[f"{col.name}[1]"]
                    out[col.name] = p[first:first + v.table.max_rows]
        return out

    def inputs(self) -> dict[str, ca.SX]:
        return {v.name: self.u[k] for k, v in enumerate(self.input_vars)}

    def _streams(self, streams: Sequence[Stream]) -> tuple[ca.SX, dict[int, ca.SX]]:
        width = sum(s.width for s in streams)
        w = ca.SX.sym("w", width)
        out, k = {}, 0
        for s in streams:
            out[s.purpose] = w[k:k + s.width]
            k += s.width
        return w, out

    # functions ----------------------------------------------------------------------------
    def prepare(self, body) -> ca.Function:
        """``prepare(p) -> d`` from ``body(p) -> {block: value}`` (None: nothing derived).

        Built on MX symbols, so that table work can use casadi's ``mapaccum``
        (compact loops in the generated C) rather than one statement per row.
        """
        p = ca.MX.sym("p", self.p.numel())
        values = body(self.params(p)) if body is not None else {"none": 0}
        parts = [ca.reshape(ca.MX(values[name]), n, 1) for name, n in self.D.blocks]
        return ca.Function(f"{self.prefix}_prepare", [p], [ca.densify(ca.vertcat(*parts))], ["p"], ["d"])

    def init(self, body, streams: Sequence[Stream] = ()) -> tuple[ca.Function, tuple[Stream, ...]]:
        """``init(p, d, w, t0) -> x`` from ``body(p, d, w, t0) -> {block: value}`` (every block)."""
        w, ws = self._streams(streams)
        values = body(self.params(), self.D.unpack(self.d), ws, self.t)
        f = ca.Function(f"{self.prefix}_init", [self.p, self.d, w, self.t], [self.X.pack(values)],
                        ["p", "d", "w", "t"], ["x"])
        return f, tuple(streams)

    def step(self, body, streams: Sequence[Stream] = ()) -> tuple[ca.Function, tuple[Stream, ...]]:
        """``step(x, u, p, d, w, t, h) -> x`` from ``body(x, u, p, d, w, t, h) -> {changed block: value}``."""
        w, ws = self._streams(streams)
        x = self.X.unpack(self.x)
        values = body(x, self.inputs(), self.params(), self.D.unpack(self.d), ws, self.t, self.h)
        f = ca.Function(f"{self.prefix}_step", [self.x, self.u, self.p, self.d, w, self.t, self.h],
                        [self.X.pack(values, x)], ["x", "u", "p", "d", "w", "t", "h"], ["x_next"])
        return f, tuple(streams)

    def event(self, name: str, guard, handler, streams: Sequence[Stream] = ()) -> Event:
        """An :class:`Event` from ``guard(x, u, p, d, t, h) -> bool expression`` and
        ``handler(x, u, p, d, w, t, h) -> {changed block: value}``."""
        x = self.X.unpack(self.x)
        u, p, d = self.inputs(), self.params(), self.D.unpack(self.d)
        g = ca.Function(f"{self.prefix}_{name}_guard", [self.x, self.u, self.p, self.d, self.t, self.h],
                        [ca.densify(ca.SX(guard(x, u, p, d, self.t, self.h)))], ["x", "u", "p", "d", "t", "h"], ["g"])
        w, ws = self._streams(streams)
        values = handler(x, u, p, d, ws, self.t, self.h)
        f = ca.Function(f"{self.prefix}_{name}", [self.x, self.u, self.p, self.d, w, self.t, self.h],
                        [self.X.pack(values, x)], ["x", "u", "p", "d", "w", "t", "h"], ["x_next"])
        return Event(name, g, f, tuple(streams))

    def output(self, body) -> ca.Function:
        """``output(x, p, d, t) -> y`` from ``body(x, p, d, t) -> {output name: value}`` (every output)."""
        values = body(self.X.unpack(self.x), self.params(), self.D.unpack(self.d), self.t)
        missing = [v.name for v in self.output_vars if v.name not in values]
        if missing:
            raise ValueError(f"{self.component.name}: outputs without a value: {', '.join(missing)}")
        y = ca.densify(ca.vertcat(*[ca.SX(values[v.name]) for v in self.output_vars]))
        return ca.Function(f"{self.prefix}_output", [self.x, self.p, self.d, self.t], [y],
                           ["x", "p", "d", "t"], ["y"])

    def program(self, prepare: ca.Function, init, output: ca.Function, step=None,
                events: Sequence[Event] = ()) -> Program:
        init_f, init_streams = init
        step_f, step_streams = step if step is not None else (None, ())
        return Program(self.X.blocks, prepare, init_f, step_f, output, init_streams, step_streams, tuple(events))


class Component:
    """Base of the component models: declarations and the program.

    Subclasses set :attr:`name` and :attr:`component_index` and implement
    :meth:`variables` and :meth:`build`; :meth:`fmu_parameters` turns
    configuration keys into FMU parameters where they differ.
    """

    name: ClassVar[str] = ""
    component_index: ClassVar[int] = 0

    @classmethod
    def variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        """The declarations: FMU variables (tables as their row count) and configuration-only keys."""
        raise NotImplementedError

    @classmethod
    def fmu_variables(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        """The FMU's variables in value-reference order: tables expanded, configuration-only keys left out."""
        return _fmu_variables(cls, int(n_beacons))

    @classmethod
    def config_parameters(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        """The parameters a configuration section may set (those the orchestrator fills left out)."""
        return _config_parameters(cls, int(n_beacons))

    @classmethod
    def fmu_parameters_declared(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        """The FMU parameters, in the order they travel in ``p``."""
        return _by_causality(cls, int(n_beacons), "parameter")

    @classmethod
    def inputs(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        return _by_causality(cls, int(n_beacons), "input")

    @classmethod
    def outputs(cls, n_beacons: int = 4) -> tuple[Variable, ...]:
        return _by_causality(cls, int(n_beacons), "output")

    @classmethod
    def fmu_parameters(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """FMU parameter values from a resolved configuration section (default: the same keys).

        Raises
        ------
        ModelError
            If a configuration key cannot be turned into FMU parameters (e.g. an unreadable file).
        """
        names = {v.name for v in cls.fmu_parameters_declared(n_beacons)}
        return {k: v for k, v in values.items() if k in names}

    @classmethod
    def config_values(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """Configuration keys from FMU parameter values (the inverse of :meth:`fmu_parameters`).

        A choice's index becomes its text; FMU parameters the orchestrator
        fills are left out (subclasses turn their tables back into text).
        """
        out = {}
        for v in cls.config_parameters(n_beacons):
            if v.name in values and v.in_fmu:
                value = values[v.name]
                out[v.name] = v.choices[int(value)] if v.type == "String" and not isinstance(value, str) else value
        return out

    @classmethod
    def program(cls, n_beacons: int = 4) -> Program:
        """The component's program for ``n_beacons`` beacons (built once, then cached)."""
        return _program(cls, int(n_beacons))

    @classmethod
    def build(cls, n_beacons: int) -> Program:
        raise NotImplementedError

    @classmethod
    def parameter_vector(cls, values: Mapping[str, Any], n_beacons: int = 4) -> np.ndarray:
        """The ``p`` vector of FMU parameter values; missing ones take their declared start.

        Raises
        ------
        ModelError
            On an unknown name, or a value outside its allowed range.
        """
        declared = cls.fmu_parameters_declared(n_beacons)
        known = {v.name: v for v in declared}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ModelError(f"{cls.name}.{unknown[0]}: not a parameter of the {cls.name} FMU")
        out = np.empty(len(declared))
        for k, v in enumerate(declared):
            value = values.get(v.name, v.start)
            out[k] = v.code(value if v.in_table else v.coerce(value, f"{cls.name}.{v.name}"))
        return out

    @classmethod
    def parameter_matrix(cls, values: Mapping[str, Any], batch: int, n_beacons: int = 4,
                         out: np.ndarray | None = None) -> np.ndarray:
        """The ``p`` vectors of a batch: one row per replicate.

        Parameters
        ----------
        values : mapping
            FMU parameter values: a scalar for every replicate, or an array
            of shape (B,) with one value per replicate (a batch spanning
            design cells). Missing ones take their declared start.
        batch : int
            B.
        out : ndarray, shape (B, n_p), optional
            Where to write them (e.g. a compiled batch's parameter memory), else a new array.

        Returns
        -------
        ndarray, shape (B, n_p)

        Raises
        ------
        ModelError
            On an unknown name, a value outside its allowed range, or an array of the wrong length.
        """
        arrays = {k: np.asarray(v) for k, v in values.items() if isinstance(v, np.ndarray) and v.ndim > 0}
        first = {k: (v.reshape(-1)[0].item() if k in arrays else v) for k, v in values.items()}
        base = cls.parameter_vector(first, n_beacons)
        if out is None:
            out = np.empty((batch, base.size))
        out[:] = base
        declared = {v.name: (k, v) for k, v in enumerate(cls.fmu_parameters_declared(n_beacons))}
        for name, array in arrays.items():
            k, var = declared[name]
            if array.shape != (batch,):
                raise ModelError(f"{cls.name}.{name}: {array.size} per-replicate values for a batch of {batch}")
            for item in np.unique(array):
                var.coerce(item.item(), f"{cls.name}.{name}")
            out[:, k] = [var.code(x.item()) for x in array] if var.type == "String" else array.astype(float)
        return out

    @classmethod
    def fmi_values(cls, values: Mapping[str, Any], n_beacons: int = 4) -> dict[str, Any]:
        """Parameter values as an FMU takes them: a String choice becomes the index of the choice."""
        declared = {v.name: v for v in cls.fmu_parameters_declared(n_beacons)}
        return {k: (declared[k].choices.index(v) if k in declared and declared[k].type == "String" else v)
                for k, v in values.items()}


@lru_cache(maxsize=None)
def _config_parameters(cls: type, n_beacons: int) -> tuple[Variable, ...]:
    return tuple(v for v in cls.variables(n_beacons) if v.causality == "parameter" and v.scope != "fmu")


@lru_cache(maxsize=None)
def _by_causality(cls: type, n_beacons: int, causality: str) -> tuple[Variable, ...]:
    return tuple(v for v in _fmu_variables(cls, n_beacons) if v.causality == causality)


@lru_cache(maxsize=None)
def _fmu_variables(cls: type, n_beacons: int) -> tuple[Variable, ...]:
    out: list[Variable] = []
    for v in cls.variables(n_beacons):
        if not v.in_fmu:
            continue
        out.append(v)
        if v.table is not None:
            out.extend(v.table.array_variables())
    return tuple(out)


@lru_cache(maxsize=None)
def _program(cls: type, n_beacons: int) -> Program:
    program = cls.build(n_beacons)
    program.check_dense()
    return program


# --------------------------------------------------------------------------------------------
# casadi helpers shared by the models


def sample_due(index, start, period, t, h):
    """Guard of a periodic sample: the next sample ``start + (index + 1)·period`` has been reached by
    the end ``t + h`` of the step (to within 1e-6 periods, so that a host's rounded communication
    points neither miss nor add a sample) [s]."""
    return start + (index + 1.0) * period <= t + h + 1e-6 * period


def padded_rows(count, columns: Sequence[Any], gap: float) -> tuple[list[Any], list[Any]]:
    """A table's rows padded for interpolation: the used rows, then rows that keep the grid increasing.

    Rows ``k < count`` are kept; a row ``k ≥ count`` repeats the last used row,
    its first column continuing ``last + gap + (k − count)``. Built with
    casadi's ``mapaccum`` (one loop in the generated C).

    Parameters
    ----------
    count : casadi.MX
        Rows in use.
    columns : sequence of casadi.MX, each (N, 1)
        The columns.
    gap : float
        Step from the last used value of the first column to the first padding row.

    Returns
    -------
    padded : list of casadi.MX, each (N, 1)
    last : list of casadi.MX
        The last used row (zeros if ``count`` is 0).
    """
    m, N = len(columns), int(columns[0].numel())
    acc = ca.SX.sym("acc", 2 + m)
    row = [ca.SX.sym(f"c{j}") for j in range(m)]
    k, n, last = acc[0], acc[1], acc[2:]
    used = k < n
    first = ca.if_else(used, row[0], last[0] + gap + (k - n))
    out = [first] + [ca.if_else(used, row[j], last[j]) for j in range(1, m)]
    kept = ca.vertcat(*[ca.if_else(used, row[j], last[j]) for j in range(m)])
    pad = ca.Function("sblsim_pad_row", [acc] + row, [ca.vertcat(k + 1, n, kept)] + out).mapaccum("sblsim_pad", N)
    result = pad(ca.vertcat(0, count, ca.MX.zeros(m)), *[ca.reshape(c, 1, N) for c in columns])
    final = result[0][:, N - 1]
    return [ca.reshape(r, N, 1) for r in result[1:]], [final[2 + j] for j in range(m)]


def cumulative_sum(values: Any) -> Any:
    """Running sum of an (N, 1) casadi.MX vector (``mapaccum``), starting with the first value."""
    N = int(values.numel())
    acc, v = ca.SX.sym("acc"), ca.SX.sym("v")
    total = ca.Function("sblsim_add", [acc, v], [acc + v, acc + v]).mapaccum("sblsim_cumsum", N)
    return ca.reshape(total(0, ca.reshape(values, 1, N))[1], N, 1)


def switch(name: str, branches: Sequence[ca.Function]) -> ca.Function:
    """``f(index, *args) = branches[index](*args)``, only that branch evaluated in the generated C.

    A casadi ``Switch`` called through a never-inlined wrapper: an SX
    expression that calls it holds one call, and the C it generates runs the
    selected branch alone (an ``if_else`` of the branches would evaluate them
    all). ``index`` is rounded toward zero; outside ``[0, n)`` it takes the
    last branch. The branches share one signature.
    """
    first = branches[0]
    switch_f = ca.Function.conditional(f"{name}_switch", list(branches[:-1]), branches[-1])
    index = ca.MX.sym("index")
    args = [ca.MX.sym(first.name_in(k), first.sparsity_in(k)) for k in range(first.n_in())]
    return ca.Function(name, [index, *args], switch_f.call([index, *args]), ["index", *first.name_in()],
                       first.name_out(), {"never_inline": True})


def select(index: ca.SX, rows: Sequence[ca.SX]) -> ca.SX:
    """``rows[index]`` for a symbolic integer-valued ``index`` (zero if out of range).

    Sums ``if_else(index == k, rows[k], 0)``: exact, since the other
    terms are exact zeros. Every row is computed; for costly alternatives use
    :func:`switch`.
    """
    total = 0
    for k, row in enumerate(rows):
        total = total + ca.if_else(index == k, row, 0)
    return total


def lookup(index: ca.SX, values: Sequence[float]) -> ca.SX:
    """A constant table indexed by a symbolic integer (zero if out of range)."""
    return select(index, [float(v) for v in values])


# --------------------------------------------------------------------------------------------
# Philox-4x64-10 reference (numpy), the definition the C runtime is tested against

_MASK64 = (1 << 64) - 1


def philox_key(seed: int, scenario_key: int, component: int, purpose: int) -> tuple[int, int]:
    """Philox key of a stream: ``(seed, scenario_key·2³² + component·2¹⁶ + purpose)``."""
    return int(seed) & _MASK64, ((int(scenario_key) << 32) | (int(component) << 16) | int(purpose)) & _MASK64


def philox_words(key: tuple[int, int], counter: Sequence[int]) -> np.ndarray:
    """The four 64-bit words of Philox-4×64-10 at ``counter`` (numpy's ``Philox`` bit generator).

    numpy advances the counter before it ciphers, so its state is set one
    below ``counter``.
    """
    value = sum((int(c) & _MASK64) << (64 * i) for i, c in enumerate(counter))
    value = (value - 1) % (1 << 256)
    before = np.array([(value >> (64 * i)) & _MASK64 for i in range(4)], dtype=np.uint64)
    gen = np.random.Philox(counter=before, key=np.array(key, dtype=np.uint64))
    return gen.random_raw(4)


def uniforms(seed: int, scenario_key: int, cell: int, replicate: int, component: int, purpose: int,
             draw: int, count: int) -> np.ndarray:
    """The uniforms on [0, 1) of one draw of a stream (module docstring, "Randomness").

    Returns
    -------
    ndarray, shape (count,)
    """
    key = philox_key(seed, scenario_key, component, purpose)
    blocks = [philox_words(key, (j, draw, cell, replicate)) for j in range((count + 3) // 4)]
    words = np.concatenate(blocks)[:count] if blocks else np.zeros(0, dtype=np.uint64)
    return (words >> np.uint64(11)).astype(float) * (1.0 / 9007199254740992.0)


def normals(seed: int, scenario_key: int, cell: int, replicate: int, component: int, purpose: int,
            draw: int, count: int) -> np.ndarray:
    """The standard normals of one draw: Box-Muller on consecutive uniform pairs.

    Uses :mod:`math` (the C library's ``log``, ``sqrt`` and ``cos``), as the C runtime does.
    """
    u = uniforms(seed, scenario_key, cell, replicate, component, purpose, draw, 2 * count)
    return np.array([math.sqrt(-2.0 * math.log(1.0 - u[2 * i])) * math.cos(2.0 * math.pi * u[2 * i + 1])
                     for i in range(count)])


__all__ = ["Blocks", "Column", "Component", "Event", "ModelError", "Program", "SEED_NAMES", "SEED_PARAMETERS",
           "Stream", "Table", "UNITS", "Variable", "check_entry", "check_increasing", "format_table",
           "lookup", "normals", "ProgramBuilder", "parameters", "parse_table", "philox_key", "philox_words",
           "cumulative_sum", "padded_rows", "resolve_parameters", "sample_due", "select", "uniforms"]
