"""The receiver takes packets on its own clock, whatever steps a host takes.

A host that adds its communication step up in floating point (OMSimulator does) ends a 94.2 s run at
94.19999999999892 s and takes one more step of about 1e-12 s. Under Jacobi stepping, the packet of the last
slot becomes visible to the receiver only in that step. A receiver that took it there would run a whole update
that an exact host never runs (it moved the final estimate by 5 cm); on its own clock the receiver reaches no
new tick in such a step and leaves the packet for its next tick. Steps of the receiver's own communication step
take every packet as before.
"""

from __future__ import annotations

import tempfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from sblsim.fmus.build import fmu_path
from sblsim.models import MODELS, RECEIVERS
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run

INPUTS = [v.name for v in MODELS["receiver"].inputs()]
T = 0.1


@pytest.fixture(scope="module")
def recorded():
    cfg = load_config("semicircle", seed=4)  # one pass: 942 slots of 0.1 s, 94.2 s
    return cfg, run(cfg).timeseries


class Receiver:
    """A receiver FMU stepped by hand, as a host steps it."""

    def __init__(self, path, params):
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.types = {v.name: v.type for v in md.modelVariables}
        self._unzipped = tempfile.TemporaryDirectory(prefix="sblsim-test-")  # removed with the instance
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path), self._unzipped.name),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName="receiver")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(params)
        self.fmu.exitInitializationMode()

    def set(self, values):
        for name, value in values.items():
            kind = self.types[name]
            if kind == "Real":
                self.fmu.setReal([self.vr[name]], [float(value)])
            elif kind == "Integer":
                self.fmu.setInteger([self.vr[name]], [int(value)])
            else:
                self.fmu.setBoolean([self.vr[name]], [bool(value)])

    def estimate(self):
        return np.array(self.fmu.getReal([self.vr["est_x"], self.vr["est_y"], self.vr["est_z"]]))


def test_a_tiny_last_step_takes_no_packet_and_a_whole_step_does(fmu_dir, recorded):
    cfg, series = recorded
    model = MODELS[RECEIVERS["ekf"]]  # a choice travels as its index
    params = model.fmi_values({k: v for k, v in make_plan(cfg).component_parameters("receiver").items() if k in
                               {p.name for p in model.fmu_parameters_declared()}})
    assert params["communication_step"] == pytest.approx(T)
    rows = [{n: getattr(r, n, 0.0) for n in INPUTS} for r in series.itertuples(index=False)]  # (lanes: empty)
    n = len(rows)
    path = fmu_path(fmu_dir, "receiver")
    # a Jacobi host: in its step from t_j the receiver sees the packet the channel produced at the end of the step
    # before (recorded as row j - 1, transmitted at t_j); the host adds its steps up in floating point
    host, t = Receiver(path, params), 0.0
    for j in range(n):
        if j:
            host.set(rows[j - 1])
        host.fmu.doStep(t, T)
        t += T
    assert 0 < n * T - t < 1e-9  # 94.19999999999892: a picosecond short of the stop time
    before = host.estimate()
    host.set(rows[n - 1])  # the last slot's packet (transmitted at the stop time), visible only now
    host.fmu.doStep(t, n * T - t)  # the host's closing step of about 1e-12 s
    # no tick of the receiver's clock, so no update: only the prediction over 1e-12 s (0.5 m/s x 1e-12 s)
    assert np.linalg.norm(host.estimate() - before) < 1e-9
    host.fmu.doStep(n * T, T)  # the receiver's next tick takes the packet
    assert np.linalg.norm(host.estimate() - before) > 1e-4
    # an exact host stepping at the receiver's communication step gives the recorded estimate at every step
    exact = Receiver(path, params)
    for k, row in enumerate(rows):
        exact.set(row)
        exact.fmu.doStep(k * T, T)
        np.testing.assert_allclose(exact.estimate(), series[["est_x", "est_y", "est_z"]].to_numpy()[k], atol=1e-9)
