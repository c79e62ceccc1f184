"""The helper that starts a child for a signal test gives it SIGINT and SIGTERM at their defaults.

A background job (``nohup pytest &``) runs the suite with SIGINT ignored; a child started plainly inherits
that, and a test that sends it SIGINT would then see it run to the end.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from tests.helpers import start_for_signals

#: The child reports its dispositions (Python installs its KeyboardInterrupt handler only over a default SIGINT),
#: then waits to be signalled.
CHILD = ("import signal, sys, time\n"
         "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler,"
         " signal.getsignal(signal.SIGTERM) == signal.SIG_DFL, flush=True)\n"
         "time.sleep(60)\n")


@pytest.fixture
def ignoring():
    """The test process ignores SIGINT and SIGTERM, as under ``nohup … &``."""
    saved = signal.signal(signal.SIGINT, signal.SIG_IGN), signal.signal(signal.SIGTERM, signal.SIG_IGN)
    yield
    signal.signal(signal.SIGINT, saved[0])
    signal.signal(signal.SIGTERM, saved[1])


def _dispositions_and_end(proc: subprocess.Popen, sig: int, wait: float) -> tuple[str, int | None]:
    try:
        line = proc.stdout.readline().strip()
        proc.send_signal(sig)
        try:
            proc.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            pass
        return line, proc.poll()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_the_child_gets_default_sigint_and_sigterm_under_an_ignoring_parent(ignoring, sig):
    proc = start_for_signals([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    line, status = _dispositions_and_end(proc, sig, 30)
    assert line == "True True", line
    assert status == -sig  # killed by the signal (an uncaught KeyboardInterrupt ends by SIGINT too)


@pytest.mark.slow
def test_a_plainly_started_child_inherits_the_ignored_signals(ignoring):
    """What the helper exists for: without it the child ignores both and the signal does nothing."""
    proc = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    line, status = _dispositions_and_end(proc, signal.SIGINT, 2)
    assert line == "False False", line
    assert status is None  # still running 2 s after SIGINT (then killed)
