"""Progress of long work: a tqdm bar at a terminal, a plain log line every few seconds otherwise, a caller's
callback, or nothing.

Every command that can take more than a few seconds (``run``, ``compare``, ``map``, ``budget``,
``campaign``) reports through :class:`Progress`: the command line passes ``"auto"`` (a bar when standard
error is a terminal, else a line ``DESC: done/total UNITs (P %), about S s left`` every :data:`LOG_EVERY`
seconds, none for work that ends sooner), the Python API ``False`` by default (silent), ``True`` for a bar,
or a callable. A campaign's reporter takes three options: it starts where a resumed campaign stands
(``initial``), prints its first and last line whatever the time (``ends``), and its line has the rate
(``rate``: ``campaign: 4/8 runs (50 %), 0.5 runs/s, about 8 s left``).

Each update is also where the work stops when a stop is pending (:func:`sblsim.orchestrator.io.stop.check`: a
signal whose exception a compiled library dropped, or that came between two steps).
"""

from __future__ import annotations

import sys
import time
from typing import Callable, Union

from tqdm import tqdm

from sblsim.models.declarations import ModelError, shown
from sblsim.orchestrator.io.stop import check

#: How often a plain progress line is printed when standard error is not a terminal [s].
LOG_EVERY = 10.0

#: What a ``progress`` argument may be: ``False``/``None``/``"off"`` (silent), ``True`` (a tqdm bar on standard
#: error), ``"auto"`` (a bar at a terminal, else log lines), ``"log"`` (log lines, even at a terminal), or a
#: callable ``progress(done, total)`` [units of the work].
ProgressSpec = Union[bool, None, str, Callable[[float, float], object]]


def check_progress(spec: object, where: str = "progress") -> None:
    """Refuse a progress ``spec`` that is none of :data:`ProgressSpec`.

    Raises
    ------
    ModelError
        Naming ``where`` and what is allowed (a :class:`ValueError` too).
    """
    if callable(spec) or spec is None or isinstance(spec, bool) or (isinstance(spec, str)
                                                                    and spec in ("auto", "log", "off")):
        return
    raise ModelError(f"{where}: {shown(spec)} is not True, False, 'auto', 'log', 'off' or a callable(done, total)")


class Progress:
    """Report ``done`` of ``total`` units of work (steps, runs, cells, targets).

    The rate is the units done since this reporter started over the time since [units/s], and the time
    left the units still to do over that rate [s].

    Parameters
    ----------
    total : float
        Units of the whole work (0: unknown; no time left is estimated).
    desc : str
        What the work is (the bar's label, the log line's start).
    unit : str
        The unit's name (``step``, ``run``, ...).
    spec : bool, str or callable
        :data:`ProgressSpec`.
    every : float
        Seconds between plain log lines [s].
    initial : float
        Units already done when this reporter starts (a resumed campaign's): the bar and the lines start
        there, and the rate counts only the units done since.
    ends : bool
        Report the start and the end whatever the time: the first log line at once and the last when the
        work is done (a callback is called at once with ``initial``); the bar stays on the terminal.
    rate : bool
        The log line gives the rate (``, 0.5 runs/s``).

    Raises
    ------
    ModelError
        On a ``spec`` that is none of :data:`ProgressSpec` (:func:`check_progress`).
    """

    def __init__(self, total: float, desc: str, unit: str = "step", spec: ProgressSpec = False,
                 every: float = LOG_EVERY, *, initial: float = 0, ends: bool = False, rate: bool = False) -> None:
        self.total, self.desc, self.unit, self.every = total, desc, unit, every
        self.initial = self.done = initial
        self.ends, self.rate = ends, rate
        self.start = self.last = time.perf_counter()
        self.bar = None
        self.callback: Callable[[float, float], object] | None = None
        self.log = False
        check_progress(spec)
        if callable(spec):
            self.callback = spec
        elif spec == "auto":
            if sys.stderr.isatty():
                self._open_bar()
            else:
                self.log = True
        elif spec == "log":
            self.log = True
        elif spec is True:
            self._open_bar()
        if ends:
            if self.callback is not None:
                self.callback(self.done, self.total)
            elif self.log:
                self._line(self.start)

    def _open_bar(self) -> None:
        self.bar = tqdm(total=self.total or None, initial=self.initial, unit=self.unit, desc=self.desc,
                        leave=self.ends, smoothing=0.1)

    @property
    def active(self) -> bool:
        """Whether anything is reported (callers may skip the bookkeeping when not)."""
        return self.bar is not None or self.callback is not None or self.log

    def update(self, units: float = 1) -> None:
        """``units`` more of the work are done.

        Raises
        ------
        KeyboardInterrupt
            A stop is pending (:func:`sblsim.orchestrator.io.stop.check`): the work stops at this step.
        """
        check()
        self.done += units
        if self.bar is not None:
            self.bar.update(units)
        elif self.callback is not None:
            self.callback(self.done, self.total)
        elif self.log:
            now = time.perf_counter()
            if now - self.last >= self.every or (self.ends and self.total and self.done >= self.total):
                self.last = now
                self._line(now)

    def _line(self, now: float) -> None:
        rate = (self.done - self.initial) / (now - self.start) if now > self.start else 0.0
        if self.total:
            speed = f", {rate:.1f} {self.unit}s/s" if self.rate else ""
            left = (f", about {(self.total - self.done) / rate:.0f} s left" if rate > 0 and self.done < self.total
                    else "")
            print(f"{self.desc}: {self.done:.0f}/{self.total:.0f} {self.unit}s ({100.0 * self.done / self.total:.0f} "
                  f"%){speed}{left}", file=sys.stderr, flush=True)
        else:
            print(f"{self.desc}: {self.done:.0f} {self.unit}s, {now - self.start:.0f} s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress_of(spec: ProgressSpec | Progress, total: float, desc: str, unit: str = "step") -> tuple[Progress, bool]:
    """A :class:`Progress` for a piece of work: ``spec`` itself when it is one already (shared by the pieces
    of a larger work; not closed by the piece), else a new one of ``total`` units.

    Returns
    -------
    progress : Progress
    own : bool
        Whether the caller made it (and closes it).
    """
    if isinstance(spec, Progress):
        return spec, False
    return Progress(total, desc, unit, spec), True
