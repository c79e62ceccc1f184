"""The system as an SSP 1.0 package: export for other FMI hosts, and read back.

An SSP archive (Modelica Association, *System Structure and Parameterization*
1.0, 2019) holds

* ``SystemStructure.ssd``: one ``Component`` per FMU with its connectors
  (type and unit), every connection of the scenario, the units, and a default
  experiment (start, stop) whose step is the Open Simulation Platform's
  ``FixedStepAlgorithm`` annotation (libcosim reads the step nowhere else);
  each component carries an OSP ``StepSizeHint`` (its communication step: T
  for the physics, T / EKF rate ratio for the receiver);
* ``resources/sblsim_*.fmu``: the FMUs;
* ``resources/<component>.ssv``: the scenario's parameter values, one
  parameter set per component, bound to it by a ``ParameterBinding`` whose
  parameter names are the FMU's variable names (no prefix). libcosim reads
  only component-level bindings and ignores a binding's ``prefix``, so this
  is the form both libcosim and fmpy's reader accept.

:func:`read_ssp` reads a package back (components, connections, parameter
sets, experiment) into a resolved configuration, the connections and the
package's FMU files, so ``sblsim run --ssp`` runs a system edited in another
SSP tool.
"""

from __future__ import annotations

import atexit
import math
import os
import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence
from xml.etree import ElementTree as ET

from models import COMPONENTS
from models.core import SEED_PARAMETERS, UNITS, ModelError
from orchestrator.config import (EXTERNAL_PREFIX, RECEIVERS, apply_overrides, component_params, resolve,
                                 section_variables)
from orchestrator.connections import Connection, default_connections
from orchestrator.run import beacon_count, fmu_paths, system_sources

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
OSP_ANNOTATION = "com.opensimulationplatform"
SSD_NAME = "SystemStructure.ssd"
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


class SspError(ModelError):
    """An SSP package that cannot be written or read; the message names the element."""


def _q(tag: str) -> str:
    prefix, name = tag.split(":")
    return f"{{{NS[prefix]}}}{name}"


def _text(value: Any, type_: str) -> str:
    if type_ == "Boolean":
        return "true" if value else "false"
    if type_ == "Real":
        return repr(float(value))
    if type_ == "Integer":
        return str(int(value))
    return str(value)


def _value(text: str, type_: str) -> Any:
    if type_ == "Boolean":
        return text.strip().lower() in ("true", "1")
    if type_ == "Real":
        return float(text)
    if type_ == "Integer":
        return int(text)
    return text


def _annotations(parent: ET.Element, content: ET.Element) -> None:
    notes = ET.SubElement(parent, _q("ssd:Annotations"))
    note = ET.SubElement(notes, _q("ssc:Annotation"), type=OSP_ANNOTATION)
    note.append(content)


_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def _unit_definition(unit: Any) -> dict[str, str]:
    """``ssc:BaseUnit`` attributes of an FMU's unit definition."""
    base = unit.baseUnit
    if base is None:
        return {}
    attrs = {k: str(getattr(base, k)) for k in _BASE if getattr(base, k, 0)}
    if base.factor != 1.0:
        attrs["factor"] = repr(float(base.factor))
    if base.offset != 0.0:
        attrs["offset"] = repr(float(base.offset))
    return attrs


def _units(parent: ET.Element, tag: str, names: set[str], definitions: dict[str, dict[str, str]]) -> None:
    """A ``Units`` element defining ``names``: from the FMUs' definitions, else sblsim's table
    (:data:`models.core.UNITS`); a unit neither defines is left undefined."""
    known = [n for n in sorted(names) if n in definitions or n in UNITS]
    if not known:
        return
    units = ET.SubElement(parent, _q(tag))
    for name in known:
        if name in definitions:
            attrs = definitions[name]
        else:
            exponents, factor = UNITS[name]
            attrs = {k: str(e) for k, e in exponents.items()}
            if factor != 1.0:
                attrs["factor"] = repr(float(factor))
        ET.SubElement(ET.SubElement(units, _q("ssc:Unit"), name=name), _q("ssc:BaseUnit"), attrs)


def _parameter_set(name: str, params: dict[str, Any], variables: dict[str, Any],
                   units: dict[str, dict[str, str]]) -> bytes:
    root = ET.Element(_q("ssv:ParameterSet"), version="1.0", name=name)
    plist = ET.SubElement(root, _q("ssv:Parameters"))
    used = set()
    for pname, value in params.items():
        var = variables[pname]
        p = ET.SubElement(plist, _q("ssv:Parameter"), name=pname)
        attrs = {"value": _text(value, var.type)}
        if var.type == "Real" and var.unit:
            attrs["unit"] = var.unit
            used.add(var.unit)
        ET.SubElement(p, _q(f"ssv:{var.type}"), attrs)
    _units(root, "ssv:Units", used, units)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def export_ssp(cfg: dict, out: Path | str, fmu_dir: Path | str | None = None,
               connections: Sequence[Connection] | None = None) -> Path:
    """Write a resolved configuration as an SSP 1.0 archive.

    Parameters
    ----------
    cfg : dict
        Resolved configuration (:func:`orchestrator.config.load_config`).
    out : path
        The ``.ssp`` file to write (replaced atomically).
    fmu_dir : path, optional
        Directory of the built FMUs (default ``fmus/build``).
    connections : sequence of Connection, optional
        Default: the scenario's :func:`default_connections`.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ModelError
        If an FMU is missing, or the written package fails the SSP schemas
        (then nothing is left on disk).
    """
    from fmpy import read_model_description

    out = Path(out)
    if out.suffix != ".ssp":
        raise SspError(f"--out: {str(out)!r} must end in .ssp")
    n_beacons = beacon_count(cfg)
    connections = list(connections) if connections is not None else default_connections(n_beacons)
    paths = fmu_paths(fmu_dir, system_sources(cfg))
    sim = cfg["simulation"]
    T, ratio = sim["sampling_time"], sim["ekf_rate_ratio"]
    n_steps = int(math.floor(sim["duration"] / T + 1e-9))
    steps = {name: T / ratio if name == "receiver" else T for name in paths}

    root = ET.Element(_q("ssd:SystemStructureDescription"), version="1.0", name=f"sblsim {cfg['run']['scenario']}")
    system = ET.SubElement(root, _q("ssd:System"), name=cfg["run"]["scenario"],
                           description="sblsim SBL acoustic positioning system")
    elements = ET.SubElement(system, _q("ssd:Elements"))
    files: dict[str, bytes | Path] = {}
    units: dict[str, Any] = {}
    used_units: set[str] = set()
    for name, path in paths.items():
        md = read_model_description(str(path), validate=False)
        units.update({u.name: _unit_definition(u) for u in md.unitDefinitions})
        variables = {v.name: v for v in md.modelVariables}
        source = f"resources/{path.name}"
        files[source] = path
        comp = ET.SubElement(elements, _q("ssd:Component"), name=name, source=source,
                             type="application/x-fmu-sharedlibrary")
        connectors = ET.SubElement(comp, _q("ssd:Connectors"))
        for v in md.modelVariables:
            if v.causality not in ("input", "output"):
                continue
            connector = ET.SubElement(connectors, _q("ssd:Connector"), name=v.name, kind=v.causality)
            ET.SubElement(connector, _q(f"ssc:{v.type}"), {"unit": v.unit} if v.type == "Real" and v.unit else {})
            if v.type == "Real" and v.unit:
                used_units.add(v.unit)
        accepted = frozenset(n for n, v in variables.items() if v.causality == "parameter")
        params = component_params(cfg, name, accepted)
        ssv = f"resources/{name}.ssv"
        files[ssv] = _parameter_set(name, params, variables, units)
        bindings = ET.SubElement(comp, _q("ssd:ParameterBindings"))
        ET.SubElement(bindings, _q("ssd:ParameterBinding"), source=ssv)
        _annotations(comp, ET.Element(_q("osp:StepSizeHint"), value=repr(steps[name])))
    wires = ET.SubElement(system, _q("ssd:Connections"))
    for c in connections:
        ET.SubElement(wires, _q("ssd:Connection"), startElement=c.source, startConnector=c.output,
                      endElement=c.destination, endConnector=c.input)
    _units(root, "ssd:Units", used_units, units)
    experiment = ET.SubElement(root, _q("ssd:DefaultExperiment"), startTime="0.0", stopTime=repr(n_steps * T))
    algorithm = ET.Element(_q("osp:Algorithm"))
    ET.SubElement(algorithm, _q("osp:FixedStepAlgorithm"), baseStepSize=repr(min(steps.values())))
    _annotations(experiment, algorithm)
    ET.indent(root)
    files[SSD_NAME] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)

    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
            for arcname, content in files.items():
                if isinstance(content, Path):
                    archive.write(content, arcname)
                else:
                    archive.writestr(arcname, content)
        validate_ssp(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return out


def validate_ssp(path: Path | str) -> Any:
    """Read an SSP archive with fmpy, validating the ``.ssd`` and every ``.ssv`` against the SSP 1.0 schemas.

    Returns
    -------
    fmpy.ssp.ssd.SystemStructureDescription

    Raises
    ------
    SspError
        If the archive is unreadable or a file does not validate (fmpy's message).
    """
    from fmpy.ssp.ssd import read_ssd

    try:
        return read_ssd(str(path), validate=True)
    except Exception as exc:  # fmpy raises plain Exception on schema errors
        first = str(exc).splitlines()
        raise SspError(f"ssp: {Path(path).name} is not a valid SSP 1.0 package: "
                       + " ".join(line.strip() for line in first[:3])) from None


@dataclass
class SspSystem:
    """A system read from an SSP package.

    Attributes
    ----------
    config : dict
        Resolved configuration (parameter sets, experiment, overrides).
    connections : list of Connection
    fmu_files : dict
        Component -> its FMU extracted from the package.
    """

    config: dict
    connections: list[Connection]
    fmu_files: dict[str, Path]


def _experiment(ssd_xml: bytes) -> tuple[float, float | None, float | None, dict[str, float]]:
    """Start, stop, base step and per-component step hints from the ``.ssd`` text."""
    root = ET.fromstring(ssd_xml)
    start, stop, base = 0.0, None, None
    experiment = root.find("ssd:DefaultExperiment", NS)
    if experiment is not None:
        start = float(experiment.get("startTime", 0.0))
        stop = float(experiment.get("stopTime")) if experiment.get("stopTime") is not None else None
        fixed = experiment.find(".//osp:FixedStepAlgorithm", NS)
        if fixed is not None:
            base = float(fixed.get("baseStepSize"))
    hints = {}
    for comp in root.findall("ssd:System/ssd:Elements/ssd:Component", NS):
        hint = comp.find(".//osp:StepSizeHint", NS)
        if hint is not None:
            hints[comp.get("name")] = float(hint.get("value"))
    return start, stop, base, hints


def read_ssp(path: Path | str, overrides: Iterable[str] = (), seed: int | None = None) -> SspSystem:
    """Read an SSP package back into a configuration, its connections and its FMUs.

    The package's components must be named ``platform``, ``acoustics``,
    ``target`` and ``receiver``; each one's parameter set fills that section
    of the configuration (the seed keys fill ``run``). The sampling time is
    the physics components' step hint (else the base step), the EKF rate
    ratio is T over the receiver's step, the duration is stop − start. A
    receiver FMU other than sblsim's EKF or least-squares receiver becomes
    ``receiver = "fmu:PATH"``; of its parameter set, the keys of sblsim's
    ``[receiver]`` section are kept and its own other parameters keep their
    FMU start values.

    Parameters
    ----------
    path : path
        The ``.ssp`` archive.
    overrides, seed
        As for :func:`orchestrator.config.load_config` (e.g. ``master=jacobi``).

    Raises
    ------
    SspError, ModelError
        Invalid package, unknown component, or parameter values outside
        their allowed range.
    """
    from fmpy import read_model_description

    path = Path(path)
    if not path.is_file():
        raise SspError(f"--ssp: no such file {str(path)!r}")
    ssd = validate_ssp(path)
    system = ssd.system
    names = [c.name for c in system.elements]
    if sorted(names) != sorted(COMPONENTS):
        raise SspError(f"ssp: components {', '.join(names)}; sblsim runs exactly {', '.join(COMPONENTS)}")
    unzipdir = Path(tempfile.mkdtemp(prefix="sblsim_ssp_"))
    atexit.register(shutil.rmtree, unzipdir, ignore_errors=True)
    with zipfile.ZipFile(path) as archive:
        archive.extractall(unzipdir)
        start, stop, base, hints = _experiment(archive.read(SSD_NAME))

    seed_names = {v.name for v in SEED_PARAMETERS}
    raw: dict[str, dict] = {"run": {"scenario": system.name}, "simulation": {}}
    fmu_files: dict[str, Path] = {}
    for comp in system.elements:
        fmu_files[comp.name] = unzipdir / comp.source
        section = raw.setdefault(comp.name, {})
        for binding in comp.parameterBindings:
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    target = raw["run"] if p.name in seed_names else section
                    target[p.name] = _value(p.value, p.type)
    identifier = read_model_description(str(fmu_files["receiver"]), validate=False).coSimulation.modelIdentifier
    builtin = {f"sblsim_{core}": key for key, core in RECEIVERS.items()}
    raw["simulation"]["receiver"] = builtin.get(identifier, f"{EXTERNAL_PREFIX}{fmu_files['receiver']}")
    if identifier not in builtin:  # a user's receiver: keep the keys sblsim's receiver section knows
        known = {v.name for v in section_variables("receiver")}
        raw["receiver"] = {k: v for k, v in raw["receiver"].items() if k in known}
    T = hints.get("platform", base)
    if T is None:
        raise SspError("ssp: no step size (osp:StepSizeHint of the platform or osp:FixedStepAlgorithm baseStepSize)")
    raw["simulation"]["sampling_time"] = T
    raw["simulation"]["ekf_rate_ratio"] = max(1, round(T / hints.get("receiver", base or T)))
    if stop is not None:
        raw["simulation"]["duration"] = stop - start
    if start != 0.0:
        raise SspError(f"ssp: DefaultExperiment startTime {start} s; sblsim starts at 0 s")
    connections = [Connection(c.startElement, c.startConnector, c.endElement, c.endConnector)
                   for c in system.connections]
    if any(c.source is None or c.destination is None for c in connections):
        raise SspError("ssp: connections to the system's own connectors are not supported")
    return SspSystem(resolve(apply_overrides(raw, overrides, seed)), connections, fmu_files)


__all__ = ["SspError", "SspSystem", "export_ssp", "read_ssp", "validate_ssp"]
