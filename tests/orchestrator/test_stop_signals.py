"""One way to stop (orchestrator/io/stop.py): Ctrl-C, SIGTERM or SIGHUP ends a command with one line ``sblsim:
interrupted`` and 128 + the signal, nothing written, wherever the signal lands: inside a compiled library's call too,
where casadi's wrapper reports the signal handler's exception as ``NotImplementedError: Wrong number or type of
arguments for function 'Function_call'`` (or a ``TypeError``, CPython a ``SystemError``) and drops it.

The fast tests run a command of their own through the command line's ``main`` in a child process (signalled as a
user's shell or a scheduler signals it) and in this one (the exception a library makes of a stop, the loop that
stops at its next step, the dispositions). The slow ones interrupt each long command at several points: its exit
status, its one line, its time to end (under 5 s) and that it leaves no output at all.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
import types
from pathlib import Path

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator import cli
from sblsim.orchestrator.io import stop
from sblsim.orchestrator.io.progress import Progress
from sblsim.orchestrator.tracks.resume import MARKER
from tests.helpers import signal_and_wait, start_for_signals

#: The most a command may take to end after the signal [s] (the issue's bound).
WITHIN = 5.0
#: The child: ``sblsim``'s ``main`` running one command of its own. ``inside``: a casadi call whose argument's
#: conversion (casadi's typecheck calls the argument's ``__DM__``) sends the process the signal, so that the handler
#: runs inside ``Function_call``; ``spin``: the box-in's lever arm (casadi, a map over 2000 attitudes) in a loop,
#: ``ready`` printed before it; ``linger``: a thread started that never ends (as a library's can be left stuck),
#: then a loop; ``again``: stopped by SIGTERM, a thread it started sends the process the signal again 0.2 s later
#: (while its end waits for that thread). Each prints the type of the exception that came out of the work. Run as the
#: console script runs (``cli.run``), its grace for lingering threads 0.3 s.
CHILD = textwrap.dedent('''
    import os, signal, sys, threading, time, types
    import numpy as np
    import casadi as ca
    from sblsim.models.calibration import boxin
    from sblsim.orchestrator import cli
    from sblsim.orchestrator.io import stop

    mode, signum = sys.argv[1], int(sys.argv[2])

    class Signalling:
        def __DM__(self):
            signal.raise_signal(signum)  # raise(3): its C handler has run before it returns, in this thread
            return ca.DM(np.arange(3.0) + sum(range(100)))  # Python instructions after the signal: the handler runs

    def inside(args):
        x = ca.MX.sym("x", 3)
        double = ca.Function("double", [x], [2 * x])
        try:
            double(Signalling())
        except BaseException as exc:
            print(type(exc).__name__, flush=True)
            raise
        print("returned", flush=True)
        return 0

    def spin(args):
        angles = np.random.default_rng(1).uniform(-0.1, 0.1, (2000, 3))
        print("ready", flush=True)
        while True:
            try:
                boxin.lever_enu(angles, np.array([0.0, 0.0, 1.0]))
            except BaseException as exc:
                print(type(exc).__name__, flush=True)
                raise

    def again(args):
        def late():
            time.sleep(0.2)
            print("sent", flush=True)
            os.kill(os.getpid(), signum)  # a second signal while the stopped process ends
        threading.Thread(target=late, name="late").start()
        signal.raise_signal(signal.SIGTERM)

    def linger(args):
        threading.Thread(target=threading.Event().wait, name="stuck").start()  # a library's, that never ends
        print("ready", flush=True)
        while True:
            time.sleep(0.05)

    stop.THREADS_GRACE = 0.3
    cli.COMMANDS[mode] = types.SimpleNamespace(main=locals()[mode], add_arguments=lambda p: None, HELP=mode)
    cli.run([mode])
''')

SIGNALS = {"SIGINT": signal.SIGINT, "SIGTERM": signal.SIGTERM, "SIGHUP": signal.SIGHUP}


def _child(tmp_path: Path, mode: str, sig: int) -> subprocess.Popen:
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    return start_for_signals([sys.executable, str(script), mode, str(int(sig))], cwd=tmp_path, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("name", [n if n == "SIGINT" else pytest.param(n, marks=pytest.mark.slow) for n in SIGNALS])
def test_a_signal_handled_inside_a_casadi_call_is_the_stop(tmp_path, name):
    """The handler's KeyboardInterrupt raised inside casadi's ``Function_call`` comes out as casadi's
    NotImplementedError (what the child's command saw); the command line takes it as the stop: 128 + the signal, one
    line."""
    sig = SIGNALS[name]
    proc = _child(tmp_path, "inside", sig)
    out, err = proc.communicate(timeout=120)
    assert out.splitlines() == ["NotImplementedError"], (out, err)  # inside the compiled call, the signal lost there
    assert proc.returncode == 128 + sig, (proc.returncode, err)
    assert err.splitlines() == ["sblsim: interrupted"], err


def test_a_stopped_command_does_not_wait_for_good_on_a_stuck_thread(tmp_path):
    """A thread the interpreter's exit would join that never ends (a library's, stuck once its work was cut short:
    CPython 3.11's process pool manager thread): stopped, the command says its one line and its process ends with
    128 + the signal after its grace (0.3 s here), where the interpreter's exit alone would wait for good."""
    proc = _child(tmp_path, "linger", signal.SIGTERM)
    if proc.stdout.readline().strip() != "ready":
        proc.kill()
        pytest.fail(str(proc.communicate()))
    _, err, took = signal_and_wait(proc, signal.SIGTERM)
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, err)
    assert err.splitlines() == ["sblsim: interrupted"], err
    assert 0.3 <= took < WITHIN, took


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM"])
def test_a_second_signal_while_a_stopped_command_ends_keeps_its_status(tmp_path, name):
    """Stopped by SIGTERM, then signalled again while its process ends (a second Ctrl-C, a signal sent twice): the
    process ends at once with the stop's 143 and its one line, where Python's own handlers, back after the command,
    raised a KeyboardInterrupt through the exit (its traceback, the process ended by SIGINT) or let SIGTERM kill it."""
    proc = _child(tmp_path, "again", SIGNALS[name])
    out, err = proc.communicate(timeout=120)
    assert out.split() == ["sent"], (out, err)  # the second signal was sent before the process ended
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, err)
    assert err.splitlines() == ["sblsim: interrupted"], err


@pytest.mark.slow
def test_signals_sent_while_casadi_calls_run_end_the_command(tmp_path):
    """A loop of casadi calls (the box-in's lever arm, the issue's traceback), signalled from outside at different
    moments of its calls (three children at once): each ends within 5 s with 128 + the signal and one line, whatever
    exception the signal became (KeyboardInterrupt between calls; NotImplementedError, TypeError or SystemError
    inside one)."""
    plan = [(signal.SIGTERM, 0.35), (signal.SIGINT, 0.7), (signal.SIGTERM, 1.05)]
    procs = []
    for k, (sig, _) in enumerate(plan):
        folder = tmp_path / str(k)
        folder.mkdir()
        procs.append(_child(folder, "spin", sig))
    try:
        for proc in procs:
            assert proc.stdout.readline().strip() == "ready", proc.communicate()
        begun = time.monotonic()
        results = []
        for proc, (sig, delay) in zip(procs, plan):
            time.sleep(max(0.0, begun + delay - time.monotonic()))
            sent = time.monotonic()
            proc.send_signal(sig)
            out, err = proc.communicate(timeout=60)
            results.append((proc.returncode, time.monotonic() - sent, out.split(), err.splitlines()))
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    for (status, took, seen, lines), (sig, _) in zip(results, plan):
        assert status == 128 + sig, (status, seen, lines)
        assert took < WITHIN, took
        assert lines == ["sblsim: interrupted"], (seen, lines)


@pytest.fixture
def default_signals():
    """SIGINT, SIGTERM and SIGHUP at their defaults in this process while a test runs (a background run of the
    suite starts it with SIGINT ignored), restored after."""
    saved = {sig: signal.getsignal(sig) for sig in SIGNALS.values()}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def _run(monkeypatch, main) -> int:
    """``sblsim work`` through the command line's ``main``, ``work`` being ``main(args)``."""
    monkeypatch.setitem(cli.COMMANDS, "work", types.SimpleNamespace(main=main, add_arguments=lambda p: None,
                                                                      HELP="work"))
    return cli.main(["work"])


def _lost(sig: int) -> None:
    """The signal handled and its exception dropped, as a compiled library drops it."""
    try:
        signal.raise_signal(sig)
    except KeyboardInterrupt:
        pass


#: Errors a compiled library raises once it has dropped the handler's exception (casadi's wrapper, CPython around an
#: extension's call, a numpy solve that went on, a reader's error) and ours, each with a stop pending: the stop.
ERRORS = {"casadi": NotImplementedError("Wrong number or type of arguments for function 'Function_call'"),
          "casadi type": TypeError("Use an equivalent CasADi function instead of that numpy function."),
          "cpython": SystemError("<function DM.__array__> returned a result with an exception set"),
          "numpy": np.linalg.LinAlgError("Singular matrix"), "ours": ModelError("log: 'x.csv' line 3: ..."),
          "disk": OSError(28, "No space left on device")}


@pytest.mark.parametrize("kind", ERRORS)
@pytest.mark.parametrize("name", ["SIGTERM", "SIGHUP"])
def test_whatever_comes_out_while_a_stop_is_pending_is_the_stop(default_signals, monkeypatch, capsys, kind, name):
    sig = SIGNALS[name]

    def work(args):
        _lost(sig)
        raise ERRORS[kind]

    assert _run(monkeypatch, work) == 128 + sig
    assert capsys.readouterr().err.splitlines() == ["sblsim: interrupted"]
    assert stop.pending() is None  # the stop ends with its command


def test_without_a_stop_an_error_is_an_error(default_signals, monkeypatch, capsys):
    """No signal: casadi's NotImplementedError is a fault of ours (its traceback), a ModelError one line and 2."""
    def failing(exc):
        def work(args):
            raise exc
        return work

    with pytest.raises(NotImplementedError):
        _run(monkeypatch, failing(ERRORS["casadi"]))
    assert _run(monkeypatch, failing(ERRORS["ours"])) == 2
    assert capsys.readouterr().err.splitlines() == ["sblsim: error: log: 'x.csv' line 3: ..."]


def test_a_loop_whose_stop_was_lost_stops_at_its_next_step(default_signals, monkeypatch, capsys):
    """A compiled library dropped the signal's exception and returned (the work goes on): the loop's next progress
    step stops it; the steps done before the signal are the steps done."""
    done = []

    def work(args):
        with Progress(10, "work", spec=False) as bar:
            for k in range(10):
                if k == 3:
                    _lost(signal.SIGTERM)
                done.append(k)
                bar.update()
        return 0

    assert _run(monkeypatch, work) == 143
    assert done == [0, 1, 2, 3] and capsys.readouterr().err.splitlines() == ["sblsim: interrupted"]


def test_the_exit_statuses_are_128_plus_the_signal(default_signals, monkeypatch, capsys):
    for sig in SIGNALS.values():
        assert _run(monkeypatch, lambda args, sig=sig: signal.raise_signal(sig)) == 128 + sig
    assert _run(monkeypatch, lambda args: (_ for _ in ()).throw(KeyboardInterrupt)) == 130  # no signal: Ctrl-C's
    assert capsys.readouterr().err.splitlines() == ["sblsim: interrupted"] * 4


def test_an_ignored_signal_stays_ignored_and_the_handlers_are_restored(default_signals):
    """``nohup``'s SIGHUP (a background job's SIGINT) stays ignored while a command runs; the others are the stop's,
    and the earlier handlers come back after."""
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    before = {sig: signal.getsignal(sig) for sig in SIGNALS.values()}
    with stop.stop_on():
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, signal.SIG_IGN, None)
        signal.raise_signal(signal.SIGHUP)  # ignored: nothing pending
        assert stop.pending() is None
    assert {sig: signal.getsignal(sig) for sig in SIGNALS.values()} == before


def test_a_second_signal_while_the_command_ends_is_recorded_not_raised(default_signals):
    """The command's last lines (its one line said, its locks released) are not cut by a second Ctrl-C."""
    with stop.stop_on():
        _lost(signal.SIGINT)
        with stop.ending():
            signal.raise_signal(signal.SIGTERM)  # would raise KeyboardInterrupt here otherwise
            stop.check()
        assert stop.pending() == signal.SIGINT and stop.exit_status() == 130
        with pytest.raises(KeyboardInterrupt):
            stop.check()


class _Finalised:
    """An object whose finaliser runs the stop's handler (a signal handled while the garbage collector finalises it:
    Python cannot raise the handler's exception from there)."""

    def __init__(self, sig):
        self.sig = sig

    def __del__(self):
        signal.raise_signal(self.sig)


def test_a_stop_handled_inside_a_finaliser_says_nothing_and_stays_pending(default_signals, monkeypatch):
    """A signal handled while a ``__del__`` runs (seen as ``Exception ignored in: <function ZipFile.__del__>`` and
    its traceback on a stopped ``sblsim run`` of FMUs): nothing goes to the process's hook for what Python cannot
    raise (it prints them), the stop is pending and the next check raises it; another exception a finaliser cannot
    raise goes to it as before, and so does a KeyboardInterrupt of no stop; the hook is the process's own again
    after the command."""
    import gc

    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda unraisable: seen.append(unraisable.exc_type))
    hook = sys.unraisablehook
    with stop.stop_on():
        _Finalised(signal.SIGTERM)  # (made and let go at once: its finaliser runs the handler)
        gc.collect()
        assert stop.pending() == signal.SIGTERM and seen == []
        with pytest.raises(KeyboardInterrupt):
            stop.check()

    class Failing:
        def __del__(self):
            raise ValueError("a finaliser's own fault")

    class Interrupted:
        def __del__(self):
            raise KeyboardInterrupt

    with stop.stop_on():
        Failing()
        Interrupted()  # no signal recorded: not the stop's
        gc.collect()
        assert seen == [ValueError, KeyboardInterrupt] and stop.pending() is None
    assert sys.unraisablehook is hook


POOL = textwrap.dedent('''
    import multiprocessing, signal
    from concurrent.futures import ProcessPoolExecutor
    from sblsim.orchestrator import cli  # noqa: F401  (a command's main module imports it)

    def disposition():
        return signal.getsignal(signal.SIGINT) is signal.SIG_IGN

    if __name__ == "__main__":
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            print(pool.submit(disposition).result(), signal.getsignal(signal.SIGINT) is signal.default_int_handler)
''')


def test_a_spawned_worker_ignores_ctrl_c_from_its_first_import(tmp_path):
    """A spawned worker (a pool of ``track``, ``design`` or ``campaign``) ignores SIGINT from the command line's
    import on: the spawn's preparation gives it the command's ``sys.argv`` and no parent while it imports, and a
    Ctrl-C at the terminal then printed ``Process SpawnProcess-1:`` with its traceback. The command itself keeps
    Python's handler."""
    (tmp_path / "main.py").write_text(POOL)
    # started as a shell starts a command (a background job's pytest has SIGINT ignored, which the child inherits)
    proc = start_for_signals([sys.executable, "main.py"], cwd=tmp_path, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert out.split() == ["True", "True"], out  # the worker ignores it, the command handles it


# --------------------------------------------------------------------------- each long command, as a user runs it

BOATS = Path(__file__).resolve().parents[2] / "data" / "boats-norway"
#: Each long command: its arguments (``--out o`` added), when its work has begun (``lock``: its output folder locked,
#: its input read and checked; a number: seconds after its start, for a command that reads or solves before it locks
#: its folder; a text: the start of its first progress line, a campaign's workers or cluster up), the points its
#: signal lands at (seconds into the work), and whether it runs worker processes (then Ctrl-C also as a terminal
#: sends it, to the whole process group). Each runs far longer uninterrupted.
LONG = {
    "run": (["run", "semicircle", "--set", "simulation.duration=30000"], "lock", (0.3, 2.0), False),  # 6 s here
    "run fmu": (["run", "semicircle", "--engine", "fmu", "--set", "simulation.duration=20000"], "lock", (1.0, 3.0),
                False),
    "compare": (["compare", "semicircle", "--replicates", "2000"], "lock", (0.5, 3.0), False),  # 20 s here (200
                                              # replicates, 3 s, ended before its last point on a faster machine)
    "budget": (["budget", "lbl-field"], "lock", (1.0, 8.0), False),
    "map": (["map", "usbl-deep", "--extent", "2000", "--step", "10"], "lock", (0.2, 6.0), False),
    "design": (["design", "lbl-field-2km"], "lock", (1.0, 6.0), False),
    "design workers": (["design", "lbl-field-2km", "--workers", "2"], "lock", (2.0, 6.0), True),
    "campaign workers": (["campaign", "paper", "--workers", "2"], "campaign:", (0.0, 4.0), True),
    # a stop in a local Dask cluster's first seconds of work waits for its nannies (6-8 s measured on 2 busy cores)
    "campaign dask": (["campaign", "paper", "--scheduler", "local", "--workers", "2"], "campaign:", (3.0, 8.0), True),
    "calibrate replicates": (["calibrate", "box-in", "--replicates", "100000"], "lock", (0.2, 1.0, 3.0, 7.0), False),
    "calibrate log": (["calibrate", "LOG"], 2.0, (0.5, 4.0, 10.0), False),
    "sync": (["sync", str(BOATS / "detections.csv"), "--receivers", str(BOATS / "hydrophones.csv"),
              "--sound-speed-file", str(BOATS / "sound_speed.csv"), "--refine-positions", "--bin-hours", "0.1"],
             2.0, (1.0, 4.0, 8.0), False),  # positions refined over six-minute bins: 52 s here (12 s without: 10 s,
                                              # less than its last point, on a faster machine)
    "track": (["track", str(BOATS / "detections.csv"), "--receivers", str(BOATS / "deployments.csv"), "--tags",
               str(BOATS / "tags.csv"), "--refine-positions"], 2.0, (2.0, 10.0, 20.0), True),  # 160 s here: the
                                              # plain study's 23 s ended as its last point's signal came
}
#: (command, point, signal, to the whole group): each command's points with SIGINT and SIGTERM alternately (each
#: command has two or more: it meets both; every signal's status and line are the fast tests'); a command with
#: workers once more with Ctrl-C to its process group.
CASES = [(name, point, (signal.SIGINT, signal.SIGTERM)[k % 2], False) for name, (_, _, points, _) in LONG.items()
         for k, point in enumerate(points)]
CASES += [(name, points[-1], signal.SIGINT, True) for name, (_, _, points, workers) in LONG.items() if workers]


@pytest.fixture(scope="module")
def warm(tmp_path_factory) -> Path:
    """What the commands run on, built before any clock runs (the local engine's libraries, the FMUs, the deep site's
    eigenray tables: each command once, small), and a calibration log of 200,000 replies of the simulated box-in
    (a day, a reply every 0.43 s)."""
    work = tmp_path_factory.mktemp("warm")
    for args in (["map", "usbl-deep", "--extent", "20", "--step", "10"],
                 ["budget", "lbl-field", "--replicates", "2", "--set", "simulation.duration=30"],
                 ["run", "semicircle", "--engine", "fmu", "--set", "simulation.duration=5"]):
        subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", *args, "--out", args[0]], cwd=work,
                       check=True, capture_output=True)
    from sblsim.orchestrator.surveys.log import write_log
    from sblsim.orchestrator.surveys.simulate import load_simulated, replicate

    survey, _ = replicate(load_simulated("box-in", ["survey.duration_s=86400", "survey.ping_period_s=0.432"]), 0)
    write_log(survey.log, work / "log.csv")
    return work / "log.csv"


def _lines(stream, into: list) -> None:
    for line in stream:
        into.append((time.monotonic(), line.rstrip("\n")))


@pytest.mark.slow
@pytest.mark.parametrize("name,point,sig,group", CASES,
                         ids=[f"{n}-{p:g}s-{signal.Signals(s).name}{'-group' if g else ''}" for n, p, s, g in CASES])
def test_a_long_command_stops_cleanly_at_any_point(warm, tmp_path, name, point, sig, group):
    """Signalled ``point`` seconds into its work (the command alone, as a scheduler signals it, or its whole process
    group, as a terminal's Ctrl-C): 128 + the signal within 5 s, one line after the signal (the lines before it are
    its notes and progress), no traceback (of its workers either), and no output: no folder (a campaign keeps the
    chunks it finished, to resume, but no runs.parquet; a study the tags it finished, beside its output), no lock,
    no staging folder."""
    import threading

    args, begun, _, _ = LONG[name]
    args = [str(warm) if a == "LOG" else a for a in args]
    proc = start_for_signals([sys.executable, "-m", "sblsim.orchestrator.cli", *args, "--out", "o"], cwd=tmp_path,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                             **({"process_group": 0} if group else {}))  # a shell's job: its own group
    lines: list = []
    reader = threading.Thread(target=_lines, args=(proc.stderr, lines), daemon=True)
    reader.start()
    try:
        started, deadline = time.monotonic(), time.monotonic() + 300
        while not ((tmp_path / ".o.lock").exists() if begun == "lock" else
                   any(line.startswith(begun) for _, line in lines) if isinstance(begun, str) else
                   time.monotonic() - started >= begun):
            assert proc.poll() is None, lines
            assert time.monotonic() < deadline, "the command never locked its output folder"
            time.sleep(0.01)
        time.sleep(point)
        assert proc.poll() is None, f"the work ended before the signal: {lines}"
        sent = time.monotonic()
        if group:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        proc.wait(timeout=60)
        took = time.monotonic() - sent
        reader.join(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    after = [line for at, line in lines if at >= sent]
    # 130 for Ctrl-C, or ended by SIGINT itself once its one line is said (seen twice in some sixty: a SIGINT
    # delivered again as the interpreter ends); a shell reports both as 130
    assert proc.returncode in ((128 + sig, -sig) if sig == signal.SIGINT else (128 + sig,)), (proc.returncode, lines)
    assert took < WITHIN, (took, lines)
    assert len(after) == 1 and after[0].startswith("sblsim: interrupted"), lines
    assert not any("Traceback" in line for _, line in lines), lines
    left = sorted(p.name for p in tmp_path.iterdir())
    if name.startswith("campaign"):
        assert left in ([], ["o"]) and not (tmp_path / "o" / "runs.parquet").exists(), left
    elif name == "track":  # the tags it finished, kept for a rerun (marked sblsim's), and nothing else
        assert left in ([], [".o.resume"]) and (not left or (tmp_path / left[0] / MARKER).is_file()), left
    else:
        assert left == [], left
