"""Cost of one co-simulation macro step (four components, 39 connections, recording).

Run:  python benchmarks/bench_step.py [--duration 30] [--repeat 3] [--against REV] [--pythonfmu REV]

Measures, in one process and one run, the `semicircle` scenario on
* the local engine, one replicate (B = 1): the baseline;
* the local engine, 50 replicates stepped together (cost per replicate-step);
* the fmu engine: the four native FMUs through fmpy, B = 1;
* with ``--against REV``: the local engine (B = 1) and the native FMUs of an
  earlier revision, timed the same way in a subprocess from a temporary git
  worktree (e.g. to check that a refactoring kept the speed);
* with ``--pythonfmu REV``: the fmu engine of an earlier git revision whose
  FMUs embedded Python (pythonfmu; e.g. ``9903b13``), built and timed in a
  subprocess from a temporary git worktree of this repository (needs
  ``pip install pythonfmu``).
Prints the best of ``--repeat`` wall-clock times per macro step and the ratio
to the baseline. The FMUs are built into a temporary directory first.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from sblsim.fmus.build import build_all
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.run import run

sys.path.insert(0, str(Path(__file__).resolve().parent))
from revision import run_at  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

#: Timed in the earlier revision's own code (its ``run`` and ``make_handles`` had the same signatures).
OLD = """
import sys, tempfile, time
from sblsim.fmus.build import build_all
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import make_handles, run
duration, repeat = float(sys.argv[1]), int(sys.argv[2])
cfg = load_config("semicircle", [f"simulation.duration={duration}"], seed=1)
with tempfile.TemporaryDirectory() as tmp:
    build_all(tmp)
    handles = make_handles("fmu", tmp)
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        result = run(cfg, "fmu", handles=handles)
        best = min(best, time.perf_counter() - start)
print(best / result.steps)
"""


#: The local engine (B = 1) and the native FMUs of an earlier compiled revision, timed as :func:`main` times them.
AT_REVISION = """
import sys, tempfile, time
from sblsim.fmus.build import build_all
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
try:
    from sblsim.orchestrator.cosim.engines import make_handles, close_handles
except ImportError:  # revisions where the run module built the handles
    from sblsim.orchestrator.cosim.run import make_handles, close_handles
duration, repeat = float(sys.argv[1]), int(sys.argv[2])
cfg = load_config("semicircle", [f"simulation.duration={duration}"], seed=1)
def best(engine, handles):
    run(cfg, engine, handles=handles)
    out = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        result = run(cfg, engine, handles=handles)
        out = min(out, time.perf_counter() - start)
    return out / result.steps
local = best("local", make_handles("local"))
with tempfile.TemporaryDirectory() as tmp:
    build_all(tmp)
    handles = make_handles("fmu", tmp)
    fmu = best("fmu", handles)
    close_handles(handles)
print(local, fmu)
"""


def best_time(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def pythonfmu_step(revision: str, duration: float, repeat: int) -> float:
    """Seconds per macro step of the fmu engine at an earlier revision (its pythonfmu FMUs)."""
    return float(run_at(revision, OLD, str(duration), str(repeat)).split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="simulated time per run [s]")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions (best is kept)")
    parser.add_argument("--against", metavar="REV", default=None,
                        help="also time the local engine (B = 1) and the FMUs of an earlier compiled revision")
    parser.add_argument("--pythonfmu", metavar="REV", default=None,
                        help="also time the pythonfmu FMUs of an earlier git revision (e.g. 9903b13)")
    args = parser.parse_args()
    cfg = load_config("semicircle", [f"simulation.duration={args.duration}"], seed=1)
    steps = int(round(args.duration / cfg["simulation"]["sampling_time"]))

    rows = []
    local = make_handles("local")
    run(cfg, "local", handles=local)  # warm-up: the compiled library is built or loaded once
    t_local = best_time(lambda: run(cfg, "local", handles=local), args.repeat) / steps
    rows.append(("local, B = 1", t_local))
    batch = 50
    t_batch = best_time(lambda: run(cfg, "local", replicates=range(batch), handles=local), args.repeat)
    rows.append((f"local, B = {batch} (per replicate-step)", t_batch / steps / batch))
    with tempfile.TemporaryDirectory() as tmp:
        build_all(tmp)
        fmu = make_handles("fmu", tmp)
        try:
            run(cfg, "fmu", handles=fmu)
            rows.append(("fmu, B = 1 (native FMUs through fmpy)",
                         best_time(lambda: run(cfg, "fmu", handles=fmu), args.repeat) / steps))
        finally:
            close_handles(fmu)
    if args.against:
        local_then, fmu_then = map(float, run_at(args.against, AT_REVISION, str(args.duration),
                                                 str(args.repeat)).split()[-2:])
        rows += [(f"local, B = 1, revision {args.against}", local_then),
                 (f"fmu, B = 1, revision {args.against}", fmu_then)]
    if args.pythonfmu:
        rows.append((f"fmu, B = 1, pythonfmu FMUs of {args.pythonfmu}",
                     pythonfmu_step(args.pythonfmu, args.duration, args.repeat)))

    print(f"semicircle, {steps} macro steps of T = {cfg['simulation']['sampling_time']} s, best of {args.repeat}")
    print(f"{'engine':48s} {'per step [us]':>14s} {'ratio to local B=1':>20s}")
    for name, seconds in rows:
        print(f"{name:48s} {seconds * 1e6:14.1f} {seconds / t_local:20.2f}")


if __name__ == "__main__":
    main()
