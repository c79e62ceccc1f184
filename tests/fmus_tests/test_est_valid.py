"""``est_valid``: the Boolean output by which every receiver FMU says whether it has an estimate, read by fmpy.

* the model description of every built-in receiver's FMI 2.0 FMU declares it an output of type Boolean, listed
  among the outputs of its model structure, after every other variable;
* fed packets made here (a diver standing still at a known point, exact ranges from four beacons at known
  positions, the first packets lost), each receiver's ``est_valid`` is false at every step before its first fix,
  while ``est_*`` are NaN, and true at the step of the first fix and at every step after it, while ``est_*`` are
  finite and at the diver. The step of the first fix is known from the packets alone: a Kalman-type receiver's
  first received packet, the least-squares receiver's packet that makes three beacons heard.

The FMI 3.0 FMUs' twins of these tests are in test_fmi3.py (on the FMUs that module builds), with the helpers
here (:func:`check_description`, :func:`drive`, :func:`check`, :class:`Fmi3Receiver`).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi3 import FMU3Slave

from sblsim.fmus.arrays import fmi3_variables
from sblsim.fmus.build import fmu_path
from sblsim.models import MODELS, RECEIVERS
from tests.fmus_tests.test_fmi_semantics import Slave

T = 0.1  # the host's step and the receivers' own [s]
STEPS = 24
BEACONS = np.array([[6.0, 0.0, 1.0], [0.0, 6.0, 1.0], [-6.0, 0.0, 1.0], [0.0, -6.0, 1.0]])  # NED [m]
DIVER = np.array([4.0, 3.0, 12.0])  # standing still [m]
START = {"x0_x": 4.5, "x0_y": 2.6, "x0_z": 11.8}  # the starting guess, half a metre off
#: Step of each packet's arrival -> whether it was received; packets go round the four beacons from beacon 1.
PACKETS = {2: False, 4: False, 6: True, 8: True, 10: False, 12: True, 14: True, 16: True, 18: True, 20: True}
ESTIMATE = ("est_x", "est_y", "est_z", "est_vx", "est_vy", "est_vz")


def first_fix(least_squares: bool) -> int:
    """The step of the first fix, from the packets alone: the first received packet (a Kalman-type receiver), or
    the received packet that makes three distinct beacons heard (the least-squares receiver's multilateration)."""
    heard: set[int] = set()
    for seq, (step, received) in enumerate(PACKETS.items()):
        if received:
            heard.add(seq % len(BEACONS))
            if len(heard) >= (3 if least_squares else 1):
                return step
    raise AssertionError("no fix in the packets")


def packet_inputs(step: int, seq: int, received: bool) -> dict:
    """The receiver's inputs for the packet ``seq`` (1-based) arriving in ``step`` (a lost one: range and position
    0, as the channel delivers it)."""
    beacon = BEACONS[(seq - 1) % len(BEACONS)]
    rng = float(np.linalg.norm(DIVER - beacon))
    rx = (step + 1) * T - 0.02
    return {"packet_seq": seq, "beacon_id": (seq - 1) % len(BEACONS) + 1, "packet_valid": received,
            "tx_time": rx - rng / 1500.0, "rx_time": rx, "range": rng if received else 0.0,
            **{f"beacon_{a}": float(beacon[k]) if received else 0.0 for k, a in enumerate("xyz")}}


def drive(set_inputs, step, read) -> tuple[np.ndarray, np.ndarray]:
    """The receiver stepped STEPS times with the depth and the PACKETS: ``est_valid`` (STEPS,) and ``est_*``
    (STEPS, 6) after each step."""
    valid, estimate, seq = [], [], 0
    for k in range(STEPS):
        inputs = {"depth": float(DIVER[2])}
        if k in PACKETS:
            seq += 1
            inputs.update(packet_inputs(k, seq, PACKETS[k]))
        set_inputs(inputs)
        step(k * T)
        flag, values = read()
        valid.append(flag)
        estimate.append(values)
    return np.array(valid), np.array(estimate, dtype=float)


def check(name: str, valid: np.ndarray, estimate: np.ndarray) -> None:
    first = first_fix(name == RECEIVERS["lsq"])
    assert valid.dtype == bool
    np.testing.assert_array_equal(valid, np.arange(STEPS) >= first, err_msg=f"{name}: est_valid")
    assert np.isnan(estimate[:first]).all(), f"{name}: an estimate before the first fix"
    assert np.isfinite(estimate[first:]).all(), f"{name}: no estimate from the first fix on"
    assert np.linalg.norm(estimate[-1, :3] - DIVER) < 0.5, f"{name}: the estimate is not at the diver"


def check_description(path: Path) -> None:
    """The receiver FMU ``path`` declares ``est_valid`` a Boolean output, in its model structure's outputs, last."""
    md = read_model_description(str(path))
    variables = [v for v in md.modelVariables if v.causality != "independent"]
    est_valid = next(v for v in variables if v.name == "est_valid")
    assert (est_valid.causality, est_valid.type) == ("output", "Boolean"), (path, md.fmiVersion)
    assert est_valid in [o.variable for o in md.outputs], (path, md.fmiVersion)
    assert variables[-1] is est_valid, (path, md.fmiVersion)  # declared last: earlier references stay


def test_the_fmi2_model_description_lists_est_valid_as_a_boolean_output(fmu_dir):
    for name in RECEIVERS.values():
        check_description(fmu_path(fmu_dir, name))


@pytest.mark.parametrize("name", list(RECEIVERS.values()))
def test_fmi2_est_valid_is_false_before_the_first_fix_and_true_from_it_on(fmu_dir, name):
    s = Slave(str(fmu_path(fmu_dir, name))).start(**START)
    valid, estimate = drive(lambda inputs: s.set(**inputs), lambda t: s.fmu.doStep(t, T),
                            lambda: (bool(s.get("est_valid")[0]), s.get(*ESTIMATE)))
    check(name, valid, estimate)


class Fmi3Receiver:
    """An FMI 3.0 receiver instance (fmpy's) in initialization mode, read and written by its FMI 2.0 scalars'
    names: each one an FMI 3.0 scalar or an element of an array (:func:`sblsim.fmus.arrays.fmi3_variables`)."""

    def __init__(self, path: Path, name: str, into: Path) -> None:
        md = read_model_description(str(path))
        with zipfile.ZipFile(path) as archive:
            archive.extractall(into)
        scalars = MODELS[name].fmu_variables(4)
        self.table = fmi3_variables(scalars, 4)
        self.where = {scalars[e].name: (vr, k) for vr, t in enumerate(self.table) for k, e in enumerate(t.elements)}
        self.fmu = FMU3Slave(guid=md.guid, unzipDirectory=str(into), modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=name)
        self.fmu.instantiate()
        self.fmu.enterInitializationMode(startTime=0.0)

    def set(self, **values) -> None:
        arrays: dict[int, dict[int, object]] = {}
        for name, value in values.items():
            vr, k = self.where[name]
            arrays.setdefault(vr, {})[k] = value
        for vr, elements in arrays.items():
            t = self.table[vr]
            assert sorted(elements) == list(range(t.size)), f"{t.name}: set whole"
            getattr(self.fmu, f"set{t.fmi_type}")([vr], [elements[k] for k in range(t.size)])

    def get(self, *names) -> list:
        out = []
        for name in names:
            vr, k = self.where[name]
            t = self.table[vr]
            out.append(getattr(self.fmu, f"get{t.fmi_type}")([vr], nValues=t.size)[k])
        return out
