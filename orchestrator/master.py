"""The master algorithm: fixed-step, multi-rate co-simulation, Gauss-Seidel or Jacobi.

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

After each macro step every output of every component is recorded.

References
----------
Gomes, Thule, Broman, Larsen, Vangheluwe, "Co-simulation: a survey",
ACM Computing Surveys 51(3), 2018, Section 3 (Gauss-Seidel and Jacobi master
algorithms, multi-rate stepping).
"""

from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np

from orchestrator.connections import Connection, execution_order

#: Master algorithms of :func:`simulate`.
ALGORITHMS = ("gauss-seidel", "jacobi")


def simulate(handles: Mapping[str, object], connections: Sequence[Connection], rates: Mapping[str, int],
             macro_step: float, n_steps: int, t0: float = 0.0,
             progress: Callable[[int], None] | None = None,
             record: Sequence[str] | None = None, algorithm: str = "gauss-seidel") -> dict[str, np.ndarray]:
    """Run the co-simulation and record every output at each communication point.

    Parameters
    ----------
    handles : mapping
        Component name -> set-up handle (:mod:`orchestrator.engines`).
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
    algorithm : {'gauss-seidel', 'jacobi'}
        Where inputs come from (see the module).

    Returns
    -------
    dict
        ``"component.variable"`` -> array of shape (n_steps, B) for each
        recorded output, and
        ``"time"`` -> array of shape (n_steps,) [s] (the end of each macro step).

    Raises
    ------
    ValueError
        If ``algorithm`` is unknown.
    KeyError
        If a recorded name is not an output of the system.
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"simulation.master: {algorithm!r} is not one of {', '.join(ALGORITHMS)}")
    jacobi = algorithm == "jacobi"
    order = execution_order(list(handles), connections)
    incoming = {c: [k for k in connections if k.destination == c] for c in handles}
    outputs = {c: handles[c].get_outputs() for c in handles}
    recorded = [(c, n) for c in handles for n in outputs[c]]
    if record is not None:
        unknown = sorted(set(record) - {f"{c}.{n}" for c, n in recorded})
        if unknown:
            raise KeyError(f"record: {unknown[0]} is not an output of the system")
        wanted = set(record)
        recorded = [(c, n) for c, n in recorded if f"{c}.{n}" in wanted]
    records: dict[str, list] = {f"{c}.{n}": [] for c, n in recorded}

    def feed(c: str) -> None:
        """Set a component's inputs from the latest outputs (copied under Jacobi: a core may update
        its output arrays in place while it steps, after the copy was handed on)."""
        if incoming[c]:
            handles[c].set_inputs({conn.input: np.array(outputs[conn.source][conn.output], copy=True) if jacobi
                                   else outputs[conn.source][conn.output] for conn in incoming[c]})

    for k in range(n_steps):
        t = t0 + k * macro_step
        if jacobi:  # every input from the outputs at the start of the macro step
            for c in order:
                feed(c)
        for c in order:
            handle = handles[c]
            if not jacobi:
                feed(c)
            ratio = rates.get(c, 1)
            sub = macro_step / ratio
            for j in range(ratio):
                handle.do_step(t + j * sub, sub)
            outputs[c] = handle.get_outputs()
        for c, n in recorded:
            records[f"{c}.{n}"].append(np.array(outputs[c][n], copy=True))
        if progress is not None:
            progress(1)
    result = {key: np.stack(values) for key, values in records.items()}
    result["time"] = t0 + macro_step * np.arange(1, n_steps + 1)
    return result
