"""Campaign progress: a bar on a terminal, log lines otherwise."""

from __future__ import annotations

import sys
import time

from tqdm import tqdm


class Progress:
    """Runs done, runs per second and time left: a tqdm bar on a terminal, log lines otherwise.

    ``bar``: None (a bar at a terminal, else log lines), True (a bar), False (log lines), ``"off"`` (nothing)
    or a callable ``bar(done, total)`` [runs].
    """

    def __init__(self, total: int, done: int, bar, every: float = 10.0) -> None:
        self.total, self.done, self.every = total, done, every
        self.start = self.last = time.perf_counter()
        self.first = done
        self.callback = bar if callable(bar) else None
        self.quiet = bar == "off" or self.callback is not None
        if bar is None:
            bar = sys.stderr.isatty()
        self.bar = None
        if self.quiet:
            if self.callback is not None:
                self.callback(done, total)
        elif bar:
            self.bar = tqdm(total=total, initial=done, unit="run", desc="campaign", smoothing=0.1)
        else:
            self._log(force=True)

    def update(self, runs: int) -> None:
        self.done += runs
        if self.callback is not None:
            self.callback(self.done, self.total)
        elif self.quiet:
            return
        elif self.bar is not None:
            self.bar.update(runs)
        else:
            self._log(force=self.done >= self.total)

    def _log(self, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last < self.every:
            return
        self.last = now
        rate = (self.done - self.first) / (now - self.start) if now > self.start else 0.0
        left = f", about {(self.total - self.done) / rate:.0f} s left" if rate > 0 and self.done < self.total else ""
        print(f"campaign: {self.done}/{self.total} runs ({100.0 * self.done / self.total:.0f} %), "
              f"{rate:.1f} runs/s{left}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
