"""The FMU engine's FMI 3.0 handle: an sblsim FMI 3.0 FMU stepped through fmpy, its arrays seen as the FMI 2.0
scalars (:class:`Fmu3Handle`).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from sblsim.fmus.arrays import element_positions, fmi3_variables
from sblsim.models.declarations import ModelError
from sblsim.models.errors import FMICallError
from sblsim.orchestrator.cosim.fmu_engine import FmuHandle
from sblsim.orchestrator.cosim.fmu_files import FMI2_OK, one_line
from sblsim.orchestrator.cosim.handles import DTYPES, Port


class Fmu3Handle(FmuHandle):
    """An sblsim FMI 3.0 Co-Simulation FMU stepped through fmpy, seen as its FMI 2.0 twin.

    Its variables are the model's FMI 2.0 scalars grouped into arrays (:mod:`sblsim.fmus.arrays`); the handle
    names its inputs, outputs and ports by those scalars (the master, the connections and the records are those
    of :class:`~sblsim.orchestrator.cosim.fmu_engine.FmuHandle`) and moves each array whole, one
    ``fmi3Set<Type>``/``fmi3Get<Type>`` call per type and
    step. Create it with :func:`~sblsim.orchestrator.cosim.engines.open_fmu`.

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
