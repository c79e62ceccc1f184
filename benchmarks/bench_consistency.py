"""Consistency of the receivers under every error source sblsim simulates: NEES, RMS error and RMS / PCRB.

Run:  python benchmarks/bench_consistency.py [--seeds 20] [--systems sbl,lbl-owtt,lbl-twtt,usbl]
                                            [--receivers ekf-seq,ukf,ekf] [--conditions default,...]

Each cell is a system on the ``random-walk`` scenario (a diver drawn from the receivers' own motion model,
so that the PCRB is a true bound) under one condition, ``--seeds`` replicates (seeds) stepped together,
through each receiver; the two site scenarios (``lbl-field``, ``usbl-deep``) run as they are, and USBL also
straight below its transceiver and 200 m off in 1,000 m of water. It prints, per cell, the mean 3-D
position NEES over the seeds (consistent: 3; the band [1.5, 4.5]), the RMS of ``e_tot`` over the seeds
[m], the RMS of the PCRB [m] and their ratio, and marks a cell of ``ekf-seq`` or ``ukf`` outside the band
or above 1.3 times the bound. The table is docs/receivers.md's "Consistency under every error source".
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

import sblsim

#: The systems on ``random-walk``: name -> overrides.
SYSTEMS = {
    "sbl": [],
    "lbl-owtt": ["platform.system=lbl", "acoustics.ranging=owtt"],
    "lbl-twtt": ["platform.system=lbl", "acoustics.ranging=twtt"],
    "usbl": ["platform.system=usbl"],
}
#: The error sources: name -> overrides over the system's.
CONDITIONS = {
    "default": [],
    "gps-1m-white": ["platform.gps_sigma=1"],
    "gps-1m-markov-60s": ["platform.gps_sigma=1", "platform.gps_model=gauss-markov", "platform.gps_tau=60"],
    "imu-5deg": ["platform.imu_sigma_deg=5"],
    "imu-bias-1deg": ["platform.imu_bias_deg=1"],
    "clock-drift-5ppm": ["acoustics.clock_drift_ppm=5"],
    "multipath-10pct": ["acoustics.outlier_pct=10"],
}
#: USBL in deep water, isovelocity, 0.5 s cycle: a random walk starting 1 m and 200 m off the vertical.
DEEP = ["platform.system=usbl", "target.depth=1000", "simulation.sampling_time=0.5", "simulation.duration=120"]
EXTRA = {
    "usbl-nadir-1000m": ("random-walk", DEEP + ["target.radius=1"]),
    "usbl-200m-off-1000m": ("random-walk", DEEP + ["target.radius=200"]),
    "lbl-field": ("lbl-field", []),
    "usbl-deep": ("usbl-deep", []),
}
BAND = (1.5, 4.5)
RATIO = 1.3


def cell(scenario: str, overrides: list[str], receiver: str, seeds: int) -> dict[str, float]:
    """One cell: the mean NEES over the seeds, the RMS error and the RMS PCRB [m]."""
    result = sblsim.run(scenario, replicates=seeds, seed=1, set=overrides + [f"simulation.receiver={receiver}"])
    runs = result.metrics
    rms = math.sqrt(float(np.mean(runs["e_tot_rms"] ** 2)))
    bound = math.sqrt(float(np.mean(runs["pcrb_rms"] ** 2)))
    return {"nees": float(np.mean(runs["nees_mean"])), "rms": rms, "pcrb": bound, "ratio": rms / bound,
            "diverged": int(np.sum(runs["diverged"]))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="replicates per cell (default 20)")
    parser.add_argument("--systems", default=",".join(SYSTEMS), help="systems on random-walk (comma-separated)")
    parser.add_argument("--conditions", default=",".join(list(CONDITIONS) + list(EXTRA)),
                        help="conditions (comma-separated)")
    parser.add_argument("--receivers", default="ekf-seq,ukf,ekf", help="receivers (comma-separated)")
    args = parser.parse_args()
    receivers = args.receivers.split(",")
    cells = []
    for condition in args.conditions.split(","):
        if condition in EXTRA:
            scenario, overrides = EXTRA[condition]
            cells.append((condition, "", scenario, overrides))
            continue
        for system in args.systems.split(","):
            cells.append((condition, system, "random-walk", SYSTEMS[system] + CONDITIONS[condition]))
    print("| condition | system | receiver | NEES | RMS [m] | PCRB [m] | RMS / PCRB | diverged |")
    print("|---|---|---|---|---|---|---|---|")
    outside = []
    start = time.perf_counter()
    for condition, system, scenario, overrides in cells:
        for receiver in receivers:
            c = cell(scenario, overrides, receiver, args.seeds)
            judged = receiver in ("ekf-seq", "ukf")
            bad = judged and not (BAND[0] <= c["nees"] <= BAND[1] and c["ratio"] <= RATIO)
            mark = " **out**" if bad else ""
            print(f"| {condition} | {system or scenario} | {receiver} | {c['nees']:.2f}{mark} | {c['rms']:.3f} | "
                  f"{c['pcrb']:.3f} | {c['ratio']:.2f} | {c['diverged']} |", flush=True)
            if bad:
                outside.append((condition, system or scenario, receiver))
    print(f"\n{len(cells) * len(receivers)} cells of {args.seeds} seeds in {time.perf_counter() - start:.0f} s; "
          f"ekf-seq and ukf cells outside NEES {BAND} or above RMS/PCRB {RATIO}: "
          f"{', '.join('/'.join(o) for o in outside) or 'none'}")
    sys.exit(1 if outside else 0)


if __name__ == "__main__":
    main()
