"""Ctrl-C and SIGTERM during long compiled work (a large site map, a site budget) and during a first run's
compilation: the command ends within 2 s with exit status 130 or 143 and one line, its lock removed and nothing
written.

A map's eigenrays over a grid of 160,000 points are minutes of compiled code, a site budget's master loop
minutes more; Python handles a signal only between its own instructions, so the work is cut into calls of a
fraction of a second (:func:`sblsim.models.expressions.map_in_chunks`) or made abandonable
(:func:`sblsim.fmus.native.abandonable`); a compilation stops its compilers
(:mod:`sblsim.fmus.compiler`). Each command runs as a user runs it: a process of its own, started
with SIGINT and SIGTERM at their defaults (as a shell starts it, whatever this test process ignores), the signal
sent to it and its exit timed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

#: The signal's end: within this [s] of the signal, where the work would run minutes more (a hang guard, not a
#: speed test: the worst measured on two busy cores 0.6 s, on a machine 2.8 times slower not measured).
WITHIN = 10.0


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """What the commands below run on (the local engine's libraries, the deep site's eigenray tables), built before
    any clock runs: each command once, small (the budget's runs 30 s long)."""
    work = tmp_path_factory.mktemp("warm")
    for args in (["map", "usbl-deep", "--extent", "20", "--step", "10"],
                 ["budget", "lbl-field", "--replicates", "2", "--set", "simulation.duration=30"]):
        subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", *args, "--out", args[0]], cwd=work,
                       check=True, capture_output=True)


def _default_signals() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _interrupt(tmp_path: Path, sig: int, *args: str, into: float, env: dict[str, str] | None = None,
               begun: Path | None = None) -> tuple[int, float, str]:
    """Start ``sblsim ARGS --out o`` in ``tmp_path``, send ``sig`` ``into`` seconds after it locked its output
    folder (its input checked, the work begun) and a file matching ``begun`` exists, and return its exit status,
    the seconds it took to end and its standard error."""
    lock = tmp_path / ".o.lock"
    proc = subprocess.Popen([sys.executable, "-m", "sblsim.orchestrator.cli", *args, "--out", "o"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_signals,
                            env=env)
    try:
        deadline = time.monotonic() + 120
        while not lock.exists() or (begun is not None and not any(begun.parent.glob(begun.name))):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the command never locked its output folder or began its work"
            time.sleep(0.01)
        time.sleep(into)
        assert proc.poll() is None, "the work ended before the signal: make it longer"
        sent = time.monotonic()
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=60)
        return proc.returncode, time.monotonic() - sent, stderr
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _ended_cleanly(tmp_path: Path, status: int, took: float, stderr: str, sig: int) -> None:
    assert status == 128 + sig, (status, stderr)
    assert took < WITHIN, took
    assert stderr.splitlines() == ["sblsim: interrupted"], stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no lock, no output, no staging folder


@pytest.mark.slow
def test_ctrl_c_during_a_large_site_map(built, tmp_path):
    """USBL at the deep site, ±2 km every 10 m: the eigenrays of 160,000 points (about two minutes)."""
    status, took, stderr = _interrupt(tmp_path, signal.SIGINT, "map", "usbl-deep", "--extent", "2000", "--step", "10",
                                      into=3.0)
    _ended_cleanly(tmp_path, status, took, stderr, signal.SIGINT)


@pytest.mark.slow
def test_sigterm_during_a_site_budget(built, tmp_path):
    """The LBL field's budget: 13 configurations of 500 replicates, each step of the master loop seconds long."""
    status, took, stderr = _interrupt(tmp_path, signal.SIGTERM, "budget", "lbl-field", into=5.0)
    _ended_cleanly(tmp_path, status, took, stderr, signal.SIGTERM)


@pytest.mark.slow
def test_ctrl_c_during_a_first_compile(tmp_path):
    """A first run on a machine compiles the local engine's models (a minute of the compiler): Ctrl-C one second
    into a compilation stops the compilers, keeps the objects already made and leaves no partial one, nor a killed
    compiler's temporary file (gcc's assembly) in the temporary folder."""
    work, cache, scratch = tmp_path / "work", tmp_path / "cache", tmp_path / "tmp"
    work.mkdir()
    scratch.mkdir()
    objects = cache / "objects"
    status, took, stderr = _interrupt(work, signal.SIGINT, "run", "semicircle", into=1.0,
                                      env={**os.environ, "SBLSIM_CACHE_DIR": str(cache), "TMPDIR": str(scratch)},
                                      begun=objects / "*.lock")
    _ended_cleanly(work, status, took, stderr, signal.SIGINT)
    names = {p.name for p in objects.iterdir()}
    assert not [n for n in names if n.endswith(".partial") or n.startswith(".")], names
    begun = {n.removesuffix(".lock") for n in names if n.endswith(".lock")}
    assert begun - names, "no compilation was under way at the signal: signal sooner"  # a lock without its object
    if Path("/proc/self/cmdline").exists():  # Linux: no compiler left running on the cache
        left = []
        for _ in range(20):
            left = [c for c in Path("/proc").glob("[0-9]*/cmdline") if _reads(c, str(objects))]
            if not left:
                break
            time.sleep(0.05)
        assert not left, left
    assert not list(scratch.iterdir()), list(scratch.iterdir())


def _reads(cmdline: Path, text: str) -> bool:
    """The process of ``/proc/PID/cmdline`` names ``text`` (False once it has ended)."""
    try:
        return text.encode() in cmdline.read_bytes()
    except OSError:
        return False


@pytest.mark.slow
def test_sigterm_during_a_design_searched_by_worker_processes(tmp_path):
    """``sblsim design`` with two worker processes searching candidates: SIGTERM to the command (not to its workers)
    ends it within 2 s, the candidates under way stopped (their processes terminated, not awaited), nothing
    written."""
    status, took, stderr = _interrupt(tmp_path, signal.SIGTERM, "design", "lbl-field-2km", "--workers", "2",
                                      into=5.0)
    _ended_cleanly(tmp_path, status, took, stderr, signal.SIGTERM)


@pytest.mark.slow
def test_ctrl_c_during_a_design_whose_estimate_was_allowed(tmp_path):
    """``sblsim design`` in one process, its effort allowed by ``--max-minutes``: Ctrl-C three seconds into its
    search ends it within 2 s with 130 and one line, nothing written."""
    status, took, stderr = _interrupt(tmp_path, signal.SIGINT, "design", "lbl-field-2km", "--max-minutes", "600",
                                      into=3.0)
    _ended_cleanly(tmp_path, status, took, stderr, signal.SIGINT)


@pytest.mark.slow
def test_ctrl_c_during_a_moving_ocean_search(tmp_path):
    """A day-long simulated figure-eight (21,601 replies) whose moving ocean is searched over four numbers of bases
    (each Gauss-Newton iteration up to half a second, the whole some 15 s): Ctrl-C three seconds into the search
    ends it within 2 s, nothing written (a simulated survey locks its output folder before it simulates)."""
    status, took, stderr = _interrupt(tmp_path, signal.SIGINT, "calibrate", "box-in",
                                      "--set", "survey.pattern=figure-eight", "--set", "survey.duration_s=86400",
                                      "--set", "survey.ntd_sigma_s=2e-4", "--set", "solver.perturbation=ntd",
                                      "--set", "solver.n_bases=[100, 200, 300, 400]",
                                      "--set", "solver.outlier_factor=100", into=3.0)
    _ended_cleanly(tmp_path, status, took, stderr, signal.SIGINT)


def _raising(exc: BaseException):
    def main(args):
        raise exc
    return main


def test_ctrl_c_inside_an_extension_s_call_is_an_interruption(monkeypatch, capsys):
    """A Ctrl-C handled while an extension's function ran, which then returned a value (casadi's ``DM.__array__``
    in a map's chunk), reaches the command as CPython's ``SystemError(... returned a result with an exception
    set)`` caused by the KeyboardInterrupt: one line and 130, as any Ctrl-C. Another SystemError stays an error."""
    import argparse
    import types

    from sblsim.orchestrator import cli

    def system_error(cause):
        try:
            raise cause
        except BaseException as exc:
            try:
                raise SystemError("<function DM.__array__> returned a result with an exception set") from exc
            except SystemError as wrapped:
                return wrapped

    args = argparse.Namespace(command="map")
    monkeypatch.setitem(cli.COMMANDS, "map", types.SimpleNamespace(main=_raising(system_error(KeyboardInterrupt()))))
    assert cli._command(args) == 130
    assert capsys.readouterr().err.splitlines() == ["sblsim: interrupted"]
    monkeypatch.setitem(cli.COMMANDS, "map", types.SimpleNamespace(main=_raising(system_error(ValueError("x")))))
    with pytest.raises(SystemError):
        cli._command(args)
