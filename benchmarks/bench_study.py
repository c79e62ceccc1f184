"""The whole paper study against an earlier revision, as a user runs it, in one run on this machine.

Run:  python benchmarks/bench_study.py --against REV [--workers 2] [--rounds 3] [--study paper]

Each round times ``sblsim campaign STUDY --workers N`` (a fresh Python process: imports, planning,
the worker processes, merging and writing ``runs.parquet``, all of it) in this checkout and then in a
temporary worktree of ``REV`` (e.g. ``5a58c56``); rounds alternate, so a slow spell of the machine
hits both. Both sides run once first to fill the compiled-library cache. It prints every round, the
median of each side and the ratio of the medians, with the range of the per-round ratios.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from revision import checkout  # noqa: E402

#: One whole study through the command line's entry point; prints its wall time [s].
STUDY = """
import os, sys, tempfile, time
start = time.perf_counter()
from sblsim.orchestrator.cli import main
with tempfile.TemporaryDirectory() as tmp:
    status = main(["campaign", sys.argv[1], "--workers", sys.argv[2], "--out", os.path.join(tmp, "study")])
assert not status, status
print(time.perf_counter() - start)
"""


def here(study: str, workers: int) -> float:
    """The study's wall time in this checkout [s]."""
    done = subprocess.run([sys.executable, "-c", STUDY, study, str(workers)], capture_output=True, text=True,
                          check=True)
    return float(done.stdout.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, metavar="REV", help="the earlier revision to time")
    parser.add_argument("--workers", type=int, default=2, help="worker processes of the campaign")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (the median is reported)")
    parser.add_argument("--study", default="paper", help="built-in study (default: paper)")
    args = parser.parse_args()
    now, then = [], []
    with checkout(args.against) as old:
        def there() -> float:
            return float(old(STUDY, args.study, str(args.workers)).split()[-1])

        here(args.study, args.workers), there()  # fill the compiled-library caches
        for k in range(args.rounds):
            now.append(here(args.study, args.workers))
            then.append(there())
            print(f"round {k + 1}: this revision {now[-1]:.1f} s, {args.against} {then[-1]:.1f} s "
                  f"({now[-1] / then[-1]:.2f}x)", flush=True)
    ratios = [a / b for a, b in zip(now, then)]
    print(f"\n`sblsim campaign {args.study} --workers {args.workers}`, median of {args.rounds}: this revision "
          f"{statistics.median(now):.1f} s, {args.against} {statistics.median(then):.1f} s: "
          f"{statistics.median(now) / statistics.median(then):.2f}x (rounds {min(ratios):.2f}-{max(ratios):.2f}x)")


if __name__ == "__main__":
    main()
