"""Time ``sblsim sync`` on a synthetic month of a large array (issue 68, "Speed"): 70 receivers, each with its own
sync tag, 30 days (about 1.3 × 10⁶ sync detections), on one core.

Run:  python benchmarks/bench_sync_scale.py [--receivers 70] [--days 30] [--seed 1] [--baseline-days D]
      [--no-leave-one-out] [--write] [--refine-positions] [--window-days D]

The array (:func:`simulate`): receivers on a grid of 200 m (10 columns; each moved by N(0, 20 m) per axis), each
receiver's clock with an offset uniform in ±2 s and a drift uniform in ±20 ppm (the first receiver's the true time),
its sync tag at its position bursting at intervals uniform in 540–660 s; an emission is heard by a receiver at
distance ``d`` with probability ``0.95 / (1 + exp((d − 250 m) / 25 m))`` (its own receiver and the four nearest
neighbours, rarely the diagonal ones), along the straight line at 1,480 m/s with 0.15 ms of timing noise, and 1 %
of the arrivals followed by a multipath echo 0.5–5 ms later. The files' clocks are the receivers'.

What is timed, at ``--baseline-days`` (default a tenth of ``--days``) and at ``--days``, each once after an untimed
run of one day that loads the modules: :func:`sblsim.orchestrator.sync.run.synchronise` from the detections in
memory (what ``sblsim sync`` runs after reading the files), the sound speed given, 1 h bins, by stage: grouping
(the sync-tag arrivals picked, emissions grouped, echoes found, the receivers tied), the fit (the robust
reweighting, the kept arrivals' least squares, the last solve with the offsets' sigmas: the selected inverse of
the block-tridiagonal normal equations, :func:`sblsim.models.sync.selected_inversion.selected_inverse`), the
leave-one-out (each sync tag positioned with the clocks refitted without it: one refit per tag) and the tables; with
``--write``, the files and figures (:func:`sblsim.orchestrator.sync.outputs.write`) too. Each stage's wall time,
the process's CPU time (the time on a core whatever else the machine runs), the peak resident memory (the
process's high-water mark, reset before each size where Linux allows), the time per detection against the
baseline's (1.00: linear), and the offsets against the simulated clocks (the share within 3 of their sigmas). With
``--refine-positions`` the receivers table is the truth plus a survey error of :data:`SURVEY_SIGMA_M` per axis and
the sync refines the positions with that prior (``refine_positions=True``): the refined positions' RMS error
against the table's is printed too. ``--window-days`` (default the library's,
:data:`~sblsim.models.sync.windows.WINDOW_DAYS`; 0: one fit) fits a span longer than a window and its overlaps window
by window (:mod:`sblsim.models.sync.windows`); the resident memory before the sync (the detections in memory, which
grow with the span) is printed beside the peak, their difference the sync's own. A JSON line last.
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before numpy loads
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from bench_memory import peak_bytes, reset_peak, resident_bytes  # noqa: E402

#: The issue's targets for a month of 70 receivers on one core: seconds and bytes.
TARGET_S = 300.0
TARGET_BYTES = 4 * 1024**3
#: The array and its sync tags (module docstring).
SPACING_M = 200.0
COLUMNS = 10
RANGE_M = 250.0
RANGE_WIDTH_M = 25.0
SOUND_SPEED = 1480.0
INTERVAL_S = (540.0, 660.0)
NOISE_S = 0.15e-3
ECHO_SHARE = 0.01
#: The survey error per axis of ``--refine-positions``' table [m] (its prior's sigma too).
SURVEY_SIGMA_M = 2.0
#: The files' epoch [s since 1970 UTC] of the simulation's t = 0.
EPOCH = 1_700_000_000


class Simulated:
    """A simulated array's sync detections (:func:`simulate`): ``positions`` (R, 2) [m], ``offset0``, ``drift``
    (R,) [s], [s/s], and per detection ``receiver``, ``tag`` (int) and ``time`` [s] on the receiver's clock from
    :data:`EPOCH`."""

    def __init__(self, positions, offset0, drift, receiver, tag, time):
        self.positions, self.offset0, self.drift = positions, offset0, drift
        self.receiver, self.tag, self.time = receiver, tag, time

    def offset(self, receiver: np.ndarray, time: np.ndarray) -> np.ndarray:
        """(n,) [s] the true offset of ``receiver`` at its clock's ``time`` against receiver 0's clock (the true
        time)."""
        tau = (time - self.offset0[receiver]) / (1 + self.drift[receiver])
        return time - tau


def simulate(n_receivers: int, days: float, seed: int = 1) -> Simulated:
    """The synthetic array (module docstring), seeded."""
    rng = np.random.default_rng(seed)
    k = np.arange(n_receivers)
    positions = np.c_[(k % COLUMNS) * SPACING_M, (k // COLUMNS) * SPACING_M] + rng.normal(0, 20.0, (n_receivers, 2))
    offset0 = rng.uniform(-2.0, 2.0, n_receivers)
    drift = rng.uniform(-20e-6, 20e-6, n_receivers)
    offset0[0] = drift[0] = 0.0
    span = days * 86400.0
    distance = np.linalg.norm(positions[:, None] - positions[None], axis=2)
    p = 0.95 / (1 + np.exp((distance - RANGE_M) / RANGE_WIDTH_M))
    rec, tag, tau = [], [], []
    for i in range(n_receivers):
        count = int(span / INTERVAL_S[0]) + 2
        times = rng.uniform(0, INTERVAL_S[1]) + np.r_[0.0, np.cumsum(rng.uniform(*INTERVAL_S, count - 1))]
        times = times[times < span]
        near = np.flatnonzero(p[i] > 1e-4)
        e, j = np.nonzero(rng.random((len(times), len(near))) < p[i, near])
        rec.append(near[j])
        tag.append(np.full(len(j), i))
        tau.append(times[e] + distance[i, near[j]] / SOUND_SPEED)
    rec, tag, tau = map(np.concatenate, (rec, tag, tau))
    tau = tau + rng.normal(0, NOISE_S, len(tau))
    echo = rng.random(len(tau)) < ECHO_SHARE
    rec, tag = np.r_[rec, rec[echo]], np.r_[tag, tag[echo]]
    tau = np.r_[tau, tau[echo] + rng.uniform(0.5e-3, 5e-3, echo.sum())]
    clock = tau + offset0[rec] + drift[rec] * tau
    order = np.lexsort((clock, rec))
    return Simulated(positions, offset0, drift, rec[order], tag[order], clock[order])


def inputs(sim: Simulated, table: np.ndarray | None = None):
    """The detections and the receivers' table as the readers return them (``table`` (R, 2) [m] the table's
    positions, default the truth)."""
    import pandas as pd

    from sblsim.orchestrator.readers.detections import Detections

    names = np.array([f"R{j}" for j in range(len(sim.positions))], dtype=object)
    tags = np.array([f"S{j}" for j in range(len(sim.positions))], dtype=object)
    frame = pd.DataFrame({"receiver": names[sim.receiver], "tag": tags[sim.tag], "time": sim.time + EPOCH,
                          "sensor_value": np.nan, "sensor_unit": "", "line": np.arange(2, len(sim.time) + 2)})
    table = sim.positions if table is None else table
    hydrophones = pd.DataFrame({"receiver": names, "sync_tag": tags, "x": table[:, 0], "y": table[:, 1], "z": np.nan})
    return Detections(frame, "simulated", "yaps"), hydrophones


def measure(n_receivers: int, days: float, seed: int = 1, leave_one_out: bool = True, write: bool = False,
            refine: bool = False, window_days: float | None = None) -> dict:
    """One size's sync (module docstring): its stages' times [s], CPU time, peak memory and the offsets' check."""
    from sblsim.orchestrator.sync.run import synchronise

    sim = simulate(n_receivers, days, seed)
    table = None
    if refine:
        table = sim.positions + np.random.default_rng(seed + 1000).normal(0, SURVEY_SIGMA_M, sim.positions.shape)
    detections, hydrophones = inputs(sim, table)
    before = resident_bytes()
    reset = reset_peak()
    timings: dict = {}
    start, cpu = time.perf_counter(), time.process_time()
    outcome = synchronise(detections, hydrophones, sound_speed=SOUND_SPEED, bin_hours=1.0, reference="R0",
                          leave_one_out=leave_one_out, timings=timings, refine_positions=refine,
                          survey_sigma=SURVEY_SIGMA_M,
                          **({} if window_days is None else {"window_days": window_days or None}))
    sync_s, sync_cpu = time.perf_counter() - start, time.process_time() - cpu
    write_s = 0.0
    if write:
        from sblsim.orchestrator.sync.outputs import write as write_files

        with tempfile.TemporaryDirectory() as folder:
            tick = time.perf_counter()
            write_files(outcome, Path(folder) / "out")
            write_s = time.perf_counter() - tick
    peak = peak_bytes()
    o = outcome.offsets
    j = o["receiver"].str.slice(1).astype(int).to_numpy()
    others = j != 0
    error = o["offset_start_s"].to_numpy() - sim.offset(j, o["start"].to_numpy() - EPOCH)
    sigma = o["offset_start_sigma_s"].to_numpy()
    within = float(np.mean(np.abs(error[others]) <= 3 * sigma[others]))
    fit = outcome.fit
    knots = int(np.isfinite(fit.knots[1:]).sum())
    return {"receivers": n_receivers, "days": days, "detections": int(len(sim.time)),
            "sync_arrivals_kept": int(fit.kept.sum()), "knots": knots, "bins": int(len(fit.edges) - 1),
            "grouping_s": timings["grouping"], "fit_s": timings["fit"], "reweighting_s": timings["reweighting"],
            "least_squares_s": timings["least_squares"], "covariance_s": timings["covariance"],
            "leave_one_out_s": timings["leave_one_out"],
            "tables_s": sync_s - timings["grouping"] - timings["fit"] - timings["leave_one_out"],
            "sync_s": sync_s, "sync_cpu_s": sync_cpu, "write_s": write_s, "peak_bytes": peak, "peak_reset": reset,
            "resident_before_bytes": before, "windows": (outcome.summary.get("windows") or {}).get("count", 1),
            "offsets_within_3_sigma": within, "offset_error_median_us": float(np.median(np.abs(error[others])) * 1e6),
            "offset_sigma_median_us": float(np.median(sigma[others]) * 1e6),
            "sync_tags_positioned": int(len(outcome.sync_tags)),
            "refined_rms_m": float(np.sqrt(np.mean((outcome.positions[["x_m", "y_m"]].to_numpy()
                                                    - sim.positions) ** 2))) if refine else None,
            "table_rms_m": float(np.sqrt(np.mean((table - sim.positions) ** 2))) if refine else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--receivers", type=int, default=70)
    parser.add_argument("--days", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--baseline-days", type=float, default=None, help="default a tenth of --days")
    parser.add_argument("--no-leave-one-out", action="store_true", help="skip the sync tags' leave-one-out fixes")
    parser.add_argument("--write", action="store_true", help="time the files and figures too")
    parser.add_argument("--refine-positions", action="store_true",
                        help=f"a table {SURVEY_SIGMA_M:g} m off per axis, the positions refined with the clocks")
    parser.add_argument("--window-days", type=float, default=None,
                        help="the sync's windows [days] (default the library's; 0: one fit)")
    args = parser.parse_args()
    if args.receivers < 3 or args.days <= 0:
        parser.error("--receivers: at least 3; --days: positive")
    baseline_days = args.baseline_days or args.days / 10
    measure(min(args.receivers, 10), 1.0, args.seed, leave_one_out=False)  # untimed: the modules loaded
    rows = [measure(args.receivers, d, args.seed, not args.no_leave_one_out, args.write, args.refine_positions,
                    args.window_days) for d in (baseline_days, args.days)]
    base = rows[0]
    print(f"sync of a synthetic array of {args.receivers} receivers, one sync tag each, 1 h bins, one core "
          f"(OMP/OPENBLAS/MKL threads {os.environ.get('OPENBLAS_NUM_THREADS')})")
    header = (f"{'days':>6} {'detections':>11} {'knots':>7} {'group':>6} {'reweight':>8} {'lsq':>6} {'sigmas':>6} "
              f"{'fit':>6} {'LOO':>7} {'tables':>6} {'sync':>7} {'CPU':>7} {'write':>6} {'peak GiB':>8} "
              f"{'per det.':>8} {'3 sigma':>7} {'windows':>7} {'before GiB':>10}")
    print(header)
    for r in rows:
        ratio = (r["sync_s"] / r["detections"]) / (base["sync_s"] / base["detections"])
        r["per_detection_ratio"] = ratio
        print(f"{r['days']:>6g} {r['detections']:>11} {r['knots']:>7} {r['grouping_s']:>6.1f} "
              f"{r['reweighting_s']:>8.1f} {r['least_squares_s']:>6.1f} {r['covariance_s']:>6.1f} {r['fit_s']:>6.1f} "
              f"{r['leave_one_out_s']:>7.1f} {r['tables_s']:>6.1f} {r['sync_s']:>7.1f} {r['sync_cpu_s']:>7.1f} "
              f"{r['write_s']:>6.1f} {r['peak_bytes'] / 1024**3:>8.2f} {ratio:>8.2f} "
              f"{r['offsets_within_3_sigma']:>7.3f} {r['windows']:>7} {r['resident_before_bytes'] / 1024**3:>10.2f}")
    last = rows[-1]
    if args.refine_positions:
        print("positions refined: RMS error per axis " + ", ".join(
            f"{r['days']:g} d {r['refined_rms_m']:.3f} m (the table's {r['table_rms_m']:.3f} m)" for r in rows))
    total = last["sync_s"] + last["write_s"]
    print(f"target: {TARGET_S:.0f} s and {TARGET_BYTES / 1024**3:.0f} GiB for a month of 70 receivers: "
          f"{total:.1f} s ({'met' if total <= TARGET_S else 'not met'}), "
          f"{last['peak_bytes'] / 1024**3:.2f} GiB ({'met' if last['peak_bytes'] <= TARGET_BYTES else 'not met'})"
          + ("" if last["peak_reset"] else " (peak since the process started)"))
    print(json.dumps({"benchmark": "sync_scale", "receivers": args.receivers, "seed": args.seed, "sizes": rows}))


if __name__ == "__main__":
    main()
