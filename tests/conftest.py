"""Shared fixtures of the sblsim test suite."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

#: The project's plain C FMI host (one FMU twice, or a system of FMUs: its header comment).
C_HOST = Path(__file__).with_name("fmus_tests") / "c_host.c"


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


@pytest.fixture(scope="session")
def c_host(tmp_path_factory) -> Path:
    """The plain C host (:data:`C_HOST`), compiled with the system compiler and the FMI headers fmpy ships."""
    from sblsim.fmus.codegen import fmi_headers_dir
    from sblsim.fmus.compiler import find_compiler

    exe = tmp_path_factory.mktemp("host") / "c_host"
    cc = find_compiler("system")
    subprocess.run([*cc.command, "-std=c99", "-O1", f"-I{fmi_headers_dir()}", str(C_HOST), "-o", str(exe), "-ldl"],
                   check=True, capture_output=True)
    return exe
