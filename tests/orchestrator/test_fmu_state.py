"""FMI 2.0 FMU state (fmi2GetFMUstate / fmi2SetFMUstate / fmi2FreeFMUstate, serialization) of the four components' FMUs.

The whole system is stepped through fmpy by the real master
(:func:`sblsim.orchestrator.cosim.master.simulate`, Gauss-Seidel over the default
connections); states are taken and restored on every component at once.
"""

from __future__ import annotations

import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from sblsim.fmus.build import fmu_path
from sblsim.models import COMPONENTS
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.connections import default_connections
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.master import simulate
from sblsim.orchestrator.cosim.run import merge_params

N_BEFORE = 20  # macro steps before the state is saved
N_AFTER = 30   # macro steps replayed from the saved state

SCENARIOS = {
    "semicircle": [],
    # lost packets (range 0, packet_valid false) and outliers
    "semicircle-lossy": ["acoustics.loss_pct=40", "acoustics.outlier_pct=20"],
}


@pytest.fixture
def system(fmu_dir, request):
    """The four FMU handles of a scenario of :data:`SCENARIOS`, set up like ``run_batch`` does.

    Yields the handles and the master's settings (connections, rates, macro step).
    """
    cfg = load_config("semicircle", SCENARIOS[request.param], seed=3)
    handles = make_handles("fmu", fmu_dir)
    try:
        for name, handle in handles.items():
            params, reps = merge_params([cfg], name)
            handle.setup(params, reps)
        sim = cfg["simulation"]
        yield handles, {"connections": default_connections(), "rates": {"receiver": sim["ekf_rate_ratio"]},
                        "macro_step": sim["sampling_time"]}
    finally:
        close_handles(handles)


def steps(handles, master, n, first):
    """Run the master for ``n`` macro steps from macro step ``first``; every output of every step."""
    return simulate(handles, master["connections"], master["rates"], master["macro_step"], n,
                    t0=first * master["macro_step"])


def outputs(handles):
    return {name: handle.get_outputs() for name, handle in handles.items()}


def save(handles):
    return {name: handle.fmu.getFMUstate() for name, handle in handles.items()}


def restore(handles, states):
    for name, handle in handles.items():
        handle.fmu.setFMUstate(states[name])


def free(handles, states):
    for name, state in states.items():
        handles[name].fmu.freeFMUstate(state)


def assert_identical(a, b):
    """Same outputs, exactly: same keys, shapes, dtypes, values and NaN positions."""
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key, strict=True)


def assert_same_outputs(a, b):
    """Same current outputs of every component (as :func:`outputs` gives them), NaN equal to NaN."""
    assert_identical({f"{c}.{n}": v for c in a for n, v in a[c].items()},
                     {f"{c}.{n}": v for c in b for n, v in b[c].items()})


def differing(a, b):
    """Recorded outputs whose values differ somewhere (NaN equal to NaN)."""
    return [k for k in a if k != "time" and not np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f")]


def head(record, n):
    return {k: v[:n] for k, v in record.items()}


@pytest.mark.parametrize("name", list(COMPONENTS))
def test_fmu_declares_get_set_and_serialized_state(fmu_dir, name):
    with zipfile.ZipFile(fmu_path(fmu_dir, name)) as archive:
        cosim = ET.fromstring(archive.read("modelDescription.xml")).find("CoSimulation")
    assert cosim.get("canGetAndSetFMUstate") == "true"
    assert cosim.get("canSerializeFMUstate") == "true"  # the state is plain numbers (tests/fmus_tests)


@pytest.mark.parametrize("system", list(SCENARIOS), indirect=True)
def test_restored_state_replays_the_system_exactly(system, request):
    """Save every component at step N, run M steps, restore, re-run them: every output identical, twice."""
    handles, master = system
    first = steps(handles, master, N_BEFORE, 0)
    at_save = outputs(handles)
    states = save(handles)
    try:
        original = steps(handles, master, N_AFTER, N_BEFORE)
        at_end = outputs(handles)

        restore(handles, states)
        assert_same_outputs(outputs(handles), at_save)
        replay = steps(handles, master, N_AFTER, N_BEFORE)
        assert_identical(original, replay)
        assert_same_outputs(outputs(handles), at_end)

        # the same state restored a second time (it was replayed from once) replays again
        restore(handles, states)
        assert_same_outputs(outputs(handles), at_save)
        assert_identical(original, steps(handles, master, N_AFTER, N_BEFORE))
    finally:
        free(handles, states)
    # not degenerate: the system moves and estimates
    assert np.ptp(first["target.pos_x"]) > 0 and np.isfinite(original["receiver.est_x"]).all()
    if request.node.callspec.id == "semicircle-lossy":
        # lost packets inside the replayed window
        lost = original["acoustics.packet_valid"] < 0.5
        assert lost.any() and not lost.all() and np.all(original["acoustics.range"][lost] == 0.0)


@pytest.mark.parametrize("system", ["semicircle"], indirect=True)
def test_state_restored_later_changes_the_next_outputs(system):
    """A state saved at step N, restored after step N + M: the next outputs are not the continuation's."""
    handles, master = system
    steps(handles, master, N_BEFORE, 0)
    at_save = outputs(handles)
    early = save(handles)
    try:
        original = steps(handles, master, N_AFTER, N_BEFORE)
        late = save(handles)
        try:
            # what going on from step N + M gives, and that restoring N + M gives it again
            continuation = steps(handles, master, 5, N_BEFORE + N_AFTER)
            after_continuation = outputs(handles)
            restore(handles, late)
            assert_identical(continuation, steps(handles, master, 5, N_BEFORE + N_AFTER))
        finally:
            free(handles, late)
        # now restore step N, after step N + M + 5
        restore(handles, early)
        restored = outputs(handles)
        rewound = steps(handles, master, 5, N_BEFORE)
    finally:
        free(handles, early)
    # the restore changed the instances: outputs back to step N, not those it had
    assert_same_outputs(restored, at_save)
    assert any(not np.array_equal(restored[c][n], after_continuation[c][n], equal_nan=True)
               for c in restored for n in restored[c] if restored[c][n].dtype.kind == "f")
    # the next outputs are those that followed step N, not the continuation's
    assert_identical(head(original, 5), rewound)
    changed = differing(continuation, rewound)
    assert {"target.pos_x", "acoustics.range", "receiver.est_x"} <= set(changed)
