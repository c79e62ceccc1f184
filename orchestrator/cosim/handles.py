"""What every engine's handle is: the interface the master algorithm steps (:class:`ComponentHandle`), a variable
as a handle exposes it (:class:`Port`), outputs as their FMI types, and what implements a component (a built-in
model, a user's model class or a user's FMU: :data:`Source`).
"""

from __future__ import annotations

from collections import namedtuple
from pathlib import Path
from typing import Any, Mapping, Protocol, Sequence

import numpy as np

from sblsim.models import COMPONENTS, MODELS

#: A variable as an engine exposes it (what the connection checks need).
Port = namedtuple("Port", "name causality type unit")
#: numpy type of each FMI type, as the engines return outputs.
DTYPES = {"Real": float, "Integer": np.int64, "Boolean": bool}


class ComponentHandle(Protocol):
    """What the master algorithm and a run ask of a component, on any engine.

    Attributes
    ----------
    input_names, output_names : list of str
        The inputs and outputs, in the order of the vectors below.
    ports : list of Port
        Every variable (for the connection checks).
    parameters : frozenset of str
        The parameters it takes.
    batched : bool
        Whether it steps a batch of replicates at once (else one at a time, B = 1).
    """

    input_names: list[str]
    output_names: list[str]
    ports: list[Port]
    parameters: frozenset[str]
    batched: bool

    def setup(self, params: Mapping[str, Any], replicates: Sequence[int], t0: float = 0.0) -> None:
        """(Re)start for a run: set the parameters of the replicates and initialize at ``t0`` [s]."""

    def set_input_vector(self, values: np.ndarray) -> None:
        """Every input at once, shape (n_in, B) in the order of ``input_names``."""

    def do_step(self, t: float, h: float) -> None:
        """One communication step from ``t`` [s] of length ``h`` [s]."""

    def output_vector(self) -> np.ndarray:
        """Every output at once, shape (n_out, B) in the order of ``output_names`` (a new array, floats)."""

    def terminate(self) -> None:
        """End the run (the handle may be set up again)."""

    def native_batch(self) -> Any | None:
        """The compiled batch the handle steps, for the compiled master loop
        (:func:`~sblsim.orchestrator.cosim.local_engine.native_system`), or None.

        A handle that changes what is exchanged (a wrapper or subclass of a compiled one) returns None.
        """


def typed_outputs(names: Sequence[str], types: Sequence[type], vector: np.ndarray) -> dict[str, np.ndarray]:
    """Outputs by name from an output matrix (n_out, B), Integer and Boolean ones cast to their type."""
    return {name: cast_column(vector[k], dtype) for k, (name, dtype) in enumerate(zip(names, types))}


def cast_column(values: np.ndarray, dtype: type) -> np.ndarray:
    """A column of an output matrix as its FMI type (floats carry Integer and Boolean values)."""
    if dtype is bool:
        return values > 0.5
    if dtype is np.int64:
        return np.rint(values).astype(np.int64)
    return values


#: What implements a component: a built-in model's name, a user's model class or the path of a user's FMU.
Source = str | Path | type


def source_model(source: Source) -> type | None:
    """The model class of a source (None for a user's FMU)."""
    if isinstance(source, Path):
        return None
    return source if isinstance(source, type) else MODELS[source]


def paper_sources() -> dict[str, Source]:
    """The paper's system: each component by its built-in model."""
    return {name: name for name in COMPONENTS}
