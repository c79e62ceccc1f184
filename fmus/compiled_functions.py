"""The casadi functions the local engine's library exports, called from Python: the eigenray solve's and the
availability map's (through casadi, :func:`compiled_exact_points`, :func:`compiled_family_points`,
:func:`compiled_family_levels`) and the design's layout information (through ctypes on numpy arrays,
:func:`compiled_layout`).
"""

from __future__ import annotations

import ctypes
from functools import lru_cache

import casadi as ca

from sblsim.fmus.native import NO_MODELS, library_path, load
from sblsim.models.acoustics.detection import family_levels
from sblsim.models.acoustics.ray_tables import exact_points, family_points
from sblsim.models.errors import CompileError
from sblsim.models.interrupts import pending


def compiled_exact_points(n_beacons: int = 4) -> ca.Function | None:
    """:func:`sblsim.models.acoustics.ray_tables.exact_points` compiled in the local engine's library (built if
    missing), or None when no compiler can build it."""
    try:
        return ca.external(exact_points().name(), str(library_path(n_beacons, models=NO_MODELS)))
    except (CompileError, OSError, RuntimeError):
        if pending() is not None:  # a signal's exception lost in casadi's symbolic work: the stop, not a failure
            raise
        return None


def compiled_family_points(n_beacons: int = 4) -> ca.Function | None:
    """:func:`sblsim.models.acoustics.ray_tables.family_points` compiled in the local engine's library (built if
    missing), or None when no compiler can build it."""
    try:
        return ca.external(family_points().name(), str(library_path(n_beacons, models=NO_MODELS)))
    except (CompileError, OSError, RuntimeError):
        if pending() is not None:  # a signal's exception lost in casadi's symbolic work: the stop, not a failure
            raise
        return None


def compiled_family_levels(n_beacons: int = 4) -> ca.Function | None:
    """:func:`sblsim.models.acoustics.detection.family_levels` compiled in the local engine's library (built if
    missing), or None when no compiler can build it."""
    try:
        return ca.external(family_levels().name(), str(library_path(n_beacons, models=NO_MODELS)))
    except (CompileError, OSError, RuntimeError):
        if pending() is not None:  # a signal's exception lost in casadi's symbolic work: the stop, not a failure
            raise
        return None


class CompiledFunction:
    """A casadi-generated function of the local engine's library, called through ctypes on numpy arrays (no
    conversion to casadi's matrices: a call costs the C function's time).

    Parameters
    ----------
    lib : ctypes.CDLL
        The library (:func:`~sblsim.fmus.native.load`).
    name : str
        The generated function's name.

    Notes
    -----
    Each input and output is a float64 array laid out as casadi lays out a matrix (column-major: a (rows, K)
    matrix of K mapped columns is a C-contiguous (K, rows) numpy array).
    """

    def __init__(self, lib: ctypes.CDLL, name: str) -> None:
        self.function = getattr(lib, name)
        self.function.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int]
        sizes = [ctypes.c_longlong() for _ in range(4)]
        work = getattr(lib, f"{name}_work")
        work(*[ctypes.byref(size) for size in sizes])
        self.n_arg, self.n_res, n_iw, n_w = (size.value for size in sizes)
        self._iw = (ctypes.c_longlong * max(n_iw, 1))()
        self._w = (ctypes.c_double * max(n_w, 1))()
        self._arg = (ctypes.c_void_p * self.n_arg)()
        self._res = (ctypes.c_void_p * self.n_res)()

    def __call__(self, inputs, outputs) -> None:
        """Evaluate into ``outputs`` (each C-contiguous float64, written in place) from ``inputs`` (each
        C-contiguous float64).

        Raises
        ------
        RuntimeError
            If the generated function reports an error.
        """
        for k, array in enumerate(inputs):
            self._arg[k] = array.ctypes.data
        for k, array in enumerate(outputs):
            self._res[k] = array.ctypes.data
        if self.function(self._arg, self._res, self._iw, self._w, 0):
            raise RuntimeError("a compiled layout function failed")


@lru_cache(maxsize=None)
def compiled_layout(slots: int) -> CompiledFunction | None:
    """The design's layout information of ``slots`` transducers over
    :data:`~sblsim.fmus.library_sources.LAYOUT_CHUNK` points (:func:`~sblsim.fmus.library_sources.layout_functions`),
    compiled in the local engine's library (built if missing), or None when no compiler can build it; one per process
    (its work memory is its own: not for two threads at once)."""
    try:
        return CompiledFunction(load(4, NO_MODELS), f"sblsim_layout_{slots}")
    except (CompileError, OSError, RuntimeError, AttributeError):
        return None



__all__ = ["CompiledFunction", "compiled_exact_points", "compiled_family_levels", "compiled_family_points",
           "compiled_layout"]
