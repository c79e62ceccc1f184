"""An installed sblsim is one namespaced package: ``sblsim.models``, ``sblsim.orchestrator``,
``sblsim.fmus``, and nothing top-level named ``models``, ``fmus`` or ``orchestrator``.

The project is built into a wheel (from a copy of its sources, so that the checkout is not
written to) and installed, not editable, into a fresh virtual environment. The checks then run
from a folder outside the checkout. The fresh environment takes the dependencies from the test
environment's site-packages through a path entry, which adds that folder to ``sys.path`` without
running its ``.pth`` files: the editable install of the checkout is therefore not seen.

The installed copy runs ``sblsim run semicircle --engine fmu`` with nothing built beforehand: the FMUs are
built into the user's cache, and nothing is written under the environment's site-packages. The tests run
as root, for whom a read-only folder is writable anyway, so instead of ``chmod`` the test compares the
site-packages tree (every file's size, time stamp and content digest) before and after the runs.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import site
import subprocess
import sys
import venv
from pathlib import Path

import pytest

from tests.helpers import share_compiled_objects

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("models", "orchestrator", "fmus", "pyproject.toml", "README.md")

PROBE = """
import importlib.util, json, sys
import sblsim.models, sblsim.orchestrator.cli, sblsim.fmus.build
found = {name: importlib.util.find_spec(name) is not None for name in ("models", "fmus", "orchestrator")}
print(json.dumps({"top_level": found, "models_file": sblsim.models.__file__,
                  "scenarios": sorted(p.name for p in __import__("importlib.resources").resources.files(
                      "sblsim.orchestrator").joinpath("scenarios").iterdir()),
                  "c_sources": sorted(p.name for p in __import__("importlib.resources").resources.files(
                      "sblsim.fmus").joinpath("c").iterdir() if p.name.endswith(".c"))}))
"""


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A fresh virtual environment with sblsim installed from a wheel; returns its folder."""
    work = tmp_path_factory.mktemp("packaging")
    source = work / "source"
    source.mkdir()
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, source / name, ignore=shutil.ignore_patterns("__pycache__", "build", "*.fmu"))
        else:
            shutil.copy2(path, source / name)
    wheels = work / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                    "-w", str(wheels), str(source)], check=True, capture_output=True, timeout=600)
    env = work / "env"
    venv.EnvBuilder(with_pip=True).create(env)
    python = env / "bin" / "python"
    (wheel,) = wheels.glob("sblsim-*.whl")
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True,
                   capture_output=True, timeout=600)
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             check=True, capture_output=True, text=True).stdout.strip()
    # the dependencies: the test environment's site-packages as a plain path entry (its .pth files do not run)
    Path(purelib, "dependencies.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    outside = work / "elsewhere"
    outside.mkdir()
    return env, outside, wheel


def test_installed_names_are_namespaced(installed):
    env, outside, _ = installed
    done = subprocess.run([str(env / "bin" / "python"), "-c", PROBE], cwd=outside, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    found = json.loads(done.stdout)
    assert found["top_level"] == {"models": False, "fmus": False, "orchestrator": False}
    assert Path(found["models_file"]).is_relative_to(env), "sblsim.models came from outside the environment"
    assert "semicircle.toml" in found["scenarios"] and "fmi2_shell.c" in found["c_sources"]


def test_wheel_holds_only_the_sblsim_package(installed):
    _, _, wheel = installed
    import zipfile

    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
    tops = {name.split("/")[0] for name in names}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"sblsim"}
    # the recordings of data/ (their own licences: folders lake-hald/, boats-norway/) are for the tests and the docs,
    # not the wheel; a built-in problem named after a site (designs/lake-hald-array.toml) is no recording
    assert not [n for n in names if "lake-hald/" in n or "boats-norway/" in n or n.endswith(("toa.txt", "gps.txt"))]


def test_the_wheel_holds_every_module_of_the_sources(installed):
    """Every Python module of models/, orchestrator/ and fmus/ is in the wheel, at its installed name (a package
    folder missing from pyproject.toml's ``packages`` would be left out)."""
    _, _, wheel = installed
    import zipfile

    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    mapping = {"models": "sblsim/models", "orchestrator": "sblsim/orchestrator", "fmus": "sblsim/fmus"}
    expected = set()
    for folder, installed_as in mapping.items():
        for path in (ROOT / folder).rglob("*.py"):
            relative = path.relative_to(ROOT / folder)
            if "build" in relative.parts or "__pycache__" in relative.parts:
                continue
            if relative.parts[0] == "toplevel":  # the package sblsim itself
                expected.add("sblsim/" + "/".join(relative.parts[1:]))
            else:
                expected.add(f"{installed_as}/{relative.as_posix()}")
    assert len(expected) > 100
    assert sorted(expected - names) == []


def test_console_script_answers_its_version(installed):
    env, outside, _ = installed
    done = subprocess.run([str(env / "bin" / "sblsim"), "--version"], cwd=outside, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    from importlib.metadata import version

    assert done.stdout.strip() == f"sblsim {version('sblsim')}"


def _tree(folder: Path) -> dict[str, tuple]:
    """Every entry under ``folder``: relative path -> (size, modification time, SHA-256) of a file, or a folder."""
    out = {}
    for path in sorted(folder.rglob("*")):
        st = path.lstat()
        key = str(path.relative_to(folder))
        out[key] = (st.st_size, st.st_mtime_ns, hashlib.sha256(path.read_bytes()).hexdigest()) if path.is_file() \
            else ("dir",)
    return out


def test_the_fmu_engine_runs_from_a_wheel_without_writing_into_site_packages(installed, fmu_dir):
    """``sblsim run semicircle --engine fmu --seed 1`` from a non-editable install, no FMU built beforehand:
    the FMUs are built into the user's cache, site-packages is left as it was, and the numbers are the
    local engine's. (The user's cache is given the objects the suite compiled for its FMUs and the local engine:
    the wheel's sources are the checkout's, so the FMUs and the library are linked from them.)"""
    from sblsim.fmus.native import library_path
    from sblsim.models import COMPONENTS, MODELS

    env, outside, _ = installed
    python = env / "bin" / "python"
    purelib = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                  check=True, capture_output=True, text=True).stdout.strip())
    cache = outside.parent / "user-cache"
    library_path(4, models=tuple(m for m in MODELS.values() if m in COMPONENTS.values()))
    assert share_compiled_objects(cache / "sblsim") > 0
    run_env = {k: v for k, v in os.environ.items() if not k.startswith(("SBLSIM_", "VIRTUAL_ENV", "PYTHONPATH"))}
    run_env.update(XDG_CACHE_HOME=str(cache), HOME=str(outside.parent / "home"))
    before = _tree(purelib)
    assert any(k.startswith("sblsim/fmus/") for k in before)
    summaries = {}
    for engine in ("fmu", "local"):
        out = outside / f"run-{engine}"
        done = subprocess.run([str(env / "bin" / "sblsim"), "run", "semicircle", "--engine", engine, "--seed", "1",
                               "--out", str(out)], cwd=outside, env=run_env, capture_output=True, text=True,
                              timeout=1200)
        assert done.returncode == 0, done.stderr[-3000:]
        summaries[engine] = json.loads((out / "summary.json").read_text())
    after = _tree(purelib)
    assert {k: v for k, v in after.items() if before.get(k) != v} == {}, "written under site-packages"
    assert set(before) == set(after)
    built = sorted(p.name for p in cache.glob("sblsim/fmus/*/sblsim_*.fmu"))
    assert built == ["sblsim_acoustics.fmu", "sblsim_platform.fmu", "sblsim_receiver.fmu", "sblsim_target.fmu"]
    fmu, local = summaries["fmu"], summaries["local"]
    assert (fmu["engine"], local["engine"]) == ("fmu", "local")
    numbers = [k for k, v in local.items() if isinstance(v, (int, float)) and k != "wall_time"]
    assert {"e_tot_rms", "nees_mean", "pcrb_rms", "steps"} <= set(numbers)
    assert {k: fmu[k] for k in numbers} == {k: local[k] for k in numbers}
