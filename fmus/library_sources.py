"""The sources of the local engine's compiled library: the models' generated C, the runtime, the registry of the
models, the bound, the eigenray and layout entry points and the batch API, written into one folder
(:func:`write_library_sources`); :mod:`sblsim.fmus.native` compiles them into the library.
"""

from __future__ import annotations

from pathlib import Path

import casadi as ca

from sblsim.fmus.codegen import BATCH, C_DIR, METRICS, stem, write_runtime, write_sources
from sblsim.models import MODELS
from sblsim.models.acoustics.detection import family_levels
from sblsim.models.acoustics.ray_tables import exact_points, family_points
from sblsim.models.bound import bound_step
from sblsim.models.design.information import SLOTS, layout_information
from sblsim.models.systems import interface_system

#: Exports the eigenray solve's casadi entry points from the library (built with hidden symbols).
RAY_EXPORT = """#if defined(_WIN32)
#define CASADI_SYMBOL_EXPORT __declspec(dllexport)
#else
#define CASADI_SYMBOL_EXPORT __attribute__((visibility("default")))
#endif
"""
#: The compiled loop of a system's own bound (the library of that system's interface only).
SYSTEM_BOUND = "sblsim_system_bound.c"
#: The points one call of a compiled layout function evaluates (:func:`layout_functions`).
LAYOUT_CHUNK = 64


def layout_functions() -> list[ca.Function]:
    """The design's layout information (:func:`sblsim.models.design.information.layout_information`) of each slot
    count (:data:`~sblsim.models.design.information.SLOTS`), mapped over :data:`LAYOUT_CHUNK` points that share the
    layout (the transducers, their lever arms, the attitude and depth variances): ``sblsim_layout_S``, what the
    library exports for the design's search (:func:`~sblsim.fmus.compiled_functions.compiled_layout`)."""
    return [layout_information(slots).map(f"sblsim_layout_{slots}", "serial", LAYOUT_CHUNK, [1, 2, 5, 6], [])
            for slots in SLOTS]



def _registry(n_beacons: int, models: tuple[type, ...]) -> str:
    symbols = [f"{stem(model, n_beacons)}_model" for model in models]
    lines = ['#include <stddef.h>', '#include "sblsim_runtime.h"']
    lines += [f"extern const sblsim_model {s};" for s in symbols]
    lines.append("const sblsim_model* const sblsim_models[] = {" + "".join(f"&{s}, " for s in symbols) + "NULL};")
    return "\n".join(lines) + "\n"


def write_library_sources(n_beacons: int, directory: Path, models: tuple[type, ...] | None = None) -> list[Path]:
    """The models' sources (default every built-in; ``()``: none), the runtime, the registry, the bound and the
    batch API into ``directory``; the C files. A model's generated files do not depend on the others compiled
    with it, so libraries of different models share their objects in the compiler's cache."""
    models = _library_models(models)
    directory.mkdir(parents=True, exist_ok=True)
    for model in models:
        write_sources(model, n_beacons, directory, shell="")
    write_runtime(directory)  # (with each model's sources too; a library of no model needs it as well)
    (directory / "sblsim_models.c").write_text(_registry(n_beacons, models))
    cg = ca.CodeGenerator("sblsim_bound_casadi.c", {"with_header": True, "casadi_real": "double",
                                                    "casadi_int": "long long int"})
    cg.add(bound_step())
    own = interface_system(n_beacons).bound_function()
    for function in own or ():  # the interface's system steps a bound of its own (USBL: range, azimuth, elevation)
        cg.add(function)
    cg.generate(str(directory) + "/")
    # the eigenray table's builder (sblsim.models.acoustics.ray_tables.eigenray_table) calls this one through casadi
    rays = ca.CodeGenerator("sblsim_ray_points.c", {"casadi_real": "double", "casadi_int": "long long int"})
    rays.add(exact_points())
    rays.add(family_levels())  # and the availability map (sblsim.orchestrator.maps) this one
    rays.add(family_points())  # and the family table's (sblsim.models.acoustics.detection.level_table) these two
    rays.generate(str(directory) + "/")
    code = (directory / "sblsim_ray_points.c").read_text()
    (directory / "sblsim_ray_points.c").write_text(RAY_EXPORT + code)
    # the design's search calls these through ctypes (compiled_layout)
    layout = ca.CodeGenerator("sblsim_layout.c", {"casadi_real": "double", "casadi_int": "long long int"})
    for function in layout_functions():
        layout.add(function)
    layout.generate(str(directory) + "/")
    (directory / "sblsim_layout.c").write_text(RAY_EXPORT + (directory / "sblsim_layout.c").read_text())
    for name in (BATCH, METRICS) + ((SYSTEM_BOUND,) if own else ()):
        (directory / name).write_text((C_DIR / name).read_text())
    return sorted(directory.glob("*.c"))


def _library_models(models: tuple[type, ...] | None) -> tuple[type, ...]:
    """The models of a library (None: every built-in)."""
    return tuple(MODELS.values()) if models is None else models



__all__ = ["LAYOUT_CHUNK", "RAY_EXPORT", "SYSTEM_BOUND", "layout_functions", "write_library_sources"]
