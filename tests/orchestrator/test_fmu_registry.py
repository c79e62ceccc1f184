"""Each FMU is loaded once per process and re-used (pythonfmu FMUs cannot be loaded twice)."""

import shutil

import pytest

from models.core import ModelError
from orchestrator.config import load_config
from orchestrator.run import close_handles, make_handles, run


def test_handles_are_reused_and_not_shared_between_concurrent_runs(fmu_dir):
    first = make_handles("fmu", fmu_dir)
    try:
        with pytest.raises(ModelError, match="in use by another run"):
            make_handles("fmu", fmu_dir)
    finally:
        close_handles(first)
    again = make_handles("fmu", fmu_dir)
    try:
        assert all(again[name] is first[name] for name in first)
    finally:
        close_handles(again)
    # and a run on its own handles still works after that
    cfg = load_config("semicircle", ["simulation.duration=2"], seed=4)
    assert run(cfg, "fmu", fmu_dir=fmu_dir).timeseries.equals(run(cfg, "fmu", fmu_dir=fmu_dir).timeseries)


def test_another_file_of_a_loaded_fmu_is_refused_clearly(fmu_dir, tmp_path):
    close_handles(make_handles("fmu", fmu_dir))  # make sure this process has loaded them
    copy = tmp_path / "copy"
    shutil.copytree(fmu_dir, copy)
    with pytest.raises(ModelError, match="already loaded in this process"):
        make_handles("fmu", copy)
    # the failed attempt released what it had opened
    close_handles(make_handles("fmu", fmu_dir))
