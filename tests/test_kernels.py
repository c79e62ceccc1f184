"""The numerical kernels the tests run on (tests/conftest.py's ``KERNELS``): pinned where the processor runs them,
so that the pages' figures, some of which follow decisions that last bits move, are the same on every such
processor (docs/extending.md, "Figures a page quotes")."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg  # noqa: F401  (its own OpenBLAS loaded, for threadpoolctl to find)
from conftest import _has_avx2_and_fma
from threadpoolctl import threadpool_info

#: The OpenBLAS libraries numpy and scipy loaded (none where they were built on another BLAS, MKL say)
OPENBLAS = [i for i in threadpool_info() if i["internal_api"] == "openblas"]
pinned = pytest.mark.skipif(not _has_avx2_and_fma() or not OPENBLAS, reason="the processor has no AVX2 and FMA "
                            "(numpy's and OpenBLAS's own choice of kernels), or numpy and scipy use no OpenBLAS")

#: numpy's table of its processor features and dispatch targets (numpy._core from numpy 2, numpy.core before)
UMATH = f"numpy.{'_core' if int(np.__version__.split('.')[0]) >= 2 else 'core'}._multiarray_umath"
PROBE = ("import numpy, scipy.linalg, json; from threadpoolctl import threadpool_info; "
         f"from {UMATH} import __cpu_features__ as f, __cpu_dispatch__ as d; "
         "print(json.dumps([sorted({i['architecture'] for i in threadpool_info() if i['internal_api'] == 'openblas'}),"
         " sorted(k for k in d if f[k] and ('512' in k or k == 'X86_V4'))]))")


@pinned
def test_this_process_runs_the_pinned_kernels():
    from importlib import import_module

    umath = import_module(UMATH)
    __cpu_dispatch__, __cpu_features__ = umath.__cpu_dispatch__, umath.__cpu_features__
    assert {i["architecture"] for i in OPENBLAS} == {"Haswell"}, OPENBLAS
    # numpy's AVX-512 targets of dispatch (X86_V4 and the AVX512_* above it) are off; AVX2's (X86_V3) are not
    assert [k for k in __cpu_dispatch__ if __cpu_features__[k] and ("512" in k or k == "X86_V4")] == []


@pinned
def test_a_command_the_tests_start_runs_the_pinned_kernels():
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True)
    assert json.loads(done.stdout) == [["Haswell"], []], done.stdout + done.stderr


def test_the_kernels_are_pinned_only_where_the_processor_runs_them(tmp_path):
    info = tmp_path / "cpuinfo"
    for flags, runs in (("fpu sse2 avx avx2 fma bmi2", True), ("fpu sse2 avx fma", False), ("fpu sse2 avx2", False)):
        info.write_text(f"processor\t: 0\nflags\t\t: {flags}\n\nprocessor\t: 1\nflags\t\t: fpu\n")
        assert _has_avx2_and_fma(info) is runs, flags
    assert _has_avx2_and_fma(tmp_path / "absent") is False
