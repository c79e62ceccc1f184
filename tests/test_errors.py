"""Errors by kind: each kind of :mod:`sblsim.models.errors` comes out of a real failure, and one
``except SblsimError`` catches every one of them."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from sblsim.fmus.build import cached_fmu
from sblsim.fmus.compiler import compile_library, find_compiler
from sblsim.models import MODELS
from sblsim.models.errors import (
    ArchiveError,
    CampaignError,
    CompileError,
    ConfigError,
    FMICallError,
    ModelError,
    SblsimError,
)
from sblsim.orchestrator.analysis import compute
from sblsim.orchestrator.campaign import run_campaign
from sblsim.orchestrator.campaign.errors import StudyError
from sblsim.orchestrator.campaign.study import load_study
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.engines import open_fmu
from sblsim.orchestrator.cosim.ssp import SspError
from sblsim.orchestrator.cosim.ssp_read import read_ssp
from sblsim.orchestrator.io.archives import check_members

KINDS = (ModelError, FMICallError, CompileError, ArchiveError, CampaignError)


def _caught(action) -> SblsimError:
    """What ``except SblsimError`` catches of ``action()`` (fails if it raises nothing or something else)."""
    try:
        action()
    except SblsimError as exc:
        return exc
    pytest.fail("no error raised")


def _kind(exc: SblsimError) -> type:
    """The one kind an error belongs to."""
    kinds = [k for k in KINDS if isinstance(exc, k)]
    assert len(kinds) == 1, kinds
    return kinds[0]


def test_the_kinds_are_distinct_below_one_root():
    assert all(issubclass(k, SblsimError) for k in KINDS)
    assert [k for k in KINDS if issubclass(k, ValueError)] == [ModelError]  # kept a ValueError, as it was
    assert issubclass(ConfigError, ModelError) and issubclass(StudyError, ConfigError)
    assert issubclass(SspError, ArchiveError)


def test_an_invalid_value_is_a_model_error():
    exc = _caught(lambda: load_config("semicircle", ["acoustics.loss_pct=150"]))
    assert _kind(exc) is ModelError and isinstance(exc, ValueError)
    assert str(exc).startswith("acoustics.loss_pct: 150.0 is outside the allowed range [0, 100]")
    exc = _caught(lambda: load_config("no-such-scenario"))
    assert isinstance(exc, ConfigError) and _kind(exc) is ModelError
    assert str(exc).startswith("scenario: unknown scenario 'no-such-scenario'")
    exc = _caught(lambda: load_study({"study": {"name": "s", "scenarios": ["semicircle"], "replicates": 0}}))
    assert isinstance(exc, StudyError) and _kind(exc) is ModelError and "replicates" in str(exc)


def test_a_failed_fmi_call_is_an_fmi_call_error():
    handle = open_fmu("receiver", cached_fmu(MODELS["receiver"]))
    try:
        handle.setup({}, [0])
        values = np.zeros((len(handle.input_names), 1))
        values[handle.input_names.index("range"), 0] = 1e300
        exc = _caught(lambda: handle.set_input_vector(values))
    finally:
        handle.terminate()
    assert _kind(exc) is FMICallError
    assert (exc.function, exc.status) == ("fmi2SetReal", 3)
    assert "range = 1e+300 is outside the allowed range" in exc.log and exc.log in str(exc)


def test_a_failed_compilation_is_a_compile_error(tmp_path):
    source = tmp_path / "broken.c"
    source.write_text("int f(void) { return undeclared_name; }\n")
    exc = _caught(lambda: compile_library(find_compiler("auto"), [source], tmp_path / "libbroken.so"))
    assert _kind(exc) is CompileError
    assert "failed for broken.c" in str(exc) and "undeclared_name" in str(exc)


def test_a_hostile_archive_is_an_archive_error(tmp_path):
    path = tmp_path / "evil.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("../outside.txt", "x")
    with zipfile.ZipFile(path) as archive:
        exc = _caught(lambda: check_members(archive, "evil.zip"))
    assert _kind(exc) is ArchiveError and "../outside.txt" in str(exc)
    (tmp_path / "not.ssp").write_text("not a zip")
    exc = _caught(lambda: read_ssp(tmp_path / "not.ssp"))
    assert isinstance(exc, SspError) and _kind(exc) is ArchiveError


def test_a_campaign_that_cannot_run_is_a_campaign_error(tmp_path):
    (tmp_path / "taken").write_text("a file where the campaign folder would go")
    study = load_study({"study": {"name": "s", "scenarios": ["semicircle"], "replicates": 1,
                                  "set": ["simulation.duration=1"]},
                        "factors": [{"name": "loss", "key": "acoustics.loss_pct", "low": 0, "high": 10}]})
    exc = _caught(lambda: run_campaign(study, tmp_path / "taken", workers=1))
    assert _kind(exc) is CampaignError and "is not a directory" in str(exc)
    exc = _caught(lambda: compute(tmp_path / "nothing"))
    assert _kind(exc) is CampaignError and "runs.parquet" in str(exc)
