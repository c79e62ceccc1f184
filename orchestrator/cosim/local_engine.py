"""The local engine: a model's generated C stepped in-process, batched over replicates
(:class:`sblsim.fmus.native.NativeBatch`: one call per component and step for the whole batch), and the compiled
master loop over such batches (:func:`native_system`).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, Mapping, Sequence

import numpy as np

from sblsim.fmus.native import NativeBatch, NativeSystem
from sblsim.models import COMPONENTS
from sblsim.orchestrator.cosim.handles import DTYPES, Port, typed_outputs


@lru_cache(maxsize=None)
def _model_ports(model: type, n_beacons: int) -> tuple[tuple[Port, ...], frozenset, tuple[str, ...],
                                                      tuple[str, ...], tuple[Any, ...]]:
    """A model's ports, parameter names, input and output names and output dtypes (made once per model)."""
    ports = tuple(Port(v.name, v.causality, v.fmi_type, v.unit) for v in model.fmu_variables(n_beacons))
    parameters = model.fmu_parameter_names(n_beacons)
    outputs = model.outputs(n_beacons)
    return (ports, parameters, tuple(v.name for v in model.inputs(n_beacons)), tuple(v.name for v in outputs),
            tuple(DTYPES[v.fmi_type] for v in outputs))


def parameter_rows(params: Mapping[str, Any], size: int) -> tuple[np.ndarray, np.ndarray]:
    """Which runs of a batch share their parameters: runs with the same value, bit for bit, of every parameter
    given per run (an array of shape (B,); a design cell's replicates differ only in ``replicate``, which
    keys their random streams and is not compared).

    Parameters
    ----------
    params : mapping
        Parameter values, a scalar or an array of shape (B,) each.
    size : int
        B.

    Returns
    -------
    row_of : ndarray of int, shape (B,)
        Each run's row, numbered in the order of the runs.
    first : ndarray of int, shape (R,)
        The first run of each row.
    """
    columns = [v.view(np.int64) if v.dtype == np.float64 else v for k, v in params.items()
               if k != "replicate" and isinstance(v, np.ndarray) and v.ndim > 0]
    if any(c.shape != (size,) for c in columns):  # one row per run (the wrong length is refused by its check)
        return np.arange(size), np.arange(size)
    if not columns:
        return np.zeros(size, dtype=np.int64), np.zeros(1, dtype=np.int64)
    rows: dict[tuple, int] = {}
    row_of = np.fromiter((rows.setdefault(key, len(rows)) for key in zip(*(c.tolist() for c in columns))),
                         dtype=np.int64, count=size)
    return row_of, np.unique(row_of, return_index=True)[1]


class LocalHandle:
    """A model's compiled code stepped in-process for a batch of replicates (the fast path).

    Parameters
    ----------
    component : str
        Component name in the system (a key of :data:`models.COMPONENTS`).
    model : type, optional
        The model that implements it (default the paper's, ``COMPONENTS[component]``).
    n_beacons : int
        Beacons of the interface.
    library : tuple of type, optional
        The models of the compiled library it runs in (:func:`sblsim.fmus.native.library_path`; default every
        built-in, or the model alone if it is not one): the handles of one run share one, so the compiled master
        loop steps them together, and a first run compiles only the models it uses.
    """

    #: Steps a batch of replicates at once.
    batched = True

    def __init__(self, component: str, model: type | None = None, n_beacons: int = 4,
                 library: tuple[type, ...] | None = None) -> None:
        self.component = component
        self.model = model or COMPONENTS[component]
        self.n_beacons = n_beacons
        self.library = library
        ports, self.parameters, inputs, outputs, types = _model_ports(self.model, int(n_beacons))
        self.ports, self.input_names = list(ports), list(inputs)
        self.output_names, self._types = list(outputs), list(types)
        self.batch = None

    def setup(self, params: Mapping[str, Any], replicates: Sequence[int], t0: float = 0.0) -> None:
        """Create the batch for the replicates, set its parameters and initialize it at ``t0`` [s].

        Raises
        ------
        ModelError
            On a parameter outside its declared range.
        """
        replicates = np.asarray(replicates, dtype=np.int64)
        size = replicates.size
        row_of, first = parameter_rows(params, size)
        values = {k: (v[first] if isinstance(v, np.ndarray) and v.shape == (size,) else v) for k, v in params.items()}
        seeded = "replicate" in self.parameters
        if seeded:
            values["replicate"] = replicates[first]
            for value in {replicates.min(), replicates.max()}:  # every run's, by its declaration
                self.model.parameter_vector({"replicate": int(value)}, self.n_beacons)
        if self.batch is None or (self.batch.batch, self.batch.rows) != (size, first.size):
            self.close()
            self.batch = NativeBatch(self.model, size, self.n_beacons, rows=first.size, models=self.library)
        self.model.parameter_matrix(values, first.size, self.n_beacons, out=self.batch.p)
        self.batch.assign(row_of, replicates if seeded else None)
        self.batch.u[:] = [v.start for v in self.model.inputs(self.n_beacons)] or 0.0
        self.batch.initialize(t0)

    def set_input_vector(self, values: np.ndarray) -> None:
        """Every input at once, shape (n_in, B) in the order of :attr:`input_names`."""
        self.batch.u[:] = values.T

    def output_vector(self) -> np.ndarray:
        """Every output at once, shape (n_out, B) in the order of :attr:`output_names` (a new array)."""
        return self.batch.y.T.copy()

    def set_inputs(self, values: Mapping[str, np.ndarray]) -> None:
        for name, value in values.items():
            self.batch.u[:, self.input_names.index(name)] = value

    def do_step(self, t: float, h: float) -> None:
        self.batch.do_step(t, h)

    def get_outputs(self) -> dict[str, np.ndarray]:
        return typed_outputs(self.output_names, self._types, self.output_vector())

    def states(self) -> dict[str, np.ndarray]:
        """The current state by block name, each (B, size) (for inspection and tests)."""
        x = self.batch.states()
        return {name: x[:, s] for name, s in self.model.program(self.n_beacons).state_slices().items()}

    def native_batch(self) -> Any | None:
        """The compiled batch (:class:`sblsim.fmus.native.NativeBatch`) if this is exactly a LocalHandle, else None
        (a subclass may change what is exchanged: the master's Python loop steps it)."""
        return self.batch if type(self) is LocalHandle else None

    def terminate(self) -> None:
        """Keep the batch for the next run of the same size (its memory is re-used)."""

    def close(self) -> None:
        if self.batch is not None:
            self.batch.close()
            self.batch = None


def native_system(batches: Sequence[Any], rates: Sequence[int], links: Sequence[tuple[int, int, int, int]],
                  record: Sequence[tuple[int, int]]) -> Any | None:
    """The compiled master loop over compiled batches (:class:`sblsim.fmus.native.NativeSystem`), or None when
    the batches are not of one library and one size (the master's Python loop then steps them).

    Parameters
    ----------
    batches : sequence
        The components' compiled batches (:meth:`~sblsim.orchestrator.cosim.handles.ComponentHandle.native_batch`), in
        execution order.
    rates : sequence of int
        Communication steps per macro step of each.
    links : sequence of tuple
        (source, output row, destination, input row) of every connection, by position in ``batches``.
    record : sequence of tuple
        (component, output row) of every recorded output.
    """
    if len({id(b.lib) for b in batches}) != 1 or len({b.batch for b in batches}) != 1:
        return None
    return NativeSystem(list(batches), list(rates), list(links), list(record))
