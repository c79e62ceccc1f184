"""Every input of every FMU has a declared range; fmi2SetReal and fmi2SetInteger refuse a value outside it.

A finite but absurd input (a range of 1e300 m) would otherwise give fmi2OK and non-finite outputs. The
ranges (:data:`sblsim.models.declarations.SIGNAL_RANGES`) are written as ``min``/``max`` into
``modelDescription.xml`` and compiled into the FMU; at their edges every output stays finite.
"""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException

from sblsim.fmus.build import fmu_path
from sblsim.models import MODELS
from tests.fmus_tests.test_fmi_semantics import Slave, finite_but_the_estimate_before_a_fix

T = 0.1
WITH_INPUTS = [name for name, model in MODELS.items() if model.inputs(4)]
RECEIVERS = [name for name in WITH_INPUTS if name.startswith("receiver")]


def _range(v) -> str:
    unit = f" {v.unit}" if v.unit and v.unit != "1" else ""
    return f"[{v.min:g}, {v.max:g}]{unit}"


def test_every_numeric_input_declares_its_range():
    assert WITH_INPUTS == ["acoustics", "receiver", "receiver_ekf_seq", "receiver_ukf", "receiver_lsq"]
    for name in WITH_INPUTS:
        for v in MODELS[name].inputs(4):
            if v.fmi_type in ("Real", "Integer"):
                assert v.min is not None and v.max is not None and v.min <= v.start <= v.max, (name, v.name)


@pytest.mark.parametrize("name", WITH_INPUTS)
def test_the_model_description_carries_the_input_ranges(fmu_dir, name):
    md = {v.name: v for v in read_model_description(str(fmu_path(fmu_dir, name))).modelVariables}
    for v in MODELS[name].inputs(4):
        if v.fmi_type in ("Real", "Integer"):
            assert (float(md[v.name].min), float(md[v.name].max)) == (v.min, v.max), v.name


@pytest.mark.parametrize("name", WITH_INPUTS)
def test_a_huge_input_is_refused_with_one_log_line(fmu_dir, name):
    """1e300 and -1e300 on every Real input, -1 on every Integer one, before and after initialization."""
    s = Slave(str(fmu_path(fmu_dir, name)))
    for started in (False, True):
        if started:
            s.start()
        for v in MODELS[name].inputs(4):
            if v.fmi_type == "Boolean":
                continue
            values = (1e300, -1e300) if v.fmi_type == "Real" else (-1,)
            for value in values:
                s.log.clear()
                with pytest.raises(FMICallException):
                    s.set(**{v.name: value})
                shown = f"{value:g}"
                assert s.log == [f"fmi2Set{v.fmi_type}: {v.name} = {shown} is outside the allowed range {_range(v)}"]
            s.set(**{v.name: v.max})  # the edge itself is allowed
    s.fmu.doStep(0.0, T)
    finite_but_the_estimate_before_a_fix(s.output_names(), s.outputs())  # a receiver's: NaN before its first fix


def test_the_message_of_a_huge_range():
    v = next(v for v in MODELS["receiver"].inputs(4) if v.name == "range")
    assert _range(v) == "[-1e+07, 1e+07] m"


def _run(slave: Slave, inputs, steps: int = 40) -> np.ndarray:
    rows = []
    for k in range(steps):
        slave.set(**inputs(k))
        slave.fmu.doStep(k * T, T)
        rows.append(slave.outputs())
    return np.array(rows)


@pytest.mark.parametrize("edge", ["min", "max", "mixed"])
def test_the_channel_at_the_edges_of_its_ranges_gives_finite_outputs(fmu_dir, edge):
    s = Slave(str(fmu_path(fmu_dir, "acoustics"))).start(loss_pct=10.0, outlier_pct=10.0)
    inputs = MODELS["acoustics"].inputs(4)
    pick = {"min": lambda k, v: v.min, "max": lambda k, v: v.max,
            "mixed": lambda k, v: v.min if k % 2 else v.max}[edge]
    values = {v.name: pick(j, v) for j, v in enumerate(inputs)}
    out = _run(s, lambda k: values)
    assert np.all(np.isfinite(out))
    assert s.get("packet_seq")[0] > 0


@pytest.mark.parametrize("name", RECEIVERS)
@pytest.mark.parametrize("edge", ["min", "max", "mixed"])
def test_a_receiver_at_the_edges_of_its_ranges_gives_finite_outputs(fmu_dir, name, edge):
    """A packet every step, every numeric input but the counters at an edge of its range: every output finite but
    the estimate before the first fix (NaN); a Kalman receiver has one from its first packet on."""
    s = Slave(str(fmu_path(fmu_dir, name))).start()
    declared = {v.name: v for v in MODELS[name].inputs(4)}

    def at(k: int, which: str) -> float:
        v = declared[which]
        lo, hi = v.min, v.max
        return {"min": lo, "max": hi, "mixed": lo if k % 2 else hi}[edge]

    def inputs(k: int) -> dict:
        out = {n: at(k + j, n) for j, n in enumerate(("range", "beacon_x", "beacon_y", "beacon_z", "depth"))}
        out.update(packet_seq=k + 1, beacon_id=k % 4 + 1, packet_valid=True,
                   tx_time=declared["tx_time"].min if edge == "min" else k * T)  # min: long past
        return out

    out = _run(s, inputs)
    estimated = finite_but_the_estimate_before_a_fix(s.output_names(), out)
    if name != "receiver_lsq":  # a Kalman receiver updates with the first packet; lsq needs a fix of the edges
        assert estimated.all(), estimated
