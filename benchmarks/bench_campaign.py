"""Campaign throughput, with every ratio measured in this one run on this machine.

Run:  python benchmarks/bench_campaign.py [--workers N] [--numpy REV] [--against REV] [--skip-paper]
                                             [--skip-scaling] [--ray | --only-ray] [--ray-runs N]
                                             [--snr | --only-snr] [--snr-runs N] [--only-floor]

1. **Engines**: a sample of the `paper` study (semicircle, one design cell at T = 0.1 s and one at
   T = 1 s, ``--replicates`` runs each) stepped three ways in this process: the local engine one
   replicate at a time (B = 1, the baseline), batched, and the fmu engine (the four native FMUs through
   fmpy, built into a temporary directory); the three must give the same metrics (checked, bit for bit).
2. **A campaign chunk**: 800 runs of `semicircle` (its 100 s at T = 0.1 s: 1,000 steps) in one batch, as a
   campaign worker steps them, timed after a first run in the process (best of three): µs per
   replicate-step, its ratio to **one FilterPy ``ExtendedKalmanFilter`` predict + update** (6 states, four
   ranges and the depth, the paper's EKF step; the best of seven rounds) timed here and to **the same step in
   plain C** (``ekf_floor.c``: compiled here ``-O2`` without vectorization, checked equal to FilterPy's step to
   1e-12 first; the compiled floor, which does not move with numpy's overhead; target ≤ 2.5×), and where the
   time goes (each component's compiled step, the compiled master loop, the metrics and the bound); then the
   same chunk for SBL with TWTT ranging, LBL and USBL, against the SBL chunk. ``--only-floor`` times the chunk,
   the two EKF steps and (unless ``--skip-paper``) the whole study on ``--workers`` processes alone. With
   ``--ray`` (or alone with ``--only-ray``): the chunk of SBL, LBL and USBL through the Munk profile with
   ``acoustics.propagation = ray`` beside ``straight``, alternated in this run: µs per replicate-step and the
   ratio (target ≤ 1.5×).
   With ``--snr`` (or alone with ``--only-snr``): the same with eigenrays for both, ``acoustics.detection =
   snr`` beside ``fixed`` in 20 m of water (target ≤ 2×).
3. With ``--numpy REV``: the same chunk on the batched numpy engine of an earlier revision (e.g.
   ``9903b13``), timed the same way in a subprocess from a temporary git worktree.
   With ``--against REV``: the same chunk on the compiled engine of an earlier revision, timed the same
   way (e.g. to check that a refactoring kept the speed).
4. **The whole `paper` study** (19,200 runs) with 1 and with ``--workers`` processes: wall time, runs/s,
   µs per replicate-step per core (and its ratio to the plain-C EKF step) and the speed-up.
5. **Time against study size**: the `million` study cut to 1×, 2× and 4× ``--scale`` replicates per cell
   on ``--workers`` processes: wall time and its ratio to the 1× one (linear growth expected).
6. **Threads inside a process**: the chunk's master loop (compiled; it releases the GIL) as one batch
   against two half-batches in two threads, and what that makes of a whole chunk (its metrics stay in one
   thread), to compare with the processes of 4.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.fmus.build import build_all
from sblsim.models.errors import CompileError
from sblsim.orchestrator.campaign import plan, run_campaign
from sblsim.orchestrator.campaign.study import load_study, study_source
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.master import RecordBuffer
from sblsim.orchestrator.cosim.metrics import RUN_METRICS
from sblsim.orchestrator.cosim.run import run_batch, with_replicates

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ekf_floor import filterpy_step, floor_step  # noqa: E402
from revision import run_at  # noqa: E402

#: The chunk, timed in an earlier revision's own code (its run_batch had the same signature).
OLD_CHUNK = """
import sys, time
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run_batch, with_replicates
cfg = load_config("semicircle", ["simulation.duration=" + sys.argv[1]], seed=1)
cfgs = with_replicates(cfg, range(int(sys.argv[2])))
run_batch(cfgs[:10], timeseries=False)
best = float("inf")
for _ in range(2):
    start = time.perf_counter()
    result = run_batch(cfgs, timeseries=False)
    best = min(best, time.perf_counter() - start)
print(best / len(cfgs) / result.steps)
"""


def sample_configs(study, replicates: int) -> tuple[list[list[dict]], int]:
    """Semicircle configs of one cell at each sampling time, ``replicates`` runs each; total replicate-steps."""
    picked = {}
    for chunk in plan(study, study.replicates):
        if chunk.scenario == "semicircle":
            picked.setdefault(chunk.plans[0]["simulation"]["sampling_time"], chunk)
    groups = [with_replicates(chunk.plans[0], range(replicates)) for chunk in picked.values()]
    return groups, sum(chunk.steps * replicates for chunk in picked.values())


def engines(study, replicates: int) -> None:
    """Time the sample on each engine (B = 1, batched, FMUs); the metrics must agree bit for bit."""
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
    columns = list(RUN_METRICS)
    single, batched = single[columns].reset_index(drop=True), batched[columns].reset_index(drop=True)
    pd.testing.assert_frame_equal(single, batched, check_exact=True)  # bit for bit
    with tempfile.TemporaryDirectory() as tmp:
        build_all(tmp)
        fmu = make_handles("fmu", tmp)
        try:
            start = time.perf_counter()
            via_fmu = pd.concat([run_batch(g, "fmu", handles=fmu, timeseries=False).metrics for g in groups])
            rows.append(("fmu (B = 1, through fmpy)", time.perf_counter() - start))
        finally:
            close_handles(fmu)
    pd.testing.assert_frame_equal(via_fmu[columns].reset_index(drop=True), batched, check_exact=True)
    print(f"1. sample of the paper study: semicircle, one cell at T = 0.1 s and one at T = 1 s, {replicates} "
          f"replicates each ({len(cfgs)} runs, {steps} replicate-steps), one process")
    print(f"   {'engine':36s} {'wall [s]':>9s} {'runs/s':>8s} {'us/replicate-step':>18s} {'speed-up':>9s}")
    for name, wall in rows:
        print(f"   {name:36s} {wall:9.2f} {len(cfgs) / wall:8.2f} {wall / steps * 1e6:18.1f} {t_single / wall:9.2f}")


#: The benchmark chunk: semicircle runs of 100 s (1,000 steps at T = 0.1 s), in one batch.
CHUNK_RUNS, CHUNK_DURATION = 800, 100.0


def time_chunk(overrides: tuple[str, ...] = ()):
    """The benchmark chunk with ``--set`` overrides, timed after a first run in this process (best of three):
    the wall time [s] and the run's result."""
    cfgs = with_replicates(load_config("semicircle", [f"simulation.duration={CHUNK_DURATION}", *overrides], seed=1),
                           range(CHUNK_RUNS))
    records = RecordBuffer()  # re-used from batch to batch, as a campaign worker does
    run_batch(cfgs, timeseries=False, records=records)  # first time: the library loaded, memory first touched
    best = None
    for _ in range(3):
        start = time.perf_counter()
        result = run_batch(cfgs, timeseries=False, records=records)
        wall = time.perf_counter() - start
        best = (wall, result) if best is None or wall < best[0] else best
    return best


#: The systems timed against the SBL chunk: their ``--set`` overrides (the defaults ``sblsim compare`` starts from).
SYSTEM_CHUNKS = {"SBL with TWTT ranging": ("acoustics.ranging=twtt",),
                 "LBL (4 transponders on a 50 m circle)": ("platform.system=lbl", "platform.layout=circle",
                                                           "platform.baseline=50"),
                 "USBL (range and direction of arrival)": ("platform.system=usbl",)}


def system_timing(per_step: float) -> None:
    """The chunk of each system of :data:`SYSTEM_CHUNKS`, per replicate-step and against the SBL chunk."""
    print("   other systems, the same chunk:")
    for label, overrides in SYSTEM_CHUNKS.items():
        wall, result = time_chunk(overrides)
        cost = wall / (CHUNK_RUNS * result.steps)
        print(f"     {label:44s} {cost * 1e6:.2f} us per replicate-step, {cost / per_step:.2f}x the SBL chunk")


#: The systems whose chunk is timed with eigenrays beside the straight line (``--ray``): their ``--set`` overrides.
RAY_SYSTEMS = {"SBL": (), "LBL": SYSTEM_CHUNKS["LBL (4 transponders on a 50 m circle)"],
               "USBL": ("platform.system=usbl",)}
#: The profile of both propagations' chunks (a deep one: the rays bend), and the issue's target for the ratio.
RAY_PROFILE, RAY_TARGET = "munk", 1.5


def alternated_timing(key: str, choices: tuple[str, str], common: tuple[str, ...], runs: int, duration: float,
                      rounds: int, target: float, own: Mapping[str, tuple[str, ...]] | None = None
                      ) -> dict[str, tuple[float, float, object, object]]:
    """The chunk of each system of :data:`RAY_SYSTEMS` with ``key`` set to each of the two ``choices`` (and the
    ``--set`` overrides ``common``, and a system's ``own``), each timed after a first run, the two alternated
    ``rounds`` times (the best of each: a load on the machine falls on both alike); prints µs per replicate-step
    and their ratio against ``target``.

    Returns
    -------
    dict
        System -> (first, second choice) s per replicate-step and the two runs' results.
    """
    out = {}
    for label, overrides in RAY_SYSTEMS.items():
        batches, records, best, results = {}, {}, {}, {}
        for choice in choices:
            cfg = load_config("semicircle", [f"simulation.duration={duration}", *overrides, *common,
                                             *(own or {}).get(label, ()), f"{key}={choice}"], seed=1)
            batches[choice], records[choice] = with_replicates(cfg, range(runs)), RecordBuffer()
            run_batch(batches[choice], timeseries=False, records=records[choice])  # first time
        for _ in range(rounds):
            for choice, cfgs in batches.items():
                start = time.perf_counter()
                results[choice] = run_batch(cfgs, timeseries=False, records=records[choice])
                wall = time.perf_counter() - start
                best[choice] = min(wall, best.get(choice, wall))
        steps = runs * results[choices[1]].steps
        base, other = best[choices[0]] / steps, best[choices[1]] / steps
        print(f"     {label:5s} {choices[0]} {base * 1e6:7.2f} us, {choices[1]} {other * 1e6:7.2f} us per "
              f"replicate-step: {other / base:.2f}x ({'within' if other / base <= target else 'beyond'} the target "
              f"{target}x)")
        out[label] = (base, other, results[choices[0]], results[choices[1]])
    return out


def propagation_timing(runs: int = CHUNK_RUNS, duration: float = CHUNK_DURATION,
                       rounds: int = 3) -> dict[str, tuple[float, float, object, object]]:
    """The chunk of each system of :data:`RAY_SYSTEMS` with ``acoustics.propagation = ray`` beside ``straight``
    (both through :data:`RAY_PROFILE`), alternated (:func:`alternated_timing`).

    Returns
    -------
    dict
        System -> (straight, ray) s per replicate-step and the two runs' results.
    """
    print(f"\n2b. eigenrays (acoustics.propagation = ray) beside the straight line, the same chunk ({runs} runs x "
          f"{duration:g} s, profile {RAY_PROFILE}), best of {rounds} alternated:")
    return alternated_timing("acoustics.propagation", ("straight", "ray"),
                             (f"acoustics.sound_speed_profile={RAY_PROFILE}",), runs, duration, rounds, RAY_TARGET)


#: The ``--set`` overrides of both detections' chunks (``--snr``): eigenrays through :data:`RAY_PROFILE` in water
#: of :data:`SNR_WATER_DEPTH` (the surface- and bottom-reflected families exist; a USBL exchange and its multipath
#: end within the chunk's 0.1 s slot), and the issue's target for the ratio.
SNR_WATER_DEPTH, SNR_TARGET = 20.0, 2.0
SNR_COMMON = (f"acoustics.sound_speed_profile={RAY_PROFILE}", "acoustics.propagation=ray",
              f"acoustics.water_depth={SNR_WATER_DEPTH:g}")
#: The systems' own overrides there: LBL's transponders on that floor (1 m above it).
SNR_OWN = {"LBL": (f"platform.seafloor_depth={SNR_WATER_DEPTH - 1:g}",)}


def detection_timing(runs: int = CHUNK_RUNS, duration: float = CHUNK_DURATION,
                     rounds: int = 3) -> dict[str, tuple[float, float, object, object]]:
    """The chunk of each system of :data:`RAY_SYSTEMS` with ``acoustics.detection = snr`` beside ``fixed`` (both
    with eigenrays, :data:`SNR_COMMON`), alternated (:func:`alternated_timing`).

    Returns
    -------
    dict
        System -> (fixed, snr) s per replicate-step and the two runs' results.
    """
    print(f"\n2c. detection by signal-to-noise (acoustics.detection = snr) beside the fixed one, the same chunk "
          f"({runs} runs x {duration:g} s, propagation ray, profile {RAY_PROFILE}, water depth {SNR_WATER_DEPTH:g} "
          f"m), best of {rounds} alternated:")
    return alternated_timing("acoustics.detection", ("fixed", "snr"), SNR_COMMON, runs, duration, rounds,
                             SNR_TARGET, SNR_OWN)


def chunk_timing() -> float:
    """The benchmark chunk timed after a first run in this process (best of three), and its profile; s per
    replicate-step."""
    wall, result = time_chunk()
    n = CHUNK_RUNS * result.steps
    per_step = wall / n
    print(f"\n2. a campaign chunk ({CHUNK_RUNS} semicircle runs x {result.steps} steps, local engine, one batch): "
          f"{wall:.2f} s, {per_step * 1e6:.2f} us per replicate-step")
    parts = {f"{name} (compiled step)": seconds for name, seconds in result.step_time.items()}
    parts["master loop (compiled: exchange, recording)"] = result.wall_time - sum(result.step_time.values())
    parts["set-up, metrics and the bound (Python, numpy, compiled bound)"] = wall - result.wall_time
    print("   where the time goes:")
    for label, seconds in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f"     {label:62s} {100 * seconds / wall:5.1f} %  ({seconds / n * 1e6:.2f} us per replicate-step)")
    return per_step


def threads(per_step: float) -> None:
    """The chunk's master loop: one batch against two half-batches in two threads."""
    import threading

    from sblsim.orchestrator.cosim.connections import default_connections
    from sblsim.orchestrator.cosim.master import simulate
    from sblsim.orchestrator.cosim.run import METRIC_INPUTS, TIMESERIES_COLUMNS, merge_params

    cfgs = with_replicates(load_config("semicircle", [f"simulation.duration={CHUNK_DURATION}"], seed=1),
                           range(CHUNK_RUNS))
    record = [TIMESERIES_COLUMNS[c] for c in METRIC_INPUTS]
    steps = int(round(CHUNK_DURATION / 0.1))

    def ready(group):
        handles = make_handles("local")
        for name, handle in handles.items():
            params, reps = merge_params(group, name, handle.parameters)
            handle.setup(params, reps)
        return handles

    def loop(handles):
        simulate(handles, default_connections(), {"receiver": 1}, 0.1, steps, record=record)

    best = {}
    for _ in range(2):
        whole = ready(cfgs)
        start = time.perf_counter()
        loop(whole)
        one = time.perf_counter() - start
        halves = [ready(cfgs[:CHUNK_RUNS // 2]), ready(cfgs[CHUNK_RUNS // 2:])]
        workers = [threading.Thread(target=loop, args=(h,)) for h in halves]
        start = time.perf_counter()
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        two = time.perf_counter() - start
        best = {"one": min(one, best.get("one", one)), "two": min(two, best.get("two", two))}
    chunk = per_step * CHUNK_RUNS * steps
    threaded = chunk - best["one"] + best["two"]
    print(f"   master loop, {CHUNK_RUNS} runs: one thread {best['one']:.2f} s, two threads {best['two']:.2f} s "
          f"({best['one'] / best['two']:.2f}x); a whole chunk with it: {chunk:.2f} s -> {threaded:.2f} s "
          f"({chunk / threaded:.2f}x in one process)")


#: The issue's target for a replicate-step against the plain-C EKF step (:func:`yardsticks`).
FLOOR_TARGET = 2.5


def yardsticks(per_step: float) -> float | None:
    """A replicate-step of ``per_step`` seconds against one EKF predict + update of the paper's problem
    (:mod:`ekf_floor`): FilterPy's (numpy's small-matrix overhead: it moves from machine to machine) and the plain-C
    step compiled and checked against FilterPy's here (the compiled floor). Returns the C step's seconds (None
    without FilterPy or a compiler)."""
    try:
        ekf = filterpy_step()
    except ImportError:
        print("   (FilterPy not installed: pip install filterpy, or the test extra)")
        return None
    print(f"   one FilterPy ExtendedKalmanFilter predict + update (6 states, 4 ranges + depth): "
          f"{ekf * 1e6:.1f} us; a whole replicate-step here (platform, channel, diver, EKF, fix, metrics, "
          f"bound) takes {ekf / per_step:.1f}x less")
    try:
        floor, worst, compiler = floor_step()
    except (CompileError, OSError, subprocess.CalledProcessError) as exc:
        print(f"   (the plain-C EKF step was not built: {exc})")
        return None
    print(f"   the same step in plain C (ekf_floor.c by {compiler}, -O2 without vectorization, equal to FilterPy's "
          f"to {worst:.1e}): {floor * 1e6:.3f} us; a whole replicate-step here takes {per_step / floor:.2f}x its "
          f"time (target {FLOOR_TARGET}x)")
    return floor


def paper(study, workers: int, floor: float | None = None, alone: bool = False) -> None:
    """The whole study with 1 and ``workers`` processes (``alone``: with ``workers`` only): wall time, runs/s, µs
    per replicate-step per core (and against ``floor``, the plain-C EKF step's seconds, when given)."""
    replicate_steps = sum(chunk.runs * chunk.steps for chunk in plan(study, 800))
    walls = {}
    for count in [workers] if alone else sorted({1, workers}):
        with tempfile.TemporaryDirectory() as tmp:
            result = run_campaign(study, Path(tmp) / "paper", workers=count, progress=False)
        walls[count] = result.wall_time
        per_core = result.wall_time * count / replicate_steps
        against = f", {per_core / floor:.2f}x the plain-C EKF step" if floor else ""
        print(f"   {count} worker(s): {result.wall_time:.1f} s, {result.runs_per_second:.0f} runs/s, "
              f"{per_core * 1e6:.2f} us per replicate-step per core{against}")
    if len(walls) == 2:
        print(f"   speed-up of {workers} workers over 1: {walls[1] / walls[workers]:.2f}x")


def scaling(workers: int, scale: int) -> None:
    raw, _ = study_source("million")
    walls = []
    for factor in (1, 2, 4):
        table = {**raw, "study": {**raw["study"], "replicates": scale * factor}}
        study = load_study(table)
        with tempfile.TemporaryDirectory() as tmp:
            result = run_campaign(study, Path(tmp) / "m", workers=workers, progress=False)
        walls.append(result.wall_time)
        print(f"   {factor}x: {study.runs} runs in {result.wall_time:.1f} s ({result.runs_per_second:.0f} runs/s), "
              f"{result.wall_time / walls[0]:.2f}x the 1x time")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes for the studies")
    parser.add_argument("--replicates", type=int, default=5, help="replicates per cell of the engine sample")
    parser.add_argument("--numpy", default=None, metavar="REV", help="also time the numpy engine of revision REV")
    parser.add_argument("--against", default=None, metavar="REV",
                        help="also time the chunk on the compiled engine of an earlier revision REV")
    parser.add_argument("--scale", type=int, default=128, help="replicates per cell of the 1x million-study cut")
    parser.add_argument("--skip-paper", action="store_true", help="skip the whole-study runs")
    parser.add_argument("--skip-scaling", action="store_true", help="skip the study-size runs")
    parser.add_argument("--ray", action="store_true",
                        help="also time the chunk with eigenrays (acoustics.propagation = ray) beside the straight "
                             "line for SBL, LBL and USBL")
    parser.add_argument("--only-ray", action="store_true", help="time only that (implies --ray)")
    parser.add_argument("--ray-runs", type=int, default=CHUNK_RUNS, help="runs of the chunk of --ray")
    parser.add_argument("--snr", action="store_true",
                        help="also time the chunk with detection by signal-to-noise (acoustics.detection = snr) "
                             "beside the fixed one, both with eigenrays, for SBL, LBL and USBL")
    parser.add_argument("--only-snr", action="store_true", help="time only that (implies --snr)")
    parser.add_argument("--snr-runs", type=int, default=CHUNK_RUNS, help="runs of the chunk of --snr")
    parser.add_argument("--only-floor", action="store_true",
                        help="time only the chunk and the whole study (on --workers processes; not with "
                             "--skip-paper) against FilterPy's EKF step and the plain-C one")
    args = parser.parse_args()
    study = load_study("paper")
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}, numpy {np.__version__}\n")
    if args.only_floor:
        floor = yardsticks(chunk_timing())
        if not args.skip_paper:
            print(f"\n4. whole paper study: {study.runs} runs on the local engine")
            paper(study, args.workers, floor, alone=True)
        return
    if args.only_ray or args.only_snr:
        if args.only_ray:
            propagation_timing(args.ray_runs)
        if args.only_snr:
            detection_timing(args.snr_runs)
        return
    engines(study, args.replicates)
    per_step = chunk_timing()
    system_timing(per_step)
    if args.ray:
        propagation_timing(args.ray_runs)
    if args.snr:
        detection_timing(args.snr_runs)
    floor = yardsticks(per_step)
    if args.numpy:
        old = float(run_at(args.numpy, OLD_CHUNK, str(CHUNK_DURATION), str(CHUNK_RUNS)).split()[-1])
        print(f"\n3. the same chunk on the batched numpy engine of revision {args.numpy}: {old * 1e6:.2f} us per "
              f"replicate-step; the compiled batch is {old / per_step:.1f}x faster")
    if args.against:
        then = float(run_at(args.against, OLD_CHUNK, str(CHUNK_DURATION), str(CHUNK_RUNS)).split()[-1])
        print(f"   the same chunk on the compiled engine of revision {args.against}: {then * 1e6:.2f} us per "
              f"replicate-step; this revision takes {per_step / then:.2f}x its time")
    if not args.skip_paper:
        print(f"\n4. whole paper study: {study.runs} runs on the local engine")
        paper(study, args.workers, floor)
    if not args.skip_scaling:
        print(f"\n5. time against study size: the million study cut to {args.scale}, {2 * args.scale} and "
              f"{4 * args.scale} replicates per cell, {args.workers} workers")
        scaling(args.workers, args.scale)
    print("\n6. threads inside a process")
    threads(per_step)


if __name__ == "__main__":
    main()
