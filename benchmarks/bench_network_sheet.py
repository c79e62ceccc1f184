"""A network's whole receiver sheet with a small study's detections costs no more than the study's own deployments
(issue 96: "a sheet of 2,000 deployments costs no more than the deployments used").

Run:  python benchmarks/bench_network_sheet.py [--others 2000] [--receivers 12] [--tags 6] [--days 0.5]
      [--rounds 3] [--workers 2] [--seed 1]

A small study is simulated (:func:`sblsim.orchestrator.telemetry.simulate.simulate_study`: ``--receivers``, one
redeployed, each with a sync tag; ``--tags`` animals; ``--days``) and written as its people bring it. Its
deployments sheet is written twice: as it is (the baseline) and as a network's sheet holding it among ``--others``
other deployments (other serials, years before the study, about 7,000 km away in another UTM zone, half with a
sync tag of their own) and the study's first three serials deployed there a year before. :func:`sblsim.track`
runs on the same detections and tag sheet with each sheet, whole (reading, synchronising, every tag, the
outputs), once untimed (the caches), then ``--rounds`` times in alternation, each into a fresh folder. Printed:
each run's seconds, the medians, the network sheet's median over the baseline's (the target: within 1.10; the
CPU seconds' too, less disturbed by other work on the machine), and whether the two give the same tracks and
frame (they must). A JSON line last.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

import sblsim
from sblsim.orchestrator.io.times import iso_utc, utc_seconds
from sblsim.orchestrator.telemetry.simulate import simulate_study

#: The issue's target: the network sheet's run time over the study's own deployments'.
TARGET_RATIO = 1.10
#: Where the network's other deployments lie (latitude, longitude [°]), far from the simulated study's.
ELSEWHERE = (44.5, -82.5)


def network_sheet(deployments: pd.DataFrame, others: int, seed: int) -> pd.DataFrame:
    """The study's deployments among ``others`` of a network (the module docstring), in the sheet's own columns."""
    rng = np.random.default_rng(seed)
    start = utc_seconds(["2015-01-01T00:00:00Z"], "", [1], "")[0] + rng.uniform(0, 7 * 365 * 86400, others)
    far = pd.DataFrame({
        "station": [f"NET-{k:05d}" for k in range(others)],
        "ins_serial_no": [str(700000 + k) for k in range(others)],
        "deploy_lat": ELSEWHERE[0] + rng.uniform(-3, 3, others),
        "deploy_long": ELSEWHERE[1] + rng.uniform(-6, 6, others),
        "deploy_date_time": iso_utc(start), "recover_date_time": iso_utc(start + rng.uniform(30, 300, others) * 86400),
        "transmitter": [f"A69-1601-{30000 + k}" if k % 2 else "" for k in range(others)]})
    serials = deployments["ins_serial_no"].drop_duplicates().head(3).to_numpy()
    first = utc_seconds([deployments["deploy_date_time"].min()], "", [1], "")[0]
    before = pd.DataFrame({"station": [f"OLD-{k}" for k in range(len(serials))], "ins_serial_no": serials,
                           "deploy_lat": ELSEWHERE[0], "deploy_long": ELSEWHERE[1] + 0.01 * np.arange(len(serials)),
                           "deploy_date_time": iso_utc([first - 400 * 86400] * len(serials)),
                           "recover_date_time": iso_utc([first - 200 * 86400] * len(serials)), "transmitter": ""})
    return pd.concat([deployments, before, far], ignore_index=True)


def timed(files: dict[str, Path], sheet: Path, out: Path, workers: int):
    """One study run whole: its wall and CPU seconds (this process's and its worker processes') and its result."""
    started, cpu = time.perf_counter(), os.times()
    result = sblsim.track(files["detections"], receivers=sheet, tags=files["tags"], out=out, workers=workers)
    wall, after = time.perf_counter() - started, os.times()
    cpu_s = sum(getattr(after, k) - getattr(cpu, k) for k in ("user", "system", "children_user", "children_system"))
    return wall, cpu_s, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--others", type=int, default=2000)
    parser.add_argument("--receivers", type=int, default=12)
    parser.add_argument("--tags", type=int, default=6)
    parser.add_argument("--days", type=float, default=0.5)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    if args.others < 1 or args.receivers < 4 or args.tags < 1 or args.days <= 0 or args.rounds < 1 \
            or args.workers < 1:
        print("bench_network_sheet: error: --receivers: at least 4; --others, --tags, --rounds, --workers: at least "
              "1; --days: positive", file=sys.stderr)
        sys.exit(2)
    sim = simulate_study(n_receivers=args.receivers, n_tags=args.tags, days=args.days, redeployed=1, seed=args.seed)
    times: dict[str, list[float]] = {"own": [], "network": []}
    cpu: dict[str, list[float]] = {"own": [], "network": []}
    results = {}
    with tempfile.TemporaryDirectory(prefix="sblsim-bench-network-") as tmp:
        folder = Path(tmp)
        files = sim.write(folder / "files", "vue")
        sheets = {"own": files["deployments"], "network": folder / "network.csv"}
        network = network_sheet(sim.deployments, args.others, args.seed)
        network.to_csv(sheets["network"], index=False, float_format="%.10f")
        timed(files, sheets["own"], folder / "warm-up", args.workers)  # the caches and imports, not counted
        for k in range(args.rounds):
            for name in ("own", "network") if k % 2 == 0 else ("network", "own"):
                seconds, cpu_s, results[name] = timed(files, sheets[name], folder / f"{name}{k}", args.workers)
                times[name].append(seconds)
                cpu[name].append(cpu_s)
    own, more = results["own"], results["network"]
    same_tracks = own.tracks.equals(more.tracks)
    same_frame = own.summary["frame"] == more.summary["frame"]
    r = more.summary["receivers"]
    median = {name: statistics.median(values) for name, values in times.items()}
    median_cpu = {name: statistics.median(values) for name, values in cpu.items()}
    ratio, ratio_cpu = median["network"] / median["own"], median_cpu["network"] / median_cpu["own"]
    print(f"a simulated study: {args.receivers} receivers (one redeployed, {len(sim.deployments)} deployments), "
          f"{args.tags} tags, {args.days:g} days, {len(sim.detections)} detections; {args.workers} worker processes")
    print(f"the network's sheet: {len(network)} deployments; used {r['used']}, not used {r['not_used']['count']} "
          f"({', '.join(f'{k} {v}' for k, v in r['not_used'].items() if k != 'count')})")
    print(f"{'sheet':>8} {'deployments':>12} " + " ".join(f"{'run ' + str(k + 1):>7}" for k in range(args.rounds))
          + f" {'median s':>9} {'ratio':>6} {'CPU s':>7} {'ratio':>6}")
    for name, count in (("own", len(sim.deployments)), ("network", len(network))):
        print(f"{name:>8} {count:>12} " + " ".join(f"{t:>7.1f}" for t in times[name])
              + f" {median[name]:>9.1f} {median[name] / median['own']:>6.2f} {median_cpu[name]:>7.1f} "
              f"{median_cpu[name] / median_cpu['own']:>6.2f}")
    print(f"same tracks: {same_tracks}; same frame: {same_frame} ({more.summary['frame']['crs']})")
    print(f"target: the network sheet within {TARGET_RATIO:.2f} of its own deployments' time: "
          f"{'met' if ratio <= TARGET_RATIO and same_tracks and same_frame else 'not met'} (wall {ratio:.3f}, "
          f"CPU {ratio_cpu:.3f})")
    print(json.dumps({"benchmark": "network_sheet", "others": args.others, "receivers": args.receivers,
                      "tags": args.tags, "days": args.days, "workers": args.workers, "seed": args.seed,
                      "seconds": times, "cpu_s": cpu, "median_s": median, "ratio": ratio,
                      "median_cpu_s": median_cpu, "ratio_cpu": ratio_cpu, "same_tracks": same_tracks,
                      "same_frame": same_frame, "used": r["used"], "not_used": r["not_used"]}))


if __name__ == "__main__":
    main()
