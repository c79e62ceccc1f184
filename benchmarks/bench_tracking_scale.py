"""Time the robust smoother's track of a long synthetic record (issue 67, "Scale") on one core: 10⁶ pings, a month
of a 2.5 s tag.

Run:  python benchmarks/bench_tracking_scale.py [--pings N] [--replay-pings N] [--seed S] [--no-baseline]

The record (:func:`simulate`): a tag on a stable 2.5 s interval (its clock's jitter and drift as the tracker's
model says, :func:`~sblsim.models.tracking.simulate.simulate_pings`, seeded) moving along a Lissajous path of
±150 m (periods 1 h and 1.41 h, up to 0.26 m/s) inside 8 receivers on a 200 m circle, each hearing each ping with
probability 0.8 with 0.15 ms of timing noise, 1 % of the arrivals late by 2 to 20 ms (multipath).

What is timed, at N/100, N/10 and N pings (each size once, after a first untimed run at the smallest that loads
the modules), the sound speed given (the simulation's): the **robust smoother's track** = the single-ping fixes
(:func:`fix_pings`), the tracker's settings and the ping schedule (the replay's own functions), and
:func:`robust_track` without the RTS smoother's start (the fixes' anchored start, its graduated start, each
screened, the better one on to convergence, the covariances by block cyclic reduction in place); the motion noise is
the simulation's (no EM). Each stage's time (wall clock, and the process's CPU time: on a shared machine the time on
a core whatever else runs) and the peak resident memory over the track (the process's high-water mark, reset
before it where Linux allows, else since the start); the per-ping time against the smallest size's
(1.00 for linear scaling); at the smallest size, the EKF with the RTS smoother on the same pings (a ping-by-ping
loop) per ping beside it, with its baseline (the TOA model called per ping as before: :func:`casadi_called`),
and the PCRB with the smoothing bound along the true track (what a replay scores against) with its baseline (a
step's terms made inside the recursion as before: :func:`pcrb_stepwise`); and the whole replay
(``sblsim.replay_toa`` from files: the EM of the motion noise, the EKF, the sequential EKF, the UKF, both smoothers,
the quality marks, scoring) at ``--replay-pings``. A JSON line last.

The baseline, measured in the same run on the same records (unless ``--no-baseline``): the same track with the
fixes' splice rounds as they were before (:func:`whole_rounds`: each round a re-solve of the whole record from the
track and from its splice) in place of today's (:func:`~sblsim.models.tracking.starts.with_fixes_spliced`: each
round the splices' own windows re-solved, the rest held); each size's CPU time against it, the rounds' own CPU time
in each (``splice_cpu_s``), and how far today's track lies from it (the largest move of a position, and of an
emission time times the sound speed, [m]).
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before numpy loads
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from bench_memory import peak_bytes, reset_peak  # noqa: E402

#: The issue's targets for the robust smoother's track of 10⁶ pings on one core: seconds and bytes.
TARGET_S = 60.0
TARGET_BYTES = 2 * 1024**3
#: The record's tag and array (module docstring).
SOUND_SPEED = 1480.0
INTERVAL_S = 2.5
RADIUS_M = 200.0
AMPLITUDE_M = 150.0
PERIOD_S = 3600.0
DETECTION = 0.8
MULTIPATH = 0.01


def simulate(n_pings: int, seed: int = 0, multipath: tuple[float, float] | None = None):
    """The synthetic record (module docstring): times of arrival (n_pings, 8) [s], receivers (8, 2) [m], the tag's
    positions (n_pings, 2) [m] and emission times (n_pings,) [s], and the tracker's settings it was drawn with.
    ``multipath`` (share [1], mean excess path [m]): the late arrivals drawn as the design's walk draws them
    (:func:`~sblsim.orchestrator.design.telemetry_confirm.multipath_delays`) in place of the 1 % of 2 to 20 ms."""
    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.models.tracking.timing import SIGMA_TOA

    angles = np.arange(8) * np.pi / 4
    receivers = RADIUS_M * np.c_[np.cos(angles), np.sin(angles)]

    def path(t):
        w = 2 * np.pi / PERIOD_S
        return AMPLITUDE_M * np.c_[np.sin(w * t), np.sin(w * t / np.sqrt(2) + 1.0)]

    settings = tt.TrackerSettings(sound_speed=SOUND_SPEED, sigma_toa=SIGMA_TOA, interval=INTERVAL_S)
    rng = np.random.default_rng(seed)
    toa, truth, emissions = tt.simulate_pings(receivers, n_pings, settings, rng, detection=DETECTION, path=path)
    if multipath is not None:
        from sblsim.orchestrator.design.telemetry_confirm import multipath_delays

        return (toa + multipath_delays(toa.shape, 100.0 * multipath[0], multipath[1], SOUND_SPEED, rng), receivers,
                truth, emissions, settings)
    late = np.isfinite(toa) & (rng.random(toa.shape) < MULTIPATH)
    toa[late] += rng.uniform(2e-3, 2e-2, int(late.sum()))
    return toa, receivers, truth, emissions, settings


def cpu_s() -> float:
    """The process's CPU time so far, user and system [s] (:func:`resource.getrusage`: the time on a core, whatever
    else the machine runs)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def whole_rounds(track, toa, receivers, settings, fixes, schedule, depth=None):
    """The baseline's splice rounds: :func:`~sblsim.models.tracking.starts.with_fixes_spliced` as it was before the
    windows (each round a re-solve of the whole record from the track and from its splice, kept where the cost is
    lower by more than ``MODE_BETTER``; the covariance made once, for the track kept)."""
    from sblsim.models.tracking.modes import MODE_BETTER
    from sblsim.models.tracking.smoother import robust_smooth, with_covariance
    from sblsim.models.tracking.starts import SPLICE_ROUNDS, splice_pings, spliced

    covariance, improved = track.P is not None, False
    for _ in range(SPLICE_ROUNDS):
        pings = splice_pings(track.x, toa, receivers, settings, fixes)
        if not len(pings):
            break
        again = robust_smooth(toa, receivers, settings, [track.x, spliced(track.x, fixes, pings)],
                              schedule=schedule, depth=depth, covariance=False, student_start=False)
        if not again.cost < track.cost - MODE_BETTER:
            break
        track, improved = replace(again, start=track.start, start_names=track.start_names), True
    if improved and covariance:
        track = with_covariance(track, toa, receivers, settings, schedule, depth)
    return track


@contextmanager
def splice_rounds(baseline: bool, spent: list):
    """:func:`robust_track`'s splice rounds today's, or the baseline's (:func:`whole_rounds`), for the block; each
    call's CPU time [s] appended to ``spent``."""
    from sblsim.models.tracking import starts

    today = starts.with_fixes_spliced
    rounds = whole_rounds if baseline else today

    def timed(*args, **kwargs):
        begun = cpu_s()
        try:
            return rounds(*args, **kwargs)
        finally:
            spent.append(cpu_s() - begun)

    starts.with_fixes_spliced = timed
    try:
        yield
    finally:
        starts.with_fixes_spliced = today


def track(toa: np.ndarray, receivers: np.ndarray, sound_speed: float, acceleration_psd: float,
          baseline: bool = False) -> dict:
    """The robust smoother's track of a record (module docstring) with each stage's time [s]: ``fixes_s``,
    ``schedule_s`` (the settings and the schedule), ``robust_s`` (:func:`robust_track`), ``track_s`` (their sum),
    the process's CPU time of the fixes, of :func:`robust_track`, of its splice rounds and of the track
    (``fixes_cpu_s``, ``robust_cpu_s``, ``splice_cpu_s``, ``track_cpu_s``: the time on a core, whatever else the
    machine runs), ``peak_bytes`` (the high-water mark over them), ``peak_reset`` (whether it was reset before) and
    ``robust`` (the :class:`RobustTrack`); with ``baseline``, the splice rounds the baseline's
    (:func:`whole_rounds`)."""
    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.models.tracking.timing import SIGMA_TOA
    from sblsim.orchestrator.tracks.tracker import ping_schedule, tracker_settings

    reset = reset_peak()
    start, cpu = time.perf_counter(), cpu_s()
    fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, sound_speed, SIGMA_TOA)
    fixed, fixed_cpu = time.perf_counter(), cpu_s()
    settings = replace(tracker_settings(sound_speed, fe), acceleration_psd=acceleration_psd)
    schedule, _ = ping_schedule(toa, receivers, settings)
    settings = replace(settings, interval=schedule.interval)
    scheduled, scheduled_cpu = time.perf_counter(), cpu_s()
    spent: list = []
    with splice_rounds(baseline, spent):
        robust = tt.robust_track(toa, receivers, settings, (fx, fe, fused), None, schedule)
    done, done_cpu = time.perf_counter(), cpu_s()
    return {"fixes_s": fixed - start, "schedule_s": scheduled - fixed, "robust_s": done - scheduled,
            "track_s": done - start, "fixes_cpu_s": fixed_cpu - cpu, "robust_cpu_s": done_cpu - scheduled_cpu,
            "splice_cpu_s": sum(spent), "track_cpu_s": done_cpu - cpu, "peak_bytes": peak_bytes(),
            "peak_reset": reset, "robust": robust}


def casadi_called(receivers: np.ndarray, sound_speed: float):
    """The baseline of the EKF's TOA model: :func:`~sblsim.models.tracking.toa.toa_model`, the casadi function
    called per ping with numpy arguments, casadi converting them and its results each time (as the EKF did before
    :class:`~sblsim.models.tracking.toa.PingModel`)."""
    from sblsim.models.tracking.toa import toa_model

    return lambda position, emission: toa_model(position, emission, receivers, sound_speed)


def ekf_rts(toa: np.ndarray, receivers: np.ndarray, sound_speed: float, acceleration_psd: float,
            baseline: bool = True) -> dict:
    """The EKF with the RTS smoother on the same pings, from the same fixes and schedule: its time alone [s]
    (``ekf_rts_s``); with ``baseline``, the same with the TOA model called per ping as before
    (:func:`casadi_called`, ``ekf_rts_baseline_s``) and whether the two give the same records and smoothed
    track to the last bit (``ekf_rts_same``)."""
    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.models.tracking.timing import SIGMA_TOA
    from sblsim.orchestrator.tracks.tracker import ping_schedule, tracker_settings

    fx, fe, fc, fused, _ = tt.fix_pings(toa, receivers, sound_speed, SIGMA_TOA)
    settings = replace(tracker_settings(sound_speed, fe), acceleration_psd=acceleration_psd)
    schedule, _ = ping_schedule(toa, receivers, settings)

    def timed(called: bool) -> tuple[float, list[np.ndarray]]:
        tracker = tt.ToaTracker(receivers, replace(settings, interval=schedule.interval))
        if called:
            tracker._model = casadi_called(receivers, sound_speed)
        start = time.perf_counter()
        record = tracker.run(toa, (fx, fc, fused.sum(axis=1)), fused, schedule)
        smoothed = tracker.smooth(record)
        return time.perf_counter() - start, [record.x_filtered, record.P_filtered, record.used, *smoothed]

    seconds, today = timed(False)
    out = {"ekf_rts_s": seconds}
    if baseline:
        seconds, before = timed(True)
        out |= {"ekf_rts_baseline_s": seconds,
                "ekf_rts_same": all(np.array_equal(a, b, equal_nan=True) for a, b in zip(today, before))}
    return out


def pcrb_stepwise(positions, velocities, emissions, heard, receivers, c, sigma_toa, motion):
    """The baseline of the PCRB along a track: :func:`~sblsim.models.receiver.toa_bound.pcrb` (one stable interval
    a step) as it was, every step's transition, process noise and their products made inside the recursion, one
    step at a time."""
    from sblsim.models.receiver import toa_bound as tb

    m, d = positions.shape
    s, idx = 2 * d + 2, np.r_[0:d, 2 * d]
    Jz = np.zeros((m, s, s))
    Jz[np.ix_(np.arange(m), idx, idx)] = tb.ping_information(positions, heard, receivers, c, sigma_toa)
    J = Jz[0].copy()
    J[d:2 * d, d:2 * d] += np.eye(d) / motion.sigma_speed**2
    J[-1, -1] += 1.0 / motion.sigma_interval**2
    intervals = np.diff(emissions)
    B, Bp, Fs = np.empty((m, s, s)), np.empty((m, s, s)), np.tile(np.eye(s), (m, 1, 1))
    B[0] = Bp[0] = np.linalg.inv(J)
    for k in range(m - 1):
        F, Q = tb.transition(velocities[k], intervals[k], motion)
        Qi = np.linalg.inv(Q)
        D11, D12 = F.T @ Qi @ F, -F.T @ Qi
        J = Qi + Jz[k + 1] - D12.T @ np.linalg.solve(J + D11, D12)
        J = 0.5 * (J + J.T)
        B[k + 1], Fs[k + 1], Bp[k + 1] = np.linalg.inv(J), F, F @ B[k] @ F.T + Q
    Bs = B.copy()
    for k in range(m - 2, -1, -1):
        C = np.linalg.solve(Bp[k + 1], Fs[k + 1] @ B[k]).T
        Bs[k] = B[k] + C @ (Bs[k + 1] - Bp[k + 1]) @ C.T
        Bs[k] = 0.5 * (Bs[k] + Bs[k].T)
    return B, Bs


def bound(toa: np.ndarray, receivers: np.ndarray, truth: np.ndarray, emissions: np.ndarray, settings,
          baseline: bool = True) -> dict:
    """The PCRB and the smoothing bound along the record's true track (what a replay scores its track against):
    their time [s] (``bound_s``); with ``baseline``, :func:`pcrb_stepwise`'s (``bound_baseline_s``) and whether
    the two give the same bounds to the last bit (``bound_same``)."""
    from sblsim.models.receiver import toa_bound as tb

    velocities = np.gradient(truth, emissions, axis=0)
    args = (truth, velocities, emissions, np.isfinite(toa), receivers, SOUND_SPEED, settings.sigma_toa,
            tb.MotionModel.of(settings))
    start = time.perf_counter()
    today = tb.pcrb(*args)
    out = {"bound_s": time.perf_counter() - start}
    if baseline:
        start = time.perf_counter()
        before = pcrb_stepwise(*args)
        out |= {"bound_baseline_s": time.perf_counter() - start,
                "bound_same": all(np.array_equal(a, b) for a, b in zip((today.B_filtered, today.B_smoothed), before))}
    return out


def replay(n_pings: int, seed: int = 0) -> dict:
    """The whole replay (``sblsim.replay_toa``, the sound speed given) of the record of ``n_pings`` written to files:
    its time [s] (``replay_s``, the files' reading among it) and the track's RMS error [m] (``replay_rms_m``)."""
    import sblsim

    toa, receivers, truth, emissions, settings = simulate(n_pings, seed)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        names = [f"R{k + 1}" for k in range(len(receivers))]
        rows = [" ".join(names)] + [" ".join("NA" if not np.isfinite(v) else repr(float(v)) for v in row)
                                    for row in toa]
        (folder / "toa.txt").write_text("\n".join(rows) + "\n")
        (folder / "receivers.csv").write_text("name,x_m,y_m\n" + "".join(
            f"{n},{float(x)!r},{float(y)!r}\n" for n, (x, y) in zip(names, receivers)))
        (folder / "truth.txt").write_text('"x" "y" "t"\n' + "".join(
            f"{float(x)!r} {float(y)!r} {float(t)!r}\n" for (x, y), t in zip(truth, emissions)))
        start = time.perf_counter()
        result = sblsim.replay_toa(folder / "toa.txt", receivers=folder / "receivers.csv",
                                   truth=folder / "truth.txt", sound_speed=settings.sound_speed)
        return {"replay_s": time.perf_counter() - start, "replay_rms_m": result.score["rms_m"]}


def measure(n_pings: int, seed: int = 0, replay_pings: int = 0, sizes: int = 3, baseline: bool = True) -> dict:
    """The timings (module docstring) at ``sizes`` sizes up to ``n_pings`` (each a tenth of the next), and the whole
    replay at ``replay_pings`` (0: not run). Returns the JSON's fields and ``runs`` (per size: ``pings``, the
    stages' times, ``per_ping_us`` [µs], ``ratio`` to the smallest size's per-ping time, ``peak_bytes``,
    ``rms_m`` of the robust track against the simulated truth, ``sigma_m`` the timing noise's own position scale
    (σ_toa c), ``iterations``, ``start``; with ``baseline``, ``baseline`` the same of the baseline's track
    (:func:`whole_rounds`), ``cpu_ratio`` today's CPU time over its, ``moved_m`` and ``moved_te_m`` the largest
    difference of a position and of an emission time times the sound speed between the two tracks [m]) and
    ``robust`` (the largest size's :class:`RobustTrack`)."""
    counts = sorted({max(n_pings // 10**k, 100) for k in range(sizes)})
    small = simulate(counts[0], seed)
    track(small[0], small[1], SOUND_SPEED, small[4].acceleration_psd)  # loads the modules, untimed
    ekf = ekf_rts(small[0], small[1], SOUND_SPEED, small[4].acceleration_psd, baseline)
    ekf |= bound(*small[:4], small[4], baseline)
    runs, robust = [], None

    def summary(r, count, truth, arrivals):
        out = r.pop("robust")
        error = np.hypot(*(out.x[:, :2] - truth).T)
        return out, {"pings": count, **r, "per_ping_us": 1e6 * r["track_s"] / count,
                     "rms_m": float(np.sqrt(np.mean(error**2))), "iterations": out.iterations,
                     "start": out.start_names[out.start], "arrivals": arrivals}

    for count in counts:
        toa, receivers, truth, _, settings = simulate(count, seed)
        arrivals = int(np.isfinite(toa).sum())
        robust, run = summary(track(toa, receivers, SOUND_SPEED, settings.acceleration_psd), count, truth, arrivals)
        run["sigma_m"] = settings.sigma_toa * SOUND_SPEED
        if baseline:  # the same record, the splice rounds the baseline's; today's states alone kept meanwhile
            robust = replace(robust, P=None, P_lag=None)
            before, run["baseline"] = summary(track(toa, receivers, SOUND_SPEED, settings.acceleration_psd, True),
                                              count, truth, arrivals)
            run["cpu_ratio"] = run["track_cpu_s"] / run["baseline"]["track_cpu_s"]
            run["moved_m"] = float(np.hypot(*(robust.x[:, :2] - before.x[:, :2]).T).max())
            run["moved_te_m"] = float(SOUND_SPEED * np.abs(robust.x[:, -2] - before.x[:, -2]).max())
            del before
        runs.append(run)
        del toa, receivers, truth
    for run in runs:
        run["ratio"] = run["per_ping_us"] / runs[0]["per_ping_us"]
    last = runs[-1]
    out = {"pings": last["pings"], "track_s": last["track_s"], "track_cpu_s": last["track_cpu_s"],
           "fixes_s": last["fixes_s"],
           "schedule_s": last["schedule_s"], "robust_s": last["robust_s"], "peak_gib": last["peak_bytes"] / 1024**3,
           "target_s": TARGET_S, "target_gib": TARGET_BYTES / 1024**3,
           "per_ping_us": [run["per_ping_us"] for run in runs], "ratio": [run["ratio"] for run in runs],
           "sizes": counts, "rms_m": last["rms_m"], "ekf_rts_per_ping_us": 1e6 * ekf["ekf_rts_s"] / counts[0],
           "bound_per_ping_us": 1e6 * ekf["bound_s"] / counts[0],
           "cores": os.cpu_count(), "runs": runs, "robust": robust}
    if baseline:
        out |= {"baseline_track_cpu_s": last["baseline"]["track_cpu_s"], "cpu_ratio": last["cpu_ratio"],
                "moved_m": last["moved_m"], "moved_te_m": last["moved_te_m"],
                "ekf_rts_baseline_per_ping_us": 1e6 * ekf["ekf_rts_baseline_s"] / counts[0],
                "ekf_rts_ratio": ekf["ekf_rts_s"] / ekf["ekf_rts_baseline_s"], "ekf_rts_same": ekf["ekf_rts_same"],
                "bound_baseline_per_ping_us": 1e6 * ekf["bound_baseline_s"] / counts[0],
                "bound_ratio": ekf["bound_s"] / ekf["bound_baseline_s"], "bound_same": ekf["bound_same"]}
    if replay_pings:
        out |= {"replay_pings": replay_pings, **replay(replay_pings, seed)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pings", type=int, default=10**6, help="the largest record's pings (default 10⁶)")
    parser.add_argument("--replay-pings", type=int, default=10**4, help="the whole replay's pings (0: not run)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-baseline", action="store_true",
                        help="skip the baseline (the splice rounds as whole-record re-solves) in the same run")
    args = parser.parse_args()
    if args.pings < 100:
        parser.error("--pings: must be at least 100")
    if args.replay_pings < 0:
        parser.error("--replay-pings: must be 0 or more")
    r = measure(args.pings, args.seed, args.replay_pings, baseline=not args.no_baseline)
    for run in r["runs"]:
        print(f"{run['pings']:>9,} pings ({run['arrivals']:,} arrivals): the track {run['track_s']:7.2f} s (fixes "
              f"{run['fixes_s']:.2f}, schedule {run['schedule_s']:.2f}, robust_track {run['robust_s']:.2f}; "
              f"{run['iterations']} steps from the {run['start']} start; CPU {run['track_cpu_s']:.2f} s: fixes "
              f"{run['fixes_cpu_s']:.2f}, robust_track {run['robust_cpu_s']:.2f}, its splice rounds "
              f"{run['splice_cpu_s']:.2f}), {run['per_ping_us']:.1f} µs per ping ({run['ratio']:.2f}× the smallest), "
              f"peak {run['peak_bytes'] / 1024**3:.2f} GiB{'' if run['peak_reset'] else ' (since the start)'}; "
              f"RMS error {run['rms_m']:.3f} m")
        if "baseline" in run:
            base = run["baseline"]
            print(f"{'':>9}   the baseline (splice rounds re-solving the whole record): CPU {base['track_cpu_s']:.2f} "
                  f"s (its splice rounds {base['splice_cpu_s']:.2f}), peak {base['peak_bytes'] / 1024**3:.2f} GiB, "
                  f"RMS error {base['rms_m']:.3f} m; today's CPU {run['cpu_ratio']:.2f}× its; the tracks apart by "
                  f"{run['moved_m']:.2g} m at most (emission times {run['moved_te_m']:.2g} m)")
    print(f"the EKF with the RTS smoother at {r['sizes'][0]:,} pings: {r['ekf_rts_per_ping_us']:.1f} µs per ping"
          + (f" (the baseline, the TOA model called per ping: {r['ekf_rts_baseline_per_ping_us']:.1f} µs; today's "
             f"time {r['ekf_rts_ratio']:.2f}× its; the same records to the last bit: {r['ekf_rts_same']})"
             if "ekf_rts_ratio" in r else "")
          + f"; targets at 10⁶ pings: {r['target_s']:g} s of CPU and {r['target_gib']:g} GiB on one core")
    print(f"the PCRB and the smoothing bound along the true track at {r['sizes'][0]:,} pings: "
          f"{r['bound_per_ping_us']:.1f} µs per ping"
          + (f" (the baseline, a step's terms made inside the recursion: {r['bound_baseline_per_ping_us']:.1f} µs; "
             f"today's time {r['bound_ratio']:.2f}× its; the same bounds to the last bit: {r['bound_same']})"
             if "bound_ratio" in r else ""))
    if "replay_s" in r:
        print(f"the whole replay (EM, EKF, sequential EKF, UKF, both smoothers, quality, scoring) of "
              f"{r['replay_pings']:,} pings: {r['replay_s']:.2f} s, RMS error {r['replay_rms_m']:.3f} m")
    r.pop("robust")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
