"""The model program: a component's per-step math as casadi functions.

The program of a component (what the generated C runs, in this order):

* ``prepare(p) -> d``: quantities derived once from the parameters (e.g. a
  padded, interpolation-ready table), at the end of initialization;
* ``init(p, d, w, t0) -> x``: the state at the start time ``t0`` [s];
* every communication step ``doStep(t, h)``:

  1. ``step(x, u, p, d, w, t, h) -> x`` once (if the program has one);
  2. each :class:`Event` in order (those whose choice parameter, if they name
     one, holds their choice): while ``guard(x, u, p, d, t, h)`` is
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

:class:`ProgramBuilder` builds a :class:`Program` from Python functions of
named blocks (:class:`Blocks`).

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import casadi as ca

from sblsim.models.interrupts import check


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


#: The share of its states above which an event's handler computes the whole state (written in sequence, then
#: swapped in) rather than the states it changes (each then copied into place by the runtime, about the cost of
#: computing one more state: the channel's slot, 130 of its 268 states, costs less whole).
WHOLE_STATE = 0.45


@dataclass(frozen=True)
class Event:
    """A handler run while its guard holds, after the step function of a ``doStep``.

    Attributes
    ----------
    name : str
    guard : casadi.Function
        ``(x, u, p, d, t, h) -> g``; the handler runs while ``g > 0.5``.
    handler : casadi.Function
        ``(x, u, p, d, w, t, h) -> x_written``: the new values of the states in :attr:`writes`, in that order.
    writes : tuple of int or None
        The indices in ``x`` of the states the handler computes (the states it changes, when they are at most
        :data:`WHOLE_STATE` of them; every other state keeps its value: the runtime writes these alone, so that an
        event that changes a few states costs no copy of the others); None: the handler computes every state
        (``x_written`` is the whole ``x``), which costs less when it changes most of them.
    streams : tuple of Stream
        Random numbers of the handler.
    when : tuple of (str, tuple of str)
        ``(choice parameter, choices)`` pairs: the event exists only in a run where every one of these
        parameters holds one of its choices; in any other neither its guard nor its handler runs, so a run
        computes only what its configuration uses (e.g. the channel's slot of one-way ranging along the
        straight line, ``(("ranging", ("owtt",)), ("propagation", ("straight",)))``). Empty: every run. A
        choice parameter is fixed for a run.
    """

    name: str
    guard: ca.Function
    handler: ca.Function
    writes: tuple[int, ...] | None
    streams: tuple[Stream, ...] = ()
    when: tuple[tuple[str, tuple[str, ...]], ...] = ()


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
        check()  # each view begins a piece of the symbolic build: a stop whose exception casadi lost ends it here
        p = self.p if p is None else p
        # one split into the elements, not an indexing a parameter (a component's tables hold thousands)
        elements = ca.vertsplit(p) if isinstance(p, ca.SX) else [p[k] for k in range(len(self.param_vars))]
        out = dict(zip((v.name for v in self.param_vars), elements, strict=True))
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

    def event(self, name: str, guard, handler, streams: Sequence[Stream] = (),
              when: Mapping[str, Sequence[str]] | None = None) -> Event:
        """An :class:`Event` from ``guard(x, u, p, d, t, h) -> bool expression`` and
        ``handler(x, u, p, d, w, t, h) -> {changed block: value}``, for the runs ``when`` selects: a mapping
        of choice parameters to the choices the event runs with (see :class:`Event`; None: every run).

        Raises
        ------
        ValueError
            If ``when`` names no choice parameter of the component, a choice it does not have, or none.
        """
        pairs = []
        for parameter, options in (when or {}).items():
            choice = next((v for v in self.param_vars if v.name == parameter and v.choices is not None), None)
            if choice is None or isinstance(options, str) or not options or not set(options) <= set(choice.choices):
                raise ValueError(f"event {name}: {parameter!r} is not a choice parameter with the choices {options!r}")
            pairs.append((str(parameter), tuple(str(c) for c in options)))
        x = self.X.unpack(self.x)
        u, p, d = self.inputs(), self.params(), self.D.unpack(self.d)
        g = ca.Function(f"{self.prefix}_{name}_guard", [self.x, self.u, self.p, self.d, self.t, self.h],
                        [ca.densify(ca.SX(guard(x, u, p, d, self.t, self.h)))], ["x", "u", "p", "d", "t", "h"], ["g"])
        w, ws = self._streams(streams)
        values = handler(x, u, p, d, ws, self.t, self.h)
        x_next = self.X.pack(values, x)
        # the states the handler changes: an element that is not the state's own symbol
        writes = tuple(k for k, (new, own) in enumerate(zip(ca.vertsplit(x_next), ca.vertsplit(self.x), strict=True))
                       if not ca.is_equal(new, own))
        if len(writes) > WHOLE_STATE * x_next.numel():
            writes, x_next = None, ca.densify(x_next)  # most of them: the whole state, written in sequence
        else:
            x_next = ca.densify(x_next[list(writes)])
        f = ca.Function(f"{self.prefix}_{name}", [self.x, self.u, self.p, self.d, w, self.t, self.h],
                        [x_next], ["x", "u", "p", "d", "w", "t", "h"], ["x_written"])
        return Event(name, g, f, writes, tuple(streams), tuple(pairs))

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


__all__ = ["Blocks", "Event", "Program", "ProgramBuilder", "Stream", "WHOLE_STATE"]
