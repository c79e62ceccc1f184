"""Time a telemetry study interrupted half way and run again against the same study run whole (the issue "a season,
not a week", item 4: resumable).

Run:  python benchmarks/bench_resume.py [--receivers 20] [--tags 40] [--days 2] [--seed 1] [--workers 2]
      [--signal kill|int]

The study is the telemetry benchmark's (:func:`sblsim.orchestrator.telemetry.simulate.simulate_study`, a VUE
export). ``sblsim track`` runs it whole (timed: the baseline of this run), then again into another ``--out``,
stopped (SIGKILL, or SIGINT: Ctrl-C) once half its tags are kept in the output's resume folder, then run a third
time with the same ``--out`` (taking the kept synchronisation and tags). Printed: each run's seconds, the tags the
rerun kept, the interrupted pair's total over the whole run (the target: at most 1.1) and whether every tag's
``track.csv`` is the whole run's to the byte. A JSON line last.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.tracks.resume import resume_folder

#: The issue's target: interrupted at half and resumed, the total time over the uninterrupted run's.
TARGET_RATIO = 1.1


def _command(files: dict[str, Path], workers: int, out: Path) -> list[str]:
    return [sys.executable, "-m", "sblsim.orchestrator.cli", "track", str(files["detections"]), "--receivers",
            str(files["deployments"]), "--tags", str(files["tags"]), "--workers", str(workers), "--out", str(out)]


def _timed(command: list[str]) -> float:
    started = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - started


def _kept(out: Path) -> int:
    """The tags kept in ``out``'s resume folder (its entries but the synchronisation's)."""
    folder = resume_folder(out)
    return max(sum(1 for p in folder.iterdir() if len(p.name) == 64) - 1, 0) if folder.is_dir() else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--receivers", type=int, default=20)
    parser.add_argument("--tags", type=int, default=40)
    parser.add_argument("--days", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--signal", choices=("kill", "int"), default="kill")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-resume-") as tmp:
        folder = Path(tmp)
        sim = simulate_study(n_receivers=args.receivers, n_tags=args.tags, days=args.days, seed=args.seed)
        files = sim.write(folder / "files", "vue")
        whole = _timed(_command(files, args.workers, folder / "whole"))
        print(f"whole study: {whole:.1f} s", flush=True)
        out = folder / "out"
        started = time.perf_counter()
        stopped = subprocess.Popen(_command(files, args.workers, out), stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL)
        while stopped.poll() is None and _kept(out) < args.tags // 2:
            time.sleep(0.05)
        stopped.send_signal(signal.SIGKILL if args.signal == "kill" else signal.SIGINT)
        stopped.wait()
        first = time.perf_counter() - started
        kept = _kept(out)
        second = _timed(_command(files, args.workers, out))
        ratio = (first + second) / whole
        same = all((out / "tags" / p.name / "track.csv").read_bytes() == (p / "track.csv").read_bytes()
                   for p in (folder / "whole" / "tags").iterdir() if (p / "track.csv").is_file())
        print(f"stopped (SIG{args.signal.upper()}) after {first:.1f} s with {kept} of {args.tags} tags kept; "
              f"run again: {second:.1f} s")
        print(f"interrupted + resumed over whole: {ratio:.2f} (target at most {TARGET_RATIO}); "
              f"every track the whole run's: {same}")
        print(json.dumps({"whole_s": whole, "stopped_s": first, "resumed_s": second, "tags_kept": kept,
                          "tags": args.tags, "ratio": ratio, "identical": same}))


if __name__ == "__main__":
    main()
