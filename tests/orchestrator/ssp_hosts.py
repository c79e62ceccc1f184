"""Run an SSP package in an independent FMI host and save the receiver's estimate.

    python ssp_hosts.py libcosim|ecos|fmpy FILE.ssp OUT.npz [COMPONENT.VARIABLE ...]

No sblsim code is imported: only the host (libcosimpy, the Open Simulation
Platform's libcosim; ecospy, the ecos C++ engine; or fmpy's SSP simulator)
and the standard library. Every component runs at the package's base step;
the saved arrays have one row per base step (the time at its end): ``time``,
the target's true position ``pos_*`` and the receiver's estimate ``est_*``, and
each further Real variable named on the command line (its name as the key).
"""

from __future__ import annotations

import sys
import zipfile
from xml.etree import ElementTree as ET

import numpy as np

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations"}
SIGNALS = {**{f"pos_{a}": ("target", f"pos_{a}") for a in "xyz"},
           **{f"est_{a}": ("receiver", f"est_{a}") for a in "xyz"}}


def experiment(ssp: str) -> tuple[float, float, str]:
    """Stop time, base step [s] and the name of the system's parameter set."""
    with zipfile.ZipFile(ssp) as archive:
        root = ET.fromstring(archive.read("SystemStructure.ssd"))
        binding = root.find(".//ssd:ParameterBinding", NS).get("source")
        name = ET.fromstring(archive.read(binding)).get("name")
    stop = float(root.find("ssd:DefaultExperiment", NS).get("stopTime"))
    base = float(root.find(".//osp:FixedStepAlgorithm", NS).get("baseStepSize"))
    return stop, base, name


def run_libcosim(ssp: str, signals: dict[str, tuple[str, str]] = SIGNALS) -> dict[str, np.ndarray]:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    stop, base, _ = experiment(ssp)
    execution = CosimExecution.from_ssp_file(ssp_path=ssp)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer=observer)
    slaves = {info.name.decode(): info.index for info in execution.slave_infos()}
    refs = {}
    for key, (component, variable) in signals.items():
        index = slaves[component]
        by_name = {v.name.decode(): v.reference for v in execution.slave_variables(slave_index=index)}
        refs[key] = (index, by_name[variable])
    n_steps = round(stop / base)
    out = {key: np.empty(n_steps) for key in signals}
    for k in range(n_steps):
        if not execution.step(step_count=1):
            raise RuntimeError(f"libcosim: step {k} failed")
        for key, (index, ref) in refs.items():
            out[key][k] = observer.last_real_values(slave_index=index, variable_references=[ref])[0]
    out["time"] = base * np.arange(1, n_steps + 1)
    return out


def run_ecos(ssp: str, signals: dict[str, tuple[str, str]] = SIGNALS) -> dict[str, np.ndarray]:
    import ctypes
    import os

    tbb = os.path.join(sys.prefix, "lib", "libtbb.so.12")  # the tbb package installs it into the environment
    if os.path.exists(tbb):
        ctypes.CDLL(tbb, mode=ctypes.RTLD_GLOBAL)
    from ecospy import EcosSimulation

    stop, base, name = experiment(ssp)
    n_steps = round(stop / base)
    out = {key: np.empty(n_steps) for key in signals}
    with EcosSimulation(step_size=base, ssp_path=ssp) as sim:
        if not sim.init(parameter_set=name):
            raise RuntimeError("ecos: initialization failed")
        for k in range(n_steps):
            sim.step()
            for key, (component, variable) in signals.items():
                out[key][k] = sim.get_real(f"{component}::{variable}")
        sim.terminate()
    out["time"] = base * np.arange(1, n_steps + 1)
    return out


def run_fmpy(ssp: str, signals: dict[str, tuple[str, str]] = SIGNALS) -> dict[str, np.ndarray]:
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import ParameterSet, read_ssd

    stop, base, _ = experiment(ssp)
    # simulate_ssp ignores the bindings and applies one parameter set with names "component.variable"
    parameters = ParameterSet(name="system")
    for component in read_ssd(ssp).system.elements:
        for binding in component.parameterBindings:
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    p.name = f"{component.name}.{p.name}"
                    parameters.parameters.append(p)
    # fmpy's loop runs while time < stop_time with time += step: stop half a step early
    result = simulate_ssp(ssp, stop_time=stop - base / 2, step_size=base, parameter_set=parameters)
    out = {key: np.asarray(result[f"{component}.{variable}"], float) for key, (component, variable) in signals.items()}
    out["time"] = np.asarray(result["time"], float) + base
    return out


if __name__ == "__main__":
    host, ssp, target = sys.argv[1:4]
    signals = {**SIGNALS, **{name: tuple(name.split(".", 1)) for name in sys.argv[4:]}}
    data = {"libcosim": run_libcosim, "ecos": run_ecos, "fmpy": run_fmpy}[host](ssp, signals)
    np.savez(target, **data)
