"""Still tags: the verdict "moved beyond what its error terms allow" and the σ of its place, on simulated records.

Run:  python benchmarks/bench_still_tags.py [--seeds N]

A tag at a fixed place among 8 receivers (1 km × 0.8 km), a ping every 120 ± 24 s over a day, each receiver hearing
80 % with 0.1 ms noise, in water whose sound speed is 1,480 ± 5 m/s over the day (a sine of random phase), tracked as
``sblsim replay --motion stationary`` does (``sblsim.orchestrator.tracks.track.track``, the sound speed calibrated from
the pings): for ``--seeds`` still tags, the share of rows flagged and the mean 2-D NEES of the place against the
truth with the covariance reported; the same tags' fixes under the permutation test of their order alone (the verdict
before: :func:`sblsim.models.tracking.stationary.moved`); a tag moved 20 m at its 360th ping, where its rows are
flagged from; a random walk of 2 m per ping (an animal); and the verdict's own time on 10⁴ fixes, still and moved
(best of three). Prints a JSON line last.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

RECEIVERS = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 800.0], [0.0, 800.0], [500.0, 400.0], [250.0, 700.0],
                      [800.0, 150.0], [650.0, 750.0]])
TAG = np.array([780.0, 560.0])
SIGMA = 1e-4
PINGS = 720


def record(folder: Path, seed: int, move: np.ndarray | None = None, walk: float | None = None):
    """A simulated record's TOA and receivers files in ``folder``, and the tag's place at each ping (module
    docstring)."""
    from sblsim.orchestrator.tracks.variants import write_toa

    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(96.0, 144.0, PINGS))
    c = 1480.0 + 5.0 * np.sin(2 * np.pi * t / 86400.0 + rng.uniform(0, 2 * np.pi))
    places = np.repeat(TAG[None], PINGS, axis=0)
    if move is not None:
        places[PINGS // 2:] += move
    if walk is not None:
        places = places + np.cumsum(rng.normal(scale=walk, size=(PINGS, 2)), axis=0)
    toa = t[:, None] + np.linalg.norm(places[:, None] - RECEIVERS[None], axis=2) / c[:, None]
    toa = toa + SIGMA * rng.normal(size=toa.shape)
    toa[rng.random(toa.shape) > 0.8] = np.nan
    names = [f"H{k + 1}" for k in range(len(RECEIVERS))]
    write_toa(folder / "toa.txt", toa, names)
    rows = "\n".join(f"{name},{x:g},{y:g}" for name, (x, y) in zip(names, RECEIVERS))
    (folder / "receivers.csv").write_text("name,x_m,y_m\n" + rows + "\n")
    return folder / "toa.txt", folder / "receivers.csv", places


def tracked(folder: Path, seed: int, **kw):
    """The record tracked as a still tag: the outcome, the places, and the seconds it took."""
    from sblsim.orchestrator.tracks.track import track

    toa, receivers, places = record(folder, seed, **kw)
    start = time.perf_counter()
    outcome = track(toa, receivers, motion="stationary", toa_sigma=SIGMA, other_filters=False)
    return outcome, places, time.perf_counter() - start


def verdict_time(moved_by: float) -> float:
    """The best of three times [s] of :func:`~sblsim.models.tracking.still.still_verdict` on 10⁴ fixes (a ping a
    minute, 0.2 m noise, a slow error of 1 m), moved by ``moved_by`` [m] half way."""
    from sblsim.models.tracking.still import still_verdict

    rng = np.random.default_rng(0)
    n = 10_000
    x = rng.normal(scale=0.2, size=(n, 2))
    x[n // 2:, 0] += moved_by
    R = np.tile(0.04 * np.eye(2), (n, 1, 1))
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        still_verdict(x, R, np.arange(n) * 60.0, np.ones(n, bool), np.eye(2))
        best = min(best, time.perf_counter() - start)
    return best


def measure(seeds: int) -> dict:
    """The figures (module docstring)."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        nees, flagged, rows, order_moved, seconds = [], 0, 0, 0, []
        for seed in range(seeds):
            outcome, places, took = tracked(folder, seed)
            still = outcome.summary["motion"]["still"]
            e = np.asarray(still["place"]) - places[0]
            nees.append(float(e @ np.linalg.solve(np.asarray(still["covariance"]), e)))
            flagged += int((outcome.track["quality"] == "flagged").sum())
            rows += len(outcome.track)
            order_moved += bool(outcome.summary["motion"]["moved_test"]["in_order"])
            seconds.append(took)
        offsets, before_ok, distance = [], [], []
        for seed in range(5):
            outcome, places, _ = tracked(folder, seed, move=np.array([20.0, 0.0]))
            reasons = outcome.track["quality_reason"].str.contains("tag_moved").to_numpy()
            first = int(np.argmax(reasons)) if reasons.any() else len(reasons)
            offsets.append(first - PINGS // 2)
            before_ok.append(bool((outcome.track["quality"].to_numpy()[:first] == "ok").all()))
            change = outcome.summary["motion"]["still"]["change"]
            distance.append(float(np.linalg.norm(np.asarray(change["second_place"]) - places[-1])))
        animals = [tracked(folder, seed, walk=2.0)[0].summary["motion"]["still"]["verdict"] for seed in range(5)]
    return {"seeds": seeds, "rows": rows, "flagged": flagged, "share_flagged": flagged / rows,
            "nees_mean": float(np.mean(nees)), "nees_median": float(np.median(nees)),
            "order_test_moved": order_moved, "track_s_median": float(np.median(seconds)),
            "moved_first_flag_offsets": offsets, "moved_rows_before_ok": before_ok,
            "moved_second_place_error_m": distance, "animal_verdicts": animals,
            "verdict_1e4_still_s": verdict_time(0.0), "verdict_1e4_moved_s": verdict_time(20.0)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="still tags simulated")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds: must be at least 1")
    r = measure(args.seeds)
    print(f"{r['seeds']} still tags in water of 1480 ± 5 m/s over a day: {r['flagged']} of {r['rows']} rows flagged "
          f"({100 * r['share_flagged']:.1f} %), mean 2-D NEES {r['nees_mean']:.2f} (median {r['nees_median']:.2f}); "
          f"the permutation test of their fixes' order alone says {r['order_test_moved']} of {r['seeds']} moved; "
          f"a still tag tracked in {r['track_s_median']:.2f} s (median)")
    second = np.round(r["moved_second_place_error_m"], 2).tolist()
    print(f"moved 20 m at ping {PINGS // 2}: first flagged row {r['moved_first_flag_offsets']} pings from the move, "
          f"the rows before ok {r['moved_rows_before_ok']}, the second place {second} m from where it went; a random "
          f"walk of 2 m per ping: {r['animal_verdicts']}")
    print(f"the verdict on 10^4 fixes: {r['verdict_1e4_still_s']:.3f} s still, {r['verdict_1e4_moved_s']:.3f} s moved "
          "(best of three)")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
