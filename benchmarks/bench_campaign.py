"""Campaign throughput: the whole `paper` study, both engines, and batching against B = 1.

Run:  python benchmarks/bench_campaign.py [--workers N] [--skip-paper]

Measures in one run, on this machine:

1. a sample of the `paper` study (semicircle, one design cell at T = 0.1 s and
   one at T = 1 s, ``--replicates`` runs each) stepped three ways in this
   process: the local engine one replicate at a time (B = 1, the baseline),
   the local engine batched (all sample runs in one batch), and the fmu
   engine (the four native FMUs through fmpy, built into a temporary
   directory); runs per second and the ratio to B = 1; the three must give
   the same metrics (checked: bit for bit);
2. the whole `paper` study (19,200 runs) with ``sblsim campaign`` on the
   local engine with ``--workers`` processes: wall time and runs per second;
3. the largest chunk of the study (800 runs in one batch, as the campaign
   steps it): cost per replicate-step and speed-up over B = 1, then where its
   time goes: each component's compiled step (the whole batch in one call)
   and the master's Python (data exchange, recording).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from fmus.build import build_all
from orchestrator.campaign import plan, run_campaign, run_chunk
from orchestrator.metrics import RUN_METRICS
from orchestrator.run import close_handles, make_handles, run_batch, with_replicates
from orchestrator.study import load_study


def sample_configs(study, replicates: int) -> tuple[list[list[dict]], int]:
    """Semicircle configs of one cell at each sampling time, ``replicates`` runs each; total replicate-steps."""
    picked = {}
    for chunk in plan(study, study.replicates):
        if chunk.scenario == "semicircle":
            picked.setdefault(chunk.configs[0]["simulation"]["sampling_time"], chunk)
    groups = [with_replicates(chunk.configs[0], range(replicates)) for chunk in picked.values()]
    return groups, sum(chunk.steps * replicates for chunk in picked.values())


def engines(study, replicates: int) -> float:
    """Time the sample on each engine; return the B = 1 cost per replicate-step [s]."""
    groups, steps = sample_configs(study, replicates)
    cfgs = [c for group in groups for c in group]
    rows = []
    local = make_handles("local")
    start = time.perf_counter()
    single = pd.concat([run_batch([c], "local", handles=local, timeseries=False).metrics for c in cfgs])
    t_single = time.perf_counter() - start
    rows.append(("local, B = 1 (baseline)", t_single))
    start = time.perf_counter()
    batched = pd.concat([run_batch(g, "local", handles=local, timeseries=False).metrics for g in groups])
    rows.append((f"local, batched (B = {replicates} per cell)", time.perf_counter() - start))
    assert np.array_equal(single[list(RUN_METRICS)].to_numpy(), batched[list(RUN_METRICS)].to_numpy(),
                          equal_nan=True), "batched and B = 1 metrics differ"
    with tempfile.TemporaryDirectory() as tmp:
        build_all(tmp)
        fmu = make_handles("fmu", tmp)
        try:
            start = time.perf_counter()
            via_fmu = pd.concat([run_batch(g, "fmu", handles=fmu, timeseries=False).metrics for g in groups])
            rows.append(("fmu (B = 1, through fmpy)", time.perf_counter() - start))
        finally:
            close_handles(fmu)
    assert np.array_equal(via_fmu[list(RUN_METRICS)].to_numpy(), batched[list(RUN_METRICS)].to_numpy(),
                          equal_nan=True), "fmu and local metrics differ"
    print(f"sample of the paper study: semicircle, one cell at T = 0.1 s and one at T = 1 s, {replicates} "
          f"replicates each ({len(cfgs)} runs, {steps} replicate-steps), one process")
    print(f"{'engine':36s} {'wall [s]':>9s} {'runs/s':>8s} {'us/replicate-step':>18s} {'speed-up':>9s}")
    for name, wall in rows:
        print(f"{name:36s} {wall:9.2f} {len(cfgs) / wall:8.2f} {wall / steps * 1e6:18.1f} {t_single / wall:9.2f}")
    return t_single / steps


def paper(study, workers: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        result = run_campaign(study, Path(tmp) / "paper", workers=workers, progress=False)
    print(f"\nwhole paper study: {result.computed} runs on the local engine, {workers} workers: "
          f"{result.wall_time:.1f} s, {result.runs_per_second:.0f} runs/s")
    return result.wall_time


def profile(study, baseline: float) -> None:
    """Time the largest chunk of the study (B = 800 on the local engine) and split it by component."""
    chunk = max(plan(study, 800), key=lambda c: c.runs * c.steps)
    start = time.perf_counter()
    run_chunk(chunk, study)
    wall = time.perf_counter() - start
    per_step = wall / chunk.runs / chunk.steps
    print(f"\nlargest chunk of the study ({chunk.runs} runs x {chunk.steps} steps, local engine, one batch): "
          f"{wall:.2f} s, {per_step * 1e6:.2f} us per replicate-step, speed-up over B = 1: {baseline / per_step:.0f}x")
    cfgs = [cfg for base in chunk.configs for cfg in with_replicates(base, range(chunk.replicates))]
    handles = make_handles("local")
    spent = dict.fromkeys(handles, 0.0)
    for name, handle in handles.items():
        def timed(t, h, _step=handle.do_step, _name=name):
            begin = time.perf_counter()
            _step(t, h)
            spent[_name] += time.perf_counter() - begin
        handle.do_step = timed
    start = time.perf_counter()
    run_batch(cfgs, "local", handles=handles, timeseries=False)
    total = time.perf_counter() - start
    print("where the time goes (each component's compiled step for the whole batch; the rest is Python):")
    parts = {f"{name} (compiled step)": seconds for name, seconds in spent.items()}
    parts["master, set-up and metrics (Python)"] = total - sum(spent.values())
    for label, seconds in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f"  {label:48s} {100 * seconds / total:5.1f} %  ({seconds / chunk.runs / chunk.steps * 1e6:.2f} us "
              "per replicate-step)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes for the paper study")
    parser.add_argument("--replicates", type=int, default=5, help="replicates per cell of the engine sample")
    parser.add_argument("--skip-paper", action="store_true", help="skip the whole-study run")
    args = parser.parse_args()
    study = load_study("paper")
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}, numpy {np.__version__}\n")
    baseline = engines(study, args.replicates)
    if not args.skip_paper:
        paper(study, args.workers)
    profile(study, baseline)


if __name__ == "__main__":
    main()
