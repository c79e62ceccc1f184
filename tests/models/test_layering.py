"""models/ is the pure numeric core: it never imports the FMI layer or the orchestrator."""

import ast
from pathlib import Path

import numpy as np

import sblsim.models

FORBIDDEN = ("orchestrator", "fmus", "fmpy", "pythonfmu", "sblsim_slave")


def _top(module: str) -> str:
    """The first name of a module path, below the ``sblsim`` namespace (``sblsim.fmus.build`` -> ``fmus``)."""
    parts = module.split(".")
    return parts[1] if parts[0] == "sblsim" and len(parts) > 1 else parts[0]


def _imported_modules(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(_top(alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(_top(node.module))
    return names


def test_models_do_not_import_fmi_or_orchestrator():
    files = sorted(Path(sblsim.models.__file__).parent.rglob("*.py"))
    assert len(files) >= 10
    offenders = {str(f): sorted(_imported_modules(f) & set(FORBIDDEN)) for f in files}
    assert {f: m for f, m in offenders.items() if m} == {}


def test_the_platform_geometry_is_in_the_model():
    """The beacon geometry of a configuration's platform section lives in models/platform/geometry.py."""
    from sblsim.models.platform import geometry

    platform = {"layout": "cross", "baseline": 2.0, "transducer_depth": 1.5, "beacon_offsets": "",
                "heading_deg": 90.0}
    assert geometry.platform_offsets(platform).shape == (4, 3)
    assert geometry.largest_arm(platform) == np.hypot(2.0, 1.5)
    np.testing.assert_allclose(geometry.lever_arms(platform)[0], [0.0, 2.0, 1.5], atol=1e-12)
