"""Read an SSP 1.0 package back: its components, connections, parameter sets and default experiment into a
resolved configuration, the connections and the package's FMU files (:func:`read_ssp`), so ``sblsim run --ssp``
runs a system edited in another SSP tool.

The package's layout (Modelica Association, *System Structure and Parameterization* 1.0, 2019) and its export are
:mod:`sblsim.orchestrator.cosim.ssp`'s.
"""

from __future__ import annotations

import atexit
import re
import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable
from xml.etree import ElementTree as ET

from sblsim.models import COMPONENTS, RECEIVERS
from sblsim.models.declarations import SEED_NAMES
from sblsim.orchestrator.cosim.config import (
    EXTERNAL_PREFIX,
    apply_overrides,
    named_files,
    section_variables,
)
from sblsim.orchestrator.cosim.connections import Connection
from sblsim.orchestrator.cosim.fmu_files import read_description
from sblsim.orchestrator.cosim.plan import RunPlan, make_plan
from sblsim.orchestrator.cosim.ssp import NS, SSD_NAME, SspError, validate_ssp
from sblsim.orchestrator.io.archives import check_members, inside, safe_extract


def _value(text: str, type_: str) -> Any:
    if type_ == "Boolean":
        return text.strip().lower() in ("true", "1")
    if type_ == "Real":
        return float(text)
    if type_ == "Integer":
        return int(text)
    return text


@dataclass
class SspSystem:
    """A system read from an SSP package.

    Attributes
    ----------
    config : RunPlan
        The plan of the configuration (parameter sets, experiment, overrides), resolved once.
    connections : list of Connection
    fmu_files : dict
        Component -> its FMU extracted from the package.
    """

    config: RunPlan
    connections: list[Connection]
    fmu_files: dict[str, Path]


def _experiment(ssd_xml: bytes) -> tuple[float, float | None, float | None]:
    """Start, stop and base step of the ``.ssd`` (the OSP or OMSimulator annotation)."""
    root = ET.fromstring(ssd_xml)
    start, stop, base = 0.0, None, None
    experiment = root.find("ssd:DefaultExperiment", NS)
    if experiment is not None:
        start = float(experiment.get("startTime", 0.0))
        stop = float(experiment.get("stopTime")) if experiment.get("stopTime") is not None else None
        fixed = experiment.find(".//osp:FixedStepAlgorithm", NS)
        if fixed is not None:
            base = float(fixed.get("baseStepSize"))
    if base is None:
        master = root.find(".//oms:FixedStepMaster", NS)
        if master is not None:
            base = float(master.get("stepSize"))
    return start, stop, base


def read_ssp(path: Path | str, overrides: Iterable[str] = (), seed: int | None = None) -> SspSystem:
    """Read an SSP package back into a configuration, its connections and its FMUs.

    The package's components must be named ``platform``, ``acoustics``,
    ``target`` and ``receiver``; each one's parameter set fills that section
    of the configuration (the seed keys fill ``run``; choices, tables and
    custom offsets are turned back into configuration text). The sampling time
    is the channel's ``slot_period``, the EKF rate ratio is T over the base
    step, the duration is stop − start. A receiver FMU other than sblsim's
    EKF or least-squares receiver becomes ``receiver = "fmu:PATH"``; of its
    parameter set, the keys of sblsim's ``[receiver]`` section are kept. A
    parameter value naming a file (in a key declared to take one,
    :func:`sblsim.orchestrator.cosim.config.named_files`) is refused: a
    package names no file sblsim opens.

    Parameters
    ----------
    path : path
        The ``.ssp`` archive.
    overrides, seed
        As for :func:`sblsim.orchestrator.cosim.config.load_config` (e.g. ``master=jacobi``).

    Raises
    ------
    SspError, ModelError
        Invalid package, unknown component, a missing FMU, or parameter values
        outside their allowed range.
    """
    path = Path(path)
    if path.is_dir():
        raise SspError(f"--ssp: {str(path)!r} is a directory, not an .ssp file")
    if not path.is_file():
        raise SspError(f"--ssp: no such file {str(path)!r}")
    label = f"--ssp: {path.name}"
    try:  # refuse a hostile archive before fmpy reads anything of it
        with zipfile.ZipFile(path) as archive:
            check_members(archive, label)
    except zipfile.BadZipFile:
        raise SspError(f"{label} is not a zip archive (an SSP package is one)") from None
    ssd = validate_ssp(path)
    system = ssd.system
    names = [c.name for c in system.elements]
    if sorted(names) != sorted(COMPONENTS):
        raise SspError(f"ssp: components {', '.join(names)}; sblsim runs exactly {', '.join(COMPONENTS)}")
    unzipdir = Path(tempfile.mkdtemp(prefix="sblsim_ssp_"))
    atexit.register(shutil.rmtree, unzipdir, ignore_errors=True)
    safe_extract(path, unzipdir, label)
    start, stop, base = _experiment((unzipdir / SSD_NAME).read_bytes())

    raw: dict[str, dict] = {"run": {"scenario": system.name}, "simulation": {}}
    fmu_files: dict[str, Path] = {}
    values: dict[str, dict[str, Any]] = {}
    for comp in system.elements:
        fmu = inside(unzipdir, comp.source or "")
        if fmu is None:
            raise SspError(f"ssp: component {comp.name}: source {comp.source!r} is not a file inside the package")
        fmu_files[comp.name] = fmu
        if not fmu.is_file():
            raise SspError(f"ssp: component {comp.name}: no FMU {comp.source!r} in the package")
        found = values.setdefault(comp.name, {})
        for binding in comp.parameterBindings:
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    found[p.name] = _value(p.value, p.type)
    platform_md = read_description("platform", fmu_files["platform"])
    n_beacons = sum(1 for v in platform_md.modelVariables if re.fullmatch(r"beacon\d+_x", v.name))
    identifier_ = read_description("receiver", fmu_files["receiver"]).coSimulation.modelIdentifier
    builtin = {f"sblsim_{model}": key for key, model in RECEIVERS.items()}
    raw["simulation"]["receiver"] = builtin.get(identifier_, f"{EXTERNAL_PREFIX}{fmu_files['receiver']}")
    for comp, found in values.items():
        raw["run"].update({k: v for k, v in found.items() if k in SEED_NAMES})
        model = COMPONENTS[comp] if comp != "receiver" or identifier_ in builtin else None
        if model is None:  # a user's receiver: keep the keys sblsim's receiver section knows
            known = {v.name for v in section_variables("receiver")}
            raw[comp] = {k: v for k, v in found.items() if k in known}
        else:
            known = {v.name for v in section_variables(comp)}
            raw[comp] = {k: v for k, v in model.config_values(found, n_beacons).items() if k in known}
    T = values["acoustics"].get("slot_period", base)
    if T is None:
        raise SspError("ssp: no sampling time (the channel's slot_period, or a base step annotation)")
    raw["simulation"]["sampling_time"] = T
    raw["simulation"]["ekf_rate_ratio"] = max(1, round(T / (base or T)))
    if stop is not None:
        raw["simulation"]["duration"] = stop - start
    if start != 0.0:
        raise SspError(f"ssp: DefaultExperiment startTime {start} s; sblsim starts at 0 s")
    for section, key, named in named_files(raw):  # a package's parameters are data: they never name a file we open
        if (section, key) != ("simulation", "receiver"):  # the package's own receiver FMU, extracted above
            raise SspError(f"ssp: component {section}'s parameter {key} names a file ({named[:80]!r}), which a "
                           "package may not; sblsim reads no file an SSP package names")
    connections = [Connection(c.startElement, c.startConnector, c.endElement, c.endConnector)
                   for c in system.connections]
    if any(c.source is None or c.destination is None for c in connections):
        raise SspError("ssp: connections to the system's own connectors are not supported")
    return SspSystem(make_plan(apply_overrides(raw, overrides, seed)), connections, fmu_files)


__all__ = ["SspSystem", "read_ssp"]
