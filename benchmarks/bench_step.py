"""Cost of one co-simulation step (macro step T: four components, connections, recording).

Run:  python benchmarks/bench_step.py [--duration 30] [--repeat 3]

Measures, in one process and one run, the `semicircle` scenario on
* the local engine, one replicate (B = 1): the baseline;
* the local engine, 50 replicates stepped together (cost per replicate-step);
* the fmu engine (the four built FMUs through fmpy, B = 1).
Prints the best of ``--repeat`` wall-clock times per step and ratios to the baseline.
The FMUs are built into a temporary directory first.
"""

from __future__ import annotations

import argparse
import tempfile
import time

from fmus.build import build_all
from orchestrator.config import load_config
from orchestrator.run import close_handles, make_handles, run


def best_time(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="simulated time per run [s]")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions (best is kept)")
    args = parser.parse_args()
    cfg = load_config("semicircle", [f"simulation.duration={args.duration}"], seed=1)
    steps = int(round(args.duration / cfg["simulation"]["sampling_time"]))

    rows = []
    local = make_handles("local")
    t_local = best_time(lambda: run(cfg, "local", handles=local), args.repeat) / steps
    rows.append(("local, B = 1", t_local))
    batch = 50
    t_batch = best_time(lambda: run(cfg, "local", replicates=range(batch), handles=local), args.repeat)
    rows.append((f"local, B = {batch} (per replicate-step)", t_batch / steps / batch))
    with tempfile.TemporaryDirectory() as tmp:
        build_all(tmp)
        fmu = make_handles("fmu", tmp)
        try:
            rows.append(("fmu, B = 1", best_time(lambda: run(cfg, "fmu", handles=fmu), args.repeat) / steps))
        finally:
            close_handles(fmu)

    print(f"semicircle, {steps} macro steps of T = {cfg['simulation']['sampling_time']} s, best of {args.repeat}")
    print(f"{'engine':40s} {'per step [ms]':>14s} {'ratio to local B=1':>20s}")
    for name, seconds in rows:
        print(f"{name:40s} {seconds * 1e3:14.3f} {seconds / t_local:20.2f}")


if __name__ == "__main__":
    main()
