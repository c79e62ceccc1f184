"""Component handles: the two engines behind one master algorithm, and the choice of the engine per component.

Every handle follows one interface, :class:`~sblsim.orchestrator.cosim.handles.ComponentHandle` (``setup``,
``set_input_vector``, ``do_step``, ``output_vector``, ``terminate``,
``native_batch``; ``set_inputs`` and ``get_outputs`` by name for
convenience), names its inputs and outputs (``input_names``,
``output_names``: the order of those vectors) and exposes its variables as
``ports`` for the connection checks; :func:`make_handles` makes one per
component of a system:

* :class:`~sblsim.orchestrator.cosim.local_engine.LocalHandle` steps a model's generated C in-process, batched over
  replicates (:class:`sblsim.fmus.native.NativeBatch`: one call per component and
  step for the whole batch; :mod:`sblsim.orchestrator.cosim.local_engine`);
* :class:`~sblsim.orchestrator.cosim.fmu_engine.FmuHandle` steps a real FMU through fmpy (B = 1), instantiated once
  per process and reset between runs (:func:`open_fmu`; :mod:`sblsim.orchestrator.cosim.fmu_engine`);
  :class:`~sblsim.orchestrator.cosim.fmu3_engine.Fmu3Handle` an sblsim FMI 3.0 FMU, its arrays seen as the
  FMI 2.0 scalars (:mod:`sblsim.orchestrator.cosim.fmu3_engine`). Where each FMU file is and its model description:
  :mod:`sblsim.orchestrator.cosim.fmu_files`.

The two run the same generated code and runtime, so they give the same numbers.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

from sblsim.models import COMPONENTS, MODELS
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.connections import check_interface
from sblsim.orchestrator.cosim.fmu3_engine import Fmu3Handle
from sblsim.orchestrator.cosim.fmu_engine import FmuHandle
from sblsim.orchestrator.cosim.fmu_files import FMU_BEACONS, _description, fmu_paths, fmu_ports
from sblsim.orchestrator.cosim.handles import ComponentHandle, Source, paper_sources, source_model
from sblsim.orchestrator.cosim.local_engine import LocalHandle

#: The engines of :func:`make_handles`.
ENGINES = ("local", "fmu")
#: FMU instances made in this process, by file: (file signature, handles).
_LOADED: dict[str, tuple[tuple, list["FmuHandle"]]] = {}


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
        needs it: its arrays are read as the model's FMI 2.0 scalars,
        :class:`~sblsim.orchestrator.cosim.fmu3_engine.Fmu3Handle`).
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
        default :func:`~sblsim.orchestrator.cosim.handles.paper_sources`). A user's FMU is loaded on either engine and
        checked against the
        component's interface.
    fmu_files : dict, optional
        Component -> FMU file, overriding ``fmu_dir`` (an SSP package's FMUs).
    fmi_version : {2, 3}
        The fmu engine's FMUs of sblsim's models: FMI 2.0 or 3.0
        (:class:`~sblsim.orchestrator.cosim.fmu3_engine.Fmu3Handle`; the same numbers).
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
