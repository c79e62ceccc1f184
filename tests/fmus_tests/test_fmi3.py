"""The FMI 3.0 Co-Simulation FMUs (``sblsim fmus build --fmi-version 3``): the FMI 2.0 numbers, with arrays.

* fmpy validates every FMI 3.0 FMU with no problem; every FMI 2.0 variable is an element of exactly one FMI 3.0
  variable of its causality, variability and type, and each carries its FMI 2.0 twin's unit;
* the fmu engine on the FMI 3.0 FMUs equals it on the FMI 2.0 FMUs step by step (0 difference: the same C) for
  the paper's scenarios, an LBL, a USBL and every receiver;
* the two site scenarios' FMI 3.0 scenario FMUs, with nothing set, stepped through fmpy's FMI 3.0 bindings by a
  Jacobi loop that moves each array whole, give ``sblsim run SCENARIO --engine fmu --master jacobi`` on the
  FMI 2.0 FMUs (<= 1e-9), and so does the package ``sblsim ssp export --fmi-version 3`` writes, stepped along
  its own connections (array to array);
* the FMI 3.0 state machine refuses what the standard forbids (a second fmi3Terminate, a step before
  initialization, a fixed parameter set in step mode, a wrong value count, another beacon count) with fmi3Error
  and a logged line, and two instances of one FMU in one process, reset and run again, give the same numbers.
"""

from __future__ import annotations

import ctypes
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pandas as pd
import pytest
from fmpy import read_model_description
from fmpy.fmi3 import FMU3Slave

from sblsim.fmus.arrays import fmi3_variables
from sblsim.fmus.build import beacons_dir, build_all, fmu_path, validate, version_dir
from sblsim.models import MODELS, RECEIVERS
from sblsim.models.columns import TIMESERIES_COLUMNS
from sblsim.models.errors import ModelError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.connections import default_connections
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.master import simulate
from sblsim.orchestrator.cosim.plan import load_plan
from sblsim.orchestrator.cosim.run import merge_params, run
from tests.fmus_tests.test_est_valid import ESTIMATE, START, Fmi3Receiver, T, check, check_description, drive

OK, ERROR = 0, 3
SHORT = ["simulation.duration=10", "acoustics.loss_pct=20", "acoustics.outlier_pct=5"]


@pytest.fixture(scope="module")
def fmu3_root(tmp_path_factory) -> Path:
    """A folder whose ``fmi3`` folder holds every model's FMI 3.0 FMU (``sblsim fmus build --fmi-version 3``)."""
    root = tmp_path_factory.mktemp("fmi3")
    paths = build_all(root, fmi_version=3)
    assert sorted(p.name for p in paths) == sorted(f"sblsim_{n}.fmu" for n in MODELS)
    assert all(p.parent == version_dir(root, 3) for p in paths)
    return root


@pytest.mark.slow
def test_fmpy_validates_every_fmi3_fmu_and_every_fmi2_variable_is_one_element(fmu3_root, fmu_dir):
    for name, model in MODELS.items():
        fmu3 = fmu_path(version_dir(fmu3_root, 3), name)
        assert validate(fmu3) == [], name
        md3, md2 = read_model_description(str(fmu3)), read_model_description(str(fmu_path(fmu_dir, name)))
        assert md3.fmiVersion == "3.0" and md2.fmiVersion == "2.0"
        scalars = {v.valueReference: v for v in md2.modelVariables}
        table = fmi3_variables(model.fmu_variables(4), 4)
        seen: list[int] = []
        for v3, t in zip([v for v in md3.modelVariables if v.causality != "independent"], table, strict=True):
            assert v3.name == t.name and v3.valueReference == table.index(t)
            if t.causality == "structuralParameter":
                assert v3.type == "UInt64" and int(v3.start) == 4
                continue
            shape = [int(d.start) if d.start is not None else 4 for d in v3.dimensions]
            assert int(np.prod(shape)) == len(t.elements) and tuple(shape) == t.shape, t.name
            for e in t.elements:
                twin = scalars[e]
                assert (twin.causality, twin.variability) == (v3.causality, v3.variability), (t.name, twin.name)
                assert {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}[twin.type] == v3.type
                assert (twin.unit or None) == (v3.unit or None), (t.name, twin.name, twin.unit, v3.unit)
            if t.causality != "output":  # an array's start values are its elements', in order
                starts = str(v3.start).split() if t.shape else [str(v3.start)]
                assert [float(x) if v3.type != "Boolean" else x == "true" for x in starts] == \
                    [float(scalars[e].start) if v3.type != "Boolean" else scalars[e].start in ("true", True)
                     for e in t.elements], t.name
            seen += sorted(set(t.elements))
        assert sorted(seen) == sorted(scalars), name  # each FMI 2.0 variable exactly once
    # the arrays are there: a host sees the beacons' positions and the ray tables as one variable each
    md = read_model_description(str(fmu_path(version_dir(fmu3_root, 3), "acoustics")))
    arrays = {v.name: v for v in md.modelVariables if v.dimensions}
    assert "beacon_positions" in arrays and arrays["beacon_positions"].dimensions[0].valueReference is not None
    assert len(md.modelVariables) < 110 < len(read_model_description(str(fmu_path(fmu_dir, "acoustics"))
                                                                       ).modelVariables)


def test_the_fmi3_model_description_lists_est_valid_as_a_boolean_output(fmu3_root):
    for name in RECEIVERS.values():
        check_description(fmu_path(version_dir(fmu3_root, 3), name))


@pytest.mark.parametrize("name", list(RECEIVERS.values()))
def test_fmi3_est_valid_is_false_before_the_first_fix_and_true_from_it_on(fmu3_root, name, tmp_path):
    """fmpy's FMI 3.0 bindings read est_valid false while est is NaN, before the first fix, and true from it on
    (test_est_valid.py: the packets and the step of the first fix)."""
    s = Fmi3Receiver(fmu_path(version_dir(fmu3_root, 3), name), name, tmp_path)
    try:
        s.set(**START)  # in initialization mode
        s.fmu.exitInitializationMode()
        valid, estimate = drive(lambda inputs: s.set(**inputs), lambda t: s.fmu.doStep(t, T),
                                lambda: (bool(s.get("est_valid")[0]), s.get(*ESTIMATE)))
    finally:
        s.fmu.terminate()
        s.fmu.freeInstance()
    check(name, valid, estimate)


def _same(a: pd.DataFrame, b: pd.DataFrame) -> None:
    pd.testing.assert_frame_equal(a, b, check_exact=True)


@pytest.mark.slow
@pytest.mark.parametrize("name, overrides", [
    ("semicircle", []), ("spiral", []), ("random", []), ("square", []), ("harbour", []), ("random-walk", []),
    ("semicircle", ["platform.system=lbl"]), ("semicircle", ["platform.system=usbl"]),
    ("random", ["receiver=ekf-seq"]), ("random", ["receiver=ukf"]), ("random", ["receiver=lsq"]),
])
def test_the_fmi3_fmus_give_the_fmi2_numbers_step_by_step(fmu3_root, fmu_dir, name, overrides):
    two = run(load_plan(name, SHORT + overrides, 5), "fmu", fmu_dir=fmu_dir)
    three = run(load_plan(name, SHORT + overrides + ["simulation.fmi_version=3"], 5), "fmu", fmu_dir=fmu3_root)
    assert len(two.timeseries) == 100 and not two.timeseries["packet_valid"].all()  # loss at work
    _same(two.timeseries, three.timeseries)
    _same(two.metrics, three.metrics)


# --------------------------------------------------------------------------- the site scenarios, nothing set

SITES = ("lbl-field", "usbl-deep")
SEED = 3
STEPS = 40
SSD = "{http://ssp-standard.org/SSP1/SystemStructureDescription}"


def _unzip(fmu: Path, into: Path) -> Path:
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(into)
    return into


def scalar_links(n_beacons: int, tables: dict) -> list[tuple[str, str, str, str]]:
    """The FMI 2.0 connections of the system as connections of FMI 3.0 variables (each array whole, checked here
    element by element): (source, output, destination, input) by FMI 3.0 names."""
    where = {}  # (component, FMI 2.0 name) -> (FMI 3.0 variable, position)
    for component, (scalars, table) in tables.items():
        for t in table:
            for k, e in enumerate(t.elements):
                where.setdefault((component, scalars[e].name), (t, k))
    links: dict[tuple, list] = {}
    for c in default_connections(n_beacons):
        (s, sk), (d, dk) = where[(c.source, c.output)], where[(c.destination, c.input)]
        links.setdefault((c.source, s.name, c.destination, d.name), []).append((sk, dk, s.size, d.size))
    for key, pairs in links.items():  # every connection is one array, whole, in order
        assert all(a == b for a, b, _, _ in pairs) and len(pairs) == pairs[0][2] == pairs[0][3], key
    return list(links)


def jacobi_fmi3(fmus: dict[str, Path], n_beacons: int, steps: int, h: float, into: Path,
                links: list[tuple[str, str, str, str]] | None = None) -> dict:
    """The FMI 3.0 FMUs stepped by fmpy's FMI 3.0 bindings with nothing set, by a Jacobi loop that moves each
    connected FMI 3.0 variable whole (``links``: by FMI 3.0 names; default :func:`scalar_links`):
    ``"component.output"`` (FMI 2.0 name) -> values (steps,)."""
    slaves, tables, vr = {}, {}, {}
    for component, fmu in fmus.items():
        md = read_model_description(str(fmu))
        slave = FMU3Slave(guid=md.guid, unzipDirectory=str(_unzip(fmu, into / component)),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName=component)
        slave.instantiate()
        slave.enterInitializationMode(startTime=0.0)
        slave.exitInitializationMode()
        slaves[component] = slave
        model = MODELS[md.coSimulation.modelIdentifier.removeprefix("sblsim_")]
        tables[component] = (model.fmu_variables(n_beacons), fmi3_variables(model.fmu_variables(n_beacons),
                                                                            n_beacons))
        vr[component] = {v.name: v.valueReference for v in md.modelVariables}
    links = links if links is not None else scalar_links(n_beacons, tables)

    def get(component: str, k: int) -> list:
        t = tables[component][1][k]
        return getattr(slaves[component], f"get{t.fmi_type}")([k], nValues=t.size)

    outputs = [(c, k) for c, (_, table) in tables.items() for k, t in enumerate(table) if t.causality == "output"]
    record = {f"{c}.{tables[c][0][e].name}": [] for c, k in outputs for e in tables[c][1][k].elements}
    t = 0.0
    for _ in range(steps):
        values = {(c, k): get(c, k) for c, k in outputs}  # Jacobi: every input from the outputs at t
        for source, output, destination, input_ in links:
            k = vr[destination][input_]
            typ = tables[destination][1][k].fmi_type
            getattr(slaves[destination], f"set{typ}")([k], values[(source, vr[source][output])])
        for slave in slaves.values():
            slave.doStep(t, h)
        t += h
        for c, k in outputs:
            now = dict(zip(tables[c][1][k].elements, get(c, k)))  # the covariance shows an entry twice
            for e, value in now.items():
                record[f"{c}.{tables[c][0][e].name}"].append(float(value))
    for slave in slaves.values():
        slave.terminate()
        slave.freeInstance()
    return {k: np.array(v) for k, v in record.items()}


def assert_sblsim_numbers(host: dict, ours: pd.DataFrame) -> None:
    for column, output in TIMESERIES_COLUMNS.items():
        np.testing.assert_allclose(host[output], ours[column].to_numpy(dtype=float), rtol=0, atol=1e-9,
                                   err_msg=f"{column} ({output})")
    assert ours["packet_valid"].any()


@pytest.mark.slow
@pytest.mark.parametrize("site", SITES)
def test_the_site_scenario_fmi3_fmus_setting_nothing_give_the_sblsim_run(site, fmu_dir, tmp_path):
    duration = f"simulation.duration={STEPS * load_plan(site).sampling_time!r}"
    plan = load_plan(site, ["simulation.master=jacobi", duration], SEED)
    folder = beacons_dir(tmp_path / "fmus", plan.n_beacons)
    args = ["fmus", "build", "--scenario", site, "--seed", str(SEED), "--set", duration, "--fmi-version", "3",
            "--out", str(folder)]
    assert main(args) == 0
    fmus = {c: fmu_path(version_dir(folder, 3), plan.model(c).name) for c in plan.sources}
    assert all(validate(f) == [] for f in fmus.values())
    ours = run(plan, "fmu", fmu_dir=fmu_dir).timeseries  # the FMI 2.0 FMUs, every parameter set by sblsim
    host = jacobi_fmi3(fmus, plan.n_beacons, plan.n_steps, plan.sampling_time, tmp_path / "run")
    assert len(ours) == plan.n_steps == STEPS
    assert_sblsim_numbers(host, ours)
    # the SSP package of FMI 3.0 FMUs: its connections, array to array, run the same numbers
    ssp = tmp_path / f"{site}.ssp"
    assert main(["ssp", "export", site, "--seed", str(SEED), "--set", duration, "--fmi-version", "3",
                 "--out", str(ssp)]) == 0
    packed = _unzip(ssp, tmp_path / "ssp")
    ssd = ET.parse(packed / "SystemStructure.ssd").getroot()
    links = [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
             for c in ssd.iter(f"{SSD}Connection")]
    assert len(links) < len(default_connections(plan.n_beacons))  # arrays: fewer connections than scalars
    sources = {e.get("name"): packed / e.get("source") for e in ssd.iter(f"{SSD}Component")}
    host = jacobi_fmi3(sources, plan.n_beacons, plan.n_steps, plan.sampling_time, tmp_path / "ssp-run", links)
    assert_sblsim_numbers(host, ours)


# --------------------------------------------------------------------------- the state machine

class Raw:
    """An FMI 3.0 instance of the target FMU called through its library directly, keeping what it logs."""

    def __init__(self, fmu: Path, into: Path, name: str = "instance", **instantiate) -> None:
        self.md = read_model_description(str(fmu))
        self.log: list[str] = []
        self.slave = FMU3Slave(guid=self.md.guid, unzipDirectory=str(_unzip(fmu, into)),
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(logMessage=lambda env, status, category, message: self.log.append(message.decode()),
                               **instantiate)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}

    def call(self, function: str, *args) -> int:
        return getattr(self.slave.dll, function)(self.slave.component, *args)

    def step(self, t: float, h: float) -> int:
        return self.step_flags(t, h)[0]

    def step_flags(self, t: float, h: float) -> tuple[int, bool, bool, bool, float]:
        """fmi3DoStep: its status, eventHandlingNeeded, terminateSimulation, earlyReturn, lastSuccessfulTime."""
        flags = [ctypes.c_bool() for _ in range(3)]
        last = ctypes.c_double()
        status = self.call("fmi3DoStep", ctypes.c_double(t), ctypes.c_double(h), ctypes.c_bool(True),
                           *[ctypes.byref(f) for f in flags], ctypes.byref(last))
        return status, flags[0].value, flags[1].value, flags[2].value, last.value

    def floats(self, name: str, n: int) -> np.ndarray:
        vrs = (ctypes.c_uint * 1)(self.vr[name])
        out = (ctypes.c_double * n)()
        assert self.call("fmi3GetFloat64", vrs, 1, out, n) == OK
        return np.array(out)

    def refused(self, status: int, text: str) -> None:
        assert status == ERROR and self.log and text in self.log[-1], (status, self.log[-3:])


def test_the_fmi3_state_machine_refuses_what_the_standard_forbids(fmu3_root, tmp_path):
    fmu = fmu_path(version_dir(fmu3_root, 3), "target")
    a, b = Raw(fmu, tmp_path / "a", "a"), Raw(fmu, tmp_path / "b", "b")
    a.refused(a.step(0.0, 0.1), "fmi3DoStep: not allowed in state Instantiated")
    for s in (a, b):
        s.slave.enterInitializationMode(startTime=0.0)
        s.slave.exitInitializationMode()
    first = []
    for k in range(20):
        assert a.step(k * 0.1, 0.1) == OK and b.step(k * 0.1, 0.1) == OK
        first.append(a.floats("pos", 3))
        assert np.array_equal(first[-1], b.floats("pos", 3))  # two instances, one process, the same numbers
    assert np.abs(first[-1] - first[0]).max() > 0.1  # it moves
    # a fixed parameter in step mode, a wrong value count, an unknown value reference
    vrs = (ctypes.c_uint * 1)(a.vr["speed"])
    a.refused(a.call("fmi3SetFloat64", vrs, 1, (ctypes.c_double * 1)(2.0), 1), "speed")
    a.refused(a.call("fmi3GetFloat64", (ctypes.c_uint * 1)(a.vr["pos"]), 1, (ctypes.c_double * 2)(), 2), "nValues")
    a.refused(a.call("fmi3GetFloat64", (ctypes.c_uint * 1)(99999), 1, (ctypes.c_double * 1)(), 1), "99999")
    a.refused(a.step(0.5, 0.1), "fmi3DoStep")  # not the FMU's time
    assert a.call("fmi3Terminate") == OK
    a.refused(a.call("fmi3Terminate"), "fmi3Terminate: not allowed in state Terminated")
    # reset: the same run again
    assert a.call("fmi3Reset") == OK
    a.slave.enterInitializationMode(startTime=0.0)
    a.slave.exitInitializationMode()
    for k in range(20):
        assert a.step(k * 0.1, 0.1) == OK
    assert np.array_equal(a.floats("pos", 3), first[-1])
    for s in (a, b):
        s.slave.freeInstance()


def test_event_mode_for_an_importer_that_uses_it(fmu3_root, tmp_path):
    """eventModeUsed: initialization ends in Event Mode (no step there), fmi3UpdateDiscreteStates has nothing to
    update, fmi3EnterStepMode leaves it; an early return at an arrival asks for event handling. Without
    eventModeUsed, fmi3EnterEventMode is refused."""
    fmu = fmu_path(version_dir(fmu3_root, 3), "acoustics")
    s = Raw(fmu, tmp_path / "e", eventModeUsed=True, earlyReturnAllowed=True)
    s.slave.enterInitializationMode(startTime=0.0)
    s.slave.exitInitializationMode()
    s.refused(s.step(0.0, 0.1), "fmi3DoStep: not allowed in state EventMode")
    need = [ctypes.c_bool(True) for _ in range(5)]
    assert s.call("fmi3UpdateDiscreteStates", *[ctypes.byref(b) for b in need], ctypes.byref(ctypes.c_double())) == OK
    assert not any(b.value for b in need)
    assert s.call("fmi3EnterStepMode") == OK
    status, handling, terminate, early, last = s.step_flags(0.0, 1.0)  # over 0.1 s slots: the first arrival ends it
    assert status == OK and early and handling and not terminate and 0.0 < last < 1.0
    assert s.call("fmi3EnterEventMode") == OK and s.call("fmi3EnterStepMode") == OK
    s.slave.freeInstance()
    plain = Raw(fmu, tmp_path / "p")
    plain.slave.enterInitializationMode(startTime=0.0)
    plain.slave.exitInitializationMode()
    plain.refused(plain.call("fmi3EnterEventMode"), "eventModeUsed=false")
    status, handling, _, early, last = plain.step_flags(0.0, 1.0)  # no early return unless allowed
    assert status == OK and not early and not handling and last == 1.0
    plain.slave.freeInstance()


def test_an_fmi3_fmu_accepts_only_its_compiled_beacon_count(fmu3_root, tmp_path):
    s = Raw(fmu_path(version_dir(fmu3_root, 3), "platform"), tmp_path / "p")
    vrs = (ctypes.c_uint * 1)(s.vr["n_beacons"])
    assert s.call("fmi3SetUInt64", vrs, 1, (ctypes.c_uint64 * 1)(4), 1) == OK
    s.refused(s.call("fmi3SetUInt64", vrs, 1, (ctypes.c_uint64 * 1)(6), 1), "n_beacons")
    s.slave.enterInitializationMode(startTime=0.0)
    s.slave.exitInitializationMode()
    out = (ctypes.c_uint64 * 1)()
    assert s.call("fmi3GetUInt64", vrs, 1, out, 1) == OK and out[0] == 4
    assert s.floats("beacon_positions", 12).reshape(4, 3)[:, 2].max() > 0  # below the surface (NED), 4 rows
    s.slave.freeInstance()


# --------------------------------------------------------------------------- early return at an arrival

def _run_at(handles: dict, plan, algorithm: str, macro_step: float, duration: float) -> dict:
    """The system of ``handles`` set up from ``plan`` (its slots every T) and stepped by the master at
    ``macro_step`` (a host's communication interval) with ``algorithm``."""
    for name, handle in handles.items():
        params, replicates = merge_params([plan], name, handle.parameters)
        handle.setup(params, replicates)
    n = int(round(duration / macro_step))
    return simulate(handles, default_connections(plan.n_beacons), plan.rates, macro_step, n, algorithm=algorithm)


def _horizontal_rms(rec: dict) -> float:
    """The horizontal RMS error over the steps with an estimate (none before the receiver's first fix)."""
    error = np.hypot(rec["receiver.est_x"] - rec["target.pos_x"], rec["receiver.est_y"] - rec["target.pos_y"])
    return float(np.sqrt(np.mean(error[np.isfinite(error)] ** 2)))


def test_the_event_master_delivers_each_range_at_its_arrival_and_a_1_s_host_keeps_every_packet(fmu3_root,
                                                                                                 fmu_dir):
    """The channel's slots are 0.1 s; a host that communicates every 1 s. On FMI 2.0 a 1 s step sends ten
    packets, of which eight find an in-flight place (the others are refused: ``overflow_travel_time``) and are
    delivered at the step's end on the lanes of the delivery, each dated at its arrival. With FMI 3.0 and early
    return, each doStep of the channel ends at the arrival of the packet it delivers (its own ``rx_time``), the
    receiver is stepped to that time with the packet, every packet is delivered, none refused, and the error stays
    that of the 0.1 s run."""
    plan = load_plan("semicircle", ["simulation.duration=60"], 2)
    two = make_handles("fmu", fmu_dir, plan.n_beacons, dict(plan.sources))
    three = make_handles("fmu", fmu3_root, plan.n_beacons, dict(plan.sources), fmi_version=3, early_return=True)
    try:
        channel, receiver = three["acoustics"], three["receiver"]
        seq, rx = (channel.output_names.index(n) for n in ("packet_seq", "rx_time"))
        returns, fed, ends = [], [], []
        step_until, set_inputs, do_step = channel.step_until, receiver.set_input_vector, receiver.do_step

        def channel_step(t, h):
            reached = step_until(t, h)
            out = channel.output_vector()
            returns.append((t, h, reached, out[seq, 0], out[rx, 0]))
            return reached

        def receiver_inputs(values):
            fed.append(values[receiver.input_names.index("packet_seq"), 0])
            set_inputs(values)

        def receiver_step(t, h):
            ends.append((t + h, fed[-1]))
            do_step(t, h)

        channel.step_until, receiver.set_input_vector, receiver.do_step = channel_step, receiver_inputs, receiver_step
        event = _run_at(three, plan, "event", 1.0, 60.0)
        reference = _run_at(two, plan, "gauss-seidel", 0.1, 60.0)
        slow = _run_at(two, plan, "gauss-seidel", 1.0, 60.0)
    finally:
        close_handles(two)
        close_handles(three)
    early = [r for r in returns if r[2] < r[0] + r[1] - 1e-9]
    assert len(early) > 500  # the 0.1 s slots of a minute: almost every packet ends a step
    for t, h, reached, _, arrival in early:  # at the channel's own arrival epoch, inside the step
        assert reached == pytest.approx(arrival, abs=1e-12) and t < arrival < t + h
    delivered = {packet: arrival for _, _, _, packet, arrival in returns}
    for packet, arrival in delivered.items():  # the receiver has a step ending at each arrival, with the packet
        if packet > 0:
            assert any(abs(end - arrival) < 1e-9 and seen == packet for end, seen in ends), packet
    # every packet of the 0.1 s run delivered, none overflowing; the FMI 2.0 host at 1 s refuses some
    assert event["acoustics.packet_seq"][-1, 0] == reference["acoustics.packet_seq"][-1, 0] > 550
    assert event["acoustics.overflow_travel_time"].max() == 0.0 < slow["acoustics.overflow_travel_time"].max()
    assert np.all(slow["acoustics.lane8_packet_seq"][1:] > 0)  # eight lanes filled at each step's end
    assert _horizontal_rms(event) < 1.5 * _horizontal_rms(reference)
    assert _horizontal_rms(slow) < 1.5 * _horizontal_rms(reference)


@pytest.mark.parametrize("name, overrides", [("semicircle", []), ("lbl-field", ["simulation.duration=60"])])
def test_at_the_scenarios_own_step_the_event_master_gives_the_gauss_seidel_numbers(fmu3_root, fmu_dir, name,
                                                                                    overrides):
    """Slots every T and a receiver on its own clock: ending the channel's and the receiver's steps at the
    arrivals changes the numbers by rounding only (an OWTT and a two-way LBL site)."""
    plan = load_plan(name, SHORT[1:] + overrides, 4)
    gauss_seidel = run(plan, "fmu", fmu_dir=fmu_dir).timeseries
    event = run(load_plan(name, SHORT[1:] + overrides + ["simulation.master=event", "simulation.fmi_version=3"], 4),
                "fmu", fmu_dir=fmu3_root).timeseries
    assert list(event.columns) == list(gauss_seidel.columns) and len(event) == len(gauss_seidel)
    for column in gauss_seidel.columns:
        np.testing.assert_allclose(event[column].to_numpy(dtype=float), gauss_seidel[column].to_numpy(dtype=float),
                                   rtol=0, atol=1e-9, err_msg=column)


def test_sblsim_run_master_event_needs_fmi3_fmus(fmu_dir):
    with pytest.raises(ModelError, match="event needs the fmu engine on FMI 3.0 FMUs"):
        run(load_plan("semicircle", ["simulation.duration=1", "simulation.master=event"], 1), "fmu", fmu_dir=fmu_dir)
    with pytest.raises(ModelError, match="event needs"):
        run(load_plan("semicircle", ["simulation.duration=1", "simulation.master=event"], 1), "local")
