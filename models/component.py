"""The base of the component models: declarations and program of one FMI component.

A model (:class:`Component`) declares its variables
(:mod:`sblsim.models.declarations`) and builds its casadi program
(:mod:`sblsim.models.program`); both are cached per beacon count.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, ClassVar, Mapping

import numpy as np

from sblsim.models.declarations import ModelError, Variable
from sblsim.models.program import Program


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
    def fmu_parameter_names(cls, n_beacons: int = 4) -> frozenset[str]:
        """The names of :meth:`fmu_parameters_declared` (made once per model and beacon count)."""
        return _parameter_names(cls, int(n_beacons))

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
        names = cls.fmu_parameter_names(n_beacons)
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
        index, starts = _parameter_index(cls, int(n_beacons))
        unknown = sorted(set(values) - set(index))
        if unknown:
            raise ModelError(f"{cls.name}.{unknown[0]}: not a parameter of the {cls.name} FMU")
        out = starts.copy()
        for name in sorted(values, key=lambda name: index[name][0]):  # checked in the declared order
            k, v = index[name]
            value = values[name]
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
        declared = _parameter_index(cls, int(n_beacons))[0]
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
def _parameter_names(cls: type, n_beacons: int) -> frozenset[str]:
    return frozenset(v.name for v in cls.fmu_parameters_declared(n_beacons))


@lru_cache(maxsize=None)
def _config_parameters(cls: type, n_beacons: int) -> tuple[Variable, ...]:
    return tuple(v for v in cls.variables(n_beacons) if v.causality == "parameter" and v.scope != "fmu")


@lru_cache(maxsize=None)
def _parameter_index(cls: type, n_beacons: int) -> tuple[dict[str, tuple[int, Variable]], np.ndarray]:
    """Each FMU parameter's place in ``p`` and declaration, and the ``p`` of the declared starts (read-only)."""
    declared = _by_causality(cls, n_beacons, "parameter")
    starts = np.array([v.code(v.start if v.in_table else v.coerce(v.start, f"{cls.name}.{v.name}"))
                       for v in declared], dtype=float)
    starts.flags.writeable = False
    return {v.name: (k, v) for k, v in enumerate(declared)}, starts


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


__all__ = ["Component"]
