"""The orchestrator's boundaries: the master algorithm knows handles only by their interface, the
configuration does not load code, and the model knows nothing of the orchestrator (tests/models)."""

import ast
from pathlib import Path

import sblsim.orchestrator.cosim
from sblsim.orchestrator.cosim import engines, fmu3_engine, fmu_engine, handles, local_engine

#: The co-simulation kernel's folder (orchestrator/cosim/): the master algorithm and the configuration.
COSIM = Path(sblsim.orchestrator.cosim.__file__).parent

#: The engines' modules: the choice of the engine, the handles' interface and one module per engine.
ENGINE_MODULES = (engines, handles, local_engine, fmu_engine, fmu3_engine)
#: The handle classes of the engines (the master must not know them).
HANDLE_CLASSES = {name for module in ENGINE_MODULES for name, value in vars(module).items()
                  if isinstance(value, type) and value.__module__ == module.__name__ and name.endswith("Handle")}


def _imports(path: Path) -> list[tuple[str, str | None]]:
    """Every import of a file, at any depth: (module, imported name or None)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            out += [(node.module, alias.name) for alias in node.names]
    return out


def test_the_handle_classes_are_found():
    assert {"LocalHandle", "FmuHandle", "ComponentHandle"} <= HANDLE_CLASSES


def test_the_master_imports_neither_the_fmi_layer_nor_handle_classes():
    imports = _imports(COSIM / "master.py")
    assert imports
    fmi = [m for m, _ in imports if m.split(".")[:2] == ["sblsim", "fmus"] or m.split(".")[0] in ("fmus", "fmpy")]
    assert fmi == []
    classes = [name for m, name in imports if m in {module.__name__ for module in ENGINE_MODULES}
               and name in HANDLE_CLASSES - {"ComponentHandle"}]
    assert classes == []


def test_the_configuration_loads_no_code():
    imports = _imports(COSIM / "config.py")
    assert not [m for m, _ in imports if m in ("importlib.util", "importlib.machinery", "runpy")]
    assert ("importlib", "util") not in imports
    text = (COSIM / "config.py").read_text()
    assert "spec_from_file_location" not in text and "exec_module" not in text


def test_the_configuration_computes_no_geometry():
    """The platform's beacon geometry is model code (models/platform/geometry.py)."""
    tree = ast.parse((COSIM / "config.py").read_text())
    defined = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert not defined & {"beacon_offsets", "beacon_arms", "beacon_arm", "platform_offsets", "lever_arms"}
