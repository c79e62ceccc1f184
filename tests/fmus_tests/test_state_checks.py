"""A serialized FMU state is checked before it is taken (fmi2DeSerializeFMUstate).

A state from a file or a network is bytes from someone else: a NaN time, a NaN or out-of-range parameter
or a NaN state entry would make every output after it NaN. The FMU refuses such a state with fmi2Error
and one log line naming what is wrong, and the host's state object stays as it was (it still restores the
state it held).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from sblsim.fmus.build import fmu_path
from sblsim.models import MODELS
from tests.fmus_tests.test_fmi_semantics import Slave

T = 0.1
#: Words before the values: magic, value count, purposes, state number, start time, t0, t (fmi2_shell.c).
HEADER, STATE_WORD, START_WORD, T0_WORD, T_WORD = 7, 3, 4, 5, 6


def _layout(name: str) -> dict[str, int]:
    """The word offset of each value block of a model's serialized state."""
    model = MODELS[name]
    program = model.program(4)
    sizes = {"p": len(model.fmu_parameters_declared(4)), "d": program.derived_size, "x": program.state_size,
             "u": len(model.inputs(4)), "y": len(model.outputs(4))}
    out, offset = {}, HEADER
    for block, size in sizes.items():
        out[block] = offset
        offset += size
    return out


def _tampered(data: bytes, word: int, value: float | int) -> bytes:
    packed = struct.pack("<Q", value) if isinstance(value, int) else struct.pack("<d", value)
    return data[:8 * word] + packed + data[8 * word + 8:]


def _ranged_parameter(name: str) -> tuple[int, str]:
    """Index and name of the first Real parameter with a declared maximum (not a table entry)."""
    params = MODELS[name].fmu_parameters_declared(4)
    return next((k, v.name) for k, v in enumerate(params)
                if v.fmi_type == "Real" and v.max is not None and not v.in_table)


def _cases(name: str) -> list[tuple[str, int, float | int, str]]:
    """(label, word, value, what the log line says) of each tampering."""
    at = _layout(name)
    k, param = _ranged_parameter(name)
    first_output = MODELS[name].outputs(4)[0].name
    cases = [
        ("nan time", T_WORD, float("nan"), "its times are not finite"),
        ("nan start", START_WORD, float("nan"), "its times are not finite"),
        ("infinite t0", T0_WORD, float("inf"), "its times are not finite"),
        ("t before t0", T_WORD, -5.0, "its times are out of order"),
        ("nan parameter", at["p"] + k, float("nan"), f"parameter {param} = nan is not finite"),
        ("parameter out of range", at["p"] + k, 1e300, f"{param}: 1.0000000000000001e+300 is outside the allowed"),
        ("nan state", at["x"], float("nan"), "x[0] = nan is not finite"),
        ("nan output", at["y"], float("nan"), f"{first_output} = nan is not finite"),
        ("state number", STATE_WORD, 99, "state number 99 is not one of the 5 states"),
    ]
    inputs = [v for v in MODELS[name].inputs(4) if v.fmi_type == "Real"]
    if inputs:
        j = MODELS[name].inputs(4).index(inputs[0])
        cases.append(("input out of range", at["u"] + j, 1e300, f"{inputs[0].name} = 1e+300 is outside the allowed"))
    return cases


@pytest.fixture(scope="module", params=list(MODELS))
def stepped(request, fmu_dir):
    """An instance of a model's FMU stepped 10 times, its state at step 10 serialized, and the outputs that
    follow that state (10 more steps)."""
    s = Slave(str(fmu_path(fmu_dir, request.param))).start()
    for k in range(10):
        s.fmu.doStep(k * T, T)
    state = s.fmu.getFMUstate()
    data = s.fmu.serializeFMUstate(state)
    at_save = s.outputs()
    after = []
    for k in range(10, 20):
        s.fmu.doStep(k * T, T)
        after.append(s.outputs())
    return request.param, s, state, data, at_save, np.array(after)


def test_the_untouched_state_is_taken(stepped):
    name, s, state, data, at_save, after = stepped
    taken = s.fmu.deSerializeFMUstate(data)
    s.fmu.setFMUstate(taken)
    np.testing.assert_array_equal(s.outputs(), at_save)
    s.fmu.freeFMUstate(taken)


def test_a_tampered_state_is_refused_with_one_log_line_and_the_held_state_kept(stepped):
    name, s, state, data, at_save, after = stepped
    for label, word, value, message in _cases(name):
        s.log.clear()
        with pytest.raises(FMICallException):
            s.fmu.deSerializeFMUstate(_tampered(data, word, value), state)
        assert len(s.log) == 1, (label, s.log)
        assert s.log[0].startswith("fmi2DeSerializeFMUstate: ") and message in s.log[0], (label, s.log)
        assert s.log[0].endswith("; the state is refused"), (label, s.log)
    # the state object the host passed still holds the saved state: restoring it replays the same steps
    s.fmu.setFMUstate(state)
    np.testing.assert_array_equal(s.outputs(), at_save)
    replay = []
    for k in range(10, 20):
        s.fmu.doStep(k * T, T)
        replay.append(s.outputs())
    np.testing.assert_array_equal(np.array(replay), after)
    assert np.all(np.isfinite(after))


def test_a_parameter_out_of_range_is_taken_before_initialization(fmu_dir):
    """Before fmi2ExitInitializationMode a parameter may hold any finite value (it is checked there)."""
    s = Slave(str(fmu_path(fmu_dir, "platform")))
    k, param = _ranged_parameter("platform")
    s.set(**{param: 1e300})
    state = s.fmu.getFMUstate()
    taken = s.fmu.deSerializeFMUstate(s.fmu.serializeFMUstate(state))
    s.fmu.setFMUstate(taken)
    s.fmu.setupExperiment(startTime=0.0)
    s.fmu.enterInitializationMode()
    with pytest.raises(FMICallException):
        s.fmu.exitInitializationMode()
    assert "is outside the allowed range" in s.log[-1] and param in s.log[-1]
