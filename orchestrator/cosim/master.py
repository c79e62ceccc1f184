"""The master algorithm: fixed-step, multi-rate co-simulation, Gauss-Seidel or Jacobi, or event-driven.

Every macro step of length T each component with rate ratio r takes r
communication steps (doStep) of T / r with its inputs held (zero-order hold).
The two algorithms differ in where an input's value comes from:

* **Gauss-Seidel** steps the components in the order of the connection graph
  (platform and target, then the channel, then the receiver); before a
  component steps, each input takes the output it is connected to as it is
  now, so the channel already sees the platform and target at the end of the
  macro step.
* **Jacobi** sets every input from the outputs at the start of the macro step
  (the initial outputs at the first one), then steps all components; no
  component sees another's output of the same macro step. This is what FMI
  hosts such as libcosim's fixed-step algorithm and fmpy's SSP simulator do.
* **Event** (FMI 3.0 FMUs instantiated with early return allowed: ``--engine fmu --fmi-version 3``) is
  Gauss-Seidel, except that the channel's steps end at the acoustic arrivals: what feeds the channel (platform,
  target) takes the macro step, the channel is stepped from arrival to arrival (it returns early at each, with
  the packet in its outputs), and what it feeds (the receiver) is stepped to each arrival (at its rate's
  communication points on the way), so the receiver has each packet at its arrival. At sblsim's own macro step
  (the slot) the numbers are Gauss-Seidel's up to rounding; a host that steps at a long interval keeps every
  packet (docs/interop.md, FMI 3.0).

After each macro step every output of every component is recorded.

References
----------
Gomes, Thule, Broman, Larsen, Vangheluwe, "Co-simulation: a survey",
ACM Computing Surveys 51(3), 2018, Section 3 (Gauss-Seidel and Jacobi master
algorithms, multi-rate stepping).
"""

from __future__ import annotations

import time
from typing import Callable, Mapping, Sequence

import numpy as np

from sblsim.orchestrator.cosim.connections import Connection, execution_order
from sblsim.orchestrator.cosim.handles import ComponentHandle
from sblsim.orchestrator.cosim.local_engine import native_system

#: Master algorithms of :func:`simulate`.
ALGORITHMS = ("gauss-seidel", "jacobi", "event")


class RecordBuffer:
    """Memory for the compiled master loop's record array, re-used from one simulation to the next.

    Allocating and first touching a large batch's record (150 MB for a campaign chunk) costs time; a
    caller that is done with the previous result's arrays before the next simulation hands the same
    buffer to :func:`simulate` each time (the Python loop does not use it).
    """

    def __init__(self) -> None:
        self._flat: np.ndarray | None = None

    def take(self, size: int) -> np.ndarray:
        """A flat float array of ``size`` elements: a view of the kept one if it is large enough, else a new
        one, kept for the next call. Its previous contents are overwritten by the caller."""
        if self._flat is None or self._flat.size < size:
            self._flat = np.empty(size)
        return self._flat[:size]


def simulate(handles: Mapping[str, ComponentHandle], connections: Sequence[Connection], rates: Mapping[str, int],
             macro_step: float, n_steps: int, t0: float = 0.0,
             progress: Callable[[int], None] | None = None,
             record: Sequence[str] | None = None, algorithm: str = "gauss-seidel",
             timing: dict[str, float] | None = None, buffer: RecordBuffer | None = None) -> dict[str, np.ndarray]:
    """Run the co-simulation and record every output at each communication point.

    A handle (:class:`sblsim.orchestrator.cosim.handles.ComponentHandle`) names its inputs and outputs
    (``input_names``, ``output_names``), takes its inputs as one matrix
    (``set_input_vector``, shape (n_in, B)), gives its outputs as one matrix
    (``output_vector``, shape (n_out, B), numbers as floats) and steps
    (``do_step``). The connections are resolved once into index arrays, so
    a macro step moves whole vectors. When every handle has a compiled batch
    (``native_batch``) of one library, the compiled master loop steps them.

    Parameters
    ----------
    handles : mapping
        Component name -> set-up handle.
    connections : sequence of Connection
        Checked connections.
    rates : mapping
        Component name -> communication steps per macro step (≥ 1).
    macro_step : float
        Macro step T [s].
    n_steps : int
        Number of macro steps.
    t0 : float
        Start time [s].
    progress : callable, optional
        Called with 1 after every macro step.
    record : sequence of str, optional
        The ``"component.variable"`` outputs to record; default all of them.
    algorithm : {'gauss-seidel', 'jacobi', 'event'}
        Where inputs come from and where steps end (see the module); ``event`` needs a handle that can return
        early (:meth:`sblsim.orchestrator.cosim.fmu3_engine.Fmu3Handle.step_until`).
    timing : dict, optional
        Filled with the wall-clock time [s] spent in each component's ``do_step`` calls (added to).
    buffer : RecordBuffer, optional
        Memory for the record, re-used from a previous call (the compiled loop only): the arrays of the
        previous result taken from the same buffer are overwritten. Default: new memory.

    Returns
    -------
    dict
        ``"component.variable"`` -> array of shape (n_steps, B) for each
        recorded output (float; the caller casts Integer and Boolean ones), and
        ``"time"`` -> array of shape (n_steps,) [s] (the end of each macro step).

    Raises
    ------
    ValueError
        If ``algorithm`` is unknown, or ``event`` without a handle that returns early.
    KeyError
        If a recorded name is not an output of the system.
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"simulation.master: {algorithm!r} is not one of {', '.join(ALGORITHMS)}")
    jacobi = algorithm == "jacobi"
    order = execution_order(list(handles), connections)
    known = {f"{c}.{n}" for c in handles for n in handles[c].output_names}
    if record is not None:
        unknown = sorted(set(record) - known)
        if unknown:
            raise KeyError(f"record: {unknown[0]} is not an output of the system")
    # per destination: for each source, (source rows, destination rows)
    plans: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for c in handles:
        inputs = {n: k for k, n in enumerate(handles[c].input_names)}
        by_source: dict[str, tuple[list, list]] = {}
        for conn in connections:
            if conn.destination == c:
                rows = by_source.setdefault(conn.source, ([], []))
                rows[0].append(handles[conn.source].output_names.index(conn.output))
                rows[1].append(inputs[conn.input])
        plans[c] = [(src, np.array(a), np.array(b)) for src, (a, b) in by_source.items()]
    outputs = {c: handles[c].output_vector() for c in handles}
    buffers = {c: np.zeros((len(handles[c].input_names), outputs[c].shape[1])) for c in handles}
    # the output rows recorded of each component (all, or those asked for)
    kept = {c: [k for k, n in enumerate(handles[c].output_names) if record is None or f"{c}.{n}" in record]
            for c in handles}
    rows = {c: (slice(None) if len(kept[c]) == len(handles[c].output_names) else np.array(kept[c], dtype=int))
            for c in handles}
    early = [c for c in order if getattr(handles[c], "early_return", False) and
             getattr(handles[c], "might_return_early", False)]
    if algorithm == "event" and not early:
        raise ValueError("simulation.master: event needs a channel FMU that returns early at an arrival (FMI 3.0: "
                         "--engine fmu --fmi-version 3)")
    system = None if algorithm == "event" else _native_system(handles, order, plans, kept, rates)
    if system is not None:
        return _simulate_native(system, handles, order, kept, macro_step, n_steps, t0, progress, jacobi, timing,
                                buffer)
    history: dict[str, list[np.ndarray]] = {c: [] for c in handles}

    def feed(c: str) -> None:
        """Set a component's inputs from the latest outputs of its sources."""
        if plans[c]:
            u = buffers[c]
            for src, rows, into in plans[c]:
                u[into] = outputs[src][rows]
            handles[c].set_input_vector(u)

    def step(c: str, start: float, end: float) -> None:
        """Step a component from ``start`` to ``end`` through its communication points on the way."""
        ratio = rates.get(c, 1)
        sub = macro_step / ratio
        clock = time.perf_counter()
        points = [t0 + j * sub for j in range(int(np.floor((start - t0) / sub + 1e-9)) + 1,
                                                int(np.ceil((end - t0) / sub - 1e-9)))]
        for a, b in zip([start, *points], [*points, end]):
            handles[c].do_step(a, b - a)
        if timing is not None:
            timing[c] = timing.get(c, 0.0) + time.perf_counter() - clock
        outputs[c] = handles[c].output_vector()

    for k in range(n_steps):
        t = t0 + k * macro_step
        if early:  # event: the channel from arrival to arrival, what it feeds stepped to each
            now, end, channel = t, t + macro_step, early[0]
            before = order[:order.index(channel)]
            for c in before:  # what feeds the channel (platform, target): the whole macro step, as Gauss-Seidel
                feed(c)
                step(c, t, end)
            feed(channel)
            while end - now > 1e-9 * (1.0 + abs(end)):
                clock = time.perf_counter()
                reached = handles[channel].step_until(now, end - now)
                if timing is not None:
                    timing[channel] = timing.get(channel, 0.0) + time.perf_counter() - clock
                outputs[channel] = handles[channel].output_vector()
                for c in order[len(before) + 1:]:  # what it feeds (the receiver): to the arrival
                    feed(c)
                    step(c, now, reached)
                now = reached
            for c in order:
                if kept[c]:
                    history[c].append(outputs[c][rows[c]])
            if progress is not None:
                progress(1)
            continue
        if jacobi:  # every input from the outputs at the start of the macro step
            for c in order:
                feed(c)
        for c in order:
            handle = handles[c]
            if not jacobi:
                feed(c)
            ratio = rates.get(c, 1)
            sub = macro_step / ratio
            start = time.perf_counter()
            for j in range(ratio):
                handle.do_step(t + j * sub, sub)
            if timing is not None:
                timing[c] = timing.get(c, 0.0) + time.perf_counter() - start
            outputs[c] = handle.output_vector()
            if kept[c]:
                history[c].append(outputs[c][rows[c]])
        if progress is not None:
            progress(1)
    result: dict[str, np.ndarray] = {}
    for c in handles:
        if not kept[c]:
            continue
        batch = outputs[c].shape[1]
        stacked = np.stack(history[c]) if history[c] else np.zeros((0, len(kept[c]), batch))  # (n_steps, kept, B)
        for j, k in enumerate(kept[c]):
            result[f"{c}.{handles[c].output_names[k]}"] = stacked[:, j, :]
    result["time"] = t0 + macro_step * np.arange(1, n_steps + 1)
    return result


def _native_system(handles: Mapping[str, ComponentHandle], order: Sequence[str], plans: dict, kept: dict,
                   rates: Mapping[str, int]):
    """The compiled master loop for these handles, when every one is a compiled batch of the same library
    with every input connected (else None: the Python loop above runs)."""
    batches = [_native_batch(handles[c]) for c in order]
    if any(b is None for b in batches):
        return None
    index = {c: k for k, c in enumerate(order)}
    links = []
    for c in order:
        connected = sum(len(into) for _, _, into in plans[c])
        if connected != len(handles[c].input_names):
            return None
        links += [(index[src], int(out), index[c], int(into_k)) for src, rows_, into in plans[c]
                  for out, into_k in zip(rows_, into)]
    record = [(index[c], k) for c in order for k in kept[c]]
    return native_system(batches, [rates.get(c, 1) for c in order], links, record)


def _native_batch(handle: ComponentHandle):
    """A handle's compiled batch, or None.

    Asked of the handle's class: a wrapper that passes other attributes on to a compiled handle
    (``__getattr__``) may change what is exchanged, so it is stepped by the Python loop unless its class
    defines ``native_batch`` itself.
    """
    ask = getattr(type(handle), "native_batch", None)
    return ask(handle) if ask is not None else None


def _simulate_native(system, handles: Mapping[str, ComponentHandle], order: Sequence[str], kept: dict,
                     macro_step: float, n_steps: int, t0: float, progress, jacobi: bool, timing,
                     buffer: RecordBuffer | None) -> dict[str, np.ndarray]:
    """:func:`simulate` by the compiled master loop: the same operations in the same order, in C."""
    shape = (n_steps, system.n_record, system.B)
    size = int(np.prod(shape))
    flat = buffer.take(size) if buffer is not None else np.empty(size)
    record = flat.reshape(shape)
    chunk = max(1, n_steps // 100) if progress is not None else n_steps
    for k0 in range(0, n_steps, chunk):
        count = min(chunk, n_steps - k0)
        system.run(t0, macro_step, k0, count, jacobi, record[k0:k0 + count])
        if progress is not None:
            progress(count)
    if timing is not None:
        for c, seconds in zip(order, system.timing):
            timing[c] = timing.get(c, 0.0) + float(seconds)
    result: dict[str, np.ndarray] = {}
    j = 0
    for c in order:
        for k in kept[c]:
            result[f"{c}.{handles[c].output_names[k]}"] = record[:, j, :]
            j += 1
    result["time"] = t0 + macro_step * np.arange(1, n_steps + 1)
    return result
