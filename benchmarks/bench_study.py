"""The whole paper study against an earlier revision, as a user runs it, in one run on this machine.

Run:  python benchmarks/bench_study.py --against REV [--workers 2] [--rounds 3] [--study paper]
      python benchmarks/bench_study.py --against REV --instructions [--cut 2] [--study paper]

Each round times ``sblsim campaign STUDY --workers N`` (a fresh Python process: imports, planning,
the worker processes, merging and writing ``runs.parquet``, all of it) in this checkout and then in a
temporary worktree of ``REV`` (e.g. ``5a58c56``); rounds alternate, so a slow spell of the machine
hits both. Both sides run once first to fill the compiled-library cache. It prints every round, the
median of each side and the ratio of the medians, with the range of the per-round ratios.

With ``--instructions``: what other work on a shared machine does not change, the instructions executed
(valgrind's callgrind; valgrind must be installed). A cut of the study, every cell with ``--cut`` replicates,
runs in one process (one worker) here and at ``REV``, each under callgrind, once the compiled-library caches
are filled: the whole process's instructions and the compiled step's (``sblsim_do_step`` and all it calls: every
component's step, events and outputs, the random draws), and their ratios. The compiled step of the whole
study is the cut's times replicates / cut; the rest (imports, planning, each cell's set-up) hardly grows with
the replicates. It takes minutes (callgrind runs the code some fifty times slower).
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
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


#: A cut of a built-in study (argv[1]) with argv[2] replicates per cell, run in this process (one worker).
CUT = """
import sys, tempfile
from sblsim.orchestrator.campaign import run_campaign
from sblsim.orchestrator.campaign.study import load_study, study_source
raw, _ = study_source(sys.argv[1])
study = load_study({**raw, "study": {**raw["study"], "replicates": int(sys.argv[2])}})
with tempfile.TemporaryDirectory() as tmp:
    run_campaign(study, tmp + "/cut", workers=1, progress=False)
"""
#: The compiled step's entry point in callgrind's report (inclusive: every function it calls).
STEP = re.compile(r":sblsim_do_step\s")


def here(study: str, workers: int) -> float:
    """The study's wall time in this checkout [s]."""
    done = subprocess.run([sys.executable, "-c", STUDY, study, str(workers)], capture_output=True, text=True,
                          check=True)
    return float(done.stdout.split()[-1])


def callgrind(output: Path) -> list[str]:
    """The command prefix that runs a program under callgrind, its report into ``output``."""
    return ["valgrind", "--tool=callgrind", f"--callgrind-out-file={output}"]


def instructions(report: Path) -> tuple[int, int]:
    """The whole process's instructions and the compiled step's (:data:`STEP`, inclusive) in a callgrind report."""
    text = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", "--auto=no", str(report)],
                          capture_output=True, text=True, check=True).stdout
    total = step = 0
    for line in text.splitlines():
        count = re.match(r"\s*([\d,]+)\s", line)
        if count is None:
            continue
        value = int(count.group(1).replace(",", ""))
        if "PROGRAM TOTALS" in line:
            total = value
        elif STEP.search(line):
            step = max(step, value)
    return total, step


def count_instructions(against: str, study: str, cut: int) -> None:
    """The cut of ``study`` (``cut`` replicates per cell) under callgrind here and at ``against``: instructions of
    the whole process and of the compiled step, and their ratios."""
    if shutil.which("valgrind") is None or shutil.which("callgrind_annotate") is None:
        sys.exit("--instructions: valgrind (callgrind) is not installed")
    counts = {}
    with tempfile.TemporaryDirectory(prefix="sblsim_callgrind_") as tmp, checkout(against) as old:
        subprocess.run([sys.executable, "-c", CUT, study, "1"], capture_output=True, check=True)  # fill the caches
        old(CUT, study, "1")
        for label, run in (("this revision", None), (against, old)):
            report = Path(tmp) / f"{len(counts)}.out"
            if run is None:
                subprocess.run([*callgrind(report), sys.executable, "-c", CUT, study, str(cut)], capture_output=True,
                               check=True)
            else:
                run(CUT, study, str(cut), wrapper=callgrind(report))
            counts[label] = instructions(report)
            print(f"{label}: {counts[label][0]:,} instructions, the compiled step {counts[label][1]:,}", flush=True)
    (total, step), (total_then, step_then) = counts.values()
    print(f"\n`{study}` cut to {cut} replicates per cell, one worker: this revision executes {total / total_then:.3f}x "
          f"the instructions of {against} (the compiled step {step / step_then:.3f}x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, metavar="REV", help="the earlier revision to time")
    parser.add_argument("--workers", type=int, default=2, help="worker processes of the campaign")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (the median is reported)")
    parser.add_argument("--study", default="paper", help="built-in study (default: paper)")
    parser.add_argument("--instructions", action="store_true",
                        help="count the instructions of a cut of the study under callgrind instead of timing it")
    parser.add_argument("--cut", type=int, default=2, help="replicates per cell of --instructions' cut (default 2)")
    args = parser.parse_args()
    if args.instructions:
        count_instructions(args.against, args.study, args.cut)
        return
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
