"""Gauss-Seidel and Jacobi master algorithms on a hand-worked chain of toy components."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.orchestrator.cosim.connections import Connection
from sblsim.orchestrator.cosim.master import simulate


class Counter:
    """Output ``n``: the number of doSteps taken; input ``u`` copied to output ``seen`` at each step.

    A handle as the master sees it: named inputs and outputs, one vector each.
    """

    input_names = ["u"]
    output_names = ["n", "seen"]

    def __init__(self):
        self.n, self.u, self.seen = 0, 0.0, 0.0

    def set_input_vector(self, values):
        self.u = float(values[0, 0])

    def do_step(self, t, h):
        self.n += 1
        self.seen = self.u

    def output_vector(self):
        return np.array([[float(self.n)], [self.seen]])


def chain(algorithm, rates=None, steps=3):
    # a -> b -> c: b sees a's count, c sees b's count
    handles = {"a": Counter(), "b": Counter(), "c": Counter()}
    conns = [Connection("a", "n", "b", "u"), Connection("b", "n", "c", "u")]
    return simulate(handles, conns, rates or {}, 1.0, steps, algorithm=algorithm)


def test_gauss_seidel_passes_this_steps_outputs_down_the_chain():
    rec = chain("gauss-seidel")
    # after macro step k (1-based) a has counted k and b saw k, c saw b's k
    assert rec["b.seen"][:, 0].tolist() == [1, 2, 3]
    assert rec["c.seen"][:, 0].tolist() == [1, 2, 3]


def test_jacobi_uses_the_outputs_at_the_start_of_the_macro_step():
    rec = chain("jacobi")
    # b and c see the counts of the previous communication point (0 at the first)
    assert rec["b.seen"][:, 0].tolist() == [0, 1, 2]
    assert rec["c.seen"][:, 0].tolist() == [0, 1, 2]


def test_jacobi_multi_rate_holds_inputs_over_the_sub_steps():
    rec = chain("jacobi", rates={"b": 4})
    # b takes 4 sub-steps per macro step with a's count from the start of it
    assert rec["b.n"][:, 0].tolist() == [4, 8, 12]
    assert rec["b.seen"][:, 0].tolist() == [0, 1, 2]
    assert rec["c.seen"][:, 0].tolist() == [0, 4, 8]


def test_unknown_algorithm_is_refused():
    with pytest.raises(ValueError, match="simulation.master: 'newton' is not one of gauss-seidel, jacobi"):
        chain("newton")


class Plain:
    """A LocalHandle seen through a wrapper: the master takes its Python loop for it."""

    def __init__(self, handle):
        self._handle = handle
        self.input_names, self.output_names = handle.input_names, handle.output_names

    def set_input_vector(self, values):
        self._handle.set_input_vector(values)

    def do_step(self, t, h):
        self._handle.do_step(t, h)

    def output_vector(self):
        return self._handle.output_vector()


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("batch", [1, 7])
def test_the_compiled_master_loop_equals_the_python_one(algorithm, batch, monkeypatch):
    """The compiled loop (every handle a compiled batch) and the Python loop give identical records, with a
    receiver at three steps per macro step, loss and multipath."""
    from sblsim.orchestrator.cosim.config import load_config
    from sblsim.orchestrator.cosim.connections import default_connections
    from sblsim.orchestrator.cosim.local_engine import LocalHandle
    from sblsim.orchestrator.cosim.run import merge_params, with_replicates

    cfg = load_config("random", ["acoustics.loss_pct=20", "acoustics.outlier_pct=10", "simulation.duration=20"],
                      seed=4)
    cfgs = with_replicates(cfg, range(batch))
    from sblsim.orchestrator.cosim import master

    original, compiled = master._simulate_native, []

    def counting(*args, **kwargs):
        compiled.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(master, "_simulate_native", counting)
    records = []
    for wrap in (False, True):
        handles = {}
        for name in ("platform", "acoustics", "target", "receiver"):
            handle = LocalHandle(name)
            params, reps = merge_params(cfgs, name, handle.parameters)
            handle.setup(params, reps)
            handles[name] = Plain(handle) if wrap else handle
        timing = {}
        records.append(simulate(handles, default_connections(), {"receiver": 3}, 0.1, 200, algorithm=algorithm,
                                timing=timing))
        assert set(timing) == set(handles) and all(v > 0 for v in timing.values())
    native, python = records
    assert compiled == [1]  # the unwrapped handles took the compiled loop, the wrapped ones the Python one
    assert native.keys() == python.keys() and len(native) > 60
    for name in native:
        np.testing.assert_array_equal(native[name], python[name], err_msg=name)
