"""FMU instances are made once per process and re-used between runs; concurrent runs get their own."""

import zipfile

import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.engines import close_handles, make_handles, open_fmu
from sblsim.orchestrator.cosim.run import run


def test_instances_are_reused_and_concurrent_runs_get_their_own(fmu_dir):
    first = make_handles("fmu", fmu_dir)
    try:
        second = make_handles("fmu", fmu_dir)  # native FMUs: any number of instances
        try:
            assert all(second[name] is not first[name] for name in first)
        finally:
            close_handles(second)
    finally:
        close_handles(first)
    again = make_handles("fmu", fmu_dir)
    try:
        assert all(again[name] is first[name] or again[name] is second[name] for name in first)
    finally:
        close_handles(again)
    # and a run on its own handles still works after that, with the same numbers
    cfg = load_config("semicircle", ["simulation.duration=2"], seed=4)
    assert run(cfg, "fmu", fmu_dir=fmu_dir).timeseries.equals(run(cfg, "fmu", fmu_dir=fmu_dir).timeseries)


def test_an_fmu_that_declares_one_instance_per_process_is_not_instantiated_twice(fmu_dir, tmp_path):
    """A user's FMU that can be instantiated only once per process (e.g. one built with pythonfmu)."""
    once = tmp_path / "once.fmu"
    with zipfile.ZipFile(fmu_dir / "sblsim_receiver.fmu") as src, zipfile.ZipFile(once, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b'canBeInstantiatedOnlyOncePerProcess="false"',
                                    b'canBeInstantiatedOnlyOncePerProcess="true"')
            dst.writestr(item, data)
    handle = open_fmu("receiver", once)
    try:
        with pytest.raises(ModelError, match="can be instantiated only once per process"):
            open_fmu("receiver", once)
    finally:
        handle.terminate()
    assert open_fmu("receiver", once) is handle  # released: the same instance again
    handle.terminate()


def test_a_description_is_read_once_per_file_and_again_when_the_file_changes(fmu_dir, tmp_path, monkeypatch):
    """A pooled instance is reopened for every run: its model description is parsed once, and again (a new
    instance of the new file) when the file at that path has been replaced."""
    import shutil

    import sblsim.orchestrator.cosim.fmu_files as fmu_files

    reads = []
    real = fmu_files.read_description
    monkeypatch.setattr(fmu_files, "read_description", lambda *a, **k: reads.append(a[1]) or real(*a, **k))
    path = tmp_path / "receiver.fmu"
    shutil.copyfile(fmu_dir / "sblsim_receiver.fmu", path)
    first = open_fmu("receiver", path)
    first.terminate()
    assert open_fmu("receiver", path) is first and len(reads) == 1  # the same file: not parsed again
    first.terminate()
    with zipfile.ZipFile(fmu_dir / "sblsim_receiver.fmu") as src, zipfile.ZipFile(path, "w") as dst:
        for item in src.namelist():  # the same FMU with another description, written over the file
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b'description="', b'description="Rewritten. ', 1)
            dst.writestr(item, data)
    second = open_fmu("receiver", path)
    try:
        assert len(reads) == 2 and second is not first
        assert second.variables.keys() == first.variables.keys()
    finally:
        second.terminate()
    path.unlink()
    with pytest.raises(ModelError, match="not found"):
        open_fmu("receiver", path)
