"""The FMU engine: a component FMU stepped through fmpy (the interoperability path, B = 1), instantiated once per
process and reset between runs (:func:`sblsim.orchestrator.cosim.engines.open_fmu`).
"""

from __future__ import annotations

import atexit
import ctypes
import os
import shutil
import tempfile
from collections import deque
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.errors import FMICallError
from sblsim.orchestrator.cosim.fmu_files import (
    FMI2_OK,
    FMI2_WARNING,
    LOG_LINES,
    _choice_index,
    _ports,
    check_status,
    one_line,
)
from sblsim.orchestrator.cosim.handles import DTYPES, typed_outputs
from sblsim.orchestrator.io.archives import safe_extract


class FmuHandle:
    """A component FMU stepped through fmpy (the interoperability path, B = 1).

    Create it with :func:`~sblsim.orchestrator.cosim.engines.open_fmu`. Inputs and outputs go through fmpy's
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
        its status is checked as fmpy checks it (:func:`~sblsim.orchestrator.cosim.fmu_files.check_status`), the FMU's
        log message in the error."""
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
        """Release the handle for the next run; the instance stays loaded (see
        :func:`~sblsim.orchestrator.cosim.engines.open_fmu`)."""
        self.in_use = False
