"""A serialized FMU state is checked before it is taken (fmi2DeSerializeFMUstate).

A state from a file or a network is bytes from someone else: a NaN time, a NaN or out-of-range parameter
or a NaN state entry would make every output after it NaN. The FMU refuses such a state with fmi2Error
and one log line naming what is wrong, and the host's state object stays as it was (it still restores the
state it held). An output may be NaN only where the state itself makes it NaN: a receiver's estimate before its
first fix (no estimate), whose state is taken.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from sblsim.fmus.build import fmu_path
from sblsim.models import MODELS
from tests.fmus_tests.test_fmi_semantics import Slave, finite_but_the_estimate_before_a_fix

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


#: A still diver and four beacons (NED [m]): the packets fed to a receiver, so that its state has a fix.
DIVER, BEACONS = np.array([10.0, 5.0, 5.0]), np.array([[1.5, 0.0, 1.0], [0.0, 1.5, 1.0], [-1.5, 0.0, 1.0],
                                                        [0.0, -1.5, 1.0]])


def feed(s: Slave, k: int) -> None:
    """Step k's packet to a receiver (a round robin over :data:`BEACONS`, the exact range to :data:`DIVER`)."""
    beacon = BEACONS[k % 4]
    distance = float(np.linalg.norm(DIVER - beacon))
    s.set(packet_seq=k + 1, beacon_id=k % 4 + 1, packet_valid=True, tx_time=k * T, rx_time=k * T + distance / 1500.0,
          range=distance, beacon_x=beacon[0], beacon_y=beacon[1], beacon_z=beacon[2], depth=DIVER[2])


def step(s: Slave, name: str, k: int) -> None:
    if name.startswith("receiver"):
        feed(s, k)
    s.fmu.doStep(k * T, T)


@pytest.fixture(scope="module", params=list(MODELS))
def stepped(request, fmu_dir):
    """An instance of a model's FMU stepped 10 times (a receiver fed a packet at each: it has a fix), its state at
    step 10 serialized, and the outputs that follow that state (10 more steps)."""
    s = Slave(str(fmu_path(fmu_dir, request.param))).start()
    for k in range(10):
        step(s, request.param, k)
    state = s.fmu.getFMUstate()
    data = s.fmu.serializeFMUstate(state)
    at_save = s.outputs()
    after = []
    for k in range(10, 20):
        step(s, request.param, k)
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
        step(s, name, k)
        replay.append(s.outputs())
    np.testing.assert_array_equal(np.array(replay), after)
    assert np.all(np.isfinite(at_save)) and np.all(np.isfinite(after))  # a receiver has its fix: an estimate


RECEIVERS = [name for name in MODELS if name.startswith("receiver")]


@pytest.mark.parametrize("name", RECEIVERS)
def test_a_receiver_state_before_its_first_fix_is_taken_and_a_nan_it_does_not_give_refused(fmu_dir, name):
    """Before its first fix a receiver's estimate outputs are NaN (no estimate): its state then is taken and
    replays the same steps (packets from step 5 on: its first fix, then estimates). A NaN the state does not give
    is refused: in another output of that state (pos_std), or in an estimate output of a state with a fix."""
    s = Slave(str(fmu_path(fmu_dir, name))).start()
    for k in range(5):
        s.fmu.doStep(k * T, T)  # no packet
    at_save = s.outputs()
    assert not finite_but_the_estimate_before_a_fix(s.output_names(), at_save).any()
    data = s.fmu.serializeFMUstate(s.fmu.getFMUstate())
    ahead = []
    for k in range(5, 15):
        step(s, name, k)
        ahead.append(s.outputs())
    assert finite_but_the_estimate_before_a_fix(s.output_names(), ahead)[-1]  # a fix from the packets
    taken = s.fmu.deSerializeFMUstate(data)
    s.fmu.setFMUstate(taken)
    np.testing.assert_array_equal(s.outputs(), at_save)  # NaN where it was
    replay = []
    for k in range(5, 15):
        step(s, name, k)
        replay.append(s.outputs())
    np.testing.assert_array_equal(np.array(replay), np.array(ahead))
    at = _layout(name)
    outputs = [v.name for v in MODELS[name].outputs(4)]
    for label, blob, output in (("before the fix", data, "pos_std"),
                                ("with a fix", s.fmu.serializeFMUstate(s.fmu.getFMUstate()), "est_y")):
        s.log.clear()
        with pytest.raises(FMICallException):
            s.fmu.deSerializeFMUstate(_tampered(blob, at["y"] + outputs.index(output), float("nan")))
        assert len(s.log) == 1 and f"{output} = nan is not finite (its state gives " in s.log[0], (label, s.log)
        assert s.log[0].endswith("; the state is refused"), (label, s.log)


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
