"""The counts and indices the C sources share with Python come from the Python tuples only; the model
record names the fields it sets.

``sblsim_contract.h`` is generated from the tuples (:mod:`sblsim.fmus.contract`): an edit by hand on the
C side (a name defined again in ``fmus/c``, a header kept in the sources) or a header that no longer
matches the tuples fails here.
"""

from __future__ import annotations

import re

from sblsim.fmus.codegen import C_DIR, model_record, write_sources
from sblsim.fmus.compiled_metrics import metrics_sizes, system_bound_sizes
from sblsim.fmus.contract import CONTRACT, contract_header, contract_tables
from sblsim.fmus.native import VECTORS, load
from sblsim.models import MODELS
from sblsim.models.bound import FIXED, bound_step
from sblsim.models.columns import LANE_METRIC_INPUTS
from sblsim.models.declarations import SEED_NAMES
from sblsim.models.error_bound import ERROR_MOTION
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.metrics import METRIC_INPUTS, RUN_METRICS


def header_enums(text: str) -> list[list[str]]:
    """The names of each enum of a C header, in order."""
    return [[item.strip() for item in body.split(",") if item.strip()]
            for body in re.findall(r"enum\s*\{([^}]*)\}", text)]


def generated_names() -> list[str]:
    return [name for names in header_enums(contract_header()) for name in names] + ["SBLSIM_BOUND_STATE"]


def test_the_header_lists_every_tuple_in_order():
    expected = [(SEED_NAMES, "SBLSIM_SEED_", "SBLSIM_N_SEEDS"), (VECTORS, "SBLSIM_VECTOR_", "SBLSIM_N_VECTORS"),
                (METRIC_INPUTS + LANE_METRIC_INPUTS, "SBLSIM_COLUMN_", "SBLSIM_N_COLUMNS"),
                (RUN_METRICS, "SBLSIM_METRIC_", "SBLSIM_N_METRICS"), (FIXED, "SBLSIM_FIXED_", "SBLSIM_N_FIXED"),
                (tuple(bound_step().name_in()), "SBLSIM_BOUND_IN_", "SBLSIM_BOUND_N_IN")]
    for system in SYSTEMS.values():  # every system's own bound: its packed layouts
        if system.bound_fixed:
            name = system.name.upper()
            expected += [(system.bound_fixed, f"SBLSIM_{name}_FIXED_", f"SBLSIM_{name}_N_FIXED"),
                         (system.bound_steps, f"SBLSIM_{name}_STEP_", f"SBLSIM_{name}_N_STEPS")]
    assert any(s.bound_fixed for s in SYSTEMS.values())  # USBL has one: the loop above is not empty
    enums = header_enums(contract_header())
    assert len(enums) == len(expected) == len(contract_tables())
    for names, (source, prefix, count) in zip(enums, expected):
        assert names == [prefix + n.upper() for n in source] + [count]


def test_a_build_directory_holds_the_header_regenerated_from_the_tuples(tmp_path):
    sources = write_sources(MODELS["target"], 4, tmp_path)
    assert CONTRACT in sources.files
    assert (tmp_path / CONTRACT).read_text() == contract_header()


def test_the_c_sources_define_none_of_the_generated_names():
    assert not (C_DIR / CONTRACT).exists(), "the header is generated into each build, not kept in fmus/c"
    names = generated_names()
    for path in sorted(C_DIR.iterdir()):
        text = path.read_text()
        for body in re.findall(r"enum\s*\{([^}]*)\}", text):
            defined = [item.split("=")[0].strip() for item in body.split(",")]
            assert not set(defined) & set(names), f"{path.name} defines {set(defined) & set(names)}"
        for name in names:
            assert not re.search(rf"#\s*define\s+{name}\b", text), f"{path.name} defines {name}"


def test_the_compiled_library_reports_the_tuples_counts():
    assert metrics_sizes() == (len(METRIC_INPUTS) + len(LANE_METRIC_INPUTS), len(RUN_METRICS), len(FIXED))
    lib = load()
    model = MODELS["target"]
    program = model.program(4)
    expected = {"p": len(model.fmu_parameters_declared(4)), "d": program.derived_size, "x": program.state_size,
                "u": len(model.inputs(4)), "y": len(model.outputs(4)), "x_next": program.state_size,
                "draws": len(program.purposes())}
    assert {v: lib.sblsim_model_size(model.name.encode(), k) for k, v in enumerate(VECTORS)} == expected


def test_the_model_record_names_every_field_it_sets():
    """The generated ``sblsim_model`` record uses designated initializers: every field of the struct in
    ``sblsim_runtime.h`` appears once as ``.field =``, in any order a reader need not count."""
    struct = re.search(r"typedef struct \{([^}]*)\} sblsim_model;", (C_DIR / "sblsim_runtime.h").read_text())
    declarations = re.sub(r"/\*.*?\*/", "", struct.group(1), flags=re.S)
    fields = re.findall(r"\**(\w+)(?:\[\w+\])?\s*[,;]", declarations)
    text = model_record(MODELS["target"], 4, "{guid}")
    body = text[text.index("const sblsim_model sblsim_target_model = {"):]
    assert fields and all(body.count(f"    .{name} = ") == 1 for name in fields), fields


def test_every_compiled_system_bound_reports_its_systems_layouts():
    """The library of the interface of each system with a bound of its own (USBL) compiles the system's casadi
    prior and step with the packed layouts of its tuples: the sizes it reports are the tuples' lengths, and the
    bound's entries the error-state receivers' state size squared."""
    checked = 0
    for system in SYSTEMS.values():
        if system.bound_fixed and system.interface_beacons is not None:  # compiled into its interface's library
            n = system.interface_beacons
            assert system_bound_sizes(n) == (len(system.bound_fixed), len(system.bound_steps),
                                             ERROR_MOTION.state_size ** 2)
            prior, step = system.bound_function()
            assert step.size1_in(1) == len(system.bound_fixed) and step.size1_in(2) == len(system.bound_steps)
            assert prior.size1_in(0) == len(system.bound_fixed)
            checked += 1
    assert checked >= 1
