"""Time the site scenarios' runs (eigenrays through the cast, detection by signal-to-noise), optionally against an
earlier revision measured in the same run.

Run:  python benchmarks/bench_site.py [--repeats N] [--against REV] [--scenarios lbl-field,usbl-deep]

For each scenario, :func:`sblsim.run` on the local engine (seed 0, the scenario's own duration), best of
``--repeats`` after a first run that loads (or compiles) the engine's library; with ``--against REV`` the same
snippet in a temporary worktree of that revision (its library compiled into the user's cache on first use), the
ratio, and whether the two runs' time series are the same numbers (they must be, for a change of speed only).
A random walk solves every leg's eigenrays exactly (no eigenray table), so these runs time the exact solve: the
bracketed Newton iterations over the profile's layers (docs/model.md).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from revision import checkout  # noqa: E402

#: Runs a scenario (argv[1]) argv[2] times after a first run; prints the best time [s] and a digest of its series.
SNIPPET = """
import hashlib, json, sys, time
import numpy as np
from sblsim.orchestrator.commands.common import load
from sblsim.orchestrator.commands.run import run
config = load(sys.argv[1], seed=0)
run(config)
best = float("inf")
for _ in range(int(sys.argv[2])):
    start = time.perf_counter()
    result = run(config)
    best = min(best, time.perf_counter() - start)
series = result.timeseries.select_dtypes("number").to_numpy(dtype=float)
print(json.dumps({"seconds": best, "steps": len(series),
                  "digest": hashlib.sha256(np.ascontiguousarray(series).tobytes()).hexdigest()}))
"""


def timed(run, scenario: str, repeats: int) -> dict:
    return json.loads(run(SNIPPET, scenario, str(repeats)).splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per scenario (the best is kept)")
    parser.add_argument("--against", default=None, metavar="REV", help="also time revision REV")
    parser.add_argument("--scenarios", default="lbl-field,usbl-deep", help="comma-separated scenarios")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats: must be at least 1")
    scenarios = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    today = {s: timed(_here, s, args.repeats) for s in scenarios}
    then = {}
    if args.against:
        with checkout(args.against) as run:
            then = {s: timed(run, s, args.repeats) for s in scenarios}
    for s in scenarios:
        line = f"{s}: {today[s]['steps']} steps in {today[s]['seconds']:.2f} s"
        if s in then:
            same = "the same numbers" if then[s]["digest"] == today[s]["digest"] else "DIFFERENT numbers"
            ratio = then[s]["seconds"] / today[s]["seconds"]
            line += f"; revision {args.against}: {then[s]['seconds']:.2f} s, {ratio:.1f}x today's time; {same}"
        print(line, flush=True)


def _here(code: str, *args: str) -> str:
    """``code`` run in this checkout's environment (as :func:`revision.checkout` runs it in a revision's)."""
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, check=True).stdout


if __name__ == "__main__":
    main()
