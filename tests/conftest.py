"""Shared fixtures of the sblsim test suite, and how pytest-xdist shares the tests between the cores.

The suite runs on every core (``-n auto``) with :class:`FileScheduling`: a test file is one unit of work (its
module fixtures made once), except where a file splits its tests into units of their own (:func:`unit_of`: the
documentation's page runs are two chains, run side by side). The units start longest first (:data:`LONGEST`),
and a worker takes its next unit only when it has run out of work, so no unit waits behind a long one while
another core idles. ``docs/architecture.md`` lists the slowest tests and the command that measures them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

# One BLAS thread per process, set before numpy loads (in this process, its pytest-xdist workers and every command
# the tests start, which inherit it): on 2 cores with 2 workers busy, OpenBLAS's second thread in each process spun
# for the core the other worker needed. The 20 seeds' sync test took 161 s with the default and 74 s with one thread
# on the same loaded cores; the benchmarks set the same (benchmarks/bench_sync_scale.py).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

#: The numerical kernels every test and every command it starts uses, set before numpy loads: OpenBLAS's
#: Haswell kernels (it otherwise picks them by the processor) and numpy's dispatch without AVX-512 (its X86_V4 group;
#: the older numpy's names beside it). A run's last bits follow the kernels, and a few of the pages' figures follow
#: decisions those bits move (docs/extending.md, "Figures a page quotes"): pinned, the pages print their figures on
#: any x86-64 processor with AVX2 and FMA, the AVX-512 machines included (whatever the environment said).
KERNELS = {"OPENBLAS_CORETYPE": "Haswell",
           "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX "
                                       "AVX512_CNL AVX512_ICL AVX512_SPR"}


def _has_avx2_and_fma(cpuinfo: str | Path = "/proc/cpuinfo") -> bool:
    """Whether the processor runs the Haswell kernels (Linux's flags of its first processor; False elsewhere)."""
    try:
        with open(cpuinfo, encoding="ascii", errors="replace") as info:
            flags = next((line.split(":", 1)[1].split() for line in info if line.startswith("flags")), [])
    except OSError:
        return False
    return {"avx2", "fma"} <= set(flags)


if _has_avx2_and_fma():
    os.environ.update(KERNELS)

#: The units of work that take longest (measured with ``--durations``, docs/architecture.md), longest first: they
#: start first. A file's tests and a group's keep their order; the other units follow in collection order, and
#: the documentation site's build from the page runs' figures comes last (it waits for the page chains).
LONGEST = ("pages-1", "pages-2", "tests/test_tiers.py", "tests/test_docs.py", "tests/test_packaging.py",
           "tests/test_bad_input.py",
           "tests/orchestrator/test_systems.py", "tests/models/test_rays.py", "tests/orchestrator/test_replay.py",
           "tests/orchestrator/test_beacons.py", "tests/orchestrator/test_campaign.py",
           "tests/orchestrator/test_fmus.py", "tests/fmus_tests/test_binaries.py",
           # the fast tier's longest files (its own run, --durations): first, so none is the last one a core waits on
           "tests/orchestrator/test_design.py", "tests/orchestrator/test_replay_security.py",
           "tests/orchestrator/test_calibrate_simulated.py", "tests/orchestrator/test_tracking.py",
           "tests/orchestrator/test_study.py", "tests/orchestrator/test_site_factors.py",
           "tests/orchestrator/test_design_telemetry_3d.py", "tests/orchestrator/test_scenario_fmus.py")
LAST = ("pages-site",)


def unit_of(nodeid: str) -> str:
    """The unit of work of a test (by its id, which is all the scheduler sees): the one its file names for it
    (``tests/test_readme.py``'s :func:`~tests.test_readme.unit_of_test`), else its file."""
    file, _, test = nodeid.partition("::")
    if file == "tests/test_readme.py":
        from tests.test_readme import unit_of_test

        return unit_of_test(test) or file
    return file


def _rank(unit: str) -> int:
    if unit in LAST:
        return len(LONGEST) + 1
    return LONGEST.index(unit) if unit in LONGEST else len(LONGEST)


#: The package's folders (pyproject.toml's package-dir), whose modules every test process imports.
ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIRS = ("orchestrator", "models", "fmus")


def pytest_configure(config):
    """Under ``PYTHONDONTWRITEBYTECODE`` (set in many containers) no process writes the bytecode of sblsim's
    modules, so each of the suite's thousand-odd processes (the commands it runs, the pages' blocks) compiles them
    all again, about 0.14 s each. The run's first process compiles them once into their ``__pycache__`` (ignored
    by git; Python reads what is there whatever the setting); a stale file is recompiled by its timestamp.

    The same setting keeps pytest from keeping the test files with their asserts rewritten (``tests/__pycache__``),
    so every worker rewrote all of them at every run: about 15 s of each worker's collection of 27 s. Each test
    process (the run's, and its workers, before they collect) may write bytecode again; the processes the tests
    start keep the setting."""
    if sys.dont_write_bytecode:
        if not hasattr(config, "workerinput"):
            import compileall

            for name in PACKAGE_DIRS:
                compileall.compile_dir(ROOT / name, quiet=2)
        sys.dont_write_bytecode = False


def pytest_collection_modifyitems(config, items):
    """Longest units first, the site build last (a stable sort: each unit keeps its order). Where the environment
    names a file in ``SBLSIM_COLLECTED_MARKERS`` (tests/test_tiers.py), each test's id and markers are written there
    (JSON) as collected, before ``-m`` selects."""
    items.sort(key=lambda item: _rank(unit_of(item.nodeid)))
    target = os.environ.get("SBLSIM_COLLECTED_MARKERS")
    if target and not hasattr(config, "workerinput"):
        Path(target).write_text(json.dumps({item.nodeid: sorted({m.name for m in item.iter_markers()})
                                            for item in items}))


def pytest_xdist_make_scheduler(config, log):
    return FileScheduling(config, log)


try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # without pytest-xdist the suite runs in one process
    LoadScopeScheduling = object


class FileScheduling(LoadScopeScheduling):
    """pytest-xdist's ``loadfile``, with the units of :func:`unit_of`, in collection order (see
    :func:`pytest_collection_modifyitems`), and no unit handed to a worker that still has work."""

    def __init__(self, config, log=None):
        super().__init__(config, log)
        config.option.loadscopereorder = False  # the collection's order: longest first

    def _split_scope(self, nodeid: str) -> str:
        return unit_of(nodeid)

    def _reschedule(self, node) -> None:
        """A worker holds the last test it was sent until it knows the next (or is shut down): with one test left
        it is idle, and only then does it get a new unit (xdist's ``loadscope`` hands it one with two left, and a
        unit then waits behind a long test)."""
        if node.shutting_down:
            return
        if not self.workqueue:
            node.shutdown()
            return
        if self._pending_of(self.assigned_work[node]) > 1:
            return
        self._assign_work_unit(node)


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
