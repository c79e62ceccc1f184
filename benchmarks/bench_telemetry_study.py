"""Time a telemetry study in one command (``sblsim track``) on a simulated study as its people bring it, and score
every track against its truth and its accuracy limit (the issue "a telemetry study's own files in").

Run:  python benchmarks/bench_telemetry_study.py [--receivers 20] [--tags 100] [--days 7] [--redeployed 2]
      [--seed 1] [--workers 2] [--format vue|fathom] [--baseline-days D] [--no-bound] [--boats]

The study (:func:`sblsim.orchestrator.telemetry.simulate.simulate_study`): receivers on a jittered grid of 150 m,
``--redeployed`` of them moved to another station in the middle third (their clocks set again), each with a
co-located sync tag (540-660 s); ``--tags`` animals on smooth paths inside the array at a stable, random and
pseudo-random burst interval in turn (about 150 s); the receivers' clocks offset by up to 2 s and drifting by up to
20 ppm; a detection range curve of 50 % at 220 m; 0.15 ms timing noise. It is written as the deployments sheet
(lat/lon, dates), the tag sheet and a VUE export (or a Fathom CSV), and :func:`sblsim.track` runs on the files
with ``--workers`` processes: timed whole (reading, synchronising, every tag's matrix and track, the outputs), at
``--baseline-days`` (default a tenth of ``--days``) and at ``--days``, the time per ping against the baseline's
(1.00: linear).

Then each track (the robust smoother's rows) against the truth: the truth's emissions read on the reference
receiver's clock (the study's UTC), the 2-D errors' RMS; and, unless ``--no-bound``, against its accuracy limit:
each tag tracked again with its truth (:func:`~sblsim.orchestrator.tracks.track.track`, the same options), the
smoothing bound along the true track (the posterior Cramér-Rao bound's RTS pass,
:mod:`sblsim.orchestrator.tracks.bound`), the ratio of the track's RMS error to the bound's RMS (the target: every
track within 1.3). With ``--boats``, the boats study from its lat/lon deployments and tag sheet is timed too (the
target: 60 s on 2 cores). A JSON line last.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

import sblsim
from sblsim.orchestrator.telemetry.simulate import simulate_study

#: The issue's targets: the simulated study's seconds on 2 cores, each track's RMS error over its bound's RMS, the
#: boats study's seconds.
TARGET_S = 600.0
TARGET_RATIO = 1.3
TARGET_BOATS_S = 60.0
DATA = Path(__file__).resolve().parents[1] / "data" / "boats-norway"


def run(receivers: int, tags: int, days: float, redeployed: int, seed: int, workers: int, format: str,
        folder: Path, bound: bool = True) -> dict:
    """One study simulated, written, tracked (timed) and scored (the module docstring)."""
    sim = simulate_study(n_receivers=receivers, n_tags=tags, days=days, redeployed=redeployed, seed=seed)
    files = sim.write(folder / "files", format)
    size = files["detections"].stat().st_size
    started, cpu = time.perf_counter(), os.times()
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"],
                          out=folder / "out", workers=workers)
    wall = time.perf_counter() - started
    after = os.times()
    cpu_s = (after.user + after.system + after.children_user + after.children_system
             - cpu.user - cpu.system - cpu.children_user - cpu.children_system)
    reference = result.summary["clocks"]["reference_receiver"]
    k = int(np.flatnonzero(result.receivers["receiver"].to_numpy() == reference)[0])
    rows = []
    for tag in result.tags.itertuples():
        entry = {"tag": tag.tag, "status": tag.status, "ping_type": tag.ping_type, "pings": tag.pings}
        if tag.status != "tracked":
            rows.append(entry | {"reason": tag.reason})
            continue
        truth = sim.truth[tag.tag]
        on_clock = sim.clock_time(k, truth["tau"].to_numpy())
        mine = result.tracks[result.tracks["tag"] == tag.tag]
        x = np.interp(mine["epoch_s"], on_clock, truth["x"])
        y = np.interp(mine["epoch_s"], on_clock, truth["y"])
        error = np.hypot(mine["x"] - x, mine["y"] - y).to_numpy()
        drms = np.hypot(mine["sigma_x"], mine["sigma_y"]).to_numpy()
        entry |= {"rms_m": float(np.sqrt(np.mean(error**2))), "median_m": float(np.median(error)),
                  "sigma_rms_m": float(np.sqrt(np.mean(drms**2))),
                  "flagged_share": float((mine["quality"] == "flagged").mean())}
        if bound:
            entry |= _bound(folder / "out" / tag.folder, pd.DataFrame({"epoch_s": on_clock, "x": truth["x"],
                                                                      "y": truth["y"]}), result, tag)
        rows.append(entry)
    pings = int(result.tags["pings"].fillna(0).sum())
    return {"days": days, "receivers": receivers, "tags": tags, "detections": int(len(sim.detections)),
            "file_mib": size / 2**20, "pings": pings, "wall_s": wall, "cpu_s": cpu_s,
            "per_ping_ms": 1e3 * wall / max(pings, 1), "set_aside": result.summary["detections"]["set_aside"],
            "tracked": int((result.tags["status"] == "tracked").sum()), "per_tag": rows}


def _bound(folder: Path, truth: pd.DataFrame, result, tag) -> dict:
    """A tag tracked again with its truth (epoch seconds on the study's UTC): its RMS error over the smoothing
    bound's RMS along the true track."""
    from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet, spec_for
    from sblsim.orchestrator.tracks.track import track

    path = folder / "truth.csv"
    truth.to_csv(path, index=False, float_format="%.6f")
    summary = json.loads((folder / "toa.json").read_text())
    sheet = read_tag_sheet(Path(result.summary["tag_sheet"]["file"]))
    spec = spec_for(sheet, tag.transmitter)
    frame = result.summary["frame"]
    o = track(folder / "toa.txt", folder / "receivers.csv", path, smooth=True, ping_type=spec.ping_type,
              burst_interval=spec.burst_interval, burst_sequence_path=spec.burst_sequence,
              crs=None if frame is None else frame["crs"], time_origin=summary["origin_epoch_s"],
              other_filters=False)
    errors = o.errors[o.errors["estimator"] == "robust"]
    predicted = o.bound["pcrb_smoothed_m"].to_numpy()[errors["ping"].to_numpy()]
    ok = np.isfinite(predicted) & np.isfinite(errors["error_2d_m"].to_numpy())
    observed = float(np.sqrt(np.mean(errors["error_2d_m"].to_numpy()[ok] ** 2)))
    limit = float(np.sqrt(np.mean(predicted[ok] ** 2)))
    return {"bound_rms_m": limit, "observed_rms_m": observed, "ratio": observed / limit if limit > 0 else None}


def boats(folder: Path, workers: int) -> float:
    """The boats study in one call [s]."""
    started = time.perf_counter()
    sblsim.track(DATA / "detections.csv", receivers=DATA / "deployments.csv", tags=DATA / "tags.csv",
                 out=folder / "boats", workers=workers)
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--receivers", type=int, default=20)
    parser.add_argument("--tags", type=int, default=100)
    parser.add_argument("--days", type=float, default=7.0)
    parser.add_argument("--redeployed", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--format", choices=("vue", "fathom"), default="vue")
    parser.add_argument("--baseline-days", type=float, default=None, help="default a tenth of --days")
    parser.add_argument("--no-bound", action="store_true", help="skip the tracks against their accuracy limit")
    parser.add_argument("--boats", action="store_true", help="time the boats study too")
    args = parser.parse_args()
    if args.receivers < 4 or args.tags < 1 or args.days <= 0 or args.workers < 1:
        print("bench_telemetry_study: error: --receivers: at least 4; --tags, --workers: at least 1; --days: "
              "positive", file=sys.stderr)
        sys.exit(2)
    baseline = args.baseline_days or args.days / 10
    with tempfile.TemporaryDirectory(prefix="sblsim-bench-study-") as tmp:
        rows = [run(args.receivers, args.tags, d, args.redeployed, args.seed, args.workers, args.format,
                    Path(tmp) / f"d{k}", bound=not args.no_bound and k == 1)
                for k, d in enumerate((baseline, args.days))]
        boats_s = boats(Path(tmp), args.workers) if args.boats else None
    print(f"a simulated study: {args.receivers} receivers ({args.redeployed} redeployed), {args.tags} tags (sbi, rbi, "
          f"pbi in turn), {args.format} export, {args.workers} worker processes")
    print(f"{'days':>6} {'detections':>11} {'MiB':>6} {'pings':>8} {'tracked':>8} {'aside':>6} {'wall s':>8} "
          f"{'CPU s':>8} {'ms/ping':>8} {'ratio':>6}")
    base = rows[0]["per_ping_ms"]
    for r in rows:
        r["per_ping_ratio"] = r["per_ping_ms"] / base
        print(f"{r['days']:>6g} {r['detections']:>11} {r['file_mib']:>6.1f} {r['pings']:>8} {r['tracked']:>8} "
              f"{r['set_aside']:>6} {r['wall_s']:>8.1f} {r['cpu_s']:>8.1f} {r['per_ping_ms']:>8.2f} "
              f"{r['per_ping_ratio']:>6.2f}")
    last = rows[-1]
    tracked = [t for t in last["per_tag"] if t["status"] == "tracked"]
    rms = np.array([t["rms_m"] for t in tracked])
    print(f"tracks against the truth ({len(tracked)} tags): RMS error median {np.median(rms):.3f} m, largest "
          f"{rms.max():.3f} m; own DRMS's RMS median {np.median([t['sigma_rms_m'] for t in tracked]):.3f} m; "
          f"rows flagged {np.mean([t['flagged_share'] for t in tracked]):.2%}")
    verdicts = [f"{last['wall_s']:.0f} s for every tag ({'met' if last['wall_s'] <= TARGET_S else 'not met'} "
                f"against {TARGET_S:.0f} s)"]
    if not args.no_bound:
        ratios = np.array([t["ratio"] for t in tracked if t.get("ratio") is not None])
        worst = max(tracked, key=lambda t: t.get("ratio") or 0)
        print(f"tracks against their smoothing bound: RMS error / the bound's RMS median {np.median(ratios):.2f}, "
              f"largest {ratios.max():.2f} ({worst['tag']}, {worst['ping_type']}); within {TARGET_RATIO:g}: "
              f"{int((ratios <= TARGET_RATIO).sum())} of {len(ratios)}")
        verdicts.append(f"every track within {TARGET_RATIO:g} of its bound "
                        f"({'met' if (ratios <= TARGET_RATIO).all() else 'not met'})")
    if boats_s is not None:
        print(f"the boats study, both animals from lat/lon deployments and a tag sheet: {boats_s:.1f} s")
        verdicts.append(f"boats {boats_s:.0f} s ({'met' if boats_s <= TARGET_BOATS_S else 'not met'} against "
                        f"{TARGET_BOATS_S:.0f} s)")
    print("targets: " + "; ".join(verdicts))
    print(json.dumps({"benchmark": "telemetry_study", "seed": args.seed, "workers": args.workers,
                      "format": args.format, "boats_s": boats_s, "sizes": rows}))


if __name__ == "__main__":
    main()
