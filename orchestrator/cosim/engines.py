"""Component handles: the two engines behind one master algorithm.

Both handles follow one interface, :class:`ComponentHandle` (``setup``,
``set_input_vector``, ``do_step``, ``output_vector``, ``terminate``,
``native_batch``; ``set_inputs`` and ``get_outputs`` by name for
convenience), name their inputs and outputs (``input_names``,
``output_names``: the order of those vectors) and expose their variables as
``ports`` for the connection checks; :func:`make_handles` makes one per
component of a system:

* :class:`LocalHandle` steps a model's generated C in-process, batched over
  replicates (:class:`sblsim.fmus.native.NativeBatch`: one call per component and
  step for the whole batch);
* :class:`FmuHandle` steps a real FMU through fmpy (B = 1), instantiated once
  per process and reset between runs; :class:`Fmu3Handle` an sblsim FMI 3.0 FMU, its arrays seen as the
  FMI 2.0 scalars.

The two run the same generated code and runtime, so they give the same numbers.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import shutil
import tempfile
import zipfile
from collections import deque, namedtuple
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping, Protocol, Sequence

import numpy as np

from sblsim.fmus.arrays import element_positions, fmi3_variables
from sblsim.fmus.build import DEFAULT_DIR, beacons_dir, cached_fmu, fmu_path, version_dir
from sblsim.fmus.native import NativeBatch, NativeSystem
from sblsim.models import COMPONENTS, MODELS
from sblsim.models.declarations import ModelError
from sblsim.models.errors import FMICallError, SblsimError
from sblsim.orchestrator.cosim.connections import check_interface
from sblsim.orchestrator.io.archives import check_members, safe_extract

#: The engines of :func:`make_handles`.
ENGINES = ("local", "fmu")
#: Beacons of the FMUs ``sblsim fmus build`` writes by default (other numbers: a folder per number, or the cache).
FMU_BEACONS = 4

#: A variable as an engine exposes it (what the connection checks need).
Port = namedtuple("Port", "name causality type unit")


@lru_cache(maxsize=None)
def _model_ports(model: type, n_beacons: int) -> tuple[tuple[Port, ...], frozenset, tuple[str, ...],
                                                      tuple[str, ...], tuple[Any, ...]]:
    """A model's ports, parameter names, input and output names and output dtypes (made once per model)."""
    ports = tuple(Port(v.name, v.causality, v.fmi_type, v.unit) for v in model.fmu_variables(n_beacons))
    parameters = model.fmu_parameter_names(n_beacons)
    outputs = model.outputs(n_beacons)
    return (ports, parameters, tuple(v.name for v in model.inputs(n_beacons)), tuple(v.name for v in outputs),
            tuple(DTYPES[v.fmi_type] for v in outputs))

#: numpy type of each FMI type, as the engines return outputs.
DTYPES = {"Real": float, "Integer": np.int64, "Boolean": bool}


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
        """The compiled batch the handle steps, for the compiled master loop (:func:`native_system`), or None.

        A handle that changes what is exchanged (a wrapper or subclass of a compiled one) returns None.
        """


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


#: The FMI 2.0 status values (``fmi2Status``) by number.
FMI2_STATUS = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending")
#: The last status that is not a failure, and the one before it.
FMI2_OK, FMI2_WARNING = 0, 1
#: Log messages an FMU handle keeps (the latest explains a refused call).
LOG_LINES = 20


def check_status(status: int, function: str, where: str, reason: str = "") -> None:
    """Raise if an FMI 2.0 function's status is a failure (above ``fmi2Warning``, as fmpy's checked calls).

    Parameters
    ----------
    status : int
        What the function returned.
    function : str
        Its name, e.g. ``fmi2DoStep``.
    where : str
        The FMU file and component instance, for the message.
    reason : str
        What the FMU logged about it (empty: it logged nothing we kept).

    Raises
    ------
    FMICallError
        E.g. ``fmu: receiver.fmu (receiver): fmi2DoStep returned fmi2Error (3): <the FMU's message>`` (its
        ``function``, ``status`` and ``log`` as given).
    """
    if status > FMI2_WARNING:
        name = FMI2_STATUS[status] if 0 <= status < len(FMI2_STATUS) else "an unknown status"
        raise FMICallError(f"fmu: {where}: {function} returned {name} ({status}): "
                           f"{reason or 'the FMU logged no reason'}", function, status, reason)


def one_line(text: str, limit: int = 400) -> str:
    """A message on one line (blanks and line breaks collapsed), shortened past ``limit`` characters."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit] + " ..."


#: FMU instances made in this process, by file: (file signature, handles).
_LOADED: dict[str, tuple[tuple, list["FmuHandle"]]] = {}


def read_description(component: str, path: Path, versions: tuple[str, ...] = ("2.0",)) -> Any:
    """The model description of an FMI 2.0 (or, in ``versions``, 3.0) Co-Simulation FMU.

    Raises
    ------
    ModelError
        If the file is missing or unreadable, not Co-Simulation of one of ``versions``, or an archive that is not
        safe to unpack (:func:`sblsim.orchestrator.io.archives.check_members`: checked before its description is
        read).
    """
    from fmpy import read_model_description

    if path.is_dir():
        raise ModelError(f"fmu: {str(path)!r} is a directory, not an FMU file")
    if not path.is_file():
        raise ModelError(f"fmu: {component} FMU not found at {str(path)!r}; build it with `sblsim fmus build`")
    try:
        with zipfile.ZipFile(path) as archive:
            check_members(archive, f"fmu: {path.name} ({component})")
        md = read_model_description(str(path), validate=False)
    except SblsimError:  # an ArchiveError of check_members
        raise
    except Exception as exc:  # fmpy raises plain exceptions on unreadable archives
        raise ModelError(f"fmu: {str(path)!r} is not a readable FMU ({exc})") from None
    if md.fmiVersion not in versions or md.coSimulation is None:
        raise ModelError(f"fmu: {str(path)!r} must be an FMI {' or '.join(versions)} Co-Simulation FMU")
    return md


def fmu_ports(component: str, path: Path | str) -> list[Port]:
    """An FMU's variables as :class:`Port` records, read without loading it.

    Raises
    ------
    ModelError
        As :func:`read_description`.
    """
    return _ports(read_description(component, Path(path)))


def _ports(md: Any) -> list[Port]:
    return [Port(v.name, v.causality, v.type, v.unit or "") for v in md.modelVariables]


#: Model descriptions read in this process, by file and FMI versions allowed: (file signature, description).
_DESCRIPTIONS: dict[tuple[str, tuple[str, ...]], tuple[tuple, Any]] = {}


def _description(component: str, path: Path, resolved: Path, versions: tuple[str, ...]
                 ) -> tuple[Any, os.stat_result]:
    """:func:`read_description` of a file (``path`` as given, ``resolved`` its resolved path), read again only when
    the file has changed (its size, modification time or inode) since this process last read it (a pooled instance
    is reopened for every run), and its ``stat``."""
    key = (str(resolved), versions)
    try:
        stat = resolved.stat()
    except OSError:  # read_description names what is wrong
        stat = None
    cached = _DESCRIPTIONS.get(key)
    if stat is not None and cached is not None and cached[0] == (stat.st_size, stat.st_mtime_ns, stat.st_ino):
        return cached[1], stat
    md = read_description(component, path, versions)
    stat = resolved.stat()
    _DESCRIPTIONS[key] = ((stat.st_size, stat.st_mtime_ns, stat.st_ino), md)
    return md, stat


def open_fmu(component: str, path: Path | str, model: type | None = None,
             n_beacons: int = FMU_BEACONS, early_return: bool = False) -> "FmuHandle":
    """An instance of an FMU file for a run: an idle one made earlier in this process, else a new one.

    Instances are made once and reset between runs. A run that needs an FMU while all its
    instances are busy gets a new instance, unless the FMU declares
    ``canBeInstantiatedOnlyOncePerProcess`` (a user's pythonfmu FMU should:
    a second copy crashes the interpreter, NTNU-IHB/PythonFMU#228).

    Parameters
    ----------
    component : str
    path : path
    model : type, optional
        The sblsim model the FMU was built from (its String choices are sent as their indices; an FMI 3.0 FMU
        needs it: its arrays are read as the model's FMI 2.0 scalars, :class:`Fmu3Handle`).
    n_beacons : int
        The beacons of the interface (an FMI 3.0 FMU's arrays).
    early_return : bool
        An FMI 3.0 instance made with early return allowed (the event master), kept apart from the others.

    Raises
    ------
    ModelError
        If the file is missing or unreadable, or a once-per-process FMU is in use by another run.
    """
    path = Path(path)
    resolved = path.resolve()
    md, stat = _description(component, path, resolved, ("2.0", "3.0") if model is not None else ("2.0",))
    signature = (stat.st_size, stat.st_mtime_ns, md.guid)
    key = str(resolved) + ("\0early" if early_return and md.fmiVersion == "3.0" else "")
    if key not in _LOADED or _LOADED[key][0] != signature:
        _LOADED[key] = (signature, [])
    pool = _LOADED[key][1]
    handle = next((h for h in pool if not h.in_use), None)
    if handle is None:
        if pool and md.coSimulation.canBeInstantiatedOnlyOncePerProcess:
            raise ModelError(f"fmu: {path.name} is in use by another run in this process and can be instantiated "
                             "only once per process")
        handle = (Fmu3Handle(component, path, md, model, n_beacons, early_return) if md.fmiVersion == "3.0"
                  else FmuHandle(component, path, md, model))
        pool.append(handle)
    handle.component, handle.model = component, model
    handle.in_use = True
    return handle


class FmuHandle:
    """A component FMU stepped through fmpy (the interoperability path, B = 1).

    Create it with :func:`open_fmu`. Inputs and outputs go through fmpy's
    ctypes bindings with value-reference arrays prepared once.

    Parameters
    ----------
    component : str
        Component name used in connections.
    path : path
        The ``.fmu`` file.
    md : fmpy.model_description.ModelDescription
        Its model description.
    model : type, optional
        The sblsim model it was built from.
    """

    #: Steps one replicate at a time.
    batched = False
    #: What the FMU logged (warnings and errors, the latest last); each instance keeps its own from loading on,
    #: this empty one (it holds nothing) stands for a handle that has loaded no FMU.
    log: deque[str] = deque(maxlen=0)

    def __init__(self, component: str, path: Path, md: Any, model: type | None = None) -> None:
        self.component, self.path, self.model = component, path, model
        self.variables = {v.name: v for v in md.modelVariables}
        self.ports = _ports(md)
        self.parameters = frozenset(v.name for v in md.modelVariables if v.causality == "parameter")
        self._unpack_and_load(md)
        inputs = [v for v in md.modelVariables if v.causality == "input"]
        outputs = [v for v in md.modelVariables if v.causality == "output"]
        self.input_names = [v.name for v in inputs]
        self.output_names = [v.name for v in outputs]
        self._types = [DTYPES[v.type] for v in outputs]
        self._in, self._out = self._groups(inputs), self._groups(outputs)

    def _unpack_and_load(self, md: Any) -> None:
        """Unpack the FMU into a folder of its own (removed at exit) and load it (:meth:`_load`): an FMU may come
        from anyone, so it is unpacked only after every check of :func:`~sblsim.orchestrator.io.archives.
        safe_extract`."""
        self.log = deque(maxlen=LOG_LINES)
        self._unzipdir = tempfile.mkdtemp(prefix="sblsim_fmu_")
        try:
            safe_extract(self.path, self._unzipdir, f"fmu: {self.path.name} ({self.component})")
            self.fmu = self._load(md)
        except BaseException:
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            raise
        atexit.register(shutil.rmtree, self._unzipdir, ignore_errors=True)
        self._fresh = True
        self.in_use = False

    @property
    def where(self) -> str:
        """The FMU file and component, as the messages name them."""
        return f"{self.path.name} ({self.component})"

    def _load(self, md: Any) -> Any:
        """Load the unpacked FMU's library and instantiate it, with a logger that keeps what the FMU says.

        Raises
        ------
        ModelError
            One line naming the FMU: no binaries for this platform, a ``modelIdentifier`` that names no
            library, a library that does not load.
        FMICallError
            An instantiation the FMU refused (with its log message, e.g. a GUID that does not match the binary).
        """
        from fmpy import platform, sharedLibraryExtension
        from fmpy.fmi2 import FMU2Slave

        identifier = md.coSimulation.modelIdentifier
        folder = Path(self._unzipdir, "binaries", platform)
        if not folder.is_dir():
            raise ModelError(f"fmu: {self.where}: the FMU has no binaries/{platform} (it was not built for this "
                             "platform)")
        library = folder / f"{identifier}{sharedLibraryExtension}"
        if not library.is_file():
            present = sorted(p.name for p in folder.iterdir())
            raise ModelError(f"fmu: {self.where}: modelIdentifier {identifier!r} names no library: binaries/"
                             f"{platform} holds {', '.join(present) if present else 'nothing'}")
        cwd = os.getcwd()
        try:
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._unzipdir, modelIdentifier=identifier,
                            instanceName=self.component)
        except Exception as exc:  # fmpy raises plain exceptions: a library that does not load or lacks functions
            raise ModelError(f"fmu: {self.where}: its library {library.name} cannot be loaded "
                             f"({one_line(str(exc))})") from None
        finally:
            os.chdir(cwd)  # fmpy changes into the library's folder and does not come back when loading fails
        try:
            fmu.instantiate(callbacks=self._callbacks())
        except Exception:
            fmu.freeLibrary()
            raise FMICallError(f"fmu: {self.where}: fmi2Instantiate failed: {self.reason()}", "fmi2Instantiate",
                               None, self.log[-1] if self.log else "") from None
        return fmu

    def _callbacks(self) -> Any:
        """FMI callbacks whose logger keeps the FMU's warnings and errors in :attr:`log` (none is printed)."""
        from fmpy.fmi1 import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )

        def logger(environment, instance, status, category, message):
            if status > FMI2_OK and message:
                # sblsim's FMUs double every '%' (the message is a printf format); shown as meant
                self.log.append(one_line(message.decode("utf-8", "replace").replace("%%", "%")))

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._keep_callbacks = callbacks  # alive as long as the instance
        return callbacks

    def reason(self) -> str:
        """The FMU's latest log message (what it said when it refused a call), or that it said nothing."""
        return self.log[-1] if self.log else "the FMU logged no reason"

    def _groups(self, variables: Sequence[Any]) -> list[tuple]:
        """Per FMI type: (raw setter/getter suffix, positions in the vector, value-reference array, buffer)."""
        groups = []
        for typ in ("Real", "Integer", "Boolean"):
            rows = [k for k, v in enumerate(variables) if v.type == typ]
            if rows:
                vrs = (ctypes.c_uint * len(rows))(*[variables[k].valueReference for k in rows])
                buffer = np.zeros(len(rows), dtype=np.float64 if typ == "Real" else np.int32)
                pointer = ctypes.POINTER(ctypes.c_double if typ == "Real" else ctypes.c_int)
                groups.append((typ, np.array(rows), vrs, buffer, buffer.ctypes.data_as(pointer)))
        return groups

    def _set(self, values: Mapping[str, Any]) -> None:
        groups: dict[str, tuple[list, list]] = {}
        for name, value in values.items():
            var = self.variables[name]
            vrs, vals = groups.setdefault(var.type, ([], []))
            vrs.append(var.valueReference)
            vals.append(np.asarray(value).reshape(-1)[0].item() if not isinstance(value, str) else value)
        for typ, (vrs, vals) in groups.items():
            getattr(self.fmu, f"set{typ}")(vrs, vals)

    def setup(self, params: Mapping[str, Any], replicates: Sequence[int], t0: float = 0.0) -> None:
        """Reset (after the first run), set parameters and initialize at ``t0`` [s].

        Raises
        ------
        ModelError
            If more than one replicate is asked for, or a parameter is not in the FMU.
        FMICallError
            If the FMU refuses a call (its log message is given).
        """
        if len(replicates) != 1:
            raise ModelError("engine: the fmu engine steps one replicate at a time (B = 1)")
        missing = [n for n in params if n not in self.variables]
        if missing:
            raise ModelError(f"fmu: {self.path.name} has no parameter {missing[0]!r}")
        values = dict(params)
        if self.model is not None:
            values = self.model.fmi_values(values)
        else:  # a user's FMU: a String choice the configuration sets goes as its index, as sblsim's FMUs take it
            values = {k: (_choice_index(k, v) if isinstance(v, str) and self.variables[k].type == "Integer" else v)
                      for k, v in values.items()}
        if "replicate" in self.variables:
            values["replicate"] = int(replicates[0])
        self._call(self._initialize, values, t0)

    def _initialize(self, values: Mapping[str, Any], t0: float) -> None:
        if not self._fresh:
            self.fmu.reset()
        self._fresh = False
        self.fmu.setupExperiment(startTime=t0)
        self.fmu.enterInitializationMode()
        self._set(values)
        self.fmu.exitInitializationMode()

    def _call(self, function, *args) -> Any:
        """Call into fmpy; an FMU error becomes a one-line :class:`FMICallError`."""
        from fmpy.fmi1 import FMICallException

        self.log.clear()
        try:
            return function(*args)
        except FMICallException as exc:
            raise FMICallError(f"fmu: {self.where} refused a call: {exc}: {self.reason()}", exc.function, exc.status,
                               self.log[-1] if self.log else "") from None

    def _raw(self, name: str, *args) -> None:
        """Call an FMI function directly with prepared arguments (fmpy's wrapper costs more than the call);
        its status is checked as fmpy checks it (:func:`check_status`), the FMU's log message in the error."""
        self.log.clear()
        status = getattr(self.fmu.dll, name)(self.fmu.component, *args)
        if status > FMI2_WARNING:
            check_status(status, name, self.where, self.log[-1] if self.log else "")

    def set_input_vector(self, values: np.ndarray) -> None:
        """Every input at once, shape (n_in, 1) in the order of :attr:`input_names`."""
        for typ, rows, vrs, buffer, pointer in self._in:
            buffer[:] = values[rows, 0]
            self._raw(f"fmi2Set{typ}", vrs, len(rows), pointer)

    def output_vector(self) -> np.ndarray:
        """Every output at once, shape (n_out, 1) in the order of :attr:`output_names` (a new array)."""
        out = np.empty((len(self.output_names), 1))
        for typ, rows, vrs, buffer, pointer in self._out:
            self._raw(f"fmi2Get{typ}", vrs, len(rows), pointer)
            out[rows, 0] = buffer
        return out

    def set_inputs(self, values: Mapping[str, np.ndarray]) -> None:
        self._set(values)

    def get_outputs(self) -> dict[str, np.ndarray]:
        return typed_outputs(self.output_names, self._types, self.output_vector())

    def do_step(self, t: float, h: float) -> None:
        self._raw("fmi2DoStep", ctypes.c_double(t), ctypes.c_double(h), 1)

    def native_batch(self) -> None:
        """None: an FMU is stepped through its FMI functions."""
        return None

    def terminate(self) -> None:
        """Release the handle for the next run; the instance stays loaded (see :func:`open_fmu`)."""
        self.in_use = False


class Fmu3Handle(FmuHandle):
    """An sblsim FMI 3.0 Co-Simulation FMU stepped through fmpy, seen as its FMI 2.0 twin.

    Its variables are the model's FMI 2.0 scalars grouped into arrays (:mod:`sblsim.fmus.arrays`); the handle
    names its inputs, outputs and ports by those scalars (the master, the connections and the records are those
    of :class:`FmuHandle`) and moves each array whole, one ``fmi3Set<Type>``/``fmi3Get<Type>`` call per type and
    step. Create it with :func:`open_fmu`.

    Raises
    ------
    ModelError
        If the FMU's variables are not those sblsim writes for this model and beacon count.
    """

    _TYPES = {"Float64": (np.float64, ctypes.c_double), "Int32": (np.int32, ctypes.c_int32),
              "Boolean": (np.bool_, ctypes.c_bool)}

    def __init__(self, component: str, path: Path, md: Any, model: type, n_beacons: int,
                 early_return: bool = False) -> None:
        self.component, self.path, self.model = component, path, model
        #: Instantiated with early return allowed (the event master), and whether the FMU may return early.
        self.early_return = early_return
        self.might_return_early = bool(md.coSimulation.mightReturnEarlyFromDoStep)
        scalars = model.fmu_variables(n_beacons)
        self.table = fmi3_variables(scalars, n_beacons)
        if [v.name for v in md.modelVariables if v.causality != "independent"] != [v.name for v in self.table]:
            raise ModelError(f"fmu: {path.name} ({component}): its FMI 3.0 variables are not those of sblsim's "
                             f"{model.name} for {n_beacons} beacons (build it with `sblsim fmus build "
                             "--fmi-version 3` of this version)")
        self.variables = {v.name: v for v in scalars}
        self._vr = {v.name: k for k, v in enumerate(scalars)}
        self._where = element_positions(self.table)
        self.ports = [Port(v.name, v.causality, v.fmi_type, v.unit or "") for v in scalars]
        self.parameters = frozenset(v.name for v in scalars if v.causality == "parameter")
        self._unpack_and_load(md)
        inputs = [v for v in scalars if v.causality == "input"]
        outputs = [v for v in scalars if v.causality == "output"]
        self.input_names = [v.name for v in inputs]
        self.output_names = [v.name for v in outputs]
        self._types = [DTYPES[v.fmi_type] for v in outputs]
        self._in, self._out = self._groups3("input", inputs), self._groups3("output", outputs)

    def _groups3(self, causality: str, scalars: Sequence[Any]) -> list[tuple]:
        """Per FMI 3.0 type: (type, positions in the scalar vector of each value, value-reference array,
        buffer, its pointer): the arrays of ``causality`` whole, in value-reference order."""
        position = {self._vr[v.name]: k for k, v in enumerate(scalars)}
        groups = []
        for typ, (dtype, ctype) in self._TYPES.items():
            chosen = [(vr, v) for vr, v in enumerate(self.table) if v.causality == causality and v.fmi_type == typ]
            if chosen:
                rows = np.array([position[e] for _, v in chosen for e in v.elements])
                vrs = (ctypes.c_uint * len(chosen))(*[vr for vr, _ in chosen])
                buffer = np.zeros(len(rows), dtype=dtype)
                groups.append((typ, rows, vrs, buffer, buffer.ctypes.data_as(ctypes.POINTER(ctype))))
        return groups

    def _load(self, md: Any) -> Any:
        """Load the unpacked FMU's library and instantiate it (Co-Simulation, no Event Mode, early return as
        asked), with a logger that keeps what the FMU says."""
        from fmpy import platform_tuple, sharedLibraryExtension
        from fmpy.fmi3 import FMU3Slave

        identifier = md.coSimulation.modelIdentifier
        library = Path(self._unzipdir, "binaries", platform_tuple, f"{identifier}{sharedLibraryExtension}")
        if not library.is_file():
            raise ModelError(f"fmu: {self.where}: the FMU has no binaries/{platform_tuple}/{library.name}")
        cwd = os.getcwd()
        try:
            fmu = FMU3Slave(guid=md.guid, unzipDirectory=self._unzipdir, modelIdentifier=identifier,
                            instanceName=self.component)
        except Exception as exc:
            raise ModelError(f"fmu: {self.where}: its library {library.name} cannot be loaded "
                             f"({one_line(str(exc))})") from None
        finally:
            os.chdir(cwd)

        def logger(environment, status, category, message):
            if status > FMI2_OK and message:
                self.log.append(one_line(message.decode("utf-8", "replace").replace("%%", "%")))

        try:
            fmu.instantiate(logMessage=logger, earlyReturnAllowed=self.early_return)
        except Exception:
            fmu.freeLibrary()
            raise FMICallError(f"fmu: {self.where}: fmi3InstantiateCoSimulation failed: {self.reason()}",
                               "fmi3InstantiateCoSimulation", None, self.log[-1] if self.log else "") from None
        return fmu

    def _set(self, values: Mapping[str, Any]) -> None:
        """Set scalars by their FMI 2.0 names: each array they belong to is read, changed and written whole."""
        changed: dict[int, np.ndarray] = {}
        for name, value in values.items():
            vr3, k = self._where[self._vr[name]]
            v = self.table[vr3]
            if vr3 not in changed:
                changed[vr3] = np.array(getattr(self.fmu, f"get{v.fmi_type}")([vr3], nValues=v.size))
            changed[vr3][k] = np.asarray(value).reshape(-1)[0].item()
        for vr3, array in changed.items():
            typ = self.table[vr3].fmi_type
            cast = {"Float64": float, "Int32": int, "Boolean": bool}[typ]
            getattr(self.fmu, f"set{typ}")([vr3], [cast(x) for x in array])

    def _initialize(self, values: Mapping[str, Any], t0: float) -> None:
        if not self._fresh:
            self.fmu.reset()
        self._fresh = False
        self.fmu.enterInitializationMode(startTime=t0)
        self._set(values)
        self.fmu.exitInitializationMode()

    def set_input_vector(self, values: np.ndarray) -> None:
        """Every input at once, shape (n_in, 1) in the order of :attr:`input_names`."""
        for typ, rows, vrs, buffer, pointer in self._in:
            buffer[:] = values[rows, 0]
            self._raw(f"fmi3Set{typ}", vrs, len(vrs), pointer, len(rows))

    def output_vector(self) -> np.ndarray:
        """Every output at once, shape (n_out, 1) in the order of :attr:`output_names` (a new array)."""
        out = np.empty((len(self.output_names), 1))
        for typ, rows, vrs, buffer, pointer in self._out:
            self._raw(f"fmi3Get{typ}", vrs, len(vrs), pointer, len(rows))
            out[rows, 0] = buffer
        return out

    def do_step(self, t: float, h: float) -> None:
        self.step_until(t, h)

    def step_until(self, t: float, h: float) -> float:
        """``fmi3DoStep`` from ``t`` [s] over ``h`` [s]; the time it reached [s]: ``t + h``, or the arrival it
        returned early at (an instance made with early return allowed)."""
        flags = [ctypes.c_bool() for _ in range(3)]
        last = ctypes.c_double()
        self._raw("fmi3DoStep", ctypes.c_double(t), ctypes.c_double(h), ctypes.c_bool(True),
                  *[ctypes.byref(f) for f in flags], ctypes.byref(last))
        return last.value if flags[2].value else t + h


def native_system(batches: Sequence[Any], rates: Sequence[int], links: Sequence[tuple[int, int, int, int]],
                  record: Sequence[tuple[int, int]]) -> Any | None:
    """The compiled master loop over compiled batches (:class:`sblsim.fmus.native.NativeSystem`), or None when
    the batches are not of one library and one size (the master's Python loop then steps them).

    Parameters
    ----------
    batches : sequence
        The components' compiled batches (:meth:`ComponentHandle.native_batch`), in execution order.
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


#: What implements a component: a built-in model's name, a user's model class or the path of a user's FMU.
Source = str | Path | type


@lru_cache(maxsize=None)
def _choice_index(name: str, value: str) -> int:
    """The index of ``value`` among the choices sblsim's models declare for the String parameter ``name`` (the
    FMUs take a choice as its index).

    Raises
    ------
    ModelError
        When no model declares ``value`` as a choice of ``name``.
    """
    for model in MODELS.values():
        for variable in model.fmu_parameters_declared(1):
            if variable.name == name and variable.choices is not None and value in variable.choices:
                return variable.choices.index(value)
    raise ModelError(f"fmu: parameter {name!r} is an Integer; the value {value!r} is none of its choices")


def source_model(source: Source) -> type | None:
    """The model class of a source (None for a user's FMU)."""
    if isinstance(source, Path):
        return None
    return source if isinstance(source, type) else MODELS[source]


def paper_sources() -> dict[str, Source]:
    """The paper's system: each component by its built-in model."""
    return {name: name for name in COMPONENTS}


def fmu_paths(fmu_dir: Path | str | None = None, sources: dict[str, Source] | None = None,
              n_beacons: int = FMU_BEACONS, fmi_version: int = 2) -> dict[str, Path]:
    """The FMU file of every component: built ones in ``fmu_dir``, a user's FMU, or a model built into the
    cache (:func:`sblsim.fmus.build.cached_fmu`).

    Without ``fmu_dir``, a built-in model's FMU is the one ``sblsim fmus build`` wrote into
    :data:`sblsim.fmus.build.DEFAULT_DIR` (:func:`sblsim.fmus.build.beacons_dir` for the number of beacons)
    when it is there, else it is built once into the user's cache and reused: the ``fmu`` engine runs
    every configuration out of the box, and writes nothing into the installed package. With ``fmu_dir``, the
    paper's 4-beacon FMUs must be there (a folder given is a folder meant); another number of beacons is
    built into the cache when that folder does not hold it. FMI 3.0 (``fmi_version`` 3): the same, in the
    folders' ``fmi3`` folder (:func:`sblsim.fmus.build.version_dir`).

    Raises
    ------
    ModelError
        If an FMU is missing.
    CompileError
        If an FMU must be built and the compiler is missing or fails.
    """
    directory = version_dir(beacons_dir(Path(fmu_dir) if fmu_dir is not None else DEFAULT_DIR, n_beacons),
                            fmi_version)
    sources = sources if sources is not None else paper_sources()
    paths = {}
    for name, src in sources.items():
        if isinstance(src, Path):
            paths[name] = src
        elif isinstance(src, type):
            paths[name] = cached_fmu(src, n_beacons, fmi_version)
        else:
            built = fmu_path(directory, src)
            given = fmu_dir is not None and n_beacons == FMU_BEACONS
            paths[name] = built if built.is_file() or given else cached_fmu(MODELS[src], n_beacons, fmi_version)
    for name, path in paths.items():
        if not path.is_file():
            raise ModelError(f"fmu: {name} FMU not found at {str(path)!r}; build it with `sblsim fmus build"
                             f"{' --fmi-version 3' if fmi_version == 3 else ''}`")
    return paths


def make_handles(engine: str, fmu_dir: Path | str | None = None, n_beacons: int = 4,
                 sources: dict[str, Source] | None = None,
                 fmu_files: dict[str, Path] | None = None, fmi_version: int = 2,
                 early_return: bool = False) -> dict[str, ComponentHandle]:
    """One handle per component for an engine.

    Parameters
    ----------
    engine : {'local', 'fmu'}
    fmu_dir : path, optional
        Directory of the built FMUs (fmu engine).
    n_beacons : int
    sources : dict, optional
        What implements each component (:attr:`sblsim.orchestrator.cosim.plan.RunPlan.sources` of a run's plan;
        default :func:`paper_sources`). A user's FMU is loaded on either engine and checked against the
        component's interface.
    fmu_files : dict, optional
        Component -> FMU file, overriding ``fmu_dir`` (an SSP package's FMUs).
    fmi_version : {2, 3}
        The fmu engine's FMUs of sblsim's models: FMI 2.0 or 3.0 (:class:`Fmu3Handle`; the same numbers).
    early_return : bool
        FMI 3.0 instances made with early return allowed (the event master).

    Raises
    ------
    ModelError
        Unknown engine, a missing FMU, or a user's FMU that does not match
        the interface (the message lists every mismatch).
    """
    if engine not in ENGINES:
        raise ModelError(f"engine: {engine!r} is not one of {', '.join(ENGINES)}")
    sources = sources if sources is not None else paper_sources()
    if engine == "fmu":
        paths = {**fmu_paths(fmu_dir, {k: v for k, v in sources.items() if k not in (fmu_files or {})}, n_beacons,
                             fmi_version), **(fmu_files or {})}
    else:
        paths = {name: src for name, src in sources.items() if isinstance(src, Path)}
    local = {source_model(src) for name, src in sources.items() if name not in paths}
    library = tuple(model for model in MODELS.values() if model in local)  # the built-ins this run compiles
    handles: dict[str, ComponentHandle] = {}
    try:
        for name, src in sources.items():
            if name not in paths:
                model = source_model(src)
                handles[name] = LocalHandle(name, model, n_beacons, library if model in library else None)
                continue
            if isinstance(src, Path):  # a user's FMU: check its interface before loading it
                check_interface(name, fmu_ports(name, src), COMPONENTS[name].fmu_variables(n_beacons), src)
            handles[name] = open_fmu(name, paths[name], source_model(src), n_beacons, early_return)
    except Exception:
        close_handles(handles)
        raise
    return handles


def close_handles(handles: Mapping[str, ComponentHandle]) -> None:
    """Terminate every handle."""
    for handle in handles.values():
        handle.terminate()
