"""The system as an SSP 1.0 package for other FMI hosts: the package's layout, its export and its schema check.

An SSP archive (Modelica Association, *System Structure and Parameterization*
1.0, 2019) holds

* ``SystemStructure.ssd``: one ``Component`` per FMU with its connectors
  (type and unit), every connection of the scenario, the units, and a default
  experiment (start, stop);
* ``resources/sblsim_*.fmu``: the FMUs;
* ``resources/<component>.ssv``: the scenario's parameter values for that
  component, bound to it by a ``ParameterBinding`` of type
  ``application/x-ssp-parameter-set`` with the FMU's own variable names.
  Every set carries the same name (the system's), so they form **one
  parameter set for the whole system**: ecos applies it by that name,
  libcosim applies the first set of each component, OMSimulator every
  binding.

What the package avoids, because one of the hosts it was run in rejects it
(docs/interop.md lists the hosts): names that are not identifiers
(``[A-Za-z][A-Za-z0-9_]*``), String parameters (the FMUs have none: choices
are Integer indices, tables are Real arrays), and annotations on a component.
A configuration with ``receiver.latency`` > 0 is not exported: the
orchestrator delays the receiver's recorded outputs after a run, and an FMI
host stepping the package would show them undelayed (other numbers than
``sblsim run``).
Every component runs at one step, the base step ``T / ekf_rate_ratio``: the
FMUs sample and slot on their own clocks, so a finer step changes nothing but
the receiver's prediction rate. The step is given where each host reads it:
OMSimulator's ``oms:FixedStepMaster`` annotation on the system, the Open
Simulation Platform's ``osp:FixedStepAlgorithm`` on the default experiment
(libcosim), and ``step_size`` for ecos.

``export_ssp(..., fmi_version=3)`` (``sblsim ssp export --fmi-version 3``) packs the scenario's FMI 3.0 FMUs
instead, built for the package (SSP 1.0 has no array values: the arrays travel as the FMUs' start values), its
scalar parameters in the parameter sets and its connections array to array.

:func:`sblsim.orchestrator.cosim.ssp_read.read_ssp` reads a package back (components, connections, parameter
sets, experiment) into a resolved configuration.
"""

from __future__ import annotations

import os
import re
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence
from xml.etree import ElementTree as ET

from sblsim.fmus.arrays import element_positions, fmi3_variables
from sblsim.models.acoustics.channel.lanes import lane_of
from sblsim.models.declarations import UNITS
from sblsim.models.errors import ArchiveError
from sblsim.orchestrator.cosim.connections import Connection, default_connections
from sblsim.orchestrator.cosim.fmu_files import fmu_paths, read_description
from sblsim.orchestrator.cosim.plan import RunPlan, as_plan
from sblsim.orchestrator.cosim.scenario_fmus import build_scenario_fmus, check_no_latency

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd",
}
OSP_ANNOTATION = "com.opensimulationplatform"
OMS_ANNOTATION = "org.openmodelica"
PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
SSD_NAME = "SystemStructure.ssd"
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


class SspError(ArchiveError):
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


def _annotations(parent: ET.Element, kind: str, content: ET.Element) -> None:
    notes = ET.SubElement(parent, _q("ssd:Annotations"))
    note = ET.SubElement(notes, _q("ssc:Annotation"), type=kind)
    note.append(content)


def identifier(text: str) -> str:
    """``text`` as an identifier every SSP host accepts: ``[A-Za-z][A-Za-z0-9_]*``."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", text)
    return out if out[:1].isalpha() else f"s_{out}"


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
    (:data:`sblsim.models.declarations.UNITS`); a unit neither defines is left undefined."""
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
        if var.type == "String":
            raise SspError(f"ssp: {pname} is a String parameter, which OMSimulator cannot set from an SSP")
        p = ET.SubElement(plist, _q("ssv:Parameter"), name=pname)
        attrs = {"value": _text(value, var.type)}
        if var.type == "Real" and var.unit:
            attrs["unit"] = var.unit
            used.add(var.unit)
        ET.SubElement(p, _q(f"ssv:{var.type}"), attrs)
    _units(root, "ssv:Units", used, units)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


#: FMI 3.0 type -> the SSP 1.0 connector and parameter type.
_SSC_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "Real": "Real", "Integer": "Integer"}


@dataclass(frozen=True)
class _Typed:
    """A variable as the parameter sets need it: its SSP type and unit."""

    type: str
    unit: str | None


def export_ssp(cfg: RunPlan | dict, out: Path | str, fmu_dir: Path | str | None = None,
               connections: Sequence[Connection] | None = None, fmi_version: int = 2, compiler: str = "auto",
               report: Callable[[str], object] | None = None) -> Path:
    """Write a run's plan as an SSP 1.0 archive.

    Parameters
    ----------
    cfg : RunPlan or dict
        The run's plan (:func:`sblsim.orchestrator.cosim.plan.load_plan`; a configuration: its plan is made once).
    out : path
        The ``.ssp`` file to write (replaced atomically).
    fmu_dir : path, optional
        Directory of the built FMUs (default ``fmus/build``; FMI 2.0 only).
    connections : sequence of Connection, optional
        Default: the scenario's :func:`default_connections`.
    fmi_version : {2, 3}
        FMI 2.0 (default): the built FMUs and every parameter in the parameter sets. FMI 3.0: the scenario's
        FMI 3.0 FMUs, built for the package with its parameters as their start values
        (:func:`sblsim.orchestrator.cosim.scenario_fmus.build_scenario_fmus`: SSP 1.0 has no array values, so the
        arrays, e.g. ``beacon_offsets`` or a sound-speed table, travel in the FMUs), its scalar parameters in the
        parameter sets, and each connection between two arrays whole (``pos`` to ``target``,
        ``beacon_positions`` to ``beacon_positions``).
    compiler, report
        With FMI 3.0: as :func:`sblsim.fmus.build.build_fmu`.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ModelError
        If an FMU is missing, the written package fails the SSP schemas
        (then nothing is left on disk), or ``receiver.latency`` is not 0 (the
        orchestrator applies it after a run; an FMI host would not).
    CompileError
        FMI 3.0: if the compiler is missing or fails.
    """
    out = Path(out)
    if out.suffix != ".ssp":
        raise SspError(f"--out: {str(out)!r} must end in .ssp")
    plan = as_plan(cfg)
    check_no_latency(plan, "exported", SspError)
    n_beacons = plan.n_beacons
    connections = list(connections) if connections is not None else default_connections(n_beacons)
    with tempfile.TemporaryDirectory(prefix="sblsim_ssp_") as tmp:
        if fmi_version == 3:
            built = build_scenario_fmus(plan, tmp, compiler, report=report, fmi_version=3)
            paths = dict(zip(plan.sources, built))
            connections = _array_connections(plan, connections)
        else:
            paths = fmu_paths(fmu_dir, dict(plan.sources), n_beacons)
        _write_package(plan, paths, connections, out, fmi_version)
    return out


def _array_connections(plan: RunPlan, connections: Sequence[Connection]) -> list[Connection]:
    """The FMI 2.0 connections as connections of the FMI 3.0 variables (:mod:`sblsim.fmus.arrays`): the scalars
    of one array go whole, element by element, to one array of the same size.

    Raises
    ------
    SspError
        If a connection joins part of an array, or two arrays out of order (a connection FMI 3.0 cannot make).
    """
    where = {}  # (component, FMI 2.0 name) -> (FMI 3.0 variable, position)
    for component in plan.sources:
        scalars = plan.model(component).fmu_variables(plan.n_beacons)
        table = fmi3_variables(scalars, plan.n_beacons)
        where.update({(component, scalars[e].name): (table[vr], k) for e, (vr, k) in element_positions(table).items()})
    grouped: dict[tuple[str, str, str, str], list[tuple[int, int, int]]] = {}
    for c in connections:
        (source, k), (destination, j) = where[(c.source, c.output)], where[(c.destination, c.input)]
        grouped.setdefault((c.source, source.name, c.destination, destination.name), []).append(
            (k, j, source.size if source.size == destination.size else -1))
    out = []
    for (src, output, dst, input_), pairs in grouped.items():
        if len(pairs) != pairs[0][2] or any(k != j for k, j, _ in pairs):
            raise SspError(f"ssp: the connection {src}.{output} -> {dst}.{input_} joins part of an array; FMI 3.0 "
                           "connects arrays whole")
        out.append(Connection(src, output, dst, input_))
    return out


def _write_package(plan: RunPlan, paths: dict[str, Path], connections: Sequence[Connection], out: Path,
                   fmi_version: int) -> None:
    """The package's SystemStructure.ssd, parameter sets and FMUs, written to ``out`` atomically."""
    n_beacons = plan.n_beacons
    T, ratio = plan.sampling_time, plan.ekf_rate_ratio
    n_steps = plan.n_steps
    base = T / ratio
    name = identifier(plan.scenario)

    root = ET.Element(_q("ssd:SystemStructureDescription"), version="1.0", name=f"sblsim_{name}")
    system = ET.SubElement(root, _q("ssd:System"), name=name, description="sblsim SBL acoustic positioning system")
    elements = ET.SubElement(system, _q("ssd:Elements"))
    files: dict[str, bytes | Path] = {}
    inputs: dict[str, set[str]] = {}
    units: dict[str, Any] = {}
    used_units: set[str] = set()
    for component, path in paths.items():
        # a user's FMU too: its archive checked first
        md = read_description(component, Path(path), ("3.0",) if fmi_version == 3 else ("2.0",))
        units.update({u.name: _unit_definition(u) for u in md.unitDefinitions})
        variables = {v.name: v for v in md.modelVariables}
        source = f"resources/{path.name}"
        files[source] = path
        comp = ET.SubElement(elements, _q("ssd:Component"), name=component, source=source,
                             type="application/x-fmu-sharedlibrary")
        connectors = ET.SubElement(comp, _q("ssd:Connectors"))
        inputs[component] = {v.name for v in md.modelVariables if v.causality == "input"}
        for v in md.modelVariables:
            if v.causality not in ("input", "output"):
                continue
            kind = _SSC_TYPES.get(v.type, v.type)
            connector = ET.SubElement(connectors, _q("ssd:Connector"), name=v.name, kind=v.causality)
            ET.SubElement(connector, _q(f"ssc:{kind}"), {"unit": v.unit} if kind == "Real" and v.unit else {})
            if kind == "Real" and v.unit:
                used_units.add(v.unit)
        if fmi_version == 3:  # the scalar parameters (the arrays' values are the FMUs' start values)
            variables = {v.name: _Typed(_SSC_TYPES[v.type], v.unit) for v in md.modelVariables
                         if v.causality == "parameter" and not v.dimensions}
        accepted = frozenset(n for n, v in variables.items() if fmi_version == 3 or v.causality == "parameter")
        model = plan.model(component)
        params = plan.component_parameters(component, accepted)
        if model is not None:
            params = model.fmi_values(params, n_beacons)
        ssv = f"resources/{component}.ssv"
        files[ssv] = _parameter_set(name, params, variables, units)
        bindings = ET.SubElement(comp, _q("ssd:ParameterBindings"))
        ET.SubElement(bindings, _q("ssd:ParameterBinding"), type=PARAMETER_SET_TYPE, source=ssv)
    wires = ET.SubElement(system, _q("ssd:Connections"))
    for c in connections:
        if lane_of(c.input) and c.input not in inputs[c.destination]:
            continue  # a user's receiver without the later lanes of a delivery: lane 1 alone
        ET.SubElement(wires, _q("ssd:Connection"), startElement=c.source, startConnector=c.output,
                      endElement=c.destination, endConnector=c.input)
    info = ET.Element(_q("oms:Annotations"))
    ET.SubElement(ET.SubElement(info, _q("oms:SimulationInformation")), _q("oms:FixedStepMaster"),
                  description="oms-ma", stepSize=repr(base), relativeTolerance="0.0001")
    _annotations(system, OMS_ANNOTATION, info)
    _units(root, "ssd:Units", used_units, units)
    experiment = ET.SubElement(root, _q("ssd:DefaultExperiment"), startTime="0.0", stopTime=repr(n_steps * T))
    algorithm = ET.Element(_q("osp:Algorithm"))
    ET.SubElement(algorithm, _q("osp:FixedStepAlgorithm"), baseStepSize=repr(base))
    _annotations(experiment, OSP_ANNOTATION, algorithm)
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


__all__ = ["NS", "SSD_NAME", "SspError", "export_ssp", "validate_ssp"]
