"""A ``fmu:PATH`` component that is broken or hostile stops a run with one line, never a traceback.

A user's FMU is a zip from someone else. A GUID that does not match the binary, an FMU without
binaries for this platform, a ``modelIdentifier`` that names no library: each ends the run with one
line (``sblsim: error: ...``, exit status 2) naming the FMU and carrying what the FMU itself logged. A
zip bomb or an entry that climbs out of the folder is refused before a byte is unpacked
(:func:`sblsim.orchestrator.io.archives.safe_extract`).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from sblsim.fmus.build import fmu_path
from sblsim.models.errors import FMICallError
from sblsim.orchestrator.cosim.engines import open_fmu

SHORT = ["--set", "simulation.duration=2"]


def _copy(fmu: Path, dest: Path, edit=None, drop: str = "", extra: dict[str, bytes] | None = None) -> Path:
    """A copy of ``fmu``: modelDescription.xml edited, entries under ``drop`` left out, ``extra`` entries added."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as out:
        for name in src.namelist():
            if drop and name.startswith(drop):
                continue
            data = src.read(name)
            if edit is not None and name == "modelDescription.xml":
                data = edit(data)
            out.writestr(name, data)
        for name, data in (extra or {}).items():
            out.writestr(name, data)
    return dest


def _run(fmu: Path, tmp_path: Path) -> tuple[subprocess.CompletedProcess, Path]:
    """``sblsim run semicircle --set receiver=fmu:PATH`` in a new process whose temporary folder is its own."""
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch)}
    proc = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "run", "semicircle", "--set",
                           f"receiver=fmu:{fmu}", *SHORT, "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, env=env, timeout=300)
    return proc, scratch


def _one_line(proc: subprocess.CompletedProcess, tmp_path: Path, *parts: str) -> str:
    err = proc.stderr
    assert proc.returncode == 2, err
    assert err.count("\n") == 1 and err.startswith("sblsim: error: fmu: ") and "Traceback" not in err, err
    assert all(part in err for part in parts), err
    assert not (tmp_path / "out").exists()
    return err


def _guid(data: bytes) -> bytes:
    return re.sub(rb'guid="\{(.)', lambda m: b'guid="{' + (b"0" if m.group(1) != b"0" else b"1"), data, count=1)


def test_a_guid_that_does_not_match_the_binary(fmu_dir, tmp_path):
    fmu = _copy(fmu_path(fmu_dir, "receiver"), tmp_path / "guid.fmu", edit=_guid)
    proc, _ = _run(fmu, tmp_path)
    _one_line(proc, tmp_path, "guid.fmu (receiver)", "fmi2Instantiate failed: GUID {", "does not match this binary's {")


@pytest.mark.slow
def test_an_fmu_without_binaries_for_this_platform(fmu_dir, tmp_path):
    from fmpy import platform

    fmu = _copy(fmu_path(fmu_dir, "receiver"), tmp_path / "nobin.fmu", drop=f"binaries/{platform}")
    proc, _ = _run(fmu, tmp_path)
    _one_line(proc, tmp_path, "nobin.fmu (receiver)", f"has no binaries/{platform}")


@pytest.mark.slow
def test_a_model_identifier_that_names_no_library(fmu_dir, tmp_path):
    fmu = _copy(fmu_path(fmu_dir, "receiver"), tmp_path / "ident.fmu",
                edit=lambda d: d.replace(b'modelIdentifier="sblsim_receiver"', b'modelIdentifier="elsewhere"'))
    proc, _ = _run(fmu, tmp_path)
    _one_line(proc, tmp_path, "ident.fmu (receiver)", "modelIdentifier 'elsewhere' names no library",
              "sblsim_receiver.so")


@pytest.mark.parametrize("entry, data, message", [
    pytest.param("resources/bomb.bin", bytes(64 << 20), "inflates", marks=pytest.mark.slow),  # 64 MiB of zeros
    ("../escaped.txt", b"outside", "climbs out of the package"),
])
def test_a_hostile_archive_is_refused_before_anything_is_unpacked(fmu_dir, tmp_path, entry, data, message):
    fmu = _copy(fmu_path(fmu_dir, "receiver"), tmp_path / "hostile.fmu", extra={entry: data})
    proc, scratch = _run(fmu, tmp_path)
    _one_line(proc, tmp_path, "hostile.fmu (receiver)", repr(entry), message)
    assert list(scratch.iterdir()) == []  # no unpacked folder left, nothing beside it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hostile.fmu", "scratch"]


def test_a_refused_call_carries_the_fmus_own_message(fmu_dir):
    """An input outside its range in a run: the one-line error quotes the FMU's log line."""
    handle = open_fmu("receiver", fmu_path(fmu_dir, "receiver"))
    try:
        handle.setup({}, [0])
        values = np.zeros((len(handle.input_names), 1))
        values[handle.input_names.index("range"), 0] = 1e300
        with pytest.raises(FMICallError) as info:
            handle.set_input_vector(values)
        message = str(info.value)
        assert (info.value.function, info.value.status) == ("fmi2SetReal", 3)
        assert info.value.log.endswith("range = 1e+300 is outside the allowed range [-1e+07, 1e+07] m")
        assert message.startswith("fmu: sblsim_receiver.fmu (receiver): fmi2SetReal returned fmi2Error (3): ")
        assert message.endswith("fmi2SetReal: range = 1e+300 is outside the allowed range [-1e+07, 1e+07] m")
        assert "\n" not in message
    finally:
        handle.terminate()
