"""The engines' shared interface: handles answer for their compiled batch, FMI failures are named, the record
memory is re-used by its owner."""

from types import SimpleNamespace

import numpy as np
import pytest

from sblsim.models.errors import FMICallError, ModelError, SblsimError
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.fmu_engine import FmuHandle
from sblsim.orchestrator.cosim.fmu_files import check_status
from sblsim.orchestrator.cosim.handles import ComponentHandle
from sblsim.orchestrator.cosim.local_engine import LocalHandle
from sblsim.orchestrator.cosim.master import RecordBuffer
from sblsim.orchestrator.cosim.run import merge_params


def test_both_handles_have_every_method_of_the_interface():
    methods = {n for n, v in vars(ComponentHandle).items() if callable(v) and not n.startswith("_")}
    assert {"setup", "set_input_vector", "do_step", "output_vector", "terminate", "native_batch"} <= methods
    for cls in (LocalHandle, FmuHandle):
        assert all(callable(getattr(cls, m, None)) for m in methods), cls


def test_a_local_handle_gives_its_batch_and_a_subclass_none():
    cfg = load_config("semicircle", ["simulation.duration=1"])

    class Changed(LocalHandle):
        """A subclass may change what is exchanged: stepped by the master's Python loop."""

    for cls in (LocalHandle, Changed):
        handle = cls("target")
        assert handle.native_batch() is None  # not set up yet
        handle.setup(*merge_params([cfg], "target", handle.parameters))
        assert (handle.native_batch() is handle.batch) == (cls is LocalHandle)
        handle.close()


@pytest.mark.parametrize("status, name", [(2, "fmi2Discard"), (3, "fmi2Error"), (4, "fmi2Fatal"),
                                          (5, "fmi2Pending"), (9, "an unknown status")])
def test_a_failed_fmi_call_names_the_function_and_the_status(status, name):
    with pytest.raises(FMICallError, match=rf"^fmu: r\.fmu \(receiver\): fmi2DoStep returned {name} \({status}\)") \
            as caught:
        check_status(status, "fmi2DoStep", "r.fmu (receiver)", "slot_period is outside [0.001, 60]")
    assert (caught.value.function, caught.value.status, caught.value.log) == \
        ("fmi2DoStep", status, "slot_period is outside [0.001, 60]")
    assert isinstance(caught.value, SblsimError) and not isinstance(caught.value, ModelError)
    check_status(0, "fmi2DoStep", "r.fmu (receiver)")
    check_status(1, "fmi2DoStep", "r.fmu (receiver)")  # a warning is not a failure (as fmpy)


def test_the_raw_calls_of_an_fmu_handle_are_checked():
    """FmuHandle's prepared-array calls go through the same check (a stand-in for the FMU's functions)."""
    handle = object.__new__(FmuHandle)
    handle.fmu = SimpleNamespace(component=None, dll=SimpleNamespace(fmi2DoStep=lambda *args: 3))
    handle.path, handle.component = SimpleNamespace(name="receiver.fmu"), "receiver"
    with pytest.raises(FMICallError, match=r"receiver\.fmu \(receiver\): fmi2DoStep returned fmi2Error \(3\)"):
        handle.do_step(0.0, 0.1)


def test_a_record_buffer_re_uses_its_memory():
    records = RecordBuffer()
    first = records.take(1000)
    assert first.shape == (1000,)
    assert np.shares_memory(records.take(600), first)  # smaller: the same memory
    larger = records.take(2000)
    assert not np.shares_memory(larger, first) and np.shares_memory(records.take(2000), larger)


def test_a_wrapper_that_passes_attributes_on_is_not_a_compiled_batch():
    from sblsim.orchestrator.cosim.master import _native_batch

    class Passing:
        def __init__(self, handle):
            self.handle = handle

        def __getattr__(self, name):
            return getattr(self.handle, name)

    handle = LocalHandle("target")
    handle.batch = object()
    assert _native_batch(handle) is handle.batch and _native_batch(Passing(handle)) is None
