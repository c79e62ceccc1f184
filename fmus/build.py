"""Build and validate the four FMI 2.0 Co-Simulation FMUs with pythonfmu.

pythonfmu writes the model description from the registered variables but
knows nothing of units and leaves out ``ModelStructure/InitialUnknowns``; the
build completes the description from the same core declarations: a
``UnitDefinitions`` section, the unit (and range) of every variable, and the
initial unknowns, so that each FMU validates with zero problems.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from models import CORES
from models.core import UNITS, Variable

HERE = Path(__file__).resolve().parent
MODELS_DIR = HERE.parent / "models"
#: Where ``sblsim fmus build`` writes and the ``fmu`` engine looks by default.
DEFAULT_DIR = Path(os.environ.get("SBLSIM_FMU_DIR", HERE / "build"))


def fmu_path(directory: Path | str, component: str) -> Path:
    """Path of a component's FMU in a directory: ``DIR/sblsim_<component>.fmu``."""
    return Path(directory) / f"sblsim_{component}.fmu"


def _format(value: float) -> str:
    return f"{value:.16g}"


def complete_model_description(xml: bytes, declarations: tuple[Variable, ...]) -> bytes:
    """Add units, ranges, initial unknowns and a default experiment to a pythonfmu description.

    Parameters
    ----------
    xml : bytes
        ``modelDescription.xml`` as written by pythonfmu.
    declarations : tuple of Variable
        The core's declarations (the single source of the interface).

    Returns
    -------
    bytes
        The completed model description.

    Raises
    ------
    ValueError
        If the description's variables differ from the declarations.
    """
    root = ET.fromstring(xml)
    by_name = {v.name: v for v in declarations}
    model_vars = root.find("ModelVariables")
    names = [sv.get("name") for sv in model_vars]
    if names != [v.name for v in declarations]:
        raise ValueError("the FMU's variables differ from the core declarations")
    root.find("CoSimulation").set("needsExecutionTool", "false")

    used = sorted({v.unit for v in declarations if v.type == "Real"})
    units = ET.Element("UnitDefinitions")
    for name in used:
        exponents, factor = UNITS[name]
        unit = ET.SubElement(units, "Unit", name=name)
        base = {k: str(e) for k, e in exponents.items()}
        if factor != 1.0:
            base["factor"] = _format(factor)
        ET.SubElement(unit, "BaseUnit", base)
    children = list(root)
    root.insert(children.index(root.find("CoSimulation")) + 1, units)

    if root.find("DefaultExperiment") is None:
        experiment = ET.Element("DefaultExperiment", startTime="0", stepSize="0.1")
        root.insert(list(root).index(model_vars), experiment)

    for sv in model_vars:
        var = by_name[sv.get("name")]
        typed = sv[0]
        if var.type == "Real":
            typed.set("unit", var.unit)
        if var.type in ("Real", "Integer") and var.causality != "output":
            if var.min is not None:
                typed.set("min", _format(var.min) if var.type == "Real" else str(int(var.min)))
            if var.max is not None:
                typed.set("max", _format(var.max) if var.type == "Real" else str(int(var.max)))

    structure = root.find("ModelStructure")
    outputs = structure.find("Outputs")
    if structure.find("InitialUnknowns") is None and outputs is not None:
        initial = ET.SubElement(structure, "InitialUnknowns")
        for unknown in outputs:
            ET.SubElement(initial, "Unknown", index=unknown.get("index"))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_fmu(component: str, out_dir: Path | str, n_beacons: int = 4) -> Path:
    """Build one component's FMU into ``out_dir``.

    Parameters
    ----------
    component : str
        A core name: ``platform``, ``acoustics``, ``target``, ``receiver`` or ``receiver_lsq``.
    out_dir : path
        Destination directory (created if missing).
    n_beacons : int
        Beacons of the interface; only 4 is built by default.

    Returns
    -------
    Path
        The written ``.fmu`` file (replaced atomically).
    """
    from pythonfmu import FmuBuilder

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    script = HERE / f"sblsim_{component}.py"
    target = fmu_path(out_dir, component)
    with tempfile.TemporaryDirectory(prefix="sblsim_fmu_") as tmp:
        # FMU state get/set is supported (CoreSlave deep-copies the core); serialization is not. A
        # pythonfmu FMU loads once per process (NTNU-IHB/PythonFMU#228): declared, and one instance each.
        built = Path(FmuBuilder.build_FMU(script, dest=tmp, project_files=[MODELS_DIR, HERE / "sblsim_slave.py"],
                                          canGetAndSetFMUstate=True, canSerializeFMUstate=False,
                                          canBeInstantiatedOnlyOncePerProcess=True))
        declarations = CORES[component].variables(n_beacons)
        partial = out_dir / f".{target.name}.partial"
        with zipfile.ZipFile(built) as src, zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as dst:
            for item in src.infolist():
                if "__pycache__" in item.filename:
                    continue
                data = src.read(item.filename)
                if item.filename == "modelDescription.xml":
                    data = complete_model_description(data, declarations)
                dst.writestr(item.filename, data)
        os.replace(partial, target)
    return target


def build_all(out_dir: Path | str = DEFAULT_DIR) -> list[Path]:
    """Build every FMU into ``out_dir`` (the four components and the least-squares receiver); returns their paths."""
    return [build_fmu(name, out_dir) for name in CORES]


def validate(path: Path | str) -> list[str]:
    """fmpy's validation problems of one FMU (empty list: valid)."""
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(path)))


__all__ = ["DEFAULT_DIR", "build_all", "build_fmu", "complete_model_description", "fmu_path", "validate"]
