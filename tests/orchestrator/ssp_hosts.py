"""Run an SSP package in an independent FMI host and save the receiver's estimate.

    python ssp_hosts.py libcosim|fmpy FILE.ssp OUT.npz

No sblsim code is imported: only libcosimpy (the Open Simulation Platform's
libcosim) or fmpy's SSP simulator, and the standard library. The integration
tests run this in a subprocess, because a pythonfmu FMU can be loaded only
once per process. The saved arrays have one row per macro step (the time at
its end): ``time``, the target's true position ``pos_*`` and the receiver's
estimate ``est_*``.
"""

from __future__ import annotations

import sys
import zipfile
from xml.etree import ElementTree as ET

import numpy as np

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations"}
SIGNALS = {**{f"pos_{a}": ("target", f"pos_{a}") for a in "xyz"},
           **{f"est_{a}": ("receiver", f"est_{a}") for a in "xyz"}}


def experiment(ssp: str) -> tuple[float, float, float]:
    """Stop time, macro step (the platform's step hint) and base step of the package [s]."""
    with zipfile.ZipFile(ssp) as archive:
        root = ET.fromstring(archive.read("SystemStructure.ssd"))
    stop = float(root.find("ssd:DefaultExperiment", NS).get("stopTime"))
    base = float(root.find(".//osp:FixedStepAlgorithm", NS).get("baseStepSize"))
    macro = base
    for comp in root.findall("ssd:System/ssd:Elements/ssd:Component", NS):
        if comp.get("name") == "platform":
            macro = float(comp.find(".//osp:StepSizeHint", NS).get("value"))
    return stop, macro, base


def run_libcosim(ssp: str) -> dict[str, np.ndarray]:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    stop, macro, base = experiment(ssp)
    execution = CosimExecution.from_ssp_file(ssp_path=ssp)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer=observer)
    slaves = {info.name.decode(): info.index for info in execution.slave_infos()}
    refs = {}
    for key, (component, variable) in SIGNALS.items():
        index = slaves[component]
        by_name = {v.name.decode(): v.reference for v in execution.slave_variables(slave_index=index)}
        refs[key] = (index, by_name[variable])
    ratio = round(macro / base)
    n_steps = round(stop / macro)
    out = {key: np.empty(n_steps) for key in SIGNALS}
    for k in range(n_steps):
        if not execution.step(step_count=ratio):
            raise RuntimeError(f"libcosim: step {k} failed")
        for key, (index, ref) in refs.items():
            out[key][k] = observer.last_real_values(slave_index=index, variable_references=[ref])[0]
    out["time"] = macro * np.arange(1, n_steps + 1)
    return out


def run_fmpy(ssp: str) -> dict[str, np.ndarray]:
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import ParameterSet, read_ssd

    stop, macro, base = experiment(ssp)
    if macro != base:
        raise SystemExit("fmpy's simulate_ssp steps every component with one step size (no multi-rate)")
    # simulate_ssp applies one parameter set with names "component.variable"
    # and cannot set String variables: gather the bound sets, numbers only
    parameters = ParameterSet(name="system")
    for component in read_ssd(ssp).system.elements:
        for binding in component.parameterBindings:
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    if p.type != "String":
                        p.name = f"{component.name}.{p.name}"
                        parameters.parameters.append(p)
    # fmpy's loop runs while time < stop_time with time += step: stop half a step early
    result = simulate_ssp(ssp, stop_time=stop - macro / 2, step_size=macro, parameter_set=parameters)
    out = {key: np.asarray(result[f"{component}.{variable}"], float) for key, (component, variable) in SIGNALS.items()}
    out["time"] = np.asarray(result["time"], float) + macro
    return out


if __name__ == "__main__":
    host, ssp, target = sys.argv[1:4]
    data = {"libcosim": run_libcosim, "fmpy": run_fmpy}[host](ssp)
    np.savez(target, **data)
