"""The native FMUs as an FMI host sees them through fmpy: repeated use, instances, step rules, state, no NaN.

Each test is a promise of fmus/c/fmi2_shell.c that a host relies on; the
expected values come from an independent run (another instance, another
process, another step pattern) or from the FMI 2.0 standard.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile

import fmpy
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from sblsim.fmus.build import fmu_path
from sblsim.models import MODELS

T = 0.1
#: A receiver's estimate outputs: undefined (NaN) before its first fix, never its starting guess
#: (:data:`sblsim.models.receiver.core.NO_ESTIMATE`).
ESTIMATE_OUTPUTS = tuple(f"est_{a}" for a in ("x", "y", "z", "vx", "vy", "vz"))


def finite_but_the_estimate_before_a_fix(names, rows) -> np.ndarray:
    """Checks the outputs ``rows`` (steps, outputs) of the variables ``names``: every one finite but a receiver's
    estimate outputs, which are NaN, all of them, at each step before the receiver's first fix and finite, all of
    them, at every step from it on; where ``names`` holds the receiver's ``est_valid``, it is true exactly at the
    steps with an estimate. Returns whether each step has an estimate."""
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    estimate = np.isin(np.asarray(names), ESTIMATE_OUTPUTS)
    assert np.all(np.isfinite(rows[:, ~estimate])), "an output that is not finite"
    defined = np.isfinite(rows[:, estimate]).all(axis=1)
    assert np.all(np.isnan(rows[~defined][:, estimate])), "an estimate defined in part, or infinite"
    if defined.any():
        assert defined[int(np.argmax(defined)):].all(), "an estimate undefined after the first fix"
    if "est_valid" in names:
        np.testing.assert_array_equal(rows[:, list(names).index("est_valid")] != 0.0, defined, "est_valid")
    return defined


class Slave:
    """One instance of a built FMU, driven by name, recording what the FMU logs."""

    def __init__(self, fmu: str, name: str = "instance") -> None:
        self.md = read_model_description(fmu)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.log: list[str] = []
        # fmpy's extract() alone leaves its folder behind: this one goes with the instance (or at exit)
        self._unzipped = tempfile.TemporaryDirectory(prefix="sblsim-test-")
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=extract(fmu, self._unzipped.name),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(callbacks=self._callbacks())

    def _callbacks(self):
        """FMI callbacks whose logger keeps each message in :attr:`log` (the FMU logs errors always)."""
        from fmpy.fmi1 import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )

        def logger(env, instance, status, category, message):
            self.log.append(message.decode())

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._keep = callbacks
        return callbacks

    def set(self, **values) -> None:
        for name, value in values.items():
            v = self.vars[name]
            getattr(self.fmu, f"set{v.type}")([v.valueReference], [value])

    def get(self, *names) -> list:
        return [getattr(self.fmu, f"get{self.vars[n].type}")([self.vars[n].valueReference])[0] for n in names]

    def start(self, t0: float = 0.0, **params) -> "Slave":
        self.fmu.setupExperiment(startTime=t0)
        self.fmu.enterInitializationMode()
        self.set(**params)
        self.fmu.exitInitializationMode()
        return self

    def output_names(self) -> list[str]:
        return [v.name for v in self.md.modelVariables if v.causality == "output"]

    def outputs(self) -> np.ndarray:
        return np.array(self.get(*self.output_names()), dtype=float)


def run_channel(fmu: str, steps: list[float], **params) -> list[tuple]:
    """The packets an acoustics instance delivers for a sequence of host step sizes (constant inputs), each with its
    arrival ``rx_time``, on every lane of each delivery (lane 1: the packet outputs; lane m: ``lane<m>_*``), in
    the order of the lanes."""
    s = Slave(fmu).start(**params)
    s.set(**{f"beacon{i}_true_x": 3.0 * i for i in range(1, 5)}, target_x=10.0, target_y=5.0, target_z=5.0)
    t, packets, held = 0.0, [], [0.0] * 8
    fields = ("packet_seq", "beacon_id", "packet_valid", "tx_time", "range", "rx_time")
    for h in steps:
        s.fmu.doStep(t, h)
        t += h
        for m in range(8):
            packet = tuple(s.get(*[f if m == 0 else f"lane{m + 1}_{f}" for f in fields]))
            if packet[0] > 0 and packet[0] != held[m]:
                held[m] = packet[0]
                assert packet[3] < packet[5] <= t + 1e-9  # sent, then delivered in the step that reached its arrival
                assert t - h < packet[5] - 1e-9 or not packets  # not held back from an earlier step
                packets.append(packet)
    return packets


@pytest.mark.parametrize("name", list(MODELS))
def test_simulate_fmu_three_times_in_one_process(fmu_dir, name):
    """A notebook calling fmpy again and again: the same numbers each time, no crash, no NaN (but a receiver's
    estimate, which has no value before its first fix: with fmpy's start inputs it receives no packet)."""
    results = [fmpy.simulate_fmu(str(fmu_path(fmu_dir, name)), stop_time=3.0, output_interval=T)
               for _ in range(3)]
    for r in results[1:]:
        for column in r.dtype.names:
            np.testing.assert_array_equal(r[column], results[0][column])
    numbers = np.array([list(row)[1:] for row in results[0]], dtype=float)
    assert numbers.shape[0] == 31
    estimated = finite_but_the_estimate_before_a_fix(results[0].dtype.names[1:], numbers)
    if name.startswith("receiver"):  # no packet, no fix: never an estimate (its starting guess is not one)
        assert not estimated.any()


_ALONE = """
import sys, numpy as np
sys.path.insert(0, {tests!r})
from fmus_tests.test_fmi_semantics import Slave
s = Slave(sys.argv[1]).start(**{{k: float(v) for k, v in (a.split("=") for a in sys.argv[2:])}})
rows = []
for k in range(40):
    s.fmu.doStep(k * 0.1, 0.1)
    rows.append(s.outputs())
np.save(sys.stdout.buffer, np.array(rows))
"""


def test_two_instances_side_by_side_equal_runs_in_their_own_process(fmu_dir, tmp_path):
    """Two platforms with different baselines stepped in turn, each equal to a run alone in another process."""
    import io
    from pathlib import Path

    fmu = str(fmu_path(fmu_dir, "platform"))
    a, b = Slave(fmu, "a").start(baseline=0.4), Slave(fmu, "b").start(baseline=3.0, gps_sigma=2.0)
    rows_a, rows_b = [], []
    for k in range(40):
        a.fmu.doStep(k * T, T)
        b.fmu.doStep(k * T, T)
        rows_a.append(a.outputs())
        rows_b.append(b.outputs())
    tests = str(Path(__file__).resolve().parents[1])
    for rows, args in ((rows_a, ["baseline=0.4"]), (rows_b, ["baseline=3.0", "gps_sigma=2.0"])):
        proc = subprocess.run([sys.executable, "-c", _ALONE.format(tests=tests), fmu, *args], capture_output=True)
        assert proc.returncode == 0, proc.stderr.decode()[-1500:]
        np.testing.assert_array_equal(np.array(rows), np.load(io.BytesIO(proc.stdout)))
    assert not np.allclose(rows_a, rows_b)  # the two instances really hold different parameters


@pytest.mark.parametrize("steps", [
    pytest.param([T / 4] * 80, marks=pytest.mark.slow),  # four host steps per slot
    [T] * 20,                                            # one per slot
    [0.03, 0.07, 0.25, 0.05, 0.6, 0.1, 0.9],             # irregular, some spanning several slots
], ids=["quarter", "slot", "irregular"])
def test_slots_do_not_depend_on_the_host_step(fmu_dir, steps):
    """The channel sends slot k at t_k = k T of its own clock, whatever the host's steps (2 s of slots), and
    delivers it at the end of the step that reaches its arrival (the 20th is still in flight at 2 s): a step
    that spans several slots delivers each of their packets, on the lanes of the delivery."""
    fmu = str(fmu_path(fmu_dir, "acoustics"))
    reference = run_channel(fmu, [T] * 20, sigma_range=0.3, loss_pct=20.0)
    got = run_channel(fmu, steps, sigma_range=0.3, loss_pct=20.0)
    assert len(reference) == 19 and [p[3] for p in reference] == pytest.approx([T * k for k in range(1, 20)])
    if steps[0] == 0.03:  # the last step (0.9 s) sends slots 12 … 19 with slot 11 in flight: the 19th finds no room
        assert got == reference[:18]
    else:
        assert got == reference


def test_a_tiny_closing_step_adds_no_packet(fmu_dir):
    """OMSimulator's closing step of 2e-15 s after the last slot must not send or deliver one more packet (the
    tenth, sent at 1 s, arrives a travel time later)."""
    fmu = str(fmu_path(fmu_dir, "acoustics"))
    packets = run_channel(fmu, [T] * 10 + [2e-15])
    assert [p[0] for p in packets] == list(range(1, 10))
    assert [p[0] for p in run_channel(fmu, [T] * 10 + [2e-15, T])] == list(range(1, 11))


def call_fails(slave: Slave, call, *args, match: str) -> None:
    before = len(slave.log)
    with pytest.raises(FMICallException):
        call(*args)
    assert any(match in line for line in slave.log[before:]), slave.log[before:]


def test_bad_step_calls_return_fmi2error_and_log_why(fmu_dir):
    fmu = str(fmu_path(fmu_dir, "target"))
    s = Slave(fmu)
    call_fails(s, s.fmu.doStep, 0.0, T, match="fmi2DoStep: not allowed in state Instantiated")
    s.start()
    call_fails(s, s.fmu.doStep, 0.0, 0.0, match="must be positive")
    call_fails(s, s.fmu.doStep, 0.0, -T, match="must be positive")
    s.fmu.doStep(0.0, T)
    call_fails(s, s.fmu.doStep, 0.5, T, match="differs from the FMU's time")  # a gap
    call_fails(s, s.fmu.doStep, 0.0, T, match="differs from the FMU's time")  # a step back
    s.fmu.doStep(T, T)  # the right time still works
    assert s.get("pos_x")[0] == pytest.approx(15.0 * np.cos(-np.pi / 2 + 0.5 * 2 * T / 15.0))


@pytest.mark.parametrize("name, params, match", [
    ("platform", dict(baseline=0.0), "baseline: 0 is outside the allowed range (0, 1000] m"),
    ("platform", dict(beaufort=9), "beaufort: 9 is outside the allowed range [0, 8]"),
    ("target", dict(trajectory=4), "waypoint_rows: 0 rows in use; this setting needs at least 2"),
    ("acoustics", {"sound_speed_rows": 2, "sound_speed[1]": 1500.0, "sound_speed[2]": 1.5},
     "sound_speed[2]: 1.5 is outside the allowed range [1300, 1700] m/s"),
    ("acoustics", {"sound_speed_rows": 2, "sound_speed_depth[1]": 5.0, "sound_speed_depth[2]": 1.0,
                   "sound_speed[1]": 1500.0, "sound_speed[2]": 1500.0}, "must be greater than row 1"),
    ("receiver", dict(sigma_range=0.0), "sigma_range: 0 is outside the allowed range [0.001, 1000] m"),
])
def test_a_parameter_outside_its_range_fails_initialization(fmu_dir, name, params, match):
    s = Slave(str(fmu_path(fmu_dir, name)))
    s.fmu.setupExperiment(startTime=0.0)
    s.fmu.enterInitializationMode()
    s.set(**params)
    call_fails(s, s.fmu.exitInitializationMode, match=match)


def test_a_range_without_a_unit_names_none(fmu_dir):
    """A dimensionless parameter's range ends at its bracket (its unit "1" is not written after it)."""
    s = Slave(str(fmu_path(fmu_dir, "receiver")))
    s.fmu.setupExperiment(startTime=0.0)
    s.fmu.enterInitializationMode()
    s.set(gate_probability=2.0)
    call_fails(s, s.fmu.exitInitializationMode, match="gate_probability")
    assert s.log[-1].endswith("allowed range [0.5, 1]"), s.log[-1]


def test_parameters_are_fixed_after_initialization_and_outputs_cannot_be_set(fmu_dir):
    s = Slave(str(fmu_path(fmu_dir, "platform"))).start()
    call_fails(s, lambda: s.set(baseline=2.0), match="fixed parameter")
    call_fails(s, lambda: s.set(roll=1.0), match="is an output")


def test_get_and_set_state_and_serialization_replay_the_same_steps(fmu_dir):
    fmu = str(fmu_path(fmu_dir, "platform"))
    s = Slave(fmu).start(gps_model=1)  # Gauss-Markov: the state carries the GPS error
    for k in range(5):
        s.fmu.doStep(k * T, T)
    state = s.fmu.getFMUstate()
    blob = s.fmu.serializeFMUstate(state)
    ahead = []
    for k in range(5, 12):
        s.fmu.doStep(k * T, T)
        ahead.append(s.outputs())
    for restore in ("state", "serialized", "state"):  # a state can be restored many times
        s.fmu.setFMUstate(state if restore == "state" else s.fmu.deSerializeFMUstate(blob))
        again = []
        for k in range(5, 12):
            s.fmu.doStep(k * T, T)
            again.append(s.outputs())
        np.testing.assert_array_equal(np.array(again), np.array(ahead))
    s.fmu.freeFMUstate(state)


def test_reset_gives_the_first_run_again(fmu_dir):
    s = Slave(str(fmu_path(fmu_dir, "acoustics"))).start(loss_pct=30.0)
    s.set(target_x=10.0)
    first = []
    for k in range(12):
        s.fmu.doStep(k * T, T)
        first.append(s.outputs())
    s.fmu.reset()
    s.start(loss_pct=30.0)
    s.set(target_x=10.0)
    for k in range(12):
        s.fmu.doStep(k * T, T)
        np.testing.assert_array_equal(s.outputs(), first[k])


def test_no_output_is_nan_with_lost_packets_and_no_fix(fmu_dir):
    """A lost packet has packet_valid false and range 0; a missing fix has instr_valid false and instr_* 0; the
    receiver, which has received no packet, has no estimate (NaN) and every other output finite."""
    channel = Slave(str(fmu_path(fmu_dir, "acoustics"))).start(loss_pct=100.0)
    channel.set(target_x=10.0)
    receiver = Slave(str(fmu_path(fmu_dir, "receiver"))).start()
    for k in range(8):
        channel.fmu.doStep(k * T, T)
        packet = dict(zip(("packet_seq", "beacon_id", "packet_valid", "tx_time", "range", "beacon_x"),
                          channel.get("packet_seq", "beacon_id", "packet_valid", "tx_time", "range", "beacon_x")))
        assert not packet["packet_valid"] and packet["range"] == 0.0 and packet["beacon_x"] == 0.0
        receiver.set(**packet)
        receiver.fmu.doStep(k * T, T)
        assert not finite_but_the_estimate_before_a_fix(receiver.output_names(), receiver.outputs()).any()
        assert [bool(receiver.get("instr_valid")[0])] + receiver.get("instr_x", "nis") == [False, 0.0, 0.0]
