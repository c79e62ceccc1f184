"""Component handles: the two engines behind one master algorithm.

Both handles share one small interface (``setup``, ``set_inputs``,
``do_step``, ``get_outputs``, ``terminate``) and expose their variables as
``ports`` for the connection checks:

* :class:`LocalHandle` steps a core in-process, batched over replicates;
* :class:`FmuHandle` steps a real FMU through fmpy's ``FMU2Slave``,
  instantiated once and reset between runs (B = 1).
"""

from __future__ import annotations

import atexit
import shutil
from collections import namedtuple
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from models import COMPONENTS
from models.core import ModelError

#: A variable as an engine exposes it (what the connection checks need).
Port = namedtuple("Port", "name causality type unit")

_DTYPES = {"Real": float, "Integer": np.int64, "Boolean": bool}


class LocalHandle:
    """A component core stepped in-process (the fast, batched path).

    Parameters
    ----------
    component : str
        Component name in the system (a key of :data:`models.COMPONENTS`).
    core_class : type, optional
        The core that implements it (default the paper's, ``COMPONENTS[component]``).
    n_beacons : int
        Beacons of the interface.
    """

    #: Steps a batch of replicates at once.
    batched = True

    def __init__(self, component: str, core_class: type | None = None, n_beacons: int = 4) -> None:
        self.component = component
        self.core_class = core_class or COMPONENTS[component]
        self.n_beacons = n_beacons
        declarations = self.core_class.variables(n_beacons)
        self.ports = [Port(v.name, v.causality, v.type, v.unit) for v in declarations]
        self.parameters = frozenset(v.name for v in declarations if v.causality == "parameter")
        self.core = None

    def setup(self, params: Mapping[str, Any], replicates: Sequence[int], t0: float = 0.0) -> None:
        """Create the core for a batch of replicates and initialize it at ``t0`` [s]."""
        self.core = self.core_class(params, replicates, self.n_beacons)
        self.core.initialize(t0)

    def set_inputs(self, values: Mapping[str, np.ndarray]) -> None:
        self.core.set_inputs(values)

    def do_step(self, t: float, h: float) -> None:
        self.core.step(t, h)

    def get_outputs(self) -> dict[str, np.ndarray]:
        return self.core.outputs

    def terminate(self) -> None:
        self.core = None


#: FMUs loaded in this process, by model identifier: (file signature, handle).
_LOADED: dict[str, tuple[tuple, "FmuHandle"]] = {}


def read_description(component: str, path: Path) -> Any:
    """The model description of an FMI 2.0 Co-Simulation FMU.

    Raises
    ------
    ModelError
        If the file is missing or unreadable, or not FMI 2.0 Co-Simulation.
    """
    from fmpy import read_model_description

    if not path.is_file():
        raise ModelError(f"fmu: {component} FMU not found at {str(path)!r}; build it with `sblsim fmus build`")
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises plain exceptions on unreadable archives
        raise ModelError(f"fmu: {str(path)!r} is not a readable FMU ({exc})") from None
    if md.fmiVersion != "2.0" or md.coSimulation is None:
        raise ModelError(f"fmu: {str(path)!r} must be an FMI 2.0 Co-Simulation FMU")
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


def open_fmu(component: str, path: Path | str) -> "FmuHandle":
    """The process's handle of an FMU, loaded and instantiated on first use.

    A pythonfmu FMU embeds its model in the host's Python interpreter, and
    loading a second copy of it in one process (a later run, or two
    instances) crashes the process (pythonfmu 0.7, cf. NTNU-IHB/PythonFMU#228).
    So each FMU is loaded once per process and re-used, reset between runs,
    as DESIGN.md asks ("instantiated once and reset between runs"); it is
    freed when the process ends.

    Raises
    ------
    ModelError
        If the file is missing or unreadable, if the FMU is in use by another
        run, or if another file with the same model identifier (or a rebuilt
        file) was already loaded in this process.
    """
    path = Path(path)
    md = read_description(component, path)
    stat = path.resolve().stat()
    signature = (str(path.resolve()), stat.st_size, stat.st_mtime_ns, md.guid)
    identifier = md.coSimulation.modelIdentifier
    if identifier in _LOADED:
        loaded_signature, handle = _LOADED[identifier]
        if loaded_signature != signature:
            raise ModelError(f"fmu: {identifier} is already loaded in this process from {loaded_signature[0]!r} "
                             "(a pythonfmu FMU loads once per process); use that file or a new process")
        if handle.in_use:
            raise ModelError(f"fmu: {identifier} is in use by another run in this process")
    else:
        handle = FmuHandle(component, path, md)
        _LOADED[identifier] = (signature, handle)
    handle.in_use = True
    return handle


class FmuHandle:
    """A component FMU stepped through fmpy (the interoperability path, B = 1).

    Create it with :func:`open_fmu`, which loads each FMU once per process.

    Parameters
    ----------
    component : str
        Component name used in connections.
    path : path
        The ``.fmu`` file.
    md : fmpy.model_description.ModelDescription
        Its model description.
    """

    #: Steps one replicate at a time.
    batched = False

    def __init__(self, component: str, path: Path, md: Any) -> None:
        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave

        self.component = component
        self.path = path
        self.variables = {v.name: v for v in md.modelVariables}
        self.ports = _ports(md)
        self.parameters = frozenset(v.name for v in md.modelVariables if v.causality == "parameter")
        self._unzipdir = extract(str(path))
        atexit.register(shutil.rmtree, self._unzipdir, ignore_errors=True)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=component)
        self.fmu.instantiate()
        self._fresh = True
        self.in_use = False
        self._outputs = {t: [(v.name, v.valueReference) for v in md.modelVariables
                             if v.causality == "output" and v.type == t] for t in ("Real", "Integer", "Boolean")}

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
        """
        if len(replicates) != 1:
            raise ModelError("engine: the fmu engine steps one replicate at a time (B = 1)")
        missing = [n for n in params if n not in self.variables]
        if missing:
            raise ModelError(f"fmu: {self.path.name} has no parameter {missing[0]!r}")
        if not self._fresh:
            self.fmu.reset()
        self._fresh = False
        self.fmu.setupExperiment(startTime=t0)
        self.fmu.enterInitializationMode()
        self._set({**params, "replicate": int(replicates[0])} if "replicate" in self.variables else params)
        self.fmu.exitInitializationMode()

    def set_inputs(self, values: Mapping[str, np.ndarray]) -> None:
        self._set(values)

    def do_step(self, t: float, h: float) -> None:
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def get_outputs(self) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for typ, items in self._outputs.items():
            if items:
                values = getattr(self.fmu, f"get{typ}")([vr for _, vr in items])
                out.update({name: np.array([val], dtype=_DTYPES[typ]) for (name, _), val in zip(items, values)})
        return out

    def terminate(self) -> None:
        """Release the handle for the next run; the instance stays loaded (see :func:`open_fmu`)."""
        self.in_use = False
