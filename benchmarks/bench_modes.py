"""Time the robust smoother's search of its other local modes where late arrivals are modelled (issue 67;
``sblsim.models.tracking.modes``): one late arrival a hypothesis against one or two, beside the smoother's own time.

Run:  python benchmarks/bench_modes.py [--pings N] [--share P] [--excess M] [--seed S]

The record: ``bench_tracking_scale.py``'s tag and array (a stable 2.5 s interval, 8 receivers on a 200 m circle, each
hearing a ping with probability 0.8, 0.15 ms of timing noise), its multipath replaced by the design walk's: a share P
of the arrivals (default 0.10) late by an exponential excess path of mean M [m] (default 5) over the sound speed.
The tracker is told P and M (its one-sided delay term, ``delay_share``, ``delay_mean``) and the motion noise the
record was drawn with. What is timed on one core, as CPU time of the process (each once, after a first untimed
smoother that loads the modules): the **robust smoother** (the fixes' anchored and graduated starts, the Student-t's
own minimum, the lowest cost on to convergence, its covariance), then the search of its other modes
(:func:`~sblsim.models.tracking.modes.local_modes`: its better starts and the spread of the others; the restart from
a better start not included) with ``MODE_LATE`` 1 and 2: the hypotheses each solves, its CPU time and its ratio to the
smoother's, and the mean 2-D NEES of the track against the simulated truth with the smoother's covariance alone and
with each search's spread added. A JSON line last.
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before numpy loads
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
from bench_tracking_scale import SOUND_SPEED, simulate  # noqa: E402

#: The record's multipath by default: the design walk's harder level (docs/design.md).
SHARE = 0.10
EXCESS_M = 5.0


def smoother(toa: np.ndarray, receivers: np.ndarray, settings) -> tuple:
    """The robust smoother of the record with the delay term (module docstring; :func:`robust_track` without the
    search of its other modes): its track (:class:`RobustTrack`), its schedule and its settings."""
    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.models.tracking.timing import SIGMA_TOA
    from sblsim.orchestrator.tracks.tracker import ping_schedule, tracker_settings

    fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, settings.sound_speed, SIGMA_TOA)
    told = replace(tracker_settings(settings.sound_speed, fe), acceleration_psd=settings.acceleration_psd,
                   delay_share=settings.delay_share, delay_mean=settings.delay_mean)
    schedule, _ = ping_schedule(toa, receivers, told)
    told = replace(told, interval=schedule.interval)
    return tt.robust_track(toa, receivers, told, (fx, fe, fused), None, schedule, modes=False), schedule, told


def nees(x: np.ndarray, P: np.ndarray, truth: np.ndarray) -> float:
    """The mean 2-D NEES of positions x (m, 2) [m] with covariances P (m, 2, 2) [m²] against the truth (m, 2) [m]."""
    e = x - truth
    return float(np.mean(np.einsum("ki,kij,kj->k", e, np.linalg.inv(P), e)))


def measure(n_pings: int, share: float = SHARE, excess_m: float = EXCESS_M, seed: int = 0) -> dict:
    """The timings and NEES of the module docstring: the JSON's fields, with ``track`` (the smoother's
    :class:`RobustTrack`), ``truth`` (m, 2) [m], ``toa`` and ``spread`` (per ``MODE_LATE``, (m, 2, 2) [m²])."""
    from sblsim.models.tracking import modes

    toa, receivers, truth, _, settings = simulate(n_pings, seed, (share, excess_m))
    settings = replace(settings, delay_share=share, delay_mean=excess_m / SOUND_SPEED)
    smoother(toa[:100], receivers, settings)  # loads the modules, untimed
    cpu = time.process_time()
    track, schedule, told = smoother(toa, receivers, settings)
    smoother_s = time.process_time() - cpu
    x, P = track.x[:, :2], track.P[:, :2, :2]
    out = {"pings": n_pings, "arrivals": int(np.isfinite(toa).sum()), "share": share, "excess_m": excess_m,
           "smoother_cpu_s": smoother_s, "nees_smoother": nees(x, P, truth), "searches": [],
           "track": track, "truth": truth, "toa": toa, "spread": {}}
    kept = modes.MODE_LATE
    try:
        for late in (1, 2):
            modes.MODE_LATE = late
            cpu = time.process_time()
            found = modes.local_modes(track, toa, receivers, told, schedule)
            search_s = time.process_time() - cpu
            out["spread"][late] = found.spread
            out["searches"].append({"late": late, "hypotheses": found.hypotheses, "cpu_s": search_s,
                                    "ratio": search_s / smoother_s, "better": found.better is not None,
                                    "nees": nees(x, P + found.spread, truth)})
    finally:
        modes.MODE_LATE = kept
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pings", type=int, default=1000, help="the record's pings (default 1,000)")
    parser.add_argument("--share", type=float, default=SHARE, help="the share of late arrivals, in (0, 1)")
    parser.add_argument("--excess", type=float, default=EXCESS_M, help="their mean excess path [m], > 0")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.pings < 100:
        parser.error("--pings: must be at least 100")
    if not 0.0 < args.share < 1.0:
        parser.error(f"--share: {args.share} is outside the allowed range (0, 1)")
    if not args.excess > 0.0:
        parser.error(f"--excess: {args.excess} must be above 0 m")
    r = measure(args.pings, args.share, args.excess, args.seed)
    print(f"{r['pings']:,} pings ({r['arrivals']:,} arrivals), {100 * r['share']:g} % of them late by "
          f"{r['excess_m']:g} m on average: the robust smoother {r['smoother_cpu_s']:.2f} s of CPU, NEES "
          f"{r['nees_smoother']:.2f}")
    for s in r["searches"]:
        print(f"  its modes, up to {s['late']} late arrival{'s' if s['late'] > 1 else ''} a hypothesis: "
              f"{s['hypotheses']:,} hypotheses, {s['cpu_s']:.2f} s of CPU ({s['ratio']:.1f}× the smoother), "
              f"NEES {s['nees']:.2f}{' (a better start found)' if s['better'] else ''}")
    for key in ("track", "truth", "toa", "spread"):
        r.pop(key)
    print(json.dumps(r))


if __name__ == "__main__":
    main()
