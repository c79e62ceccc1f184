"""Shared fixtures of the sblsim test suite."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory, request):
    """Directory holding the FMUs (one per model of ``models.MODELS``) freshly built with ``build_all``.

    Session-scoped and lazy: the FMUs are built once, and only when a test
    asks for this fixture.
    """
    from filelock import FileLock

    from sblsim.fmus.build import build_all
    from sblsim.models import MODELS

    def build(directory):
        paths = build_all(directory)
        assert sorted(p.name for p in paths) == sorted(f"sblsim_{n}.fmu" for n in MODELS)
        assert all(p.is_file() for p in paths)
        (directory / "complete").write_text("built\n")
        return directory

    if not hasattr(request.config, "workerinput"):  # one process: its own folder
        return build(tmp_path_factory.mktemp("fmus"))
    # pytest-xdist: the workers of this run share one build (their temporary folders have one parent per run)
    shared = tmp_path_factory.getbasetemp().parent / "fmus"
    with FileLock(str(shared) + ".lock"):
        if not (shared / "complete").is_file():
            shared.mkdir(exist_ok=True)
            build(shared)
    return shared
