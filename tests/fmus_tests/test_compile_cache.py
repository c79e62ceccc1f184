"""The compiled objects are kept and shared: a C file is compiled once per compiler, flags, target, text, included
headers and the macros it names, whichever library or FMU needs it, and the libraries linked from the kept objects
compute what freshly compiled ones do."""

from __future__ import annotations

import ctypes
import os
import signal
import stat
import threading
import time
import zipfile
from pathlib import Path

import pytest
from filelock import FileLock
from fmpy import read_model_description

from sblsim.fmus import compiler
from sblsim.fmus.build import build_fmu
from sblsim.fmus.compiler import compile_library, find_compiler
from sblsim.models import MODELS

#: Exported despite -fvisibility=hidden (as the FMI shell exports its functions).
EXPORT = '__attribute__((visibility("default"))) '
SHARED = '#include "shared.h"\n' + EXPORT + 'double scale(double x) { return SCALE * x; }\n'
PLUS = EXPORT + "double offset(double x) { return x + 1.0; }\n"
MINUS = EXPORT + "double offset(double x) { return x - 1.0; }\n"


@pytest.fixture
def logged(tmp_path, monkeypatch):
    """A fresh cache, and the system compiler behind a wrapper ($CC) that logs each compilation's source file."""
    cc = find_compiler("system")
    log = tmp_path / "compilations.log"
    wrapper = tmp_path / "cc-logged"
    wrapper.write_text("#!/bin/sh\n"
                       f'for a in "$@"; do case "$a" in *.c) echo "$a" >> "{log}";; esac; done\n'
                       f'exec {" ".join(cc.command)} "$@"\n')
    wrapper.chmod(wrapper.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("CC", str(wrapper))
    monkeypatch.setenv("SBLSIM_CACHE_DIR", str(tmp_path / "cache"))
    compiler._identity.cache_clear()

    def compiled() -> list[str]:
        names = [Path(line).name for line in log.read_text().splitlines()] if log.exists() else []
        log.unlink(missing_ok=True)
        return sorted(names)

    return find_compiler("auto"), compiled


def _library(tmp_path: Path, name: str, files: dict[str, str], cc, defines=()) -> ctypes.CDLL:
    folder = tmp_path / name
    folder.mkdir()
    for file, text in files.items():
        (folder / file).write_text(text)
    out = compile_library(cc, sorted(folder.glob("*.c")), tmp_path / f"lib{name}.so", [folder], defines)
    lib = ctypes.CDLL(str(out))
    for symbol in ("scale", "offset"):
        if hasattr(lib, symbol):
            getattr(lib, symbol).restype = ctypes.c_double
            getattr(lib, symbol).argtypes = [ctypes.c_double]
    return lib


def test_a_file_two_libraries_share_is_compiled_once(logged, tmp_path):
    cc, compiled = logged
    a = _library(tmp_path, "a", {"shared.c": SHARED, "shared.h": "#define SCALE 2.0\n",
                                 "a.c": PLUS}, cc)
    assert compiled() == ["a.c", "shared.c"]
    b = _library(tmp_path, "b", {"shared.c": SHARED, "shared.h": "#define SCALE 2.0\n",
                                 "b.c": MINUS}, cc)
    assert compiled() == ["b.c"]  # shared.c came from the cache
    assert (a.scale(3.0), b.scale(3.0), a.offset(3.0), b.offset(3.0)) == (6.0, 6.0, 4.0, 2.0)
    # a header it includes changed: compiled again, and the library computes the new value
    c = _library(tmp_path, "c", {"shared.c": SHARED, "shared.h": "#define SCALE 5.0\n"}, cc)
    assert compiled() == ["shared.c"] and c.scale(3.0) == 15.0
    # a macro only the files that name it see: it keys shared.c when SCALE comes from the command line
    d = _library(tmp_path, "d", {"shared.c": SHARED, "shared.h": "",
                                 "a.c": PLUS}, cc, ["SCALE=7.0"])
    assert compiled() == ["shared.c"] and d.scale(1.0) == 7.0  # a.c (no SCALE in it) from the cache


def test_an_object_another_process_compiles_is_waited_for_and_ctrl_c_ends_the_wait(logged, tmp_path):
    """Another process holds the objects' locks (it compiles them): a build waits, compiles each once the lock is
    free and the object still missing, and Ctrl-C (SIGINT to the main thread) ends the wait at once."""
    cc, compiled = logged
    files = {"shared.c": SHARED, "shared.h": "#define SCALE 2.0\n", "a.c": PLUS}
    _library(tmp_path, "first", files, cc)
    assert compiled() == ["a.c", "shared.c"]
    objects = sorted((tmp_path / "cache" / "objects").glob("*.o"))
    for path in objects:
        path.unlink()
    locks = [FileLock(str(path) + ".lock") for path in objects]
    for lock in locks:
        lock.acquire()
    main = threading.main_thread().ident
    timer = threading.Timer(0.5, signal.pthread_kill, (main, signal.SIGINT))
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C as a user's Python has it
    try:
        timer.start()
        began = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            _library(tmp_path, "interrupted", files, cc)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, handler)
    # a hang guard, not a speed test: the wait ends at the signal (0.5 s in), not at a poll seconds later
    assert time.monotonic() - began < 10.0 and compiled() == []
    waiting = threading.Thread(target=_library, args=(tmp_path, "waiting", files, cc))
    waiting.start()
    time.sleep(0.5)
    assert waiting.is_alive() and compiled() == []  # still waiting for the other process
    for lock in locks:
        lock.release()
    waiting.join(60)
    assert not waiting.is_alive() and compiled() == ["a.c", "shared.c"]
    assert [path.is_file() for path in objects] == [True, True]


def test_an_unwritable_cache_costs_only_the_compilation(logged, tmp_path, monkeypatch):
    cc, compiled = logged
    if os.geteuid() == 0:  # root writes anywhere: the cache is a file instead of a folder
        (tmp_path / "blocked").write_text("a file")
        monkeypatch.setenv("SBLSIM_CACHE_DIR", str(tmp_path / "blocked"))
    else:
        (tmp_path / "cache").mkdir()
        (tmp_path / "cache").chmod(0o500)
    for name in ("e", "f"):
        lib = _library(tmp_path, name, {"shared.c": SHARED, "shared.h": "#define SCALE 2.0\n"}, cc)
        assert lib.scale(2.0) == 4.0
        assert compiled() == ["shared.c"]  # nothing kept: compiled each time


@pytest.mark.slow
def test_a_scenarios_fmu_compiles_only_its_model_record(logged, tmp_path):
    """An FMU with other compiled-in parameter defaults differs from the plain one by its model record: the
    generated math, the runtime and the FMI shell come from the cache."""
    cc, compiled = logged
    plain = build_fmu("target", tmp_path / "plain")
    first = compiled()
    assert "sblsim_target_casadi.c" in first and "fmi2_shell.c" in first
    radius = build_fmu("target", tmp_path / "radius", parameters={"radius": 12.0})
    assert compiled() == ["sblsim_target_model.c"]
    with zipfile.ZipFile(plain) as a, zipfile.ZipFile(radius) as b:
        binary = "binaries/linux64/sblsim_target.so"
        assert a.read(binary) != b.read(binary)
    starts = [{v.name: v.start for v in read_model_description(str(fmu)).modelVariables}["radius"]
              for fmu in (plain, radius)]
    assert starts == [repr(float(next(v.start for v in MODELS["target"].fmu_variables() if v.name == "radius"))),
                      "12.0"]
