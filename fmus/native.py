"""The local engine's compiled path: the models' generated C and the runtime in one library.

The library holds the same generated code and runtime as the FMUs, plus a
batch API (``fmus/c/sblsim_batch.c``) that steps B replicates of a model in
one call. It is built on first use for a beacon count and a set of models (a
run's engine asks for the models the run uses) into a cache folder, keyed by
a hash of what its sources are generated from (the package's model and FMU
sources, casadi's version), the models and the compiler flags, and re-used
by every later process: ``$SBLSIM_CACHE_DIR`` or the user's cache folder
(``platformdirs``). Its objects are the compiler's cache's
(:mod:`sblsim.fmus.compiler`), shared with the other libraries and the FMUs,
so a library of other models compiles only the models new to the machine. A
process generates the sources only when it compiles them, or when a model or
system from outside the package takes part (then the key hashes the
generated sources themselves).

:class:`NativeBatch` wraps one batch: parameter, input and output matrices
are numpy views of the library's memory (B rows of inputs and outputs; one
parameter row per design cell of the batch, shared by its replicates, whose
derived values are prepared once).

The sources come from :mod:`sblsim.fmus.library_sources`; the compiled passes over recorded runs are
:mod:`sblsim.fmus.compiled_metrics`, the exported casadi functions :mod:`sblsim.fmus.compiled_functions`.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import sys
import tempfile
import threading
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable

import numpy as np

from sblsim.fmus.codegen import built_in, package_digest
from sblsim.fmus.compiler import FLAGS, PLATFORMS, cache_dir, compile_library, find_compiler, host_platform
from sblsim.fmus.contract import VECTORS
from sblsim.fmus.library_sources import _library_models, write_library_sources
from sblsim.models import MODELS
from sblsim.models.declarations import ModelError
from sblsim.models.systems import SYSTEMS

#: The models of the library of the metrics, the bounds and the eigenray entry points: none (the runtime, the
#: bound, the eigenray functions and the metrics alone).
NO_MODELS: tuple[type, ...] = ()


@lru_cache(maxsize=None)
def library_path(n_beacons: int = 4, compiler: str = "auto", models: tuple[type, ...] | None = None) -> Path:
    """The compiled batch library for ``n_beacons`` beacons, built into the cache if missing.

    Parameters
    ----------
    n_beacons : int
    compiler : {'auto', 'system', 'zig'}
    models : tuple of type, optional
        The models compiled in (default every built-in; a run's engine asks for the models it runs, a user's model
        for a library of its own, and the metrics, the bounds and the eigenray entry points for none:
        :data:`NO_MODELS`). Libraries share the objects of their common sources (the compiler's cache), so a
        first run compiles only what it uses.

    Raises
    ------
    CompileError
        If no compiler is found or it fails.
    """
    cc = find_compiler(compiler)
    flags = " ".join(FLAGS + cc.command[-1:]).encode()
    package = package_digest() if built_in(_library_models(models)) else None
    with tempfile.TemporaryDirectory(prefix="sblsim_native_") as tmp:
        digest = hashlib.sha256(flags)
        if package is not None:  # what the sources are generated from: no need to generate them to know them
            names = [model.__name__ for model in _library_models(models)] + list(SYSTEMS)
            digest.update(package + " ".join(names).encode() + str(n_beacons).encode())
        else:
            write_library_sources(n_beacons, Path(tmp), models)
            for path in sorted(Path(tmp).iterdir()):
                digest.update(path.name.encode() + path.read_bytes())
        key = digest.hexdigest()[:16]
        target = cache_dir() / f"libsblsim-{key}-n{n_beacons}{PLATFORMS[host_platform()][1]}"
        if target.is_file():
            return target
        files = write_library_sources(n_beacons, Path(tmp), models) if package is not None else sorted(
            Path(tmp).glob("*.c"))
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = target.parent / f".{target.name}.{os.getpid()}.partial"
        if sys.stderr.isatty():  # the first run on a machine waits seconds for this: say so at a terminal
            print(f"sblsim: compiling the local engine for {n_beacons} beacons with {cc.describe()} (once; cached "
                  f"in {target.parent})", file=sys.stderr, flush=True)
        try:
            compile_library(cc, files, partial, [Path(tmp)])
            os.replace(partial, target)
        finally:
            partial.unlink(missing_ok=True)
    return target


@lru_cache(maxsize=None)
def load(n_beacons: int = 4, models: tuple[type, ...] | None = None) -> ctypes.CDLL:
    """The batch library for ``n_beacons`` beacons (and ``models``, default the built-ins), loaded (built first
    if needed)."""
    lib = ctypes.CDLL(str(library_path(n_beacons, models=models)))
    lib.sblsim_batch_new.restype = ctypes.c_void_p
    lib.sblsim_batch_new.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_int]
    lib.sblsim_batch_rows.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int),
                                      ctypes.POINTER(ctypes.c_longlong)]
    lib.sblsim_batch_free.argtypes = [ctypes.c_void_p]
    lib.sblsim_batch_vector.restype = ctypes.POINTER(ctypes.c_double)
    lib.sblsim_batch_vector.argtypes = [ctypes.c_void_p, ctypes.c_int]
    lib.sblsim_batch_states.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)]
    lib.sblsim_batch_message.restype = ctypes.c_char_p
    lib.sblsim_batch_message.argtypes = [ctypes.c_void_p]
    lib.sblsim_batch_initialize.argtypes = [ctypes.c_void_p, ctypes.c_double]
    lib.sblsim_batch_do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double]
    lib.sblsim_model_size.argtypes = [ctypes.c_char_p, ctypes.c_int]
    lib.sblsim_metrics_sizes.argtypes = [ctypes.POINTER(ctypes.c_int)]
    lib.sblsim_run_metrics.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(ctypes.c_void_p),
                                       ctypes.POINTER(ctypes.c_longlong), ctypes.c_int] + [ctypes.c_void_p] * 5
    ints, doubles = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)
    lib.sblsim_system_run.argtypes = [ctypes.c_int, ctypes.POINTER(ctypes.c_void_p), ints, ints, ints, ints, ints,
                                      ctypes.c_int, ints, ints, doubles, ctypes.c_double, ctypes.c_double,
                                      ctypes.c_int, ctypes.c_int, ctypes.c_int, doubles, ints, ints]
    for name in ("sblsim_stream_uniforms", "sblsim_stream_normals"):
        getattr(lib, name).argtypes = [ctypes.POINTER(ctypes.c_uint64), ctypes.c_int, ctypes.c_int, ctypes.c_uint64,
                                       ctypes.c_int, ctypes.POINTER(ctypes.c_double)]
    return lib


class NativeBatch:
    """B replicates of one model stepped together by the compiled runtime.

    Parameters
    ----------
    model : type
        A :class:`sblsim.models.component.Component`.
    batch : int
        Number of replicates B.
    n_beacons : int
    rows : int, optional
        Number of parameter rows R, 1 ≤ R ≤ B (default B: one per replicate). Replicates that differ only in
        their random streams (a design cell's) share one row and its derived values, which are then checked
        and prepared once (:meth:`assign` says which row each replicate uses).
    models : tuple of type, optional
        The models of the library it runs in (:func:`library_path`; default every built-in, or ``model`` alone if
        it is not one); ``model`` is one of them.

    Raises
    ------
    ValueError
        If ``model`` is not one of ``models``.

    Attributes
    ----------
    p : ndarray, shape (R, n_p)
        Parameter rows (filled before :meth:`initialize`).
    d : ndarray, shape (R, n_d)
        Derived values of each row (after :meth:`initialize`).
    u : ndarray, shape (B, n_u)
        Inputs (set before every :meth:`do_step`).
    y : ndarray, shape (B, n_y)
        Outputs (after :meth:`initialize` and every :meth:`do_step`).
    """

    def __init__(self, model: type, batch: int, n_beacons: int = 4, rows: int | None = None,
                 models: tuple[type, ...] | None = None) -> None:
        if models is None:
            models = None if model in MODELS.values() else (model,)
        elif model not in models:
            raise ValueError(f"NativeBatch: the model {model.name!r} is not one of the library's models")
        self.lib = load(n_beacons, models)
        self.model, self.batch = model, int(batch)
        self.rows = self.batch if rows is None else int(rows)
        name = model.name.encode()
        self._handle = self.lib.sblsim_batch_new(name, self.batch, self.rows)
        if not self._handle:
            raise ModelError(f"engine: the compiled library has no model {model.name!r}, {self.rows} parameter "
                             f"rows for a batch of {self.batch}, or it is out of memory")
        sizes = {k: self.lib.sblsim_model_size(name, VECTORS.index(k)) for k in ("p", "d", "x", "u", "y", "draws")}
        self.sizes = sizes
        self.p = self._view("p", self.rows, sizes["p"])
        self.d = self._view("d", self.rows, sizes["d"])
        self.u = self._view("u", self.batch, sizes["u"])
        self.y = self._view("y", self.batch, sizes["y"])

    def _view(self, which: str, rows: int, n: int) -> np.ndarray:
        pointer = self.lib.sblsim_batch_vector(self._handle, VECTORS.index(which))
        return np.ctypeslib.as_array(pointer, shape=(rows, max(n, 1)))[:, :n]

    def assign(self, row_of: np.ndarray, replicate: np.ndarray | None = None) -> None:
        """Replicate ``i`` uses parameter row ``row_of[i]`` and, if given, draws its random streams as replicate
        ``replicate[i]`` (else as its row's ``replicate`` parameter).

        Raises
        ------
        ModelError
            If a row index is outside ``[0, R)`` or the arrays are not of length B.
        """
        rows = np.ascontiguousarray(row_of, dtype=np.intc)
        keys = None if replicate is None else np.ascontiguousarray(replicate, dtype=np.longlong)
        if rows.shape != (self.batch,) or (keys is not None and keys.shape != (self.batch,)):
            raise ModelError(f"{self.model.name}: a row and a replicate for each of the {self.batch} replicates")
        self._check(self.lib.sblsim_batch_rows(
            self._handle, rows.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
            None if keys is None else keys.ctypes.data_as(ctypes.POINTER(ctypes.c_longlong))), "parameter rows")

    def _check(self, status: int, what: str) -> None:
        if status:
            message = self.lib.sblsim_batch_message(self._handle).decode()
            raise ModelError(f"{self.model.name}: {message} (replicate {status - 1} of the batch, {what})")

    def initialize(self, t0: float = 0.0) -> None:
        """Check every replicate's parameters, then prepare, init and output at ``t0`` [s].

        Raises
        ------
        ModelError
            Naming the first parameter outside its declared range.
        """
        self._check(self.lib.sblsim_batch_initialize(self._handle, float(t0)), "initialization")

    def do_step(self, t: float, h: float) -> None:
        """One communication step of every replicate from ``t`` to ``t + h`` [s]."""
        self._check(self.lib.sblsim_batch_do_step(self._handle, float(t), float(h)), f"step at t = {t:g} s")

    def states(self) -> np.ndarray:
        """A copy of the current states, shape (B, n_x)."""
        out = np.empty((self.batch, max(self.sizes["x"], 1)))
        self.lib.sblsim_batch_states(self._handle, out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        return out[:, :self.sizes["x"]]

    def close(self) -> None:
        if getattr(self, "_handle", None):
            self.lib.sblsim_batch_free(self._handle)
            self._handle = None

    def __del__(self) -> None:
        self.close()


def abandonable(call: Callable[[], Any], cancel: ctypes.c_int) -> Any:
    """``call()``, a compiled call that reads ``cancel`` as it works, made interruptible.

    A compiled call holds the thread that made it for as long as it runs (minutes for a site's budget) and
    Python handles a signal only in the main thread, between two of its own instructions: a user's Ctrl-C or
    SIGTERM would wait for the call's end. The call therefore runs in a worker thread (ctypes releases the GIL)
    while this thread waits and handles signals; when the wait ends in an exception (KeyboardInterrupt from
    Ctrl-C, or the SIGTERM handler's), ``cancel`` is set, the compiled code stops at its next check (within one
    replicate's step) and the exception goes on. The call's own result or exception is this function's.
    """
    outcome: list = []

    def work() -> None:
        try:
            outcome.append((True, call()))
        except BaseException as exc:  # handed to the waiting thread
            outcome.append((False, exc))

    worker = threading.Thread(target=work, name="sblsim-native", daemon=True)
    worker.start()
    try:
        while worker.is_alive():
            worker.join(0.5)
    except BaseException:
        cancel.value = 1
        worker.join()
        raise
    ok, value = outcome[0]
    if not ok:
        raise value
    return value


class NativeSystem:
    """Several batches of one library stepped together by the compiled master loop (``sblsim_system_run``).

    Parameters
    ----------
    batches : sequence of NativeBatch
        In execution order, the same batch size and library.
    rates : sequence of int
        Communication steps per macro step of each.
    links : sequence of (int, int, int, int)
        ``(source batch, source output, destination batch, destination input)``.
    record : sequence of (int, int)
        ``(batch, output)`` recorded after every macro step.
    """

    def __init__(self, batches, rates, links, record) -> None:
        self.batches = list(batches)
        self.lib = self.batches[0].lib
        n = len(self.batches)
        self.n, self.B = n, self.batches[0].batch
        self._pointers = (ctypes.c_void_p * n)(*[b._handle for b in self.batches])
        by_destination = sorted(links, key=lambda link: link[2])
        offsets = np.searchsorted([link[2] for link in by_destination], np.arange(n + 1)).astype(np.int32)
        self._arrays = {
            "rates": np.asarray(rates, dtype=np.int32), "offsets": offsets,
            "src": np.array([link[0] for link in by_destination] or [0], dtype=np.int32),
            "out": np.array([link[1] for link in by_destination] or [0], dtype=np.int32),
            "in": np.array([link[3] for link in by_destination] or [0], dtype=np.int32),
            "rec_comp": np.array([r[0] for r in record] or [0], dtype=np.int32),
            "rec_out": np.array([r[1] for r in record] or [0], dtype=np.int32),
        }
        self.n_record = len(record)
        self.timing = np.zeros(n)

    def run(self, t0: float, T: float, k0: int, n_steps: int, jacobi: bool, into: np.ndarray) -> None:
        """Macro steps ``k0 … k0 + n_steps − 1``; the records into ``into`` (n_steps, n_record, B), C order.

        Raises
        ------
        ModelError
            As :meth:`NativeBatch.do_step`, naming the component and the replicate.
        """
        ints = ctypes.POINTER(ctypes.c_int)
        a = {k: v.ctypes.data_as(ints) for k, v in self._arrays.items()}
        failed, cancel = ctypes.c_int(0), ctypes.c_int(0)
        status = abandonable(lambda: self.lib.sblsim_system_run(
            self.n, self._pointers, a["rates"], a["offsets"], a["src"], a["out"], a["in"], self.n_record,
            a["rec_comp"], a["rec_out"], into.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), float(t0), float(T),
            int(k0), int(n_steps), int(jacobi), self.timing.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            ctypes.byref(failed), ctypes.byref(cancel)), cancel)
        if status:
            batch = self.batches[status - 1]
            t = t0 + k0 * T
            batch._check(1 + failed.value, f"step between t = {t:g} s and {t0 + (k0 + n_steps) * T:g} s")


def stream(kind: str, keys, component: int, purpose: int, draw: int, count: int, n_beacons: int = 4) -> np.ndarray:
    """One draw of a random stream as the C runtime makes it (for the tests against numpy's Philox)."""
    lib = load(n_beacons, NO_MODELS)
    out = np.empty(count)
    key_array = (ctypes.c_uint64 * 4)(*[int(k) for k in keys])
    getattr(lib, f"sblsim_stream_{kind}s")(key_array, component, purpose, draw, count,
                                            out.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
    return out


__all__ = ["NO_MODELS", "NativeBatch", "NativeSystem", "VECTORS", "abandonable", "cache_dir", "library_path", "load",
           "stream", "write_library_sources"]
