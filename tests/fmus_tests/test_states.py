"""The FMI 2.0 Co-Simulation state machine, checked from a plain C host (``c_states.c``).

Every FMI function taking an instance is called in every state an sblsim FMU can reach. Where the
standard (FMI 2.0.4, section 4.2.4, the table of the calling sequence) does not allow it, the call
returns fmi2Error and logs ``<function>: not allowed in state <state>``; where it does, a supported call
returns fmi2OK and an unsupported one refuses for its own reason. Nothing crashes.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from fmpy import read_model_description

from sblsim.fmus.build import fmu_path
from sblsim.fmus.codegen import fmi_headers_dir
from sblsim.fmus.compiler import find_compiler
from tests.fmus_tests.test_binaries import unpack

STATES_HOST = Path(__file__).with_name("c_states.c")
OK, ERROR = 0, 3
STATES = ("Instantiated", "InitializationMode", "StepComplete", "Terminated", "Error")
ALL = set(STATES)
SETTABLE = {"Instantiated", "InitializationMode", "StepComplete"}
INITIALIZED = {"InitializationMode", "StepComplete", "Terminated", "Error"}
STEPPED = {"StepComplete", "Terminated"}  # stepInProgress and stepFailed are never entered
#: The states each function may be called in (the standard's table restricted to these states).
ALLOWED = {
    "fmi2SetDebugLogging": ALL, "fmi2FreeInstance": ALL, "fmi2SetupExperiment": {"Instantiated"},
    "fmi2EnterInitializationMode": {"Instantiated"}, "fmi2ExitInitializationMode": {"InitializationMode"},
    "fmi2Terminate": {"StepComplete"}, "fmi2Reset": ALL,
    **{f"fmi2Get{t}": INITIALIZED for t in ("Real", "Integer", "Boolean", "String")},
    **{f"fmi2Set{t}": SETTABLE for t in ("Real", "Integer", "Boolean", "String")},
    **{f: ALL for f in ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize",
                        "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate")},
    "fmi2GetDirectionalDerivative": INITIALIZED, "fmi2SetRealInputDerivatives": SETTABLE,
    "fmi2GetRealOutputDerivatives": {"StepComplete", "Terminated", "Error"}, "fmi2DoStep": {"StepComplete"},
    "fmi2CancelStep": set(),
    **{f"fmi2Get{t}Status": STEPPED for t in ("", "Real", "Integer", "Boolean", "String")},
}
#: Functions the FMU declares it does not provide (or that never apply): fmi2Error even where allowed.
UNSUPPORTED = {"fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
               "fmi2CancelStep", "fmi2GetStatus", "fmi2GetIntegerStatus", "fmi2GetBooleanStatus",
               "fmi2GetStringStatus"}


@pytest.fixture(scope="module")
def c_states(tmp_path_factory) -> Path:
    """The state-machine host, compiled with the system compiler and the FMI headers fmpy ships."""
    exe = tmp_path_factory.mktemp("states") / "c_states"
    cc = find_compiler("system")
    subprocess.run([*cc.command, "-std=c99", "-O1", f"-I{fmi_headers_dir()}", str(STATES_HOST), "-o", str(exe),
                    "-ldl"], check=True, capture_output=True)
    return exe


def test_every_call_in_every_state_follows_the_fmi_state_machine(fmu_dir, c_states, tmp_path):
    fmu = fmu_path(fmu_dir, "platform")
    binary, guid, _ = unpack(fmu, tmp_path)
    baseline = next(v.valueReference for v in read_model_description(str(fmu)).modelVariables
                    if v.name == "baseline")
    proc = subprocess.run([str(c_states), str(binary), guid, str(baseline), "0.0"], capture_output=True, text=True,
                          env={}, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    seen = {}
    for line in proc.stdout.splitlines():
        state, function, status, *message = line.split(" ", 3)
        seen[state, function] = (status, " ".join(message))
    assert set(seen) == {(s, f) for s in STATES for f in ALLOWED}, "the host stopped early or skipped a call"
    for (state, function), (status, message) in seen.items():
        refusal = f"{function}: not allowed in state {state}"
        if state not in ALLOWED[function]:
            assert (status, message) == (str(ERROR), refusal), (state, function)
        elif function in UNSUPPORTED:
            assert status == str(ERROR) and message.startswith(f"{function}: ") and refusal not in message
        else:
            assert (status, message) == (str(OK), ""), (state, function)
