"""Time the replay of a recorded inverted-LBL track (the Lake Hald tow track, docs/tracking.md) on one core.

Run:  python benchmarks/bench_tracking.py [--repeats N] [--receivers-kept H2,H4,...] [--against REV]

Best of ``--repeats`` (after a first run that loads the modules and makes casadi's functions): the whole replay
(reading, the sound speed's calibration, the single-ping fixes, the EKF, the RTS smoother, the robust smoother,
scoring, no files written) against the issue's target of 10 s on one core; and, on the same pings in the same run,
the robust smoother (its three starts made and run: ``robust_track``) against its baseline, the EKF with the RTS
smoother (the ratio of their times). Prints a JSON
line last (``replay_s``, ``ekf_rts_s``, ``robust_s``, ``ratio``, ``rms_m`` of the track). With ``--against REV``,
the tracking itself (``sblsim.orchestrator.tracks.track.track``: everything but the command's checks of its
arguments) timed in this checkout and at the revision REV, one after the other in the same run, each best of
``--repeats`` after a first run, and their ratio (``against``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from revision import run_at  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "data" / "lake-hald"
#: The issue's target for the whole replay on one core [s].
TARGET_S = 10.0


#: The tracking timed at a revision (and here): the Lake Hald folder, the repeats and the receivers kept ("" all) as
#: its arguments; prints the best time [s].
TRACK_TIMED = """
import sys, time
from pathlib import Path
from sblsim.orchestrator.tracks.track import track
data, repeats, kept = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3].split(",") if sys.argv[3] else None
def run():
    return track(data / "toa.txt", data / "hydrophones.csv", data / "gps.txt", receivers_kept=kept)
run()
best = float("inf")
for _ in range(repeats):
    start = time.perf_counter()
    run()
    best = min(best, time.perf_counter() - start)
print(best)
"""


def best_of(repeats: int, work, warm: bool = True) -> tuple[float, object]:
    """The best time [s] of ``repeats`` calls of ``work`` (after a first, untimed one when ``warm``), and its last
    result."""
    result = work() if warm else None
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        result = work()
        best = min(best, time.perf_counter() - start)
    return best, result


def measure(repeats: int, kept: str | None = None, warm: bool = True) -> dict:
    """The timings (module docstring) on the Lake Hald files, and the replay's result (``result``); ``warm``: each
    timed after a first, untimed run."""
    import sblsim
    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.models.tracking.timing import SIGMA_TOA
    from sblsim.orchestrator.readers.receivers_file import read_receivers
    from sblsim.orchestrator.readers.toa_matrix import read_toa
    from sblsim.orchestrator.tracks.thinning import _usable
    from sblsim.orchestrator.tracks.tracker import tracker_settings

    def replay():
        return sblsim.replay_toa(DATA / "toa.txt", receivers=DATA / "hydrophones.csv", truth=DATA / "gps.txt",
                                 receivers_kept=kept)

    replay_s, result = best_of(repeats, replay, warm)
    c = result.summary["sound_speed"]["sound_speed_m_s"]
    toa, positions, _ = _usable(read_toa(DATA / "toa.txt"), read_receivers(DATA / "hydrophones.csv"),
                                None if kept is None else kept.split(","))
    fx, fe, fc, fused, _ = tt.fix_pings(toa, positions, c, SIGMA_TOA)
    settings = tracker_settings(c, fe)
    tracker = tt.ToaTracker(positions, settings)

    def ekf_rts():
        record = tracker.run(toa, (fx, fc, fused.sum(axis=1)), fused)
        return record, tracker.smooth(record)

    ekf_rts_s, (record, (xs, _)) = best_of(repeats, ekf_rts, warm)
    k0 = record.start
    fixes = (fx[k0:], fe[k0:], fused[k0:])
    robust_s, _ = best_of(repeats, lambda: tt.robust_track(toa[k0:], positions, settings, fixes, xs[k0:]), warm)
    return {"replay_s": replay_s, "target_s": TARGET_S, "ekf_rts_s": ekf_rts_s, "robust_s": robust_s,
            "ratio": robust_s / ekf_rts_s, "pings": int(len(toa)), "rms_m": result.score["rms_m"],
            "cores": os.cpu_count(), "result": result}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of each (the best is kept)")
    parser.add_argument("--receivers-kept", default=None, help="a thinned array: the receivers' names, by commas")
    parser.add_argument("--against", default=None, metavar="REV",
                        help="also time the tracking here and at this earlier revision, in the same run")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats: must be at least 1")
    if args.against is not None:
        arguments = (str(DATA), str(args.repeats), args.receivers_kept or "")
        now = float(subprocess.run([sys.executable, "-c", TRACK_TIMED, *arguments], capture_output=True, text=True,
                                   check=True).stdout.split()[-1])
        then = float(run_at(args.against, TRACK_TIMED, *arguments).split()[-1])
        print(f"the tracking, best of {args.repeats}: this checkout {now:.2f} s, {args.against} {then:.2f} s: "
              f"{now / then:.2f}x")
        print(json.dumps({"against": args.against, "now_s": now, "then_s": then, "ratio": now / then}))
        return
    r = measure(args.repeats, args.receivers_kept)
    print(f"Lake Hald, {r['pings']} pings: the whole replay {r['replay_s']:.2f} s (target {r['target_s']:g} s on one "
          f"core); the EKF and RTS smoother {r['ekf_rts_s']:.2f} s, the robust smoother {r['robust_s']:.2f} s "
          f"({r['ratio']:.2f}× the EKF and RTS smoother); the track's RMS error {r['rms_m']:.3f} m")
    r.pop("result")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
