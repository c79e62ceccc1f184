"""Command line: ``sblsim COMMAND ...``, its parser and dispatch built from the registered commands
(:data:`sblsim.orchestrator.commands.COMMANDS`: ``run``, ``replay``, ``calibrate``, ``compare``, ``budget``,
``map``, ``campaign``, ``ssp export``, ``analyze``, ``fmus build|validate|variables``, ``codegen receiver``).

Bad input of any kind ends with a one-line ``sblsim: error: ...`` naming the field and the allowed range, exit
status 2, and nothing written; Ctrl-C, SIGTERM or SIGHUP with one line ``sblsim: interrupted`` and 128 + the signal
(130, 143, 129), nothing half-written, wherever the signal lands (inside a compiled library's call too:
:mod:`sblsim.orchestrator.io.stop`). Standard output survives a reader that goes away (``sblsim run ... | head -1``).
"""
from __future__ import annotations

import argparse
import os
import sys

from sblsim.orchestrator.io.memory import arrow_pool
from sblsim.orchestrator.io.stop import (
    SIGNAL_STATUS_BASE,
    end_on_further_signals,
    ending,
    exit_past_threads,
    exit_status,
    is_stop,
    stop_on,
    workers_ignore_ctrl_c,
)

# a worker process a command spawns imports this module first: it ignores Ctrl-C (its command stops it) before the
# seconds of imports below, in which a Ctrl-C at the terminal would end it with a traceback of its own
workers_ignore_ctrl_c()

from sblsim.models.errors import SblsimError  # noqa: E402
from sblsim.orchestrator.commands import COMMANDS  # noqa: E402
from sblsim.orchestrator.commands.console import EXIT_USAGE, LOCKS, print_notes  # noqa: E402
from sblsim.orchestrator.cosim.config import collected_notes  # noqa: E402
from sblsim.orchestrator.io.version import installed_version  # noqa: E402


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2 (argparse prints usage too)
        self.exit(EXIT_USAGE, f"sblsim: error: {message}\n")


def _parser() -> argparse.ArgumentParser:
    """``sblsim``'s parser: a subparser per command of :data:`~sblsim.orchestrator.commands.COMMANDS`."""
    p = _Parser(prog="sblsim", description="SBL acoustic underwater positioning co-simulation")
    p.add_argument("--version", action="version", version=f"sblsim {installed_version()}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, command in COMMANDS.items():
        command.add_arguments(sub.add_parser(name, help=command.HELP))
    return p


class _PipeSafeStream:
    """Standard output that a closed pipe does not stop (``sblsim run ... | head -1``).

    When the reader goes away, the first write or flush that fails with :class:`BrokenPipeError` points the
    stream's file descriptor at ``os.devnull`` (as Python's documentation of SIGPIPE recommends, so that
    nothing fails again at exit) and drops the rest: the command finishes its work (every result written)
    and exits with its own status, without an error about a pipe nobody reads.
    """

    def __init__(self, stream) -> None:
        self._stream = stream
        self.broken = False

    def _closed_pipe(self) -> None:
        self.broken = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, AttributeError):  # a stream without a descriptor (a test's capture)
            pass

    def write(self, text: str) -> int:
        if self.broken:
            return len(text)
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._closed_pipe()
            return len(text)

    def flush(self) -> None:
        if self.broken:
            return
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._closed_pipe()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``sblsim`` console script."""
    args = _parser().parse_args(argv)
    # Arrow's memory pool chosen before the command loads pyarrow (its C++ library takes its default once, when
    # loaded); a store's reading, whose memory is its piece's, keeps jemalloc's decay (faster)
    arrow_pool(decay=args.command != "store")
    stdout = sys.stdout
    sys.stdout = _PipeSafeStream(stdout)
    try:
        with stop_on():  # SIGINT, SIGTERM, SIGHUP: the command's stop (sblsim.orchestrator.io.stop)
            status = _command(args)
            sys.stdout.flush()
            return status
    finally:
        sys.stdout = stdout


def run(argv: list[str] | None = None) -> None:
    """The ``sblsim`` console script and ``python -m sblsim.orchestrator.cli``: :func:`main`, then the process's exit
    with its status; a command a stop ended does not wait for good on a thread a library left running
    (:func:`~sblsim.orchestrator.io.stop.exit_past_threads`), and a further signal while it ends ends it at once with
    the stop's status (:func:`~sblsim.orchestrator.io.stop.end_on_further_signals`)."""
    status = main(argv)
    if status > SIGNAL_STATUS_BASE:  # a stop's status (128 + the signal); a command's own are 0, 1 and 2
        end_on_further_signals(status)
        exit_past_threads(status)
    sys.exit(status)


def _command(args: argparse.Namespace) -> int:
    try:
        with collected_notes():  # the configurations' notes: printed with the output folder, or at the end
            status = COMMANDS[args.command].main(args)
            print_notes()
            return status
    except BaseException as exc:
        with ending():
            return _ended_by(exc, args)
    finally:
        with ending():  # a second signal does not stop the release
            while LOCKS:
                LOCKS.pop().release()


def _ended_by(exc: BaseException, args: argparse.Namespace) -> int:
    """The exit status of a command that ``exc`` ended, its one line printed; ``exc`` raised again where it is
    none of these (a fault of ours: its traceback)."""
    if is_stop(exc):  # a signal: whatever came out of the work while it was pending (a compiled library's error)
        print("sblsim: interrupted", file=sys.stderr)
        return exit_status()
    if isinstance(exc, SblsimError):  # every kind of sblsim's errors (sblsim.models.errors): one line, exit 2
        print(f"sblsim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if isinstance(exc, OSError):  # a full disk or a folder that refused a write during the work: one line
        reason = os.strerror(exc.errno) if exc.errno else str(exc)
        where = f": {exc.filename}" if exc.filename else ""
        resume = (" (a campaign keeps its finished chunks: run it again with --resume)" if args.command == "campaign"
                  else "")
        print(f"sblsim: error: {reason}{where}; nothing in the output folder was replaced{resume}", file=sys.stderr)
        return EXIT_USAGE
    raise exc


if __name__ == "__main__":
    run()
